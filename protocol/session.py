"""The one helper that builds zenoh session configs (why they look so: docs/architecture.md).

Hermetic by default: multicast scouting off, explicit endpoints, a short link lease so a dead
peer is noticed within about two seconds. Processes connect as clients to the server, which
listens on ``tcp/127.0.0.1:7447`` in ``router`` mode (a router relays between its clients; a
peer would not)::

    parser = argparse.ArgumentParser()
    add_zenoh_arguments(parser)                 # --mode --connect --listen --zenoh-config ...
    args = parser.parse_args()
    with zenoh.open(config_from_args(args)) as session:
        ...
"""

from __future__ import annotations

import argparse
import json
from collections.abc import Sequence
from pathlib import Path

import zenoh

__all__ = [
    "DEFAULT_ENDPOINT",
    "DEFAULT_LEASE_MS",
    "MODES",
    "add_zenoh_arguments",
    "config_from_args",
    "make_config",
]

DEFAULT_ENDPOINT = "tcp/127.0.0.1:7447"
DEFAULT_LEASE_MS = 2000
MODES = ("client", "peer", "router")


def make_config(
    mode: str = "client",
    listen: Sequence[str] | None = None,
    connect: Sequence[str] | None = None,
    config_file: str | Path | None = None,
    multicast: bool = False,
    namespace: str | None = None,
    lease_ms: int | None = DEFAULT_LEASE_MS,
) -> zenoh.Config:
    """Build a zenoh config.

    ``config_file`` (a zenoh json5 config) is loaded first; the other arguments override it
    where given: ``mode``, ``listen``/``connect`` endpoint lists (an empty list leaves the
    file's or zenoh's default), multicast scouting (off unless ``multicast``), an optional
    ``namespace`` prefixed to every key (isolates parallel runs), the link ``lease_ms``.
    """
    if mode not in MODES:
        raise ValueError(f"zenoh mode must be one of {list(MODES)}, got {mode!r}")
    if config_file is not None:
        path = Path(config_file)
        if not path.is_file():
            raise ValueError(f"zenoh config file not found: {path}")
        conf = zenoh.Config.from_file(str(path))
    else:
        conf = zenoh.Config()
    conf.insert_json5("mode", json.dumps(mode))
    if listen:
        conf.insert_json5("listen/endpoints", json.dumps(list(listen)))
    elif config_file is None and mode == "client":
        conf.insert_json5("listen/endpoints", json.dumps([]))
    if connect:
        conf.insert_json5("connect/endpoints", json.dumps(list(connect)))
    if config_file is None or not multicast:
        conf.insert_json5("scouting/multicast/enabled", json.dumps(bool(multicast)))
    if namespace:
        conf.insert_json5("namespace", json.dumps(namespace))
    if lease_ms is not None:
        conf.insert_json5("transport/link/tx/lease", json.dumps(int(lease_ms)))
    return conf


def add_zenoh_arguments(
    parser: argparse.ArgumentParser,
    default_listen: Sequence[str] | None = None,
    default_connect: Sequence[str] | None = None,
    default_mode: str = "client",
) -> None:
    """Add the common zenoh flags: ``--mode``, ``--connect``, ``--listen``, ``--zenoh-config``,
    ``--multicast-scouting``, ``--namespace``. Endpoint flags repeat and accept comma lists."""
    g = parser.add_argument_group("zenoh")
    connect_default = (", ".join(default_connect) if default_connect
                       else f"{DEFAULT_ENDPOINT} in client mode, none in the others")
    g.add_argument(
        "--mode",
        choices=MODES,
        default=default_mode,
        help=f"zenoh session mode (default: {default_mode})",
    )
    g.add_argument(
        "--connect",
        "-e",
        action="append",
        default=None,
        metavar="ENDPOINT",
        help=f"endpoint to connect to (repeatable, or a comma list; default: {connect_default}; "
        "a --zenoh-config file's endpoints replace the default)",
    )
    g.add_argument(
        "--listen",
        "-l",
        action="append",
        default=None,
        metavar="ENDPOINT",
        help="endpoint to listen on (repeatable; default: "
        f"{', '.join(default_listen) if default_listen else 'none'})",
    )
    g.add_argument(
        "--zenoh-config",
        default=None,
        metavar="FILE",
        help="a zenoh json5 config file, loaded first (flags override it)",
    )
    g.add_argument(
        "--multicast-scouting",
        action="store_true",
        help="enable multicast scouting (off by default)",
    )
    g.add_argument("--namespace", default=None, help="zenoh namespace prefixed to every key")
    parser.set_defaults(
        _zenoh_default_listen=list(default_listen or []),
        _zenoh_default_connect=list(default_connect or []),
    )


def _endpoints(values: list[str] | None) -> list[str]:
    out: list[str] = []
    for v in values or []:
        out.extend(e.strip() for e in v.split(",") if e.strip())
    return out


def config_from_args(args: argparse.Namespace) -> zenoh.Config:
    """The zenoh config of parsed ``add_zenoh_arguments`` flags. Defaults (when neither the
    flag nor a config file gives endpoints): the ``default_listen``/``default_connect`` given to
    ``add_zenoh_arguments`` (``default_listen`` not in client mode: ``rhbl server --mode client``
    must not grab the default port), and a client with no endpoint connects to
    ``DEFAULT_ENDPOINT``."""
    listen = _endpoints(getattr(args, "listen", None))
    connect = _endpoints(getattr(args, "connect", None))
    mode = getattr(args, "mode", "client")
    config_file = getattr(args, "zenoh_config", None)
    if config_file is None:
        if not listen and mode != "client":  # a client connects; it does not listen
            listen = list(getattr(args, "_zenoh_default_listen", []))
        if not connect:
            connect = list(getattr(args, "_zenoh_default_connect", []))
        if mode == "client" and not connect:
            connect = [DEFAULT_ENDPOINT]
    return make_config(
        mode=mode,
        listen=listen,
        connect=connect,
        config_file=config_file,
        multicast=bool(getattr(args, "multicast_scouting", False)),
        namespace=getattr(args, "namespace", None),
    )
