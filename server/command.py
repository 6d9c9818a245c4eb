"""``rhbl server``: serve a world over zenoh (Player-like position2d + laser per robot).

It runs through ``process.runtime.run_process``, as the client processes do: the same log lines and exit
codes (0 ok, also after SIGINT/SIGTERM once the session is closed; 2 bad world or flags; 3 a
connect endpoint unreachable, the session refused or a listen endpoint taken).
"""

from __future__ import annotations

import argparse
import logging

from process import arguments
from process.runtime import (
    EXIT_OK,
    EXIT_USAGE,
    Context,
    ProcessError,
    add_report_arguments,
    on_stop_signal,
    run_process,
    uninterrupted,
)
from process.session import DEFAULT_ENDPOINT, add_zenoh_arguments
from protocol import keys

__all__ = ["add_arguments", "main"]

log = logging.getLogger("server")


def add_arguments(parser: argparse.ArgumentParser) -> None:
    from server import world_arg

    parser.add_argument(
        "--world",
        default="room",
        type=world_arg,
        help="world file or shipped world name (default: room, the wall-following world)",
    )
    parser.add_argument(
        "--robot",
        action="append",
        default=None,
        metavar="NAME",
        type=arguments.key_chunk,
        help="robot name, repeat for several robots (default: r0, r1, ...)",
    )
    parser.add_argument("--robots", type=arguments.Number(int, 1, 1000, name="robots"),
                        default=None, help="number of robots (default: 1; at most 1000)")
    parser.add_argument("--rate", type=arguments.Number(float, 0, 1000, low_open=True,
                                                        name="rate"),
                        default=10.0, help="publishing rate in sim Hz (10; at most 1000)")
    pace = parser.add_mutually_exclusive_group()
    pace.add_argument(
        "--speedup",
        type=arguments.non_negative_float,
        default=1.0,
        help="N times real time (default 1; 0: as fast as possible)",
    )
    pace.add_argument(
        "--lockstep",
        action="store_true",
        help="start each tick only when the driving process answered the last scan",
    )
    parser.add_argument(
        "--lockstep-timeout",
        type=arguments.seconds,
        default=1.0,
        help="lock-step: real seconds to wait for an answer before stepping anyway (1.0)",
    )
    parser.add_argument(
        "--watchdog",
        type=arguments.seconds,
        default=0.5,
        help="sim seconds without commands before a source loses the robot and it stops (0.5)",
    )
    parser.add_argument("--seed", type=arguments.seed, default=0, help="random seed (noise)")
    parser.add_argument("--range-noise", type=arguments.non_negative_float, default=0.0,
                        help="laser noise sigma, m")
    parser.add_argument("--odom-noise", type=arguments.non_negative_float, default=0.0,
                        help="odometry noise factor")
    parser.add_argument(
        "--duration", type=arguments.seconds, default=None,
        help="stop after this many sim seconds"
    )
    parser.add_argument(
        "--ident",
        default=None,
        type=arguments.key_chunk,
        help="server id in its liveliness tokens rhbl/alive/server/<id>/<robot>, one per robot "
        "(default: <host>-<pid>, unique on the network)",
    )
    add_report_arguments(parser)
    add_zenoh_arguments(parser, default_listen=[DEFAULT_ENDPOINT], default_mode="router")


def main(args: argparse.Namespace) -> int:
    server = ServerProcess(args)
    return run_process("server", args, server.serve, check=server.prepare,
               early_token=False)  # the node declares rhbl/alive/server/<ident>/<robot> itself


class ServerProcess:
    """``rhbl server``: ``prepare`` checks the flags and loads the world (bad input: exit 2,
    before any network); ``serve`` runs a ``ServerNode`` on the session until SIGINT/SIGTERM
    (or ``--duration``) and reports its counters."""

    def __init__(self, args: argparse.Namespace):
        self.args = args
        self.spec = self.world = None
        self.names: list[str] = []

    def prepare(self) -> None:
        from server import world_path
        from server.world import World, WorldError, load_world

        args = self.args
        try:
            self.spec = load_world(world_path(args.world))
        except (FileNotFoundError, WorldError) as e:
            raise ProcessError(f"server: {e}", EXIT_USAGE) from e
        names = args.robot
        n = args.robots if args.robots is not None else (len(names) if names else 1)
        if names is None:
            names = [keys.robot_name(i) for i in range(n)]
        if len(names) != n:
            raise ValueError(f"--robots {n} but {len(names)} --robot names")
        for name in names:
            keys.check_chunk(name, "robot name")
        if args.ident is None:  # unique on the network: <host>-<pid>
            from server.node import default_ident

            args.ident = default_ident()
        keys.check_chunk(args.ident, "--ident")
        self.names = names
        self.world = World(self.spec, robots=n, seed=args.seed, range_noise=args.range_noise,
                           odom_noise=args.odom_noise)
        if n > len(self.spec.start_poses):
            log.warning("%d robots but world %r has %d start poses: some robots start together",
                        n, self.spec.name, len(self.spec.start_poses))

    def serve(self, ctx: Context) -> int:
        # the node's liveliness tokens say "up" as it is made: a stop signal that follows them at
        # once waits until its closing and its last report are in place
        with uninterrupted():
            node = self._node(ctx)
            ctx.report(lambda: {"ticks": node.ticks, "sim_time": round(self.world.time, 3),
                                "counters": dict(node.counters)})
            ctx.scope.callback(self._report, node)  # after the node is closed (LIFO scope)
            ctx.scope.callback(node.close)
            on_stop_signal(node.stop)
        args = self.args
        pace = ("lock-step" if args.lockstep else
                "as fast as possible" if args.speedup == 0 else f"{args.speedup:g}x real time")
        print(f"rhbl server: world {self.spec.name!r} ({self.spec.path}), robots "
              f"{', '.join(self.names)}, {args.rate:g} Hz, {pace}; listening on "
              f"{ctx.config.get_json('listen/endpoints')}", flush=True)
        node.run(duration=args.duration)
        return EXIT_OK

    def _node(self, ctx: Context):
        from server.node import ServerNode

        args = self.args
        try:
            return ServerNode(ctx.session, self.world, names=self.names, rate=args.rate,
                              speedup=0.0 if args.lockstep else args.speedup,
                              lockstep=args.lockstep, lockstep_timeout=args.lockstep_timeout,
                              watchdog=args.watchdog, ident=args.ident)
        except ValueError as e:
            raise ProcessError(f"server: {e}", EXIT_USAGE) from e

    def _report(self, node) -> None:
        log.info("stopped after %d ticks (%.1f s sim); counters %s", node.ticks,
                 self.world.time, dict(node.counters))
