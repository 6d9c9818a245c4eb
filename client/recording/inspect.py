"""``rhbl inspect``: what an MCAP recording holds (robots, keys and counts, sim time, teacher
labels, gaps in the scan stream, the metadata); ``--json`` prints the summary as JSON.

    summary = recording_summary("run.mcap")
    print(format_summary(summary))
"""

from __future__ import annotations

import argparse
import json
import os
from collections import defaultdict

from client.recording.mcap_file import RecordingError, RecordingReader
from process import arguments

__all__ = ["add_arguments", "format_summary", "main", "recording_summary"]


def recording_summary(path: str | os.PathLike) -> dict:
    """What a recording holds (``rhbl inspect``): robots, keys and counts, the sim-time span,
    teacher labels per action, gaps in the scan stream, the metadata."""
    reader = RecordingReader(path)
    keys_: dict[str, dict] = {}
    robots: dict[str, dict] = {}
    viewer: dict[str, int] = defaultdict(int)
    labels: dict[str, dict[str, int]] = defaultdict(lambda: defaultdict(int))
    last_scan: dict[str, tuple[int, float]] = {}
    gaps: list[dict] = []
    t_first = t_last = None
    for m in reader.messages(viewer=True):
        if m.kind == "viewer":
            viewer[m.key] += 1
            continue
        k = keys_.setdefault(m.key, {"kind": m.kind, "schema": m.schema, "messages": 0})
        k["messages"] += 1
        t_first = m.log_time if t_first is None else min(t_first, m.log_time)
        t_last = m.log_time if t_last is None else max(t_last, m.log_time)
        if not m.robot or m.kind == "alive":
            continue
        r = robots.setdefault(m.robot, {"sim_start": None, "sim_end": None, "scans": 0})
        if m.kind in ("scan", "state"):
            s = m.sim_time
            r["sim_start"] = s if r["sim_start"] is None else min(r["sim_start"], s)
            r["sim_end"] = s if r["sim_end"] is None else max(r["sim_end"], s)
        if m.kind == "scan":
            r["scans"] += 1
            try:
                scan = m.message()
            except Exception:  # noqa: BLE001
                continue
            prev = last_scan.get(m.robot)
            if prev is not None and scan.id > prev[0] + 1:
                gaps.append({"robot": m.robot, "after_scan": prev[0], "missing": scan.id - prev[0] - 1,
                             "sim_time": round(prev[1], 3)})
            last_scan[m.robot] = (scan.id, scan.ts)
        elif m.kind == "label":
            try:
                labels[m.robot][m.message().action] += 1
            except Exception:  # noqa: BLE001
                labels[m.robot]["<malformed>"] += 1
    return {"path": str(path), "metadata": reader.metadata.get("rhbl", {}), "robots": robots,
            "keys": keys_, "viewer": dict(viewer),
            "labels": {r: dict(v) for r, v in labels.items()}, "gaps": gaps,
            "notes": reader.notes,
            "wall_seconds": (t_last - t_first) / 1e9 if t_first is not None else 0.0}



def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("recording", nargs="+", type=arguments.input_file,
                        help="MCAP file(s) written by rhbl")
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
