"""`fourierjax explore`: slider move -> new pose sent (one character), and the crowd's frame rate.

Run: `python -m experiments.benchmarks.explore --out out/bench/explore.json [--small]`.
Baseline (same run): one `fourierjax synth --config` process of the same parameter set, what each
edit cost before the explorer (import, compile, synthesize, write).
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import pathlib
import subprocess
import sys
import tempfile
import time

import numpy as np

from experiments.benchmarks._common import Record, load_average, timeit


def _stats(ts) -> dict:
    a = np.asarray(ts)
    return {"median": float(np.median(a)), "min": float(a.min()), "max": float(a.max()),
            "q25": float(np.percentile(a, 25)), "q75": float(np.percentile(a, 75)), "repeats": len(ts)}


def _free_port() -> int:
    import socket

    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def run(size: str) -> list[Record]:
    import jax.numpy as jnp

    from fourierjax import data, explore, kinematics, style

    full = size == "full"
    seconds, fps = (4.0, 120.0) if full else (1.0, 60.0)
    repeats = 30 if full else 3
    gaits = explore.fit_clips({n: data.load(n) for n in ("07_01", "02_03")}, {"07_01": "walk", "02_03": "run"})
    lib = explore.Library(gaits, {"run": style.characteristic(gaits["02_03"].model, gaits["07_01"].model)})
    t0 = time.perf_counter()
    ex = explore.Explorer(lib, port=_free_port(), stance=False, seconds=seconds, fps=fps)
    first_s = time.perf_counter() - t0
    ex.playing = False
    try:
        rng = np.random.default_rng(0)

        def latencies(**fixed):
            ex.set(s=0.1, step=1.05, weight_run=0.1, **fixed)  # warm every slider's path once
            lat = []
            for i in range(repeats):
                change = [{"s": float(rng.uniform(-1, 2))}, {"step": float(rng.uniform(0.5, 1.5))},
                          {"weight_run": float(rng.uniform(-1, 2))}][i % 3]
                t = time.perf_counter()
                assert ex.set(**change), ex.messages[-1:]
                lat.append(ex.pose_sent_at - t)
            return lat

        # Interleaved: the page's default (feet locked), without locking, on a circle.
        lat, lat_free, lat_path = [], [], []
        for _ in range(2 if full else 1):
            lat += latencies(foot_lock=True, path_radius_m=0.0)
            lat_free += latencies(foot_lock=False, path_radius_m=0.0)
            lat_path += latencies(foot_lock=True, path_radius_m=2.0)
        ex.set(foot_lock=True, path_radius_m=0.0)
        # Where the time goes, for one parameter set.
        p = ex.params
        a, b = lib.gait(p.a), lib.gait(p.b)
        chars = [lib.characteristics[n] for n, _ in p.weights]
        model = explore.edited_model(a.model, b.model, chars, p)
        motion, _ = explore.synthesize_motion(a, model, p)
        skel = a.template.skeleton()
        result = explore.synthesize_result(a, model, p)
        free = dataclasses.replace(p, foot_lock=False)
        parts = {  # a slider move: edited model, synthesis, foot lock, view FK, send; an export adds the BVH
            "edited_model_s": timeit(lambda: explore.edited_model(a.model, b.model, chars, p).offset,
                                     repeats=5)["median"],
            "synthesize_unlocked_s": timeit(lambda: explore.synthesize_result(a, model, free).features,
                                            repeats=5)["median"],
            "synthesize_locked_s": timeit(lambda: explore.synthesize_result(a, model, p).features, repeats=5)["median"],
            "view_positions_s": timeit(lambda: explore.view_positions(a, model.representation, result),
                                       repeats=5)["median"],
            "send_pose_s": timeit(lambda: ex._send_frame(ex.frame), repeats=20)["median"],
            "export_bvh_channels_s": timeit(lambda: explore.result_motion(a, model.channel_names, result, p).channels,
                                            repeats=3)["median"],
            "joint_positions_of_bvh_s": timeit(lambda: kinematics.joint_positions(skel, jnp.asarray(motion.channels)),
                                               repeats=5)["median"],
        }
        # Baseline: a fresh `synth --config` process of the same parameter set.
        with tempfile.TemporaryDirectory() as tmp:
            _, config = ex.export(tmp)
            base = []
            for _ in range(2 if full else 1):
                t = time.perf_counter()
                subprocess.run([sys.executable, "-m", "fourierjax", "synth", "--config", str(config), "--out",
                                str(pathlib.Path(tmp) / "b.bvh")], check=True, capture_output=True)
                base.append(time.perf_counter() - t)
        ours = _stats(lat)
        free_stats, path_stats = _stats(lat_free), _stats(lat_path)
        records = [Record(
            "explore_slider_latency", ours["median"], float(np.median(base)), "s", lower_is_better=True,
            target=0.050, target_on="ours", target_op="<=",
            description=f"slider move -> new pose sent, one character, {p.num_frames} frames ({seconds:g} s at "
                        f"{fps:g} Hz) resynthesized per move, feet locked (the page's default)",
            baseline_name="one `fourierjax synth --config` process (import, compile, synthesize, write)",
            ours_stats=ours, baseline_stats=_stats(base),
            details={"first_start_s": round(first_s, 2), "feet_not_locked": free_stats, "on_circle_r2m": path_stats,
                     **{k: round(v, 5) for k, v in parts.items()}},
        )]
        # Crowd: compute + the float16 points sent, per frame.
        crowd = ex.crowd
        num = 10_000 if full else 64
        crowd.gui_num.value, crowd.gui_jitter.value = num, 0.2
        t = time.perf_counter()
        crowd.rebuild()
        pts = crowd.frame(0.0)
        build_s = time.perf_counter() - t
        handle = ex.server.scene.add_point_cloud("/bench_crowd", pts, (90, 90, 110), point_size=0.04,
                                                 precision="float16")
        clock = {"t": 0.0}

        def step():
            clock["t"] += 1 / 60
            handle.points = crowd.frame(clock["t"])

        frame = timeit(step, repeats=10 if full else 3, warmup=2)
        compute = timeit(lambda: crowd.frame(clock["t"]), repeats=10 if full else 3, warmup=1)
        records.append(Record(
            f"explore_crowd_{num}", 1.0 / frame["median"], 1.0 / compute["median"], "frames/s",
            description=f"crowd mode, {num} characters: positions computed and sent as float16 points",
            baseline_name="the same frame computed, not sent (the ratio is the cost of sending)",
            ours_stats=frame, baseline_stats=compute,
            details={"build_and_first_frame_s": round(build_s, 2), "bytes_per_frame": int(pts.nbytes)},
        ))
    finally:
        ex.close()
    for r in records:
        r.notes.append(f"load average {load_average()} (a machine shared by eight engineers: noisy timings)")
    return records


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(prog="python -m experiments.benchmarks.explore", description=__doc__)
    parser.add_argument("--out", default="out/bench/explore.json")
    parser.add_argument("--small", action="store_true", help="tiny sizes: checks that it runs")
    args = parser.parse_args(argv)
    records = [r.as_json() for r in run("small" if args.small else "full")]
    out = pathlib.Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps(records, indent=2))
    for r in records:
        print(f"{r['name']}: ours {r['ours']:.4g} {r['unit']}, baseline {r['baseline']:.4g}, ratio {r['ratio']:.3g}x")
    return 0


if __name__ == "__main__":
    sys.exit(main())
