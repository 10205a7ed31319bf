"""Tests of the style algebra: interpolation, transitions, characteristics, noise, style space."""

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest
from jax.flatten_util import ravel_pytree

from fourierjax import style
from fourierjax._style import _common, characteristics, interpolation, transitions
from fourierjax.errors import UserError
from fourierjax.fourier import FourierModel, synthesize_phase


def _names(c):
    return tuple(f"j{i}.Xrotation" for i in range(c))


def random_model(seed, c=4, n=3, omega=None, representation="euler", names=None):
    rng = np.random.default_rng(seed)
    return FourierModel(
        jnp.asarray(rng.normal(size=c)),
        jnp.asarray(rng.uniform(0.05, 1.0, size=(c, n))),
        jnp.asarray(rng.uniform(-np.pi, np.pi, size=(c, n))),
        jnp.asarray(rng.uniform(4.0, 10.0) if omega is None else omega),
        representation,
        _names(c) if names is None else names,
    )


def numpy_eval(offset, amplitude, phase, theta):
    """Independent reference for Unuma eq. 1 at phases theta [T] -> [T, C]."""
    n = np.arange(1, np.shape(amplitude)[1] + 1)
    arg = n[None, None, :] * np.asarray(theta)[:, None, None] + np.asarray(phase)[None]
    return np.asarray(offset)[None] + np.sum(np.asarray(amplitude)[None] * np.sin(arg), axis=-1)


def assert_models_close(m1, m2, atol=1e-10, branch=False):
    """Same signal and same ω (phase compared on the circle; zero amplitudes ignore phase).

    With `branch`, the offsets of Euler channels are compared modulo 2π (the same rotations,
    on another branch: the result of combining models on one branch); root channels exactly.
    """
    if branch:
        angle = np.asarray([not n.startswith("root.") for n in m1.channel_names])
        d = np.asarray(m1.offset) - np.asarray(m2.offset)
        np.testing.assert_allclose(np.where(angle, np.asarray(style.wrap_angle(d)), d), 0.0, atol=atol)
    else:
        np.testing.assert_allclose(m1.offset, m2.offset, atol=atol)
    np.testing.assert_allclose(m1.amplitude, m2.amplitude, atol=atol)
    dphi = np.asarray(style.wrap_angle(m1.phase - m2.phase))
    np.testing.assert_allclose(np.where(np.asarray(m1.amplitude) > atol, dphi, 0.0), 0.0, atol=atol)
    np.testing.assert_allclose(m1.omega, m2.omega, rtol=1e-12)


THETA = np.linspace(0.0, 2 * np.pi, 97)


# ------------------------------------------------------------------------------ helpers


def test_wrap_angle_range_and_gradient(x64):
    x = jnp.linspace(-20.0, 20.0, 4001)
    y = style.wrap_angle(x)
    assert float(y.min()) > -np.pi and float(y.max()) <= np.pi
    np.testing.assert_allclose(np.sin(y), np.sin(x), atol=1e-12)
    np.testing.assert_allclose(np.cos(y), np.cos(x), atol=1e-12)
    assert float(style.wrap_angle(jnp.pi)) == pytest.approx(np.pi)
    assert float(style.wrap_angle(-jnp.pi)) == pytest.approx(np.pi)
    g = jax.vmap(jax.grad(style.wrap_angle))(x)
    np.testing.assert_array_equal(g, 1.0)


def test_polar_from_phasor_is_nan_free_at_zero(x64):
    amp, ph = _common.polar_from_phasor(jnp.zeros((2,)))
    assert float(amp) == 0.0 and float(ph) == 0.0
    g = jax.grad(lambda c: _common.polar_from_phasor(c)[0] + _common.polar_from_phasor(c)[1])(jnp.zeros((2,)))
    assert np.all(np.isfinite(g))


# ---------------------------------------------------------------------- interpolation


@pytest.mark.parametrize("method", ["polar", "phasor"])
def test_interpolation_endpoints_reproduce_models(x64, method):
    a, b = random_model(0), random_model(1)
    assert_models_close(style.interpolate(a, b, 0.0, method=method), a)
    assert_models_close(style.interpolate(a, b, 1.0, method=method), b)


def test_phase_interpolation_takes_the_shorter_arc(x64):
    a = FourierModel(jnp.zeros(1), jnp.ones((1, 1)), jnp.full((1, 1), 3.0), jnp.asarray(6.0), "euler", ("x",))
    b = eqx.tree_at(lambda m: m.phase, a, jnp.full((1, 1), -3.0))
    # The arc from 3.0 to -3.0 through pi is 2pi - 6 = 0.283 rad long; the long way is 6 rad.
    for s in np.linspace(0.0, 1.0, 11):
        ph = float(style.interpolate(a, b, s).phase[0, 0])
        expected = 3.0 + s * (2 * np.pi - 6.0)
        assert abs(float(style.wrap_angle(ph - expected))) < 1e-12, (s, ph)
        assert abs(ph) > 2.9  # never passes through 0
    mid = float(style.interpolate(a, b, 0.5).phase[0, 0])
    assert mid == pytest.approx(np.pi)
    # and the other direction
    back = float(style.interpolate(b, a, 0.25).phase[0, 0])
    assert float(style.wrap_angle(back - (-3.0 - 0.25 * (2 * np.pi - 6.0)))) == pytest.approx(0)


def test_polar_interpolation_is_unuma_eq3(x64):
    # Against eq. 3 written out in numpy (phases pre-unwrapped so the plain formula is the
    # shorter arc), inside and outside [0, 1].
    a, b = random_model(2), random_model(3)
    pa, pb = np.asarray(a.phase), np.asarray(b.phase)
    pb_near = pa + np.angle(np.exp(1j * (pb - pa)))
    for s in (-0.7, 0.3, 1.0, 1.8):
        m = style.interpolate(a, b, s)
        ref = numpy_eval(
            (1 - s) * np.asarray(a.offset) + s * np.asarray(b.offset),
            (1 - s) * np.asarray(a.amplitude) + s * np.asarray(b.amplitude),
            (1 - s) * pa + s * pb_near,
            THETA,
        )
        np.testing.assert_allclose(synthesize_phase(m, THETA), ref, atol=1e-10)
        assert np.all(np.asarray(m.amplitude) >= 0)
        phase = np.asarray(m.phase)
        assert np.all((phase > -np.pi) & (phase <= np.pi))
        expected_omega = float(a.omega) ** (1 - s) * float(b.omega) ** s
        assert float(m.omega) == pytest.approx(expected_omega, rel=1e-12)


def test_extrapolation_canonicalises_negative_amplitudes(x64):
    a = FourierModel(jnp.zeros(1), jnp.asarray([[1.0]]), jnp.asarray([[0.5]]), jnp.asarray(6.0), "euler", ("x",))
    b = eqx.tree_at(lambda m: m.amplitude, a, jnp.asarray([[0.2]]))
    m = style.interpolate(a, b, 2.0)  # amplitude 1 + 2 (0.2 - 1) = -0.6
    assert float(m.amplitude[0, 0]) == pytest.approx(0.6)
    assert float(m.phase[0, 0]) == pytest.approx(0.5 - np.pi)
    np.testing.assert_allclose(synthesize_phase(m, THETA)[:, 0], -0.6 * np.sin(THETA + 0.5), atol=1e-12)


def test_linear_omega_option(x64):
    a, b = random_model(4, omega=5.0), random_model(5, omega=9.0)
    assert float(style.interpolate(a, b, 0.25, omega_mode="linear").omega) == pytest.approx(6.0)
    assert float(style.interpolate(a, b, 0.5).omega) == pytest.approx(np.sqrt(45.0))
    # geometric stays positive where linear would not
    assert float(style.interpolate(a, b, -2.0).omega) > 0
    # linear extrapolated through zero (5 - 3 (9 - 5) = -7 rad/s) is refused, not returned
    with pytest.raises(UserError, match=r"^interpolate: linear ω interpolation gives -7\.0 rad/s"):
        style.interpolate(a, b, -3.0, omega_mode="linear")
    with pytest.raises(UserError, match=r"^interpolate_omega: linear ω"):
        style.interpolate_omega(5.0, 9.0, jnp.asarray([0.0, -3.0]), omega_mode="linear")


def test_phasor_interpolation_is_the_time_domain_blend(x64):
    a, b = random_model(6), random_model(7, n=2)  # different harmonic counts are padded
    for s in (-0.5, 0.3, 1.4):
        m = style.interpolate(a, b, s, method="phasor")
        blend = jax.vmap(lambda th: style.blend_time_domain(a, b, s, th))(jnp.asarray(THETA))
        ref = (1 - s) * synthesize_phase(a, THETA) + s * synthesize_phase(b, THETA)
        np.testing.assert_allclose(blend, ref, atol=1e-12)
        np.testing.assert_allclose(synthesize_phase(m, THETA), ref, atol=1e-10)


def test_interpolation_vmaps_over_s_and_does_not_retrace(x64):
    a, b = random_model(8), random_model(9)
    ss = jnp.linspace(-1.0, 2.0, 7)
    batched = jax.vmap(lambda s: style.interpolate(a, b, s))(ss)
    for i, s in enumerate(ss):
        one = style.interpolate(a, b, float(s))
        np.testing.assert_allclose(batched.amplitude[i], one.amplitude, atol=1e-12)
        np.testing.assert_allclose(batched.phase[i], one.phase, atol=1e-12)
    jitted = jax.jit(lambda s: style.interpolate(a, b, s).offset)
    np.testing.assert_allclose(jitted(0.4), style.interpolate(a, b, 0.4).offset, atol=1e-12)


def test_public_entry_points_do_not_retrace_for_new_numbers(monkeypatch):
    # Python numbers become arrays before the jitted core: new s, weights or windows reuse
    # the compiled function. A trace runs the Python body, which calls these helpers; a cached
    # call does not. (Shapes used by no other test, so the first call traces.)
    a, b = random_model(8, c=7, n=5), random_model(9, c=7, n=5)
    char = style.characteristic(a, b)
    t = jnp.linspace(0.0, 1.0, 13)
    traces = []

    def spy(module, name):
        real = getattr(module, name)
        monkeypatch.setattr(module, name, lambda *args: traces.append(name) or real(*args))
        return name

    calls = [
        (spy(interpolation, "interpolate_core"), lambda v: style.interpolate(a, b, v)),
        (spy(characteristics, "canonical"), lambda v: style.superpose(a, char, v)),
        (spy(transitions, "_schedule_one"), lambda v: style.transition(a, b, t, v, 0.5)),
    ]
    for name, call in calls:
        call(0.1)
        before = traces.count(name)
        assert before >= 1  # the spy sees traces
        for v in (0.2, 0.7, 3):
            call(v)
        assert traces.count(name) == before


# ------------------------------------------------------------------------- incompatibility


def test_incompatible_models_name_the_argument():
    a = random_model(0, c=4)
    with pytest.raises(ValueError, match="^b: channels"):
        style.interpolate(a, random_model(1, c=5), 0.5)
    with pytest.raises(ValueError, match="^b: channels .*channel 2"):
        names = ("j0.Xrotation", "j1.Xrotation", "zz", "j3.Xrotation")
        style.characteristic(a, random_model(1, c=4, names=names))
    with pytest.raises(ValueError, match="^b: representation 'expmap'"):
        style.transition(a, random_model(1, representation="expmap"), jnp.zeros(3), 0.0, 1.0)
    char = style.characteristic(random_model(2, c=5), random_model(3, c=5))
    with pytest.raises(ValueError, match="^characteristics: channels"):
        style.superpose(a, char, 1.0)
    with pytest.raises(ValueError, match="^target: channels"):
        style.fit_style_weights(random_model(2, c=5), char, a)
    with pytest.raises(ValueError, match="weights"):
        style.superpose(a, [style.characteristic(a, random_model(1))] * 2, [1.0])
    with pytest.raises(ValueError, match="method"):
        style.interpolate(a, a, 0.5, method="cubic")
    with pytest.raises(ValueError, match="duration_s"):
        style.transition(a, a, jnp.zeros(3), 0.0, 0.0)


# ------------------------------------------------------------------------------ transitions


def _reference_phase(t, wa, wb, start, dur):
    """Independent reference: cumulative trapezoid of ω(s(τ)) on a very fine grid."""
    grid = np.linspace(0.0, t, 200001)
    u = np.clip((grid - start) / dur, 0, 1)
    s = u * u * (3 - 2 * u)
    w = wa ** (1 - s) * wb**s
    return float(np.sum((w[1:] + w[:-1]) * np.diff(grid)) / 2)


def test_transition_phase_is_the_integral_of_omega(x64):
    wa, wb, start, dur = 5.0, 9.0, 1.0, 1.5
    t = jnp.asarray([0.0, 0.5, 1.0, 1.3, 1.75, 2.2, 2.5, 4.0])
    s, theta = style.transition_schedule(wa, wb, t, start, dur)
    for ti, th in zip(np.asarray(t), np.asarray(theta)):
        assert th == pytest.approx(_reference_phase(ti, wa, wb, start, dur), abs=1e-8)
    np.testing.assert_allclose(s, [0, 0, 0, 0.104, 0.5, 0.896, 1, 1], atol=1e-12)
    # dθ/dt = ω(s(t)) everywhere, including across the window edges
    tt = jnp.linspace(0.0, 4.0, 2001)
    dtheta = jax.vmap(jax.grad(lambda x: style.transition_schedule(wa, wb, x[None], start, dur)[1][0]))(tt)
    s_tt, _ = style.transition_schedule(wa, wb, tt, start, dur)
    np.testing.assert_allclose(dtheta, wa ** (1 - s_tt) * wb**s_tt, rtol=1e-10)


def test_transition_window_starting_before_zero_keeps_theta_0_at_zero(x64):
    # The phase integrates from t = 0 whatever the window: a window from -0.5 s gave
    # theta(0) = 0.30 rad (the integral over [-0.5, 0] added in).
    wa, wb, start, dur = 5.0, 9.0, -0.5, 1.0
    t = jnp.asarray([0.0, 0.25, 0.5, 1.0])
    _, theta = style.transition_schedule(wa, wb, t, start, dur)
    assert float(theta[0]) == 0.0
    for ti, th in zip(np.asarray(t), np.asarray(theta)):
        assert th == pytest.approx(_reference_phase(ti, wa, wb, start, dur), abs=1e-8)


def test_transition_plays_a_then_b(x64):
    a, b = random_model(10, omega=5.0), random_model(11, omega=8.0)
    t = jnp.linspace(0.0, 5.0, 501)
    values, s, theta = style.transition(a, b, t, 1.0, 2.0, return_schedule=True)
    before = np.asarray(t) < 1.0
    after = np.asarray(t) > 3.0
    np.testing.assert_allclose(values[before], synthesize_phase(a, 5.0 * t[before]), atol=1e-10)
    np.testing.assert_allclose(values[after], synthesize_phase(b, theta[after]), atol=1e-10)
    np.testing.assert_allclose(np.diff(theta[after]), 8.0 * 0.01, rtol=1e-10)
    # every frame is Ξ(s, θ) of eq. 3
    i = 250
    m = style.interpolate(a, b, float(s[i]))
    np.testing.assert_allclose(values[i], synthesize_phase(m, theta[i : i + 1])[0], atol=1e-10)


# ------------------------------------------------------------- characteristics, superposition


def test_characteristic_is_unuma_eq7_and_psi_is_eq8(x64):
    a, b = random_model(12), random_model(13)
    char = style.characteristic(a, b)
    np.testing.assert_allclose(char.amplitude, a.amplitude - b.amplitude, atol=1e-14)
    np.testing.assert_allclose(np.exp(1j * char.phase), np.exp(1j * (a.phase - b.phase)), atol=1e-12)
    assert np.all(np.abs(np.asarray(char.phase)) <= np.pi)
    assert float(char.log_omega) == pytest.approx(np.log(float(a.omega) / float(b.omega)))
    psi = jax.vmap(lambda th: style.characteristic_function(char, th))(jnp.asarray(THETA))
    ref = numpy_eval(char.offset, a.amplitude - b.amplitude, a.phase - b.phase, THETA)
    np.testing.assert_allclose(psi, ref, atol=1e-12)


@pytest.mark.parametrize("method", ["polar", "phasor"])
def test_superposition_identities(x64, method):
    a, b, base = random_model(14), random_model(15), random_model(16)
    char = style.characteristic(a, b)
    # a, on b's branch: these random offsets differ by more than π on some channels
    assert_models_close(style.superpose(b, char, 1.0, method=method), a, branch=True)
    assert_models_close(style.superpose(base, [char], [0.0], method=method), base)
    # base + 1 (A - base) == A
    assert_models_close(style.superpose(base, style.characteristic(a, base), 1.0, method=method), a, branch=True)


def test_polar_superposition_equals_interpolation(x64):
    a, b = random_model(17), random_model(18)
    for s in (-0.4, 0.35, 1.6):
        assert_models_close(style.superpose(a, style.characteristic(b, a), s), style.interpolate(a, b, s))


def test_phasor_superposition_adds_signals(x64):
    # The documented identity: Θ_base + Σ w_k (Θ_A,k − Θ_B,k) at a common phase.
    base = random_model(19)
    pairs = [(random_model(20 + i), random_model(30 + i, n=2)) for i in range(3)]
    chars = [style.characteristic(x, y) for x, y in pairs]
    w = np.array([1.37, -0.5, 0.25])
    m = style.superpose(base, chars, w, method="phasor")
    ref = synthesize_phase(base, THETA) + sum(
        wk * (synthesize_phase(x, THETA) - synthesize_phase(y, THETA)) for wk, (x, y) in zip(w, pairs)
    )
    np.testing.assert_allclose(synthesize_phase(m, THETA), ref, atol=1e-10)
    omega = float(base.omega) * np.prod([(float(x.omega) / float(y.omega)) ** wk for wk, (x, y) in zip(w, pairs)])
    assert float(m.omega) == pytest.approx(omega, rel=1e-12)
    # stacked batch == sequence
    m2 = style.superpose(base, style.stack(chars), jnp.asarray(w), method="phasor")
    assert_models_close(m, m2)
    # include_omega=False keeps the base's ω
    assert float(style.superpose(base, chars, w, include_omega=False).omega) == float(base.omega)


@pytest.mark.parametrize("method", ["polar", "phasor"])
def test_saturation_extrapolates_the_posture_not_the_swings(x64, method):
    """`superpose(saturation=s)` (issue #22, limb flips): weights in [0, 1] as without it; outside,
    the offsets follow the weight and the harmonics and ω saturate at `1 + s` (above) and `−s`
    (below), smoothly (the weight's derivative is 1 at the knee, 0 far beyond it)."""
    a, base = random_model(41), random_model(42)
    char = style.characteristic(a, base)
    s = 0.05
    for w in (0.0, 0.3, 1.0):
        assert_models_close(style.superpose(base, char, w, method=method, saturation=s),
                            style.superpose(base, char, w, method=method))
    for w, w_h in ((1.5, 1 + s * np.tanh(0.5 / s)), (3.0, 1 + s), (-2.0, -s)):
        got = style.superpose(base, char, w, method=method, saturation=s)
        plain = style.superpose(base, char, w, method=method)
        np.testing.assert_allclose(got.offset, plain.offset, atol=1e-12)  # the posture follows w
        swings = style.superpose(base, char, w_h, method=method)
        np.testing.assert_allclose(style.phasor(got), style.phasor(swings), atol=1e-9)
        assert float(got.omega) == pytest.approx(float(swings.omega), rel=1e-12)
    # the amplitudes of an extrapolation never exceed those at 1 + s (phasor: exactly a chord point)
    far = style.superpose(base, char, 50.0, method=method, saturation=s)
    assert np.all(np.asarray(far.amplitude) <= np.asarray(style.superpose(base, char, 1 + s,
                                                                             method=method).amplitude) + 1e-9)

    def amp(w):
        return jnp.sum(style.superpose(base, char, w, method="phasor", saturation=s).amplitude)

    g = [float(jax.grad(amp)(jnp.asarray(w))) for w in (1.0 - 1e-6, 1.0 + 1e-6, 1.5)]
    assert g[0] == pytest.approx(g[1], rel=1e-4) and abs(g[2]) < 1e-6 * abs(g[0])
    for bad in (0.0, -0.1, float("nan"), np.ones(2)):
        with pytest.raises(UserError, match="saturation"):
            style.superpose(base, char, 1.5, saturation=bad)
    traced = jax.jit(lambda x: style.superpose(base, char, 1.5, saturation=x).offset)
    with pytest.raises(Exception, match="saturation"):
        traced(jnp.asarray(-1.0)).block_until_ready()


# --------------------------------------------------------------------------------------- noise


def test_add_noise_adds_random_higher_harmonics(x64):
    m = random_model(40, c=3, n=3)
    key = jax.random.key(0)
    noisy = style.add_noise(m, key, 0.02, harmonics=4)
    assert noisy.amplitude.shape == (3, 7)
    np.testing.assert_allclose(noisy.amplitude[:, :3], m.amplitude)
    np.testing.assert_allclose(noisy.phase[:, :3], m.phase)
    np.testing.assert_allclose(noisy.amplitude[:, 3:], 0.02)
    again = style.add_noise(m, key, 0.02, harmonics=4)
    np.testing.assert_array_equal(noisy.phase, again.phase)
    other = style.add_noise(m, jax.random.key(1), 0.02, harmonics=4)
    assert not np.allclose(other.phase[:, 3:], noisy.phase[:, 3:])
    # explicit harmonics, per-channel amplitude (channel 0 kept still)
    sparse = style.add_noise(m, key, jnp.asarray([0.0, 0.1, 0.2]), harmonics=(9, 11))
    assert sparse.amplitude.shape == (3, 11)
    np.testing.assert_allclose(sparse.amplitude[:, 8], [0.0, 0.1, 0.2])
    np.testing.assert_allclose(sparse.amplitude[:, 3:8], 0.0)
    # the noise is band-limited to the requested harmonics
    diff = synthesize_phase(sparse, THETA) - synthesize_phase(m, THETA)
    spectrum = np.abs(np.fft.rfft(diff[:-1], axis=0))
    assert np.all(spectrum[:9] < 1e-10) and spectrum[9, 2] > 1.0
    with pytest.raises(ValueError, match="above the model's N=3"):
        style.add_noise(m, key, 0.1, harmonics=(2, 5))


# ----------------------------------------------------------------------------- style space


def test_style_vector_layout_roundtrip_and_parseval(x64):
    a = random_model(50, c=54, n=2, omega=6.0)
    b = random_model(51, c=54, n=2, omega=6.0)
    va, vb = style.style_vector(a), style.style_vector(b)
    assert va.shape == (271,)  # Tilmanne: 54 channels x 5 + omega
    assert_models_close(style.model_from_style_vector(va, like=a), a)
    # Parseval: the Euclidean distance is the RMS signal difference over a cycle
    theta = np.linspace(0, 2 * np.pi, 64, endpoint=False)
    diff = np.asarray(synthesize_phase(a, theta) - synthesize_phase(b, theta))
    msd = np.mean(np.sum(diff**2, axis=1))
    assert float(jnp.sum((va - vb)[:-1] ** 2)) == pytest.approx(msd, rel=1e-10)
    # linear combinations in style space are linear combinations of signals
    mix = style.model_from_style_vector(0.3 * va + 0.7 * vb, like=a)
    np.testing.assert_allclose(
        synthesize_phase(mix, theta),
        0.3 * synthesize_phase(a, theta) + 0.7 * synthesize_phase(b, theta),
        atol=1e-10,
    )


def test_style_pca_against_numpy(x64):
    models = [random_model(60 + i, c=6, n=2) for i in range(7)]
    mat = style.style_matrix(models)
    assert mat.shape == (7, 6 * 5 + 1)
    np.testing.assert_allclose(mat[3], style.style_vector(models[3]), atol=1e-14)
    pca = style.style_pca(mat)
    x = np.asarray(mat) - np.asarray(mat).mean(0)
    evals, evecs = np.linalg.eigh(x.T @ x / 6)
    evals, evecs = evals[::-1][:6], evecs[:, ::-1][:, :6]
    np.testing.assert_allclose(pca.explained_variance, evals, rtol=1e-9)
    np.testing.assert_allclose(np.abs(np.sum(np.asarray(pca.components) * evecs.T, 1)), 1, atol=1e-9)
    assert float(jnp.sum(pca.explained_variance_ratio)) == pytest.approx(1.0)
    coords = style.pca_project(pca, mat)
    np.testing.assert_allclose(style.pca_reconstruct(pca, coords), mat, atol=1e-10)
    two = style.style_pca(mat, num_components=2)
    assert two.components.shape == (2, 31)


def test_fit_style_weights_recovers_known_weights(x64):
    base = random_model(70, c=8)
    chars = [style.characteristic(random_model(71 + i, c=8), random_model(81 + i, c=8)) for i in range(3)]
    w_true = jnp.asarray([0.7, -1.2, 1.37])
    target = style.superpose(base, chars, w_true, method="phasor")
    np.testing.assert_allclose(style.fit_style_weights(base, chars, target), w_true, atol=1e-9)
    batched = jax.vmap(
        lambda w: style.fit_style_weights(base, chars, style.superpose(base, chars, w, method="phasor"))
    )(jnp.stack([w_true, -w_true]))
    np.testing.assert_allclose(batched, jnp.stack([w_true, -w_true]), atol=1e-9)
    # least squares: the residual is orthogonal to every characteristic direction
    target2 = random_model(90, c=8)
    w = style.fit_style_weights(base, chars, target2)
    fit = style.superpose(base, chars, w, method="phasor")
    r = style.style_vector(target2) - style.style_vector(fit)
    for ch in chars:
        d = style.style_vector(style.superpose(base, ch, 1.0, method="phasor")) - style.style_vector(base)
        assert abs(float(jnp.dot(r, d))) < 1e-9


# ---------------------------------------------------------------------------- gradients


def _fd_check(f, x, eps=1e-6, rtol=1e-6, atol=1e-8):
    """Reverse-mode Jacobian of f (scalar or vector valued) against central differences."""
    x = np.asarray(x, dtype=np.float64)
    f = jax.jit(f)
    jac = np.asarray(jax.jit(jax.jacrev(f))(jnp.asarray(x)))
    assert np.all(np.isfinite(jac))
    fd = np.zeros_like(jac)
    for i in range(x.size):
        e = np.zeros_like(x)
        e.flat[i] = eps
        fd[..., i] = (np.asarray(f(jnp.asarray(x + e))) - np.asarray(f(jnp.asarray(x - e)))) / (2 * eps)
    np.testing.assert_allclose(jac, fd, rtol=rtol, atol=atol)


def test_gradients_wrt_style_weights_match_finite_differences(x64):
    base = random_model(100, c=5)
    chars = [style.characteristic(random_model(101 + i, c=5), random_model(111 + i, c=5)) for i in range(3)]
    t = jnp.linspace(0.0, 2.0, 50)
    target = jnp.asarray(np.random.default_rng(0).normal(size=(50, 5)))

    def losses(w):  # polar and phasor superposition, and through fit_style_weights itself
        out = []
        for method in ("polar", "phasor"):
            m = style.superpose(base, chars, w, method=method)
            out.append(jnp.mean((synthesize_phase(m, m.omega * t) - target) ** 2))
        tgt = style.superpose(base, chars, w, method="phasor")
        out.append(jnp.sum(style.fit_style_weights(base, chars, tgt, ridge=0.1) ** 2))
        return jnp.stack(out)

    _fd_check(losses, [0.3, -0.8, 1.37])


def test_gradients_wrt_model_parameters_match_finite_differences(x64):
    a, b = random_model(120, c=3, n=2), random_model(121, c=3, n=2)
    flat_a, unravel = ravel_pytree(a)
    t = jnp.linspace(0.0, 3.0, 40)

    def loss(p):
        m = unravel(p)
        x = style.transition(m, b, t, 0.8, 1.2)
        y = synthesize_phase(style.interpolate(m, b, -0.3), t * 6.0)
        char = style.characteristic(m, b)
        z = synthesize_phase(style.superpose(b, char, 0.6), t * 6.0)
        noisy = style.add_noise(m, jax.random.key(3), 0.05, harmonics=2)
        return jnp.sum(jnp.sin(x)) + jnp.sum(y**2) + jnp.sum(jnp.cos(z)) + jnp.sum(style.style_vector(noisy) ** 2)

    _fd_check(loss, flat_a, rtol=1e-5, atol=1e-7)
    # transition timing parameters too
    _fd_check(lambda p: jnp.sum(jnp.sin(style.transition(a, b, t, p[0], p[1]))), [0.8, 1.2], rtol=1e-5, atol=1e-7)


# ------------------------------------------------------------------- real clips (CMU, 120 fps)

CLIPS = ("02_01", "02_03", "07_01", "07_12", "07_04")


@pytest.fixture(scope="module")
def cmu():
    """Fit the bundled walks and runs in ONE batched call (N = 5, Euler features), each model
    aligned so that θ = 0 is the peak of the left hip's flexion fundamental (the documented
    fallback gait event of `fourierjax.fourier.channel_event_phase`)."""
    from fourierjax import data, fourier
    from fourierjax import motion as fmotion

    motions = {n: data.load(n) for n in CLIPS}  # T-pose (and 07_12's zero frame) dropped
    feats = {}
    names = None
    for n, m in motions.items():
        feats[n], names = fmotion.features_from_motion(m, "euler")
    length = max(f.shape[0] for f in feats.values())
    x = np.zeros((len(CLIPS), length, len(names)))
    mask = np.zeros((len(CLIPS), length), bool)
    for i, n in enumerate(CLIPS):
        x[i, : len(feats[n])] = feats[n]
        mask[i, : len(feats[n])] = True
    dt = motions[CLIPS[0]].frame_time_s
    res = fourier.fit_batch(jnp.asarray(x), jnp.full((len(CLIPS),), dt), 5, mask=jnp.asarray(mask), channel_names=names)
    hip = names.index("LeftUpLeg.Xrotation")
    models = {}
    for i, n in enumerate(CLIPS):
        m = jax.tree.map(lambda leaf, i=i: leaf[i], res.model)
        # x'(θ) = x(θ + δ): φ_n += n δ (written out: fourier.shift_phase trips rank promotion).
        delta = fourier.channel_event_phase(m, hip)
        harmonics = jnp.arange(1, m.num_harmonics + 1, dtype=m.phase.dtype)
        models[n] = eqx.tree_at(lambda mm: mm.phase, m, style.wrap_angle(m.phase + harmonics[None, :] * delta))
    return dict(motions=motions, features=feats, names=names, models=models, frame_time_s=dt)


def _angle_jumps_deg(features, names):
    rot = np.array([not n.startswith("root.") for n in names])
    return np.degrees(np.abs(np.diff(np.asarray(features, np.float64)[:, rot], axis=0)))


@pytest.mark.parametrize("src,dst", [("02_01", "02_03"), ("02_03", "02_01")])
def test_transition_on_real_clips_has_no_jump_larger_than_the_sources(cmu, src, dst):
    names, dt = cmu["names"], cmu["frame_time_s"]
    a, b = cmu["models"][src], cmu["models"][dst]
    # Source jumps on the captured (continuous-Euler) angles, per channel and overall.
    j_src = np.maximum(
        _angle_jumps_deg(cmu["features"][src], names).max(0), _angle_jumps_deg(cmu["features"][dst], names).max(0)
    )
    t = jnp.arange(int(round(5.0 / dt))) * dt
    x, s, theta = style.transition(a, b, t, 1.7, 1.2, return_schedule=True)
    j = _angle_jumps_deg(x, names)
    assert j.max() <= j_src.max()  # the acceptance criterion
    assert np.all(j.max(0) <= j_src + 1e-6)  # stronger: channel by channel
    assert np.all(np.diff(np.asarray(theta)) > 0)  # the cycle never runs backwards or jumps
    # Root velocity (heading frame) changes no faster than in the captured clips.
    iv = [names.index("root.vx"), names.index("root.vz")]
    dv = np.abs(np.diff(np.asarray(x)[:, iv], axis=0)).max()
    dv_src = max(np.abs(np.diff(cmu["features"][k][:, iv], axis=0)).max() for k in (src, dst))
    assert dv <= dv_src
    # The test has teeth: a hard switch at mid-window breaks it, and so does the naive phase
    # ω(s(t))·t (its cycle speed jumps by t·dω/dt during the window).
    hard = np.where(
        (np.asarray(t) < 2.3)[:, None],
        np.asarray(synthesize_phase(a, a.omega * t)),
        np.asarray(synthesize_phase(b, theta)),
    )
    assert not np.all(_angle_jumps_deg(hard, names).max(0) <= j_src + 1e-6)
    # (walk -> run: its jumps exceed the sources; run -> walk: the cycle plays backwards for a
    # while, the unnatural run -> walk Unuma reports).
    naive_theta = style.interpolate_omega(a.omega, b.omega, s) * t
    naive = jax.vmap(lambda si, th: synthesize_phase(style.interpolate(a, b, si), th[None])[0])(s, naive_theta)
    naive_ok = np.all(_angle_jumps_deg(naive, names).max(0) <= j_src + 1e-6)
    assert not (naive_ok and np.all(np.diff(np.asarray(naive_theta)) > 0))


def test_briskness_on_real_clips(cmu):
    """Unuma §3.2 on CMU subject 07: briskness = brisk walk − walk; a brisk run; style weights."""
    m = cmu["models"]
    walk, brisk_walk, slow_walk, run = m["07_01"], m["07_12"], m["07_04"], m["02_03"]
    brisk = style.characteristic(brisk_walk, walk)
    names = cmu["names"]
    vz = names.index("root.vz")
    for method in ("polar", "phasor"):
        brisk_run = style.superpose(run, brisk, 1.37, method=method)
        assert np.all(np.isfinite(np.asarray(brisk_run.amplitude)))
        assert float(brisk_run.omega) == pytest.approx(
            float(run.omega) * (float(brisk_walk.omega) / float(walk.omega)) ** 1.37, rel=1e-5
        )
        # faster than the run by 1.37 x the walks' speed difference (root.vz is a channel)
        gain = float(brisk_run.offset[vz] - run.offset[vz])
        assert gain == pytest.approx(1.37 * float(brisk_walk.offset[vz] - walk.offset[vz]), rel=1e-5)
        assert gain > 0
    # Projection of real walks onto the briskness axis: the brisk walk itself is +1, the slow
    # walk is negative (less brisk than normal), and the fit explains part of it.
    w_brisk = style.fit_style_weights(walk, brisk, brisk_walk)
    w_slow = style.fit_style_weights(walk, [brisk], slow_walk)
    assert float(w_brisk[0]) == pytest.approx(1.0, abs=1e-4)
    assert float(w_slow[0]) < -0.2
    fit = style.superpose(walk, brisk, w_slow, method="phasor")
    d_fit = style.style_vector(slow_walk) - style.style_vector(fit)
    d_base = style.style_vector(slow_walk) - style.style_vector(walk)
    assert float(jnp.sum(d_fit**2)) < 0.9 * float(jnp.sum(d_base**2))


def test_float64_numpy_models_work_without_x64():
    # Model files hold float64 NumPy arrays; without x64 the style functions compute in float32
    # (pytest turns the "requested dtype float64 not available" warning into an error).
    rng = np.random.default_rng(5)
    a = FourierModel(
        rng.normal(size=2), rng.uniform(0, 1, (2, 2)), rng.uniform(-3, 3, (2, 2)), np.float64(6.0), "euler", ("p", "q")
    )
    b = FourierModel(
        rng.normal(size=2), rng.uniform(0, 1, (2, 2)), rng.uniform(-3, 3, (2, 2)), np.float64(7.0), "euler", ("p", "q")
    )
    char = style.characteristic(a, b)
    outputs = [
        style.interpolate(a, b, 0.5).amplitude,
        style.transition(a, b, np.linspace(0, 1, 5), 0.2, 0.5),
        style.superpose(a, char, 0.5).phase,
        style.fit_style_weights(a, char, b),
        style.add_noise(a, jax.random.key(0), 0.1).amplitude,
        style.model_from_style_vector(style.style_vector(a), like=a).offset,
        style.blend_time_domain(a, b, 0.3, 1.0),
        style.characteristic_function(char, 1.0),
    ]
    assert all(o.dtype == jnp.float32 and np.all(np.isfinite(o)) for o in outputs)


# ------------------------------------------------------------------------------ input checks


@pytest.mark.parametrize("bad", [0.0, -6.0, float("nan"), float("inf")])
def test_non_positive_or_non_finite_omega_is_rejected_naming_the_model(bad):
    # log ω is -inf at 0 and NaN below: NaN gradients in s, inf style vectors, inf characteristics.
    good, other = random_model(0, omega=6.0), random_model(1, omega=8.0)
    m0 = random_model(2, omega=bad)
    t = jnp.linspace(0.0, 2.0, 5)
    with pytest.raises(UserError, match=r"^interpolate_omega: `omega_a` must be finite and > 0"):
        style.interpolate_omega(bad, 6.0, 0.5)
    with pytest.raises(UserError, match=r"^interpolate_omega: `omega_b`"):
        style.interpolate_omega(6.0, jnp.asarray(bad), 0.5, omega_mode="linear")
    with pytest.raises(UserError, match=r"^interpolate: `a.omega`"):
        style.interpolate(m0, good, 0.5)
    with pytest.raises(UserError, match=r"^interpolate: `b.omega`"):
        jax.grad(lambda s: style.interpolate(good, m0, s).omega)(0.5)
    with pytest.raises(UserError, match=r"^style_vector: `model.omega`"):
        style.style_vector(m0)
    with pytest.raises(UserError, match=r"^style_matrix: `models.omega`.* at index \(1,\)"):
        style.style_matrix([good, m0])
    with pytest.raises(UserError, match=r"^characteristic: `b.omega`"):
        style.characteristic(good, m0)
    with pytest.raises(UserError, match=r"^transition: `a.omega`"):
        style.transition(m0, good, t, 1.0, 0.5)
    with pytest.raises(UserError, match=r"^transition_schedule: `omega_b`"):
        style.transition_schedule(6.0, bad, t, 1.0, 0.5)
    char = style.characteristic(good, other)
    with pytest.raises(UserError, match=r"^superpose: `base.omega`"):
        style.superpose(m0, char, 1.0)
    with pytest.raises(UserError, match=r"^fit_style_weights: `target.omega`"):
        style.fit_style_weights(good, char, m0)
    if not np.isfinite(bad):  # a characteristic file may hold log(ω_A/ω_B) = inf or NaN
        bad_char = eqx.tree_at(lambda c: c.log_omega, char, jnp.asarray(bad))
        with pytest.raises(UserError, match=r"^superpose: `characteristics` log_omega must be finite"):
            style.superpose(good, bad_char, 1.0)
        with pytest.raises(UserError, match=r"^fit_style_weights: `characteristics` log_omega"):
            style.fit_style_weights(good, bad_char, other)


def test_omega_checks_keep_jit_vmap_and_gradients_in_s_working(x64):
    a, b = random_model(3, omega=5.0), random_model(4, omega=9.0)
    ss = jnp.linspace(-0.5, 1.5, 5)
    models = jax.vmap(lambda s: style.interpolate(a, b, s))(ss)
    np.testing.assert_allclose(models.omega, 5.0 ** (1 - ss) * 9.0**ss, rtol=1e-12)
    g = jax.vmap(jax.grad(lambda s: style.interpolate(a, b, s).omega))(ss)
    np.testing.assert_allclose(g, np.log(9.0 / 5.0) * models.omega, rtol=1e-12)
    g = jax.grad(lambda s: style.interpolate_omega(5.0, 9.0, s))(0.0)
    assert float(g) == pytest.approx(5.0 * np.log(9.0 / 5.0))
    # Traced models pass their value checks (eqx.error_if inside the program; bad traced values
    # are refused in test_style_branches.py).
    stacked = style.stack([a, b])
    vecs = jax.vmap(style.style_vector)(stacked)
    np.testing.assert_allclose(vecs[1], style.style_vector(b), atol=1e-14)
    jitted = jax.jit(lambda m: style.characteristic(m, b).log_omega)(a)
    assert float(jitted) == pytest.approx(np.log(5.0 / 9.0))


@pytest.mark.parametrize(
    "duration", [np.float32(0.0), jnp.asarray(0.0), np.array(-1.0), np.float64(np.inf), jnp.asarray(jnp.nan)]
)
def test_transition_rejects_a_bad_duration_of_any_scalar_type(duration):
    # NumPy and JAX scalars used to skip the check and give NaN frames.
    a, b = random_model(5), random_model(6)
    t = jnp.linspace(0.0, 2.0, 5)
    with pytest.raises(UserError, match=r"^transition: `duration_s`=.*finite positive duration"):
        style.transition(a, b, t, 1.0, duration)
    with pytest.raises(UserError, match=r"^transition_schedule: `duration_s`"):
        style.transition_schedule(a.omega, b.omega, t, 1.0, duration)


def test_transition_shape_errors_are_clear():
    a, b = random_model(5), random_model(6)
    with pytest.raises(UserError, match=r"^transition: `t_s` must be \[T\] .* got shape \(2, 3\)"):
        style.transition(a, b, jnp.zeros((2, 3)), 1.0, 1.0)
    with pytest.raises(UserError, match=r"^transition_schedule: `t_s`"):
        style.transition_schedule(6.0, 7.0, 0.5, 1.0, 1.0)
    with pytest.raises(UserError, match=r"^transition: `duration_s` must be a scalar"):
        style.transition(a, b, jnp.zeros(3), 1.0, jnp.ones(2))
    with pytest.raises(UserError, match=r"^transition: `start_s` must be finite"):
        style.transition(a, b, jnp.zeros(3), float("nan"), 1.0)
    # A traced (positive) window is still accepted: jit over the duration.
    t = jnp.linspace(0.0, 2.0, 5)
    jitted = jax.jit(lambda d: style.transition(a, b, t, 0.5, d))(0.75)
    np.testing.assert_allclose(jitted, style.transition(a, b, t, 0.5, 0.75), rtol=1e-6)


def test_clear_errors_for_vector_s_float_harmonics_and_wrong_pca_dimension():
    a, b = random_model(7), random_model(8)
    with pytest.raises(UserError, match=r"^interpolate: `s` must be a scalar, got shape \(2,\).*jax\.vmap"):
        style.interpolate(a, b, jnp.asarray([0.0, 1.0]))
    with pytest.raises(UserError, match=r"^interpolate: `s` must be finite"):
        style.interpolate(a, b, float("nan"))
    with pytest.raises(UserError, match=r"^blend_time_domain: `phase` must be a scalar"):
        style.blend_time_domain(a, b, 0.5, jnp.zeros(3))
    with pytest.raises(UserError, match=r"^characteristic_function: `phase` must be a scalar"):
        style.characteristic_function(style.characteristic(a, b), jnp.zeros(3))
    key = jax.random.key(0)
    with pytest.raises(UserError, match=r"^add_noise: `harmonics`=2\.0; expected an int"):
        style.add_noise(a, key, 0.1, harmonics=2.0)
    with pytest.raises(UserError, match=r"^add_noise: `harmonics`"):
        style.add_noise(a, key, 0.1, harmonics=(5.0, 6.5))
    # Integer types other than int still work.
    assert style.add_noise(a, key, 0.1, harmonics=np.int64(2)).amplitude.shape == (4, 5)
    assert style.add_noise(a, key, 0.1, harmonics=np.array([5, 7])).amplitude.shape == (4, 7)
    pca = style.style_pca(style.style_matrix([random_model(10 + i) for i in range(4)]))
    d, k = pca.mean.shape[0], pca.components.shape[0]
    with pytest.raises(UserError, match=rf"^pca_project: `vectors` must be \[\.\.\., {d}\].*got shape \(5,\)"):
        style.pca_project(pca, jnp.zeros(5))
    with pytest.raises(UserError, match=rf"^pca_reconstruct: `coords` must be \[\.\.\., {k}\]"):
        style.pca_reconstruct(pca, jnp.zeros(k + 1))


def test_every_style_check_raises_user_error():
    # UserError is a ValueError, so `except ValueError` keeps working.
    a = random_model(0, c=4)
    char = style.characteristic(a, random_model(1))
    calls = [
        lambda: style.check_compatible(a, random_model(1, c=5)),
        lambda: style.check_compatible(a, random_model(1, representation="expmap")),
        lambda: style.interpolate(a, a, 0.5, method="cubic"),
        lambda: style.ease(0.5, "bouncy"),
        lambda: style.transition(a, a, jnp.zeros(3), 0.0, 0.0),
        lambda: style.pad_harmonics(a, 1),
        lambda: style.stack([]),
        lambda: style.superpose(a, [], 1.0),
        lambda: style.superpose(a, [char] * 2, [1.0]),
        lambda: style.characteristic_function(style.stack([char, char]), 0.0),
        lambda: style.add_noise(a, jax.random.key(0), jnp.zeros(3)),
        lambda: style.add_noise(a, jax.random.key(0), 0.1, harmonics=0),
        lambda: style.add_noise(a, jax.random.key(0), 0.1, harmonics=(5, 5)),
        lambda: style.model_from_style_vector(jnp.zeros(3), a),
        lambda: style.style_pca(jnp.zeros((1, 3))),
        lambda: style.style_pca(jnp.zeros((4, 3)), num_components=9),
    ]
    # Non-finite or out-of-range numbers that used to give NaN, inf or 1e38 results.
    calls += [
        lambda: style.superpose(a, [char], [float("nan")]),
        lambda: style.superpose(a, [char], [float("inf")]),
        lambda: style.fit_style_weights(a, [char], a, ridge=-1e3),
        lambda: style.fit_style_weights(a, [char], a, ridge=float("nan")),
        lambda: style.add_noise(a, jax.random.key(0), float("nan")),
        lambda: style.pad_harmonics(a, 4.5),
    ]
    for i, call in enumerate(calls):
        with pytest.raises(UserError):
            call()
