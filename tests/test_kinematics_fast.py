"""The batched FK path (frame-minor layout, joint scan, fused sincos) against the one-frame FK."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from fourierjax import kinematics
from fourierjax._sincos import half_angle_sincos_degrees, sincos_degrees
from fourierjax._sincos import sincos as _sincos
from fourierjax.skeleton import Skeleton
from tests.helpers import random_topology


def test_sincos_float32_matches_float64_reference():
    x = np.concatenate([np.linspace(-1e4, 1e4, 200_001), np.linspace(-7, 7, 100_001),
                        np.arange(-64, 65) * np.pi / 4, [0.0, -0.0, 1e-30]]).astype(np.float32)
    s, c = jax.jit(_sincos)(jnp.asarray(x))
    ref = x.astype(np.float64)
    assert np.abs(np.asarray(s, np.float64) - np.sin(ref)).max() < 2e-7
    assert np.abs(np.asarray(c, np.float64) - np.cos(ref)).max() < 2e-7
    # Gradients are the other function (to float32 rounding).
    ds = jax.vmap(jax.grad(lambda v: _sincos(v)[0]))(jnp.asarray(x[:1000]))
    np.testing.assert_allclose(ds, np.cos(ref[:1000]), atol=2e-6)


def test_sincos_degrees_float32_matches_float64_reference():
    x = np.concatenate([np.linspace(-3600, 3600, 200_001), np.arange(-40, 41) * 45.0,
                        [0.0, -0.0, 1e-30]]).astype(np.float32)
    s, c = jax.jit(sincos_degrees)(jnp.asarray(x))
    ref = np.deg2rad(x.astype(np.float64))
    assert np.abs(np.asarray(s, np.float64) - np.sin(ref)).max() < 2e-7
    assert np.abs(np.asarray(c, np.float64) - np.cos(ref)).max() < 2e-7
    assert float(s[np.flatnonzero(x == 90.0)[0]]) == 1.0  # exact reduction: no rounding at 90


def test_half_angle_sincos_degrees_is_the_half_angle_up_to_one_sign():
    x = np.concatenate([np.linspace(-7200, 7200, 200_001), np.arange(-40, 41) * 90.0,
                        [0.0, -0.0, 1e-30]]).astype(np.float32)
    s, c = (np.asarray(v, np.float64) for v in jax.jit(half_angle_sincos_degrees)(jnp.asarray(x)))
    ref = np.deg2rad(0.5 * x.astype(np.float64))
    sign = np.where(s * np.sin(ref) + c * np.cos(ref) < 0, -1.0, 1.0)  # one sign for both
    assert np.abs(s - sign * np.sin(ref)).max() < 2e-7
    assert np.abs(c - sign * np.cos(ref)).max() < 2e-7
    np.testing.assert_allclose(s * s + c * c, 1.0, atol=5e-7)
    # Gradients: d/dx of (s, c) is (c, -s) / 2 in radians, with the same sign.
    xs = jnp.asarray(x[::997])
    ds = jax.vmap(jax.grad(lambda v: half_angle_sincos_degrees(v)[0]))(xs)
    np.testing.assert_allclose(ds, c[::997] * np.pi / 360, atol=1e-7)
    # Other dtypes: the signed functions themselves.
    x64 = jnp.asarray(x[:1000], jnp.float64) if jax.config.jax_enable_x64 else None
    if x64 is not None:
        s64, c64 = half_angle_sincos_degrees(x64)
        np.testing.assert_allclose(s64, np.sin(ref[:1000]), atol=1e-12)
        np.testing.assert_allclose(c64, np.cos(ref[:1000]), atol=1e-12)


@pytest.mark.parametrize("seed", range(3))
def test_fk_frames_equals_vmapped_one_frame_fk(seed):
    rng = np.random.default_rng(seed)
    topo = random_topology(rng)
    skel = Skeleton(topo, rng.normal(size=(topo.num_joints, 3)) * 10,
                    rng.normal(size=(topo.num_end_sites, 3)) * 5)
    ch = jnp.asarray(rng.uniform(-720, 720, size=(2, 5, topo.num_channels)), jnp.float32)
    fast = kinematics.fk_frames(skel, ch)
    ref = jax.vmap(jax.vmap(lambda c: kinematics.fk_from_channels(skel, c)))(ch)
    assert fast.positions.shape == (2, 5, topo.num_joints, 3)
    for a, b in zip(jax.tree.leaves(fast), jax.tree.leaves(ref)):
        np.testing.assert_allclose(a, b, atol=5e-4, rtol=1e-5)
    np.testing.assert_allclose(kinematics.joint_positions(skel, ch), ref.positions, atol=5e-4, rtol=1e-5)
    g = jax.grad(lambda c: kinematics.fk_frames(skel, c).positions.sum())(ch)
    assert np.all(np.isfinite(g))


def test_fk_frames_rejects_wrong_channel_count():
    rng = np.random.default_rng(0)
    topo = random_topology(rng)
    skel = Skeleton(topo, np.zeros((topo.num_joints, 3)))
    with pytest.raises(ValueError, match="channels"):
        kinematics.fk_frames(skel, jnp.zeros((3, topo.num_channels + 1)))


def test_chunk_size_follows_the_backend():
    # The CPU keeps its cache-sized chunks; an accelerator takes chunks large enough that its
    # kernels are not launch-bound (2048-frame chunks held an H200 at 0.73 G joint transforms/s).
    assert kinematics._chunk_frames(31, "cpu") == kinematics._FK_CHUNK
    assert kinematics._chunk_frames(31, "gpu") >= 1 << 20
    assert kinematics._chunk_frames(10**9, "gpu") == kinematics._FK_CHUNK  # never below the CPU's


def test_fk_frames_chunked_path_matches_at_any_chunk_size(monkeypatch):
    # The chunked loop with a chunk size that is neither the CPU's nor a power of two (as an
    # accelerator's can be), over more than two chunks and not a multiple of one.
    monkeypatch.setattr(kinematics, "_chunk_frames", lambda num_joints, backend=None: 3001)
    rng = np.random.default_rng(11)
    topo = random_topology(rng)
    skel = Skeleton(topo, rng.normal(size=(topo.num_joints, 3)), rng.normal(size=(topo.num_end_sites, 3)))
    m = 2 * 3001 + 77
    ch = jnp.asarray(rng.uniform(-180, 180, size=(m, topo.num_channels)), jnp.float32)
    fast = kinematics.fk_frames(skel, ch[None])
    sel = np.array([0, 3000, 3001, 6001, m - 78, m - 1])
    ref = jax.vmap(lambda c: kinematics.fk_from_channels(skel, c))(ch[sel])
    for a, b in zip(jax.tree.leaves(fast), jax.tree.leaves(ref)):
        np.testing.assert_allclose(np.asarray(a)[0, sel], b, atol=5e-4, rtol=1e-5)


def test_fk_frames_chunked_path_matches():
    # More than two chunks of frames (and not a multiple of the chunk): the lax.map path.
    rng = np.random.default_rng(7)
    topo = random_topology(rng)
    skel = Skeleton(topo, rng.normal(size=(topo.num_joints, 3)), rng.normal(size=(topo.num_end_sites, 3)))
    m = 2 * kinematics._FK_CHUNK + 123
    ch = jnp.asarray(rng.uniform(-180, 180, size=(m, topo.num_channels)), jnp.float32)
    fast = kinematics.fk_frames(skel, ch.reshape(1, m, -1))
    sel = np.array([0, 1, kinematics._FK_CHUNK, m - 1])
    ref = jax.vmap(lambda c: kinematics.fk_from_channels(skel, c))(ch[sel])
    for a, b in zip(jax.tree.leaves(fast), jax.tree.leaves(ref)):
        np.testing.assert_allclose(np.asarray(a)[0, sel], b, atol=5e-4, rtol=1e-5)


@pytest.mark.parametrize("seed", range(3))
def test_joint_positions_frames_last_is_joint_positions_transposed(seed):
    rng = np.random.default_rng(100 + seed)
    topo = random_topology(rng)
    skel = Skeleton(topo, rng.normal(size=(topo.num_joints, 3)), rng.normal(size=(topo.num_end_sites, 3)))
    ch = rng.uniform(-180, 180, size=(37, topo.num_channels)).astype(np.float32)
    ref = np.asarray(kinematics.joint_positions(skel, jnp.asarray(ch)))
    for x in (jnp.asarray(ch.T), ch.T.copy()):  # a jax array, and NumPy (padded on the host)
        got = kinematics.joint_positions_frames_last(skel, x)
        assert got.shape == (topo.num_joints, 3, 37)
        np.testing.assert_allclose(np.moveaxis(np.asarray(got), -1, 0), ref, atol=1e-5, rtol=1e-6)
    # Traced (no host padding) and differentiable.
    traced = jax.jit(kinematics.joint_positions_frames_last)(skel, jnp.asarray(ch.T))
    np.testing.assert_allclose(np.moveaxis(np.asarray(traced), -1, 0), ref, atol=1e-5, rtol=1e-6)
    g = jax.grad(lambda c: kinematics.joint_positions_frames_last(skel, c).sum())(jnp.asarray(ch.T))
    assert np.isfinite(np.asarray(g)).all()


def test_joint_positions_frames_last_chunked_path_matches(monkeypatch):
    # More than two chunks, not a multiple of one: the loop with its clamped last chunk.
    monkeypatch.setattr(kinematics, "_FRAMES_LAST_CHUNK", 1000)
    rng = np.random.default_rng(12)
    topo = random_topology(rng)
    skel = Skeleton(topo, rng.normal(size=(topo.num_joints, 3)))
    m = 2 * 1000 + 77 + kinematics.PAD_LIMIT  # above PAD_LIMIT: no bucket, its own shape
    ch = rng.uniform(-180, 180, size=(m, topo.num_channels)).astype(np.float32)
    got = np.asarray(kinematics.joint_positions_frames_last(skel, jnp.asarray(ch.T)))
    sel = np.array([0, 999, 1000, 2000, m - 1001, m - 1])
    ref = np.asarray(kinematics.joint_positions(skel, jnp.asarray(ch[sel])))
    np.testing.assert_allclose(np.moveaxis(got[..., sel], -1, 0), ref, atol=5e-4, rtol=1e-5)


def test_joint_positions_frames_last_rejects_bad_shapes():
    rng = np.random.default_rng(0)
    topo = random_topology(rng)
    skel = Skeleton(topo, np.zeros((topo.num_joints, 3)))
    c = topo.num_channels
    for bad in (np.zeros((c + 1, 4)), np.zeros((c,)), np.zeros((1, c, 5))):
        with pytest.raises(ValueError, match="joint_positions_frames_last: `channels`"):
            kinematics.joint_positions_frames_last(skel, bad)
    batched = Skeleton(topo, np.zeros((2, topo.num_joints, 3)))
    with pytest.raises(ValueError, match="offsets"):
        kinematics.joint_positions_frames_last(batched, np.zeros((topo.num_channels, 4)))
