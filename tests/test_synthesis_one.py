"""One character's synthesis on CPU: loops XLA compiles into single kernels and runs inline."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from fourierjax import fourier as F
from fourierjax._fourier import _synthesis as S


def _models(seed, C, N):
    rng = np.random.default_rng(seed)
    amp = rng.uniform(0.05, 0.5, size=(1, C, N)) / np.arange(1, N + 1)
    return F.FourierModel(
        jnp.asarray(rng.normal(size=(1, C)), jnp.float32), jnp.asarray(amp, jnp.float32),
        jnp.asarray(rng.uniform(-np.pi, np.pi, size=(1, C, N)), jnp.float32),
        jnp.asarray(rng.uniform(4.0, 8.0, size=1), jnp.float32),
    )


def _eq1(models, t):
    off, amp, ph, om = (np.asarray(x, np.float64) for x in (models.offset, models.amplitude,
                                                           models.phase, models.omega))
    n = np.arange(1, amp.shape[-1] + 1)
    arg = n * (om[0] * np.asarray(t, np.float64))[:, None, None] + ph[0]  # [T, C, N]
    return (off[0] + np.sum(amp[0] * np.sin(arg), axis=-1))[None]


@pytest.mark.skipif(jax.default_backend() != "cpu", reason="XLA:CPU's loop hoisting and inline execution")
@pytest.mark.parametrize("C, N", [(57, 3), (1, 1), (10, 4), (10, 5), (64, 2), (90, 3), (200, 1), (75, 3)])
@pytest.mark.parametrize("T", [240, 241])
def test_loops_are_single_kernels_under_the_inline_budget(C, N, T):
    """Both loops of `_synthesize_one_loop` are hoisted into one kernel each (the step's bytes
    under XLA's threshold, `_LOOP_BYTES`), XLA counts no more flops than `_inline_flops` and
    fewer than its inline budget, and the values are Unuma's eq. 1 (odd T: one frame a step)."""
    models = _models(C * 10 + N, C, N)
    t = jnp.arange(T, dtype=jnp.float32) / 120.0
    assert S._inline_flops(C, N) < S._INLINE_FLOPS
    args = (models.offset, models.amplitude, models.phase, models.omega, t)
    compiled = S._synthesize_batch_jit.lower(*args).compile()
    cost = compiled.cost_analysis()
    cost = cost[0] if isinstance(cost, list) else cost
    assert cost["flops"] <= S._inline_flops(C, N) < S._INLINE_FLOPS
    text = compiled.as_text()
    assert text.count(" while(") == 2
    assert text.count('xla_cpu_small_call="true"') == 2
    np.testing.assert_allclose(F.synthesize_batch(models, t), _eq1(models, t), atol=3e-6)


def test_odd_frame_count_values_and_gradients():
    """An odd frame count takes one frame a step; values and gradients are the vmap's."""
    models = _models(3, 57, 3)
    t = jnp.arange(37, dtype=jnp.float32) / 60.0
    np.testing.assert_allclose(F.synthesize_batch(models, t), _eq1(models, t), atol=3e-6)
    w = jnp.asarray(np.random.default_rng(4).normal(size=(1, 37, 57)), jnp.float32)
    g = jax.grad(lambda m: jnp.sum(w * F.synthesize_batch(m, t)))(models)
    ref = jax.grad(lambda m: jnp.sum(w * jax.vmap(F.synthesize, in_axes=(0, None))(m, t)))(models)
    for field in ("offset", "amplitude", "phase", "omega"):
        np.testing.assert_allclose(getattr(g, field), getattr(ref, field), rtol=2e-4, atol=2e-3)


def test_plan_chunks_cover_the_channels():
    for C in (1, 19, 28, 57, 100, 300):
        for N in (1, 3, 5):
            frames, chunks, width, _ = S._loop_plan(C, N)
            assert frames in (1, 2) and chunks * width >= C > (chunks - 1) * width
            assert 4 * ((2 * N + 1 + frames) * width + 2 * N * frames) <= S._LOOP_BYTES or width == 1
