"""Peak memory of `fourier.fit_batch` at 2,000 and 20,000 clips (240 frames x 60 channels), each
measured in a subprocess; 100,000 extrapolated from the chunks. Chunked results equal
unchunked fits on a subset.

Run alone: `python -m experiments.benchmarks --only memory` (or `python -m
experiments.benchmarks.memory --clips 20000` for one child's JSON line).
"""

from __future__ import annotations

import argparse
import json
import os
import re
import shutil
import subprocess
import sys
import time

import numpy as np

from experiments.benchmarks._common import Record, load_average

T, C, N, DT = 240, 60, 3, 1 / 120
#: The budget the benchmark passes as `max_memory` (the default, a quarter of the machine's
#: memory, would be 5.8 GB on a 23 GB machine: above the 4 GB target whatever the chunking).
BUDGET = 2 * 10**9
#: Clips the unchunked reference fit covers: the first and the last (the padded chunk).
SUBSET = 64
TARGET_GB = 4.0
#: fit_batch's own estimate of one clip (its docstring: ~26 values per feature at the peak),
#: from which the chunks it uses follow; the public API does not return them.
PER_CLIP_BYTES = 4 * (26 * T * C + 2 * T * (2 * N + 1) + 4 * C * (2 * N + 1) + 64)


def _features(num_clips: int) -> np.ndarray:
    """`[B, T, C]` float32 gait-like clips, generated 500 at a time (a float64 temporary of the
    whole batch would be 2.3 GB at 20,000 clips and dominate the peak being measured)."""
    from experiments.benchmarks.fit import gait_like_clips

    out = np.empty((num_clips, T, C), np.float32)
    for start in range(0, num_clips, 500):
        stop = min(start + 500, num_clips)
        out[start:stop] = gait_like_clips(stop - start, T, C, DT, seed=start)[0]
    return out


def child(num_clips: int, budget: int) -> dict:
    """One measurement, in this process: the chunked fit of `num_clips`, then an unchunked
    fit of the first and last `SUBSET // 2` clips, compared."""
    import resource

    import jax

    from fourierjax import fourier

    x = _features(num_clips)
    dt = np.full(num_clips, DT, np.float32)
    per_clip = PER_CLIP_BYTES
    num_chunks = -(-num_clips // max(1, budget // per_clip))
    chunk = -(-num_clips // num_chunks)
    rss_before = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024
    t0 = time.perf_counter()
    res = fourier.fit_batch(x, dt, N, max_memory=budget, throw=False)
    jax.block_until_ready(res)
    seconds = time.perf_counter() - t0
    rss_fit = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024
    idx = np.r_[0:SUBSET // 2, num_clips - SUBSET // 2:num_clips]
    ref = fourier.fit_batch(x[idx], dt[idx], N, throw=False, max_memory=10**12)
    diffs = [float(np.max(np.abs(np.asarray(a, np.float64)[idx] - np.asarray(b, np.float64))))
             for a, b in zip(jax.tree.leaves(res), jax.tree.leaves(ref), strict=True)
             if np.size(a) and np.issubdtype(np.asarray(a).dtype, np.number)]
    finite = [d for d in diffs if np.isfinite(d)]
    return {"clips": num_clips, "frames": T, "channels": C, "num_harmonics": N,
            "max_memory": budget, "chunks": num_chunks, "chunk": chunk,
            "per_clip_estimate_bytes": per_clip, "input_bytes": int(x.nbytes),
            "fit_seconds": round(seconds, 2), "clips_per_s": round(num_clips / seconds, 1),
            "peak_rss_before_fit_bytes": rss_before, "peak_rss_after_fit_bytes": rss_fit,
            # Float32 rounding of programs of two batch sizes (see fit_batch's docstring).
            "max_abs_diff_vs_unchunked": max(finite) if finite else 0.0,
            "successful": int(np.sum(np.asarray(res.result) == 0))}


def measure(num_clips: int, budget: int = BUDGET, timeout: int = 3000) -> dict:
    """`child` in a subprocess under `/usr/bin/time -v` (its maximum resident set size; the
    child's own `getrusage` where `/usr/bin/time` is missing)."""
    cmd = [sys.executable, "-m", "experiments.benchmarks.memory", "--clips", str(num_clips),
           "--max-memory", str(budget)]
    timer = shutil.which("time") or ("/usr/bin/time" if os.path.exists("/usr/bin/time") else None)
    if timer:
        cmd = [timer, "-v", *cmd]
    root = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
    proc = subprocess.run(cmd, cwd=root, capture_output=True, text=True, timeout=timeout,
                          env=dict(os.environ, JAX_PLATFORMS=os.environ.get("JAX_PLATFORMS", "cpu")))
    if proc.returncode != 0:
        raise RuntimeError(f"memory child ({num_clips} clips) exited {proc.returncode}: "
                           f"{proc.stderr[-2000:]}")
    out = json.loads(proc.stdout.strip().splitlines()[-1])
    m = re.search(r"Maximum resident set size \(kbytes\): (\d+)", proc.stderr)
    out["peak_rss_bytes"] = int(m.group(1)) * 1024 if m else out["peak_rss_after_fit_bytes"]
    out["peak_rss_source"] = "/usr/bin/time -v" if m else "getrusage in the child"
    return out


def run(size: str) -> list[Record]:
    sizes = (2_000, 20_000) if size == "full" else (96, 192)
    budget = BUDGET if size == "full" else 40 * 10**6  # small: several chunks all the same
    results = {n: measure(n, budget) for n in sizes}
    records = []
    # The record names are those of the full sizes (the suite's headline names); `--small` runs
    # the same code at 96 and 192 clips, as `details["clips"]` says.
    for (n, r), name in zip(results.items(), ("memory_fit_2000", "memory_fit_20000"), strict=True):
        gb = r["peak_rss_bytes"] / 1e9
        records.append(Record(
            name, gb, None, "GB peak RSS", target=TARGET_GB if n == sizes[-1] else None,
            target_on="ours", target_op="<=", lower_is_better=True,
            description=f"fourier.fit_batch of {n} clips x {T} frames x {C} channels (N = {N}), "
                        f"max_memory = {budget / 1e9:g} GB: {r['chunks']} chunks of "
                        f"{r['chunk']}; peak RSS of a fresh subprocess ({r['peak_rss_source']})",
            details={**r, "load_average": load_average()}).finish())
    # Extrapolation: the peak grows with the input (stored whole) and the outputs; the chunk's
    # working memory is fixed by the budget. Linear through the two measurements.
    (n0, r0), (n1, r1) = results.items()
    slope = (r1["peak_rss_bytes"] - r0["peak_rss_bytes"]) / (n1 - n0)
    n2 = 100_000 if size == "full" else 960
    peak2 = r1["peak_rss_bytes"] + slope * (n2 - n1)
    rate = r1["clips_per_s"]
    records.append(Record(
        "memory_fit_100000_extrapolated",
        peak2 / 1e9, None, "GB peak RSS (extrapolated)", lower_is_better=True,
        description=f"{n2} clips extrapolated linearly from {n0} and {n1} "
                    f"({slope / 1e3:.1f} kB per clip: the input is {T * C * 4 / 1e3:.1f} kB); "
                    f"about {n2 / rate:.0f} s at {rate} clips/s",
        details={"bytes_per_clip_slope": slope, "input_bytes": n2 * T * C * 4,
                 "estimated_seconds": n2 / rate}).finish())
    return records


def main(argv=None) -> int:
    p = argparse.ArgumentParser(prog="python -m experiments.benchmarks.memory", description=__doc__)
    p.add_argument("--clips", type=int, required=True)
    p.add_argument("--max-memory", type=int, default=BUDGET)
    args = p.parse_args(argv)
    print(json.dumps(child(args.clips, args.max_memory)))
    return 0


if __name__ == "__main__":
    sys.exit(main())
