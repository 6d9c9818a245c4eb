"""ROS 2 over zenoh, the rmw_zenoh way, without ROS 2 installed (docs/ros2.md).

The pure wire layer of the bridge between rhbl and ROS 2 (no zenoh session here; the session,
the bridge process and the ROS 2 recordings are ``client.ros2``):

- :mod:`protocol.ros2.names`: ROS 2 names, the DDS type names and the ``/`` -> ``%`` mangling.
- :mod:`protocol.ros2.qos`: QoS profiles (ROS 2's default and sensor-data ones) and the compact
  form rmw_zenoh writes into liveliness tokens.
- :mod:`protocol.ros2.graph`: a topic's data key, the liveliness tokens of nodes, publishers
  and subscriptions, their parser and the entities' GIDs.
- :mod:`protocol.ros2.attachment`: the sequence number, timestamp and GID of every sample.
- :mod:`protocol.ros2.cdr`: the messages (``rosbags``' Jazzy typestore), CDR, type hashes.
- :mod:`protocol.ros2.convert`: rhbl ``Scan``/``State``/``VelCmd`` <-> ``LaserScan``,
  ``Odometry``, ``TFMessage``, ``Twist``.

Followed: rmw_zenoh 0.2.4+ (Jazzy), 0.6.0+ (Kilted, Rolling); docs/ros2.md says where older
releases differ.
"""
