"""Input checks of fourierjax.fourier: degenerate or malformed input is a UserError naming the
argument (before any work), not a silent garbage result or a raw JAX error; traced inputs pass
the host checks and are checked at run time instead (tests/test_fit_status.py)."""

import re

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from jax import monitoring

from fourierjax import fourier as F
from fourierjax.errors import UserError

T, DT, N = 120, 1 / 60, 3


def _features(T=T, C=2):
    t = np.arange(T) * DT
    return np.stack([np.sin(2 * np.pi * t + k) + 0.3 * np.sin(4 * np.pi * t + 2 * k)
                     for k in range(C)], -1).astype(np.float32)


def _model(C=2, N=3, omega=2 * np.pi):
    rng = np.random.default_rng(0)
    return F.FourierModel(jnp.asarray(rng.normal(size=C)), jnp.asarray(rng.uniform(0.1, 1, (C, N))),
                          jnp.asarray(rng.uniform(-3, 3, (C, N))), jnp.asarray(omega))


class _Compiles:
    """Counts XLA compilations inside a with-block (a check must come before any work)."""

    def __enter__(self):
        self.count = 0
        monitoring.register_event_duration_secs_listener(self._listen)
        return self

    def _listen(self, event, duration_secs, **_):
        if event == "/jax/core/compile/backend_compile_duration":
            self.count += 1

    def __exit__(self, *exc):
        monitoring.unregister_event_duration_listener(self._listen)


_MASK8 = np.arange(T) < 2 * N + 2  # exactly the 2N + 2 frames a fit needs
_BAD_FIT_INPUTS = [
    # (features, keyword arguments, message)
    (None, dict(mask=np.zeros(T, bool)), r"fit: mask leaves 0 used frame"),
    (None, dict(mask=np.roll(_MASK8, 5) & (np.arange(T) != 5)), r"mask leaves 7 used frame.*8"),
    (None, dict(mask=np.where(_MASK8, 1.0, np.nan)), r"fit: mask must be booleans"),
    (None, dict(mask=np.where(_MASK8, 1.0, -1.0)), r"fit: mask must be booleans"),
    (_features(7), {}, r"fit: features have 7 frame\(s\), fewer than the 8"),
    (_features(0), {}, r"fit: features have 0 frame"),
    (_features()[:, :0], {}, r"fit: features have no channels"),
    (_features().astype(np.complex64), {}, r"fit: features must be real numbers"),
    (None, dict(omega_steps=-1.0), r"fit: omega_steps must be positive"),
    (None, dict(omega_steps=0.0), r"fit: omega_steps must be positive"),
    (None, dict(omega_steps=np.inf), r"fit: omega_steps must be positive"),
    (None, dict(f_min_hz=3.0, f_max_hz=0.4), r"fit: the search band f_min_hz=3.0 .. f_max_hz=0.4"),
    (None, dict(f_min_hz=1.0, f_max_hz=1.0), r"fit: the search band"),
    (None, dict(f_min_hz=-2.0, f_max_hz=-1.0), r"fit: the search band"),
    (None, dict(f_min_hz=float("nan")), r"fit: f_min_hz must be a real number"),
    (None, dict(f_min_hz=31.0, f_max_hz=100.0), r"fit: f_min_hz=31.0 is not below the Nyquist"),
    (None, dict(channel_weights=np.array([np.nan, 1.0])), r"fit: channel_weights must be finite"),
    (None, dict(channel_weights=np.array([-1.0, -1.0])), r"fit: channel_weights must be finite"),
    (None, dict(channel_weights=np.zeros(2)), r"fit: channel_weights are all zero"),
    (None, dict(channel_names=("root.vx", "root.y")), r"channel_weights are all zero.*root\.\*"),
    (None, dict(grid_points=1), r"fit: grid_points must be an integer >= 2, got 1"),
    (None, dict(grid_points=0), r"fit: grid_points must be an integer >= 2"),
    (None, dict(grid_points=8.0), r"fit: grid_points must be an integer"),
    (None, dict(search_halfwidth=-0.5), r"fit: search_halfwidth must be .* > 0"),
    (None, dict(search_halfwidth=0.0), r"fit: search_halfwidth"),
    (None, dict(search_halfwidth=-1.0), r"fit: search_halfwidth"),
    (None, dict(search_halfwidth=np.inf), r"fit: search_halfwidth"),
    (None, dict(golden_iterations=-1), r"fit: golden_iterations must be an integer >= 0"),
    (None, dict(representation="quat"), r"fit: representation 'quat'"),
    (None, dict(frame_time_s=np.nan), r"fit: frame_time_s must be positive"),
    (None, dict(num_harmonics=2.5), r"fit: num_harmonics must be an integer >= 1, got 2.5"),
    (None, dict(num_harmonics=0), r"fit: num_harmonics must be an integer >= 1, got 0"),
    (None, dict(num_harmonics="3"), r"fit: num_harmonics must be an integer"),
]


@pytest.mark.parametrize("features, kwargs, match", _BAD_FIT_INPUTS,
                         ids=[f"case{i}" for i in range(len(_BAD_FIT_INPUTS))])
def test_fit_rejects_degenerate_input_before_any_work(features, kwargs, match):
    features = _features() if features is None else features
    kwargs = dict(kwargs)
    dt = kwargs.pop("frame_time_s", DT)
    n = kwargs.pop("num_harmonics", N)
    with _Compiles() as c, pytest.raises(UserError, match=match):
        F.fit(features, dt, n, **kwargs)
    assert c.count == 0  # nothing compiled (or run) before the error
    assert issubclass(UserError, ValueError)


def test_fit_batch_names_the_bad_clip():
    x = np.stack([_features()] * 3)
    mask = np.ones((3, T), bool)
    mask[1] = False
    mask[2, 5:] = False
    with pytest.raises(UserError, match=r"fit_batch: mask leaves 0 used frame\(s\) in clip 1 "
                                        r"\(and 1 other clip"):
        F.fit_batch(x, DT, N, mask=mask)
    with pytest.raises(UserError, match=r"fit_batch: omega_steps must be positive .* -2.0 at "
                                        r"index 2"):
        F.fit_batch(x, DT, N, omega_steps=np.array([6.0, np.nan, -2.0]))
    with pytest.raises(UserError, match=r"fit_batch: features have 3 frame"):
        F.fit_batch(x[:, :3], DT, N)
    with pytest.raises(UserError, match=r"fit_batch: num_harmonics"):
        F.fit_batch(x, DT, 1.5)


def test_fit_casts_integer_features_and_accepts_the_legal_edge_cases():
    """Integer features are cast to float (as `rotations` does; it was a raw 'not inexact'
    error); exactly 2N + 2 used frames and omega_steps = NaN (unknown) are legal."""
    x = _features()
    xi = np.round(1000 * x).astype(np.int32)
    mask = np.ones(T, bool)
    kw = dict(mask=mask, omega_steps=np.nan, grid_points=9, golden_iterations=10)
    got = F.fit(xi, DT, N, **kw)
    ref = F.fit(xi.astype(np.float32), DT, N, **kw)
    assert got.model.offset.dtype == jnp.result_type(float)
    for a, b in zip(jax.tree.leaves(got), jax.tree.leaves(ref), strict=True):
        np.testing.assert_array_equal(np.asarray(a), np.asarray(b))
    np.testing.assert_allclose(float(got.omega_fit), 2 * np.pi, rtol=1e-4)
    # 2N + 2 frames spread over the clip (8 consecutive ones cover 0.13 s: less than a cycle,
    # refused since `MIN_CYCLES`).
    spread = np.isin(np.arange(T), np.linspace(0, T - 1, 2 * N + 2).round().astype(int))
    edge = F.fit(x, DT, N, **dict(kw, mask=spread))
    assert int(edge.num_frames) == 2 * N + 2


def test_fit_value_checks_are_skipped_for_traced_inputs():
    x = _features()

    @jax.jit
    def omega(f, m, om, w):
        return F.fit(f, DT, N, mask=m, omega_steps=om, channel_weights=w, grid_points=9,
                     golden_iterations=10).omega_fit

    got = omega(jnp.asarray(x), jnp.ones(T, bool), jnp.asarray(np.nan, jnp.float32),
                jnp.ones(2, jnp.float32))
    np.testing.assert_allclose(float(got), 2 * np.pi, rtol=1e-4)


def test_fit_linear_checks_its_input():
    x = _features()
    t = np.arange(T) * DT
    om = 2 * np.pi
    with pytest.raises(UserError, match=r"fit_linear: features hold 1 NaN .* index \(4, 1\)"):
        x_nan = x.copy()
        x_nan[4, 1] = np.nan
        F.fit_linear(x_nan, t, om, 2)
    with pytest.raises(UserError, match=r"fit_linear: t_s shape \(10,\), expected \(120,\)"):
        F.fit_linear(x, t[:10], om, 2)
    with pytest.raises(UserError, match=r"fit_linear: num_harmonics must be an integer >= 1, got 0"):
        F.fit_linear(x, t, om, 0)
    with pytest.raises(UserError, match=r"fit_linear: num_harmonics"):
        F.fit_linear(x, t, om, 1.5)
    with pytest.raises(UserError, match=r"fit_linear: features must be \[T, C\], got shape \(120,\)"):
        F.fit_linear(x[:, 0], t, om, 2)
    with pytest.raises(UserError, match=r"fit_linear: mask shape \(5,\)"):
        F.fit_linear(x, t, om, 2, mask=np.ones(5, bool))
    with pytest.raises(UserError, match=r"fit_linear: features have 4 frame\(s\), fewer than the 5"):
        F.fit_linear(x[:4], t[:4], om, 2)
    with pytest.raises(UserError, match=r"fit_linear: mask leaves 4 used frame"):
        F.fit_linear(x, t, om, 2, mask=np.arange(T) < 4)
    with pytest.raises(UserError, match=r"fit_linear: omega must be finite"):
        F.fit_linear(x, t, np.nan, 2)
    with pytest.raises(UserError, match=r"fit_linear: t_s holds NaN"):
        F.fit_linear(x, np.where(np.arange(T) == 3, np.nan, t), om, 2)
    with pytest.raises(UserError, match=r"fit_linear: representation 'quat'"):
        F.fit_linear(x, t, om, 2, representation="quat")
    # NaN in frames the mask leaves out is ignored (as in `fit`): it was a NaN model.
    mask = np.arange(T) != 4
    x_nan = x.copy()
    x_nan[4] = np.nan
    got = F.fit_linear(x_nan, t, om, 2, mask=mask)
    ref = F.fit_linear(x, t, om, 2, mask=mask)
    np.testing.assert_allclose(got.amplitude, ref.amplitude, rtol=1e-6, atol=1e-7)
    np.testing.assert_allclose(got.amplitude[:, 1], 0.3, rtol=1e-4)
    # Integer features are cast; traced omega or features skip the value checks.
    xi = np.round(1000 * x).astype(np.int32)
    np.testing.assert_array_equal(F.fit_linear(xi, t, om, 2).amplitude,
                                  F.fit_linear(xi.astype(np.float32), t, om, 2).amplitude)
    g = jax.grad(lambda w: jnp.sum(F.fit_linear(x, t, w, 2).amplitude))(jnp.float32(om))
    assert np.isfinite(float(g))
    a = jax.jit(lambda f: F.fit_linear(f, t, om, 2).amplitude)(jnp.asarray(x))
    np.testing.assert_allclose(a, ref.amplitude, rtol=1e-5, atol=1e-6)


def test_synthesize_rejects_times_of_the_wrong_rank():
    m = _model()
    with pytest.raises(UserError, match=r"synthesize: t_s must be \[T\].*\(3, 4\)"):
        F.synthesize(m, np.zeros((3, 4)))
    with pytest.raises(UserError, match=r"synthesize: t_s must be \[T\].*\(\)"):
        F.synthesize(m, 0.5)
    with pytest.raises(UserError, match=r"synthesize_phase: phase must be \[T\]"):
        F.synthesize_phase(m, np.zeros((2, 2)))
    stacked = F.stack_models([m, m, m])
    with pytest.raises(UserError, match=r"synthesize: `model` must be one model .*\(3, 2\)"):
        F.synthesize(stacked, np.zeros(3))
    with pytest.raises(UserError, match=r"synthesize_phase: `model` must be one model"):
        F.synthesize_phase(stacked, np.zeros(3))
    # vmap and jit see one model and [T] times: unchanged.
    t = np.linspace(0, 1, 5)
    out = jax.jit(jax.vmap(F.synthesize, in_axes=(0, None)))(stacked, t)
    np.testing.assert_allclose(out[1], F.synthesize(m, t), atol=1e-6)
    assert F.synthesize(m, np.zeros(0)).shape == (0, 2)


def test_metrics_check_shapes():
    m = _model()
    x = _features()
    t = np.arange(T) * DT
    with pytest.raises(UserError, match=r"rms_error: features shape \(120, 1\), expected \[T, 2\]"):
        F.rms_error(m, x[:, :1], t)
    with pytest.raises(UserError, match=r"rms_error: t_s shape \(10,\), expected \(120,\)"):
        F.rms_error(m, x, t[:10])
    with pytest.raises(UserError, match=r"rms_error: mask shape"):
        F.rms_error(m, x, t, mask=np.ones(3, bool))
    with pytest.raises(UserError, match=r"variance_explained: target shape \(120, 2\) and approx "
                                        r"shape \(10, 2\)"):
        F.variance_explained(x, x[:10])
    with pytest.raises(UserError, match=r"variance_explained: mask shape"):
        F.variance_explained(x, x, mask=np.ones(3, bool))
    assert F.rms_error(m, x, t).shape == (2,)


def test_channel_event_phase_rejects_out_of_range_channels():
    m = _model()
    with pytest.raises(UserError, match=r"channel 10 out of range for a model of 2 channel"):
        F.channel_event_phase(m, 10)
    with pytest.raises(UserError, match=r"channel -3 out of range"):
        F.channel_event_phase(m, -3)
    with pytest.raises(UserError, match=r"channel must be an integer"):
        F.channel_event_phase(m, 1.5)
    with pytest.raises(UserError, match=r"`model` must be one model"):
        F.channel_event_phase(F.stack_models([m, m]), 0)
    # Python-style negative indices and a traced channel still work.
    assert float(F.channel_event_phase(m, -1)) == float(F.channel_event_phase(m, 1))
    got = jax.jit(F.channel_event_phase)(m, jnp.asarray(1))
    assert float(got) == float(F.channel_event_phase(m, 1))


def _dft_amplitude(x):
    """Single-sided amplitude by a direct DFT sum (no FFT): 2 |c_k|, but |c_k| at 0 Hz and at
    the Nyquist bin of an even T (bins with no mirror image)."""
    T = x.shape[0]
    k = np.arange(T // 2 + 1)[:, None]
    n = np.arange(T)[None, :]
    c = np.exp(-2j * np.pi * k * n / T) @ x / T
    single = (k[:, 0] == 0) | (2 * k[:, 0] == T)
    return np.abs(c) * np.where(single, 1.0, 2.0)[:, None]


@pytest.mark.parametrize("T", [8, 9, 240, 241])
def test_amplitude_spectrum_dc_and_nyquist_are_not_doubled(T, x64):
    """A cosine of amplitude A on any bin, the Nyquist bin included, reads A (it read 2A at
    Nyquist for even T); against a closed form and a direct DFT sum."""
    n = np.arange(T)
    dc, a1, k1, a_nyq = 0.7, 2.5, 2, 1.3
    x = np.stack([dc + a1 * np.cos(2 * np.pi * k1 * n / T + 0.4)
                  + (a_nyq * np.cos(np.pi * n) if T % 2 == 0 else 0.0),
                  np.random.default_rng(T).normal(size=T)], -1)
    freqs, amp = F.amplitude_spectrum(x, 0.5)
    amp = np.asarray(amp)
    assert amp.shape == (T // 2 + 1, 2)
    np.testing.assert_allclose(amp[0, 0], dc, rtol=1e-12)
    np.testing.assert_allclose(amp[k1, 0], a1, rtol=1e-12)
    if T % 2 == 0:
        np.testing.assert_allclose(amp[-1, 0], a_nyq, rtol=1e-12)
        np.testing.assert_allclose(float(freqs[-1]), 1.0)  # Nyquist of 0.5 s frames
    np.testing.assert_allclose(amp, _dft_amplitude(x), atol=1e-12)
    # One channel as a 1-D array keeps its shape.
    np.testing.assert_allclose(F.amplitude_spectrum(x[:, 1], 0.5)[1], amp[:, 1], atol=1e-12)


def test_amplitude_spectrum_and_spectral_omega_check_frame_time():
    x = _features()
    for dt in (0.0, -1.0, np.nan, np.inf):
        with pytest.raises(UserError, match=r"amplitude_spectrum: frame_time_s must be positive"):
            F.amplitude_spectrum(x, dt)
        with pytest.raises(UserError, match=r"spectral_omega: frame_time_s must be positive"):
            F.spectral_omega(x, dt)
    with pytest.raises(UserError, match=r"amplitude_spectrum: features must be \[T, C\] with T >= 1"):
        F.amplitude_spectrum(x[:0], DT)
    with pytest.raises(UserError, match=r"spectral_omega: features must be \[T, C\], got shape \(120,\)"):
        F.spectral_omega(x[:, 0], DT)
    with pytest.raises(UserError, match=r"spectral_omega: the band"):
        F.spectral_omega(x, DT, f_min_hz=3.0, f_max_hz=0.4)
    with pytest.raises(UserError, match=r"spectral_omega: pad_factor"):
        F.spectral_omega(x, DT, pad_factor=0)
    with pytest.raises(UserError, match=r"spectral_omega: mask shape"):
        F.spectral_omega(x, DT, mask=np.ones(3))
    om, _, _ = F.spectral_omega(x, DT)
    np.testing.assert_allclose(float(om), 2 * np.pi, rtol=0.05)  # 2 cycles: a coarse peak


def test_model_and_style_vector_errors_are_user_errors():
    z = jnp.zeros((3, 2))
    cases = [
        lambda: F.FourierModel(jnp.zeros(4), z, z, jnp.asarray(1.0)),
        lambda: F.FourierModel(jnp.zeros(3), z, jnp.zeros((3, 3)), jnp.asarray(1.0)),
        lambda: F.FourierModel(jnp.zeros(3), z, z, jnp.zeros(2)),
        lambda: F.FourierModel(jnp.zeros(3), z, z, jnp.asarray(1.0), "quaternion"),
        lambda: F.FourierModel(jnp.zeros(3), z, z, jnp.asarray(1.0), "euler", ("a", "b")),
        lambda: F.FourierModel.from_tilmanne_vector(jnp.zeros(5), 2, 3),
        lambda: F.FourierModel.from_tilmanne_vector(jnp.zeros(15), 2, 3, convention="cos"),
        lambda: _model().tilmanne_vector("cos"),
    ]
    for make in cases:
        with pytest.raises(UserError):
            make()


@pytest.mark.parametrize("names", [5, "ab", ("a", 3), None, [b"a", b"b"]])
def test_fourier_model_refuses_channel_names_that_are_not_strings(names):
    m = _model()
    with pytest.raises(UserError, match="channel_names must be a sequence of str"):
        F.FourierModel(m.offset, m.amplitude, m.phase, m.omega, channel_names=names)


def test_fourier_model_takes_channel_names_as_any_string_sequence():
    m = _model()
    for names in (["a", "b"], ("a", "b"), np.array(["a", "b"])):
        got = F.FourierModel(m.offset, m.amplitude, m.phase, m.omega, channel_names=names)
        assert got.channel_names == ("a", "b") and all(type(n) is str for n in got.channel_names)
        hash(got.channel_names)  # a static field: must hash (jit's cache key)
    with pytest.raises(UserError, match="3 channel_names for 2 channels"):
        F.FourierModel(m.offset, m.amplitude, m.phase, m.omega, channel_names=["a", "b", "c"])


def test_fit_refuses_a_clip_that_does_not_move():
    """A constant clip has no fundamental: the omega search returned an arbitrary value (1.96
    rad/s, i.e. a 0.31 Hz "gait", for this one), now a UserError naming the clip."""
    still = np.full((T, 2), 0.3, np.float32)
    with pytest.raises(UserError, match="constant over the used frames on every weighted channel"):
        F.fit(still, DT, N)
    # Constant on the weighted channels only (the moving one weighs nothing): refused too.
    half = np.stack([still[:, 0], _features()[:, 0]], -1)
    with pytest.raises(UserError, match="constant"):
        F.fit(half, DT, N, channel_weights=np.array([1.0, 0.0], np.float32))
    assert np.isfinite(float(F.fit(half, DT, N).omega_fit))  # weighted: it moves, it fits
    # Moving only in frames the mask leaves out: nothing moves in the used frames.
    masked = still.copy()
    masked[:10] = _features()[:10]
    mask = np.arange(T) >= 10
    with pytest.raises(UserError, match="constant"):
        F.fit(masked, DT, N, mask=mask)
    # A batch names the first still clip and counts the others.
    batch = np.stack([_features(), still, still])
    with pytest.raises(UserError, match=r"in clip 1 \(and 1 other clip\(s\)\)"):
        F.fit_batch(batch, DT, N)


def test_fit_still_fits_a_small_motion_on_a_large_offset():
    """The constant test is relative to the values' size, not absolute: a 0.01-degree sway on a
    90-degree channel still fits its frequency."""
    x = 90.0 + 0.01 * _features()
    res = F.fit(x.astype(np.float32), DT, N)
    assert abs(float(res.omega_fit) - 2 * np.pi) < 0.05


def test_fit_refuses_a_clip_shorter_than_one_cycle():
    """With less than one period in view the fundamental is not determined: a third of a
    cycle was fitted at a wrong frequency with nearly all of the variance explained (a 0.9 Hz
    signal cut to 0.37 cycle: 1.85 Hz, 0.9999). Refused, naming the clip; one whole cycle
    fits."""
    x = _features(T=20)  # 1 Hz at 60 fps: a third of a cycle
    with pytest.raises(UserError, match=r"^fit: the used frames cover 0\.\d\d cycle\(s\) of the fitted fundamental"):
        F.fit(x, DT, N)
    one = F.fit(_features(T=60), DT, N)  # exactly one cycle
    assert abs(float(one.omega_fit) - 2 * np.pi) < 1e-3
    batch = np.stack([_features(), np.concatenate([_features(T=20), np.zeros((100, 2), np.float32)])])
    mask = np.stack([np.ones(T, bool), np.arange(T) < 20])
    with pytest.raises(UserError, match=r"^fit_batch: clip 1: the used frames cover"):
        F.fit_batch(batch, DT, N, mask=mask)
    # Every short clip of a batch is named (up to 11), so one run finds them all.
    with pytest.raises(UserError, match=r"^fit_batch: clip 1 \(and 1 other clip\(s\): 2\): the used"):
        F.fit_batch(batch[[0, 1, 1]], DT, N, mask=mask[[0, 1, 1]])


def test_fit_refuses_the_first_half_second_of_a_real_walk():
    # 07_01 fits at 0.93 Hz; its first 0.5 s alone fitted at 1.58 Hz with rms 1.05 degrees.
    # Its guess lies above the search's floor (0.95 cycle in 0.5 s: 1.9 Hz), where the search
    # then ends: a boundary, refused as well.
    from fourierjax import data, motion

    m = data.load("07_01")
    # fit_motions reports it against the clip (and fits the other); fit_batch raises.
    whole, head = motion.fit_motions([m, m[:60]], 3, "euler")
    assert whole.successful and head.result == "on_search_floor"
    assert re.search(r"clip 1 .*the least-squares fundamental lies on the lowest.*"
                     r"\(fitted fundamental 1\.9\d\d Hz\)", head.message)


def test_fit_search_stays_above_a_cycle_of_the_clip():
    """A clip of 1.29 cycles (4.06 rad/s over 2 s: five harmonics, a drift, noise) fitted with
    N = 7: the residual's global minimum lies at 2.87 rad/s, 0.91 cycle, where the 7th harmonic
    meets the true 5th. The fit went there (and was refused, failing the whole batch of the fit
    benchmark); the search now stays above 0.95 cycle and finds the true fundamental, as
    scipy's least_squares from the same guess does (4.0586)."""
    from experiments.benchmarks.fit import gait_like_clips

    x, omega = gait_like_clips(256, 240, 57, 1 / 120)  # the benchmark's clips
    assert abs(omega[92] - 4.0588) < 1e-3
    res = F.fit(x[92], 1 / 120, 7)
    np.testing.assert_allclose(float(res.omega_fit), omega[92], rtol=1e-3)


def test_spectral_omega_windows_the_used_frames():
    """A mask that leaves out the start of a clip: the Hann window spans the used frames (it
    was laid over frames 0..n-1, on frames the mask leaves out: 1.80 Hz for this 0.9 Hz
    signal), so the spectrum equals that of the used frames cut out."""
    t = np.arange(600) / 120
    x = np.stack([np.sin(2 * np.pi * 0.9 * t + k) + 0.3 * np.sin(4 * np.pi * 0.9 * t + 2 * k)
                  for k in range(4)], -1).astype(np.float32)
    used = np.arange(600) >= 420
    masked, _, _ = F.spectral_omega(x, 1 / 120, mask=used)
    cut, _, _ = F.spectral_omega(x[420:], 1 / 120)
    assert float(masked) == pytest.approx(float(cut), rel=1e-3)
    assert float(F.fit(x, 1 / 120, N, mask=used).omega_fit) == pytest.approx(2 * np.pi * 0.9, rel=1e-4)


def test_fit_float32_clips_under_x64(x64):
    # jnp.fft.rfftfreq is float64 under x64 and made the omega search's loop carry change
    # dtype (TypeError deep in lax.fori_loop): a float32 clip fits in float32.
    res = F.fit(_features(), DT, N)
    assert res.omega_fit.dtype == jnp.float32
    assert abs(float(res.omega_fit) - 2 * np.pi) < 1e-3
