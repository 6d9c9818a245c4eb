"""A learner whose journal writes fail as on a full disk (ENOSPC) while a flag file exists: the
fault campaign's ``disk-full`` part and the learner robustness test run it.

    FULL_FLAG=/tmp/full python -m campaigns.full_disk learner --features wall --out t.rhbl ...

It is ``rhbl learner`` (the same arguments, after the command name) given a failing writer
through the journal's seam (``client.roles.learner.main(args, journal_write=...)``,
``client.journal.Journal``'s ``write``); nothing in the product is patched.
"""

from __future__ import annotations

import errno
import os
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
if str(ROOT) not in sys.path:  # `python campaigns/full_disk.py`: the campaigns are not installed
    sys.path.insert(0, str(ROOT))

__all__ = ["ARGV", "failing_write", "main"]

# the command line prefix that runs it (then "learner", then the learner's arguments)
ARGV = [sys.executable, "-m", "campaigns.full_disk"]


def failing_write(flag: str | os.PathLike):
    """``os.write``, except that it fails with ENOSPC while ``flag`` exists."""
    def write(fd: int, data) -> int:
        if os.path.exists(flag):
            raise OSError(errno.ENOSPC, "No space left on device")
        return os.write(fd, data)

    return write


def main(argv: list[str] | None = None) -> int:
    from client.roles import learner
    from lab.cli import build_parser

    argv = sys.argv[1:] if argv is None else list(argv)
    if not argv or argv[0] != "learner" or "FULL_FLAG" not in os.environ:
        print("usage: FULL_FLAG=FILE python -m campaigns.full_disk learner [ARGS...]",
              file=sys.stderr)
        return 2
    args = build_parser("learner").parse_args(argv[1:])
    return learner.main(args, journal_write=failing_write(os.environ["FULL_FLAG"]))


if __name__ == "__main__":
    sys.exit(main())
