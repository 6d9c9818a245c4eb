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
import re
from collections.abc import Sequence
from pathlib import Path

import zenoh

from process import arguments, files

__all__ = [
    "DEFAULT_ENDPOINT",
    "DEFAULT_LEASE_MS",
    "MODES",
    "add_zenoh_arguments",
    "config_from_args",
    "load_config_file",
    "make_config",
    "zenoh_config_file",
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
    conf = load_config_file(config_file) if config_file is not None else zenoh.Config()
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


def _said(exc: Exception) -> str:
    """zenoh's message about a config file in one line: its reason and where (line:column),
    without the excerpt it draws and the Rust source location it ends with."""
    text = str(exc)
    lines = [ln.strip() for ln in text.splitlines() if ln.strip()]
    where = next((ln[3:].strip() for ln in lines if ln.startswith("-->")), None)
    reason = next((ln[1:].strip() for ln in lines if ln.startswith("=")), lines[0] if lines else
                  type(exc).__name__)
    reason = re.sub(r" at /\S+\.rs:\d+\.?$", "", reason)
    return f"{reason} (at line:column {where})" if where else reason


def load_config_file(path: str | Path) -> zenoh.Config:
    """A zenoh json5 config file, checked: a regular file zenoh can parse, whose endpoints are
    well-formed (ValueError, one line naming the file)."""
    p = files.check_input(path, "zenoh config")
    try:
        conf = zenoh.Config.from_file(str(p))
    except Exception as exc:  # noqa: BLE001 - zenoh.ZError: a syntax or schema error
        raise ValueError(f"zenoh config {p}: {_said(exc)}") from None
    for key in ("listen/endpoints", "connect/endpoints"):
        try:
            value = json.loads(conf.get_json(key))
        except Exception:  # noqa: BLE001 - not set
            continue
        values = [v for vs in value.values() for v in (vs if isinstance(vs, list) else [vs])] \
            if isinstance(value, dict) else value if isinstance(value, list) else [value]
        for ep in values:
            try:
                arguments.endpoint(str(ep))
            except argparse.ArgumentTypeError as exc:
                raise ValueError(f"zenoh config {p}: {key}: {exc}") from None
    return conf


def _check_config_file(text: str) -> str:
    if arguments.files_checked():
        load_config_file(text)
    elif not text:
        raise ValueError("an empty path")
    return text


zenoh_config_file = arguments.Checked("zenoh config file", _check_config_file)
zenoh_config_file.kind = "input"


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
        type=arguments.endpoint,
        metavar="ENDPOINT",
        help=f"endpoint to connect to (repeatable, or a comma list; default: {connect_default}; "
        "a --zenoh-config file's endpoints replace the default)",
    )
    g.add_argument(
        "--listen",
        "-l",
        action="append",
        default=None,
        type=arguments.endpoint,
        metavar="ENDPOINT",
        help="endpoint to listen on (repeatable; default: "
        f"{', '.join(default_listen) if default_listen else 'none'})",
    )
    g.add_argument(
        "--zenoh-config",
        default=None,
        type=zenoh_config_file,
        metavar="FILE",
        help="a zenoh json5 config file, loaded first (flags override it)",
    )
    g.add_argument(
        "--multicast-scouting",
        action="store_true",
        help="enable multicast scouting (off by default)",
    )
    g.add_argument("--namespace", default=None, type=arguments.key_path,
                   help="zenoh namespace prefixed to every key (chunks separated by '/')")
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
