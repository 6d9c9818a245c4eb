"""``rhbl demo``: the whole learning-from-demonstration loop as separate OS processes on loopback.

The demo is the rendezvous (a zenoh session in router mode on a free loopback port, the role a
zenohd plays in compose); every child connects to it as a client:

It runs a behaviour (``--behaviour NAME|FILE``; ``--scenario TASK`` is the shipped behaviour of
that name; default wall following): its expert teaches (``rhbl teacher --behaviour``), its
perception is the learner's (``rhbl learner --behaviour``), its start poses are the run's and its
success rule judges the final tree (``lab.metrics.judge``). It runs the training recipe of
``rhbl train`` (``lab.behaviours.recipe_of(b).for_demo()``, docs/experiments.md) over zenoh, with one server for the whole run; the demo teleports the robot to each of the world's start poses with the
sim-only ``set_pose`` request (``rhbl/r0/sim/req/set_pose``, odometry reset too):

1. ``rhbl learner`` (the tree and its journal go into the output folder), ``rhbl server
   --lockstep`` (the scenario's world) and ``rhbl teacher``: the reactive teacher demonstrates
   from each start pose for T sim seconds (or until the goal) while the learner learns;
2. corrective rounds: ``rhbl controller --from-learner --follow`` drives with the learner's latest
   tree while ``rhbl teacher --correct`` labels every scan and takes over near walls, from each
   start pose, R times; then the teacher and the learner stop (SIGINT: final snapshot);
3. ``rhbl controller --tree <snapshot>`` drives the final tree from each start pose for D sim
   seconds (or until the goal);
4. the demo computes metrics (``lab.metrics``) over what it recorded from the server's scans,
   states and commands, draws the teacher's path beside the learned robot's (``lab.plot``), prints
   a table like the paper's Table I and writes everything into the output folder.

Children are killed by PID on every exit path; the exit status is non-zero if any child failed.
"""

from __future__ import annotations

import argparse
import logging
import signal
import sys

from client.behaviour.given import behaviour_arg
from lab.by_hand import ByHand
from lab.children import free_port
from lab.demo_run import SCENARIOS, Demo, DemoError
from lab.recipe import RECIPES, per_task
from process import arguments
from server import world_arg

__all__ = ["SCENARIOS", "add_arguments", "main", "free_port"]


def _defaults(value) -> str:
    return per_task({task: value(sc) for task, sc in SCENARIOS.items()})


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--scenario", choices=list(SCENARIOS), default=None,
                        help="a task's demo: the shipped behaviour of its name (default: "
                             "wall-following); goals: goals in order, the red beacon then the "
                             "green one (the shipped behaviour red-green, docs/goals.md); or "
                             "--behaviour")
    parser.add_argument("--behaviour", default=None, type=behaviour_arg, metavar="NAME|FILE",
                        help="demo this behaviour (a shipped behaviour's name or a behaviour "
                             "file; docs/behaviours.md): its expert teaches, its perception is "
                             "the learner's, its first teaching world and start poses are the "
                             "run's, and its success rule judges the final tree; with --by-hand "
                             "the page and the terminal tell you its instructions")
    parser.add_argument("--out", metavar="DIR", default=None, type=arguments.output_folder,
                        help="output folder (default: rhbl-out/<timestamp>-<scenario or "
                             "behaviour>)")
    parser.add_argument("--world", default=None, type=world_arg,
                        help=f"world file or name (default: the behaviour's first teaching "
                             f"world, {_defaults(lambda sc: sc.world)})")
    parser.add_argument("--teach-seconds", type=arguments.seconds, default=None, metavar="S",
                        help="sim seconds the teacher demonstrates from each start pose (or until "
                             f"the goal; default: {_defaults(lambda sc: sc.recipe.segment)})")
    parser.add_argument("--rounds", type=arguments.non_negative_int, default=None, metavar="N",
                        help="corrective rounds: the controller drives the latest tree from each "
                             "start pose while the teacher labels and takes over near walls "
                             f"(default: {_defaults(lambda sc: sc.recipe.rounds)}; the training "
                             f"recipe's: {per_task({t: r.rounds for t, r in RECIPES.items()})}; "
                             "0 = demonstrations only)")
    parser.add_argument("--round-seconds", type=arguments.seconds, default=None, metavar="S",
                        help="sim seconds per start pose in each corrective round (or until the "
                             f"goal; default: {_defaults(lambda sc: sc.recipe.round_seconds)})")
    parser.add_argument("--drive-seconds", type=arguments.seconds, default=None, metavar="S",
                        help="sim seconds the final tree drives from each start pose "
                             f"(default: {_defaults(lambda sc: sc.drive)})")
    parser.add_argument("--starts", type=arguments.positive_int, default=None, metavar="N",
                        help="use the first N start poses only (default: all)")
    parser.add_argument("--style", choices=["reactive", "smooth"], default="reactive",
                        help="the teacher's style (default: reactive, the training recipe)")
    parser.add_argument("--speedup", type=arguments.non_negative_float, default=None,
                        metavar="N",
                        help="run the server N times real time instead of lock-step (0: as fast "
                             "as possible)")
    parser.add_argument("--seed", type=arguments.seed, default=0,
                        help="seed of the teacher's perturbations")
    parser.add_argument("--timeout", type=arguments.seconds, default=600.0, metavar="SECONDS",
                        help="give up (and fail) after this much wall time (not with "
                             "--by-hand: you end it)")
    parser.add_argument("--quiet", action="store_true", help="no progress lines")
    parser.add_argument("--console", nargs="?", const="127.0.0.1:8080", default=None,
                        metavar="HOST:PORT", type=arguments.address,
                        help="also serve the teacher's console (view-only) to watch the loop "
                             "live in a browser (default address 127.0.0.1:8080; the URL is "
                             "printed); with --by-hand the console you teach with, there")
    parser.add_argument("--record", nargs="?", const="", default=None, metavar="FILE",
                        type=arguments.output_file_or_default,
                        help="record the whole run (every bus message) as MCAP into FILE "
                             "(default: OUT/run.mcap; docs/recording.md)")
    parser.add_argument("--by-hand", action="store_true",
                        help="teach it yourself instead of the scripted teacher: a server "
                             "(--world, default the behaviour's first teaching world: room, "
                             "real time), a learner (the behaviour's perception; its --teacher auto "
                             "takes the person rule), the console (at --console, default "
                             "127.0.0.1:8080; its URL printed; the behaviour's instructions "
                             "on the page and in the terminal) and, after --demonstrate, a "
                             "following controller for correct mode; then the tree is evaluated "
                             "(lab.by_hand, docs/teaching.md)")
    parser.add_argument("--demonstrate", type=arguments.seconds, default=240.0, metavar="S",
                        help="with --by-hand: wall seconds you demonstrate before the controller "
                             "starts (default 240; Enter at the terminal ends it sooner)")
    parser.add_argument("--correct", type=arguments.seconds, default=120.0, metavar="S",
                        help="with --by-hand: wall seconds you correct (default 120; Enter or "
                             "Ctrl-C ends it sooner)")





def main(args: argparse.Namespace) -> int:
    logging.basicConfig(level=logging.INFO, format="%(levelname)s %(message)s")
    try:
        if args.by_hand:
            demo = ByHand(args)
        else:
            if args.demonstrate != 240.0 or args.correct != 120.0:
                raise ValueError("--demonstrate and --correct go with --by-hand")
            demo = Demo(args)
    except (OSError, ValueError) as exc:  # WorldError, FileNotFoundError, ...
        print(f"rhbl demo FAILED: {exc}", file=sys.stderr, flush=True)
        return 2
    old = {s: signal.getsignal(s) for s in (signal.SIGINT, signal.SIGTERM)}

    def _stop(signum, _frame):
        raise SystemExit(128 + signum)

    signal.signal(signal.SIGTERM, _stop)
    rc = 1
    try:
        rc = demo.run()
    except DemoError as exc:
        print(f"rhbl demo FAILED: {exc}", file=sys.stderr, flush=True)
        rc = 1
    except (KeyboardInterrupt, SystemExit) as exc:
        print("rhbl demo interrupted", file=sys.stderr, flush=True)
        rc = exc.code if isinstance(exc, SystemExit) and isinstance(exc.code, int) else 130
    finally:
        demo.cleanup()
        for s, h in old.items():
            signal.signal(s, h)
    bad = [c for c in demo.children
           if c.rc not in (0, None) and not (c.expected_stop and c.rc in (0, -2, 130))]
    if bad and rc == 0:
        for c in bad:
            print(f"rhbl demo: {c.name} (pid {c.pid}) exited with status {c.rc}:\n{c.tail()}",
                  file=sys.stderr)
        rc = 1
    return rc
