"""``python -m campaigns.contention``: run the contention probes, print a markdown report; exit
status 1 if any promise failed (see the package's docstring)."""

from __future__ import annotations

import argparse
import importlib
import logging
import random
import sys
import tempfile
import time
import traceback
from pathlib import Path

from campaigns.contention import SIZES, Outcome, Probe, ProbeFunction

MODULES = ("lineage", "console", "snapshot")


def probes() -> dict[str, ProbeFunction]:
    """Every probe of every module, in the modules' order."""
    found: dict[str, ProbeFunction] = {}
    for name in MODULES:
        module = importlib.import_module(f"campaigns.contention.{name}")
        found.update(module.PROBES)
    return found


def run(names: list[str], *, seed: int, size: str, out: Path) -> dict[str, Outcome]:
    table = probes()
    results: dict[str, Outcome] = {}
    for i, name in enumerate(names):
        workdir = out / name
        workdir.mkdir(parents=True, exist_ok=True)
        probe = Probe(name, random.Random(seed * 1000 + i), workdir, size)
        started = time.monotonic()
        try:
            outcome = table[name](probe)
        except Exception as exc:  # a probe that breaks is a failed promise, not a crash
            traceback.print_exc()
            outcome = Outcome(False, f"the probe itself failed: {type(exc).__name__}: {exc}")
        outcome.figures.setdefault("seconds", round(time.monotonic() - started, 1))
        results[name] = outcome
        print(f"{'ok  ' if outcome.ok else 'FAIL'} {name}: {outcome.said}", flush=True)
    return results


def report(results: dict[str, Outcome], *, seed: int, size: str) -> str:
    lines = [f"# Contention campaign (seed {seed}, size {size})", "",
             "| probe | held | what was seen | figures |", "|---|---|---|---|"]
    for name, o in results.items():
        figures = ", ".join(f"{k} {v}" for k, v in o.figures.items())
        lines.append(f"| {name} | {'yes' if o.ok else '**no**'} | {o.said} | {figures} |")
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m campaigns.contention",
                                     description=__doc__.splitlines()[0])
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--size", choices=SIZES, default="full",
                        help="ci: the small run of the test suite; full: the promises' sizes")
    parser.add_argument("--only", default="",
                        help="comma-separated probe names (default: all); --list shows them")
    parser.add_argument("--list", action="store_true", help="list the probes and exit")
    parser.add_argument("--out", type=Path, default=None,
                        help="a folder for the probes' files (default: a temporary one)")
    args = parser.parse_args(argv)
    logging.basicConfig(level=logging.WARNING, format="%(levelname)s %(name)s: %(message)s")
    table = probes()
    if args.list:
        print("\n".join(table))
        return 0
    names = [n for n in args.only.split(",") if n] or list(table)
    unknown = [n for n in names if n not in table]
    if unknown:
        parser.error(f"--only: unknown probe(s) {', '.join(unknown)} (known: {', '.join(table)})")
    with tempfile.TemporaryDirectory(prefix="rhbl-contention-") as tmp:
        out = args.out or Path(tmp)
        results = run(names, seed=args.seed, size=args.size, out=out)
    print()
    print(report(results, seed=args.seed, size=args.size))
    return 0 if all(o.ok for o in results.values()) else 1


if __name__ == "__main__":
    sys.exit(main())
