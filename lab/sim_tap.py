"""Recording an in-process run (``rhbl train --record``, ``rhbl evaluate --record``): the harness
has no bus, so a ``SimTap`` writes what the run would have published, step by step, into an
MCAP recording (``client.recording.mcap_file``). The run is given the tap's ``step`` as its
``on_step`` (``lab.harness.step_world`` calls it before each step).

    with record_run("train.mcap", "rhbl train") as tap:
        train(spec, learner, recipe, on_step=tap.step)
"""

from __future__ import annotations

import contextlib
import logging
import time
from pathlib import Path

from client.recording.mcap_file import RecordingError, RecordingWriter
from protocol import keys
from protocol.messages import DriverState, Scan, State, TeacherAction, VelCmd

__all__ = ["SimTap", "finish_run_recording", "record_run", "start_run_recording"]

log = logging.getLogger(__name__)


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
    """A tap recording an in-process run into ``path`` (``None``: record nothing): pass its
    ``step`` as the run's ``on_step``; ``finish_run_recording`` finishes the file."""
    if path is None:
        return None
    try:
        writer = RecordingWriter(path, overwrite=overwrite, recorder=recorder)
    except RecordingError as exc:
        raise ValueError(str(exc)) from None
    return SimTap(writer, dt=dt)


def finish_run_recording(tap: SimTap | None) -> None:
    """Finish the file of ``start_run_recording`` (a run that raised instead leaves it readable
    up to its last chunk)."""
    if tap is None:
        return
    try:
        tap.writer.close()
    except RecordingError as exc:
        raise ValueError(str(exc)) from None
    log.info("recorded %d messages (%d steps) in %s", tap.writer.messages, tap.scan_id,
             tap.writer.path)


@contextlib.contextmanager
def record_run(path: str | Path | None, recorder: str, overwrite: bool = True, dt: float = 0.1):
    """``with record_run(path, "...") as tap: train(..., on_step=tap and tap.step)``:
    start/finish_run_recording as a block (``tap`` is None without a path)."""
    tap = start_run_recording(path, recorder, overwrite, dt)
    try:
        yield tap
    finally:
        finish_run_recording(tap)
