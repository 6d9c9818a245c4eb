"""Container health check of the rhbl image: ``python healthcheck.py [PID]``.

Healthy (exit 0) when the rhbl process (PID 1 in the container, or PID) is running and its
liveliness token ``rhbl/alive/<role>/*`` is visible through zenoh. The check reads the process's
own command line, so it uses the same endpoints and ``--zenoh-config`` (credentials) as the
process, always as a zenoh *client* that listens on nothing. Commands without a zenoh session
(``--help``, ``train``, ...) are healthy while they run.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

ROLES = ("server", "teacher", "learner", "controller", "console")
TIMEOUT = 3.0


def _argv(pid: int) -> list[str]:
    raw = Path(f"/proc/{pid}/cmdline").read_bytes()
    # NUL-terminated arguments; an empty one (`--token ""`) is an argument too
    return [a.decode() for a in raw.removesuffix(b"\0").split(b"\0")] if raw else []


def _state(pid: int) -> str:
    stat = Path(f"/proc/{pid}/stat").read_text()
    return stat.rsplit(")", 1)[1].split()[0]


def _role_and_args(argv: list[str]) -> tuple[str | None, list[str]]:
    for i, arg in enumerate(argv):
        if arg in ROLES:
            return arg, argv[i + 1 :]
    return None, []


def check(pid: int = 1) -> tuple[bool, str]:
    try:
        argv = _argv(pid)
        state = _state(pid)
    except OSError as exc:
        return False, f"process {pid} is gone ({exc})"
    if state in ("Z", "X"):
        return False, f"process {pid} is a zombie"
    role, rest = _role_and_args(argv)
    if role is None:
        return True, f"process {pid} runs ({' '.join(argv[:3])})"

    import zenoh

    from lab.cli import build_parser
    from process.session import config_from_args
    from protocol import keys

    args = build_parser(role).parse_args(rest)
    connect = [e for v in args.connect or [] for e in v.split(",") if e]
    if not connect:  # a process that only listens (the local server): connect to it
        listen = [e for v in args.listen or [] for e in v.split(",") if e]
        connect = [e.replace("0.0.0.0", "127.0.0.1") for e in listen] or None
    args.mode, args.listen, args.connect = "client", None, connect
    config = config_from_args(args)
    config.insert_json5("listen/endpoints", "[]")
    zenoh.init_log_from_env_or("off")
    with zenoh.open(config) as session:
        key = keys.alive_key(role, "**")
        tokens = [
            str(r.ok.key_expr) for r in session.liveliness().get(key, timeout=TIMEOUT) if r.ok
        ]
    if not tokens:
        return False, f"{role}: no liveliness token on {key}"
    return True, f"{role}: alive ({', '.join(sorted(tokens))})"


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    pid = int(argv[0]) if argv else 1
    try:
        ok, why = check(pid)
    except Exception as exc:  # a refused session, a bad config: unhealthy, say why
        ok, why = False, f"health check failed: {exc}"
    print(json.dumps({"healthy": ok, "detail": why}))
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
