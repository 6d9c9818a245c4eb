"""Encode and decode of the protocol's messages, microseconds per call, best of many rounds.

The messages a process decodes per scan or per label (a 360-beam ``Scan``, ``State``,
``TeacherAction``, ``LabeledScan``, ``VelCmd``, a ``Decision`` with a 20-node path,
``LearnerAck``), each encoded and decoded in a loop (``timeit``). ``--peer DIR`` also times
another checkout of rhbl (DIR, e.g. ``git archive`` of an older commit unpacked): its
``protocol`` package is imported beside this one's in the same process, and the two are timed
in alternation, message by message, so both see the same load; the table gives both and checks
that they encode the same bytes.

    python benchmarks/bench_messages.py [--rounds 20] [--number 1000] [--peer DIR]
"""

from __future__ import annotations

import argparse
import importlib
import sys
import timeit
from pathlib import Path
from types import ModuleType

import numpy as np

ROOT = Path(__file__).resolve().parents[1]


def messages_of(root: Path) -> ModuleType:
    """``protocol.messages`` of the checkout at ``root``, imported apart from any other (the
    package's modules are taken out of ``sys.modules`` before and after: each copy keeps its
    own through the names it bound)."""
    def forget() -> None:
        for name in [n for n in sys.modules if n == "protocol" or n.startswith("protocol.")]:
            del sys.modules[name]

    forget()
    sys.path.insert(0, str(root))
    try:
        return importlib.import_module("protocol.messages")
    finally:
        sys.path.remove(str(root))
        forget()


def examples(m: ModuleType) -> dict:
    r = np.linspace(0.2, 7.9, 360).astype(np.float32)
    return {
        "Scan": m.Scan(ts=3.1, id=31, ranges=r, pose=(0.5, 0.25, -1.0), truth=(0.6, 0.2, -1.1)),
        "State": m.State(ts=12.5, seq=7, pos=(1.25, -2.5, 0.75), vel=(0.3, 0.01, -0.2),
                         driver="controller", truth=(1.3, -2.4, 0.7)),
        "TeacherAction": m.TeacherAction(scan_id=31, action="fwd-left", ts=3.3,
                                         origin="5c3ef4e7daff4b6d", seq=12),
        "LabeledScan": m.LabeledScan(scan_id=32, action="rot-right", origin="5c3ef4e7daff4b6d",
                                     seq=13, ranges=r, yaw=-0.4),
        "VelCmd": m.VelCmd(vx=0.35, va=-0.6, source="teacher", scan_id=31, ts=3.2),
        "Decision": m.Decision(scan_id=33, action="fwd", ts=3.5, snapshot_id="ab:1", nodes=41,
                               path=tuple((i, i, 0.5, "fwd") for i in range(20))),
        "LearnerAck": m.LearnerAck(origin="5c3ef4e7daff4b6d", upto=13, seqs=(15, 17), ts=9.5),
    }


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--rounds", type=int, default=20, help="rounds (the best of them is kept)")
    ap.add_argument("--number", type=int, default=1000, help="calls per message per round")
    ap.add_argument("--peer", metavar="DIR", type=Path,
                    help="another checkout of rhbl to time beside this one")
    args = ap.parse_args()
    if args.peer is not None and not (args.peer / "protocol" / "messages.py").is_file():
        ap.error(f"--peer {args.peer}: not a checkout of rhbl (no protocol/messages.py in it)")
    sides = {"this": examples(messages_of(ROOT))}
    if args.peer is not None:
        sides["peer"] = examples(messages_of(args.peer.resolve()))
    best: dict[tuple[str, str], list[float]] = {}
    n = args.number
    for _ in range(args.rounds):
        for name in sides["this"]:
            for side, msgs in sides.items():
                msg = msgs[name]
                data, cls = msg.encode(), type(msg)
                d = timeit.timeit(lambda cls=cls, data=data: cls.decode(data), number=n) / n
                e = timeit.timeit(msg.encode, number=n) / n
                was = best.get((side, name), [d, e])
                best[side, name] = [min(was[0], d), min(was[1], e)]
    print(f"best of {args.rounds} rounds of {n} calls, microseconds per call"
          + (f"; peer {args.peer}" if args.peer else ""))
    if args.peer is None:
        print("| message | decode us | encode us |\n|---|---|---|")
        for name in sides["this"]:
            d, e = best["this", name]
            print(f"| {name} | {d * 1e6:.2f} | {e * 1e6:.2f} |")
        return 0
    print("| message | decode us (peer) | decode us (this) | encode us (peer) | encode us (this) "
          "| same bytes |\n|---|---|---|---|---|---|")
    for name, msg in sides["this"].items():
        (d, e), (pd, pe) = best["this", name], best["peer", name]
        same = msg.encode() == sides["peer"][name].encode()
        print(f"| {name} | {pd * 1e6:.2f} | {d * 1e6:.2f} | {pe * 1e6:.2f} | {e * 1e6:.2f} | "
              f"{'yes' if same else '**no**'} |")
    return 0


if __name__ == "__main__":
    sys.exit(main())
