"""Recordings offline: ``rhbl inspect``, retraining from recordings (``rhbl train
--from-recording``) and recording the in-process runs (``rhbl train/evaluate --record``).

    summary = client.recording.mcap_file.recording_summary("run.mcap")      # what ``rhbl inspect`` prints
    learner, stats = retrain(["run.mcap"], features="wall")       # the live learner's tree again
    with record_run("train.mcap", "rhbl train"):                  # the harness records its steps
        train(spec, learner, ...)

Retraining replays the live learner's pairing: the recorded scans and teacher labels go, in the
order the recorder received them, through ``client.roles.learner.Pairing`` (a label is paired with
exactly the scan it answers) into ``DemonstrationLearner.observe``, the learner's code path; so
with the live learner's features and settings the tree is the one it built.
"""

from __future__ import annotations

import argparse
import contextlib
import json
import logging
import time
from collections.abc import Iterator
from pathlib import Path

from client.behaviour.actions import DEFAULT_ACTIONS
from client.behaviour.features import FEATURES, FeatureError
from client.behaviour.learning import DemonstrationLearner
from client.recording.mcap_file import (
    RecordingError,
    RecordingWriter,
    read_recording,
    recording_summary,
)
from protocol import keys
from protocol.messages import DriverState, Scan, State, TeacherAction, VelCmd

__all__ = ["SimTap", "active_tap", "add_arguments", "finish_run_recording", "format_summary",
           "main", "record_run", "retrain", "start_run_recording"]

log = logging.getLogger(__name__)


# ---- rhbl inspect -------------------------------------------------------------------------
def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("recording", nargs="+", help="MCAP file(s) written by rhbl")
    parser.add_argument("--json", action="store_true", help="print the summary as JSON")


def format_summary(s: dict) -> str:
    lines = [f"{s['path']}"]
    meta = s["metadata"]
    if meta:
        lines.append(f"  recorded by {meta.get('recorder', '?')} at {meta.get('created', '?')}, "
                     f"protocol v{meta.get('protocol_version', '?')}")
    lines.append(f"  {sum(k['messages'] for k in s['keys'].values())} bus messages on "
                 f"{len(s['keys'])} keys over {s['wall_seconds']:.1f} s (receive time); "
                 f"{sum(s['viewer'].values())} viewer messages on {len(s['viewer'])} topics")
    for robot, r in sorted(s["robots"].items()):
        span = (f"sim time {r['sim_start']:.1f} .. {r['sim_end']:.1f} s"
                if r["sim_start"] is not None else "no sim time")
        lines.append(f"  robot {robot}: {r['scans']} scans, {span}")
        lab = s["labels"].get(robot)
        if lab:
            lines.append(f"    teacher labels: {sum(lab.values())} ("
                         + ", ".join(f"{a} {n}" for a, n in sorted(lab.items())) + ")")
    lines.append("  keys:")
    width = max((len(k) for k in s["keys"]), default=10)
    for key, k in sorted(s["keys"].items()):
        lines.append(f"    {key:<{width}}  {k['messages']:>7}  {k['schema']}")
    gaps = s["gaps"]
    if gaps:
        lost = sum(g["missing"] for g in gaps)
        lines.append(f"  gaps: {len(gaps)} ({lost} scan ids missing), first: "
                     + "; ".join(f"{g['robot']} after scan {g['after_scan']} (sim "
                                 f"{g['sim_time']} s): {g['missing']}" for g in gaps[:5]))
    else:
        lines.append("  gaps: none (scan ids consecutive)")
    lines += [f"  note: {n}" for n in s["notes"]]
    return "\n".join(lines)


def main(args) -> int:
    out = []
    for path in args.recording:
        try:
            s = recording_summary(path)
        except RecordingError as exc:
            raise ValueError(str(exc)) from None  # the CLI prints it as one line, exit 2
        out.append(s)
        if not args.json:
            print(format_summary(s))
    if args.json:
        print(json.dumps(out if len(out) > 1 else out[0], indent=1, default=str))
    return 0


# ---- retraining ---------------------------------------------------------------------------
class _Clock:
    def __init__(self):
        self.now = 0.0

    def __call__(self) -> float:
        return self.now


def labeled_scans(path: str | Path, robots: list[str] | None = None,
                  match_timeout: float = 2.0, scan_buffer: int = 512,
                  stats: dict | None = None) -> Iterator[tuple[str, Scan, TeacherAction]]:
    """(robot, scan, label) in the order the live learner paired them: the recording's scans
    and labels through ``client.roles.learner.Pairing`` (one per robot), clocked by receive time."""
    from client.roles.learner import Pairing  # (imports zenoh: only when retraining)

    pairings: dict[str, tuple[Pairing, _Clock]] = {}
    for m in read_recording(path):
        if m.kind not in ("scan", "label") or (robots and m.robot not in robots):
            continue
        p = pairings.get(m.robot)
        if p is None:
            clock = _Clock()
            p = pairings[m.robot] = (Pairing(scan_buffer, match_timeout, clock=clock), clock)
        pairing, clock = p
        clock.now = m.log_time / 1e9
        if m.kind == "scan":
            pairing.on_scan(m.data)
        else:
            pairing.on_label(m.data)
        pairing.expire()
        while (item := pairing.get(0.0)) is not None:
            yield (m.robot, *item)
    for robot, (pairing, _clock) in pairings.items():
        pairing.close()
        if stats is not None:
            for k, v in pairing.stats.items():
                stats[f"{robot}.{k}"] = v


def retrain(paths, features: str = "wall", robots: list[str] | None = None,
            task: str | None = None, stride: int = 1, min_delta: float = 0.0,
            tree_params: dict | None = None) -> tuple[DemonstrationLearner, dict]:
    """A tree learned from the recordings' teacher labels (in order, files in the order
    given), as ``rhbl learner`` learns: labels that are no action of the tree and scans the
    features cannot use are skipped and counted. Returns (learner, stats)."""
    from client.roles.learner import TASK_OF_FEATURES

    spec = FEATURES[features]
    params = {"spawn": "winner", **(tree_params or {})}
    learner = DemonstrationLearner(spec, DEFAULT_ACTIONS,
                                   task=task or TASK_OF_FEATURES.get(features),
                                   stride=stride, min_delta=min_delta, **params)
    stats = {"paired": 0, "learned": 0, "rejected": 0, "recordings": []}
    t0 = time.perf_counter()
    for path in paths:
        pstats: dict = {}
        n0 = stats["paired"]
        for _robot, scan, act in labeled_scans(path, robots, stats=pstats):
            if act.action not in learner.actions:
                stats["rejected"] += 1
                continue
            try:
                if learner.observe(scan.ranges, float(scan.pose[2]), act.action):
                    stats["learned"] += 1
            except FeatureError as exc:
                stats["rejected"] += 1
                log.warning("%s: label %r for scan %d skipped: %s", path, act.action, scan.id, exc)
                continue
            stats["paired"] += 1
        unmatched = sum(v for k, v in pstats.items() if k.endswith(".unmatched"))
        stats["recordings"].append({"path": str(Path(path).resolve()),
                                    "labeled": stats["paired"] - n0, "unmatched": unmatched})
    stats["seconds"] = time.perf_counter() - t0
    learner.session = {"recordings": stats["recordings"], "vectors": stats["learned"]}
    return learner, stats


def save_retrained(learner: DemonstrationLearner, stats: dict, out: str | Path) -> Path:
    """Write the snapshot; its provenance names the recordings."""
    meta = learner.metadata()
    meta["provenance"]["recordings"] = [r["path"] for r in stats["recordings"]]
    meta["provenance"]["labeled"] = stats["paired"]
    out = Path(out)
    out.parent.mkdir(parents=True, exist_ok=True)
    learner.classifier.save(str(out), metadata=meta)
    return out


def train_main(args) -> int:
    """``rhbl train --from-recording FILE [FILE ...]``: the harness's CLI hands over here."""
    tree = {k: v for k, v in (("spawn", args.spawn), ("distance", args.distance),
                              ("min_radius", args.min_radius), ("max_nodes", args.max_nodes))
            if v is not None}
    try:
        learner, stats = retrain(args.from_recording, features=args.features or "wall",
                                 stride=args.stride or 1, tree_params=tree)
    except RecordingError as exc:
        raise ValueError(str(exc)) from None
    if stats["paired"] == 0:
        raise ValueError(f"no teacher labels paired with scans in {', '.join(args.from_recording)}: "
                         f"nothing to learn")
    out = save_retrained(learner, stats, args.out)
    print(f"trained from {len(stats['recordings'])} recording(s): {stats['paired']} labeled scans "
          f"({stats['learned']} learned, {stats['rejected']} rejected, "
          f"{sum(r['unmatched'] for r in stats['recordings'])} labels without their scan), tree "
          f"{learner.nodes} nodes, height {learner.height}; {stats['seconds']:.1f} s")
    print(f"wrote {out}")
    return 0


# ---- recording the in-process runs --------------------------------------------------------
_ACTIVE: list[SimTap] = []


def active_tap() -> SimTap | None:
    """The recording of the in-process run in progress (``record_run``), or None."""
    return _ACTIVE[-1] if _ACTIVE else None


class SimTap:
    """Writes what an in-process run would have published on the bus, step by step: the
    same message types (``protocol.messages``), encoded the same way, on the same keys (robot
    ``r0``): State, Scan, the driving command on ``cmd/vel/<source>``, the teacher's label,
    the driver on change, and the world (``get_world``'s WorldInfo) whenever it changes. Log
    time = the run's start (wall clock) + its own sim clock, which keeps running across
    episodes (a teleport is a jump of the pose)."""

    def __init__(self, writer: RecordingWriter, robot: str = "r0", dt: float = 0.1):
        self.writer = writer
        self.robot = robot
        self.dt = dt
        self.t0_ns = time.time_ns()
        self.sim = 0.0
        self.scan_id = 0
        self.spec = None
        self.driver = None
        self._keys = {"state": keys.state_key(robot), "scan": keys.scan_key(robot),
                      "label": keys.teacher_action_key(robot),
                      "driver": keys.driver_key(robot),
                      "world": keys.sim_request_key(robot, "get_world")}

    def _ns(self) -> int:
        return self.t0_ns + int(round(self.sim * 1e9))

    def _put(self, key: str, data: bytes, kind: str) -> None:
        self.writer.write(key, data, self._ns(), kind, self.robot)

    def step(self, world, executed: str, ranges, actions, label: str | None = None,
             source: str = "teacher") -> None:
        """Record one step before ``world.step``: the scan the decision was made on, the
        state, the label (if the teacher gave one) and the command that drives the step."""
        from server.node import world_info

        if world.spec is not self.spec:
            self.spec = world.spec
            self._put(self._keys["world"], world_info(world.spec).encode(), "world")
        self.scan_id += 1
        odom = tuple(float(v) for v in world.odom(0))
        truth = tuple(float(v) for v in world.pose(0))
        vel = tuple(float(v) for v in world.velocity(0))
        if source != self.driver:
            self.driver = source
            self._put(self._keys["driver"], DriverState(source=source, ts=self.sim,
                                                        priority=2 if source == "teacher"
                                                        else 1).encode(), "driver")
        self._put(self._keys["state"], State(ts=self.sim, seq=self.scan_id, pos=odom, vel=vel,
                                             stall=bool(world.stall(0)), driver=source,
                                             truth=truth).encode(), "state")
        self._put(self._keys["scan"], Scan(ts=self.sim, id=self.scan_id, ranges=ranges,
                                           pose=odom, truth=truth).encode(), "scan")
        if label is not None:
            self._put(self._keys["label"], TeacherAction(scan_id=self.scan_id, action=label,
                                                         ts=self.sim,
                                                         executed=executed).encode(), "label")
        vx, va = actions[executed]
        self._put(keys.cmd_vel_key(self.robot, source=source),
                  VelCmd(vx=vx, va=va, source=source, scan_id=self.scan_id,
                         ts=self.sim).encode(), "cmd")
        self.sim = round(self.sim + self.dt, 9)


def start_run_recording(path: str | Path | None, recorder: str, overwrite: bool = True,
                        dt: float = 0.1) -> SimTap | None:
    """Start recording the in-process run (``None``: record nothing); every harness step is
    written until ``finish_run_recording``."""
    if path is None:
        return None
    try:
        writer = RecordingWriter(path, overwrite=overwrite, recorder=recorder)
    except RecordingError as exc:
        raise ValueError(str(exc)) from None
    tap = SimTap(writer, dt=dt)
    _ACTIVE.append(tap)
    return tap


def finish_run_recording(tap: SimTap | None) -> None:
    """Finish the file of ``start_run_recording`` (a run that raised instead leaves it readable
    up to its last chunk)."""
    if tap is None:
        return
    if tap in _ACTIVE:
        _ACTIVE.remove(tap)
    try:
        tap.writer.close()
    except RecordingError as exc:
        raise ValueError(str(exc)) from None
    log.info("recorded %d messages (%d steps) in %s", tap.writer.messages, tap.scan_id,
             tap.writer.path)


@contextlib.contextmanager
def record_run(path: str | Path | None, recorder: str, overwrite: bool = True, dt: float = 0.1):
    """``with record_run(path, "..."): train(...)``: start/finish_run_recording as a block."""
    tap = start_run_recording(path, recorder, overwrite, dt)
    try:
        yield tap
    finally:
        finish_run_recording(tap)
