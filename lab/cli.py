"""The ``rhbl`` console script: one argparse front end that dispatches to subcommands.

Each subcommand lives in its own module, which defines ``add_arguments(parser)`` and
``main(args) -> int``. Modules are imported only when their command runs, so ``rhbl --help``
stays fast and a heavy import (zenoh, pymunk, matplotlib) is paid only by the command using it.

Options take their ``type=`` from ``process.arguments`` (checked numbers, paths, names,
endpoints): a bad value is refused while parsing, before ``main`` runs, as one line naming the
option (no usage block) and exit 2; so is a bad value found by ``main`` before it starts
(a ``ValueError`` or ``OSError``).
"""

from __future__ import annotations

import argparse
import importlib
import os
import re
import sys

__all__ = ["COMMANDS", "Parser", "build_parser", "main", "parse"]

# name -> (module, one-line help). Order is the order shown by ``rhbl --help``.
COMMANDS: dict[str, tuple[str, str]] = {
    "demo": ("lab.demo", "run the whole loop as separate processes: teach, learn, drive, report"),
    "server": ("server.command", "run the simulator server (Player-like position2d + laser over zenoh)"),
    "teacher": ("client.roles.teacher", "demonstrate: a scripted expert or keyboard teleop drives the robot"),
    "learner": ("client.roles.learner", "learn a hypersphere tree from the teacher's demonstrations"),
    "controller": ("client.roles.controller", "drive the robot with a learned tree"),
    "console": ("client.roles.console", "a web page to watch, teach and correct the robot from a browser"),
    "behaviours": ("lab.behaviours", "list the behaviours a robot can be taught (or show one in full)"),
    "train": ("lab.train", "in-process: a scripted teacher demonstrates on a world, write a tree"),
    "evaluate": ("lab.evaluate", "in simulation: run a tree (and the behaviour's scripted expert) from a world's start poses, judged by its success rule"),
    "compact": ("lab.compact", "make an existing tree smaller, keeping its behaviour on its data"),
    "refine": ("lab.refine", "improve a taught tree by practice in simulation, judged by its behaviour's success rule"),
    "generate": ("lab.generated", "draw random world files (rooms, mazes, clutter, beacons, corridors, dead ends, doorways) to teach, practise or test on"),
    "experiment": ("lab.experiment", "repeat train-then-evaluate over seeds; the paper's Table I"),
    "record": ("client.recording.record", "record every message of the robots' keys into an MCAP file"),
    "replay": ("client.recording.replay", "republish a recording's sensor stream on zenoh with its timing"),
    "inspect": ("client.recording.inspect", "print what an MCAP recording holds"),
    "foxglove": ("client.recording.bridge", "serve the live bus to Foxglove/Lichtblick (WebSocket)"),
    "ros2": ("client.ros2.bridge", "an rhbl robot on ROS 2 (rmw_zenoh): scan, odom, tf, clock out; cmd_vel in"),
    "example": ("lab.example", "a small end-to-end example of the learner on synthetic data"),
}


class Parser(argparse.ArgumentParser):
    """argparse's parser, whose usage errors are one line: ``rhbl CMD: error: argument --x:
    <why> (rhbl CMD --help lists the options)`` and exit 2, without the usage block (which
    runs to many lines for a command with many options)."""

    def error(self, message: str):
        message = " ".join(message.split())
        said = re.match(r"^argument ([^:]+): (must .*)$", message)  # --x must be ...
        if said:
            message = f"{said[1]} {said[2]}"
        self.exit(2, f"{self.prog}: error: {message} ({self.prog} --help lists the options)\n")


def _top_parser() -> argparse.ArgumentParser:
    width = max(len(n) for n in COMMANDS)
    lines = "\n".join(f"  {n:<{width}}  {h}" for n, (_, h) in COMMANDS.items())
    parser = Parser(
        prog="rhbl",
        description="Recursive, Hyperspherical Behavioral Learning for a Player-style robot over zenoh.",
        epilog=f"commands:\n{lines}\n\nRun 'rhbl COMMAND --help' for a command's options.",
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    parser.add_argument("command", choices=list(COMMANDS), metavar="COMMAND", help="see below")
    parser.add_argument("args", nargs=argparse.REMAINDER, help=argparse.SUPPRESS)
    return parser


def build_parser(command: str) -> argparse.ArgumentParser:
    """The argparse parser of one subcommand (used by ``main`` and by tests)."""
    module_name, help_text = COMMANDS[command]
    module = importlib.import_module(module_name)
    parser = Parser(prog=f"rhbl {command}", description=help_text)
    module.add_arguments(parser)
    parser.set_defaults(_main=module.main)
    return parser


def _stdout_closed() -> bool:
    """Whether stdout is a pipe whose reader has gone (poll reports an error on it)."""
    import select

    try:
        fd = sys.stdout.fileno()
        poller = select.poll()
        poller.register(fd, select.POLLOUT)
        return any(ev & (select.POLLERR | select.POLLHUP) for _fd, ev in poller.poll(0))
    except (OSError, ValueError, AttributeError):
        return False


def parse(argv: list[str]) -> tuple[str, argparse.Namespace]:
    """``(command, its parsed arguments)`` of ``rhbl ARGV...``; SystemExit(2) after one line
    on stderr for a usage error (what ``main`` does first)."""
    top = _top_parser().parse_args(argv[:1] if argv and not argv[0].startswith("-") else argv)
    parser = build_parser(top.command)
    args = parser.parse_args(argv[1:])
    args._outputs, args._inputs = ([(a.option_strings[-1] if a.option_strings else a.dest, v)
                                    for a in parser._actions if getattr(a.type, "kind", "") == kind
                                    for v in _values(getattr(args, a.dest, None))]
                                   for kind in ("output", "input"))
    return top.command, args


def _values(value) -> list[str]:
    if value is None or value == "":
        return []
    return [v for v in value if v] if isinstance(value, list) else [value]


def prepare_outputs(args: argparse.Namespace) -> None:
    """Make the folders of the output files given (``process.files``; FileRuleError, a
    ValueError, when one cannot be made: /proc/nope passes the parse-time check as root);
    ValueError when an output is the very file an input option names (``--tree t --out t``)."""
    from process import files

    for option, path in getattr(args, "_outputs", []):
        for given, read in getattr(args, "_inputs", []):  # never written over what it reads
            if os.path.exists(path) and os.path.exists(read) and os.path.samefile(path, read):
                raise ValueError(f"{option} {path}: is the file {given} reads; give another "
                                 f"file (rhbl writes nothing over its own input)")
        files.check_output(path, option, make=True)


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else list(argv)
    command, args = parse(argv)
    top = argparse.Namespace(command=command)
    try:
        prepare_outputs(args)  # the output files' folders made: a failure is exit 2, no work
        rc = int(args._main(args) or 0)
        sys.stdout.flush()  # a pipe is block-buffered: a closed reader shows here, not at exit
        return rc
    except KeyboardInterrupt:
        return 130
    except BrokenPipeError as exc:
        if not _stdout_closed():  # another pipe (a child's, a socket): a real error
            print(f"rhbl {top.command}: error: {exc}", file=sys.stderr)
            return 2
        # the reader of stdout went away (`rhbl ... | head`): no error line, the usual status
        # of a process ended by SIGPIPE; stdout goes to /dev/null so the exit flush is quiet
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())
        return 141
    except (OSError, ValueError) as exc:
        # bad input (a missing or corrupt world, snapshot or journal, a wrong value): one clear
        # line naming what was wrong, exit code 2 like argparse; RHBL_DEBUG=1 shows the traceback
        if os.environ.get("RHBL_DEBUG"):
            raise
        print(f"rhbl {top.command}: error: {' '.join(str(exc).split())}", file=sys.stderr)
        return 2


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
