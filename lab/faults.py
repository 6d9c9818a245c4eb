"""A repeatable fault campaign against the real processes: a seed, a command, a report.

    python -m lab.faults [--seed 0] [--only learner-kill,server-restart,controller-kill,
                          learner-stop,disk-full] [--kills 20] [--restarts 5] [--out DIR]

The campaign process is the zenoh router (loopback); every ``rhbl`` process connects to it as a
client, the server too (``rhbl server --mode client``), so the campaign sees all traffic across
every fault and a killed server takes no one's network with it. Parts:

- ``learner-kill``: a demonstration (teacher, ``--seconds`` of sim time, perturbed as usual)
  while the learner is SIGKILLed ``--kills`` times at random moments (seeded) and restarted with
  the same command each time. Every label the teacher published (seen on
  ``rhbl/<robot>/teacher/action``) is compared with the labels the learner holds at the end (its
  journal's records and its snapshot's label set), by (``origin``, ``seq``): lost labels and
  duplicates are reported exactly, resends (``rhbl/<robot>/teacher/labeled``) counted.
- ``server-restart``: the server SIGKILLed and restarted ``--restarts`` times during a
  demonstration; for each restart the time from starting the new server to the first command
  that reaches the robot again (the server's driver message naming the teacher), and whether
  the learner and teacher are still alive (they resume by themselves).
- ``controller-kill``: a controller drives (a small tree trained in-process); it is SIGKILLed
  5 times and restarted; the robot's stop time (kill -> first state with zero velocity) against
  the server's ``--watchdog``.
- ``learner-stop``: the learner SIGSTOPped during a demonstration: the time until the teacher
  stops labelling (its last label after the stop), then SIGCONT: labelling resumes; labels lost
  (none expected: they are resent) and resends.
- ``disk-full``: the learner's journal writes fail (ENOSPC) for a few seconds during a
  demonstration: labels lost (the learner keeps them in memory and writes them later).

Prints a markdown report; exit status 1 if any part failed its check (a process died, a robot
did not stop, nothing resumed).
"""

from __future__ import annotations

import argparse
import math
import os
import random
import signal
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

import numpy as np

from lab.processes import free_port

ROOT = Path(__file__).resolve().parents[1]

# a learner whose journal writes fail (ENOSPC) while the file $FULL_FLAG exists: the program
# text for `python -c` (the campaign's full disk, and the learner robustness test's)
FULL_DISK_LEARNER = """
import errno, os, sys
import client.journal as j
flag = os.environ["FULL_FLAG"]
class _Os:
    def __getattr__(self, name):
        return getattr(os, name)
    def write(self, fd, data):
        if os.path.exists(flag):
            raise OSError(errno.ENOSPC, "No space left on device")
        return os.write(fd, data)
j.os = _Os()
from lab.cli import main
sys.exit(main(sys.argv[1:]))
"""



class Proc:
    """One ``rhbl`` process, output appended to ``<dir>/<name>.log``."""

    def __init__(self, name: str, argv: list[str], workdir: Path, wrapper: str | None = None,
                 env: dict | None = None) -> None:
        self.name = name
        self.log = workdir / f"{name}.log"
        pre = [sys.executable, "-c", wrapper] if wrapper else [sys.executable, "-m", "lab.cli"]
        with open(self.log, "ab") as f:
            self.p = subprocess.Popen(pre + argv, cwd=ROOT, stdout=f, stderr=subprocess.STDOUT,
                                      start_new_session=True,
                                      env={**os.environ, "PYTHONUNBUFFERED": "1", **(env or {})})
        self.started = time.monotonic()

    @property
    def pid(self) -> int:
        return self.p.pid

    def alive(self) -> bool:
        return self.p.poll() is None

    def signal(self, sig: int) -> None:
        if self.alive():
            os.kill(self.p.pid, sig)

    def kill(self) -> None:
        self.signal(signal.SIGKILL)
        self.p.wait(10)

    def stop(self, timeout: float = 30.0) -> int:
        self.signal(signal.SIGCONT)
        self.signal(signal.SIGINT)
        try:
            return self.p.wait(timeout)
        except subprocess.TimeoutExpired:
            self.kill()
            return self.p.returncode


class Campaign:
    """The router session and the processes of one part."""

    def __init__(self, workdir: Path, robot: str = "r0") -> None:
        import zenoh

        from protocol.session import make_config

        self.dir = workdir
        self.robot = robot
        self.endpoint = f"tcp/127.0.0.1:{free_port()}"
        self.session = zenoh.open(make_config(mode="router", listen=[self.endpoint]))
        self.procs: list[Proc] = []
        self.cond = threading.Condition()
        self.labels: list[tuple[float, int]] = []  # (arrival, scan id)
        self.label_ids: list[tuple[str | None, int | None]] = []  # (origin, seq) of each
        self.resent = 0  # labels resent with their scan (rhbl/<robot>/teacher/labeled)
        self.drivers: list[tuple[float, str]] = []
        self.states: list[tuple[float, tuple]] = []
        self._subs = []

    def watch(self) -> None:
        from protocol import keys
        from protocol.messages import DriverState, State, TeacherAction

        def on_label(s):
            a = TeacherAction.decode(s.payload.to_bytes())
            with self.cond:
                self.labels.append((time.monotonic(), a.scan_id))
                self.label_ids.append((a.origin, a.seq))
                self.cond.notify_all()

        def on_resent(_s):
            with self.cond:
                self.resent += 1

        def on_driver(s):
            d = DriverState.decode(s.payload.to_bytes())
            with self.cond:
                self.drivers.append((time.monotonic(), d.source))
                self.cond.notify_all()

        def on_state(s):
            st = State.decode(s.payload.to_bytes())
            with self.cond:
                self.states.append((time.monotonic(), st.vel))
                if len(self.states) > 20_000:
                    del self.states[:10_000]
                self.cond.notify_all()

        r = self.robot
        self._subs += [self.session.declare_subscriber(keys.teacher_action_key(r), on_label),
                       self.session.declare_subscriber(keys.teacher_labeled_key(r), on_resent),
                       self.session.declare_subscriber(keys.driver_key(r), on_driver),
                       self.session.declare_subscriber(keys.state_key(r), on_state)]

    def start(self, name: str, *argv: str, **kw) -> Proc:
        p = Proc(name, [*argv, "--connect", self.endpoint], self.dir, **kw)
        self.procs.append(p)
        return p

    def server(self, *extra: str) -> Proc:
        return self.start("server", "server", "--world", "room", "--mode", "client",
                          "--robot", self.robot, *extra)

    def wait(self, pred, timeout: float) -> bool:
        with self.cond:
            return self.cond.wait_for(pred, timeout)

    def close(self) -> None:
        for p in reversed(self.procs):
            if p.alive():
                p.stop()
        for s in self._subs:
            s.undeclare()
        self.session.close()


def _journal_ids(out: Path) -> tuple[list[int], int]:
    """Scan ids of the records the journal holds (from its base) and its total record count."""
    from client.journal import Journal, journal_path

    with Journal.open(journal_path(out), readonly=True) as j:
        return [r.scan_id for r in j.records(j.base)], len(j)


def _held_labels(out: Path) -> tuple[list[tuple[str, int]], set[tuple[str, int]]]:
    """The labels (origin, seq) of the journal's records (from its base, in order: a repeat is
    a duplicate) and every label the learner holds (the snapshot's label set: folded ones too)."""
    from client.behaviour.learning import load_snapshot
    from client.journal import Journal, LabelSet, journal_path

    with Journal.open(journal_path(out), readonly=True) as j:
        recs = [(r.origin, r.seq) for r in j.records(j.base) if r.origin is not None]
    held = set(recs)
    if out.exists():
        prov = load_snapshot(out)[3].get("provenance") or {}
        ls = LabelSet.from_dict((prov.get("journal") or {}).get("labels"))
        for origin in ls.origins():
            upto, above = ls.ack(origin)
            held |= {(origin, q) for q in range(upto)} | {(origin, q) for q in above}
    return recs, held


def journal_size(out: Path) -> int:
    from client.journal import journal_path

    return journal_path(out).stat().st_size


def _learner(c: Campaign, out: Path, name: str = "learner", fold: bool = False, **kw) -> Proc:
    return c.start(name, "learner", "--features", "wall", "--out", str(out),
                   "--snapshot-every", "1", *(["--fold-journal"] if fold else []), **kw)


# ------------------------------------------------------------------------------------ parts
def learner_kill(workdir: Path, rng: random.Random, kills: int, speedup: float,
                 fold: bool = False) -> dict:
    c = Campaign(workdir)
    out = workdir / "tree.rhbl"
    try:
        c.watch()
        c.server("--speedup", str(speedup))
        learner = _learner(c, out, fold=fold)
        teacher = c.start("teacher", "teacher", "--policy", "wall-follower",
                          "--wait-learner-timeout", "60")
        if not c.wait(lambda: len(c.labels) > 20, 120):
            raise RuntimeError("no labels: the demonstration did not start")
        killed: list[tuple[float, float]] = []  # (kill, the new learner's start)
        for _ in range(kills):
            time.sleep(rng.uniform(1.0, 5.0))
            t_kill = time.monotonic()
            learner.kill()
            time.sleep(rng.uniform(0.0, 1.0))
            learner = _learner(c, out, fold=fold)
            killed.append((t_kill, learner.started))
        time.sleep(5.0)
        teacher.stop()
        n_pub = len(c.labels)
        time.sleep(1.0)
        rc = learner.stop(60)
        published = {x for x in c.label_ids if x[0] is not None}
        seen = dict(zip(c.label_ids, (t for t, _ in c.labels), strict=True))
        recs, held = _held_labels(out)
        _, total = _journal_ids(out)
        lost = sorted(published - held)
        # a label can be lost only around a kill: published (seen here) from shortly before
        # the kill (in flight, not yet journaled) until the teacher paused
        stray = [x for x in lost if not any(k - 1.0 <= seen[x] <= k + 2.0 for k, _ in killed)]
        return {"part": "learner-kill", "kills": kills, "fold journal": fold,
                "labels published": n_pub,
                "distinct labels": len(published), "journaled": total,
                "labels without identity": len(c.label_ids) - len(published),
                "journal bytes": journal_size(out),
                "resent": c.resent,
                "lost": len(lost),
                "lost away from a kill": len(stray),
                "duplicates in journal": len(recs) - len(set(recs)) + max(0, total - len(held)),
                "lost labels": [f"{o[:6]}:{q}" for o, q in lost][:20],
                "learner exit": rc, "ok": rc == 0 and not lost}
    finally:
        c.close()


def server_restart(workdir: Path, rng: random.Random, restarts: int) -> dict:
    c = Campaign(workdir)
    out = workdir / "tree.rhbl"
    try:
        c.watch()
        srv = c.server("--speedup", "1")
        learner = _learner(c, out)
        teacher = c.start("teacher", "teacher", "--policy", "wall-follower",
                          "--wait-learner-timeout", "60")
        if not c.wait(lambda: any(s == "teacher" for _, s in c.drivers), 120):
            raise RuntimeError("the teacher never drove the robot")
        times = []
        for _ in range(restarts):
            time.sleep(rng.uniform(2.0, 6.0))
            srv.kill()
            time.sleep(rng.uniform(0.5, 2.0))
            mark = len(c.drivers)
            srv = c.server("--speedup", "1")
            t0 = srv.started
            ok = c.wait(lambda m=mark: any(s == "teacher" for _, s in c.drivers[m:]), 60)
            if not ok:
                times.append(math.nan)
                continue
            t = next(t for t, s in c.drivers[mark:] if s == "teacher")
            times.append(t - t0)
        alive = learner.alive() and teacher.alive()
        a = np.asarray(times)
        return {"part": "server-restart", "restarts": restarts,
                "restart -> first command at the robot, s": [round(x, 2) for x in times],
                "median s": round(float(np.nanmedian(a)), 2), "max s": round(float(np.nanmax(a)), 2),
                "learner and teacher still up": alive, "ok": alive and not np.isnan(a).any()}
    finally:
        c.close()


def _train_tree(path: Path) -> None:
    from lab.harness import make_learner, resolve_world, train
    from lab.recipe import recipe_for

    spec = resolve_world("room")
    learner = make_learner(spec.task)
    train(spec, learner, recipe_for(spec.task).replace(seconds=30.0), seed=0)
    learner.save(path)


def controller_kill(workdir: Path, rng: random.Random, watchdog: float = 0.5) -> dict:
    tree = workdir / "controller-tree.rhbl"
    _train_tree(tree)
    c = Campaign(workdir)
    try:
        c.watch()
        c.server("--speedup", "1", "--watchdog", str(watchdog))
        stops = []
        for _ in range(5):
            ctl = c.start("controller", "controller", "--tree", str(tree))
            if not c.wait(lambda: c.states and abs(c.states[-1][1][0]) > 0.05, 60):
                raise RuntimeError("the controller did not drive")
            time.sleep(rng.uniform(1.0, 3.0))
            t_kill = time.monotonic()
            ctl.kill()
            with c.cond:
                c.cond.wait_for(lambda t_kill=t_kill: c.states[-1][0] > t_kill
                                and abs(c.states[-1][1][0]) < 1e-6
                                and abs(c.states[-1][1][2]) < 1e-6, 10)
                stopped = [t for t, v in c.states if t > t_kill
                           and abs(v[0]) < 1e-6 and abs(v[2]) < 1e-6]
            stops.append(stopped[0] - t_kill if stopped else math.nan)
        a = np.asarray(stops)
        return {"part": "controller-kill", "watchdog s": watchdog,
                "kill -> robot stopped, s": [round(x, 3) for x in stops],
                "max s": round(float(np.nanmax(a)), 3),
                "ok": not np.isnan(a).any() and float(np.nanmax(a)) < watchdog + 0.5}
    finally:
        c.close()


def learner_stop(workdir: Path, stop_for: float = 20.0) -> dict:
    c = Campaign(workdir)
    out = workdir / "tree.rhbl"
    try:
        c.watch()
        c.server("--speedup", "1")
        learner = _learner(c, out)
        teacher = c.start("teacher", "teacher", "--policy", "wall-follower",
                          "--wait-learner-timeout", "0")
        if not c.wait(lambda: len(c.labels) > 20, 120):
            raise RuntimeError("no labels")
        time.sleep(3.0)
        t_stop = time.monotonic()
        learner.signal(signal.SIGSTOP)
        time.sleep(stop_for)
        after = [t for t, _ in c.labels if t > t_stop]
        noticed = (after[-1] - t_stop) if after else 0.0
        paused = not after or after[-1] < t_stop + stop_for - 2.0
        learner.signal(signal.SIGCONT)
        mark = len(c.labels)
        t_cont = time.monotonic()
        resumed = c.wait(lambda: len(c.labels) > mark + 10, 60)
        resume_s = (c.labels[mark][0] - t_cont) if resumed else math.nan
        time.sleep(2.0)
        teacher.stop()
        time.sleep(1.0)
        rc = learner.stop(60)
        lost = len(set(c.label_ids) - _held_labels(out)[1])
        return {"part": "learner-stop", "stopped for s": stop_for,
                "SIGSTOP -> teacher's last label, s": round(noticed, 2),
                "teacher paused": paused, "SIGCONT -> labels again, s": round(resume_s, 2),
                "labels lost": lost, "resent": c.resent, "learner exit": rc,
                "ok": paused and resumed and rc == 0 and lost == 0}
    finally:
        c.close()


def disk_full(workdir: Path, full_for: float = 5.0) -> dict:
    c = Campaign(workdir)
    out = workdir / "tree.rhbl"
    flag = workdir / "full"
    try:
        c.watch()
        c.server("--speedup", "2")
        learner = c.start("learner", "learner", "--features", "wall", "--out", str(out),
                          "--snapshot-every", "1", wrapper=FULL_DISK_LEARNER,
                          env={"FULL_FLAG": str(flag)})
        teacher = c.start("teacher", "teacher", "--policy", "wall-follower")
        if not c.wait(lambda: len(c.labels) > 20, 120):
            raise RuntimeError("no labels")
        flag.touch()
        time.sleep(full_for)
        flag.unlink()
        time.sleep(5.0)
        teacher.stop()
        time.sleep(1.0)
        rc = learner.stop(60)
        lost = len(set(c.label_ids) - _held_labels(out)[1])
        text = learner.log.read_text(errors="replace")
        return {"part": "disk-full", "full for s": full_for, "labels": len(c.labels),
                "labels lost": lost, "ENOSPC reported": "No space left" in text,
                "learner exit": rc, "ok": lost == 0 and rc == 0}
    finally:
        c.close()


PARTS = ["learner-kill", "server-restart", "controller-kill", "learner-stop", "disk-full"]


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--only", default=",".join(PARTS), help="comma list of parts")
    ap.add_argument("--kills", type=int, default=20, help="learner SIGKILLs (20)")
    ap.add_argument("--restarts", type=int, default=5, help="server restarts (5)")
    ap.add_argument("--fold-journal", action="store_true",
                    help="learner-kill with the learner folding its journal into snapshots")
    ap.add_argument("--speedup", type=float, default=2.0,
                    help="server speed-up during the learner kills (2)")
    ap.add_argument("--out", default=None, help="folder for logs and files (default: temp)")
    args = ap.parse_args(argv)
    rng = random.Random(args.seed)
    base = Path(args.out) if args.out else Path(tempfile.mkdtemp(prefix="rhbl-faults-"))
    results = []
    for part in args.only.split(","):
        d = base / part
        d.mkdir(parents=True, exist_ok=True)
        t0 = time.monotonic()
        try:
            if part == "learner-kill":
                r = learner_kill(d, rng, args.kills, args.speedup, fold=args.fold_journal)
            elif part == "server-restart":
                r = server_restart(d, rng, args.restarts)
            elif part == "controller-kill":
                r = controller_kill(d, rng)
            elif part == "learner-stop":
                r = learner_stop(d)
            elif part == "disk-full":
                r = disk_full(d)
            else:
                raise SystemExit(f"unknown part {part!r}; parts: {', '.join(PARTS)}")
        except Exception as e:  # noqa: BLE001 - reported, the campaign goes on
            r = {"part": part, "error": f"{type(e).__name__}: {e}", "ok": False}
        r["wall s"] = round(time.monotonic() - t0)
        results.append(r)
        print(f"- {', '.join(f'{k}: {v}' for k, v in r.items())}", flush=True)
    print(f"faults campaign: seed {args.seed}, logs in {base}: "
          f"{sum(r['ok'] for r in results)}/{len(results)} parts ok")
    return 0 if all(r["ok"] for r in results) else 1


if __name__ == "__main__":
    sys.exit(main())
