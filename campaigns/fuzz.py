"""Structure-aware fuzzing of every key the rhbl processes listen to, and of their files.

    python -m campaigns.fuzz [--per-key 10000] [--seed 0] [--only server,clients,files,...]

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
- ``written``: every writer of a file a person names (snapshots, ``--json``, ``--stats``,
  ``--record`` and ``rhbl record --out`` with and without ``--overwrite``, ``--plot``) against
  every kind of non-regular target (a character device, a FIFO, a folder, a socket, symlinks
  to a device, a FIFO and a folder): each refused naming the path, the target unchanged (same
  kind, same inode); a new regular file is written (the positive control).
- ``recordings`` (``--per-key / 10`` mutations): decompression bombs (zstd 1 GiB, lz4) and
  oversized records refused at once; a small recording cut at every byte (a prefix of its
  messages and a note, or "not an MCAP recording" inside the magic); mutated recordings (read
  or one error naming the file); crafted topics (wildcards, empty chunks, ``#``, ``?``, ...)
  refused by ``rhbl replay``'s check and log times near 2^64 or 10^9 s apart played capped.
- ``bridge`` (``--per-key / 100`` of each kind): a real ``rhbl foxglove`` sent foreign
  Origins and Hosts, no Host, repeated headers, oversized headers, requests that are no
  upgrade, random bytes and a header never finished: each refused (never 101), a valid
  upgrade after each burst gets 101, the bridge alive and its log bounded.
- ``console`` (``--per-key / 100`` of each kind): two real ``rhbl console`` processes (loopback
  without a token, and with one) sent no Host, foreign Hosts, 5,000-character paths, oversized
  headers, random bytes, WebSocket upgrades with a foreign Origin, the static files and the
  page without the token or with a wrong one, a page's message nested 2,000 deep and a header
  never finished: each refused (a 4xx, the connection or WebSocket closed, an error message;
  never 101, the page or a 5xx), the page with a valid request after each burst gets 200,
  both consoles alive, no traceback, their refusal lines bounded.
- ``cli``: every option of every ``rhbl`` command with the hostile values of its type
  (``cli_hostile``): each refused by the parser, one line naming the option, exit 2.

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
    from process.session import make_config
    from protocol import keys
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
        said = json.loads(stats.read_text()) if stats.exists() else {}
        dropped[n] = dict(said.get("dropped", {}))
        # the learner refuses what does not fit the robot's laser, some before decoding it
        for kind, k in said.get("refused_messages", {}).items():
            dropped[n][kind] = dropped[n].get(kind, 0) + k
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

    from process.session import make_config

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
    learner = make_learner("wall-following")
    train(spec, learner, recipe_for("wall-following").replace(seconds=5.0), seed=0)
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


# ----------------------------------------------------------------------- the command line
# The walk of every option of every ``rhbl`` command (tests/test_cli_walk.py runs it too): the
# hostile values of an option come from its argparse type (``process.arguments``: its kind
# and, for numbers, its range) or its choices.
def cli_places(work: Path) -> dict[str, str]:
    """Files of every kind to give as paths, made in ``work``."""
    work.mkdir(parents=True, exist_ok=True)
    (work / "file.json5").write_text("{}\n")  # a regular file (a valid zenoh config too)
    for name, make in (("fifo", lambda p: os.mkfifo(p)), ("folder", lambda p: p.mkdir()),
                       ("to-dev-null", lambda p: os.symlink("/dev/null", p))):
        if not os.path.lexists(work / name):
            make(work / name)
    return {"file": str(work / "file.json5"), "fifo": str(work / "fifo"),
            "folder": str(work / "folder"), "device": "/dev/null",
            "link": str(work / "to-dev-null"), "missing": str(work / "missing" / "x"),
            "under_file": str(work / "file.json5" / "x"), "new": str(work / "new" / "out.x"),
            "new_folder": str(work / "new-folder")}


def value_actions(parser: argparse.ArgumentParser) -> list[argparse.Action]:
    """The options and positionals of ``parser`` that take a value."""
    return [a for a in parser._actions
            if a.nargs != 0 and not isinstance(a, argparse._HelpAction) and a.dest != "_main"]


def option_name(action: argparse.Action) -> str:
    return action.option_strings[-1] if action.option_strings else action.dest


def cli_example(action: argparse.Action, places: dict[str, str]) -> str:
    """A valid value of ``action`` (for the options that must be given while another is
    walked)."""
    if action.choices:
        return str(next(iter(action.choices)))
    kind = getattr(action.type, "kind", "text")
    return {"input": places["file"], "output": places["new"],
            "folder": places["new_folder"]}.get(kind, getattr(action.type, "example", "x"))


def _number_values(t) -> list[str]:
    out = ["nan", "inf", "-inf", "1e999", "", "x", "1x"]
    for v in (-1, 0, 1e12):
        low_bad = t.low is not None and (v < t.low or (t.low_open and v == t.low))
        if low_bad or (t.high is not None and v > t.high):
            out.append(f"{v:g}" if t.cast is not int else str(int(v)))
    if t.cast is int:
        out.append("1.5")
    return out


def cli_hostile(action: argparse.Action, places: dict[str, str]) -> list[str]:
    """The values ``action`` must refuse ("" is a value of a type whose ``empty_ok``)."""
    values = _cli_hostile(action, places)
    return [v for v in values if v or not getattr(action.type, "empty_ok", False)]


def _cli_hostile(action: argparse.Action, places: dict[str, str]) -> list[str]:
    from process.arguments import Checked, Number

    t = action.type
    if action.choices and not isinstance(t, Checked):
        return ["not-a-choice", ""]
    if isinstance(t, Number):
        return _number_values(t)
    kind = t.kind
    if kind == "input":
        return ["", places["fifo"], places["device"], places["folder"], places["missing"],
                places["link"]]
    if kind == "output":
        return ["", places["fifo"], places["device"], places["folder"], places["link"],
                places["under_file"]]
    if kind == "folder":
        return ["", places["file"], places["fifo"], places["device"], places["under_file"]]
    if kind == "world":
        return ["", "no-such-world", places["fifo"], places["device"], places["folder"]]
    if kind == "chunk":
        return ["", "*", "**", "a/*", "r$*0", "r#0", "r?0", "a b", "a//b", "/a", "a/"]
    if kind == "host":
        return ["", "-x", "a b", "a/b"]
    if kind == "address":
        return ["", "nonsense", "127.0.0.1:99999", ":80", "127.0.0.1:-1", "a b:80"]
    if kind == "endpoint":
        return ["", "nonsense", "tcp/", "tcp/127.0.0.1:99999", "tcp/127.0.0.1", "/x"]
    if kind == "list":
        return ["x", "nan", "inf,1,0", "nan,nan,nan", "1e999"]
    if kind == "origin":
        return ["", "evil.example", "ftp://x", "https://x/path", "https://u@x"]
    return ["", "\x00", "a\nb", "x" * 1001]  # text, token


def cli_base_argv(parser: argparse.ArgumentParser, skip: argparse.Action | None,
                  places: dict[str, str]) -> list[str]:
    """The required options and positionals of ``parser`` with valid values (but ``skip``)."""
    argv, positionals = [], []
    for a in value_actions(parser):
        if a is skip:
            continue
        if not a.option_strings:
            positionals.append(cli_example(a, places))
        elif a.required:
            argv += [a.option_strings[-1], cli_example(a, places)]
    for g in parser._mutually_exclusive_groups:
        if g.required and skip not in g._group_actions:
            first = g._group_actions[0]
            argv += [first.option_strings[-1]] + ([] if first.nargs == 0 else
                                                  [cli_example(first, places)])
    return argv + positionals


def cli_parse(parser: argparse.ArgumentParser, argv: list[str]) -> tuple[int | None, str]:
    """(the exit code, None when parsed; what it printed on stderr)."""
    import io

    err = io.StringIO()
    with contextlib.redirect_stderr(err), contextlib.redirect_stdout(io.StringIO()):
        try:
            parser.parse_args(argv)
        except SystemExit as exc:
            return exc.code, err.getvalue()
    return None, err.getvalue()


def cli_refusal(command: str, action: argparse.Action, value: str, parser,
                places: dict[str, str]) -> str | None:
    """None when ``rhbl COMMAND`` refuses ``value`` for ``action`` as it must (exit 2, one
    line naming the option, no traceback), else what went wrong."""
    argv = cli_base_argv(parser, action, places)
    argv += ([f"{action.option_strings[-1]}={value}"] if action.option_strings
             else ["--", value])
    code, err = cli_parse(parser, argv)
    what = f"rhbl {command} {option_name(action)} {value[:40]!r}"
    lines = err.strip().splitlines()
    if code != 2:
        return f"{what}: accepted (exit {code})"
    if len(lines) != 1 or not lines[0].startswith(f"rhbl {command}: error:") or \
            "Traceback" in err:
        return f"{what}: {err[:200]!r}"
    named = action.option_strings or [action.dest, action.metavar or action.dest]
    if not any(n in lines[0] for n in named):
        return f"{what}: the option is not named: {lines[0][:200]}"
    return None


def fuzz_cli(workdir: Path | None = None) -> list[KeyResult]:
    """Every option of every ``rhbl`` command with its hostile values: each refused by the
    parser, before the command runs (one line naming the option, exit 2); the command's valid
    example arguments accepted (the positive control)."""
    from lab.cli import COMMANDS, build_parser

    places = cli_places(Path(workdir or tempfile.mkdtemp(prefix="rhbl-fuzz-cli-")))
    results = []
    for command in COMMANDS:
        parser = build_parser(command)
        res = KeyResult(f"rhbl {command} (every option)", valid_sent=1)
        code, err = cli_parse(parser, cli_base_argv(parser, None, places))
        res.valid_processed = int(code is None)
        for action in value_actions(parser):
            for value in cli_hostile(action, places):
                res.sent += 1
                wrong = cli_refusal(command, action, value, parser, places)
                if wrong is None:
                    res.rejected += 1
                elif len(res.notes) < 3:
                    res.notes.append(wrong)
        results.append(res)
    return results


# ---------------------------------------------------------------------------- files written
def _odd_targets(work: Path) -> dict[str, Path]:
    """Every kind of path that is not a regular file, made in ``work`` (a socket bound)."""
    import socket

    work.mkdir(parents=True, exist_ok=True)
    os.mkfifo(work / "fifo")
    (work / "folder").mkdir()
    sock = socket.socket(socket.AF_UNIX)
    sock.bind(str(work / "socket"))
    sock.close()  # the socket file stays
    os.symlink("/dev/null", work / "link-to-device")
    os.symlink(work / "fifo", work / "link-to-fifo")
    os.symlink(work / "folder", work / "link-to-folder")
    return {"character device": Path("/dev/null"), "FIFO": work / "fifo",
            "folder": work / "folder", "socket": work / "socket",
            "symlink to a device": work / "link-to-device",
            "symlink to a FIFO": work / "link-to-fifo",
            "symlink to a folder": work / "link-to-folder"}


def _writers(work: Path) -> list[tuple[str, Callable[[Path], Any]]]:
    """Every way rhbl writes a file a person names (the real functions)."""
    import numpy as np

    from client.recording.mcap_file import RecordingWriter
    from process import files
    from process.runtime import write_stats
    from rhbl import HypersphereClassifier

    clf = HypersphereClassifier().fit(np.array([[0.0, 0.0], [1.0, 1.0]]), ["a", "b"])

    def record(p: Path, overwrite: bool) -> None:
        with RecordingWriter(p, overwrite=overwrite, viewer=False):
            pass

    def plot(p: Path) -> None:
        from lab.harness import resolve_world
        from lab.plot import plot_paths

        plot_paths(resolve_world("room"), {}, p)

    return [
        ("snapshot (train, learner, compact, example)", lambda p: clf.save(p)),
        ("--json / summary (files.write_text)", lambda p: files.write_text(p, "{}")),
        ("--stats", lambda p: write_stats(str(p), "fuzz", 0, {})),
        ("--record / record --out", lambda p: record(p, False)),
        ("record --out --overwrite", lambda p: record(p, True)),
        ("--plot", plot),
    ]


def fuzz_written(workdir: Path | None = None) -> list[KeyResult]:
    """Every writer against every kind of non-regular target: each refused with an error
    naming the path, the target left as it was (its kind, and a device's node, unchanged)."""
    import stat

    work = Path(workdir or tempfile.mkdtemp(prefix="rhbl-fuzz-written-"))
    targets = _odd_targets(work / "targets")
    results = []
    for what, write in _writers(work):
        res = KeyResult(f"writer: {what}")
        for kind, path in targets.items():
            res.sent += 1
            before = os.lstat(path), os.stat(path)
            try:
                write(path)
                res.notes.append(f"{kind}: written")
                continue
            except Exception as exc:  # noqa: BLE001 - the refusal, or the finding
                said = str(exc)
            after = os.lstat(path), os.stat(path)
            same = all(stat.S_IFMT(a.st_mode) == stat.S_IFMT(b.st_mode) and a.st_ino == b.st_ino
                       for a, b in zip(before, after, strict=True))
            if same and (path.name in said or str(path) in said):
                res.rejected += 1
            elif len(res.notes) < 3:
                res.notes.append(f"{kind}: {'changed; ' if not same else ''}{said[:120]}")
        # the positive control: a new regular file is written
        res.valid_sent += 1
        good = work / f"good-{len(results)}.png"  # (a picture for --plot)
        with contextlib.suppress(Exception):
            write(good)
        res.valid_processed += int(good.is_file() and good.stat().st_size > 0)
        results.append(res)
    return results


# ------------------------------------------------------------------------ recordings read
def _small_recording(path: Path, n: int = 12) -> list[bytes]:
    import numpy as np

    from client.recording.mcap_file import RecordingWriter
    from protocol import keys
    from protocol import messages as m

    out = []
    with RecordingWriter(path, viewer=False, chunk_seconds=1e9) as w:
        for k in range(n):
            data = m.Scan(ts=float(k), id=k, ranges=np.full(36, 2.0, np.float32)).encode()
            out.append(data)
            w.write(keys.scan_key("r0"), data, 1_000_000_000 + k)
            if (k + 1) % 4 == 0:
                w.flush()
    return out


def _bombs(work: Path) -> list[tuple[str, Path]]:
    """Crafted recordings: a zstd and an lz4 chunk of 1 GiB of zeros (a few KiB on disk), a
    chunk that declares less than it holds, a record claiming 2^63 bytes."""
    import struct

    import lz4.frame
    import zstandard

    magic = b"\x89MCAP0\r\n"
    header = struct.pack("<BQ", 0x01, 8) + struct.pack("<II", 0, 0)

    def chunk(compression: str, data: bytes, size: int) -> bytes:
        body = (struct.pack("<QQQI", 0, 0, size, 0) + struct.pack("<I", len(compression))
                + compression.encode() + struct.pack("<Q", len(data)) + data)
        return struct.pack("<BQ", 0x06, len(body)) + body

    cz = zstandard.ZstdCompressor(level=19).compressobj()
    zeros = b"\0" * 2**20
    gib = b"".join(cz.compress(zeros) for _ in range(1024)) + cz.flush()
    small = lz4.frame.compress(b"\0" * 2**26)
    cases = {"zstd bomb (1 GiB)": chunk("zstd", gib, 2**30),
             "lz4 bomb (64 MiB, declared 64 MiB + 1)": chunk("lz4", small, 2**26 + 1),
             "chunk holding more than it declares": chunk("zstd", gib, 1000),
             "record claiming 2^63 bytes": struct.pack("<BQ", 0x05, 2**63) + b"\0" * 32}
    out = []
    for i, (what, body) in enumerate(cases.items()):
        p = work / f"bomb-{i}.mcap"
        p.write_bytes(magic + header + body)
        out.append((what, p))
    return out


def _recording_bombs(work: Path) -> KeyResult:
    """Decompression bombs and oversized records: each refused at once, naming the file."""
    from client.recording.mcap_file import RecordingError, RecordingReader

    bombs = KeyResult("recording: decompression bombs, oversized records")
    for what, path in _bombs(work):
        bombs.sent += 1
        t0 = time.monotonic()
        try:
            list(RecordingReader(path).messages())
            bombs.notes.append(f"{what}: read")
        except RecordingError as exc:
            if path.name in str(exc) and time.monotonic() - t0 < 30:
                bombs.rejected += 1
            else:
                bombs.notes.append(f"{what}: {str(exc)[:100]}")
        except Exception as exc:  # noqa: BLE001 - the finding
            bombs.notes.append(f"{what}: {type(exc).__name__}: {str(exc)[:100]}")
    return bombs


def _recording_cuts(work: Path, whole: bytes, payloads: list) -> KeyResult:
    """The recording ``whole`` cut at every byte: a prefix of its messages (``payloads``) and
    a note, or (inside the magic or the header) one RecordingError naming the file."""
    from client.recording.mcap_file import RecordingError, RecordingReader

    cuts = KeyResult(f"recording cut at every byte ({len(whole)})")
    cut = work / "cut.mcap"
    for at in range(len(whole)):
        cut.write_bytes(whole[:at])
        reader = RecordingReader(cut)
        try:
            got = [m.data for m in reader.messages()]
        except RecordingError as exc:
            if at < 17 and cut.name in str(exc):  # inside the magic or the header: no MCAP
                cuts.sent += 1
                cuts.rejected += 1
            elif len(cuts.notes) < 3:
                cuts.notes.append(f"cut at {at}: {str(exc)[:100]}")
            continue
        except Exception as exc:  # noqa: BLE001 - the finding (struct.error was one)
            if len(cuts.notes) < 3:
                cuts.notes.append(f"cut at {at}: {type(exc).__name__}: {str(exc)[:100]}")
            continue
        cuts.valid_sent += 1  # a prefix of the messages, and a note
        cuts.valid_processed += int(got == payloads[:len(got)] and len(reader.notes) == 1)
    return cuts


def _recording_mutations(work: Path, whole: bytes, rng: random.Random,
                         per_file: int) -> KeyResult:
    """``per_file`` mutations of ``whole``: what is intact read, or one RecordingError naming
    the file; never another exception, never a hang."""
    from client.recording.mcap_file import RecordingError, RecordingReader

    mutated = KeyResult("recording mutated")
    target = work / "fuzzed.mcap"
    for _ in range(per_file):
        target.write_bytes(_mutate_file(whole, rng))
        mutated.sent += 1
        try:
            list(RecordingReader(target).messages(viewer=True))
            mutated.rejected += 1  # read (what is intact): no crash, no hang
        except RecordingError as exc:
            if target.name in str(exc):
                mutated.rejected += 1
            elif len(mutated.notes) < 3:
                mutated.notes.append(f"error does not name the file: {exc}")
        except Exception as exc:  # noqa: BLE001 - the finding
            if len(mutated.notes) < 3:
                mutated.notes.append(f"{type(exc).__name__}: {str(exc)[:120]}")
    return mutated


def _replay_crafted(work: Path) -> KeyResult:
    """Crafted topics given to ``rhbl replay``'s check (a plain key of a robot only, one
    ValueError naming the file) and crafted log times (the replay span bounded)."""
    from client.recording.replay import plan_replay
    from protocol import keys

    crafted = KeyResult("replay: crafted topics and log times")
    scan = keys.scan_key("r0")
    topics = ["rhbl/**/laser/0/data/scan", "rhbl/*/laser/0/data/scan", "rhbl/r$*0/laser/0/data/scan",
              "rhbl//laser/0/data/scan", "rhbl/r#0/laser/0/data/scan", "rhbl/r?0/laser/0/data/scan",
              "rhbl/r0/laser/00/data/scan", "rhbl/r 0/laser/0/data/scan",
              "rhbl/r0/sim/req/../get_world", "rhbl/**/sim/req/get_world"]
    for i, topic in enumerate(topics):
        p = work / f"crafted-{i}.mcap"
        _write_topics(p, [(scan, 10**9), (topic, 10**9 + 1)])
        crafted.sent += 1
        try:
            plan = plan_replay(p, None, 5.0)
            if all(k == scan for k in plan.keys) and set(plan.worlds) <= {"r0"}:
                crafted.rejected += 1  # not a sensor key of ours: never published
            else:
                crafted.notes.append(f"{topic!r}: would publish on {sorted(plan.keys)}")
        except ValueError as exc:
            if p.name in str(exc) and repr(topic) in str(exc):
                crafted.rejected += 1
            elif len(crafted.notes) < 3:
                crafted.notes.append(f"{topic!r}: {str(exc)[:100]}")
    for i, times in enumerate([[10**9, 2**64 - 1], [2**64 - 1, 0], [10**9, 10**9 + 10**18]]):
        p = work / f"times-{i}.mcap"
        _write_topics(p, [(scan, t) for t in times])
        crafted.valid_sent += 1
        plan = plan_replay(p, None, 5.0)
        crafted.valid_processed += int(plan.messages == 2 and plan.span <= 5.0)
    return crafted


def fuzz_recordings(per_file: int, seed: int = 0, workdir: Path | None = None
                    ) -> list[KeyResult]:
    """Recordings read by every reader (``RecordingReader``: inspect, replay, retraining):
    bombs refused at once; the file cut at every byte (a prefix of the messages and a note,
    never another exception); ``per_file`` mutations (a message list or one RecordingError
    naming the file); crafted topics and log times given to ``rhbl replay``'s check (a plain
    key of a robot only, one ValueError naming the file)."""
    import logging

    logging.getLogger("client.recording.mcap_file").setLevel(logging.ERROR)  # a line a cut
    rng = random.Random(seed)
    work = Path(workdir or tempfile.mkdtemp(prefix="rhbl-fuzz-mcap-"))
    work.mkdir(parents=True, exist_ok=True)
    good = work / "good.mcap"
    payloads = _small_recording(good)
    whole = good.read_bytes()
    return [_recording_bombs(work), _recording_cuts(work, whole, payloads),
            _recording_mutations(work, whole, rng, per_file), _replay_crafted(work)]


def _write_topics(path: Path, topics_times: list[tuple[str, int]]) -> None:
    import numpy as np

    from client.recording.mcap_file import RecordingWriter
    from protocol import messages as m

    with RecordingWriter(path, viewer=False) as w:
        for k, (topic, ns) in enumerate(topics_times):
            w.write(topic, m.Scan(ts=float(k), id=k, ranges=np.full(36, 2.0, np.float32))
                    .encode(), ns)


# ---------------------------------------------------------------------- the Foxglove bridge
def _http(port: int, raw: bytes, timeout: float = 30.0, source: str = "127.0.0.1") -> bytes:
    """What the server answers ``raw`` (sent from the address ``source``) with (its first
    line), b"" when it closes."""
    import socket

    with socket.create_connection(("127.0.0.1", port), timeout=timeout,
                                  source_address=(source, 0)) as s:
        s.sendall(raw)
        got = b""
        with contextlib.suppress(OSError):
            while b"\r\n" not in got:
                part = s.recv(4096)
                if not part:
                    break
                got += part
    return got.split(b"\r\n", 1)[0]


def _upgrade(host: str | None = None, path: str = "/", origin: str | None = None,
             extra: str = "", protocol: str | None = "foxglove.sdk.v1") -> bytes:
    import base64

    key = base64.b64encode(os.urandom(16)).decode()
    lines = [f"GET {path} HTTP/1.1", *([f"Host: {host}"] if host is not None else []),
             "Upgrade: websocket", "Connection: Upgrade", f"Sec-WebSocket-Key: {key}",
             "Sec-WebSocket-Version: 13",
             *([f"Sec-WebSocket-Protocol: {protocol}"] if protocol is not None else []),
             *([f"Origin: {origin}"] if origin is not None else [])]
    return ("\r\n".join(lines) + "\r\n" + extra + "\r\n").encode()


def _bursts(name: str, port: int, kinds: dict[str, Callable[[], bytes]], per_kind: int,
            refused: Callable[[bytes], bool], control: Callable[[], bool]) -> list[KeyResult]:
    """``per_kind`` requests of each kind sent to ``port``, each answer's first line judged by
    ``refused``; after each burst the positive control (``control()`` True when served)."""
    results = []
    for what, make in kinds.items():
        res = KeyResult(f"{name}: {what}")
        for _ in range(per_kind):
            res.sent += 1
            line = _http(port, make())
            if refused(line):
                res.rejected += 1
            elif len(res.notes) < 3:
                res.notes.append(f"got {line[:60]!r}")
        res.valid_sent += 1
        res.valid_processed += int(control())
        results.append(res)
    return results


def _alive(name: str, child: Child, refusal: str, elapsed: float, slack: int) -> KeyResult:
    """The child still runs, logged no traceback and at most one line holding ``refusal`` a
    second (plus ``slack``)."""
    alive = KeyResult(f"{name}: alive, log bounded", valid_sent=1)
    alive.valid_processed = int(child.proc is not None and child.proc.poll() is None)
    out = child.output()
    refused_lines = sum(refusal in ln for ln in out.splitlines())
    if refused_lines > elapsed + slack:
        alive.notes.append(f"{refused_lines} refusal lines logged in {elapsed:.0f} s")
    if "Traceback" in out:
        alive.notes.append("a traceback in its log")
    return alive


def fuzz_bridge(per_kind: int, seed: int = 0, workdir: Path | None = None) -> list[KeyResult]:
    """A real ``rhbl foxglove`` (a zenoh peer, no server needed): hostile HTTP and WebSocket
    upgrades (foreign Origin, foreign or missing Host, a wrong token, repeated headers, an
    oversized header, a header never finished, not an upgrade, random bytes), ``per_kind`` of
    each kind: each refused (an HTTP error, never 101); a valid upgrade after each burst gets
    101 (the positive control); the bridge is alive at the end and logged a bounded number of
    lines (one a second at most)."""
    rng = random.Random(seed)
    work = Path(workdir or tempfile.mkdtemp(prefix="rhbl-fuzz-bridge-"))
    port = free_port()
    fx = Child("foxglove", rhbl_argv("foxglove", "--mode", "peer", "--listen",
                                     f"tcp/127.0.0.1:{free_port()}", "--port", str(port),
                                     "--allow-origin", "https://app.foxglove.dev"),
               work, cwd=ROOT).start()
    results = []
    try:
        if not fx.wait_for_line("Foxglove WebSocket server listening on", 120):
            raise RuntimeError(f"the bridge did not start:\n{fx.tail()}")
        here = f"127.0.0.1:{port}"
        t_start = time.monotonic()
        kinds: dict[str, Callable[[], bytes]] = {
            "foreign Origin": lambda: _upgrade(here, origin=rng.choice(
                ["http://evil.example", "null", "https://app.foxglove.dev.evil.example",
                 f"http://{here}x", "file://"])),
            "foreign Host": lambda: _upgrade(rng.choice(["attacker.example", "127.0.0.1.nip.io",
                                                         "", "[::2]:1", "localhost.evil"])),
            "no Host": lambda: _upgrade(None),
            "repeated Origin": lambda: _upgrade(here, extra="Origin: a\r\nOrigin: b\r\n"),
            "oversized header": lambda: _upgrade(here, extra="X: " + "y" * rng.randint(
                9000, 70_000) + "\r\n"),
            "not an upgrade": lambda: rng.choice([b"GET / HTTP/1.1\r\nHost: " + here.encode()
                                                  + b"\r\n\r\n",
                                                  b"POST / HTTP/1.1\r\n\r\n",
                                                  b"GET /" + b"a" * 5000 + b" HTTP/1.1\r\n\r\n"]),
            "random bytes": lambda: os.urandom(rng.randint(1, 2000)) + b"\r\n\r\n",
        }
        results += _bursts("foxglove bridge", port, kinds, per_kind,
                           lambda line: b" 101 " not in line,
                           lambda: b" 101 " in _http(port, _upgrade(here)))
        # a header never finished: closed within the gate's timeout, then still serving
        import socket

        res = KeyResult("foxglove bridge: header never finished")
        from client.recording.gate import HEADER_TIMEOUT

        with socket.create_connection(("127.0.0.1", port), timeout=HEADER_TIMEOUT + 20) as s:
            s.sendall(b"GET / HTTP/1.1\r\nHost: " + here.encode() + b"\r\n")
            res.sent += 1
            t0 = time.monotonic()
            with contextlib.suppress(OSError):
                answer = s.recv(4096)
                res.rejected += int(b" 408 " in answer and
                                    time.monotonic() - t0 < HEADER_TIMEOUT + 15)
        res.valid_sent += 1
        res.valid_processed += int(b" 101 " in _http(port, _upgrade(here)))
        results.append(res)
        results.append(_alive("foxglove bridge", fx, "refused a request from",
                              time.monotonic() - t_start, 2))
    finally:
        fx.stop()
    return results


# ------------------------------------------------------------------------------- the console
def _ws_refuses(port: int, message: str, refusal: str, timeout: float = 20.0) -> bool:
    """A page (a WebSocket with the console's own Host and Origin) sends ``message``: True when
    the console answers with an error message saying ``refusal``, or closes the WebSocket."""
    import asyncio
    import json

    import aiohttp

    here = f"127.0.0.1:{port}"

    async def go() -> bool:
        async with aiohttp.ClientSession() as http, http.ws_connect(
                f"http://{here}/ws", origin=f"http://{here}",
                timeout=aiohttp.ClientWSTimeout(ws_close=timeout)) as ws:
            await ws.send_str(message)
            while True:
                msg = await ws.receive(timeout)
                if msg.type != aiohttp.WSMsgType.TEXT:  # closed, or broken
                    return True
                reply = json.loads(msg.data)
                if reply.get("t") == "error":
                    return refusal in reply.get("error", "")

    try:
        return asyncio.run(asyncio.wait_for(go(), timeout))
    except TimeoutError:
        return False


def _console_refused(line: bytes) -> bool:
    """An HTTP refusal (4xx) or a closed connection: never 101, 2xx, 3xx or 5xx."""
    if not line:
        return True
    parts = line.split(b" ", 2)
    return (len(parts) >= 2 and parts[0].startswith(b"HTTP/") and parts[1].isdigit()
            and 400 <= int(parts[1]) < 500)


def _get(path: str, host: str | None, headers: str = "") -> bytes:
    """An HTTP/1.1 GET of ``path`` (``host``: its Host header, None: none)."""
    return (f"GET {path} HTTP/1.1\r\n" + (f"Host: {host}\r\n" if host is not None else "")
            + headers + "\r\n").encode()


def _console_kinds(rng: random.Random, op: int, sp: int,
                   token: str) -> tuple[dict[str, Callable[[], bytes]], dict[str, Callable[[], bytes]]]:
    """The hostile requests of ``fuzz_console`` by kind: to the console without a token (on
    port ``op``), then to the one with ``token`` (on ``sp``)."""
    here, there = f"127.0.0.1:{op}", f"127.0.0.1:{sp}"
    static = ["/static/index.html", "/static/console.js", "/static/console.css",
              "/static/index.html?token=" + token, "/?token=", "/"]
    open_kinds: dict[str, Callable[[], bytes]] = {
        "no Host": lambda: rng.choice([b"GET / HTTP/1.1\r\n\r\n", b"GET / HTTP/1.0\r\n\r\n",
                                       b"GET /static/console.js HTTP/1.1\r\n\r\n",
                                       b"GET /ws HTTP/1.1\r\nUpgrade: websocket\r\n\r\n"]),
        "foreign Host": lambda: _get(rng.choice(["/", "/static/console.js", "/ws"]),
                                     rng.choice(["attacker.example", "attacker.example:8080",
                                                 "127.0.0.1.nip.io", "localhost.evil",
                                                 "[::2]:1", "0.0.0.0", "10.0.0.1"])),
        "5,000-character path": lambda: _get(rng.choice(["/", "/static/", "/ws/"])
                                             + rng.choice("ab%.") * 5000, here),
        "oversized header": lambda: _get("/", here, "X: " + "y" * rng.randint(
            9000, 70_000) + "\r\n"),
        "random bytes": lambda: os.urandom(rng.randint(1, 2000)) + b"\r\n\r\n",
        "WebSocket upgrade, foreign Origin": lambda: _upgrade(
            here, path="/ws", protocol=None, origin=rng.choice(
                ["http://evil.example", "null", f"http://{here}.evil.example",
                 f"https://{here}", "file://", f"http://localhost:{op}"])),
    }
    secured_kinds: dict[str, Callable[[], bytes]] = {
        "static files and page without the token": lambda: _get(rng.choice(static), there),
        "wrong token": lambda: _get(rng.choice(["/", "/static/console.js", "/ws"]) + "?token="
                                    + rng.choice([token[:-1], token + "x", "%00", token.upper(),
                                                  "a" * 5000]), there),
    }
    return open_kinds, secured_kinds


def _nested_messages(rng: random.Random, op: int, per_kind: int, page) -> KeyResult:
    """A page's message nested 2,000 deep, ``per_kind`` times: each refused on the WebSocket,
    the page served after them (``page()``)."""
    res = KeyResult("console: a page's message nested 2,000 deep")
    for _ in range(per_kind):
        res.sent += 1
        open_, close = rng.choice([("[", "]"), ('{"t":', "}")])
        res.rejected += int(_ws_refuses(op, open_ * 2000 + "0" + close * 2000,
                                        "nested more than"))
    res.valid_sent += 1
    res.valid_processed += int(page())
    return res


def _header_never_finished(op: int, page) -> KeyResult:
    """A header never finished: closed within --header-timeout (1 s), then still serving."""
    import socket

    res = KeyResult("console: header never finished")
    with socket.create_connection(("127.0.0.1", op), timeout=30) as s:
        s.sendall(b"GET / HTTP/1.1\r\nHost: " + f"127.0.0.1:{op}".encode() + b"\r\nX-Slow: ")
        res.sent += 1
        t0 = time.monotonic()
        answer = b""
        with contextlib.suppress(OSError):
            while part := s.recv(4096):
                answer += part
        res.rejected += int(_console_refused(answer.split(b"\r\n", 1)[0])
                            and time.monotonic() - t0 < 1 + 15)
    res.valid_sent += 1
    res.valid_processed += int(page())
    return res


def fuzz_console(per_kind: int, seed: int = 0, workdir: Path | None = None) -> list[KeyResult]:
    """Two real ``rhbl console`` processes (zenoh peers, no server needed): one on loopback
    without a token (``--header-timeout 1``), one with a token. Hostile requests, ``per_kind``
    of each kind: no Host, a foreign Host, a 5,000-character path, ``/static/index.html`` and
    the other static files without the token, a wrong token, random bytes, an oversized
    header, a foreign Origin on the WebSocket upgrade, a header never finished, a page's
    message nested 2,000 deep: each refused (a 4xx, a closed connection or an error message
    on the WebSocket; never 101, the page or a 5xx); after each burst the page with a valid
    request gets 200 (the positive control); both consoles alive at the end, no traceback, a
    bounded number of refusal lines (rate-limited)."""
    import secrets

    rng = random.Random(seed)
    work = Path(workdir or tempfile.mkdtemp(prefix="rhbl-fuzz-console-"))
    ports = {"open": free_port(), "secured": free_port()}
    # one argument, --token=VALUE: a random token may begin with "-" (argparse would take
    # "--token -x..." for a missing value)
    extra = {"open": ("--header-timeout", "1"),
             "secured": (f"--token={secrets.token_urlsafe(18)}",)}
    kids = {name: Child(f"console-{name}", rhbl_argv(
        "console", "--mode", "peer", "--listen", f"tcp/127.0.0.1:{free_port()}", "--http",
        f"127.0.0.1:{port}", *extra[name]), work, cwd=ROOT).start()
        for name, port in ports.items()}
    results: list[KeyResult] = []
    try:
        for name, kid in kids.items():
            if not kid.wait_for_line("console: http", 120):
                raise RuntimeError(f"the console ({name}) did not start:\n{kid.tail()}")
        url = next(ln for ln in kids["secured"].output().splitlines()
                   if ln.startswith("console: "))
        token = url.split("?token=", 1)[1].strip()
        t_start = time.monotonic()
        op, sp = ports["open"], ports["secured"]

        def page(port: int, query: str = "", source: str = "127.0.0.1") -> bool:
            return b" 200 " in _http(port, _get("/" + query, f"127.0.0.1:{port}"),
                                     source=source)

        open_kinds, secured_kinds = _console_kinds(rng, op, sp, token)
        results += _bursts("console", op, open_kinds, per_kind, _console_refused,
                           lambda: page(op))
        # the wrong tokens come from 127.0.0.1, which the console then throttles (429, a
        # refusal too); the right one, the positive control, from another loopback address
        results += _bursts("console", sp, secured_kinds, per_kind, _console_refused,
                           lambda: page(sp, "?token=" + token, "127.0.0.2"))
        results.append(_nested_messages(rng, op, per_kind, lambda: page(op)))
        results.append(_header_never_finished(op, lambda: page(op)))
        elapsed = time.monotonic() - t_start
        for name, kid in kids.items():  # 10 lines a 10 s window, then one summing up
            results.append(_alive(f"console ({name})", kid, "refused", elapsed, 12))
    finally:
        for kid in kids.values():
            kid.stop()
    return results


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--per-key", type=int, default=10_000, help="hostile messages per key")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--only",
                    default="server,clients,files,written,recordings,bridge,console,cli",
                    help="comma list of parts: server, clients, files, written, recordings, "
                         "bridge, console, cli")
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
    if "written" in parts:
        results += fuzz_written()
    if "recordings" in parts:
        results += fuzz_recordings(max(1, args.per_key // 10), args.seed)
    if "bridge" in parts:
        results += fuzz_bridge(max(1, args.per_key // 100), args.seed)
    if "console" in parts:
        results += fuzz_console(max(1, args.per_key // 100), args.seed)
    if "cli" in parts:
        results += fuzz_cli()
    print(f"fuzz: seed {args.seed}, {args.per_key} hostile messages per key, "
          f"{time.monotonic() - t0:.0f} s")
    print("| key | hostile sent | rejected | valid sent | valid processed | result |")
    print("|---|---|---|---|---|---|")
    for r in results:
        print(r.line())
    return 0 if all(r.ok for r in results) else 1


if __name__ == "__main__":
    sys.exit(main())
