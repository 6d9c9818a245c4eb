"""Contention probes: snapshot (see campaigns/contention/__init__.py).

The promise (docs/reliability.md, "Hostile snapshots"): a snapshot with a hostile header (sizes
huge, negative, wrapping in int64, not matching its data, of the wrong type) or hostile metadata
fails in one line that names the file, exit 2, in every command that loads one; and a learner
on the bus that gives such a tree never stops a running controller, which keeps driving its tree.

- ``cli-hostile-snapshot``: each hostile file through ``rhbl evaluate --tree``, ``rhbl compact
  --tree``, ``rhbl controller --tree`` and ``rhbl learner --resume``.
- ``follow-hostile-snapshot``: a controller ``--from-learner --follow`` driving the simulated
  robot; this probe answers its snapshot queries as a learner would, with each hostile tree in
  turn after a tree notice, then a good one: every hostile one refused (``refused_trees``), the
  good one swapped in (``swaps``), commands all along, exit 0 on SIGINT.
"""

from __future__ import annotations

import json
import subprocess
import threading
import time
from collections.abc import Callable
from pathlib import Path

import msgpack

from campaigns.contention import Outcome, Probe, ProbeFunction
from lab.children import rhbl_argv

__all__ = ["HOSTILE", "PROBES", "hostile_snapshots"]

ROOT = Path(__file__).resolve().parents[2]
BIG = 2**62


def _set(path: tuple, value) -> Callable[[dict], dict]:
    """A change of the snapshot map at ``path`` (keys into nested maps) to ``value``."""
    def change(doc: dict) -> dict:
        doc = msgpack.unpackb(msgpack.packb(doc, use_bin_type=True), raw=False)  # a deep copy
        at = doc
        for key in path[:-1]:
            at = at[key]
        at[path[-1]] = value
        return doc
    return change


def _wrap(doc: dict) -> dict:
    """2^62 spheres of 4 features and no data: 2^64 values, 0 in int64 (the defect: numpy's
    reshape failed, naming no file)."""
    for change in (_set(("radii", "shape"), [BIG]), _set(("n_features",), 4),
                   _set(("centers", "shape"), [BIG, 4]), _set(("centers", "data"), b"")):
        doc = change(doc)
    return doc


# name -> the hostile snapshot map made from a good one (a learner's)
HOSTILE: dict[str, Callable[[dict], dict]] = {
    "2^62 spheres of 4 features, no data": _wrap,
    "n_features 2^62": _set(("n_features",), BIG),
    "n_features negative": _set(("n_features",), -1),
    "n_features a boolean": _set(("n_features",), True),
    "spheres 2^63 - 1": _set(("radii", "shape"), [2**63 - 1]),
    "centers data short": lambda d: _set(("centers", "data"), d["centers"]["data"][:-8])(d),
    "centers shape a string": _set(("centers", "shape"), "4x5"),
    "counters a float": _set(("counters", "n_seen"), 1.5),
    "labels a map": _set(("labels",), {"a": 1}),
    "metadata features malformed": _set(("metadata", "features"), {"kind": 5}),
    "metadata without actions": lambda d: _set(("metadata",), {
        k: v for k, v in d["metadata"].items() if k != "actions"})(d),
}


def _good_tree(path: Path) -> None:
    """A small tree a learner would write (5 s of the scripted teacher in the room)."""
    from lab.harness import make_learner, resolve_world
    from lab.recipe import recipe_for
    from lab.train import train

    spec = resolve_world("room")
    learner = make_learner("wall-following")
    train(spec, learner, recipe_for("wall-following").replace(seconds=5.0), seed=0)
    learner.save(path)


def hostile_snapshots(folder: Path, names: list[str]) -> tuple[Path, dict[str, Path]]:
    """A good snapshot in ``folder`` and the hostile ones named (files named after them)."""
    good = folder / "good.rhbl"
    _good_tree(good)
    doc = msgpack.unpackb(good.read_bytes(), raw=False)
    files = {}
    for name in names:
        files[name] = folder / (name.replace(" ", "-").replace("^", "") + ".rhbl")
        files[name].write_bytes(msgpack.packb(HOSTILE[name](doc), use_bin_type=True))
    return good, files


def _chosen(probe: Probe) -> list[str]:
    """Every hostile case (--size full), or the defect's and two more (ci)."""
    names = list(HOSTILE)
    if probe.full:
        return names
    return [names[0], *probe.rng.sample(names[1:], 2)]


def _one_error_line(text: str, path: Path, process: bool) -> str | None:
    """What is wrong with a command's output for a hostile ``path``: None when it said so in
    one line naming the file (a process's one ERROR line among its log lines)."""
    if "Traceback" in text:
        return "a traceback"
    lines = [ln for ln in text.splitlines() if ln.strip()]
    if process:
        lines = [ln for ln in lines if " ERROR " in ln]
    if len(lines) != 1:
        return f"{len(lines)} error lines"
    if str(path) not in lines[0]:
        return f"a line not naming the file: {lines[0][:160]}"
    return None


def cli_hostile_snapshot(probe: Probe) -> Outcome:
    from campaigns.faults import Campaign

    names = _chosen(probe)
    _good, files = hostile_snapshots(probe.workdir, names)
    c = Campaign(probe.workdir)  # a router for the controller to connect to
    try:
        commands = {
            "evaluate": lambda p: ["evaluate", "--tree", str(p), "--world", "room"],
            "compact": lambda p: ["compact", "--tree", str(p), "--out",
                                  str(probe.workdir / f"compacted-{time.monotonic_ns()}.rhbl")],
            "controller": lambda p: ["controller", "--tree", str(p), "--connect", c.endpoint],
            "learner": lambda p: ["learner", "--resume", str(p), "--out",
                                  str(probe.workdir / f"resumed-{time.monotonic_ns()}.rhbl"),
                                  "--connect", c.endpoint],
        }
        failures, runs, worst = [], 0, 0.0
        for name, path in files.items():
            for command, argv in commands.items():
                t0 = time.monotonic()
                r = subprocess.run(rhbl_argv(*argv(path)), cwd=ROOT, capture_output=True,
                                   text=True, timeout=180)
                worst = max(worst, time.monotonic() - t0)
                runs += 1
                wrong = _one_error_line(r.stderr, path, process=command in ("controller",
                                                                            "learner"))
                if r.returncode != 2:
                    wrong = f"exit {r.returncode}" + (f", {wrong}" if wrong else "")
                if wrong:
                    failures.append(f"{command} {name}: {wrong}")
    finally:
        c.close()
    figures = {"files": len(files), "runs": runs, "failed": len(failures),
               "slowest s": round(worst, 1)}
    if failures:
        return Outcome(False, "; ".join(failures[:3]), figures)
    return Outcome(True, f"{runs} runs ({len(files)} hostile files x evaluate, compact, "
                         f"controller, learner --resume): each exit 2 with one line naming "
                         f"the file", figures)


class _FakeLearner:
    """Answers the controller's snapshot queries with ``self.data`` and counts them."""

    def __init__(self, session, robot: str, data: bytes) -> None:
        from protocol import keys

        self.data, self.queries = data, 0
        self.cond = threading.Condition()
        self.session, self.robot = session, robot
        self.queryable = session.declare_queryable(keys.learner_snapshot_key(robot), self._on)
        self.notices = session.declare_publisher(keys.learner_notice_key(robot))
        self.seq = 0

    def _on(self, query) -> None:
        with self.cond:
            data = self.data
        query.reply(query.key_expr, data)
        with self.cond:
            self.queries += 1
            self.cond.notify_all()

    def offer(self, data: bytes, timeout: float = 30.0) -> bool:
        """Give ``data`` from now on, announce it, and wait until it was asked for."""
        from protocol.messages import TreeNotice

        with self.cond:
            self.data, before = data, self.queries
        self.seq += 1
        self.notices.put(TreeNotice(seq=self.seq, nodes=1, height=1).encode())
        with self.cond:
            return self.cond.wait_for(lambda: self.queries > before, timeout)

    def close(self) -> None:
        self.queryable.undeclare()
        self.notices.undeclare()


def follow_hostile_snapshot(probe: Probe) -> Outcome:
    from campaigns.faults import Campaign

    names = _chosen(probe)
    good, files = hostile_snapshots(probe.workdir, names)
    stats = probe.workdir / "controller.json"
    c = Campaign(probe.workdir)
    fake = _FakeLearner(c.session, c.robot, good.read_bytes())
    try:
        c.watch()
        c.server("--speedup", "1")
        ctl = c.start("controller", "controller", "--from-learner", "--follow",
                      "--query-timeout", "5", "--stats", str(stats))
        if not c.wait(lambda: c.states and abs(c.states[-1][1][0]) > 0.05, 90):
            return Outcome(False, f"the controller did not drive the good tree:\n{ctl.tail()}")
        asked = [fake.offer(path.read_bytes()) for path in files.values()]
        # the good tree again, asked for last: every hostile one was judged before it
        asked.append(fake.offer(good.read_bytes()))
        t_last = time.monotonic()
        driving = c.wait(lambda: c.states[-1][0] > t_last + 2.0, 30) and any(
            abs(v[0]) > 0.05 for t, v in c.states if t > t_last)
        alive = ctl.poll() is None
        rc = ctl.stop()
    finally:
        fake.close()
        c.close()
    counters = json.loads(stats.read_text()) if stats.exists() else {}
    refused, swaps = counters.get("refused_trees"), counters.get("swaps")
    lines = [ln for ln in ctl.output().splitlines() if "could not swap the tree" in ln]
    figures = {"hostile trees": len(files), "refused_trees": refused, "swaps": swaps,
               "commands": counters.get("commands")}
    wrong = []
    if not all(asked):
        wrong.append(f"the controller asked for {sum(asked)} of {len(asked)} announced trees")
    if not alive or rc != 0:
        wrong.append(f"the controller {'ended' if not alive else 'exited'} with {rc}")
    if refused != len(files) or swaps is None or swaps < 1:
        wrong.append(f"refused_trees {refused} (of {len(files)}), swaps {swaps}")
    if len(lines) != len(files) or not all("learner snapshot" in ln for ln in lines):
        wrong.append(f"{len(lines)} lines for {len(files)} refusals, each to name the source")
    if not driving:
        wrong.append("the robot did not keep driving")
    if wrong:
        return Outcome(False, "; ".join(wrong), figures)
    return Outcome(True, f"{len(files)} hostile trees from the bus refused in one line each "
                         f"naming the learner's snapshot; the good one swapped in after them, "
                         f"the robot driven all along", figures)


PROBES: dict[str, ProbeFunction] = {
    "cli-hostile-snapshot": cli_hostile_snapshot,
    "follow-hostile-snapshot": follow_hostile_snapshot,
}
