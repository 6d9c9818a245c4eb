"""``rhbl server``: serve a world over zenoh (Player-like position2d + laser per robot)."""

from __future__ import annotations

import argparse
import logging
import signal
import sys
import threading

from protocol import keys
from protocol.session import DEFAULT_ENDPOINT, add_zenoh_arguments, config_from_args

__all__ = ["add_arguments", "main"]

log = logging.getLogger("server")


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "--world",
        default="room",
        help="world file or shipped world name (default: room, the wall-following world)",
    )
    parser.add_argument(
        "--robot",
        action="append",
        default=None,
        metavar="NAME",
        help="robot name, repeat for several robots (default: r0, r1, ...)",
    )
    parser.add_argument("--robots", type=int, default=None, help="number of robots (default: 1)")
    parser.add_argument("--rate", type=float, default=10.0, help="publishing rate in sim Hz (10)")
    pace = parser.add_mutually_exclusive_group()
    pace.add_argument(
        "--speedup",
        type=float,
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
        type=float,
        default=1.0,
        help="lock-step: real seconds to wait for an answer before stepping anyway (1.0)",
    )
    parser.add_argument(
        "--watchdog",
        type=float,
        default=0.5,
        help="sim seconds without commands before a source loses the robot and it stops (0.5)",
    )
    parser.add_argument("--seed", type=int, default=0, help="random seed (noise)")
    parser.add_argument("--range-noise", type=float, default=0.0, help="laser noise sigma, m")
    parser.add_argument("--odom-noise", type=float, default=0.0, help="odometry noise factor")
    parser.add_argument(
        "--duration", type=float, default=None, help="stop after this many sim seconds"
    )
    parser.add_argument(
        "--ident",
        default=None,
        help="server id in its liveliness tokens rhbl/alive/server/<id>/<robot>, one per robot "
        "(default: <host>-<pid>, unique on the network)",
    )
    parser.add_argument("--log-level", default="INFO", help="logging level (INFO)")
    add_zenoh_arguments(parser, default_listen=[DEFAULT_ENDPOINT], default_mode="router")


def main(args: argparse.Namespace) -> int:
    logging.basicConfig(
        level=getattr(logging, str(args.log_level).upper(), logging.INFO),
        format="%(asctime)s %(levelname)s %(name)s: %(message)s",
    )
    import zenoh

    from server import world_path
    from server.node import ServerNode
    from server.world import World, WorldError, load_world

    try:
        spec = load_world(world_path(args.world))
    except (FileNotFoundError, WorldError) as e:
        print(f"rhbl server: {e}", file=sys.stderr)
        return 2
    names = args.robot
    n = args.robots if args.robots is not None else (len(names) if names else 1)
    if names is None:
        names = [keys.robot_name(i) for i in range(n)]
    if len(names) != n:
        print(f"rhbl server: --robots {n} but {len(names)} --robot names", file=sys.stderr)
        return 2
    try:
        for name in names:
            keys.check_chunk(name, "robot name")
        world = World(
            spec,
            robots=n,
            seed=args.seed,
            range_noise=args.range_noise,
            odom_noise=args.odom_noise,
        )
        conf = config_from_args(args)
    except ValueError as e:
        print(f"rhbl server: {e}", file=sys.stderr)
        return 2
    if n > len(spec.start_poses):
        log.warning(
            "%d robots but world %r has %d start poses: some robots start together",
            n,
            spec.name,
            len(spec.start_poses),
        )

    stop = threading.Event()
    holder: dict[str, ServerNode] = {}

    def on_signal(signum, _frame):
        stop.set()
        node = holder.get("node")
        if node is not None:
            node.stop()

    signal.signal(signal.SIGINT, on_signal)
    signal.signal(signal.SIGTERM, on_signal)

    listen = conf.get_json("listen/endpoints")
    try:
        session = zenoh.open(conf)
    except Exception as e:
        print(f"rhbl server: cannot open zenoh session ({e})", file=sys.stderr)
        return 1
    with session:
        try:
            node = ServerNode(
                session,
                world,
                names=names,
                rate=args.rate,
                speedup=0.0 if args.lockstep else args.speedup,
                lockstep=args.lockstep,
                lockstep_timeout=args.lockstep_timeout,
                watchdog=args.watchdog,
                ident=args.ident,
            )
        except ValueError as e:
            print(f"rhbl server: {e}", file=sys.stderr)
            return 2
        holder["node"] = node
        pace = (
            "lock-step"
            if args.lockstep
            else ("as fast as possible" if args.speedup == 0 else f"{args.speedup:g}x real time")
        )
        print(
            f"rhbl server: world {spec.name!r} ({spec.path}), robots {', '.join(names)}, "
            f"{args.rate:g} Hz, {pace}; listening on {listen}",
            flush=True,
        )
        if stop.is_set():
            node.stop()
        try:
            node.run(duration=args.duration)
        finally:
            node.close()
            log.info(
                "stopped after %d ticks (%.1f s sim); counters %s",
                node.ticks,
                world.time,
                dict(node.counters),
            )
    return 0
