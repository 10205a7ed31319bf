"""The crowd path (characters-minor synthesis + unrolled FK) against synthesize-then-FK and scipy."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from fourierjax import crowd, data, fourier, kinematics
from fourierjax.errors import UserError
from fourierjax.fourier import FourierModel
from fourierjax.skeleton import Skeleton
from tests.helpers import random_topology, reference_fk


def _models(rng, base, num_chars, num_harmonics=3, spread=50.0):
    """Random crowd models around a base pose `[C]` (degrees / file units), float32."""
    c = base.shape[0]
    off = np.broadcast_to(base, (num_chars, c)).copy()
    off += rng.normal(scale=spread, size=off.shape) * 0.1
    amp = rng.uniform(1.0, 40.0, size=(num_chars, c, num_harmonics)) / np.arange(1, num_harmonics + 1)
    ph = rng.uniform(-np.pi, np.pi, size=amp.shape)
    om = rng.uniform(4.0, 8.0, size=num_chars)
    f = np.float32
    return FourierModel(jnp.asarray(off, f), jnp.asarray(amp, f), jnp.asarray(ph, f), jnp.asarray(om, f))


def _reference(skeleton, models, t):
    channels = jax.vmap(lambda m: fourier.synthesize(m, jnp.asarray(t, jnp.float32)[None])[0])(models)
    return kinematics.joint_positions(skeleton, channels), channels


def test_equals_synthesize_then_fk_on_cmu_07_01():
    m = data.load("07_01")
    skel = m.skeleton()
    rng = np.random.default_rng(0)
    models = _models(rng, m.channels.mean(0), num_chars=5)
    c = crowd.make_crowd(skel, models)
    assert c.num_characters == 5 and c.num_harmonics == 3
    # 24 joints with children x 3 rotations + the root's 3 positions (leaf rotations move nothing).
    assert c.coefficients.shape == (7, 24 * 3 + 3, 5)
    for t in (0.0, 0.37, 123.456):
        ours = crowd.crowd_positions(c, jnp.float32(t))
        ref, _ = _reference(skel, models, t)
        assert ours.shape == (5, 31, 3) and ours.dtype == jnp.float32
        scale = float(jnp.abs(ref).max())
        np.testing.assert_allclose(ours, ref, atol=2e-6 * scale + 2e-3)
    # Different times give different poses (the test can fail).
    assert float(jnp.abs(crowd.crowd_positions(c, 0.1) - crowd.crowd_positions(c, 0.2)).max()) > 1.0
    # A new time (Python float, numpy or jax scalar) never recompiles.
    before = crowd._positions_jit.num_traces()
    for t in (0.5, np.float32(0.6), jnp.float32(0.7), jnp.asarray(0.8, jnp.float32)):
        crowd.crowd_positions(c, t)
    assert crowd._positions_jit.num_traces() == before


def _numpy_channels(models, t):
    """Unuma 1995 eq. 1 in float64 numpy: `[B, C]` channel values at time `t`."""
    off, amp, ph, om = (np.asarray(v, np.float64) for v in (models.offset, models.amplitude,
                                                              models.phase, models.omega))
    n = np.arange(1, amp.shape[-1] + 1)
    return off + (amp * np.sin(n * (om * t)[:, None, None] + ph)).sum(-1)


@pytest.mark.parametrize("seed", range(2))
def test_mixed_rotation_orders_match_scipy_fk(seed):
    # Random trees: all 6 Tait-Bryan orders, 1-2 rotation channels, rotation-free joints and
    # position channels on inner joints, in any channel order. Oracle: numpy synthesis and
    # scipy-rotation FK in float64.
    rng = np.random.default_rng(seed)
    topo = random_topology(rng, num_joints=10)
    skel = Skeleton(topo, rng.normal(size=(topo.num_joints, 3)) * 10, rng.normal(size=(topo.num_end_sites, 3)))
    models = _models(rng, rng.uniform(-90, 90, size=topo.num_channels), num_chars=4, num_harmonics=2)
    c = crowd.make_crowd(skel, models)
    orders = {o for o in topo.rotation_orders if o}
    assert len(orders) > 2, orders
    for t in (0.8, 31.7):
        ours = np.asarray(crowd.crowd_positions(c, t))
        oracle, _ = reference_fk(topo, np.asarray(skel.offsets), np.asarray(skel.end_site_offsets),
                                 _numpy_channels(models, t))
        np.testing.assert_allclose(ours, oracle, atol=1e-3, rtol=1e-5)


def test_float64_path_matches_scipy_fk_tightly(x64):
    rng = np.random.default_rng(5)
    topo = random_topology(rng, num_joints=5, num_end_sites=1)
    skel = Skeleton(topo, rng.normal(size=(topo.num_joints, 3)) * 10, rng.normal(size=(1, 3)))
    m32 = _models(rng, rng.uniform(-90, 90, size=topo.num_channels), num_chars=2, num_harmonics=2)
    models = jax.tree.map(lambda v: jnp.asarray(v, jnp.float64), m32)
    c = crowd.make_crowd(skel, models)
    assert c.coefficients.dtype == jnp.float64
    ours = crowd.crowd_positions(c, 1.3)
    assert ours.dtype == jnp.float64
    oracle, _ = reference_fk(topo, np.asarray(skel.offsets), np.asarray(skel.end_site_offsets),
                             _numpy_channels(models, 1.3))
    np.testing.assert_allclose(np.asarray(ours), oracle, atol=1e-9, rtol=1e-10)


def test_gradients_wrt_time_and_coefficients_are_finite_and_match_differences():
    rng = np.random.default_rng(3)
    topo = random_topology(rng, num_joints=6)
    skel = Skeleton(topo, rng.normal(size=(topo.num_joints, 3)) * 10)
    models = _models(rng, rng.uniform(-60, 60, size=topo.num_channels), num_chars=3, num_harmonics=2)
    c = crowd.make_crowd(skel, models)
    w = jnp.asarray(rng.normal(size=(3, topo.num_joints, 3)), jnp.float32)

    def loss(cr, t):
        return jnp.sum(w * crowd.crowd_positions(cr, t))

    t0 = 0.6
    gc, gt = jax.jit(jax.grad(loss, argnums=(0, 1)))(c, jnp.float32(t0))
    assert np.isfinite(gt)
    for leaf in jax.tree.leaves(gc):
        assert np.all(np.isfinite(leaf))
    # Central differences of the (already compiled) forward pass, float32: coarse tolerances.
    h = 1e-3
    fd_t = (float(loss(c, t0 + h)) - float(loss(c, t0 - h))) / (2 * h)
    np.testing.assert_allclose(float(gt), fd_t, rtol=2e-2, atol=0.5)
    assert abs(float(gt)) > 1.0
    k, b, d = c.num_harmonics + 1, 1, 0.5  # a cosine coefficient of the first kept row

    def shifted(delta):
        coef = c.coefficients.at[k, 0, b].add(delta)
        return float(loss(crowd.Crowd(coef, c.omega, c.bone_offsets, c.topology, c.channel_index), t0))

    fd_c = (shifted(d) - shifted(-d)) / (2 * d)
    np.testing.assert_allclose(float(gc.coefficients[k, 0, b]), fd_c, rtol=2e-2, atol=0.05)
    # Batching over times: vmap equals a loop.
    ts = jnp.asarray([0.1, 0.5, 2.0], jnp.float32)
    batched = jax.vmap(lambda t: crowd.crowd_positions(c, t))(ts)
    np.testing.assert_allclose(batched, jnp.stack([crowd.crowd_positions(c, t) for t in ts]), atol=1e-4)


def test_bad_input_raises_user_error_naming_the_argument():
    rng = np.random.default_rng(1)
    topo = random_topology(rng, num_joints=5)
    skel = Skeleton(topo, np.zeros((topo.num_joints, 3)))
    models = _models(rng, np.zeros(topo.num_channels), num_chars=2)
    wrong = _models(rng, np.zeros(topo.num_channels + 1), num_chars=2)
    with pytest.raises(UserError, match="`models`.*channels"):
        crowd.make_crowd(skel, wrong)
    one = jax.tree.map(lambda x: x[0], models)
    with pytest.raises(UserError, match="`models`.*leading character axis"):
        crowd.make_crowd(skel, one)
    batched = Skeleton(topo, np.zeros((2, topo.num_joints, 3)))
    with pytest.raises(UserError, match="`skeleton`"):
        crowd.make_crowd(batched, models)
    named = FourierModel(models.offset, models.amplitude, models.phase, models.omega,
                         channel_names=tuple(f"c{i}" for i in range(topo.num_channels)))
    with pytest.raises(UserError, match="channel_names"):
        crowd.make_crowd(skel, named)
    c = crowd.make_crowd(skel, models)
    with pytest.raises(UserError, match="`t`"):
        crowd.crowd_positions(c, jnp.zeros(3))
    assert isinstance(UserError("x"), ValueError)


def test_foot_lock_in_the_crowd_equals_lock_crowd_by_hand():
    from fourierjax import gait
    from fourierjax.body import infer_body_map

    m = data.load("07_01")
    skel, bm = m.skeleton(), infer_body_map(m)
    rng = np.random.default_rng(0)
    models = _models(rng, m.channels.mean(0), num_chars=5)  # the shapes of the first test: no new FK
    c = crowd.make_crowd(skel, models)
    start = rng.uniform(0, 2 * np.pi, (5, 2))
    iv = jnp.asarray(np.stack([start, start + 3.8], -1), jnp.float32)
    floor = jnp.full((5,), float(np.asarray(crowd.crowd_positions(c, 0.0))[:, :, 1].min()))
    s_crowd = s_hand = None
    moved = 0.0
    for k in range(4):
        t = jnp.float32(0.05 * k)
        ours, s_crowd = crowd.crowd_positions(c, t, True, body_map=bm, intervals=iv, state=s_crowd, floor=floor)
        plain = crowd.crowd_positions(c, t)
        hand, s_hand = gait.lock_crowd(plain, models.omega * t, iv, s_hand, body_map=bm,
                                       parents=skel.topology.parents, floor=floor)
        # The same maths in two XLA programs (fused into the crowd's, or alone): equal to float32
        # rounding. Bit-equal until the knee's pole (`_legik.knee_pole`) added a projection;
        # since then 2 of 465 coordinates differ by 1 ulp (4.8e-7 at 4.28).
        np.testing.assert_allclose(np.asarray(ours), np.asarray(hand), rtol=1e-6, atol=1e-6)
        for a, b in zip(jax.tree.leaves(s_crowd), jax.tree.leaves(s_hand)):
            np.testing.assert_allclose(np.asarray(a), np.asarray(b), rtol=1e-6, atol=1e-6)
        moved = max(moved, float(jnp.abs(ours - plain).max()))
    assert moved > 1e-3  # the lock changed the feet (the test can fail)
    with pytest.raises(UserError, match="intervals"):
        crowd.crowd_positions(c, 0.0, True, body_map=bm)
    # Shapes that do not fit are refused, naming the argument (before anything is traced).
    for kw, name in ((dict(intervals=iv[:3]), "`intervals`"), (dict(floor=floor[:2]), "`floor`"),
                     (dict(state=(s_crowd[0][..., :2], s_crowd[1])), "`state`"),
                     (dict(clearance=jnp.zeros((3, 2))), "`clearance`")):
        args = {"body_map": bm, "intervals": iv, "floor": floor, **kw}
        with pytest.raises(UserError, match=name):
            crowd.crowd_positions(c, 0.1, True, **args)
    # One program a frame: a new time or state does not retrace.
    before = crowd._positions_locked_jit.num_traces()
    crowd.crowd_positions(c, 0.3, True, body_map=bm, intervals=iv, state=s_crowd, floor=floor)
    assert crowd._positions_locked_jit.num_traces() == before


@pytest.mark.parametrize("P", [2, 3])
def test_the_crowds_hold_step_is_footlocks_with_characters_last(P):
    # `footlock.hold_step` in the crowd's layout (characters as the minor axis) gives the same
    # numbers as in the per-character layout and as a plain NumPy hold on random holds (planted,
    # landing and released points), to float32 round-off (XLA fuses the programs differently).
    from fourierjax._gait.footlock import hold_step

    rng = np.random.default_rng(7)
    B = 64
    f = np.float32
    targets = rng.normal(size=(B, 2, P, 3)).astype(f)
    planted = (rng.uniform(size=(B, 2, P)) < 0.5).astype(f)
    points = rng.normal(size=(B, 2, P, 3)).astype(f)
    weights = np.where(rng.uniform(size=(B, 2, P)) < 0.3, 0.0, rng.uniform(size=(B, 2, P))).astype(f)
    horizontal = jnp.asarray([1.0, 0.0, 1.0], jnp.float32)
    (t_ref, p_ref), s_ref = jax.jit(hold_step)((targets, planted), points, weights, horizontal)
    def last(x):  # characters as the last axis
        return np.moveaxis(x, 0, -1)

    (t_row, p_row), s_row = jax.jit(hold_step, static_argnames="characters_last")(
        (last(targets), last(planted)), last(points), last(weights), horizontal, characters_last=True)
    tol = 4e-7
    np.testing.assert_allclose(np.moveaxis(np.asarray(t_row), -1, 0), t_ref, rtol=tol, atol=tol)
    np.testing.assert_array_equal(np.moveaxis(np.asarray(p_row), -1, 0), p_ref)
    np.testing.assert_allclose(np.moveaxis(np.asarray(s_row), -1, 0), s_ref, rtol=tol, atol=tol)
    # NumPy, in float64.
    held = weights.astype(np.float64) * planted
    err = (targets - points) * np.asarray(horizontal, np.float64)
    mean = (held[..., None] * err).sum(-2) / np.maximum(held.sum(-1, keepdims=True), 1e-9)
    shift = mean * held.max(-1, keepdims=True)
    landed = (weights > 0) & (planted <= 0)
    t_np = np.where(landed[..., None], points + shift[..., None, :], targets)
    np.testing.assert_allclose(s_ref, shift, rtol=2e-6, atol=2e-6)
    np.testing.assert_allclose(t_ref, t_np, rtol=2e-6, atol=2e-6)
    np.testing.assert_array_equal(p_ref, (weights > 0).astype(f))
    assert 0 < float(np.asarray(p_ref).mean()) < 1 and float(np.abs(np.asarray(s_ref)).max()) > 0.1
