"""The wire contract between the simulator server and its clients (docs/protocol.md).

- :mod:`protocol.keys`: key expressions (``rhbl/<robot>/position2d/0/data/state``, ...).
- :mod:`protocol.messages`: message dataclasses with ``encode()`` / ``decode()``.
- :mod:`protocol.codec`: the msgpack codec and field validators behind the messages.
- :mod:`protocol.decoding`: one decoder per key, counting and logging what it drops.
- :mod:`protocol.ros2`: the ROS 2 wire layer (names, QoS, graph tokens, CDR, conversions).

The process runtime, argument and file checks and the session config are in ``process/``.
"""

from protocol.codec import PROTOCOL_VERSION, DecodeError, ProtocolError

__all__ = ["PROTOCOL_VERSION", "DecodeError", "ProtocolError"]
