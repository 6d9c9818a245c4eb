"""A Python zenoh session in router mode, standing in for the ``eclipse/zenoh`` router image.

The tests (and anyone without Docker) run the *shipped* router configuration
(``docker/zenoh/router.json5``) in a Python session opened in ``router`` mode, which applies
TLS, user/password authentication and access control exactly as zenohd does (the same Rust code
underneath); where the ``eclipse/zenoh`` image cannot be pulled, ``make compose-test`` runs it
in a container of its own (docker/router-standin.Dockerfile), given zenohd's own arguments
(``-c FILE --cfg KEY:VALUE``). On this machine::

    python docker/router_standin.py --config docker/zenoh/router.json5 \
        --secrets docker/secrets --listen tls/127.0.0.1:7447

Every string value of the config that starts with ``/run/secrets/`` (where compose mounts the
secrets) is rewritten to point into ``--secrets``; ``--listen`` replaces the listen endpoints
and ``--cfg KEY:VALUE`` overrides one key, as zenohd's own ``--cfg`` does.
Stops on SIGINT/SIGTERM. ``open_router(...)`` does the same in-process for tests.
"""

from __future__ import annotations

import argparse
import json
import signal
import sys
import threading
from pathlib import Path

import zenoh

__all__ = ["SECRETS_PREFIX", "load_config", "open_router", "main"]

SECRETS_PREFIX = "/run/secrets/"


def _rewrite(config: zenoh.Config, node, path: list[str], old: str, new: str) -> None:
    if isinstance(node, dict):
        for key, value in node.items():
            _rewrite(config, value, [*path, key], old, new)
    elif isinstance(node, str) and node.startswith(old):
        config.insert_json5("/".join(path), json.dumps(new + node[len(old) :]))


def load_config(
    config_file: str | Path,
    secrets_dir: str | Path | None = None,
    listen: list[str] | None = None,
    cfg: list[str] | None = None,
    prefix: str = SECRETS_PREFIX,
) -> zenoh.Config:
    """The router config from ``config_file``, secrets paths moved to ``secrets_dir``.

    ``cfg`` holds zenohd-style ``KEY:VALUE`` overrides (VALUE is JSON5), applied last, e.g.
    ``transport/link/tls/enable_mtls:true``.
    """
    config = zenoh.Config.from_file(str(config_file))
    if secrets_dir is not None:
        new = str(Path(secrets_dir).resolve()) + "/"
        _rewrite(config, json.loads(str(config)), [], prefix, new)
    if listen:
        config.insert_json5("listen/endpoints", json.dumps(list(listen)))
    for item in cfg or ():
        key, sep, value = item.partition(":")
        if not sep:
            raise ValueError(f"--cfg {item!r}: expected KEY:VALUE")
        config.insert_json5(key, value)
    return config


def open_router(config_file, secrets_dir=None, listen=None, cfg=None) -> zenoh.Session:
    """Open the stand-in router in this process (close it, or use ``with``)."""
    return zenoh.open(load_config(config_file, secrets_dir, listen, cfg))


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument(
        "-c", "--config", required=True, help="zenoh router config (json5; zenohd's -c)"
    )
    parser.add_argument("--secrets", help=f"directory replacing {SECRETS_PREFIX} in the config")
    parser.add_argument("--listen", action="append", help="listen endpoint (repeatable)")
    parser.add_argument(
        "--cfg", action="append", metavar="KEY:VALUE", help="config override, as zenohd's --cfg"
    )
    args = parser.parse_args(argv)

    stop = threading.Event()
    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, lambda *_: stop.set())
    try:
        config = load_config(args.config, args.secrets, args.listen, args.cfg)
        session = zenoh.open(config)
    except Exception as exc:  # a bad config or a busy port: say which, exit non-zero
        print(f"router_standin: cannot start router: {exc}", file=sys.stderr, flush=True)
        return 1
    with session:
        endpoints = json.loads(config.get_json("listen/endpoints"))
        print(f"router_standin: router {session.zid()} listening on {endpoints}", flush=True)
        while not stop.wait(0.2):
            pass
    return 0


if __name__ == "__main__":
    sys.exit(main())
