"""`python -m tests.fuzz [--bvh N] [--models N] [--cli N] [--seed S]`: the large fuzz run of `make fuzz`.

Prints one line of counts per suite and exits 1 if any case raised an untyped exception or
printed a traceback.
"""

from __future__ import annotations

import argparse
import sys


def main(argv=None) -> int:
    p = argparse.ArgumentParser(prog="python -m tests.fuzz", description=__doc__)
    p.add_argument("--bvh", type=int, default=10_000, help="mutated BVH files (default 10000)")
    p.add_argument("--models", type=int, default=1_000, help="mutated model files (default 1000)")
    p.add_argument("--cli", type=int, default=500, help="CLI argument sets (default 500)")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--case-seconds", type=int, default=120,
                   help="time limit of one CLI case (default 120)")
    args = p.parse_args(argv)
    from tests.fuzz import cases

    runs = (lambda: cases.run_bvh(args.bvh, args.seed),
            lambda: cases.run_models(args.models, args.seed),
            lambda: cases.run_cli(args.cli, args.seed, case_seconds=args.case_seconds),
            cases.run_gradients)
    reports = []
    for run in runs:
        rep = run()
        reports.append(rep)
        print(rep.line(), flush=True)
        for case, what in rep.examples:
            print(f"  untyped: {case}: {what}", flush=True)
    total = sum(r.cases for r in reports)
    bad = sum(r.untyped for r in reports)
    print(f"fuzz: {total} cases, {bad} untyped exceptions/tracebacks")
    return 1 if bad else 0


if __name__ == "__main__":
    sys.exit(main())
