"""A repeatable fault campaign against the real processes: a seed, a command, a report.

    python -m campaigns.faults [--seed 0] [--only learner-kill,server-restart,controller-kill,
                          learner-stop,disk-full,readonly-folder,readonly-mount,
                          router-restart]
                         [--kills 20] [--restarts 5] [--router-restarts 3] [--out DIR]

The campaign process is the zenoh router (loopback); every ``rhbl`` process connects to it as a
client, the server too (``rhbl server --mode client``), so the campaign sees all traffic across
every fault and a killed server takes no one's network with it (all parts but
``router-restart``, which runs the compose scenario with its own router). Parts:

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
- ``readonly-folder``: the learner's folder made read-only (mode 0555) for a few seconds during
  a demonstration, then writable again: labels lost, the learner's error naming the folder, the
  time until a snapshot is written again. Run as root, the learner is started without the
  capabilities that let root write regardless of permissions, so the folder refuses it as it
  would any other user (EACCES).
- ``readonly-mount``: the same with a read-only bind mount of the folder over itself (EROFS;
  root only: skipped otherwise).
- ``router-restart``: docker/compose.yaml's scenario run as local processes
  (docker/compose_local.py: its router stand-in with TLS, users and access control, every
  service's command as in the compose file, restarts as their policy says); the router is
  SIGKILLed and started again with the same command ``--router-restarts`` times. For each: the
  time from the new router's start to the first command reaching the robot (the server's log:
  driver '' -> a source), to the first label the learner journals, and until every service's
  liveliness token is back (seen by an observer session with the learner's credentials); no
  service may exit.

Prints a markdown report; exit status 1 if any part failed its check (a process died, a robot
did not stop, nothing resumed).
"""

from __future__ import annotations

import argparse
import logging
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

from lab.children import Child, free_port, rhbl_argv, without_file_override

ROOT = Path(__file__).resolve().parents[1]
if str(ROOT) not in sys.path:  # `python campaigns/faults.py`: the campaigns are not installed
    sys.path.insert(0, str(ROOT))
log = logging.getLogger(__name__)

class Campaign:
    """The router session and the processes of one part."""

    def __init__(self, workdir: Path, robot: str = "r0") -> None:
        import zenoh

        from process.session import make_config

        self.dir = workdir
        self.robot = robot
        self.endpoint = f"tcp/127.0.0.1:{free_port()}"
        self.session = zenoh.open(make_config(mode="router", listen=[self.endpoint]))
        self.procs: list[Child] = []
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

    def start(self, name: str, *argv: str, prefix: list[str] | None = None,
              env: dict | None = None, preexec_fn=None) -> Child:
        """Start ``rhbl ARGV... --connect <the router>`` (or ``PREFIX ARGV...``: another entry
        point to the same commands, ``campaigns.full_disk.ARGV``),
        logging into ``<dir>/<name>.log`` (appended to: a process started again under the same
        name keeps one log); stopped with SIGINT, then SIGKILL. ``preexec_fn`` runs in the
        child before the command (:func:`lab.children.without_file_override`)."""
        argv = [*argv, "--connect", self.endpoint]
        cmd = [*prefix, *argv] if prefix else rhbl_argv(*argv)
        p = Child(name, cmd, self.dir, env={**os.environ, **(env or {})}, cwd=ROOT,
                  stop_signal=signal.SIGINT, stop_timeout=30.0, escalate=False,
                  preexec_fn=preexec_fn).start()
        self.procs.append(p)
        return p

    def server(self, *extra: str) -> Child:
        return self.start("server", "server", "--world", "room", "--mode", "client",
                          "--robot", self.robot, *extra)

    def wait(self, pred, timeout: float) -> bool:
        with self.cond:
            return self.cond.wait_for(pred, timeout)

    def close(self) -> None:
        for p in reversed(self.procs):
            p.stop()  # nothing if it already ended
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


def _learner(c: Campaign, out: Path, name: str = "learner", fold: bool = False, **kw) -> Child:
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
            killed.append((t_kill, learner.started_at))
        time.sleep(5.0)
        teacher.stop()
        n_pub = len(c.labels)
        time.sleep(1.0)
        rc = learner.stop(timeout=60)
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
            t0 = srv.started_at
            ok = c.wait(lambda m=mark: any(s == "teacher" for _, s in c.drivers[m:]), 60)
            if not ok:
                times.append(math.nan)
                continue
            t = next(t for t, s in c.drivers[mark:] if s == "teacher")
            times.append(t - t0)
        alive = learner.poll() is None and teacher.poll() is None
        a = np.asarray(times)
        return {"part": "server-restart", "restarts": restarts,
                "restart -> first command at the robot, s": [round(x, 2) for x in times],
                "median s": round(float(np.nanmedian(a)), 2), "max s": round(float(np.nanmax(a)), 2),
                "learner and teacher still up": alive, "ok": alive and not np.isnan(a).any()}
    finally:
        c.close()


def _train_tree(path: Path) -> None:
    from lab.harness import make_learner, resolve_world
    from lab.recipe import recipe_for
    from lab.train import train

    spec = resolve_world("room")
    learner = make_learner("wall-following")
    train(spec, learner, recipe_for("wall-following").replace(seconds=30.0), seed=0)
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
                # the guarantee: stopped within the watchdog (the token's release is faster)
                "ok": not np.isnan(a).any() and float(np.nanmax(a)) < watchdog}
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
        learner.pause()
        time.sleep(stop_for)
        after = [t for t, _ in c.labels if t > t_stop]
        noticed = (after[-1] - t_stop) if after else 0.0
        paused = not after or after[-1] < t_stop + stop_for - 2.0
        learner.resume()
        mark = len(c.labels)
        t_cont = time.monotonic()
        resumed = c.wait(lambda: len(c.labels) > mark + 10, 60)
        resume_s = (c.labels[mark][0] - t_cont) if resumed else math.nan
        time.sleep(2.0)
        teacher.stop()
        time.sleep(1.0)
        rc = learner.stop(timeout=60)
        lost = len(set(c.label_ids) - _held_labels(out)[1])
        return {"part": "learner-stop", "stopped for s": stop_for,
                "SIGSTOP -> teacher's last label, s": round(noticed, 2),
                "teacher paused": paused, "SIGCONT -> labels again, s": round(resume_s, 2),
                "labels lost": lost, "resent": c.resent, "learner exit": rc,
                "ok": paused and resumed and rc == 0 and lost == 0}
    finally:
        c.close()


def disk_full(workdir: Path, full_for: float = 5.0) -> dict:
    from campaigns import full_disk

    c = Campaign(workdir)
    out = workdir / "tree.rhbl"
    flag = workdir / "full"
    try:
        c.watch()
        c.server("--speedup", "2")
        learner = c.start("learner", "learner", "--features", "wall", "--out", str(out),
                          "--snapshot-every", "1", prefix=full_disk.ARGV,
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
        rc = learner.stop(timeout=60)
        lost = len(set(c.label_ids) - _held_labels(out)[1])
        text = learner.output()
        return {"part": "disk-full", "full for s": full_for, "labels": len(c.labels),
                "labels lost": lost, "ENOSPC reported": "No space left" in text,
                "learner exit": rc, "ok": lost == 0 and rc == 0}
    finally:
        c.close()


def _snapshot_records(out: Path) -> int:
    """How many journal records the snapshot ``out`` holds (-1: no snapshot yet)."""
    from client.behaviour.learning import load_snapshot

    if not out.exists():
        return -1
    meta = load_snapshot(out)[3]
    return int(((meta.get("provenance") or {}).get("journal") or {}).get("records", -1))


def _since(t0: float, pred, timeout: float = 60.0, step: float = 0.05) -> float:
    """Seconds from ``t0`` until ``pred()`` held (checked every ``step``); nan after timeout."""
    while not pred():
        if time.monotonic() - t0 > timeout:
            return math.nan
        time.sleep(step)
    return time.monotonic() - t0


def _until(pred, timeout: float, step: float = 0.05) -> float:
    """Seconds until ``pred()`` held (checked every ``step``); nan after ``timeout``."""
    return _since(time.monotonic(), pred, timeout, step)


def _lines_since(child: Child, mark: int) -> list[str]:
    """The kept lines ``child`` printed after its :meth:`~lab.children.Child.mark` ``mark``."""
    lines = list(child.lines)
    n = child.mark() - mark
    return lines[len(lines) - min(n, len(lines)):] if n > 0 else []


def _in_thread(fn) -> tuple[threading.Thread, list]:
    """Run ``fn`` in a thread; the thread and a list that holds its result once it ended."""
    out: list = []
    t = threading.Thread(target=lambda: out.append(fn()), daemon=True)
    t.start()
    return t, out


class _ReadOnly:
    """Makes a folder read-only and writable again: ``mode`` (0555, then 0755) or ``mount`` (a
    read-only bind mount of the folder over itself, then unmounted; root only)."""

    def __init__(self, folder: Path, how: str) -> None:
        if how not in ("mode", "mount"):
            raise ValueError(f"read-only how: {how!r} (mode or mount)")
        self.folder, self.how, self.on = folder, how, False

    def set(self) -> None:
        if self.how == "mode":
            self.folder.chmod(0o555)
        else:
            self._run("mount", "--bind", "-o", "ro", str(self.folder), str(self.folder))
        self.on = True

    def clear(self) -> None:
        if self.on and self.how == "mount":
            self._run("umount", str(self.folder))
        self.folder.chmod(0o755)
        self.on = False

    @staticmethod
    def _run(*cmd: str) -> None:
        r = subprocess.run(cmd, capture_output=True, text=True, timeout=30)
        if r.returncode:
            raise RuntimeError(f"{' '.join(cmd)}: {(r.stderr or r.stdout).strip()}")


def readonly_folder(workdir: Path, ro_for: float = 5.0, how: str = "mode") -> dict:
    """The learner's folder made read-only for ``ro_for`` seconds, then writable (``how``:
    :class:`_ReadOnly`). With ``mode``, run as root, the learner loses the capabilities that
    let root write anyway, so it is refused as any other user would be
    (:func:`lab.children.without_file_override`)."""
    c = Campaign(workdir)
    folder = workdir / "snapshots"
    folder.mkdir(exist_ok=True)
    folder.chmod(0o755)
    out = folder / "tree.rhbl"
    ro = _ReadOnly(folder, how)
    try:
        c.watch()
        c.server("--speedup", "2")
        learner = _learner(c, out, preexec_fn=without_file_override if os.geteuid() == 0
                           else None)
        teacher = c.start("teacher", "teacher", "--policy", "wall-follower")
        if not c.wait(lambda: len(c.labels) > 20, 120):
            raise RuntimeError("no labels")
        if math.isnan(_until(lambda: _snapshot_records(out) > 0, 30)):
            raise RuntimeError(f"the learner wrote no snapshot:\n{learner.tail()}")
        mark = learner.mark()
        ro.set()
        t_ro = time.monotonic()
        before = _snapshot_records(out)  # none can be written from now on
        reported = learner.wait_for_line("cannot write snapshot", ro_for + 5.0, since=mark)
        time.sleep(max(0.0, t_ro + ro_for - time.monotonic()))
        held = _snapshot_records(out)  # the snapshot of before: nothing new could be written
        n_ro = sum(t >= t_ro for t, _ in c.labels)
        ro.clear()
        journaled = _journal_ids(out)[1]
        again = _until(lambda: _snapshot_records(out) >= journaled, 30)
        time.sleep(2.0)
        teacher.stop()
        time.sleep(1.0)
        rc = learner.stop(timeout=60)
        lost = len(set(c.label_ids) - _held_labels(out)[1])
        said = [ln for ln in _lines_since(learner, mark) if "cannot write snapshot" in ln]
        named = bool(said) and str(folder) in said[0]
        return {"part": f"readonly-{'folder' if how == 'mode' else 'mount'}",
                "read-only for s": ro_for, "labels": len(c.labels),
                "labels while read-only": n_ro, "labels lost": lost, "error reported": reported,
                "error names the folder": named, "snapshot written while read-only": held != before,
                "writable -> snapshot written, s": round(again, 2),
                "first error": said[0][said[0].index("cannot write"):] if said else None,
                "learner exit": rc,
                "ok": lost == 0 and rc == 0 and reported and named and not math.isnan(again)}
    finally:
        ro.clear()
        c.close()


# ------------------------------------------------------------------ the compose scenario's router
def _compose_local():
    """docker/compose_local.py (the compose scenario as local processes), loaded from its file."""
    import importlib.util

    name = "compose_local"
    if name not in sys.modules:
        spec = importlib.util.spec_from_file_location(name, ROOT / "docker" / f"{name}.py")
        module = importlib.util.module_from_spec(spec)
        sys.modules[name] = module
        spec.loader.exec_module(module)
    return sys.modules[name]


def _alive_roles(session) -> set[str]:
    """The roles whose liveliness tokens the router knows now (``rhbl/alive/<role>/...``)."""
    from protocol import keys

    roles = set()
    try:
        for r in session.liveliness().get(keys.alive_key("*", "**"), timeout=1.0):
            if r.ok is not None:
                roles.add(keys.parse(r.ok.key_expr).role)
    except Exception as exc:  # noqa: BLE001 - no router yet: nobody is known
        log.debug("liveliness query failed: %s", exc)
    return roles


def _observer(scenario):
    """A client session with the learner's credentials, retrying its connection every 100 ms
    (it must see the restarted router early)."""
    import zenoh

    return zenoh.open(scenario.client_config("learner", retry_ms=100))


class _Supervised:
    """The compose scenario with docker's part done here: exited services are restarted as
    their ``restart`` policy says, while the campaign waits (only from this thread)."""

    def __init__(self, scenario) -> None:
        self.sc = scenario

    def wait(self, seconds: float, threads: tuple[threading.Thread, ...] = ()) -> None:
        """Supervise for ``seconds``, or until every one of ``threads`` ended if that is
        sooner."""
        end = time.monotonic() + seconds
        while time.monotonic() < end:
            self.sc.poll(restart_delay=1.0)
            if threads and not any(t.is_alive() for t in threads):
                return
            time.sleep(0.05)


class _Drivers:
    """Who drives the robot, as the bus says (``DriverState`` on its driver key), and when."""

    def __init__(self, session, robot: str = "r0") -> None:
        from protocol import keys
        from protocol.decoding import Decoder

        self.seen: list[tuple[float, str]] = []
        self.cond = threading.Condition()
        self.decoder = Decoder(log)
        self.sub = session.declare_subscriber(keys.driver_key(robot), self._on)

    def _on(self, sample) -> None:
        from protocol.messages import DriverState

        d = self.decoder.decode(DriverState, sample.payload.to_bytes())
        if d is not None:
            with self.cond:
                self.seen.append((time.monotonic(), d.source))
                self.cond.notify_all()

    def first_after(self, t0: float, timeout: float) -> str | None:
        """The first source that drove after ``t0`` (waiting at most ``timeout`` s)."""
        def first():
            return next((s for t, s in self.seen if t >= t0 and s), None)

        with self.cond:
            self.cond.wait_for(lambda: first() is not None, timeout)
            return first()


def _restart_router_once(sv: _Supervised, obs, drivers: _Drivers, journal: Path, down: float,
                         roles: set[str]) -> dict:
    """SIGKILL the router, ``down`` s later start it again (the same command); the seconds from
    that start to the first command reaching the robot (the server's log: driver '' -> a
    source; who it was, from the bus), to the first label journaled, and until every
    service's token is back."""
    sc = sv.sc
    router, server = sc.procs["router"], sc.procs["server"].child
    mark = server.mark()
    size0 = journal.stat().st_size
    router.exits.append(router.child.kill())  # killed here: restarted here, not by poll()
    sv.wait(down)
    router.child.start()
    t0 = router.child.started_at

    def command() -> float:
        ok = server.wait_for_line("driver '' -> '", 60, since=mark)
        return time.monotonic() - t0 if ok else math.nan

    def label() -> float:
        return _since(t0, lambda: journal.stat().st_size > size0)

    def tokens() -> float:
        return _since(t0, lambda: roles <= _alive_roles(obs), step=0.2)

    waits = [_in_thread(f) for f in (command, label, tokens)]
    sv.wait(90, tuple(t for t, _ in waits))
    cmd, lab, tok = (out[0] if out else math.nan for _, out in waits)
    return {"command": cmd, "by": drivers.first_after(t0, 10.0), "label": lab, "tokens": tok}


def router_restart(workdir: Path, rng: random.Random, restarts: int) -> dict:
    """docker/compose.yaml's scenario as local processes (docker/compose_local.py: TLS, users,
    access control); its router SIGKILLed and started again ``restarts`` times."""
    compose_local = _compose_local()
    env = {**os.environ, "RHBL_LOG_LEVEL": "INFO", "RHBL_TEACH_SECONDS": "3600",
           "RHBL_DEMONSTRATE_SECONDS": "20"}
    sc = compose_local.Scenario(workdir, free_port(), env=env)
    sv = _Supervised(sc)
    obs = None
    try:
        sc.start()
        journal = sc.data / "tree.rhbl.journal"
        roles = {n for n in sc.procs if n not in ("router", "secrets")}
        server = sc.procs["server"].child
        warm = [_in_thread(lambda: server.wait_for_line("driver '' -> '", 180)),
                _in_thread(lambda: _until(lambda: journal.exists()
                                          and journal.stat().st_size > 4096, 180))]
        sv.wait(200, tuple(t for t, _ in warm))
        obs = _observer(sc)
        if not (warm[0][1] and warm[0][1][0]) or math.isnan(_until(
                lambda: roles <= _alive_roles(obs), 120, step=0.5)):
            raise RuntimeError(
                f"the scenario did not start (tokens of {sorted(_alive_roles(obs))} of "
                f"{sorted(roles)}); server log:\n{server.tail()}")
        exits = {n: len(p.exits) for n, p in sc.procs.items()}
        drivers = _Drivers(obs)
        got = []
        for _ in range(restarts):
            sv.wait(rng.uniform(2.0, 6.0))
            got.append(_restart_router_once(sv, obs, drivers, journal, rng.uniform(0.5, 2.0),
                                            roles))
        sc.poll(restart_delay=1.0)
        died = sorted(n for n in roles if len(sc.procs[n].exits) > exits[n] or not sc.running(n))
        cmd = np.asarray([g["command"] for g in got])
        lab = np.asarray([g["label"] for g in got])
        tok = np.asarray([g["tokens"] for g in got])
        return {"part": "router-restart", "restarts": restarts,
                "restart -> first command at the robot, s": [round(float(x), 2) for x in cmd],
                "commanded by": [g["by"] for g in got],
                "restart -> first label journaled, s": [round(float(x), 2) for x in lab],
                "restart -> every service's token back, s": [round(float(x), 2) for x in tok],
                "max s": round(float(np.nanmax(np.r_[cmd, lab, tok])), 2),
                "services that exited": died,
                "ok": not died and not np.isnan(np.r_[cmd, lab, tok]).any()}
    finally:
        if obs is not None:
            obs.close()
        sc.stop()


PARTS = ["learner-kill", "server-restart", "controller-kill", "learner-stop", "disk-full",
         "readonly-folder", "readonly-mount", "router-restart"]


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--only", default=",".join(PARTS), help="comma list of parts")
    ap.add_argument("--kills", type=int, default=20, help="learner SIGKILLs (20)")
    ap.add_argument("--restarts", type=int, default=5, help="server restarts (5)")
    ap.add_argument("--router-restarts", type=int, default=3,
                    help="router restarts in the compose scenario (3)")
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
            elif part == "readonly-folder":
                r = readonly_folder(d)
            elif part == "readonly-mount" and os.geteuid() != 0:
                r = {"part": part, "skipped": "a bind mount needs root", "ok": True}
            elif part == "readonly-mount":
                r = readonly_folder(d, how="mount")
            elif part == "router-restart":
                r = router_restart(d, rng, args.router_restarts)
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
