"""Run every experiment: ``python -m experiments --out out/experiments [--small] [--only NAME]``.

Each experiment runs in its own process (fresh JAX state, its own failure); the run stops with
a non-zero exit code if any fails. Benchmarks live in ``experiments.benchmarks`` (``make bench``).
"""

from __future__ import annotations

import argparse
import subprocess
import sys
import time

EXPERIMENTS = ("fit_quality", "style", "hip_rule", "stance", "style_space", "any_skeleton")


def main(argv=None) -> int:
    p = argparse.ArgumentParser(prog="python -m experiments", description=__doc__.splitlines()[0])
    p.add_argument("--out", default="out/experiments", help="output root")
    p.add_argument("--small", action="store_true", help="the quick ([small]) settings CI uses")
    p.add_argument("--only", action="append", choices=EXPERIMENTS, help="run only these")
    a = p.parse_args(argv)
    failed = []
    for name in a.only or EXPERIMENTS:
        t0 = time.perf_counter()
        cmd = [sys.executable, "-m", f"experiments.{name}", "--out", a.out]
        if a.small:
            cmd.append("--small")
        print(f"== {name}", flush=True)
        rc = subprocess.call(cmd)
        print(f"== {name}: {'ok' if rc == 0 else f'FAILED (exit {rc})'} in "
              f"{time.perf_counter() - t0:.0f} s", flush=True)
        if rc:
            failed.append(name)
    if failed:
        print(f"failed: {', '.join(failed)}", file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
