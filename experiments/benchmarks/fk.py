"""Forward kinematics throughput (joint transforms/s): `kinematics.fk_frames` vs NumPy and MJX.

Every figure is also reported as a fraction of the compute limit of the machine, estimated as
follows (issue 26). A joint transform is about 120 flops: 3 sincos of half-angles (~20 flops
each with a shared range reduction), 2 sparse quaternion products to the local rotation (~12),
a quaternion compose (28), a quaternion rotation of the bone (~30) and a translate (3). At the
float32 peak of the 2-core machine (270 GFLOP/s, FMA on 16 lanes x 2 ports x 2 cores x ~2 GHz;
`peak_gflops_measured` re-measures it in each run with a large matmul) that is about 2.2 G joint
transforms/s; a realistic 50 GFLOP/s for elementwise code gives about 0.4 G. Writing the
positions alone (12 bytes a joint) at 18 GB/s allows about 1.5 G, and `fk_frames` writes 28
bytes a joint (rotation and position) plus the End Sites. `output_write_bound_rate` measures
the write bound of the same output in the same run (fresh buffers, page faults included).
"""

from __future__ import annotations

import time

import numpy as np

from experiments.benchmarks._common import Record, timeit
from experiments.benchmarks.numpy_fk import numpy_fk

FLOPS_PER_JOINT_TRANSFORM = 120
PEAK_GFLOPS = 270.0  # float32, the 2-core machine (issue 26)
ELEMENTWISE_GFLOPS = 50.0


def compute_limit(peak_gflops: float = PEAK_GFLOPS) -> dict:
    """Joint transforms/s at the peak and at a realistic elementwise rate (see the docstring)."""
    return {"flops_per_joint_transform": FLOPS_PER_JOINT_TRANSFORM,
            "peak_gflops": peak_gflops,
            "limit_peak_joint_transforms_per_s": peak_gflops * 1e9 / FLOPS_PER_JOINT_TRANSFORM,
            "limit_elementwise_joint_transforms_per_s": ELEMENTWISE_GFLOPS * 1e9 / FLOPS_PER_JOINT_TRANSFORM}


def fractions(rate: float, limit: dict) -> dict:
    return {"fraction_of_peak_limit": rate / limit["limit_peak_joint_transforms_per_s"],
            "fraction_of_elementwise_limit": rate / limit["limit_elementwise_joint_transforms_per_s"]}


def measured_peak_gflops(n: int = 2048) -> float:
    """float32 GFLOP/s of one jitted [n, n] @ [n, n] product (the machine's peak, this run)."""
    import jax
    import jax.numpy as jnp

    a = jnp.ones((n, n), jnp.float32)
    mm = jax.jit(lambda x: x @ x)
    t = timeit(lambda: mm(a), repeats=3)["min"]
    return 2 * n**3 / t / 1e9


def clip_channels(num_clips: int, num_frames: int, seed: int = 0) -> tuple[object, np.ndarray]:
    """`(skeleton, channels [num_clips, num_frames, C] float32)`: CMU 07_01 frames plus noise."""
    from fourierjax import data

    m = data.load("07_01")
    rng = np.random.default_rng(seed)
    src = m.channels.astype(np.float32)
    idx = (np.arange(num_frames)[None, :] + rng.integers(0, len(src), size=(num_clips, 1))) % len(src)
    ch = src[idx] + rng.normal(scale=2.0, size=(num_clips, num_frames, src.shape[1])).astype(np.float32)
    return m.skeleton(), ch


def _mjx_record(size: str, skel, ch, ours_rate: float, limit: dict) -> Record:
    """MJX on (a subset of) the same frames, same skeleton, same run, positions checked."""
    import jax
    import jax.numpy as jnp

    from experiments.benchmarks import mjx
    from fourierjax import kinematics

    name, unit = "fk_1024x240_vs_mjx", "joint transforms/s"
    reason = mjx.available()
    if reason is not None:
        print(f"  fk: MJX skipped: {reason}", flush=True)
        rec = Record(name, ours_rate, None, unit, target=3.0, notes=[f"not measured: {reason}"])
        return rec
    topo = skel.topology
    flat = ch.reshape(-1, ch.shape[-1])
    sub = flat[: 4096 if size == "full" else 64]
    fn, qpos_of = mjx.mjx_positions_fn(topo, np.asarray(skel.offsets))
    q = qpos_of(sub)
    t0 = time.perf_counter()
    got = jax.block_until_ready(fn(q))
    first = time.perf_counter() - t0
    base = timeit(lambda: fn(q), repeats=3)
    ref = np.asarray(kinematics.joint_positions(skel, jnp.asarray(sub)))
    err = float(np.abs(np.asarray(got) - ref).max())
    n_base = sub.shape[0] * topo.num_joints
    base_rate = n_base / base["median"]
    return Record(
        name, ours_rate, base_rate, unit, target=3.0,
        description="fk_1024x240's rate against MuJoCo MJX (mjx.kinematics, pure-JAX impl, only "
                    "xpos kept) on the same skeleton as an MJCF model (slide/hinge joint per channel)",
        baseline_name="MuJoCo MJX mjx.kinematics under jit(vmap)",
        baseline_stats=base,
        details={"mjx_frames": int(sub.shape[0]), "mjx_first_call_s": first,
                 "max_abs_position_diff_vs_mjx": err,
                 **{f"mjx_{k}": v for k, v in fractions(base_rate, limit).items()}},
        notes=[f"MJX timed on {sub.shape[0]} frames (rate per joint transform)"],
    )


def run(size: str) -> list[Record]:
    import jax
    import jax.numpy as jnp

    from fourierjax import kinematics

    cases = [("fk_1x1000", 1, 1000), ("fk_1024x240", 1024, 240)]
    if size != "full":
        cases = [("fk_1x1000", 1, 100), ("fk_1024x240", 8, 24)]
    repeats = 5 if size == "full" else 1
    peak = measured_peak_gflops(2048 if size == "full" else 256)
    limit = compute_limit()
    out = []
    for name, clips, frames in cases:
        skel, ch = clip_channels(clips, frames)
        topo = skel.topology
        J, E = topo.num_joints, topo.num_end_sites
        x = jnp.asarray(ch)
        n_ours = clips * frames * J
        t0 = time.perf_counter()
        jax.block_until_ready(kinematics.fk_frames(skel, x))
        first = time.perf_counter() - t0
        t0 = time.perf_counter()
        jax.block_until_ready(kinematics.joint_positions(skel, x))
        first_jp = time.perf_counter() - t0
        # Frames last (issue 26): [C, M] in, [J, 3, M] out, FK's own layout, no transposes.
        x_last = jnp.asarray(np.ascontiguousarray(ch.reshape(-1, ch.shape[-1]).T))
        t0 = time.perf_counter()
        last = jax.block_until_ready(kinematics.joint_positions_frames_last(skel, x_last))
        first_last = time.perf_counter() - t0
        last_err = float(np.abs(np.moveaxis(np.asarray(last), -1, 0)
                                - np.asarray(kinematics.joint_positions(skel, x)).reshape(-1, J, 3)).max())

        @jax.jit
        def write(v):  # the bound of merely writing fk_frames' outputs (7 floats a joint, 3 an End Site)
            return (jnp.broadcast_to(v[..., :1, None], (*v.shape[:-1], J, 7)) * 1.0,
                    jnp.broadcast_to(v[..., :1, None], (*v.shape[:-1], E, 3)) * 1.0)

        @jax.jit
        def write3(v):  # ... and joint_positions' (3 floats a joint)
            return jnp.broadcast_to(v[..., :1, None], (*v.shape[:-1], J, 3)) * 1.0

        ours = timeit(lambda: kinematics.fk_frames(skel, x), repeats=repeats)
        # The compiled program alone on the padded frames it runs (`kinematics._bucketed`): what
        # the entry point's padding, cut and dispatch add (rate per frame of the clip).
        bare = None
        if clips * frames <= kinematics.PAD_LIMIT:
            rows = kinematics._padded_frames(clips * frames)
            padded = jax.device_put(np.zeros((rows, ch.shape[-1]), np.float32))
            program = getattr(kinematics._fk_frames_jit, "__wrapped__", kinematics._fk_frames_jit)
            bare = timeit(lambda: program(skel, padded), repeats=max(repeats, 20))
        jp = timeit(lambda: kinematics.joint_positions(skel, x), repeats=repeats)
        jp_last = timeit(lambda: kinematics.joint_positions_frames_last(skel, x_last), repeats=repeats)
        wr = timeit(lambda: write(x), repeats=repeats)
        wr3 = timeit(lambda: write3(x), repeats=repeats)

        # NumPy on a subset of clips when the full set would take minutes (rate per joint
        # transform is flat in the batch size once vectorised).
        sub = clips if clips * frames <= 65_536 else max(1, 65_536 // frames)
        offsets = np.asarray(skel.offsets, np.float32)
        ch_sub = ch[:sub]
        _, p = numpy_fk(topo, offsets, ch_sub)
        ref = np.asarray(kinematics.fk_frames(skel, x[:sub]).positions)
        err = float(np.abs(ref - p).max())
        base = timeit(lambda: numpy_fk(topo, offsets, ch_sub), repeats=max(1, repeats // 2))
        n_base = sub * frames * J
        rate = n_ours / ours["median"]
        rec = Record(
            name, rate, n_base / base["median"], "joint transforms/s",
            target=1e8, target_on="ours",
            description=f"{clips} clip(s) x {frames} frames x {J} joints (CMU 07_01 + noise), world "
                        "rotations + positions + End Sites (kinematics.fk_frames), float32",
            baseline_name="vectorised NumPy FK (matrices, loop over joints, np.matmul)",
            ours_stats=ours, baseline_stats=base,
            details={
                "max_abs_position_diff_vs_numpy": err,
                "first_call_s": first, "joint_positions_first_call_s": first_jp,
                "joint_positions_rate": n_ours / jp["median"],
                "joint_positions_frames_last_rate": n_ours / jp_last["median"],
                "joint_positions_frames_last_first_call_s": first_last,
                "joint_positions_frames_last_max_abs_diff": last_err,
                "output_write_bound_rate": n_ours / wr["median"],
                "fraction_of_write_bound": wr["median"] / ours["median"],
                "positions_write_bound_rate": n_ours / wr3["median"],
                "joint_positions_fraction_of_write_bound": wr3["median"] / jp["median"],
                "peak_gflops_measured": peak,
                **({} if bare is None else {"program_only_rate": n_ours / bare["median"],
                                            "entry_overhead_s": ours["median"] - bare["median"]}),
                **compute_limit(), **fractions(rate, limit),
                **{f"joint_positions_{k}": v for k, v in fractions(n_ours / jp["median"], limit).items()},
                **{f"joint_positions_frames_last_{k}": v
                   for k, v in fractions(n_ours / jp_last["median"], limit).items()},
            },
        )
        if sub != clips:
            rec.notes.append(f"NumPy baseline timed on the first {sub} of {clips} clips (rate per joint transform)")
        out.append(rec)
        if name == "fk_1024x240":
            out.append(_mjx_record(size, skel, ch, rate, limit))
    return out
