"""Structure-aware fuzzing of every key the rhbl processes listen to, and of their files.

    python -m campaigns.fuzz [--per-key 10000] [--seed 0] [--only server,clients,files]

Messages. From a valid message of each kind the generator derives hostile ones: a field of the
wrong type, a field missing, extra fields, NaN and infinities, huge and negative numbers and
sizes, wrong protocol versions, a payload truncated or oversized, not a map, random bytes. Each
candidate goes through the message's own decoder first (the oracle): only payloads it rejects are
sent, so every one of them must be rejected by the receiver and counted, and none may change the
robot. Valid traffic is interleaved (one valid message per ``--valid-every`` hostile ones) and
must still be processed.

- ``server`` (a real :class:`server.node.ServerNode` on a zenoh router on loopback, the fuzzer a
  client session): the public and a per-source command key, and every queryable (position2d
  get_geom, set_odom, reset_odom, motor_power; laser get_geom, get_config; sim set_pose,
  get_pose, get_world). Checked: the node's rejection counter rose by exactly the hostile
  commands sent, every valid command was applied, every hostile request was answered with a
  NACK, the payload-free requests answered, the robot did not move (valid commands say stand
  still) and its motors stayed on; the node still ticks.
- ``clients`` (real ``rhbl learner``, ``rhbl teacher`` and ``rhbl controller --follow``
  processes, the server at twice real time): the scan key (all three), the teacher's label key
  (learner), the learner's notice key (controller) and the learner's snapshot queryable.
  Checked: every process is alive at the end and still works (the learner journals labels, the
  teacher labels, the controller answers scans); malformed messages counted by the processes
  themselves (``--stats``: what each dropped, by kind).
- ``files``: a snapshot, a journal and a world file, each mutated the same way (bytes flipped,
  truncated, extended, random), loaded with the real loaders: each either loads or raises one
  typed error that names the file (never another exception).

The suite runs a CI-sized campaign (tests/fuzz/); the full one is this command.
"""

from __future__ import annotations

import argparse
import contextlib
import math
import os
import random
import signal
import sys
import tempfile
import time
from collections import Counter
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import msgpack

from lab.children import Child, free_port, rhbl_argv

ROOT = Path(__file__).resolve().parents[1]
if str(ROOT) not in sys.path:  # `python campaigns/fuzz.py`: the campaigns are not installed
    sys.path.insert(0, str(ROOT))

_WEIRD: list[Any] = [
    None, True, False, 0, -1, 1, 2**31, -(2**31), 2**63 - 1, -(2**63), 2**64 - 1,
    0.0, -0.0, 1e308, -1e308, 5e-324, math.nan, math.inf, -math.inf,
    "", "x", "\x00", "é" * 40, "a" * 300, "a" * 70_000, b"", b"\x00" * 7, b"\xff" * 3,
    [], [1], [1, 2], [math.nan, 0, 0], [math.inf, 0, 0], [0, 0, 0, 0], [[0, 0, 0]], {}, {"v": 1},
    [0.0] * 3000,
]


def _mutate_value(v: Any, rng: random.Random) -> Any:
    r = rng.random()
    if r < 0.6:
        return rng.choice(_WEIRD)
    if isinstance(v, list) and v:
        out = list(v)
        out[rng.randrange(len(out))] = rng.choice(_WEIRD)
        return out if rng.random() < 0.7 else out[: rng.randrange(len(out))]
    if isinstance(v, bytes):
        k = rng.choice([0, 1, 3, len(v) // 2, len(v) + 1, 4 * 70_000])
        return os.urandom(k) if rng.random() < 0.3 else v[:k] + b"\x00" * max(0, k - len(v))
    if isinstance(v, int | float) and not isinstance(v, bool):
        return rng.choice([-v, v * 1e300, -(2**40), 2**40, math.nan, -math.inf])
    return rng.choice(_WEIRD)


def mutations(valid: dict[str, Any], rng: random.Random) -> Iterator[bytes]:
    """An endless stream of payloads derived from the valid map ``valid`` (with ``v``)."""
    keys = list(valid)
    while True:
        kind = rng.randrange(10)
        m = dict(valid)
        if kind == 0:  # a field of a wrong type / weird value
            k = rng.choice(keys)
            m[k] = _mutate_value(m[k], rng)
        elif kind == 1:  # fields missing
            for k in rng.sample(keys, rng.randint(1, len(keys))):
                del m[k]
        elif kind == 2:  # extra fields with a wrong field as well
            m[f"x{rng.randrange(99)}"] = rng.choice(_WEIRD)
            k = rng.choice(keys)
            m[k] = _mutate_value(m[k], rng)
        elif kind == 3:  # wrong versions
            m["v"] = rng.choice([0, 2, -1, 99, "1", 1.0, None, [1], 2**70 if False else 2**63 - 1])
        elif kind == 4:  # several fields at once
            for k in rng.sample(keys, min(len(keys), 3)):
                m[k] = _mutate_value(m[k], rng)
        if kind <= 4:
            try:
                data = msgpack.packb(m, use_bin_type=True)
            except Exception:  # noqa: BLE001 - a value msgpack cannot encode: try another
                continue
            yield data
            continue
        good = msgpack.packb(valid, use_bin_type=True)
        if kind == 5:  # truncated
            yield good[: rng.randrange(len(good))]
        elif kind == 6:  # oversized: the valid map padded past the limits
            m["pad"] = b"\x00" * rng.choice([70_000, 1_000_000, 5_000_000])
            yield msgpack.packb(m, use_bin_type=True)
        elif kind == 7:  # not a map
            yield msgpack.packb(rng.choice([[valid.get("v"), 1], 3, "scan", None, b"x"]),
                                use_bin_type=True)
        elif kind == 8:  # bytes flipped
            b = bytearray(good)
            for _ in range(rng.randint(1, 4)):
                b[rng.randrange(len(b))] = rng.randrange(256)
            yield bytes(b)
        else:  # random bytes
            yield os.urandom(rng.choice([0, 1, 2, 5, 17, 100, 1500, 70_000]))


def hostile(valid: dict[str, Any], decode: Callable[[bytes], Any], rng: random.Random,
            ) -> Iterator[bytes]:
    """Payloads of :func:`mutations` that ``decode`` rejects (raises); the others are skipped."""
    for data in mutations(valid, rng):
        try:
            decode(data)
        except Exception:  # noqa: BLE001 - any rejection
            yield data


@dataclass
class KeyResult:
    key: str
    sent: int = 0
    rejected: int = 0
    valid_sent: int = 0
    valid_processed: int = 0
    notes: list[str] = field(default_factory=list)

    @property
    def ok(self) -> bool:
        return (self.rejected == self.sent and self.valid_processed == self.valid_sent
                and not self.notes)

    def line(self) -> str:
        status = "ok" if self.ok else "FAIL " + "; ".join(self.notes)
        return (f"| {self.key} | {self.sent} | {self.rejected} | {self.valid_sent} | "
                f"{self.valid_processed} | {status} |")


# ------------------------------------------------------------------------------------ server
@dataclass
class _Served:
    """A real ServerNode on a zenoh router (ticking in a thread) and a client session."""

    node: Any
    world: Any
    runner: Any
    cli: Any
    start_pose: tuple[float, float, float]


@contextlib.contextmanager
def _served_node() -> Iterator[_Served]:
    import threading

    import zenoh

    import server as server_pkg
    from protocol import keys
    from protocol.session import make_config
    from server.node import ServerNode
    from server.world import World, load_world

    endpoint = f"tcp/127.0.0.1:{free_port()}"
    srv_session = zenoh.open(make_config(mode="router", listen=[endpoint]))
    world = World(load_world(server_pkg.world_path("room")))
    node = ServerNode(srv_session, world, names=["r0"], rate=10.0, speedup=4.0, watchdog=0.5)
    runner = threading.Thread(target=node.run, daemon=True)
    runner.start()
    start_pose = world.pose(0)
    cli = zenoh.open(make_config(mode="client", connect=[endpoint]))
    try:
        _until(lambda: any(r.ok is not None for r in cli.get(
            keys.request_key("r0", "laser", "get_geom"), timeout=1.0)), 30,
            "the node answers the client")
        yield _Served(node, world, runner, cli, start_pose)
    finally:
        node.stop()
        runner.join(10)
        node.close()
        cli.close()
        srv_session.close()


def _command_keys() -> list[tuple[str, str | None]]:
    """(key, source): the public command key and a per-source one."""
    from protocol import keys

    return [(keys.cmd_vel_key("r0"), None), (keys.cmd_vel_key("r0", source="fuzz"), "fuzz")]


def _request_table() -> list[tuple[str, Callable[[bytes], Any] | None, dict | None]]:
    """(key, decoder, a valid payload as a map) of every queryable of the server; decoder None:
    the payload is ignored (only an oversized one is hostile)."""
    from protocol import keys
    from protocol.messages import MotorPower, SetOdom, SetPose

    table: list[tuple[str, Callable[[bytes], Any] | None, dict | None]] = [
        (keys.request_key("r0", "position2d", "set_odom"),
         lambda d: SetOdom.decode(d), msgpack.unpackb(SetOdom(pose=(1, 2, 0)).encode())),
        (keys.request_key("r0", "position2d", "motor_power"),
         lambda d: MotorPower.decode(d), msgpack.unpackb(MotorPower(state=True).encode())),
        (keys.sim_request_key("r0", "set_pose"),
         lambda d: SetPose.decode(d),
         msgpack.unpackb(SetPose(pose=(3.0, 0.7, 0.0)).encode())),
    ]
    for name in ("get_geom", "reset_odom"):
        table.append((keys.request_key("r0", "position2d", name), None, None))
    for name in ("get_geom", "get_config"):
        table.append((keys.request_key("r0", "laser", name), None, None))
    for name in ("get_pose", "get_world"):
        table.append((keys.sim_request_key("r0", name), None, None))
    return table


def _fuzz_command_key(t: _Served, key: str, source: str | None, rng: random.Random,
                      per_key: int, valid_every: int) -> KeyResult:
    """Hostile commands on ``key``, a stand-still one every ``valid_every``; the node's
    counters must rise by exactly those."""
    import zenoh

    from protocol.messages import COMMAND_MAX_PAYLOAD, VelCmd

    def decode_cmd(data: bytes) -> VelCmd:
        return VelCmd.decode(data, max_size=COMMAND_MAX_PAYLOAD)

    still = VelCmd(vx=0.0, va=0.0, source=source or "fuzz-valid").encode()
    valid_cmd = msgpack.unpackb(VelCmd(vx=0.1, va=0.2, source="fuzz", scan_id=3).encode())
    node = t.node
    res = KeyResult(key)
    pub = t.cli.declare_publisher(key, congestion_control=zenoh.CongestionControl.BLOCK)
    before = Counter(node.counters)
    gen = hostile(valid_cmd, decode_cmd, rng)
    for k in range(per_key):
        pub.put(next(gen))
        res.sent += 1
        if k % valid_every == 0:
            pub.put(still)
            res.valid_sent += 1
    # a command on a per-source key whose source differs is hostile too (not counted by the
    # decoder oracle): leave it to the tests of the node
    deadline = time.monotonic() + 30
    while time.monotonic() < deadline:
        rej = node.counters["rejected"] - before["rejected"]
        got = node.counters["cmd_accepted"] - before["cmd_accepted"]
        if got >= res.valid_sent and rej >= res.sent:
            break
        time.sleep(0.05)
    res.rejected = node.counters["rejected"] - before["rejected"]
    # the node counts accepted commands under "cmd_accepted", rejected ones apart
    res.valid_processed = node.counters["cmd_accepted"] - before["cmd_accepted"]
    pub.undeclare()
    return res


def _fuzz_request_key(t: _Served, key: str, decode: Callable[[bytes], Any] | None,
                      valid: dict | None, rng: random.Random, per_key: int) -> KeyResult:
    """``per_key`` queries derived from ``valid``: each one the decoder rejects must get a
    NACK, each one it accepts (payload-free requests only) its answer."""
    from protocol import keys
    from protocol.messages import COMMAND_MAX_PAYLOAD

    res = KeyResult(key)
    if decode is None:  # the payload is ignored: only the size limit rejects
        def decode(d: bytes, _limit=COMMAND_MAX_PAYLOAD) -> None:
            if len(d) > _limit:
                raise ValueError("oversized")
        valid = {"v": 1, "pose": [1.0, 2.0, 0.0], "state": True, "x": b"\x00" * 8}
    gen = mutations(valid, rng)
    pending: list[tuple[bool, Any]] = []  # queries in flight (answered concurrently)
    n = 0
    while n < per_key:
        data = next(gen)
        try:
            decode(data)
            want_ok = True
        except Exception:  # noqa: BLE001
            want_ok = False
        if want_ok and keys.parse(key).name in ("set_pose", "motor_power", "set_odom"):
            continue  # a valid teleport or motors-off would change the robot
        n += 1
        pending.append((want_ok, t.cli.get(key, payload=data, timeout=10.0)))
        if len(pending) >= 32:
            _drain_replies(res, pending)
    _drain_replies(res, pending)
    return res


def _drain_replies(res: KeyResult, pending: list[tuple[bool, Any]]) -> None:
    """Count the replies of the queries in flight into ``res``; empties ``pending``."""
    for want_ok, handler in pending:
        replies = list(handler)
        got_ok = any(r.ok is not None for r in replies)
        got_err = any(r.err is not None for r in replies)
        if want_ok:
            res.valid_sent += 1
            res.valid_processed += got_ok
        else:
            res.sent += 1
            res.rejected += got_err and not got_ok
        if not replies and len(res.notes) < 3:
            res.notes.append("no reply (hang?)")
    pending.clear()


def _check_robot(t: _Served, results: list[KeyResult]) -> None:
    """The robot stood still (only stand-still commands and rejected requests), its motors on,
    the node still ticking (five ticks after the last command was counted, which also lets the
    last ones act): else a note on every result."""
    ticks = t.node.ticks
    alive = _until(lambda: t.node.ticks >= ticks + 5, 10) and t.runner.is_alive()
    x0, y0, _ = t.start_pose
    x1, y1, _ = t.world.pose(0)
    moved = math.hypot(x1 - x0, y1 - y0)
    for res in results:
        if moved > 1e-9:
            res.notes.append(f"the robot moved {moved:.3g} m")
        if not t.node._robots[0].motors:
            res.notes.append("motors switched off")
        if not alive:
            res.notes.append("the node stopped ticking")


def fuzz_server(per_key: int, seed: int = 0, valid_every: int = 10) -> list[KeyResult]:
    """Fuzz every key and queryable of a real ServerNode (see the module's text)."""
    rng = random.Random(seed)
    with _served_node() as t:
        results = [_fuzz_command_key(t, key, source, rng, per_key, valid_every)
                   for key, source in _command_keys()]
        results += [_fuzz_request_key(t, key, decode, valid, rng, per_key)
                    for key, decode, valid in _request_table()]
        _check_robot(t, results)
    return results


# ----------------------------------------------------------------------------------- clients
# who listens to what; the first one counts every message (the teacher's and controller's
# scan subscriptions are rings of one, "latest scan wins": a burst is mostly dropped unread)
_LISTENERS = {"scan": ("learner", "teacher", "controller"), "action": ("learner",),
              "notice": ("controller",), "snapshot": ("learner",), "labeled": ("learner",),
              "ack": ("teacher",)}
# what each part's messages are counted as in the listeners' --stats ("dropped": by kind)
_DROPPED = {"scan": "scan", "action": "teacher/action", "notice": "learner/notice",
            "labeled": "teacher/labeled", "ack": "learner/ack"}


def _until(pred, timeout: float, what: str | None = None, step: float = 0.05) -> bool:
    """Whether ``pred()`` held within ``timeout`` s (checked every ``step``); with ``what``
    a RuntimeError naming it instead of False."""
    end = time.monotonic() + timeout
    while not pred():
        if time.monotonic() >= end:
            if what is not None:
                raise RuntimeError(f"timed out waiting for {what}")
            return False
        time.sleep(step)
    return True


def _client_targets() -> list[tuple[str, Callable[[bytes], Any], dict]]:
    """(key, decoder, a valid message as a map) of every subscription of the processes."""
    from protocol import keys
    from protocol.messages import LabeledScan, LearnerAck, Scan, TeacherAction, TreeNotice

    scan = Scan(ts=1.0, id=5, ranges=[1.0] * 360, pose=(0, 0, 0))
    return [
        (keys.scan_key("r0"), lambda d: Scan.decode(d), msgpack.unpackb(scan.encode())),
        (keys.teacher_action_key("r0"), lambda d: TeacherAction.decode(d),
         msgpack.unpackb(TeacherAction(scan_id=5, action="forward").encode())),
        (keys.learner_notice_key("r0"), lambda d: TreeNotice.decode(d),
         msgpack.unpackb(TreeNotice(seq=1, nodes=3, height=1).encode())),
        (keys.teacher_labeled_key("r0"), lambda d: LabeledScan.decode(d),
         msgpack.unpackb(LabeledScan(scan_id=5, action="forward", origin="fuzz", seq=0,
                                     ranges=scan.ranges).encode())),
        (keys.learner_ack_key("r0"), lambda d: LearnerAck.decode(d),
         msgpack.unpackb(LearnerAck(origin="fuzz", upto=1, seqs=(3,)).encode())),
    ]


def _start_clients(procs: dict[str, Child], work: Path, endpoint: str, tree: Path) -> None:
    """Server, learner and teacher; the controller once the learner wrote its first tree."""

    def start(name: str, *argv: str) -> Child:
        # its counters at exit (--stats): what it dropped, by kind
        procs[name] = Child(name, rhbl_argv(*argv, "--stats", str(work / f"{name}.json")), work,
                            cwd=ROOT, stop_signal=signal.SIGINT, stop_timeout=30.0,
                            escalate=False).start()
        return procs[name]

    def up(p: Child, line: str) -> None:
        if not p.wait_for_line(line, 120):
            raise RuntimeError(f"{p.name} did not say {line!r}:\n{p.tail()}")

    up(start("server", "server", "--world", "room", "--speedup", "2", "--listen", endpoint),
       "listening on")
    start("learner", "learner", "--features", "wall", "--out", str(tree),
          "--snapshot-every", "0.5", "--connect", endpoint)
    up(start("teacher", "teacher", "--policy", "wall-follower", "--connect", endpoint),
       "first label")
    if not _until(tree.exists, 120, step=0.2):
        raise RuntimeError(f"the learner wrote no snapshot:\n{procs['learner'].output()}")
    up(start("controller", "controller", "--from-learner", "--follow", "--robot", "r0",
             "--connect", endpoint), "server is up")


def _fuzz_subscription(s, key: str, decode: Callable[[bytes], Any], valid: dict,
                       rng: random.Random, per_key: int) -> KeyResult:
    """``per_key`` hostile messages on ``key`` (rejections are counted later, from the logs)."""
    import zenoh

    res = KeyResult(key)
    pub = s.declare_publisher(key, congestion_control=zenoh.CongestionControl.BLOCK)
    gen = hostile(valid, decode, rng)
    for _ in range(per_key):
        pub.put(next(gen))
        res.sent += 1
        if res.sent % 200 == 0:
            time.sleep(0.02)  # let the processes breathe; zenoh drops nothing
    pub.undeclare()
    return res


def _fuzz_snapshot_queries(s, rng: random.Random, per_key: int) -> KeyResult:
    """Queries with mutated payloads on the learner's snapshot queryable: the payload is
    ignored, so every one must get the snapshot."""
    from protocol import keys

    res = KeyResult(keys.learner_snapshot_key("r0"))
    gen = mutations({"v": 1}, rng)
    inflight: list[Any] = []
    for k in range(per_key):
        inflight.append(s.get(keys.learner_snapshot_key("r0"), payload=next(gen), timeout=10.0))
        if len(inflight) >= 32 or k == per_key - 1:
            for h in inflight:
                res.valid_sent += 1
                res.valid_processed += any(r.ok is not None for r in h)
            inflight.clear()
    return res


def _journal_grows(tree: Path) -> bool:
    """The learner still journals labels: its journal grows within a few seconds."""
    journal = tree.with_name(tree.name + ".journal")
    size0 = journal.stat().st_size
    return _until(lambda: journal.stat().st_size > size0, 20, step=0.2)


def _client_verdicts(results: list[KeyResult], procs: dict[str, Child], learning: bool) -> None:
    """Exit statuses, tracebacks and rejections (the listeners' --stats) into ``results``."""
    import json

    text = {n: p.logfile.read_text(errors="replace") for n, p in procs.items()}
    dropped = {}
    for n, p in procs.items():
        stats = Path(p.logfile).with_name(f"{n}.json")
        dropped[n] = json.loads(stats.read_text()).get("dropped", {}) if stats.exists() else {}
    for res in results:
        part = next(p for p in _LISTENERS if p in res.key)
        for n in _LISTENERS[part]:
            rc = procs[n].poll()
            if rc not in (0, -signal.SIGINT):
                res.notes.append(f"{n} exited with {rc}")
            if "Traceback" in text[n]:
                res.notes.append(f"{n} logged a traceback")
        if part != "snapshot":
            res.rejected = dropped[_LISTENERS[part][0]].get(_DROPPED[part], 0)
            others = [f"{n} {dropped[n].get(_DROPPED[part], 0)}" for n in _LISTENERS[part][1:]]
            if others:
                res.key += f" (read by the rings of: {', '.join(others)})"
        if not learning:
            res.notes.append("the learner stopped journaling labels")


def fuzz_clients(per_key: int, seed: int = 0, valid_every: int = 10,
                 workdir: Path | None = None) -> list[KeyResult]:
    """Fuzz the keys the learner, teacher and controller processes listen to (module text)."""
    import zenoh

    from protocol.session import make_config

    rng = random.Random(seed)
    work = Path(workdir or tempfile.mkdtemp(prefix="rhbl-fuzz-"))
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    tree = work / "tree.rhbl"
    procs: dict[str, Child] = {}
    results: list[KeyResult] = []
    try:
        _start_clients(procs, work, endpoint, tree)
        with zenoh.open(make_config(mode="client", connect=[endpoint])) as s:
            for key, decode, valid in _client_targets():
                results.append(_fuzz_subscription(s, key, decode, valid, rng, per_key))
            results.append(_fuzz_snapshot_queries(s, rng, per_key))
            learning = _journal_grows(tree)
    finally:
        for name in ("controller", "teacher", "learner", "server"):
            if name in procs:
                procs[name].stop()
    _client_verdicts(results, procs, learning)
    return results


# ------------------------------------------------------------------------------------- files
def _file_cases(work: Path) -> list[tuple[str, bytes, Callable[[Path], Any], tuple]]:
    """(what, its good bytes, its loader, the typed errors it may raise) of a snapshot, a
    journal and a world file, made in ``work``."""
    import numpy as np

    import server as server_pkg
    from client.behaviour.learning import IncompatibleSnapshotError, load_snapshot
    from client.journal import Journal, JournalError
    from lab.harness import make_learner, resolve_world
    from lab.recipe import recipe_for
    from lab.train import train
    from rhbl.snapshot import SnapshotError
    from server.world import WorldError, load_world

    spec = resolve_world("room")
    learner = make_learner(spec.task)
    train(spec, learner, recipe_for(spec.task).replace(seconds=5.0), seed=0)
    snap = work / "tree.rhbl"
    learner.save(snap)
    jpath = work / "j.journal"
    j = Journal.create(jpath, fsync_interval=0.0)
    for i in range(20):
        j.append(i, 0.1 * i, "forward", np.ones(360, np.float32), 0.0, np.ones(8, np.float32))
    j.close()
    world = Path(server_pkg.world_path("room"))
    return [
        ("snapshot", snap.read_bytes(), lambda p: load_snapshot(p),
         (SnapshotError, IncompatibleSnapshotError)),
        ("journal", jpath.read_bytes(), lambda p: Journal.open(p, fsync_interval=0.0).close(),
         (JournalError,)),
        ("world", world.read_bytes(), lambda p: load_world(p), (WorldError,)),
    ]


def _mutate_file(good: bytes, rng: random.Random) -> bytes:
    """A file's bytes flipped, truncated, extended, replaced by random ones or spliced."""
    b = bytearray(good)
    kind = rng.randrange(5)
    if kind == 0:
        for _ in range(rng.randint(1, 8)):
            b[rng.randrange(len(b))] = rng.randrange(256)
    elif kind == 1:
        b = b[: rng.randrange(len(b))]
    elif kind == 2:
        b += os.urandom(rng.randint(1, 5000))
    elif kind == 3:
        b = bytearray(os.urandom(rng.choice([0, 1, 8, 100, 5000])))
    else:
        i = rng.randrange(len(b))
        b[i:i] = os.urandom(rng.randint(1, 64))
    return bytes(b)


def fuzz_files(per_file: int, seed: int = 0, workdir: Path | None = None) -> list[KeyResult]:
    """Mutate a snapshot, a journal and a world file; each must load or raise one typed error
    naming the file."""
    rng = random.Random(seed)
    work = Path(workdir or tempfile.mkdtemp(prefix="rhbl-fuzz-files-"))
    results = []
    for what, good, load, errors in _file_cases(work):
        res = KeyResult(f"{what} file")
        target = work / f"fuzzed-{what}"
        for _ in range(per_file):
            target.write_bytes(_mutate_file(good, rng))
            try:
                load(target)
                res.valid_sent += 1
                res.valid_processed += 1
            except errors as e:
                res.sent += 1
                if str(target) in str(e) or target.name in str(e):
                    res.rejected += 1
                elif len(res.notes) < 3:
                    res.notes.append(f"error does not name the file: {e}")
            except Exception as e:  # noqa: BLE001 - the finding
                res.sent += 1
                if len(res.notes) < 3:
                    res.notes.append(f"{type(e).__name__}: {str(e)[:120]}")
        results.append(res)
    return results


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--per-key", type=int, default=10_000, help="hostile messages per key")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--only", default="server,clients,files",
                    help="comma list of parts: server, clients, files")
    args = ap.parse_args(argv)
    parts = set(args.only.split(","))
    results: list[KeyResult] = []
    t0 = time.monotonic()
    if "server" in parts:
        results += fuzz_server(args.per_key, args.seed)
    if "clients" in parts:
        results += fuzz_clients(args.per_key, args.seed)
    if "files" in parts:
        results += fuzz_files(max(1, args.per_key // 10), args.seed)
    print(f"fuzz: seed {args.seed}, {args.per_key} hostile messages per key, "
          f"{time.monotonic() - t0:.0f} s")
    print("| key | hostile sent | rejected | valid sent | valid processed | result |")
    print("|---|---|---|---|---|---|")
    for r in results:
        print(r.line())
    return 0 if all(r.ok for r in results) else 1


if __name__ == "__main__":
    sys.exit(main())
