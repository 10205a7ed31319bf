"""Per-clip status of batch fits (`fourier.FitStatus`), checks that hold under jit, and the
deprecated `FourierModel.style_vector` alias."""

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

from fourierjax import fourier as F
from fourierjax.errors import UserError

T, DT, N = 120, 1 / 60, 3


def _features(T=T, C=2):
    t = np.arange(T) * DT
    return np.stack([np.sin(2 * np.pi * t + k) + 0.3 * np.sin(4 * np.pi * t + 2 * k)
                     for k in range(C)], -1).astype(np.float32)


def _batch():
    """Four clips: good, too few used frames for a cycle, NaN in a used frame, good."""
    x = np.stack([_features()] * 4)
    mask = np.ones((4, T), bool)
    mask[1, 30:] = False  # 0.5 s of a 1 Hz walk: half a cycle
    x[2, 7, 1] = np.nan
    return x, mask


def test_fit_batch_throw_false_flags_bad_clips_and_fits_the_others():
    x, mask = _batch()
    res = F.fit_batch(x, DT, N, mask=mask, throw=False, grid_points=9, golden_iterations=10)
    assert res.result.shape == (4,)
    assert [F.FitStatus(int(c)) for c in res.result] == [
        F.FitStatus.SUCCESSFUL, F.FitStatus.TOO_FEW_CYCLES, F.FitStatus.NONFINITE,
        F.FitStatus.SUCCESSFUL]
    np.testing.assert_array_equal(res.successful, [True, False, False, True])
    np.testing.assert_allclose(res.omega_fit[np.asarray([0, 3])], 2 * np.pi, rtol=1e-4)
    msgs = res.messages()
    assert msgs[0] == "fitted" and "cycles" in msgs[1] and "NaN" in msgs[2]
    # The good clips are fitted as they are alone.
    alone = F.fit(x[0], DT, N, grid_points=9, golden_iterations=10)
    np.testing.assert_allclose(res.omega_fit[0], alone.omega_fit, rtol=1e-6)
    assert int(alone.result) == F.FitStatus.SUCCESSFUL


def test_fit_batch_throw_true_raises_naming_the_clip():
    x, mask = _batch()
    x[2, 7, 1] = 0.0
    with pytest.raises(UserError, match=r"fit_batch: clip 1: the used frames cover"):
        F.fit_batch(x, DT, N, mask=mask, grid_points=9, golden_iterations=10)
    x[3, :, :] = 1.0  # constant
    with pytest.raises(UserError, match=r"constant .* in clip 3"):
        F.fit_batch(x, DT, N, grid_points=9, golden_iterations=10)


def test_nan_under_jit_is_refused_or_flagged():
    x = _features()
    x[5, 0] = np.nan

    @jax.jit
    def omega(f):
        return F.fit(f, DT, N, grid_points=9, golden_iterations=10).omega_fit

    with pytest.raises(Exception, match="NaN or infinite"):
        jax.block_until_ready(omega(jnp.asarray(x)))

    @jax.jit
    def status(f):
        return F.fit(f, DT, N, grid_points=9, golden_iterations=10, throw=False).result

    assert int(status(jnp.asarray(x))) == F.FitStatus.NONFINITE
    assert int(status(jnp.asarray(_features()))) == F.FitStatus.SUCCESSFUL
    # A too-short clip under jit too (the mask is traced, so the host check cannot see it).
    short = jnp.arange(T) < 30
    with pytest.raises(Exception, match="cycles"):
        jax.block_until_ready(eqx.filter_jit(
            lambda f, m: F.fit(f, DT, N, mask=m, grid_points=9, golden_iterations=10).omega_fit
        )(jnp.asarray(_features()), short))


def test_fit_linear_nan_under_jit_is_refused():
    x = _features()
    x[4, 1] = np.nan
    t = np.arange(T) * DT
    with pytest.raises(Exception, match="NaN or infinite"):
        jax.block_until_ready(jax.jit(lambda f: F.fit_linear(f, t, 2 * np.pi, 2).amplitude)(
            jnp.asarray(x)))


def test_style_vector_is_a_deprecated_alias_of_tilmanne_vector():
    m = F.FourierModel(jnp.ones(2), jnp.full((2, 3), 0.5), jnp.zeros((2, 3)), jnp.asarray(6.0))
    with pytest.warns(DeprecationWarning, match="tilmanne_vector"):
        v = m.style_vector("cosine")
    np.testing.assert_array_equal(v, m.tilmanne_vector("cosine"))
    with pytest.warns(DeprecationWarning, match="from_tilmanne_vector"):
        back = F.FourierModel.from_style_vector(v, 2, 3, convention="cosine")
    np.testing.assert_allclose(back.amplitude, m.amplitude, atol=1e-6)


def test_old_import_paths_still_work():
    from fourierjax import features, motion

    assert F.wrap_angle is __import__("fourierjax._math", fromlist=["wrap_angle"]).wrap_angle
    assert F.ROOT_CHANNELS is features.ROOT_CHANNELS is motion.ROOT_CHANNELS
    for name in ("channel_names_for", "features_from_motion", "motion_from_features",
                 "channel_model", "make_euler_continuous", "local_pose_from_features",
                 "root_relative_positions", "joint_expmaps", "heading_of"):
        assert getattr(motion, name) is getattr(features, name)
    assert F.angle_channel_mask is features.angle_channel_mask


def test_value_checks_hold_under_jit():
    x = jnp.asarray(_features())
    m = F.FourierModel(jnp.ones(2), jnp.full((2, 3), 0.5), jnp.zeros((2, 3)), jnp.asarray(6.0))
    with pytest.raises(Exception, match="channel out of range"):
        jax.block_until_ready(jax.jit(F.channel_event_phase)(m, jnp.asarray(5)))
    assert np.isfinite(float(jax.jit(F.channel_event_phase)(m, jnp.asarray(-1))))
    with pytest.raises(Exception, match="frame_time_s must be positive"):
        jax.block_until_ready(jax.jit(lambda dt: F.spectral_omega(x, dt)[0])(jnp.float32(-1.0)))
    with pytest.raises(Exception, match="frame_time_s must be positive"):
        jax.block_until_ready(jax.jit(lambda dt: F.amplitude_spectrum(x, dt)[0])(jnp.float32(0.0)))
    t = jnp.arange(T) * DT
    with pytest.raises(Exception, match="omega must be finite"):
        jax.block_until_ready(jax.jit(lambda om: F.fit_linear(x, t, om, 2).amplitude)(
            jnp.float32(jnp.nan)))

    @jax.jit
    def status(mask, om_steps, cw):
        return F.fit(x, DT, N, mask=mask, omega_steps=om_steps, channel_weights=cw, throw=False,
                     grid_points=9, golden_iterations=10).result

    ones, nan, cw = jnp.ones(T), jnp.float32(jnp.nan), jnp.ones(2)
    assert int(status(ones, nan, cw)) == F.FitStatus.SUCCESSFUL
    assert int(status(ones.at[3].set(-1.0), nan, cw)) == F.FitStatus.BAD_WEIGHTS
    assert int(status(ones, jnp.float32(-2.0), cw)) == F.FitStatus.BAD_WEIGHTS
    assert int(status(ones, nan, jnp.zeros(2))) == F.FitStatus.BAD_WEIGHTS


def test_channel_model_refuses_a_traced_nonpositive_omega():
    from fourierjax import data, features

    clip = data.load("02_01")
    names = features.channel_names_for(clip.topology, "euler")
    C = len(names)
    m = F.FourierModel(jnp.zeros(C), jnp.zeros((C, 2)), jnp.zeros((C, 2)), jnp.asarray(6.0),
                       "euler", names)
    f = jax.jit(lambda om: features.channel_model(clip, eqx.tree_at(lambda m: m.omega, m, om)).omega)
    assert float(f(jnp.float32(6.0))) == 6.0
    with pytest.raises(Exception, match="omega must be > 0"):
        jax.block_until_ready(f(jnp.float32(0.0)))


def test_nan_under_jit_is_refused_when_only_the_model_is_kept():
    x = _features()
    x[9, 1] = np.inf
    f = jax.jit(lambda a: F.fit(a, DT, N, grid_points=9, golden_iterations=10).model.amplitude)
    with pytest.raises(Exception, match="NaN or infinite"):
        jax.block_until_ready(f(jnp.asarray(x)))


def test_fit_compiles_once_for_python_float_frame_times_and_steps():
    """filter_jit makes every non-array argument static: the frame time and step ω given as
    Python floats must reach it as arrays, or each value would compile a program of its own."""
    from jax import monitoring

    count = []

    def listen(event, duration_secs, **_):
        if event == "/jax/core/compile/backend_compile_duration":
            count.append(event)

    x = _features(T=96)
    kw = dict(grid_points=7, golden_iterations=6)
    F.fit(x, 1 / 60, 2, omega_steps=6.0, **kw)  # compiled here (or by an earlier test)
    monitoring.register_event_duration_secs_listener(listen)
    try:
        for dt, om in ((1 / 50, 5.0), (1 / 70, 7.0), (1 / 65, 6.5)):
            F.fit(x, dt, 2, omega_steps=om, **kw)
    finally:
        monitoring.unregister_event_duration_listener(listen)
    assert count == []
