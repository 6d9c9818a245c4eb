"""Teaching by hand, measured: person models drive the real console page in a real headless
Chromium, and the tree they taught is evaluated.

Per run (one person model, one seed): a real ``rhbl server`` (the room world, real
time), a real ``rhbl learner``, a real ``rhbl console`` and Debian's Chromium on the page
(selenium). The person (``benchmarks/people.py``: ``PEOPLE[name](seed=...)``) is fed what the
page shows at each frame (``window.rhbl.view()``: the page's clock, the robot as drawn, the
walls, the mode, who drives, the action executed, the scan displayed) and the keys it holds are
pressed and released on the page like a person's (selenium key events: arrows, ``Home``, ``C``).

1. demonstrate: the robot at its start pose (``Home``), the person drives for ``--demo`` s;
2. correct: a ``rhbl controller --from-learner --follow`` drives the learner's tree, the page in
   correct mode (``C``): the person takes over when they judge it necessary, for ``--correct`` s;
3. the learner's saved tree is evaluated (``lab.evaluate``) from every start pose of the room it
   was taught in and of the unseen rooms (``--unseen``).

The table gives per run and per model (mean over its seeds) the success in the taught room and
in the unseen rooms, the oscillation loops and collisions in those evaluations, the tree's size,
the labels (given at the page; standing in the learner's journal) and what the person saw (the
views of the page they decided on per second, the page's own frame rate). With ``--learners
default,literal`` (the default) the session is also recorded (``rhbl record``) and the paper's
literal algorithm (``--literal-args``, default ``--teacher script --spawn all``: each label
learned as it arrives, with the scan it names, every sphere spawned) is retrained from that
recording (``rhbl train --from-recording``, the live learner's own pairing) and evaluated the
same way: a baseline on exactly the labels the person taught the default learner, corrections
included (given while the default learner's tree drove), at no extra session.

    python benchmarks/bench_teach.py --people steady,hurried --seeds 0,1,2 \
        [--demo 240] [--correct 120] [--learners default[,literal]] [--jobs 2] [--json out.json]

``--people`` takes names, ``dev``, ``held-out``, ``fresh`` or ``all``. The budget per run is at most 240 s
demonstrating plus 120 s correcting (real time). ``--jobs 2`` runs two sessions at once, each
with its own server, ports, console and browser (the views/s and frames/s columns say whether
the machine kept up: compare them with a single run's).
"""

from __future__ import annotations

import argparse
import concurrent.futures
import contextlib
import json
import math
import shlex
import signal
import statistics
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "tests" / "integration"))
sys.path.insert(0, str(ROOT / "benchmarks"))

MAX_DEMO, MAX_CORRECT = 240.0, 120.0
UNSEEN = ("eval-room-jagged", "eval-room-l", "eval-room-ring")
LITERAL = "--teacher script --spawn all"  # rhbl train --from-recording: the paper's rule
# the keys held for each action (the page combines them as a person's fingers do)
ARROWS = {None: (), "fwd": ("ARROW_UP",), "fwd-left": ("ARROW_UP", "ARROW_LEFT"),
          "rot-left": ("ARROW_LEFT",), "fwd-right": ("ARROW_UP", "ARROW_RIGHT"),
          "rot-right": ("ARROW_RIGHT",)}


class Page:
    """The console page in a browser, as a person sees and touches it."""

    def __init__(self, browser, url: str):
        from selenium.webdriver.support.ui import WebDriverWait

        self.b = browser
        browser.get(url)
        WebDriverWait(browser, 30, poll_frequency=0.05).until(
            lambda d: (v := self.view_raw()) and v["link"] == "open" and v["pose"]
            and v["walls"] and v["t"] is not None)
        browser.find_element("id", "view").click()  # the keys reach the page
        self.held: set[str] = set()
        self._walls = None

    def view_raw(self) -> dict:
        return self.b.execute_script("return window.rhbl ? window.rhbl.view() : null")

    def view(self, people):
        """A ``people.View`` of what the page shows now (None before a pose and a clock)."""
        v = self.view_raw()
        if not v or v["pose"] is None or v["t"] is None:
            return None
        if self._walls is None or len(self._walls) != len(v["walls"]):
            self._walls = np.asarray(v["walls"], dtype=float).reshape(-1, 4)
        return people.View(t=float(v["t"]), pose=tuple(float(x) for x in v["pose"]),
                           walls=self._walls, mode=v["mode"], driver=v["driver"] or "",
                           action=v["action"], scan_id=v["scan_id"])

    def hold(self, action: str | None) -> None:
        """Hold the keys of ``action`` (None: none), releasing the others."""
        from selenium.webdriver.common.action_chains import ActionChains
        from selenium.webdriver.common.keys import Keys

        want = set(ARROWS[action])
        if want == self.held:
            return
        chain = ActionChains(self.b)
        for k in sorted(self.held - want):
            chain = chain.key_up(getattr(Keys, k))
        for k in sorted(want - self.held):
            chain = chain.key_down(getattr(Keys, k))
        chain.perform()
        self.held = want

    def press(self, key: str) -> None:
        from selenium.webdriver.common.action_chains import ActionChains
        from selenium.webdriver.common.keys import Keys

        k = getattr(Keys, key) if len(key) > 1 else key
        ActionChains(self.b).key_down(k).key_up(k).perform()

    def data(self, el: str, name: str) -> str:
        return self.b.find_element("id", el).get_attribute(f"data-{name}") or ""

    def until(self, pred, timeout: float, what: str) -> None:
        from selenium.common.exceptions import TimeoutException
        from selenium.webdriver.support.ui import WebDriverWait

        try:
            WebDriverWait(self.b, timeout, poll_frequency=0.05).until(lambda d: pred(self))
        except TimeoutException:
            raise RuntimeError(f"the page: not within {timeout:g} s: {what}") from None


def teach(page: Page, person, people, seconds: float, mode: str) -> dict:
    """The person at the page for ``seconds`` of the page's clock; what they did."""
    v = None
    while v is None:
        v = page.view(people)
    t0, frames, keys_held, presses = v.t, 0, 0, 0
    w0 = time.monotonic()
    last = None
    fps, next_fps = [], w0 + 1.0  # the page's own frame rate, read once a second
    while True:
        v = page.view(people)
        if v is None:
            continue
        if v.t - t0 >= seconds:
            break
        if time.monotonic() >= next_fps:
            next_fps += 1.0
            with contextlib.suppress(ValueError):
                fps.append(float(page.data("fps", "fps")))
        key = person.observe(v)
        if key != last:
            presses += key is not None
            last = key
        page.hold(key)
        frames += 1
        keys_held += key is not None
    page.hold(None)
    wall = time.monotonic() - w0
    return {"mode": mode, "seconds": round(v.t - t0, 2), "frames": frames,
            "frames_with_a_key": keys_held, "presses": presses,
            # what the person saw: the views they decided on per wall second, and the page's
            # frames per second (its #fps, once a second: median and the lowest tenth)
            "person_hz": round(frames / wall, 1) if wall > 0 else None,
            "page_fps": round(statistics.median(fps), 1) if fps else None,
            "page_fps_p10": round(sorted(fps)[len(fps) // 10], 1) if fps else None}


def _labels(page: Page) -> dict:
    return {k: int(page.data("labels", k) or 0) for k in ("given", "held", "waiting",
                                                          "withdrawn")}


def teach_one(person_name: str, seed: int, demo: float, correct: float, *,
              record: bool = False, learner_args: str = "", world: str = "room",
              workdir: Path | None = None, log=print) -> dict:
    """A person teaches at the page: demonstrating, then correcting (see the module); what they
    did and the learner's tree (``tree_path``), not evaluated yet. ``record``: a ``rhbl
    record`` of the session too (``recording``), for the literal baseline (``literal_run``)."""
    import people
    import zenoh  # noqa: F401 - fail early without it
    from browser import ConsoleProcess, chromium, close_chromium

    from lab.children import Child, rhbl_argv
    from tests.conftest import _server_factory

    work = Path(workdir or tempfile.mkdtemp(prefix="rhbl-bench-teach-"))
    work.mkdir(parents=True, exist_ok=True)
    out = work / "tree.rhbl"
    extra = shlex.split(learner_args)
    started, children, browser = [], [], None
    result = {"person": person_name, "seed": seed, "learner": "default",
              "learner_args": " ".join(extra), "world": world,
              "demo_budget": demo, "correct_budget": correct, "workdir": str(work)}
    t_start = time.monotonic()
    try:
        srv = _server_factory(started)(world)
        if record:  # every message of the session, before any label can be given
            rec = Child("recorder", rhbl_argv("record", "--out", str(work / "session.mcap"),
                                              "--connect", srv.endpoint), work, cwd=ROOT,
                        stop_signal=signal.SIGINT, stop_timeout=60.0).start()
            children.append(rec)
            if not rec.wait_for_line("recording ", 60):
                raise RuntimeError(f"the recorder did not start:\n{rec.output()[-2000:]}")
            result["recording"] = str(work / "session.mcap")
        lrn = Child("learner", rhbl_argv("learner", "--features", "wall", "--out", str(out),
                                         "--snapshot-every", "1", "--stats",
                                         str(work / "learner.json"), "--connect", srv.endpoint,
                                         *extra), work, cwd=ROOT, stop_signal=signal.SIGINT,
                    stop_timeout=60.0).start()
        children.append(lrn)
        console = ConsoleProcess(srv.endpoint, "--stats", str(work / "console.json"))
        children.append(console)
        url = console.wait_url()
        browser = chromium()
        page = Page(browser, url)
        page.until(lambda p: p.data("learner", "up") == "1", 60, "a learner is up")
        person = people.PEOPLE[person_name](seed=seed)
        person.reset()
        page.press("HOME")  # the robot at its start pose
        page.until(lambda p: "reset" in p.b.find_element("id", "info").text, 10, "reset")
        log(f"  {person_name} seed {seed}: demonstrating {demo:g} s")
        result["demonstrate"] = teach(page, person, people, demo, "demonstrate")
        result["labels_demonstrated"] = _labels(page)["given"]
        ctl = Child("controller", rhbl_argv("controller", "--from-learner", "--follow",
                                            "--connect", srv.endpoint), work, cwd=ROOT,
                    stop_signal=signal.SIGINT, stop_timeout=30.0).start()
        children.append(ctl)
        page.press("c")  # correct mode
        page.until(lambda p: (p.view_raw() or {}).get("driver", "").startswith("controller"),
                   60, "the controller drives the learner's tree")
        log(f"  {person_name} seed {seed}: correcting {correct:g} s")
        result["correct"] = teach(page, person, people, correct, "correct")
        result["loop_marks"] = int(page.data("trouble", "loops") or 0)
        result["collision_marks"] = int(page.data("trouble", "collisions") or 0)
        result["agreement"] = page.data("agreement", "value")
        ctl.stop()
        page.press("t")
        t_ack = time.monotonic()  # a learner behind its teacher catches up now: how long
        page.until(lambda p: _labels(p)["waiting"] == 0, 600, "every label acknowledged")
        result["ack_wait_s"] = round(time.monotonic() - t_ack, 1)
        result["labels"] = _labels(page)
        console.stop()
        rc = lrn.stop()
        if rc != 0:
            raise RuntimeError(f"the learner exited {rc}:\n{lrn.output()[-2000:]}")
        if record and (rc := rec.stop()) != 0:
            raise RuntimeError(f"the recorder exited {rc}:\n{rec.output()[-2000:]}")
    finally:
        if browser is not None:
            close_chromium(browser)
        for c in reversed(children):
            with contextlib.suppress(Exception):
                c.stop()
        for s in started:
            with contextlib.suppress(Exception):
                s.stop()
    result["teaching_wall_s"] = round(time.monotonic() - t_start, 1)
    stats = json.loads((work / "learner.json").read_text())
    result["labels_standing"] = stats.get("standing")
    result["rule"] = stats.get("rule")  # the rule the learner's lineage took
    result["tree_path"] = str(out)
    return result


def literal_run(result: dict, literal_args: str = LITERAL) -> dict:
    """The paper's literal algorithm on the very labels of a run (the baseline): its recording
    retrained (``rhbl train --from-recording``, the live learner's pairing; ``literal_args``,
    by default the scripted rule, no lag, every sphere spawned); a result to evaluate like the
    run's own. Its labels are those the person taught the default learner, corrections
    included (given while the default learner's tree drove)."""
    from lab.children import rhbl_argv

    work = Path(result["workdir"])
    out = work / "literal.rhbl"
    argv = rhbl_argv("train", "--from-recording", result["recording"], "--features", "wall",
                     *shlex.split(literal_args), "--out", str(out))
    t0 = time.monotonic()
    done = subprocess.run(argv, cwd=ROOT, capture_output=True, text=True, timeout=3600)
    if done.returncode != 0:
        raise RuntimeError(f"retraining the literal baseline exited {done.returncode}: "
                           f"{done.stdout[-500:]}{done.stderr[-1000:]}")
    line = next(ln for ln in done.stdout.splitlines() if ln.startswith("trained from"))
    paired = int(line.split(": ", 1)[1].split(" labeled", 1)[0])
    keep = ("person", "seed", "world", "demo_budget", "correct_budget", "workdir", "labels",
            "demonstrate", "correct", "labels_demonstrated")
    return {**{k: result[k] for k in keep if k in result}, "learner": "literal",
            "learner_args": literal_args, "rule": "literal", "tree_path": str(out),
            "labels_standing": paired, "retrain_s": round(time.monotonic() - t0, 1)}


def evaluate_run(result: dict, world: str = "room", unseen=UNSEEN,
                 eval_episodes: int | None = None, eval_seconds: float | None = None,
                 tag: str = "") -> dict:
    """Evaluate a run's tree (``rhbl evaluate``, i.e. ``lab.evaluate``, in its own process, with
    its defaults: a tree taught by hand through the controller's guard) in the room it was
    taught in and in the unseen rooms; the figures added to ``result`` (each room's report in
    the run's folder, ``eval<tag>-<learner>-<room>.json``: default and literal share it)."""
    from lab.children import rhbl_argv

    work = Path(result["workdir"])
    result["eval"] = {}
    for name in (world, *unseen):
        out = work / f"eval{tag}-{result['learner']}-{name}.json"  # default, literal
        argv = rhbl_argv("evaluate", "--world", name, "--tree", result["tree_path"],
                         "--seed", str(result["seed"]), "--json", str(out))
        if eval_episodes is not None:
            argv += ["--episodes", str(eval_episodes)]
        if eval_seconds is not None:
            argv += ["--seconds", str(eval_seconds)]
        done = subprocess.run(argv, cwd=ROOT, capture_output=True, text=True, timeout=3600)
        if done.returncode != 0:
            raise RuntimeError(f"rhbl evaluate --world {name} exited {done.returncode}: "
                               f"{done.stdout[-500:]}{done.stderr[-1000:]}")
        rep = json.loads(out.read_text())
        result["tree"] = rep["tree"]
        result["eval"][name] = {
            "success_rate": rep["success_rate"], "episodes": rep["episodes"],
            "loops": len(rep["loops"]),
            "collisions": int(sum(e["collisions"] for e in rep["learner"])),
            "wall_band": round(statistics.fmean(e["wall_band_fraction"] for e in rep["learner"]), 3),
            "teacher_success_rate": rep["teacher_success_rate"], "guard": rep.get("guard")}
    taught = result["eval"][world]
    others = [result["eval"][n] for n in unseen]
    result["success_taught"] = taught["success_rate"]
    result["success_unseen"] = (statistics.fmean(e["success_rate"] for e in others)
                                if others else None)
    result["loops"] = sum(e["loops"] for e in result["eval"].values())
    result["loops_taught"] = taught["loops"]
    result["collisions"] = sum(e["collisions"] for e in result["eval"].values())
    return result


def run_one(person_name: str, seed: int, demo: float, correct: float, *, world: str = "room",
            unseen=UNSEEN, eval_episodes: int | None = None, eval_seconds: float | None = None,
            literal: str | None = None, **kw) -> list[dict]:
    """One run, taught then evaluated (see the module); its figures, then (``literal``: the
    literal algorithm's options) the literal baseline's on the same labels."""
    r = teach_one(person_name, seed, demo, correct, world=world, record=literal is not None,
                  **kw)
    out = [evaluate_run(r, world, unseen, eval_episodes, eval_seconds)]
    if literal is not None:
        out.append(evaluate_run(literal_run(r, literal), world, unseen, eval_episodes,
                                eval_seconds))
    return out


def _pct(v) -> str:
    return "-" if v is None or (isinstance(v, float) and math.isnan(v)) else f"{100 * v:.0f}%"


def _rate(r: dict, key: str) -> str:
    vals = [r[m][key] for m in ("demonstrate", "correct") if r.get(m, {}).get(key) is not None]
    return f"{min(vals):.0f}" if vals else "-"


def table(results: list[dict]) -> str:
    """The runs, then per person model and learner the means over its seeds (markdown)."""
    rows = ["| person | learner | seed | taught room | unseen rooms | loops | collisions | "
            "tree nodes | labels given | labels standing | person views/s | page frames/s "
            "(low tenth) |",
            "|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for r in results:
        if "error" in r:
            rows.append(f"| {r['person']} | {r['learner']} | {r['seed']} | failed: "
                        f"{r['error'][:60]} | | | | | | | | |")
            continue
        rows.append(f"| {r['person']} | {r['learner']} | {r['seed']} | {_pct(r['success_taught'])} "
                    f"| {_pct(r['success_unseen'])} | {r['loops']} | {r['collisions']} | "
                    f"{r['tree']['nodes']} | {r['labels']['given']} | {r['labels_standing']} | "
                    f"{_rate(r, 'person_hz')} | {_rate(r, 'page_fps')} "
                    f"({_rate(r, 'page_fps_p10')}) |")
    rows += ["", "| person | learner | runs | taught room (mean, worst) | unseen rooms (mean, worst) | "
             "loops (mean) | collisions (mean) | tree nodes (mean) | labels (mean) |",
             "|---|---|---|---|---|---|---|---|---|"]
    groups: dict[tuple[str, str], list[dict]] = {}
    for r in results:
        if "error" not in r:
            groups.setdefault((r["person"], r["learner"]), []).append(r)
    for (p, lrn), rs in groups.items():
        def mean(f, rs=rs):
            return statistics.fmean(f(r) for r in rs)
        taught = [r["success_taught"] for r in rs]
        unseen = [r["success_unseen"] or 0.0 for r in rs]
        rows.append(f"| {p} | {lrn} | {len(rs)} | {_pct(statistics.fmean(taught))} "
                    f"({_pct(min(taught))}) | {_pct(statistics.fmean(unseen))} "
                    f"({_pct(min(unseen))}) | "
                    f"{mean(lambda r: r['loops']):.1f} | {mean(lambda r: r['collisions']):.1f} | "
                    f"{mean(lambda r: r['tree']['nodes']):.0f} | "
                    f"{mean(lambda r: r['labels']['given']):.0f} |")
    return "\n".join(rows)


def _names(text: str, people) -> list[str]:
    if text == "all":
        return list(people.PEOPLE)
    if text == "dev":
        return list(people.DEV)
    if text == "held-out":
        return list(people.HELD_OUT)
    if text == "fresh":
        return list(people.FRESH)
    names = [n for n in text.split(",") if n]
    bad = [n for n in names if n not in people.PEOPLE]
    if bad or not names:
        raise ValueError(f"--people: unknown {', '.join(bad) or '(none)'}; one of "
                         f"{', '.join(people.PEOPLE)}, dev, held-out, fresh, all")
    return names


def parse_seeds(text: str, option: str = "--seeds") -> list[int]:
    """A comma list of seeds (integers >= 0); ValueError naming ``option`` otherwise."""
    try:
        seeds = [int(s) for s in text.split(",") if s.strip()]
    except ValueError:
        raise ValueError(f"{option} must be integers separated by commas, got {text!r}") from None
    if not seeds or any(s < 0 for s in seeds):
        raise ValueError(f"{option} must be integers >= 0, got {text!r}")
    return seeds


def _evaluate_again(args) -> int:
    """``--evaluate-again``: the saved runs' trees evaluated again (see ``main``)."""
    try:
        runs = json.loads(Path(args.evaluate_again).read_text())
        trees = [Path(r["tree_path"]) for r in runs]
    except (OSError, ValueError, KeyError, TypeError) as exc:
        print(f"bench_teach: error: --evaluate-again {args.evaluate_again}: {exc}",
              file=sys.stderr)
        return 2
    if missing := [str(t) for t in trees if not t.is_file()]:
        print(f"bench_teach: error: --evaluate-again: trees not found: {', '.join(missing)}",
              file=sys.stderr)
        return 2
    unseen = [x for x in args.unseen.split(",") if x]
    for r in runs:
        evaluate_run(r, world=args.world, unseen=unseen, eval_episodes=args.eval_episodes,
                     eval_seconds=args.eval_seconds, tag="-again")
        print(f"{r['person']} seed {r['seed']} {r['learner']}: taught "
              f"{_pct(r['success_taught'])}, unseen {_pct(r['success_unseen'])}, loops "
              f"{r['loops']}, collisions {r['collisions']}", flush=True)
    if args.json:
        Path(args.json).write_text(json.dumps(runs, indent=1))
    print(table(runs))
    return 0


def main(argv=None) -> int:
    import people

    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--people", default="dev", help="names, dev, held-out, fresh or all (default dev; "
                                                "benchmarks/people.py)")
    ap.add_argument("--seeds", default="0,1,2", help="seeds, e.g. 0,1,2 (default)")
    ap.add_argument("--demo", type=float, default=MAX_DEMO,
                    help=f"seconds demonstrating per run (at most {MAX_DEMO:g}; default)")
    ap.add_argument("--correct", type=float, default=MAX_CORRECT,
                    help=f"seconds correcting per run (at most {MAX_CORRECT:g}; default)")
    ap.add_argument("--learners", default="default,literal",
                    help="default (the learner's defaults) or default,literal (default: also "
                         "the paper's literal algorithm as a baseline, learned from the same "
                         "session's labels: its recording retrained)")
    ap.add_argument("--literal-args", default=LITERAL,
                    help=f"the literal baseline's rhbl train --from-recording options (default "
                         f"{LITERAL!r})")
    ap.add_argument("--learner-args", default="",
                    help="the learner's options for the default runs (default: none, the "
                         "learner's own defaults: --teacher auto takes the person rule for the "
                         "page's labels)")
    ap.add_argument("--jobs", type=int, default=1,
                    help="sessions at once (1 or 2; each its own server, ports, console and "
                         "browser): check the person views/s and page frames/s columns against "
                         "a single run")
    ap.add_argument("--world", default="room", help="the room taught in (default room)")
    ap.add_argument("--unseen", default=",".join(UNSEEN),
                    help=f"unseen rooms, comma-separated (default {','.join(UNSEEN)})")
    ap.add_argument("--eval-episodes", type=int, default=None,
                    help="episodes per evaluated room (default: one per start pose)")
    ap.add_argument("--eval-seconds", type=float, default=None,
                    help="sim seconds per evaluated episode (default: rhbl evaluate's)")
    ap.add_argument("--json", default=None, help="write every run's figures here")
    ap.add_argument("--workdir", default=None, help="keep each run's logs and tree under here")
    ap.add_argument("--table", default=None, metavar="JSON",
                    help="no session: print the table of the runs a --json file holds (those "
                         "of --people only, when given)")
    ap.add_argument("--evaluate-again", default=None, metavar="JSON",
                    help="no session: evaluate the trees of the runs a --json file holds again "
                         "with this checkout's rhbl evaluate (--world, --unseen, --eval-*), "
                         "print their table and, with --json, write it")
    args = ap.parse_args(argv)
    if args.evaluate_again:
        return _evaluate_again(args)
    if args.table:
        try:
            runs = json.loads(Path(args.table).read_text())
            if "--people" in (argv if argv is not None else sys.argv):
                keep = set(_names(args.people, people))
                runs = [r for r in runs if r["person"] in keep]
        except (OSError, ValueError, KeyError, TypeError) as exc:
            print(f"bench_teach: error: --table {args.table}: {exc}", file=sys.stderr)
            return 2
        print(table(runs))
        return 0
    try:
        names = _names(args.people, people)
        seeds = parse_seeds(args.seeds)
        if not 0 < args.demo <= MAX_DEMO or not 0 < args.correct <= MAX_CORRECT:
            raise ValueError(f"--demo must be in (0, {MAX_DEMO:g}] and --correct in "
                             f"(0, {MAX_CORRECT:g}] seconds")
        learners = [x for x in args.learners.split(",") if x]
        if learners not in (["default"], ["default", "literal"]):
            raise ValueError(f"--learners: default or default,literal (the literal baseline "
                             f"learns the default run's labels), got {args.learners!r}")
        if args.jobs not in (1, 2):
            raise ValueError(f"--jobs must be 1 or 2, got {args.jobs}")
        unseen = [x for x in args.unseen.split(",") if x]
        from lab.harness import resolve_world

        for w in (args.world, *unseen):
            resolve_world(w)
        if args.eval_episodes is not None and args.eval_episodes < 1:
            raise ValueError("--eval-episodes must be >= 1")
        if args.eval_seconds is not None and not args.eval_seconds > 0:
            raise ValueError("--eval-seconds must be > 0")
    except Exception as exc:  # noqa: BLE001 - one line, exit 2
        print(f"bench_teach: error: {exc}", file=sys.stderr)
        return 2
    top = Path(args.workdir) if args.workdir else Path(tempfile.mkdtemp(prefix="rhbl-bench-teach-"))
    literal = args.literal_args if "literal" in learners else None
    print(f"bench_teach: {len(names)} people x {len(seeds)} seeds, {args.jobs} at a time, "
          f"{args.demo:g} s demonstrating + {args.correct:g} s correcting each"
          f"{', with the literal baseline' if literal else ''}; logs in {top}", flush=True)
    results: list[dict] = []
    lock = threading.Lock()

    def save() -> None:
        if args.json:
            with lock:
                Path(args.json).write_text(json.dumps(results, indent=1))

    def evaluated(r: dict) -> None:
        runs = [r]
        try:
            if literal is not None:
                runs.append(literal_run(r, literal))
        except Exception as exc:  # noqa: BLE001 - said in the table
            runs.append({"person": r["person"], "seed": r["seed"], "learner": "literal",
                         "error": f"retraining: {type(exc).__name__}: {exc}"})
        for x in runs:
            if "error" in x:
                continue
            try:
                evaluate_run(x, args.world, unseen, args.eval_episodes, args.eval_seconds)
            except Exception as exc:  # noqa: BLE001 - said in the table
                x["error"] = f"evaluation: {type(exc).__name__}: {exc}"
            print(f"  -> {json.dumps({k: v for k, v in x.items() if k != 'eval'})}", flush=True)
        with lock:
            results.extend(runs)
        save()

    def session(name: str, seed: int) -> None:
        try:
            r = teach_one(name, seed, args.demo, args.correct, record=literal is not None,
                          learner_args=args.learner_args, world=args.world,
                          workdir=top / f"{name}-{seed}", log=lambda s: print(s, flush=True))
        except Exception as exc:  # noqa: BLE001 - the next run still runs; said
            with lock:
                results.append({"person": name, "seed": seed, "learner": "default",
                                "error": f"{type(exc).__name__}: {exc}"})
            save()
            return
        evals.submit(evaluated, r)

    # ``--jobs`` people teach at once (real time, mostly waiting on the page); each run's trees
    # are evaluated one at a time while the next people teach
    with (concurrent.futures.ThreadPoolExecutor(max_workers=1) as evals,
          concurrent.futures.ThreadPoolExecutor(max_workers=args.jobs) as teach_pool):
        list(teach_pool.map(lambda ns: session(*ns), [(n, s) for n in names for s in seeds]))
    order = {(n, s): k for k, (n, s) in enumerate((n, s) for n in names for s in seeds)}
    results.sort(key=lambda r: (order.get((r["person"], r["seed"]), 0), r["learner"]))
    save()
    print(table(results))
    return 0 if all("error" not in r for r in results) else 1


if __name__ == "__main__":
    sys.exit(main())
