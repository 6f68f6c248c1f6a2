"""python -m tests.fuzz [--all | --per-class N] [--seed S] [--jobs J] [--keep DIR] [--list]

Prints one line per failing case and a table of cases and failures per class; exit status 1
when any case fails.
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import time
from collections import Counter
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

from .cases import CLASSES, generate, subset
from .fixtures import build
from .runner import run_case


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m tests.fuzz", description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--all", action="store_true", help="every case (default: a subset)")
    parser.add_argument("--per-class", type=int, default=6,
                        help="cases per class without --all (default 6)")
    parser.add_argument("--seed", type=int, default=0, help="draw of the random parts")
    parser.add_argument("--jobs", type=int, default=2, help="cases run at once (default 2)")
    parser.add_argument("--keep", type=Path, help="copy each failing case's folder here")
    parser.add_argument("--only", default="", help="run the cases whose name holds this")
    parser.add_argument("--list", action="store_true", help="list the cases and stop")
    args = parser.parse_args(argv)
    cases = generate(args.seed, full=args.all)
    if args.only:
        cases = [c for c in cases if args.only in c.name]
    elif not args.all:
        cases = subset(cases, args.per_class, args.seed)
    if args.list:
        for case in cases:
            print(f"{case.klass:38s} {case.name}")
        print(f"{len(cases)} cases")
        return 0
    started = time.perf_counter()
    with tempfile.TemporaryDirectory(prefix="fuzz-base-") as folder:
        base = build(Path(folder) / "base")
        print(f"fixtures ready ({time.perf_counter() - started:.0f} s); {len(cases)} cases",
              flush=True)
        with ThreadPoolExecutor(max_workers=args.jobs) as pool:
            outcomes = list(pool.map(lambda c: run_case(c, base, args.keep), cases))
    total, failed = Counter(), Counter()
    for outcome in outcomes:
        total[outcome.case.klass] += 1
        if not outcome.ok:
            failed[outcome.case.klass] += 1
            print(f"FAIL [{outcome.case.klass}] {outcome.case.name}: {outcome.problems[0]}")
    print("\n| class | cases | failing |\n|---|---|---|")
    for klass in CLASSES:
        print(f"| {klass} | {total[klass]} | {failed[klass]} |")
    print(f"| all | {sum(total.values())} | {sum(failed.values())} |")
    print(f"({time.perf_counter() - started:.0f} s, seed {args.seed})")
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
