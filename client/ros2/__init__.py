"""ROS 2 on the client side, the one home of it above the wire layer (``protocol.ros2``):

- :mod:`client.ros2.nodes`: nodes, publishers and subscriptions on a zenoh session the
  rmw_zenoh way, and a ROS 2 robot as the controller sees a robot.
- :mod:`client.ros2.bridge`: ``rhbl ros2``, the process that puts rhbl robots on ROS 2.
- :mod:`client.ros2.bag`: MCAP files of the ROS 2 profile and ``rhbl record --ros2``'s sink.
"""
