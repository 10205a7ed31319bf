"""Issue 26 on a lent GPU: batched FK and the crowd at GPU sizes, checked against NumPy.

`python -m experiments.benchmarks.gpu --out DIR [--small]` writes `DIR/gpu.json` (records in the
format of `results.json`, with the device name) and prints a table. It runs on any JAX backend;
`--small` is the CPU smoke of the same code (the test suite runs it; numbers mean nothing).

What it measures, each against a figure from the same run:
- the device's ceilings: a large device-to-device copy (bytes read + written per second) and a
  float32 elementwise rate (a chain of fused multiply-adds on a large array);
- `kinematics.joint_positions` and `kinematics.fk_frames` on B clips x 240 frames of the 31-joint
  CMU skeleton (07_01 plus noise, generated on the device), as joint transforms/s, against the
  write bound of the same output, vectorised NumPy FK on the host (a subset, per joint
  transform), and the positions checked against that NumPy FK;
- `crowd.crowd_positions` for 10k / 100k / 1M characters (frames/s), split into synthesis and
  pose, checked against NumPy synthesis + FK on a subset of characters;
- the number of kernels each compiled program launches (fusions, custom calls and loops in the
  optimized HLO's entry computation, loop bodies counted once per trip), which is what bounds
  small batches on a GPU.

The targets (issue 26): >= 10 G joint transforms/s for batched FK and >= 60 frames/s for a crowd
of 1,000,000 characters, on one GPU.
"""

from __future__ import annotations

import argparse
import json
import os
import re
import subprocess
import sys
import time
import traceback

import numpy as np

from experiments.benchmarks._common import Record, rate_str, timeit

FK_TARGET = 10e9
CROWD_TARGET = 60.0


def _nvidia_smi() -> str | None:
    try:
        out = subprocess.run(["nvidia-smi", "--query-gpu=name,memory.total,clocks.sm,clocks.max.sm,driver_version",
                              "--format=csv,noheader"], capture_output=True, text=True, timeout=20)
        return out.stdout.strip() or None
    except (OSError, subprocess.SubprocessError):
        return None


def kernel_count(compiled_text: str) -> dict:
    """Kernels in an optimized HLO module: fusions, custom calls and while loops of ENTRY.

    A GPU launches (about) one kernel per fusion or custom call; a while loop's body runs once
    per trip, so its kernels are reported apart (`loops`, `loop_body_kernels`).
    """
    comps, name, lines = {}, None, []
    for line in compiled_text.splitlines():
        m = re.match(r"^(ENTRY\s+)?%?([\w.\-]+)\s.*\{\s*$", line)
        if m and not line.startswith(" "):
            name, lines = ("ENTRY" if m.group(1) else m.group(2)), []
            comps[name] = lines
        elif name is not None:
            lines.append(line)

    def count(body):
        return sum(1 for ln in body if re.search(r"\b(fusion|custom-call)\(", ln)
                   or " fusion(" in ln or "custom-call(" in ln)

    entry = comps.get("ENTRY", [])
    loops = [ln for ln in entry if " while(" in ln]
    body_kernels = 0
    for ln in loops:
        m = re.search(r"body=%?([\w.\-]+)", ln)
        if m and m.group(1) in comps:
            body_kernels += count(comps[m.group(1)])
    return {"entry_kernels": count(entry), "loops": len(loops), "loop_body_kernels": body_kernels}


def _compiled_kernels(fn, *args) -> dict:
    import jax

    try:
        return kernel_count(jax.jit(fn).lower(*args).compile().as_text())
    except Exception as err:  # diagnostics only
        return {"error": f"{type(err).__name__}: {err}"}


def ceilings(small: bool) -> dict:
    """Copy bandwidth (bytes read + written / s) and float32 FMA rate, measured here."""
    import jax
    import jax.numpy as jnp

    n = (1 << 18) if small else (1 << 30)  # 4 GiB of float32 on the GPU
    x = jax.random.normal(jax.random.key(0), (n,), jnp.float32)
    copy = jax.jit(lambda v: v * 1.0001)
    t = timeit(lambda: copy(x), repeats=3 if small else 10, warmup=1)["median"]
    bandwidth = 2 * 4 * n / t
    m = (1 << 16) if small else (1 << 26)
    y = x[:m]
    steps = 256

    @jax.jit
    def fma(v):
        a = v
        for _ in range(steps):
            a = a * 0.999 + 0.001
        return a

    tf = timeit(lambda: fma(y), repeats=3 if small else 10, warmup=1)["median"]
    return {"copy_bytes_per_s": bandwidth, "fma_gflops": 2 * steps * m / tf / 1e9}


def _failed(name: str, unit: str, target: float, err: Exception) -> Record:
    """A record not measured, with the error (one failing size must not hide the others)."""
    traceback.print_exc()
    return Record(name, None, None, unit, target=target, target_on="ours",
                  notes=[f"not measured: {type(err).__name__}: {err}"])


def _report(rec: Record, ms_key: str) -> Record:
    print(f"  {rec.name}: {rate_str(rec.ours)} {rec.unit} ({rec.details.get(ms_key, float('nan')):.3g} ms, "
          f"err {rec.details.get('max_abs_position_diff_vs_numpy', float('nan')):.2g})", flush=True)
    return rec


def _device_channels(src: np.ndarray, clips: int, frames: int, seed: int = 0):
    """`[clips, frames, C]` float32 on the device: windows of `src` plus N(0, 2 deg) noise."""
    import jax
    import jax.numpy as jnp

    key_start, key_noise = jax.random.split(jax.random.key(seed))

    @jax.jit
    def make(s):
        start = jax.random.randint(key_start, (clips, 1), 0, s.shape[0])
        idx = (jnp.arange(frames)[None, :] + start) % s.shape[0]
        return s[idx] + 2.0 * jax.random.normal(key_noise, (clips, frames, s.shape[1]), jnp.float32)

    return jax.block_until_ready(make(jnp.asarray(src, jnp.float32)))


def fk_records(small: bool, device: str, limits: dict) -> list[Record]:
    import jax
    import jax.numpy as jnp

    from experiments.benchmarks.numpy_fk import numpy_fk
    from fourierjax import data, kinematics

    m = data.load("07_01")
    skel, topo = m.skeleton(), m.topology
    J = topo.num_joints
    src = m.channels.astype(np.float32)
    cases = [(16, 24), (64, 24)] if small else [(1024, 240), (16384, 240), (65536, 240)]
    out = []
    for clips, frames in cases:
        name = f"gpu_fk_{clips}x{frames}"
        try:
            x = _device_channels(src, clips, frames)
            n = clips * frames * J
            t0 = time.perf_counter()
            jax.block_until_ready(kinematics.joint_positions(skel, x))
            first_jp = time.perf_counter() - t0
            t0 = time.perf_counter()
            jax.block_until_ready(kinematics.fk_frames(skel, x))
            first_fk = time.perf_counter() - t0
            reps = 3 if small else 20
            jp = timeit(lambda: kinematics.joint_positions(skel, x), repeats=reps, warmup=2)
            fk = timeit(lambda: kinematics.fk_frames(skel, x), repeats=reps, warmup=2)

            @jax.jit
            def write3(v):  # the bound of writing joint_positions' output (3 floats a joint)
                return jnp.broadcast_to(v[..., :1, None], (*v.shape[:-1], J, 3)) * 1.0

            wr3 = timeit(lambda: write3(x), repeats=reps, warmup=2)
            # NumPy FK on the host, on a subset (per joint transform), and the positions checked.
            sub = min(clips, 64)
            ch_sub = np.asarray(x[:sub])
            offsets = np.asarray(skel.offsets, np.float32)
            _, p_ref = numpy_fk(topo, offsets, ch_sub)
            p_ours = np.asarray(kinematics.joint_positions(skel, x[:sub]))
            p_big = np.asarray(jax.jit(kinematics.joint_positions)(skel, x)[:sub])
            err = float(max(np.abs(p_ours - p_ref).max(), np.abs(p_big - p_ref).max()))
            base = timeit(lambda: numpy_fk(topo, offsets, ch_sub), repeats=2, warmup=0)
            rate = n / jp["median"]
            rec = Record(
                name, rate, sub * frames * J / base["median"], "joint transforms/s",
                target=FK_TARGET, target_on="ours",
                description=f"{clips} clips x {frames} frames x {J} joints (CMU 07_01 + noise) on {device}: "
                            "kinematics.joint_positions, float32",
                baseline_name=f"vectorised NumPy FK on the host CPU ({sub} clips)",
                ours_stats=jp, baseline_stats=base,
                details={"joint_transforms": n, "max_abs_position_diff_vs_numpy": err,
                         "joint_positions_first_call_s": first_jp, "fk_frames_first_call_s": first_fk,
                         "fk_frames_rate": n / fk["median"], "fk_frames_ms": 1e3 * fk["median"],
                         "joint_positions_ms": 1e3 * jp["median"],
                         "positions_write_bound_rate": n / wr3["median"],
                         "fraction_of_positions_write_bound": wr3["median"] / jp["median"],
                         "output_bytes_per_s": n * 12 / jp["median"],
                         "fraction_of_copy_bandwidth": (n * 12 + x.size * 4) / jp["median"]
                         / limits.get("copy_bytes_per_s", np.nan),
                         "flops_per_s_at_120_per_transform": 120 * rate,
                         "fraction_of_fma_rate": 120 * rate / 1e9 / limits.get("fma_gflops", np.nan),
                         "joint_positions_kernels": _compiled_kernels(kinematics.joint_positions, skel, x),
                         "fk_frames_kernels": _compiled_kernels(kinematics.fk_frames, skel, x)},
            )
        except Exception as err:
            rec = _failed(name, "joint transforms/s", FK_TARGET, err)
        out.append(_report(rec, "joint_positions_ms"))
    return out


def fk_parts(small: bool, device: str) -> list[Record]:
    """Where one FK chunk's time goes: input gather, pose, output transpose, and alternatives.

    One chunk of M frames (no loop), each stage jitted alone on its own input, every stage's
    output stored: `input_*` turns `[M, C]` channels into plan rows `[R, M]`, `pose` is the
    characters-last FK of the crowd (`pose_rows` + `gather_levels`), `output_*` turns `[J, 3, M]`
    back into `[M, J, 3]`.
    """
    import jax
    import jax.numpy as jnp

    from fourierjax import _fk, data, kinematics

    m = data.load("07_01")
    skel, topo = m.skeleton(), m.topology
    J = topo.num_joints
    frames = 4096 if small else 1 << 20
    flat = _device_channels(m.channels.astype(np.float32), 1, frames)[0]
    the_plan = _fk.plan(topo, all_rotations=False)
    rows = np.asarray(the_plan.rows, np.int32)
    dtype = flat.dtype
    reps = 3 if small else 20

    def pose(x):
        _, p = _fk.pose_rows(the_plan, x, skel.offsets, keep=_fk.store)
        return _fk.gather_levels(the_plan, p, 3, False, (x.shape[1],), dtype)

    stages = {
        "chunk_joint_positions": lambda f: kinematics._fk_chunk(skel, f, False)[1],
        "input_gather_then_transpose": lambda f: _fk.store(f[:, rows].T),
        "input_transpose_then_gather": lambda f: _fk.store(f.T[rows]),
        "input_transpose_only": lambda f: _fk.store(f.T),
        "input_selection_matmul": lambda f: _fk.store(jnp.einsum(
            "rc,mc->rm", jax.nn.one_hot(rows, f.shape[1], dtype=f.dtype), f, precision=jax.lax.Precision.HIGHEST)),
        "chunk_transpose_first": lambda f: jnp.transpose(pose(f.T[rows]), (2, 0, 1)),
    }
    x_rows = jax.block_until_ready(jax.jit(lambda f: f.T[rows])(flat))
    pose_out = jax.block_until_ready(jax.jit(pose)(x_rows))
    out = {}
    for name, fn in stages.items():
        f = jax.jit(fn)
        out[name] = timeit(lambda f=f: f(flat), repeats=reps, warmup=2)["median"]
    f = jax.jit(pose)
    out["pose_characters_last"] = timeit(lambda: f(x_rows), repeats=reps, warmup=2)["median"]
    def to_frames_major(a):
        return a.reshape(J * 3, frames).T.reshape(frames, J, 3)

    for name, fn in {"output_reshape_transpose": to_frames_major,
                     "output_transpose_201": lambda a: jnp.transpose(a, (2, 0, 1)),
                     "output_store_then_transpose": lambda a: to_frames_major(_fk.store(a))}.items():
        f = jax.jit(fn)
        out[name] = timeit(lambda f=f: f(pose_out), repeats=reps, warmup=2)["median"]
    ref = np.asarray(kinematics._fk_chunk(skel, flat[:256], False)[1])
    alt = np.asarray(jax.jit(stages["chunk_transpose_first"])(flat[:256]))
    n = frames * J
    details = {f"{k}_ms": 1e3 * v for k, v in out.items()}
    details.update({f"{k}_rate": n / v for k, v in out.items() if k.startswith("chunk") or k.startswith("pose")})
    details["transpose_first_max_abs_diff"] = float(np.abs(ref - alt).max())
    details["input_megabytes"] = flat.size * 4 / 1e6
    details["output_megabytes"] = n * 3 * 4 / 1e6
    for k, v in out.items():
        print(f"  fk part {k}: {1e3 * v:.3f} ms", flush=True)
    return [Record(f"gpu_fk_parts_{frames}", n / out["chunk_joint_positions"], None, "joint transforms/s",
                   description=f"one FK chunk of {frames} frames x {J} joints on {device}, by stage",
                   details=details)]


def crowd_records(small: bool, device: str) -> list[Record]:
    import jax
    import jax.numpy as jnp

    from experiments.benchmarks.crowd import crowd_models, frame_clock
    from experiments.benchmarks.numpy_fk import numpy_fk
    from experiments.benchmarks.synthesis import numpy_synthesize
    from fourierjax import _fk
    from fourierjax import crowd as crowd_mod

    sizes = [64, 256] if small else [10_000, 100_000, 1_000_000]
    out = []
    for num in sizes:
        name = f"gpu_crowd_{num}"
        try:
            skel, models = crowd_models(num)
            crowd = crowd_mod.make_crowd(skel, models)
            _, tick = frame_clock()

            t0 = time.perf_counter()
            jax.block_until_ready(crowd_mod.crowd_positions(crowd, jnp.float32(0.0)))
            first = time.perf_counter() - t0
            reps = 3 if small else 30
            ours = timeit(lambda: crowd_mod.crowd_positions(crowd, tick()), repeats=reps, warmup=3)
            pose = jax.jit(crowd_mod._pose)
            pose_t = timeit(lambda: pose(crowd, tick()), repeats=reps, warmup=3)
            chans = jax.jit(lambda c, t: crowd_mod._channels(c, t, _fk.store))
            chan_t = timeit(lambda: chans(crowd, tick()), repeats=reps, warmup=3)
            # Checked against NumPy synthesis + FK on the first characters.
            sub = min(num, 256)
            t_check = 0.37
            a, b = (np.asarray(v)[:sub] for v in models.sin_cos())
            off, om = np.asarray(models.offset)[:sub], np.asarray(models.omega)[:sub]
            ch = numpy_synthesize(off, a, b, om, np.asarray([t_check], np.float32))[:, 0]
            _, p_ref = numpy_fk(skel.topology, np.asarray(skel.offsets, np.float32), ch)
            got = np.asarray(crowd_mod.crowd_positions(crowd, jnp.float32(t_check))[:sub])
            err = float(np.abs(got - p_ref).max())
            base = timeit(lambda: numpy_fk(skel.topology, np.asarray(skel.offsets, np.float32),
                                           numpy_synthesize(off, a, b, om, np.asarray([t_check], np.float32))[:, 0]),
                          repeats=2, warmup=0)
            J = skel.topology.num_joints
            fps = 1.0 / ours["median"]
            rec = Record(
                name, fps, sub / num / base["median"], "animation frames/s",
                target=CROWD_TARGET, target_on="ours",
                description=f"{num} characters x {skel.topology.num_channels} channels (N = 3), synthesized "
                            f"and posed ({J} joints) per frame on {device}: crowd.crowd_positions -> [B, J, 3]",
                baseline_name=f"NumPy synthesis + FK on the host CPU ({sub} characters, scaled to {num})",
                ours_stats=ours,
                details={"characters": num, "ms_per_frame": 1e3 * ours["median"], "first_call_s": first,
                         "joint_transforms_per_s": num * J / ours["median"],
                         "characters_last_pose_ms": 1e3 * pose_t["median"],
                         "synthesis_channels_only_ms": 1e3 * chan_t["median"],
                         "coefficient_megabytes": crowd.coefficients.size * 4 / 1e6,
                         "output_megabytes_per_frame": num * J * 3 * 4 / 1e6,
                         "max_abs_position_diff_vs_numpy": err,
                         "kernels": _compiled_kernels(crowd_mod._positions, crowd, jnp.float32(0.0))},
            )
        except Exception as err:
            rec = _failed(name, "animation frames/s", CROWD_TARGET, err)
        out.append(_report(rec, "ms_per_frame"))
    return out


def main(argv=None) -> int:
    p = argparse.ArgumentParser(prog="python -m experiments.benchmarks.gpu", description=__doc__.splitlines()[0])
    p.add_argument("--out", default="out/bench_gpu")
    p.add_argument("--small", action="store_true", help="tiny sizes (a smoke test; numbers mean nothing)")
    p.add_argument("--only", default="fk,crowd", help="comma-separated subset of fk,fkparts,crowd")
    args = p.parse_args(argv)
    import jax

    os.makedirs(args.out, exist_ok=True)
    device = str(jax.devices()[0].device_kind)
    meta = {"jax": jax.__version__, "devices": [str(d) for d in jax.devices()], "device_kind": device,
            "nvidia_smi": _nvidia_smi(), "started_utc": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime()),
            "size": "small" if args.small else "full"}
    print(f"fourierjax GPU benchmarks on {meta['devices']} ({meta['nvidia_smi']}), jax {jax.__version__}", flush=True)
    t_all = time.perf_counter()
    try:
        limits = ceilings(args.small)
    except Exception:
        traceback.print_exc()
        limits = {}
    meta["ceilings"] = limits
    print(f"  ceilings: copy {rate_str(limits.get('copy_bytes_per_s'))}B/s, "
          f"fma {limits.get('fma_gflops', float('nan')):.4g} GFLOP/s", flush=True)
    records = []

    def dump():
        with open(os.path.join(args.out, "gpu.json"), "w") as f:
            json.dump({"meta": meta, "records": [r.as_json() for r in records]}, f, indent=1, default=str)

    only = set(args.only.split(","))
    if jax.default_backend() == "gpu":
        # A lent machine's MemTotal starts small and grows as memory is used (the device notes),
        # so the library's host-memory budget (a quarter of MemTotal) would refuse a crowd of a
        # million characters that the GPU holds with room to spare. The benchmark sets the budget.
        from fourierjax import _memory

        meta["machine_memory_at_start"] = _memory.machine_memory()
        _memory.default_limit = lambda: 96 * 2**30
    if "fk" in only:
        records += fk_records(args.small, device, limits)
        dump()
    if "fkparts" in only:
        records += fk_parts(args.small, device)
        dump()
    if "crowd" in only:
        records += crowd_records(args.small, device)
    meta["seconds"] = round(time.perf_counter() - t_all, 1)
    dump()
    for r in records:
        r.finish()
        print(f"{r.name:24s} {rate_str(r.ours):>8s} {r.unit:20s} target {rate_str(r.target)} met {r.met}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
