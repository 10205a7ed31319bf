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


@pytest.mark.parametrize("seed", range(3))
def test_mixed_rotation_orders_match_scipy_fk(seed):
    # Random trees: all 6 Tait-Bryan orders, 1-2 rotation channels, rotation-free joints and
    # position channels on inner joints, in any channel order.
    rng = np.random.default_rng(seed)
    topo = random_topology(rng)
    skel = Skeleton(topo, rng.normal(size=(topo.num_joints, 3)) * 10, rng.normal(size=(topo.num_end_sites, 3)))
    models = _models(rng, rng.uniform(-90, 90, size=topo.num_channels), num_chars=4, num_harmonics=2)
    c = crowd.make_crowd(skel, models)
    t = 0.8
    ours = np.asarray(crowd.crowd_positions(c, t))
    ref, channels = _reference(skel, models, t)
    np.testing.assert_allclose(ours, ref, atol=5e-4, rtol=1e-5)
    oracle, _ = reference_fk(topo, np.asarray(skel.offsets), np.asarray(skel.end_site_offsets),
                             np.asarray(channels, np.float64))
    np.testing.assert_allclose(ours, oracle, atol=5e-4, rtol=1e-5)


def test_gradients_wrt_time_and_coefficients_are_finite_and_match_reference():
    rng = np.random.default_rng(3)
    topo = random_topology(rng, num_joints=8)
    skel = Skeleton(topo, rng.normal(size=(topo.num_joints, 3)) * 10)
    models = _models(rng, rng.uniform(-60, 60, size=topo.num_channels), num_chars=3, num_harmonics=2)
    c = crowd.make_crowd(skel, models)
    w = jnp.asarray(rng.normal(size=(3, topo.num_joints, 3)), jnp.float32)

    def ours(t):
        return jnp.sum(w * crowd.crowd_positions(c, t))

    def ref(t):
        return jnp.sum(w * _reference(skel, models, t)[0])

    g = jax.grad(ours)(jnp.float32(0.6))
    g_ref = jax.grad(ref)(jnp.float32(0.6))
    assert np.isfinite(g)
    np.testing.assert_allclose(g, g_ref, rtol=2e-3, atol=1e-2)
    gc = jax.grad(lambda cr: jnp.sum(w * crowd.crowd_positions(cr, 0.6)))(c)
    for leaf in jax.tree.leaves(gc):
        assert np.all(np.isfinite(leaf))
    assert float(jnp.abs(gc.coefficients).max()) > 0.0
    # Gradient wrt the offsets row of one coefficient vs a central difference (float32, coarse).
    k = c.channel_index.index(next(i for i in c.channel_index))
    h = 1e-2

    def at(delta):
        return ours_with(c, k, delta)

    def ours_with(cr, row, delta):
        coef = cr.coefficients.at[0, row, 0].add(delta)
        return float(jnp.sum(w * crowd.crowd_positions(
            crowd.Crowd(coef, cr.omega, cr.bone_offsets, cr.topology, cr.channel_index), 0.6)))

    fd = (at(h) - at(-h)) / (2 * h)
    np.testing.assert_allclose(float(gc.coefficients[0, k, 0]), fd, rtol=2e-2, atol=2e-2)


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
