"""Forward kinematics against an independent scipy reference, on random skeletons and real CMU data."""

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

from fourierjax import anthropometry, kinematics
from fourierjax.errors import UserError
from fourierjax.skeleton import Skeleton, Topology
from tests.helpers import random_topology, reference_fk


def _random_case(seed, num_frames=7):
    rng = np.random.default_rng(seed)
    topo = random_topology(rng)
    offsets = rng.normal(size=(topo.num_joints, 3)) * 10
    ends = rng.normal(size=(topo.num_end_sites, 3)) * 5
    channels = rng.uniform(-180, 180, size=(num_frames, topo.num_channels))
    return topo, offsets, ends, channels


@pytest.mark.parametrize("seed", range(6))
def test_fk_matches_reference_on_random_skeletons(seed, x64):
    topo, offsets, ends, channels = _random_case(seed)
    skel = Skeleton(topo, offsets, ends)
    res = kinematics.fk_frames(skel, jnp.asarray(channels))
    ref_p, ref_e = reference_fk(topo, offsets, ends, channels)
    np.testing.assert_allclose(res.positions, ref_p, atol=1e-9)
    np.testing.assert_allclose(res.end_site_positions, ref_e, atol=1e-9)


def test_position_channels_replace_offsets():
    # A file whose position channels repeat the offsets (Bandai-Namco style): bones keep their length.
    topo = Topology(
        names=("root", "a", "b"),
        parents=(-1, 0, 1),
        channels=(("Xposition", "Yposition", "Zposition", "Zrotation", "Xrotation", "Yrotation"),) * 3,
    )
    offsets = np.array([[0.0, 0, 0], [0, 10, 0], [0, 0, 5]])
    frame = np.concatenate([[1.0, 2, 3, 0, 0, 0], [0, 10, 0, 0, 0, 0], [0, 0, 5, 0, 0, 0]])
    pos = kinematics.joint_positions(Skeleton(topo, offsets), jnp.asarray(frame[None]))[0]
    np.testing.assert_allclose(pos, [[1, 2, 3], [1, 12, 3], [1, 12, 8]], atol=1e-5)


def test_fk_under_jit_vmap_vmap():
    # Characters x frames: the nested vmap that batched fitting does (XLA CPU trap, STYLE.md).
    topo, offsets, ends, channels = _random_case(11, num_frames=5)
    rng = np.random.default_rng(0)
    offsets_b = offsets[None] * rng.uniform(0.8, 1.2, size=(4, 1, 1))
    chans_b = np.stack([channels + k for k in range(4)])

    def one(off, ch):
        return kinematics.fk_from_channels(Skeleton(topo, off, ends), ch).positions

    out = jax.jit(jax.vmap(jax.vmap(one, in_axes=(None, 0))))(jnp.asarray(offsets_b), jnp.asarray(chans_b))
    assert out.shape == (4, 5, topo.num_joints, 3)
    for c in range(4):
        ref, _ = reference_fk(topo, offsets_b[c], ends, chans_b[c])
        np.testing.assert_allclose(out[c], ref, atol=2e-3, rtol=1e-4)


def test_fk_gradients_match_finite_differences(x64):
    topo, offsets, ends, channels = _random_case(3, num_frames=1)
    w = jnp.asarray(np.random.default_rng(1).normal(size=(topo.num_joints, 3)))

    def loss(off, ch):
        return (w * kinematics.fk_from_channels(Skeleton(topo, off, ends), ch).positions).sum()

    off, ch = jnp.asarray(offsets), jnp.asarray(channels[0])
    g_off, g_ch = jax.jit(jax.grad(loss, argnums=(0, 1)))(off, ch)
    loss = jax.jit(loss)
    eps = 1e-6
    for _ in range(10):
        d_off = jnp.asarray(np.random.default_rng(_).normal(size=off.shape))
        d_ch = jnp.asarray(np.random.default_rng(100 + _).normal(size=ch.shape))
        fd = (loss(off + eps * d_off, ch + eps * d_ch) - loss(off - eps * d_off, ch - eps * d_ch)) / (2 * eps)
        np.testing.assert_allclose((g_off * d_off).sum() + (g_ch * d_ch).sum(), fd, rtol=1e-6, atol=1e-6)


def test_fk_gradient_finite_at_zero_pose():
    topo, offsets, ends, _ = _random_case(4, num_frames=1)
    skel = Skeleton(topo, offsets, ends)
    g = jax.jit(jax.grad(lambda c: kinematics.fk_from_channels(skel, c).positions.sum()))(
        jnp.zeros(topo.num_channels)
    )
    assert np.all(np.isfinite(g))


def test_joint_positions_does_not_retrace():
    topo, offsets, ends, channels = _random_case(5, num_frames=3)
    f = eqx.debug.assert_max_traces(
        lambda s, c: jax.vmap(lambda x: kinematics.fk_from_channels(s, x).positions)(c), max_traces=1
    )
    f = jax.jit(f)
    skel = Skeleton(topo, offsets, ends)
    for k in range(3):
        f(skel, jnp.asarray(channels + k))


def test_shape_errors_name_the_argument():
    topo, offsets, ends, channels = _random_case(6, num_frames=1)
    skel = Skeleton(topo, offsets, ends)
    with pytest.raises(UserError, match="channels"):
        kinematics.pose_from_channels(skel, jnp.zeros(topo.num_channels + 1))
    with pytest.raises(UserError, match="offsets"):
        Skeleton(topo, offsets[:-1], ends)


# -- real CMU data -------------------------------------------------------------------------


@pytest.mark.parametrize("name", ["02_01", "02_03", "07_01", "07_04", "07_12", "09_01", "09_02",
                                  "142_02", "142_08"])
def test_fk_matches_reference_on_bundled_clips(name):
    from fourierjax import data

    motion = data.load(name, raw=True)
    pos = np.asarray(kinematics.joint_positions(motion.skeleton(), jnp.asarray(motion.channels, jnp.float32)))
    ref, _ = reference_fk(motion.topology, motion.offsets, motion.end_site_offsets, motion.channels)
    err = np.abs(pos - ref).max()
    assert err <= 1e-4, f"{name}: max FK error {err:.3g} units (float32)"


def test_center_of_mass_on_cmu_tpose():
    from fourierjax import data

    motion = data.load("07_01", raw=True)
    skel = motion.skeleton()
    res = kinematics.fk_from_channels(skel, jnp.asarray(motion.channels[0], jnp.float32))
    model = anthropometry.segment_model(motion.topology)
    assert abs(model.total_mass_fraction - 1.0) < 1e-3
    com = np.asarray(anthropometry.center_of_mass(model, res.positions, res.end_site_positions))
    # Independent numpy evaluation of the same definition.
    pts = np.concatenate([np.asarray(res.positions), np.asarray(res.end_site_positions)])
    cen = pts[list(model.proximal)] + np.array(model.com_fraction)[:, None] * (
        pts[list(model.distal)] - pts[list(model.proximal)]
    )
    np.testing.assert_allclose(com, (np.array(model.mass_fraction)[:, None] * cen).sum(0), atol=1e-4)
    # Physically: in the T-pose the COM sits a few cm above the hip joint centres (near S2),
    # below the lumbar "Spine" joint, in the body's mid-plane.
    y = {n: float(res.positions[motion.topology.index(n), 1]) for n in ("LeftUpLeg", "Spine", "Hips")}
    assert y["LeftUpLeg"] < com[1] < y["Spine"], (com, y)
    hips = np.asarray(res.positions[motion.topology.index("Hips")])
    assert abs(com[0] - hips[0]) < 0.1


def test_joint_positions_entry_point_traces_once_per_shape():
    topo, offsets, ends, channels = _random_case(5, num_frames=3)
    skel = Skeleton(topo, offsets, ends)
    kinematics.joint_positions(skel, jnp.asarray(channels))
    before = kinematics.joint_positions.num_traces()
    for k in range(3):  # new values, same shapes: no new trace
        kinematics.joint_positions(Skeleton(topo, offsets + k, ends), jnp.asarray(channels + k))
    assert kinematics.joint_positions.num_traces() == before
