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
    import jax.numpy as jnp

    B = 10_000 if size == "full" else 64
    repeats = 15 if size == "full" else 2
    skel, models = crowd_models(B)
    crowd_frame = make_crowd_frame()
    clock = {"t": 0.0}

    def step():
        clock["t"] += 1 / 60
        return crowd_frame(skel, models, jnp.asarray(clock["t"], jnp.float32))

    ours = timeit(step, repeats=repeats, warmup=2)

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
    base = timeit(numpy_step, repeats=max(1, repeats // 3))
    fused = make_crowd_frame(fused_basis=True)

    # Proposal: the crowd's models never change between frames, so their linear coefficients
    # (a, b) = sin_cos() can be computed once; per frame only N sin/cos per character remain
    # (amplitude/phase form costs 2 x C x N trig calls per character per frame).
    import jax

    from fourierjax import kinematics

    @jax.jit
    def linear_frame(skeleton, offset, a, b, omega, t):
        n = jnp.arange(1, a.shape[-1] + 1, dtype=a.dtype)
        nt = (omega * t)[:, None] * n  # [B, N]
        ch = offset + (jnp.sin(nt)[:, None, :] * a).sum(-1) + (jnp.cos(nt)[:, None, :] * b).sum(-1)
        return kinematics.joint_positions(skeleton, ch)

    aj, bj = models.sin_cos()
    lin_err = float(np.abs(np.asarray(linear_frame(skel, models.offset, aj, bj, models.omega,
                                                   jnp.asarray(0.3, jnp.float32)))
                           - np.asarray(crowd_frame(skel, models, jnp.asarray(0.3, jnp.float32)))).max())
    lin_t = timeit(lambda: linear_frame(skel, models.offset, aj, bj, models.omega,
                                        jnp.asarray(clock["t"], jnp.float32)), repeats=repeats, warmup=2)
    clock["t"] = 0.0
    fused_t = timeit(lambda: fused(skel, models, jnp.asarray(clock["t"], jnp.float32)), repeats=repeats,
                     warmup=2)
    J = topo.num_joints
    rec = Record(
        "crowd_10k", 1.0 / ours["median"], 1.0 / base["median"], "animation frames/s",
        target=60.0, target_on="ours",
        description=f"{B} characters x {topo.num_channels} channels (N = 3) synthesized at one "
                    f"time and posed by FK ({J} joints) per frame, one jitted call per frame",
        baseline_name="NumPy synthesis + vectorised NumPy FK",
        ours_stats=ours, baseline_stats=base,
        details={"characters": B, "joint_transforms_per_s": B * J / ours["median"],
                 "ms_per_frame": 1e3 * ours["median"],
                 "variant_fused_basis_synthesis_frames_per_s": 1.0 / fused_t["median"],
                 "variant_precomputed_sin_cos_frames_per_s": 1.0 / lin_t["median"],
                 "variant_precomputed_sin_cos_max_abs_diff": lin_err,
                 "max_abs_position_diff_vs_numpy": err},
    )
    return [rec]
