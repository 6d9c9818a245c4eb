"""Retraining from recordings (``rhbl train --from-recording``): the live learner's tree again, or
one with other settings, from the teacher labels a recording holds. No zenoh is imported.

    learner, stats = retrain(["run.mcap"], features="wall")       # the live learner's tree again

Only the flags that apply to a run without simulation are taken (``USES``); any other one
given is a named error, not ignored.

Retraining replays the live learner's pairing: the recorded scans and teacher labels go, in the
order the recorder received them, through ``client.labels.Pairing`` (a label is paired with
exactly the scan it answers) into ``DemonstrationLearner.observe``, the learner's code path; so
with the live learner's features and settings the tree is the one it built. ``teacher="person"``
(``rhbl train --from-recording ... --teacher person``, or ``auto``, the default, when the first
label came from a person) retrains labels given by hand as
``rhbl learner --teacher person`` learns them: each paired with the scan ``lag`` scans earlier,
the tree built by the neighbours' vote (``client.behaviour.teaching.PersonLearner``).
"""

from __future__ import annotations

import argparse
import logging
import time
from collections.abc import Iterator
from pathlib import Path

from client.behaviour.actions import DEFAULT_ACTIONS
from client.behaviour.features import FEATURES, FeatureError, FeatureSpec
from client.behaviour.learning import DemonstrationLearner
from client.behaviour.rule import rule_for
from client.behaviour.tasks import task_of_features
from client.behaviour.teaching import PersonLearner
from client.labels import by_person
from client.recording.mcap_file import RecordingError, read_recording
from protocol.messages import Scan, TeacherAction

__all__ = ["first_label_source", "labeled_scans", "retrain", "save_retrained", "train_main"]

log = logging.getLogger(__name__)


# ---- retraining ---------------------------------------------------------------------------
class _Clock:
    def __init__(self):
        self.now = 0.0

    def __call__(self) -> float:
        return self.now


def labeled_scans(path: str | Path, robots: list[str] | None = None,
                  match_timeout: float = 2.0, scan_buffer: int = 512,
                  stats: dict | None = None, lag: int = 0, window: int = 0
                  ) -> Iterator[tuple[str, Scan, TeacherAction]]:
    """(robot, scan, label) in the order the live learner paired them: the recording's scans
    and labels through ``client.labels.Pairing`` (one per robot, ``lag`` and ``window`` as its
    own), clocked by receive time."""
    from client.labels import Pairing

    pairings: dict[str, tuple[Pairing, _Clock]] = {}
    for m in read_recording(path):
        if m.kind not in ("scan", "label") or (robots and m.robot not in robots):
            continue
        p = pairings.get(m.robot)
        if p is None:
            clock = _Clock()
            p = pairings[m.robot] = (Pairing(scan_buffer, match_timeout, clock=clock, lag=lag,
                                                     window=window),
                                     clock)
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


def first_label_source(paths, robots: list[str] | None = None) -> str | None:
    """The ``source`` of the recordings' first teacher label (files in the order given), None
    when they hold none (a malformed label is skipped)."""
    for path in paths:
        for m in read_recording(path):
            if m.kind == "label" and not (robots and m.robot not in robots):
                try:
                    return TeacherAction.decode(m.data).source
                except Exception:  # noqa: BLE001 - a malformed label: the pairing counts it
                    continue
    return None


def retrain(paths, features: str | FeatureSpec = "wall", robots: list[str] | None = None,
            task: str | None = None, stride: int = 1, min_delta: float = 0.0,
            tree_params: dict | None = None, record: bool = False, teacher: str = "auto",
            lag: int | None = None) -> tuple[DemonstrationLearner, dict]:
    """A tree learned from the recordings' teacher labels (in order, files in the order
    given), as ``rhbl learner`` learns: labels that are no action of the tree and scans the
    features cannot use are skipped and counted. ``record``: the learner keeps its vectors
    (to compact on them). ``teacher="person"``: as ``rhbl learner --teacher person --lag``
    (the learning rule ``client.behaviour.rule.rule_for`` chooses, recorded in the snapshot);
    ``"auto"``: the person rule when the first label came from a person (``by_person``).
    Returns (learner, stats)."""
    spec = features if isinstance(features, FeatureSpec) else FEATURES[features]
    params = {"spawn": "winner", **(tree_params or {})}
    if task is None and not isinstance(features, FeatureSpec):
        task = task_of_features(features)
    chose = ""
    if teacher == "auto":  # as the live learner chooses: by the first label's source
        source = first_label_source(paths, robots)
        teacher = "person" if by_person(source) else "script"
        chose = f" (--teacher auto chose it: the first label came from {source!r})"
    if teacher == "person":
        if params.get("radius", "parent") != "parent":
            raise ValueError(f"the person rule{chose} keeps the paper's radius (its tree is "
                             "rebuilt from its labels as they come): --radius margin is the "
                             "script rule's (force --teacher script)")
        if record or stride != 1 or min_delta:
            raise ValueError(f"the person rule{chose} learns every label (no --stride) and its "
                             "tree is rebuilt from them (no --compact: compact the snapshot it "
                             "writes; or force --teacher script)")
        learner = PersonLearner(spec, DEFAULT_ACTIONS, task=task,
                                rule=rule_for("person").replace(lag=lag), **params)
        window = learner.rule.alignment.max_lag if lag is None else 0  # the scans before each
    else:
        if lag is not None:
            raise ValueError(f"--lag is the person rule's; the script rule{chose} ties each "
                             "label to the scan it names (force --teacher person)")
        learner = DemonstrationLearner(spec, DEFAULT_ACTIONS, task=task, stride=stride,
                                       min_delta=min_delta, record=record,
                                       rule=rule_for("script"), **params)
        lag, window = 0, 0
    stats = {"paired": 0, "learned": 0, "rejected": 0, "recordings": [],
             "rule": f"{teacher}{chose}"}
    t0 = time.perf_counter()
    for path in paths:
        pstats: dict = {}
        n0 = stats["paired"]
        for _robot, scan, act in labeled_scans(path, robots, stats=pstats, lag=lag or 0,
                                               window=window):
            if act.action not in learner.actions:
                stats["rejected"] += 1
                continue
            try:
                extra = ({"earlier": [spec.extract(s.ranges, float(s.pose[2]))
                                      for s in scan.earlier]} if window else {})
                if learner.observe(scan.ranges, float(scan.pose[2]), act.action, **extra):
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


def _compact_params(args) -> dict | None:
    """``--compact METHOD`` and its ``--compact-max-*`` as ``DemonstrationLearner.compact``'s
    keywords (``lab.recipe.COMPACT``); None without ``--compact`` (or ``none``)."""
    from lab.recipe import COMPACT

    if args.compact in (None, "none"):
        if args.compact_max_nodes is not None or args.compact_max_error is not None:
            raise ValueError("--compact-max-nodes and --compact-max-error go with --compact prune")
        return None
    out = dict(COMPACT[args.compact])
    for flag, key in (("compact_max_nodes", "max_nodes"), ("compact_max_error", "max_error")):
        if getattr(args, flag) is not None:
            out[key] = getattr(args, flag)
    return out


def save_retrained(learner: DemonstrationLearner, stats: dict, out: str | Path) -> Path:
    """Write the snapshot; its provenance names the recordings."""
    meta = learner.metadata()
    meta["provenance"]["recordings"] = [r["path"] for r in stats["recordings"]]
    meta["provenance"]["labeled"] = stats["paired"]
    out = Path(out)
    out.parent.mkdir(parents=True, exist_ok=True)
    learner.classifier.save(str(out), metadata=meta)
    return out


# the flags of ``rhbl train`` a retraining uses (the features, the tree, a compaction on the
# recordings' vectors); every other one drives a simulation and is refused with its name
USES = ("out", "from_recording", "behaviour", "features", "spawn", "distance", "radius",
        "min_radius", "max_nodes",
        "stride", "compact", "compact_max_nodes", "compact_max_error", "teacher", "lag")


def check_args(parser: argparse.ArgumentParser, args: argparse.Namespace) -> None:
    """ValueError naming every flag given that a run from recordings cannot apply."""
    given = [a.option_strings[0] for a in parser._actions
             if a.option_strings and a.dest not in USES and a.dest != "help"
             and getattr(args, a.dest, a.default) != a.default]
    if given:
        raise ValueError(f"{', '.join(given)} {'does' if len(given) == 1 else 'do'} not apply to "
                         f"--from-recording (no simulation runs: it learns the recordings' "
                         f"labels; it takes --behaviour (its perception and name), --features, --spawn, --distance, "
                         f"--radius, --min-radius, "
                         f"--max-nodes, --stride, --compact with its --compact-max-*, --teacher "
                         f"and --lag)")


def train_main(args) -> int:
    """``rhbl train --from-recording FILE [FILE ...]``: the harness's CLI hands over here."""
    from lab.behaviours import get
    from lab.cli import build_parser

    check_args(build_parser("train"), args)
    tree = {k: v for k, v in (("spawn", args.spawn), ("distance", args.distance),
                              ("radius", args.radius), ("min_radius", args.min_radius),
                              ("max_nodes", args.max_nodes))
            if v is not None}
    compact = _compact_params(args)
    margin = tree.get("radius") == "margin"
    if margin and compact is not None:
        raise ValueError("--compact keeps a tree's answers by the paper's rule: not with "
                         "--radius margin")
    try:
        b = get(args.behaviour) if args.behaviour else None
        features = args.features or (b.features if b is not None else "wall")
        learner, stats = retrain(args.from_recording, features=features,
                                 task=None if b is None else b.name,
                                 stride=args.stride or 1, tree_params=tree,
                                 record=compact is not None or margin, teacher=args.teacher,
                                 lag=args.lag)
    except RecordingError as exc:
        raise ValueError(str(exc)) from None
    if margin:  # as rhbl train ends: learned again from every vector, bounded by the margin
        learner.relearn()
    if stats["paired"] == 0:
        raise ValueError(f"no teacher labels paired with scans in {', '.join(args.from_recording)}: "
                         f"nothing to learn")
    if compact is not None:
        rec = learner.compact(**compact, data="the recordings' labelled scans")
        print(f"compacted ({rec['method']}): {rec['nodes_before']} -> {rec['nodes_after']} nodes")
    out = save_retrained(learner, stats, args.out)
    print(f"trained from {len(stats['recordings'])} recording(s): {stats['paired']} labeled scans "
          f"({stats['learned']} learned, {stats['rejected']} rejected, "
          f"{sum(r['unmatched'] for r in stats['recordings'])} labels without their scan), tree "
          f"{learner.nodes} nodes, height {learner.height}; {stats['seconds']:.1f} s; the "
          f"{stats['rule']} rule")
    print(f"wrote {out}")
    return 0
