"""Tests of fourierjax.fourier on synthetic signals (closed forms, finite differences, vmap)."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from fourierjax import fourier as F
from fourierjax._linalg import spd_solve


def _model(rng, C=5, N=3, omega=2 * np.pi * 1.1, fundamental_scale=3.0, names=()):
    """Random model whose fundamental dominates (like a gait), phases in (-pi, pi]."""
    amp = rng.uniform(0.1, 1.0, size=(C, N))
    amp[:, 0] *= fundamental_scale
    return F.FourierModel(
        jnp.asarray(rng.normal(size=C)), jnp.asarray(amp),
        jnp.asarray(rng.uniform(-np.pi, np.pi, size=(C, N))), jnp.asarray(omega),
        "euler", names,
    )


def _eq1(model, theta):
    """Unuma 1995 eq. 1 written out term by term in numpy (the reference)."""
    off, amp, ph = (np.asarray(x, np.float64) for x in (model.offset, model.amplitude,
                                                        model.phase))
    out = np.tile(off, (len(theta), 1))
    for n in range(amp.shape[1]):
        out += amp[:, n] * np.sin((n + 1) * theta[:, None] + ph[:, n])
    return out


def test_synthesize_matches_eq1_and_time_equals_phase(x64):
    rng = np.random.default_rng(0)
    m = _model(rng)
    t = np.linspace(-1.0, 3.0, 97)
    np.testing.assert_allclose(F.synthesize(m, t), _eq1(m, float(m.omega) * t), atol=1e-12)
    np.testing.assert_allclose(F.synthesize_phase(m, float(m.omega) * t), F.synthesize(m, t),
                               atol=1e-12)


def test_cosine_convention_and_style_vector(x64):
    rng = np.random.default_rng(1)
    m = _model(rng, C=54, N=2)
    off, amp, phc = m.to_cosine()
    t = np.linspace(0, 2, 50)
    w = float(m.omega)
    # Tilmanne eq. 1: p0 + sum p_n cos(n w t + phi_n).
    ref = np.asarray(off)[None] + sum(
        np.asarray(amp)[:, n] * np.cos((n + 1) * w * t[:, None] + np.asarray(phc)[:, n])
        for n in range(2)
    )
    np.testing.assert_allclose(F.synthesize(m, t), ref, atol=1e-12)
    assert np.all(np.asarray(phc) > -np.pi) and np.all(np.asarray(phc) <= np.pi)
    back = F.FourierModel.from_cosine(off, amp, phc, m.omega)
    np.testing.assert_allclose(back.phase, m.phase, atol=1e-12)
    v = m.tilmanne_vector()
    assert v.shape == (271,)  # Tilmanne: 54 channels x 5 + omega
    assert float(v[-1]) == float(m.omega) and float(v[0]) == float(m.offset[0])
    for conv in ("sine", "cosine"):
        r = F.FourierModel.from_tilmanne_vector(m.tilmanne_vector(conv), 54, 2, convention=conv)
        np.testing.assert_allclose(r.amplitude, m.amplitude, atol=1e-12)
        np.testing.assert_allclose(F.wrap_angle(r.phase - m.phase), 0, atol=1e-12)
    with pytest.raises(ValueError, match="vector shape"):
        F.FourierModel.from_tilmanne_vector(v[:-1], 54, 2)


def test_model_validation():
    z = jnp.zeros((3, 2))
    with pytest.raises(ValueError, match="offset"):
        F.FourierModel(jnp.zeros(4), z, z, jnp.asarray(1.0))
    with pytest.raises(ValueError, match="amplitude"):
        F.FourierModel(jnp.zeros(3), z, jnp.zeros((3, 3)), jnp.asarray(1.0))
    with pytest.raises(ValueError, match="representation"):
        F.FourierModel(jnp.zeros(3), z, z, jnp.asarray(1.0), "quaternion")
    with pytest.raises(ValueError, match="channel_names"):
        F.FourierModel(jnp.zeros(3), z, z, jnp.asarray(1.0), "euler", ("a", "b"))


def test_vmap_over_characters_and_phase_shift(x64):
    rng = np.random.default_rng(2)
    models = [_model(rng) for _ in range(3)]
    stacked = F.stack_models(models)
    t = np.linspace(0, 1.5, 40)
    out = jax.vmap(F.synthesize, in_axes=(0, None))(stacked, t)
    for i, m in enumerate(models):
        np.testing.assert_allclose(out[i], F.synthesize(m, t), atol=1e-12)
    m = models[0]
    theta = np.linspace(-3, 9, 61)
    shifted = F.shift_phase(m, 0.7)
    np.testing.assert_allclose(F.synthesize_phase(shifted, theta),
                               F.synthesize_phase(m, theta + 0.7), atol=1e-12)
    assert np.all(np.abs(np.asarray(shifted.phase)) <= np.pi)


def test_fit_linear_inverts_synthesize_with_partial_cycles_and_mask(x64):
    rng = np.random.default_rng(3)
    m = _model(rng, C=6, N=4)
    T = 173  # 1.6 cycles: not a whole number
    t = np.arange(T) / 120.0
    x = np.asarray(F.synthesize(m, t))
    fitted = F.fit_linear(x, t, m.omega, 4)
    np.testing.assert_allclose(fitted.offset, m.offset, atol=1e-6)
    np.testing.assert_allclose(fitted.amplitude, m.amplitude, atol=1e-6)
    np.testing.assert_allclose(F.wrap_angle(fitted.phase - m.phase), 0, atol=1e-6)
    # Garbage in padded frames is ignored under the mask.
    xp = np.concatenate([x, rng.normal(size=(40, 6)) * 100])
    tp = np.arange(T + 40) / 120.0
    mask = np.arange(T + 40) < T
    fp = F.fit_linear(xp, tp, m.omega, 4, mask=mask)
    np.testing.assert_allclose(fp.amplitude, m.amplitude, atol=1e-6)


@pytest.fixture(scope="module")
def batch_problem():
    """64 band-limited clips of different lengths and fundamentals, padded to one length."""
    rng = np.random.default_rng(4)
    B, T, C, N = 64, 320, 4, 2
    models, feats, mask = [], np.zeros((B, T, C)), np.zeros((B, T), bool)
    lengths = rng.integers(200, T + 1, size=B)
    omegas = 2 * np.pi * rng.uniform(0.8, 1.6, size=B)
    for b in range(B):
        m = _model(rng, C=C, N=N, omega=omegas[b])
        models.append(m)
        feats[b] = _eq1(m, float(m.omega) * np.arange(T) / 120.0)
        feats[b, lengths[b]:] = 0.0  # padding
        mask[b, : lengths[b]] = True
    return models, feats, mask, lengths, N


@pytest.mark.timeout(240)
def test_batched_variable_projection_fit_recovers_models(batch_problem, x64):
    """fit ∘ synthesize is the identity (to 1e-6, x64) at >= 64 problems in one call; this
    also guards against the batched-linalg hang (pytest timeout)."""
    models, feats, mask, lengths, N = batch_problem
    res = F.fit_batch(jnp.asarray(feats), jnp.full((len(models),), 1 / 120.0), N,
                      mask=jnp.asarray(mask), channel_weights=jnp.ones(feats.shape[2]))
    om = np.array([float(m.omega) for m in models])
    np.testing.assert_allclose(res.omega_fit, om, rtol=1e-8)
    for b, m in enumerate(models):
        np.testing.assert_allclose(res.model.amplitude[b], m.amplitude, atol=1e-6)
        np.testing.assert_allclose(F.wrap_angle(res.model.phase[b] - m.phase), 0, atol=1e-6)
        np.testing.assert_allclose(res.model.offset[b], m.offset, atol=1e-6)
    assert np.all(np.asarray(res.rms_deg) < 1e-4)
    assert np.all(np.asarray(res.variance_explained_angles) > 1 - 1e-10)
    np.testing.assert_array_equal(res.num_frames, lengths)
    # The spectral peak is the fundamental or, where the 2nd harmonic dominates, twice it;
    # the guard and variable projection do the rest.
    ratio = np.asarray(res.omega_spectral) / om
    assert np.all((np.abs(ratio - 1) < 0.1) | (np.abs(ratio - 2) < 0.2))


def test_subharmonic_guard(x64):
    """A gait whose spectrum peaks at the step frequency (2nd harmonic) still gets the cycle
    frequency: by odd-harmonic energy, or by step events when given."""
    rng = np.random.default_rng(5)
    m = _model(rng, C=4, N=3, omega=2 * np.pi * 0.9, fundamental_scale=1.0)
    amp = np.asarray(m.amplitude).copy()
    amp[:, 1] = 3.0  # step frequency dominates the spectrum
    amp[:, 0] = 1.2
    m = F.FourierModel(m.offset, jnp.asarray(amp), m.phase, m.omega)
    x = F.synthesize(m, np.arange(600) / 120.0)
    r = F.fit(x, 1 / 120.0, 3, channel_weights=jnp.ones(4))
    assert abs(float(r.omega_spectral) / float(m.omega) - 2) < 0.05  # the peak is 2 omega
    np.testing.assert_allclose(float(r.omega_fit), float(m.omega), rtol=1e-7)
    # A pure step-frequency signal: the guard keeps the spectral peak without step events,
    # but step events (one cycle = two steps) give the cycle frequency.
    x2 = np.asarray(F.synthesize(m, np.arange(600) / 120.0)) - np.asarray(
        F.synthesize(F.FourierModel(m.offset * 0, jnp.asarray(amp * [1, 0, 1]), m.phase,
                                    m.omega), np.arange(600) / 120.0))
    r2 = F.fit(x2, 1 / 120.0, 3, channel_weights=jnp.ones(4))
    np.testing.assert_allclose(float(r2.omega_fit), 2 * float(m.omega), rtol=1e-6)
    r3 = F.fit(x2, 1 / 120.0, 3, channel_weights=jnp.ones(4), omega_steps=float(m.omega) * 1.03)
    np.testing.assert_allclose(float(r3.omega_guess), float(r2.omega_spectral) / 2, rtol=1e-9)


def test_synthesis_loss_gradients_match_finite_differences(x64):
    rng = np.random.default_rng(6)
    m = _model(rng, C=3, N=2)
    t = np.linspace(0, 2, 50)
    target = rng.normal(size=(50, 3))

    @jax.jit
    def loss(model):
        return jnp.sum((F.synthesize(model, t) - target) ** 2)

    g = jax.jit(jax.grad(loss))(m)
    leaves, _ = jax.tree.flatten(g)
    assert all(np.all(np.isfinite(np.asarray(leaf))) for leaf in leaves)
    eps = 1e-6
    for field in ("offset", "amplitude", "phase", "omega"):
        val = np.asarray(getattr(m, field))
        grad = np.asarray(getattr(g, field))
        for idx in list(np.ndindex(val.shape))[:4]:
            def with_delta(d, idx=idx, field=field, val=val):
                v = val.copy()
                v[idx] += d
                return float(loss(eqx_replace(m, field, jnp.asarray(v))))

            fd = (with_delta(eps) - with_delta(-eps)) / (2 * eps)
            np.testing.assert_allclose(grad[idx], fd, rtol=1e-5, atol=1e-6)
    # Gradients through the fit (variable projection) are finite too, also at zero amplitude.
    z = F.FourierModel.from_sin_cos(jnp.zeros(3), jnp.zeros((3, 2)), jnp.zeros((3, 2)), 6.0)
    gz = jax.grad(lambda a: loss(F.FourierModel.from_sin_cos(z.offset, a, a, z.omega)))(
        jnp.zeros((3, 2)))
    assert np.all(np.isfinite(np.asarray(gz)))
    gw = jax.grad(F.projected_residual)(jnp.asarray(6.0), jnp.asarray(target), jnp.asarray(t), 2)
    assert np.isfinite(float(gw))


def eqx_replace(model, field, value):
    import equinox as eqx

    return eqx.tree_at(lambda m: getattr(m, field), model, value)


def test_alignment_and_metrics(x64):
    rng = np.random.default_rng(7)
    m = _model(rng, C=3, N=2)
    w = float(m.omega)
    events = np.array([0.3, 0.3 + 2 * np.pi / w, 0.3 + 4 * np.pi / w])
    aligned, delta = F.align_to_events(m, events)
    np.testing.assert_allclose(float(delta), F.wrap_angle(w * 0.3), atol=1e-12)
    np.testing.assert_allclose(F.synthesize_phase(aligned, np.zeros(1))[0],
                               F.synthesize(m, np.array([0.3]))[0], atol=1e-12)
    c = 1
    d = F.channel_event_phase(m, c)
    peak = F.shift_phase(m, d)
    assert abs(float(F.wrap_angle(peak.phase[c, 0] - np.pi / 2))) < 1e-12
    t = np.arange(240) / 120.0
    x = np.asarray(F.synthesize(m, t))
    np.testing.assert_allclose(F.rms_error(m, x, t), 0, atol=1e-12)
    noisy = x + 0.1 * np.sin(37 * t)[:, None]
    np.testing.assert_allclose(F.rms_error(m, noisy, t), 0.1 / np.sqrt(2), rtol=0.02)
    assert float(F.variance_explained(x, x)) == 1.0
    np.testing.assert_allclose(F.energy_per_harmonic(m), 0.5 * np.asarray(m.amplitude) ** 2)
    # Amplitude spectrum: a sinusoid on a bin shows its amplitude (Tilmanne Fig. 1).
    T = 240
    s = 2.5 * np.sin(2 * np.pi * 6 * np.arange(T) / T)[:, None]
    freqs, amp = F.amplitude_spectrum(s, 1 / 120.0)
    np.testing.assert_allclose(float(amp[6, 0]), 2.5, rtol=1e-9)
    np.testing.assert_allclose(float(freqs[6]), 3.0)


def test_spd_solve_matches_numpy(x64):
    """The fit's LAPACK-free solve (Gauss-Jordan on [G | rhs]) against numpy, also under vmap."""
    rng = np.random.default_rng(8)
    for P in (3, 7, 15):
        A = rng.normal(size=(4, P, P))
        G = A @ np.swapaxes(A, -1, -2) + 0.1 * np.eye(P)
        rhs = rng.normal(size=(4, P, 5))
        got = jax.vmap(spd_solve)(jnp.asarray(G), jnp.asarray(rhs))
        np.testing.assert_allclose(got, np.linalg.solve(G, rhs), rtol=1e-9, atol=1e-11)


def test_fit_one_harmonic_and_switched_off_harmonics(x64):
    """N = 1 shares the guard's 2-harmonic solve with the 2nd harmonic switched off: it must
    equal a plain 1-harmonic least-squares fit (exact sinusoids are recovered)."""
    rng = np.random.default_rng(9)
    m = _model(rng, C=3, N=1, omega=2 * np.pi * 1.3)
    t = np.arange(400) / 120.0
    x = np.asarray(F.synthesize(m, t))
    r = F.fit(x, 1 / 120.0, 1, channel_weights=jnp.ones(3))
    np.testing.assert_allclose(float(r.omega_fit), float(m.omega), rtol=1e-8)
    np.testing.assert_allclose(r.model.amplitude, m.amplitude, atol=1e-7)
    np.testing.assert_allclose(F.wrap_angle(r.model.phase - m.phase), 0, atol=1e-7)
    # A 2nd harmonic the N = 1 model cannot hold: coefficients equal fit_linear's at that omega.
    x2 = x + 0.3 * np.sin(2 * float(m.omega) * t + 0.4)[:, None]
    r2 = F.fit(x2, 1 / 120.0, 1, channel_weights=jnp.ones(3))
    ref = F.fit_linear(x2, t, r2.omega_fit, 1)
    np.testing.assert_allclose(r2.model.amplitude, ref.amplitude, atol=1e-10)
    np.testing.assert_allclose(r2.model.offset, ref.offset, atol=1e-10)
    assert r2.model.amplitude.shape == (3, 1)


def test_fit_ignores_masked_out_nan_and_rejects_used_nan():
    """Frames left out by the mask may hold NaN (missing markers): the fit equals the fit of the
    same frames with finite values there (it used to return omega 2.09 instead of 6.91 rad/s,
    a wrong answer, from one masked NaN). NaN in a frame the fit uses, or a non-positive frame
    time, is a UserError naming where."""
    from fourierjax.errors import UserError

    t = np.arange(240) / 120
    x = np.stack([np.sin(2 * np.pi * 1.1 * t + k) for k in range(4)], -1).astype(np.float32)
    mask = np.ones(240, bool)
    mask[[5, 77]] = False
    x_nan = x.copy()
    x_nan[5, 2], x_nan[77, 0] = np.nan, np.inf
    got, ref = F.fit(x_nan, 1 / 120, 3, mask=mask), F.fit(x, 1 / 120, 3, mask=mask)
    for a, b in zip(jax.tree.leaves(got), jax.tree.leaves(ref), strict=True):
        np.testing.assert_array_equal(np.asarray(a), np.asarray(b))
    np.testing.assert_allclose(float(got.model.omega), 2 * np.pi * 1.1, rtol=1e-5)
    with pytest.raises(UserError, match=r"fit: features hold 2 NaN .* first at index \(5, 2\)"):
        F.fit(x_nan, 1 / 120, 3)
    with pytest.raises(UserError, match=r"fit_batch: .* index \(1, 5, 2\)"):
        F.fit_batch(np.stack([x, x_nan]), 1 / 120, 3)
    with pytest.raises(UserError, match="frame_time_s must be positive"):
        F.fit(x, 0.0, 3)
    # Traced inputs cannot be checked: jit of a fit still works.
    omega = jax.jit(lambda a: F.fit(a, 1 / 120, 3, mask=mask).model.omega)(jnp.asarray(x))
    np.testing.assert_allclose(float(omega), 2 * np.pi * 1.1, rtol=1e-5)


def test_fit_compiles_one_program_per_call_signature():
    """Defaults, broadcasts and casts happen inside the jitted program: a first call compiles
    exactly one XLA program (eager ops each compiled their own, seconds of first-call time)."""
    from jax import monitoring

    compiled = []

    def listener(event, duration_secs, **_):
        if event == "/jax/core/compile/backend_compile_duration":
            compiled.append(duration_secs)

    from fourierjax._jit import _cpu_options

    _cpu_options()  # its once-per-process probe compile, whichever test runs first
    rng = np.random.default_rng(10)
    x = rng.normal(size=(3, 131, 4)).astype(np.float32)  # shapes no other test uses
    monitoring.register_event_duration_secs_listener(listener)
    try:
        F.fit_batch(x, 1 / 60.0, 2, mask=np.ones((3, 131), bool), grid_points=5,
                    golden_iterations=3)
        assert len(compiled) == 1
        F.fit(x[0], 1 / 60.0, 2, omega_steps=6.0, grid_points=5, golden_iterations=3)
        assert len(compiled) == 2
        F.fit_batch(x + 1, 1 / 60.0, 2, mask=np.ones((3, 131), bool), grid_points=5,
                    golden_iterations=3)  # same signature: cached
        assert len(compiled) == 2
    finally:
        monitoring.unregister_event_duration_listener(listener)
    with pytest.raises(ValueError, match="mask shape"):
        F.fit_batch(x, 1 / 60.0, 2, mask=np.ones((3, 130), bool))
    with pytest.raises(ValueError, match="omega_steps shape"):
        F.fit_batch(x, 1 / 60.0, 2, omega_steps=np.ones(2))


# ----------------------------------------------------------------------------- synthesize_batch


def _batch(rng, B, C, N, dtype=np.float32):
    """Random stacked models: amplitudes ~ 1/n, phases in (-pi, pi], omega 4..8 rad/s."""
    amp = rng.uniform(0.05, 0.5, size=(B, C, N)) / np.arange(1, N + 1)
    return F.FourierModel(
        jnp.asarray(rng.normal(size=(B, C)), dtype), jnp.asarray(amp, dtype),
        jnp.asarray(rng.uniform(-np.pi, np.pi, size=(B, C, N)), dtype),
        jnp.asarray(rng.uniform(4.0, 8.0, size=B), dtype),
    )


def _eq1_batch(models, t):
    """Float64 numpy closed form of Unuma eq. 1 for stacked models: [B, T, C]."""
    off, amp, ph, om = (np.asarray(x, np.float64) for x in (models.offset, models.amplitude,
                                                           models.phase, models.omega))
    n = np.arange(1, amp.shape[-1] + 1)
    t = np.asarray(t, np.float64)
    theta = om[:, None] * t  # [B, T] from t [T] or [B, T]
    arg = n * theta[:, :, None, None] + ph[:, None]  # [B, T, C, N]
    return off[:, None] + np.sum(amp[:, None] * np.sin(arg), axis=-1)


@pytest.mark.parametrize("B, C, N", [(1, 1, 1), (1, 57, 3), (3, 57, 3), (5, 13, 1), (8, 8, 7), (2, 6, 4)])
def test_synthesize_batch_equals_vmap_and_closed_form(B, C, N):
    rng = np.random.default_rng(B * 100 + C * 10 + N)
    models = _batch(rng, B, C, N)
    t = jnp.asarray(np.arange(61) / 120.0 - 0.1, jnp.float32)
    out = F.synthesize_batch(models, t)
    assert out.shape == (B, 61, C) and out.dtype == jnp.float32
    ref = jax.vmap(F.synthesize, in_axes=(0, None))(models, t)
    np.testing.assert_allclose(out, ref, atol=2e-6)  # float32 round-off of |x| ~ 3
    np.testing.assert_allclose(out, _eq1_batch(models, t), atol=2e-6)
    # Under an outer jit and with one row of times per character.
    tb = jnp.asarray(np.random.default_rng(1).uniform(0, 3, size=(B, 17)), jnp.float32)
    outb = jax.jit(F.synthesize_batch)(models, tb)
    np.testing.assert_allclose(outb, _eq1_batch(models, tb), atol=5e-6)
    np.testing.assert_allclose(outb[-1], F.synthesize(jax.tree.map(lambda x: x[-1], models), tb[-1]),
                               atol=5e-6)


def test_synthesize_batch_float64_and_gradients_match_finite_differences(x64):
    rng = np.random.default_rng(11)
    models = _batch(rng, 3, 5, 3, np.float64)
    t = np.linspace(-0.5, 2.0, 40)
    np.testing.assert_allclose(F.synthesize_batch(models, t), _eq1_batch(models, t), atol=1e-12)
    target = rng.normal(size=(3, 40, 5))
    weights = rng.normal(size=(3, 40, 5))

    def loss(m, t):
        return jnp.sum(weights * (F.synthesize_batch(m, t) - target) ** 2)

    g, gt = jax.jit(jax.grad(loss, argnums=(0, 1)))(models, jnp.asarray(t))
    ref = jax.grad(lambda m: jnp.sum(
        weights * (jax.vmap(F.synthesize, in_axes=(0, None))(m, t) - target) ** 2))(models)
    eps = 1e-6
    for field in ("offset", "amplitude", "phase", "omega"):
        val = np.asarray(getattr(models, field))
        grad = np.asarray(getattr(g, field))
        assert np.all(np.isfinite(grad))
        np.testing.assert_allclose(grad, getattr(ref, field), rtol=1e-10, atol=1e-10)
        for idx in [tuple(rng.integers(0, s) for s in val.shape) for _ in range(3)]:
            def at(d, idx=idx, field=field, val=val):
                v = val.copy()
                v[idx] += d
                return float(loss(eqx_replace(models, field, jnp.asarray(v)), t))

            fd = (at(eps) - at(-eps)) / (2 * eps)
            np.testing.assert_allclose(grad[idx], fd, rtol=1e-6, atol=1e-6)
    i = 7
    fd_t = (float(loss(models, t + eps * (np.arange(40) == i))) -
            float(loss(models, t - eps * (np.arange(40) == i)))) / (2 * eps)
    np.testing.assert_allclose(float(gt[i]), fd_t, rtol=1e-6, atol=1e-6)


def test_one_character_runs_inline_on_cpu_with_finite_gradients():
    """One character on CPU is synthesized in loops that XLA counts under its 1000-flop inline
    budget (no hand-off to a worker thread); its values and gradients are the vmap's."""
    from fourierjax._fourier import _synthesis as S

    models = _batch(np.random.default_rng(14), 1, 57, 3)
    t = jnp.arange(240, dtype=jnp.float32) / 120.0
    if jax.default_backend() == "cpu":
        for c, n in ((57, 3), (10, 5), (1, 1), (10, 4)):
            m = _batch(np.random.default_rng(c), 1, c, n)
            cost = S._synthesize_batch_jit.lower(m.offset, m.amplitude, m.phase, m.omega, t).compile().cost_analysis()
            cost = cost[0] if isinstance(cost, list) else cost
            assert S._inline_flops(c, n) < S._INLINE_FLOPS
            assert cost["flops"] <= S._inline_flops(c, n), (c, n, cost["flops"])
    np.testing.assert_allclose(F.synthesize_batch(models, t), _eq1_batch(models, t), atol=2e-6)
    w = jnp.asarray(np.random.default_rng(15).normal(size=(1, 240, 57)), jnp.float32)
    g, gt = jax.grad(lambda m, t: jnp.sum(w * F.synthesize_batch(m, t)), argnums=(0, 1))(models, t)
    ref = jax.grad(lambda m: jnp.sum(w * jax.vmap(F.synthesize, in_axes=(0, None))(m, t)))(models)
    for field in ("offset", "amplitude", "phase", "omega"):
        got = np.asarray(getattr(g, field))
        assert np.all(np.isfinite(got))
        np.testing.assert_allclose(got, getattr(ref, field), rtol=2e-4, atol=2e-3)
    assert np.all(np.isfinite(np.asarray(gt)))


def test_synthesize_batch_bad_shapes_name_the_argument():
    rng = np.random.default_rng(12)
    models = _batch(rng, 4, 3, 2)
    one = jax.tree.map(lambda x: x[0], models)
    with pytest.raises(ValueError, match="`models`.*offset shape \\(3,\\)"):
        F.synthesize_batch(one, jnp.zeros(5))
    with pytest.raises(ValueError, match="`models` must be a FourierModel"):
        F.synthesize_batch(np.zeros((4, 3)), jnp.zeros(5))
    for bad in (jnp.zeros(()), jnp.zeros((3, 5)), jnp.zeros((4, 5, 1)), "0.5", [None]):
        with pytest.raises(ValueError, match="`t_s`"):
            F.synthesize_batch(models, bad)
    # A non-finite time spoils only its own frame (the runtime 1 inside stays 1).
    t = jnp.asarray([np.nan, 0.1, 0.2], jnp.float32)
    out = np.asarray(F.synthesize_batch(models, t))
    assert np.all(np.isnan(out[:, 0])) and np.all(np.isfinite(out[:, 1:]))
    # Finite gradients at zero amplitude and omega; empty batches and frame counts keep shapes.
    z = F.FourierModel(jnp.zeros((2, 3)), jnp.zeros((2, 3, 2)), jnp.zeros((2, 3, 2)), jnp.zeros(2))
    g = jax.grad(lambda m: jnp.sum(F.synthesize_batch(m, t[1:]) ** 2))(z)
    assert all(np.all(np.isfinite(np.asarray(leaf))) for leaf in jax.tree.leaves(g))
    assert F.synthesize_batch(z, jnp.zeros(0)).shape == (2, 0, 3)
    assert F.synthesize_batch(jax.tree.map(lambda x: x[:0], z), t).shape == (0, 3, 3)


@pytest.mark.skipif(jax.default_backend() != "cpu", reason="a property of XLA:CPU's fusion (XLA:GPU "
                    "recomputes the basis inside the output loop, measured on an H100)")
def test_synthesize_batch_keeps_trig_out_of_the_output_loop():
    """The basis is computed per (character, frame) and stored: no sin/cos in the [B, T, C] loop."""
    models = _batch(np.random.default_rng(13), 4, 9, 3)
    t = jnp.arange(10, dtype=jnp.float32)
    hlo = jax.jit(F.synthesize_batch).lower(models, t).compile().as_text()
    blocks = [b for b in hlo.split("\n\n") if "ROOT" in b]
    big = [b for b in blocks if "f32[4,10,9]" in b.split("ROOT")[1].split("\n")[0]]
    assert big, hlo
    # sin/cos of the phases (coefficients) and the basis's range reduction (round, floor).
    trig_ops = (" sine(", " cosine(", " round-nearest-even(", " floor(")
    trig = [b for b in blocks if any(op in b for op in trig_ops)]
    assert trig and not any(b in trig for b in big), hlo
