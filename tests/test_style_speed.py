"""Joint speed of a gait cycle and the speed limit of `style.superpose` (issue #22: no limb flips)."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from fourierjax import data, fourier, style
from fourierjax.body import infer_body_map
from fourierjax.errors import UserError
from fourierjax.features import channel_names_for

from .test_transfer import _branch_changed, fit_bandai_walk_run, model


@pytest.fixture(scope="module")
def cmu():
    m = data.load("07_01")
    return m.skeleton(), channel_names_for(m.topology, "euler"), infer_body_map(m)


def test_peak_speed_is_the_largest_derivative_of_the_poses(cmu):
    """The chord measure against the exact derivative of the poses along the cycle (forward-mode
    autodiff of the FK of eq. 1 in the phase): the chord never exceeds the derivative's peak
    and converges to it; per second is per radian times ω exactly."""
    skel, names, bm = cmu
    m = model(names, 5, scale=0.25)
    pelvis = bm.pelvis
    from fourierjax import features

    def poses(theta):
        return features.root_relative_positions(skel, fourier.synthesize_phase(m, theta), "euler", pelvis)

    theta = jnp.arange(4096) * (2 * jnp.pi / 4096)
    _, dp = jax.jvp(poses, (theta,), (jnp.ones_like(theta),))
    exact = float(jnp.linalg.norm(dp, axis=-1).max())
    coarse = float(style.peak_joint_speed(m, skel, per="radian", num_samples=64, body_map=bm))
    fine = float(style.peak_joint_speed(m, skel, per="radian", num_samples=1024, body_map=bm))
    assert coarse <= fine <= exact * (1 + 1e-4)
    assert fine == pytest.approx(exact, rel=2e-3)
    per_second = float(style.peak_joint_speed(m, skel, num_samples=1024, body_map=bm))
    assert per_second == pytest.approx(fine * float(m.omega), rel=1e-6)
    # the experiments' flip criterion is this measure
    from experiments._style_transfer import max_phase_jump

    assert max_phase_jump(m, skel, body_map=bm) == pytest.approx(
        float(style.peak_joint_speed(m, skel, per="radian", body_map=bm)), rel=1e-6)


def test_speed_limit_keeps_a_branch_flip_out_and_leaves_the_rest(cmu):
    skel, names, bm = cmu
    base = model(names, 3, scale=0.2)
    flip = _branch_changed(base, names.index("LeftLeg.Xrotation"))  # a knee through a full turn
    clean = _branch_changed(base, names.index("LeftLeg.Xrotation"), turns=0)
    limit = style.joint_speed_limit([base, clean], skel, body_map=bm)
    char = style.characteristic(flip, base)
    for w in (0.25, 1.0, 1.5):
        plain = style.superpose(base, [char], [w], method="phasor")
        held = style.superpose(base, [char], [w], method="phasor", speed_limit=limit)
        assert float(style.peak_joint_speed(plain, skel, body_map=bm)) > 1.5 * float(limit.max_speed)
        speed = float(style.peak_joint_speed(held, skel, body_map=bm))
        phase_speed = float(style.peak_joint_speed(held, skel, per="radian", body_map=bm))
        assert speed <= float(limit.max_speed) * (1 + 1e-6)
        assert phase_speed <= float(limit.max_phase_speed) * (1 + 1e-6)
        assert not np.allclose(held.offset, base.offset) or not np.allclose(held.amplitude, base.amplitude)
    # a characteristic within the limit is superposed as without it (to the rounding of
    # another compiled program)
    small = style.characteristic(clean, base)
    a = style.superpose(base, [small], [0.5], method="phasor")
    b = style.superpose(base, [small], [0.5], method="phasor", speed_limit=limit)
    for x, y in zip(jax.tree.leaves(a), jax.tree.leaves(b), strict=True):
        np.testing.assert_allclose(np.asarray(x), np.asarray(y), rtol=1e-5, atol=1e-6)
    # a base faster than the limit is returned as it is
    tight = style.SpeedLimit(skel, max_speed=0.5 * float(limit.max_speed), body_map=bm)
    out = style.superpose(base, [char], [1.0], method="phasor", speed_limit=tight)
    np.testing.assert_allclose(np.asarray(out.offset), np.asarray(base.offset), atol=1e-6)


def test_speed_limit_under_jit_vmap_and_grad(cmu):
    """Traced weights and bounds; vmapped over weights; the implicit derivative of the scale
    where the limit binds matches central differences."""
    skel, names, bm = cmu
    base = model(names, 3, scale=0.2)
    flip = _branch_changed(base, names.index("LeftLeg.Xrotation"))
    limit = style.joint_speed_limit([base], skel, body_map=bm, per="second")
    char = style.characteristic(flip, base)
    ms = float(limit.max_speed)

    def f(w, bound):
        lim = style.SpeedLimit(skel, max_speed=bound, body_map=bm)
        out = style.superpose(base, [char], [w], method="phasor", speed_limit=lim)
        return jnp.sum(out.offset ** 2) + jnp.sum(out.amplitude)

    ws = jnp.array([0.5, 1.0, 1.5])
    jitted = jax.jit(jax.vmap(f, in_axes=(0, None)))(ws, jnp.asarray(ms))
    np.testing.assert_allclose(np.asarray(jitted), [float(f(w, ms)) for w in (0.5, 1.0, 1.5)], rtol=1e-5)
    g = jax.grad(f, argnums=(0, 1))(jnp.asarray(1.0), jnp.asarray(ms))
    assert all(np.isfinite(float(x)) for x in g)
    h = 0.01 * ms
    fd = (float(f(1.0, ms + h)) - float(f(1.0, ms - h))) / (2 * h)
    assert float(g[1]) == pytest.approx(fd, rel=0.1)
    assert float(g[1]) != 0.0  # the bound moves the result where it binds
    hw = 0.02
    fdw = (float(f(1.0 + hw, ms)) - float(f(1.0 - hw, ms))) / (2 * hw)
    # one characteristic: the bound fixes a * w, so the weight hardly moves the result
    assert abs(float(g[0])) <= 0.05 * abs(float(g[1]) * ms) + 1e-3 and abs(fdw) <= 0.05 * abs(float(g[1]) * ms) + 1e-3


def test_speed_limit_errors(cmu):
    skel, names, bm = cmu
    base = model(names, 3, scale=0.2)
    with pytest.raises(UserError, match="max_speed"):
        style.SpeedLimit(skel)
    with pytest.raises(UserError, match="finite and > 0"):
        style.SpeedLimit(skel, max_speed=-1.0)
    with pytest.raises(UserError, match="finite and > 0"):
        style.SpeedLimit(skel, max_phase_speed=float("nan"))
    with pytest.raises(UserError, match="iterations"):
        style.SpeedLimit(skel, max_speed=1.0, iterations=0)
    with pytest.raises(UserError, match="empty"):
        style.joint_speed_limit([], skel, body_map=bm)
    with pytest.raises(UserError, match="margin"):
        style.joint_speed_limit([base], skel, body_map=bm, margin=0.0)
    with pytest.raises(UserError, match="per"):
        style.peak_joint_speed(base, skel, per="frame", body_map=bm)
    with pytest.raises(UserError, match="SpeedLimit"):
        style.superpose(base, [style.characteristic(base, base)], [1.0], speed_limit=3.0)
    # a traced bound that is not > 0: a clear error, not a wrong answer
    char = style.characteristic(model(names, 4, scale=0.2), base)

    @jax.jit
    def g(bound):
        lim = style.SpeedLimit(skel, max_speed=bound, body_map=bm)
        return style.superpose(base, [char], [1.0], speed_limit=lim).offset

    with pytest.raises(Exception, match="finite and > 0"):
        jax.block_until_ready(g(jnp.asarray(-1.0)))


@pytest.fixture(scope="module")
def bandai():
    return fit_bandai_walk_run(("normal", "happy", "angry", "old"))


def test_eq8_with_the_speed_limit_never_outruns_its_clips_on_bandai(bandai):
    """Unuma's eq. 8 plain, walk -> run on Bandai-1, weights 0 to 1.5: without the limit some
    joint moves faster per frame than in any of the three clips it reads (the issue's flip
    criterion); with `joint_speed_limit` of those clips, never, and the styled run still
    moves towards the real one."""
    models, skel, bm, dt = bandai
    base = models[("run", "normal")]
    exceeded = 0
    for s in ("happy", "angry", "old"):
        clips = [base, models[("walk", s)], models[("walk", "normal")]]
        ref = max(float(style.peak_joint_speed(m, skel, body_map=bm)) for m in clips)
        limit = style.joint_speed_limit(clips, skel, body_map=bm)
        assert float(limit.max_speed) == pytest.approx(ref, rel=1e-6)
        char = style.characteristic(models[("walk", s)], models[("walk", "normal")])
        for w in (0.0, 0.5, 1.0, 1.5):
            plain = style.superpose(base, [char], [w])
            held = style.superpose(base, [char], [w], speed_limit=limit)
            exceeded += float(style.peak_joint_speed(plain, skel, body_map=bm)) > ref
            assert float(style.peak_joint_speed(held, skel, body_map=bm)) <= ref * (1 + 1e-6), (s, w)
            assert float(style.peak_joint_speed(held, skel, per="radian", body_map=bm)) <= \
                float(limit.max_phase_speed) * (1 + 1e-6), (s, w)
    assert exceeded >= 3  # the case under test: plain eq. 8 outruns its clips
