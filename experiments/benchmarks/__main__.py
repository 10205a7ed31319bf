"""Run the benchmark suite: `python -m experiments.benchmarks --out out/bench [--small] [--device gpu]`."""

from __future__ import annotations

import argparse
import contextlib
import json
import os
import sys
import time
import traceback

BENCHMARKS = ("bvh_parse", "fk", "synthesis", "fit", "stance", "crowd", "compile_times", "memory",
              "startup", "pipeline")
#: The headline records each benchmark writes (issue 7's names). A benchmark that raises
#: still leaves them in results.json, marked not measured with the error.
HEADLINE_OF = {"bvh_parse": ("bvh_parse",), "fk": ("fk_1x1000", "fk_1024x240"),
               "synthesis": ("synthesis_1024",), "fit": ("fit_256",), "stance": ("stance_1024",),
               "crowd": ("crowd_10k",), "compile_times": ("compile_max_s",),
               "memory": ("memory_fit_20000",), "startup": ("startup_help", "startup_import"),
               "pipeline": ("fit_motions_500",)}
HEADLINE = tuple(h for b in BENCHMARKS for h in HEADLINE_OF[b])


def _parse(argv):
    p = argparse.ArgumentParser(prog="python -m experiments.benchmarks", description=__doc__)
    p.add_argument("--out", default="out/bench", help="output folder (results.json, metadata.json)")
    p.add_argument("--small", "--tiny", dest="small", action="store_true",
                   help="tiny sizes: checks that the suite runs (CI), numbers mean nothing")
    p.add_argument("--device", choices=("cpu", "gpu"), default="cpu",
                   help="where the jitted paths run (baselines are NumPy/scipy on the CPU)")
    p.add_argument("--only", default="", help=f"comma-separated subset of {','.join(BENCHMARKS)}")
    return p.parse_args(argv)


def _table(records) -> str:
    from experiments.benchmarks._common import rate_str

    rows = [("name", "ours", "baseline", "unit", "ratio", "target", "met")]
    for r in records:
        tgt = "-" if r["target"] is None else f"{r['target_op']} {r['target']:g} ({r['target_on']})"
        met = {True: "yes", False: "NO", None: "-"}[r["met"]]
        ratio = "-" if r["ratio"] is None else f"{r['ratio']:.3g}x"
        rows.append((r["name"], rate_str(r["ours"]), rate_str(r["baseline"]), r["unit"], ratio, tgt, met))
    w = [max(len(row[i]) for row in rows) for i in range(len(rows[0]))]
    lines = ["  ".join(c.ljust(w[i]) for i, c in enumerate(row)) for row in rows]
    lines.insert(1, "  ".join("-" * x for x in w))
    return "\n".join(lines)


def main(argv=None) -> int:
    args = _parse(argv)
    # Must be decided before JAX initialises its backends.
    os.environ.setdefault("JAX_PLATFORMS", "cuda" if args.device == "gpu" else "cpu")
    import importlib

    import jax

    from experiments.benchmarks._common import load_average, metadata, not_measured

    size = "small" if args.small else "full"
    only = [b for b in args.only.split(",") if b] or list(BENCHMARKS)
    unknown = sorted(set(only) - set(BENCHMARKS))
    if unknown:
        print(f"unknown benchmarks {unknown}; choose from {BENCHMARKS}", file=sys.stderr)
        return 2
    os.makedirs(args.out, exist_ok=True)
    meta = metadata(size, args.device)
    print(f"fourierjax benchmarks ({size}) on {meta['devices']}, {meta['cpu_count']} CPUs, "
          f"load average {meta['load_average_start']}", flush=True)
    records = []
    t_start = time.perf_counter()
    for name in only:
        t0 = time.perf_counter()
        try:
            mod = importlib.import_module(f"experiments.benchmarks.{name}")
            recs = mod.run(size)
        except Exception as err:  # one broken benchmark must not hide the others
            traceback.print_exc()
            reason = f"benchmark {name} raised {type(err).__name__}: {err}"
            recs = [not_measured(h, "-", reason) for h in HEADLINE_OF[name]]
        for r in recs:
            r.details.setdefault("benchmark_seconds", round(time.perf_counter() - t0, 2))
            r.details.setdefault("load_average_after", load_average())
            records.append(r.as_json())
        print(f"  {name}: {time.perf_counter() - t0:.1f} s, load {load_average()}", flush=True)
        # Written after every benchmark, so a run stopped part way keeps what it measured.
        with open(os.path.join(args.out, "results.partial.json"), "w") as f:
            json.dump(records, f, indent=1)
        jax.clear_caches()
    meta["load_average_end"] = load_average()
    meta["seconds"] = round(time.perf_counter() - t_start, 1)
    run_meta = {k: meta[k] for k in ("size", "devices", "cpu_count", "load_average_start",
                                     "load_average_end", "jax", "numpy", "started_utc")}
    for r in records:
        r["meta"] = run_meta
    with open(os.path.join(args.out, "results.json"), "w") as f:
        json.dump(records, f, indent=1)
    with contextlib.suppress(FileNotFoundError):
        os.remove(os.path.join(args.out, "results.partial.json"))
    with open(os.path.join(args.out, "metadata.json"), "w") as f:
        json.dump(meta, f, indent=1)
    table = _table(records)
    with open(os.path.join(args.out, "results.txt"), "w") as f:
        f.write(table + "\n")
    print(table)
    missing = [h for h in HEADLINE if h not in {r["name"] for r in records}]
    if missing and not args.only:
        print(f"missing headline records: {missing}", file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main())
