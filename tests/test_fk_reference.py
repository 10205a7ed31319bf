"""The one FK (`fourierjax._fk`) against an independent slow NumPy reference, per joint, with matrices."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from fourierjax import _fk, crowd, data, fourier, kinematics
from fourierjax.fourier import FourierModel
from fourierjax.skeleton import Skeleton, Topology


def _axis_matrix(axis: str, degrees: np.ndarray) -> np.ndarray:
    """`[F, 3, 3]` right-handed rotations about `axis` by `degrees` (float64)."""
    a = np.deg2rad(np.asarray(degrees, np.float64))
    c, s = np.cos(a), np.sin(a)
    one, zero = np.ones_like(a), np.zeros_like(a)
    rows = {
        "X": [[one, zero, zero], [zero, c, -s], [zero, s, c]],
        "Y": [[c, zero, s], [zero, one, zero], [-s, zero, c]],
        "Z": [[c, -s, zero], [s, c, zero], [zero, zero, one]],
    }[axis]
    return np.stack([np.stack(r, axis=-1) for r in rows], axis=-2)


def numpy_fk(topology, offsets, end_site_offsets, channels):
    """Positions `[F, J, 3]` and End Sites `[F, E, 3]`: one joint at a time, 3x3 matrices, float64.

    Written from the BVH definition alone (no fourierjax code): each joint's channels in file
    order; a position channel replaces that OFFSET component, rotation channels (degrees) are
    multiplied on the right in the listed order; world = parent world @ local.
    """
    channels = np.asarray(channels, np.float64)
    frames = channels.shape[0]
    rot = [None] * topology.num_joints
    pos = np.zeros((frames, topology.num_joints, 3))
    col = 0
    for j in range(topology.num_joints):
        t = np.tile(np.asarray(offsets[j], np.float64), (frames, 1))
        r = np.broadcast_to(np.eye(3), (frames, 3, 3))
        for name in topology.channels[j]:
            if name.endswith("position"):
                t[:, "XYZ".index(name[0])] = channels[:, col]
            else:
                r = r @ _axis_matrix(name[0], channels[:, col])
            col += 1
        p = topology.parents[j]
        if p < 0:
            rot[j], pos[:, j] = r, t
        else:
            rot[j] = rot[p] @ r
            pos[:, j] = pos[:, p] + (rot[p] @ t[..., None])[..., 0]
    ends = np.zeros((frames, topology.num_end_sites, 3))
    for e, p in enumerate(topology.end_site_parents):
        ends[:, e] = pos[:, p] + (rot[p] @ np.asarray(end_site_offsets[e], np.float64))
    return pos, ends


@st.composite
def topologies(draw, max_joints=9):
    """Random trees: any parent order, 0-3 rotation channels in any order, position channels
    on any joint (before, after or between the rotations), End Sites on any joint."""
    n = draw(st.integers(1, max_joints))
    parents = [-1] + [draw(st.integers(0, i - 1)) for i in range(1, n)]
    channels = []
    for _ in range(n):
        rot = draw(st.permutations(["Xrotation", "Yrotation", "Zrotation"]))[: draw(st.integers(0, 3))]
        pos = draw(st.permutations(["Xposition", "Yposition", "Zposition"]))[: draw(st.integers(0, 3))]
        chans = list(rot) + list(pos)
        channels.append(tuple(draw(st.permutations(chans))))
    ends = draw(st.lists(st.integers(0, n - 1), max_size=3))
    return Topology(names=tuple(f"j{i}" for i in range(n)), parents=tuple(parents),
                    channels=tuple(channels), end_site_parents=tuple(ends))


def _pose_atol(ref):
    """Absolute tolerance for float32 FK against the float64 reference.

    Round-off in a chain of compositions grows with the size of the whole pose, not with each
    coordinate: a joint near the origin of a pose that reaches 173 units inherits the error of its
    ancestors' large translations (hypothesis drew one: -6.69873 against -6.69861). float32's
    epsilon is 1.2e-7; 2e-6 of the pose's largest coordinate allows about 16 ulp of it, and the
    1e-4 floor covers small poses.
    """
    return max(1e-4, 2e-6 * float(np.abs(np.asarray(ref)).max()))


@settings(max_examples=12, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(topo=topologies(), seed=st.integers(0, 2**31 - 1))
def test_every_entry_point_matches_numpy_reference_on_random_topologies(topo, seed):
    rng = np.random.default_rng(seed)
    skel = Skeleton(topo, rng.uniform(-1, 1, size=(topo.num_joints, 3)),
                    rng.uniform(-1, 1, size=(topo.num_end_sites, 3)))
    ch = rng.uniform(-180, 180, size=(4, topo.num_channels)).astype(np.float32)
    ref_p, ref_e = numpy_fk(topo, np.asarray(skel.offsets), np.asarray(skel.end_site_offsets), ch)
    x = jnp.asarray(ch)
    frames = kinematics.fk_frames(skel, x)
    one = jax.vmap(lambda c: kinematics.fk_from_channels(skel, c))(x)
    local = jax.vmap(lambda c: kinematics.forward_kinematics(skel, *kinematics.pose_from_channels(skel, c)))(x)
    atol = _pose_atol(np.concatenate([ref_p.reshape(-1), ref_e.reshape(-1)]))
    for res in (frames, one, local):
        np.testing.assert_allclose(res.positions, ref_p, atol=atol, rtol=2e-6)
        np.testing.assert_allclose(res.end_site_positions, ref_e, atol=atol, rtol=2e-6)
        # Rotations are unit quaternions equal (up to sign) across the entry points.
        np.testing.assert_allclose(np.linalg.norm(res.rotations, axis=-1), 1.0, atol=1e-5)
        dots = np.abs((np.asarray(res.rotations) * np.asarray(frames.rotations)).sum(-1))
        np.testing.assert_allclose(dots, 1.0, atol=1e-5)
    # float32: hypothesis once drew a 131.87-unit position, 1.2e-4 (8 ulp) off the float64 reference.
    np.testing.assert_allclose(kinematics.joint_positions(skel, x), ref_p, atol=atol, rtol=2e-6)
    last = kinematics.joint_positions_frames_last(skel, x.T)
    np.testing.assert_allclose(np.moveaxis(np.asarray(last), -1, 0), ref_p, atol=atol, rtol=2e-6)


@pytest.mark.parametrize("name", data.list())
def test_positions_match_numpy_reference_on_every_bundled_clip(name):
    motion = data.load(name, raw=True)
    ch = np.asarray(motion.channels[:200], np.float32)
    skel = motion.skeleton()
    ref_p, ref_e = numpy_fk(motion.topology, motion.offsets, motion.end_site_offsets, ch)
    pos = np.asarray(kinematics.joint_positions(skel, jnp.asarray(ch)))
    res = kinematics.fk_frames(skel, jnp.asarray(ch))
    last = np.moveaxis(np.asarray(kinematics.joint_positions_frames_last(skel, ch.T)), -1, 0)
    for got, ref in ((pos, ref_p), (res.positions, ref_p), (res.end_site_positions, ref_e), (last, ref_p)):
        err = float(np.abs(np.asarray(got) - ref).max())
        assert err <= 1e-4, f"{name}: max FK error {err:.3g} units (float32)"


def test_under_jit_vmap_vmap_matches_numpy_reference():
    # Characters (own offsets) x frames: the nested vmap of batched fitting (XLA CPU trap, STYLE.md),
    # through the one-frame entry point and through the batched one.
    rng = np.random.default_rng(4)
    motion = data.load("07_01", raw=True)
    topo = motion.topology
    scale = rng.uniform(0.01, 0.02, size=(3, 1, 1))  # CMU inches to about metres, per character
    offsets = np.asarray(motion.offsets)[None] * scale
    ch = np.stack([motion.channels[k * 40:k * 40 + 6] for k in range(3)]).astype(np.float32)
    ch[..., :3] *= scale  # the root's position channels come first in CMU files

    def one(off, c):
        return kinematics.fk_from_channels(Skeleton(topo, off, motion.end_site_offsets), c).positions

    nested = jax.jit(jax.vmap(jax.vmap(one, in_axes=(None, 0))))(jnp.asarray(offsets, jnp.float32), jnp.asarray(ch))
    batched = jax.jit(jax.vmap(lambda off, c: kinematics.joint_positions(Skeleton(topo, off), c)))(
        jnp.asarray(offsets, jnp.float32), jnp.asarray(ch))
    # Frames last, vmapped over characters and over a second batch axis of frames.
    last = jax.jit(jax.vmap(jax.vmap(
        lambda off, c: kinematics.joint_positions_frames_last(Skeleton(topo, off), c), in_axes=(None, 0))))(
        jnp.asarray(offsets, jnp.float32), jnp.asarray(np.swapaxes(ch.reshape(3, 2, 3, -1), -1, -2)))
    for k in range(3):
        ref, _ = numpy_fk(topo, offsets[k], np.zeros((topo.num_end_sites, 3)), ch[k])
        np.testing.assert_allclose(nested[k], ref, atol=1e-4)
        np.testing.assert_allclose(batched[k], ref, atol=1e-4)
        np.testing.assert_allclose(np.moveaxis(np.asarray(last[k]), -1, 1).reshape(6, -1, 3), ref, atol=1e-4)


def test_gradients_match_finite_differences(x64):
    rng = np.random.default_rng(8)
    topo = Topology(names=("r", "a", "b", "c"), parents=(-1, 0, 1, 1),
                    channels=(("Xposition", "Yposition", "Zposition", "Zrotation", "Xrotation", "Yrotation"),
                              ("Yrotation", "Xrotation"), ("Zrotation", "Yrotation", "Xrotation"), ("Xrotation",)),
                    end_site_parents=(2, 3))
    off = jnp.asarray(rng.normal(size=(4, 3)))
    ends = jnp.asarray(rng.normal(size=(2, 3)))
    ch = jnp.asarray(rng.uniform(-90, 90, size=(3, topo.num_channels)))
    w = jnp.asarray(rng.normal(size=(3, 4, 3)))
    we = jnp.asarray(rng.normal(size=(3, 2, 3)))

    def loss(o, c):
        res = kinematics.fk_frames(Skeleton(topo, o, ends), c)
        return (w * res.positions).sum() + (we * res.end_site_positions).sum()

    g_off, g_ch = jax.grad(loss, argnums=(0, 1))(off, ch)
    eps = 1e-6
    for k in range(6):
        d_off = jnp.asarray(np.random.default_rng(k).normal(size=off.shape))
        d_ch = jnp.asarray(np.random.default_rng(50 + k).normal(size=ch.shape))
        fd = (loss(off + eps * d_off, ch + eps * d_ch) - loss(off - eps * d_off, ch - eps * d_ch)) / (2 * eps)
        np.testing.assert_allclose((g_off * d_off).sum() + (g_ch * d_ch).sum(), fd, rtol=1e-6, atol=1e-7)


def test_plan_rows_read_each_moving_channel_once():
    # The plan is what makes it one FK for all entry points: each rotation channel of a joint
    # with children and each position channel is read exactly once; leaf rotations only when
    # all rotations are asked for.
    motion = data.load("07_01", raw=True)
    topo = motion.topology
    full = _fk.plan(topo)
    moving = _fk.plan(topo, all_rotations=False)
    assert sorted(full.rows) == list(range(topo.num_channels))
    assert len(set(moving.rows)) == len(moving.rows) == 24 * 3 + 3
    assert set(moving.rows) < set(full.rows)
    assert sorted(full.order) == list(range(topo.num_joints))
    assert [full.order[i] for i in full.inverse] == list(range(topo.num_joints))


def test_crowd_equals_numpy_synthesis_then_numpy_reference():
    rng = np.random.default_rng(2)
    topo = Topology(names=("r", "a", "b", "c", "d"), parents=(-1, 0, 1, 0, 3),
                    channels=(("Xposition", "Yposition", "Zposition", "Zrotation", "Yrotation", "Xrotation"),
                              ("Zrotation", "Xrotation", "Yrotation"), ("Xrotation",), ("Yrotation", "Zrotation"),
                              ("Xrotation", "Yrotation", "Zrotation")),
                    end_site_parents=(2, 4))
    skel = Skeleton(topo, rng.normal(size=(5, 3)), rng.normal(size=(2, 3)))
    num_chars, c, n = 6, topo.num_channels, 2
    off = rng.uniform(-60, 60, size=(num_chars, c))
    amp = rng.uniform(1, 30, size=(num_chars, c, n))
    ph = rng.uniform(-np.pi, np.pi, size=amp.shape)
    om = rng.uniform(4, 8, size=num_chars)
    f = np.float32
    models = FourierModel(jnp.asarray(off, f), jnp.asarray(amp, f), jnp.asarray(ph, f), jnp.asarray(om, f))
    cr = crowd.make_crowd(skel, models)
    t = 0.7
    channels = off + (amp * np.sin(np.arange(1, n + 1) * (om * t)[:, None, None] + ph)).sum(-1)
    ref, _ = numpy_fk(topo, np.asarray(skel.offsets), np.asarray(skel.end_site_offsets), channels)
    np.testing.assert_allclose(crowd.crowd_positions(cr, t), ref, atol=1e-3)
    # The same positions as the batched FK of the synthesized channels (one FK, not three).
    synth = jax.vmap(lambda m: fourier.synthesize(m, jnp.asarray([t], jnp.float32))[0])(models)
    np.testing.assert_allclose(crowd.crowd_positions(cr, t), kinematics.joint_positions(skel, synth), atol=2e-4)
