"""A crowd in real time: N characters synthesized (Fourier) and posed (FK) per animation frame."""

from __future__ import annotations

import numpy as np

from experiments.benchmarks._common import Record, timeit
from experiments.benchmarks.numpy_fk import numpy_fk
from experiments.benchmarks.synthesis import numpy_synthesize


def crowd_models(num_chars: int, seed: int = 0):
    """`(skeleton, models)`: one Fourier model per character over every BVH channel of CMU 07_01.

    Offsets are the clip's mean pose, spread over a square for the root position; amplitudes
    (degrees) fall as 1/n; each character has its own omega (4-8 rad/s) and phases.
    """
    import jax.numpy as jnp

    from fourierjax import data
    from fourierjax.fourier import FourierModel

    m = data.load("07_01")
    rng = np.random.default_rng(seed)
    C, N = m.topology.num_channels, 3
    side = int(np.ceil(np.sqrt(num_chars)))
    off = np.broadcast_to(m.channels.mean(0), (num_chars, C)).copy()
    off[:, 0] = (np.arange(num_chars) % side) * 50.0  # Xposition
    off[:, 2] = (np.arange(num_chars) // side) * 50.0  # Zposition
    amp = rng.uniform(1.0, 15.0, size=(num_chars, C, N)) / np.arange(1, N + 1)
    ph = rng.uniform(-np.pi, np.pi, size=amp.shape)
    om = rng.uniform(4.0, 8.0, size=num_chars)
    f = np.float32
    models = FourierModel(jnp.asarray(off, f), jnp.asarray(amp, f), jnp.asarray(ph, f), jnp.asarray(om, f))
    return m.skeleton(), models


def frame_clock(fps: float = 60.0):
    """`(clock, tick)`: `tick()` advances `clock["t"]` (seconds) by one animation frame and returns
    it as a NumPy float32 scalar, so each timed call of a crowd sees a new time (nothing is
    cached). NumPy, as an application's clock would be: a `jnp` scalar cost ~35 us a frame to
    make, ~25 us more per call than passing the NumPy scalar to the jitted call."""
    clock = {"t": 0.0}

    def tick():
        clock["t"] += 1 / fps
        return np.float32(clock["t"])

    return clock, tick


def make_crowd_frame(fused_basis: bool = False):
    """The jitted per-frame step: `(skeleton, models, t) -> joint positions [B, J, 3]`.

    `fused_basis=True` synthesizes with the one-contraction formulation measured in
    `synthesis.variants` (a proposal for `fourier.synthesize`) instead of the library's.
    """
    import jax

    from experiments.benchmarks.synthesis import variants
    from fourierjax import fourier, kinematics

    synth = variants()["fused_basis"] if fused_basis else fourier.synthesize

    @jax.jit
    def crowd_frame(skeleton, models, t):
        channels = jax.vmap(lambda mdl: synth(mdl, t[None])[0])(models)  # [B, C]
        return kinematics.joint_positions(skeleton, channels)

    return crowd_frame


def run(size: str) -> list[Record]:
    import time

    import jax
    import jax.numpy as jnp

    from experiments.benchmarks.fk import compute_limit, fractions
    from fourierjax import crowd as crowd_mod
    from fourierjax import kinematics
    from fourierjax._sincos import half_angle_sincos_degrees

    B = 10_000 if size == "full" else 64
    repeats = 15 if size == "full" else 2
    skel, models = crowd_models(B)
    crowd = crowd_mod.make_crowd(skel, models)
    clock, tick = frame_clock()

    t0 = time.perf_counter()
    jax.block_until_ready(crowd_mod.crowd_positions(crowd, jnp.float32(0.0)))
    first_call_s = time.perf_counter() - t0

    def step():
        return crowd_mod.crowd_positions(crowd, tick())

    # NumPy baseline: vectorised synthesis (linear coefficients precomputed, as ours) + FK.
    a, b = (np.asarray(v) for v in models.sin_cos())
    off, om = np.asarray(models.offset), np.asarray(models.omega)
    offsets = np.asarray(skel.offsets, np.float32)
    topo = skel.topology

    def numpy_step():
        clock["t"] += 1 / 60
        ch = numpy_synthesize(off, a, b, om, np.asarray([clock["t"]], np.float32))[:, 0]
        return numpy_fk(topo, offsets, ch)[1]

    ref = numpy_step()
    clock["t"] -= 1 / 60
    err = float(np.abs(np.asarray(step()) - ref).max())
    clock["t"] = 0.0
    # Ours and the baseline twice each, interleaved: the machine may be shared.
    ours_runs, base_runs = [], []
    for _ in range(2):
        ours_runs.append(timeit(step, repeats=repeats, warmup=2))
        base_runs.append(timeit(numpy_step, repeats=max(1, repeats // 5)))
    ours = min(ours_runs, key=lambda r: r["median"])
    base = min(base_runs, key=lambda r: r["median"])

    # Where the time goes: synthesis of the kept channels and their sin/cos alone, and the
    # pose with characters last (no final transpose to [B, J, 3]).
    from fourierjax import _fk

    @jax.jit
    def synthesis_only(c, t):  # the kept channels and the half-angle sincos of their rotations
        x = crowd_mod._channels(c, t, _fk.store)
        num_rot = _fk.plan(c.topology, all_rotations=False).num_rot
        return half_angle_sincos_degrees(x[:num_rot])  # as `_fk.positions`

    @jax.jit
    def channels_only(c, t):  # without the sin/cos of the Euler angles
        return crowd_mod._channels(c, t, _fk.store)

    @jax.jit
    def read_floor(c, t):  # one pass over the coefficients: the memory floor of synthesis
        k = c.coefficients
        return sum(k[i] for i in range(k.shape[0] - 1)) + k[-1] * t

    pose_soa = jax.jit(crowd_mod._pose)
    synth_t = timeit(lambda: synthesis_only(crowd, tick()), repeats=repeats, warmup=2)
    chan_t = timeit(lambda: channels_only(crowd, tick()), repeats=repeats, warmup=2)
    floor_t = timeit(lambda: read_floor(crowd, tick()), repeats=repeats, warmup=2)
    soa_t = timeit(lambda: pose_soa(crowd, tick()), repeats=repeats, warmup=2)

    # Earlier formulations, for the record: synthesize every channel per character (vmapped
    # fourier.synthesize) then kinematics.joint_positions; and the same with the linear
    # coefficients precomputed once.
    old = make_crowd_frame()

    @jax.jit
    def linear_frame(skeleton, offset, a, b, omega, t):
        n = jnp.arange(1, a.shape[-1] + 1, dtype=a.dtype)
        nt = (omega * t)[:, None] * n  # [B, N]
        ch = offset + (jnp.sin(nt)[:, None, :] * a).sum(-1) + (jnp.cos(nt)[:, None, :] * b).sum(-1)
        return kinematics.joint_positions(skeleton, ch)

    aj, bj = models.sin_cos()
    vrep = max(2, repeats // 3)
    old_t = timeit(lambda: old(skel, models, tick()), repeats=vrep, warmup=1)
    lin_t = timeit(lambda: linear_frame(skel, models.offset, aj, bj, models.omega, tick()),
                   repeats=vrep, warmup=1)
    J = topo.num_joints
    fps = [1.0 / r["median"] for r in ours_runs]
    base_fps = [1.0 / r["median"] for r in base_runs]
    rec = Record(
        "crowd_10k", 1.0 / ours["median"], 1.0 / base["median"], "animation frames/s",
        target=600.0, target_on="ours",
        description=f"{B} characters x {topo.num_channels} channels (N = 3) synthesized at one "
                    f"time and posed by FK ({J} joints) per frame: fourierjax.crowd.crowd_positions, "
                    "one jitted call per frame returning [B, J, 3]",
        baseline_name="NumPy synthesis (precomputed sin/cos coefficients) + vectorised NumPy FK",
        ours_stats=ours, baseline_stats=base,
        details={"characters": B, "joint_transforms_per_s": B * J / ours["median"],
                 "ms_per_frame": 1e3 * ours["median"],
                 "frames_per_s_each_run": fps, "baseline_frames_per_s_each_run": base_fps,
                 "ratio_each_run": [a / b for a, b in zip(fps, base_fps)],
                 "first_call_s": first_call_s,
                 "kept_channels": len(crowd.channel_index),
                 "synthesis_and_sincos_only_ms": 1e3 * synth_t["median"],
                 "synthesis_channels_only_ms": 1e3 * chan_t["median"],
                 "coefficient_read_floor_ms": 1e3 * floor_t["median"],
                 "coefficient_megabytes_per_frame": crowd.coefficients.size * 4 / 1e6,
                 "fk_ms_estimate": 1e3 * (ours["median"] - synth_t["median"]),
                 "variant_characters_last_output_frames_per_s": 1.0 / soa_t["median"],
                 "variant_synthesize_then_joint_positions_frames_per_s": 1.0 / old_t["median"],
                 "variant_precomputed_sin_cos_then_joint_positions_frames_per_s": 1.0 / lin_t["median"],
                 "max_abs_position_diff_vs_numpy": err,
                 **compute_limit(), **fractions(B * J / ours["median"], compute_limit())},
    )
    # The crowd with foot locking (issue 21), in the same run as crowd_10k.
    from experiments.benchmarks.footlock import lock_record

    return [rec, lock_record(size)]
