"""The wire contract between the simulator server and its clients (docs/protocol.md).

- :mod:`protocol.keys`: key expressions (``rhbl/<robot>/position2d/0/data/state``, ...).
- :mod:`protocol.messages`: message dataclasses with ``encode()`` / ``decode()``.
- :mod:`protocol.codec`: the msgpack codec and field validators behind the messages.
- :mod:`protocol.session`: the one helper that builds zenoh session configs.
"""

from protocol.codec import PROTOCOL_VERSION, DecodeError, ProtocolError

__all__ = ["PROTOCOL_VERSION", "DecodeError", "ProtocolError"]
