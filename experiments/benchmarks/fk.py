"""Forward kinematics throughput (joint transforms/s): `kinematics.fk_frames` vs vectorised NumPy."""

from __future__ import annotations

import numpy as np

from experiments.benchmarks._common import Record, timeit
from experiments.benchmarks.numpy_fk import numpy_fk


def clip_channels(num_clips: int, num_frames: int, seed: int = 0) -> tuple[object, np.ndarray]:
    """`(skeleton, channels [num_clips, num_frames, C] float32)`: CMU 07_01 frames plus noise."""
    from fourierjax import data

    m = data.load("07_01")
    rng = np.random.default_rng(seed)
    src = m.channels.astype(np.float32)
    idx = (np.arange(num_frames)[None, :] + rng.integers(0, len(src), size=(num_clips, 1))) % len(src)
    ch = src[idx] + rng.normal(scale=2.0, size=(num_clips, num_frames, src.shape[1])).astype(np.float32)
    return m.skeleton(), ch


def run(size: str) -> list[Record]:
    import jax
    import jax.numpy as jnp

    from fourierjax import kinematics

    cases = [("fk_1x1000", 1, 1000), ("fk_1024x240", 1024, 240)]
    if size != "full":
        cases = [("fk_1x1000", 1, 100), ("fk_1024x240", 8, 24)]
    repeats = 5 if size == "full" else 1
    out = []
    for name, clips, frames in cases:
        skel, ch = clip_channels(clips, frames)
        topo = skel.topology
        J = topo.num_joints
        x = jnp.asarray(ch)
        n_ours = clips * frames * J
        ours = timeit(lambda: kinematics.fk_frames(skel, x), repeats=repeats)

        # NumPy on a subset of clips when the full set would take minutes (rate per joint
        # transform is flat in the batch size once vectorised).
        sub = clips if clips * frames <= 65_536 else max(1, 65_536 // frames)
        offsets = np.asarray(skel.offsets, np.float32)
        ch_sub = ch[:sub]
        R, p = numpy_fk(topo, offsets, ch_sub)
        ref = np.asarray(kinematics.fk_frames(skel, x[:sub]).positions)
        err = float(np.abs(ref - p).max())
        base = timeit(lambda: numpy_fk(topo, offsets, ch_sub), repeats=max(1, repeats // 2))
        n_base = sub * frames * J

        # Context: the straightforward jitted FK (vmap of the one-frame function) and the
        # bound of merely writing the same outputs (7 floats per joint, 3 per End Site).
        details = {"max_abs_position_diff_vs_numpy": err}
        vm = jax.jit(lambda s, c: jax.vmap(jax.vmap(lambda f: kinematics.fk_from_channels(s, f)))(c))
        x_sub = x[:sub]
        if size == "full":  # context only: skipped at --small to keep CI short
            vm_t = timeit(lambda: vm(skel, x_sub), repeats=max(1, repeats // 2))
            details["vmap_one_frame_fk_rate"] = n_base / vm_t["median"]
            details["speedup_vs_vmap_one_frame_fk"] = (n_ours / ours["median"]) / (n_base / vm_t["median"])
        E = topo.num_end_sites

        @jax.jit
        def write(v):
            return (jnp.broadcast_to(v[..., :1, None], (*v.shape[:-1], J, 7)) * 1.0,
                    jnp.broadcast_to(v[..., :1, None], (*v.shape[:-1], E, 3)) * 1.0)

        wr = timeit(lambda: write(x), repeats=repeats)
        rec = Record(
            name,
            n_ours / ours["median"],
            n_base / base["median"],
            "joint transforms/s",
            target=5.0 if name == "fk_1024x240" else None,
            description=f"{clips} clip(s) x {frames} frames x {J} joints (CMU 07_01 + noise), world "
                        "rotations + positions + End Sites, float32",
            baseline_name="vectorised NumPy FK (matrices, loop over joints, np.matmul)",
            ours_stats=ours,
            baseline_stats=base,
            details={
                **details,
                "output_write_bound_rate": n_ours / wr["median"],
                "fraction_of_write_bound": wr["median"] / ours["median"],
            },
        )
        if sub != clips:
            rec.notes.append(f"NumPy and vmap baselines timed on the first {sub} of {clips} clips "
                             "(rates per joint transform)")
        out.append(rec)
    return out
