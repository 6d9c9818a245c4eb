"""A learned tree driving a ROS 2 robot through ``rhbl controller --ros2``, against the same tree
driving natively: same world, same starts, same sim seconds, ``rhbl evaluate``'s success rule.

The tree is the world's recipe (``rhbl train``), trained in-process. Natively it drives the
simulator's robot with its 360-beam 180-degree laser (``lab.evaluate.evaluate``, in-process).
Through ROS 2, this process is a zenoh router and a ROS 2-style robot (tests/integration/
ros2_robot.py: rosbags messages on rmw_zenoh's keys, the simulator's world and physics, a laser
of ``--beams`` over ``--fov`` degrees, 10 m); a real ``rhbl controller --ros2 --tree`` process
reads its LaserScan and Odometry, resamples the laser to the tree's beams and answers each scan
with a Twist on ``cmd_vel``, in lock step (one scan, one Twist, one 0.1 s step). Prints, per
start, both successes and the metrics the rule reads.

    python benchmarks/bench_ros2_drive.py [--world room] [--beams 640] [--fov 240]
"""

from __future__ import annotations

import argparse
import json
import signal
import sys
import tempfile
import time
from pathlib import Path

import zenoh

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "tests" / "integration"))  # the ROS 2-style robot

from ros2_robot import OtherLaser, Ros2StyleRobot  # noqa: E402

from client.behaviour.learning import TreePolicy  # noqa: E402
from lab.behaviours import behaviour_for_world  # noqa: E402
from lab.children import Child, free_port, rhbl_argv  # noqa: E402
from lab.evaluate import evaluate, success  # noqa: E402
from lab.harness import make_learner, resolve_world  # noqa: E402
from lab.recipe import RECIPES  # noqa: E402
from lab.train import train  # noqa: E402
from process.session import make_config  # noqa: E402


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--world", default="room", help="a world with a wall-following or maze "
                    "recipe (default: room)")
    ap.add_argument("--beams", type=int, default=640, help="the ROS 2 robot's beams (640)")
    ap.add_argument("--fov", type=float, default=240.0, help="its field of view, degrees (240)")
    ap.add_argument("--seed", type=int, default=0, help="training seed (0)")
    args = ap.parse_args()
    if args.beams < 2 or not 0 < args.fov <= 360:
        ap.error(f"--beams must be >= 2 and --fov in (0, 360], got {args.beams}, {args.fov:g}")

    spec = resolve_world(args.world)
    tmp = Path(tempfile.mkdtemp(prefix="rhbl-bench-ros2-"))
    tree = tmp / "tree.rhbl"
    t0 = time.monotonic()
    task = behaviour_for_world(spec).name  # the shipped behaviour that names the world
    learner = make_learner(RECIPES[task])
    train(spec, learner, RECIPES[task], seed=args.seed)
    learner.save(tree)
    policy = TreePolicy.load(tree)
    native = evaluate(spec, policy)
    print(f"{spec.name}: tree of {native['tree']['nodes']} nodes (recipe {task}, seed "
          f"{args.seed}), trained and evaluated natively in {time.monotonic() - t0:.0f} s",
          flush=True)
    steps = int(round(native["seconds"] / 0.1))
    laser = OtherLaser(spec, count=args.beams, fov_deg=args.fov)
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    stats = tmp / "controller.json"
    ros2 = []
    with zenoh.open(make_config(mode="router", listen=[endpoint])) as session:
        ctl = Child("controller", rhbl_argv("controller", "--ros2", "--tree", str(tree),
                                            "--connect", endpoint, "--wait-server", "120",
                                            "--log-level", "WARNING", "--stats", str(stats)),
                    cwd=ROOT, stop_signal=signal.SIGINT, escalate=False).start()
        try:
            for k, start in enumerate(spec.start_poses):
                robot = Ros2StyleRobot(session, spec, start, policy.actions, laser=laser, seed=k)
                try:
                    ep = robot.run(steps)
                except AssertionError as exc:  # no Twist answered: say what the controller said
                    raise SystemExit(f"bench_ros2_drive: start {k}: {exc}\n{ctl.output()}") from exc
                finally:
                    robot.close()
                m = ep.metrics(spec.goal)
                m["success"] = success(task, m, native["teacher"][k])
                m["other"] = ep.actions.count("other")  # Twists that are none of the tree's
                m["resent"] = robot.resent  # scans sent again: no Twist within 1-2 s
                ros2.append(m)
        finally:
            ctl.stop()
    counters = json.loads(stats.read_text()) if stats.exists() else {}
    _report(spec, task, native, ros2, steps, args, counters)
    return 0


def _cell(m: dict, task: str) -> str:
    ok = "yes" if m["success"] else "no"
    if task == "maze":
        return f"{ok} (goal {m['goal_reached']}, collisions {m['collisions']})"
    return (f"{ok} (band {m['wall_band_fraction']:.2f}, {m['distance']:.1f} m, "
            f"collisions {m['collisions']})")


def _report(spec, task: str, native: dict, ros2: list[dict], steps: int, args, counters: dict) -> None:
    print(f"{len(ros2)} starts, {steps * 0.1:g} sim s each; ROS 2 robot: {args.beams} beams over "
          f"{args.fov:g} deg, 10 m; controller commands {counters.get('commands', '?')}, "
          f"dropped {counters.get('dropped', '?')}")
    print("| start | teacher | tree natively (360 beams, 180 deg) | tree through --ros2 |")
    print("|---|---|---|---|")
    for k, start in enumerate(spec.start_poses):
        pose = ", ".join(f"{v:g}" for v in start)
        print(f"| ({pose}) | {_cell(native['teacher'][k], task)} | "
              f"{_cell(native['learner'][k], task)} | {_cell(ros2[k], task)} |")
    n_ok, r_ok = sum(native["success"]), sum(m["success"] for m in ros2)
    print(f"success: natively {n_ok}/{len(ros2)}, through --ros2 {r_ok}/{len(ros2)}; "
          f"Twists that were none of the tree's actions: {sum(m['other'] for m in ros2)}; "
          f"scans sent again (no Twist within 1-2 s): {sum(m['resent'] for m in ros2)}")


if __name__ == "__main__":
    sys.exit(main())
