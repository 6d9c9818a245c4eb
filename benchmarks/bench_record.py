"""Recorder throughput, its overhead on the live loop, and file size per minute of one robot.

1. writer throughput: how many scans per second (each with its tick's State, a teacher's
   VelCmd and label: what one robot under demonstration publishes) the recorder's writer
   (``client.recording.mcap_file.RecordingWriter``, the thread ``rhbl record`` writes with) keeps up
   with, with and without the viewer channels, on this machine's CPU.
2. the live bus: a ``rhbl server --speedup 0`` (as fast as it can) with a ``rhbl record``
   process subscribed: scans per second the server published, the share the recorder kept
   (gaps), and the recorder's CPU (user+system seconds per wall second, from /proc).
3. overhead on the live loop: a lock-step server driven by ``rhbl controller`` (every tick
   waits for the controller's command), ticks per second without and with a recorder.
4. file size per minute of one robot: a recorded 60 s in-process demonstration (``rhbl train
   --record``: the same messages a bus run of one robot publishes, 10 Hz), MB per sim minute.

    python benchmarks/bench_record.py [--seconds 10]
"""

from __future__ import annotations

import argparse
import os
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from client.recording.mcap_file import RecordingError, RecordingWriter, read_recording  # noqa: E402
from lab.children import Child, free_port, rhbl_argv  # noqa: E402
from protocol import keys  # noqa: E402
from protocol.messages import Scan, State, TeacherAction, VelCmd  # noqa: E402

ENV = {**os.environ, "PYTHONPATH": str(ROOT), "PYTHONUNBUFFERED": "1"}


def _cpu(pid: int) -> float:
    """user + system CPU seconds of a process (Linux /proc)."""
    fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def writer_throughput(tmp: Path, n: int, viewer: bool) -> float:
    rng = np.random.default_rng(0)
    ranges = rng.uniform(0.3, 8.0, (64, 360)).astype(np.float32)
    msgs = []
    for i in range(n):
        ts = i * 0.1
        pose = (1.0 + 0.01 * i, 1.0, 0.001 * i)
        msgs.append([
            (keys.state_key(), State(ts=ts, seq=i, pos=pose, truth=pose, driver="teacher").encode()),
            (keys.scan_key(), Scan(ts=ts, id=i, ranges=ranges[i % 64], pose=pose, truth=pose).encode()),
            (keys.teacher_action_key(), TeacherAction(scan_id=i, action="fwd", ts=ts).encode()),
            (keys.cmd_vel_key(source="teacher"), VelCmd(vx=0.3, source="teacher", scan_id=i, ts=ts).encode()),
        ])
    path = tmp / f"w{int(viewer)}.mcap"
    w = RecordingWriter(path, overwrite=True, viewer=viewer)
    t0 = time.perf_counter()
    now = time.time_ns()
    for i, tick in enumerate(msgs):
        for key, data in tick:
            w.write(key, data, now + i * 100_000_000)
    w.close()
    return n / (time.perf_counter() - t0)


def _start(name: str, tmp: Path, *args: str, ready: str | None = None) -> Child:
    """``rhbl ARGS...`` (output in ``tmp/<name>.log``); with ``ready``, until it printed a line
    containing it. Stopped by PID: SIGTERM, then SIGKILL (30 s each)."""
    child = Child(name, rhbl_argv(*args), tmp, env=ENV, cwd=ROOT, stop_timeout=30.0).start()
    if ready is not None and not child.wait_for_line(ready, timeout=60):
        child.stop()
        raise RuntimeError(f"{name} did not say {ready!r} within 60 s:\n{child.tail()}")
    return child


def _wait_file(path: Path, timeout: float = 30.0) -> None:
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        try:
            if path.exists() and any(m.kind == "scan" for m in read_recording(path)):
                return
        except RecordingError:  # created a moment ago: not even its header yet
            pass
        time.sleep(0.1)
    raise RuntimeError(f"{path}: nothing recorded in {timeout} s")


def live_bus(tmp: Path, seconds: float) -> dict:
    ep = f"tcp/127.0.0.1:{free_port()}"
    out = tmp / "bus.mcap"
    procs = []
    try:
        srv = _start("server", tmp, "server", "--world", "room", "--listen", ep, "--speedup", "0",
                     ready="listening on")
        procs.append(srv)
        rec = _start("rec", tmp, "record", "--out", str(out), "--overwrite", "--connect", ep,
                     "--robot", "r0")
        procs.append(rec)
        _wait_file(out)
        c0, t0 = _cpu(rec.pid), time.monotonic()
        time.sleep(seconds)
        cpu = (_cpu(rec.pid) - c0) / (time.monotonic() - t0)
        srv.stop(signal.SIGTERM)  # the bus stops; the recorder writes what it holds
        t_stop = time.monotonic()
        rec.stop(signal.SIGINT)
        drain = time.monotonic() - t_stop
    finally:
        for p in procs:
            p.stop(signal.SIGTERM)
    text = rec.output()
    backlog = int(text.split("at most ")[1].split()[0]) if "at most " in text else -1
    ids = [m.message().id for m in read_recording(out) if m.kind == "scan"]
    span = ids[-1] - ids[0] + 1
    recs = [m for m in read_recording(out) if m.kind == "scan"]
    wall = (recs[-1].log_time - recs[0].log_time) / 1e9
    return {"published_per_s": span / wall, "kept": len(ids) / span, "cpu": cpu,
            "backlog": backlog, "drain": drain}


def lockstep_rate(tmp: Path, tree: Path, seconds: float, record: bool) -> float:
    ep = f"tcp/127.0.0.1:{free_port()}"
    procs = []
    try:
        procs.append(_start("ls-server", tmp, "server", "--world", "room", "--listen", ep,
                            "--lockstep", ready="listening on"))
        if record:
            out = tmp / "ls.mcap"
            # subscribed once it says it is recording
            procs.append(_start("ls-rec", tmp, "record", "--out", str(out), "--overwrite",
                                "--connect", ep, ready="recording "))
        import zenoh

        from process.session import make_config

        ids = []
        with zenoh.open(make_config(mode="client", connect=[ep])) as s:
            sub = s.declare_subscriber(keys.scan_key(), lambda smp: ids.append(
                (time.monotonic(), Scan.decode(smp.payload.to_bytes()).id)))
            procs.append(_start("ls-controller", tmp, "controller", "--tree", str(tree),
                                "--connect", ep))
            end = time.monotonic() + 60
            while len(ids) < 20 and time.monotonic() < end:
                time.sleep(0.05)
            a = len(ids)
            time.sleep(seconds)
            b = len(ids)
            sub.undeclare()
        (t_a, _), (t_b, _) = ids[a - 1], ids[b - 1]
        return (b - a) / (t_b - t_a)
    finally:
        for p in reversed(procs):
            p.stop(signal.SIGTERM)


def size_per_minute(tmp: Path) -> tuple[float, float]:
    out, tree = tmp / "min.mcap", tmp / "min.rhbl"
    subprocess.run([sys.executable, "-m", "lab.cli", "train", "--world", "room", "--seconds",
                    "60", "--starts", "default", "--rounds", "0", "--out", str(tree), "--record",
                    str(out)], cwd=ROOT, env=ENV, check=True, capture_output=True)
    full = out.stat().st_size / 1e6
    return full, tree


def main() -> int:
    import logging

    logging.getLogger("client.recording.mcap_file").setLevel(logging.ERROR)  # polling unfinished files
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seconds", type=float, default=10.0, help="seconds per live measurement")
    ap.add_argument("--scans", type=int, default=3000, help="scans for the writer throughput")
    a = ap.parse_args()
    with tempfile.TemporaryDirectory() as d:
        tmp = Path(d)
        for viewer in (False, True):
            r = writer_throughput(tmp, a.scans, viewer)
            print(f"writer: {r:,.0f} scans/s (+ state, label, command each) "
                  f"{'with' if viewer else 'without'} viewer channels", flush=True)
        mb, tree = size_per_minute(tmp)
        print(f"file size: {mb:.2f} MB per minute of one robot under demonstration "
              f"(10 Hz, with viewer channels)", flush=True)
        bus = live_bus(tmp, a.seconds)
        print(f"live bus (server --speedup 0): {bus['published_per_s']:,.0f} scans/s published, "
              f"recorder kept {bus['kept']:.1%} of them, recorder CPU {bus['cpu']:.0%} of a core; "
              f"at most {bus['backlog']:,} messages waited to be written, {bus['drain']:.1f} s "
              f"to write them after the bus stopped", flush=True)
        base = lockstep_rate(tmp, tree, a.seconds, record=False)
        rec = lockstep_rate(tmp, tree, a.seconds, record=True)
        print(f"lock-step loop (server + controller, as fast as they go): {base:.0f} ticks/s "
              f"without a recorder, {rec:.0f} with one ({(base - rec) / base:.0%} fewer)",
              flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
