"""Euler continuity through the rotation (issue 20 item 5): twins, gimbal lock, winding."""

import pathlib

import jax
import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from fourierjax import _jit, rotations
from fourierjax.errors import UserError
from fourierjax.features import make_euler_continuous as per_angle_unwrap

BANDAI = pathlib.Path(__file__).resolve().parents[1] / ".." / "shared" / "data" / "mocap" / "bandai1" / "data"
needs_bandai = pytest.mark.skipif(not BANDAI.is_dir(), reason=f"Bandai-Namco data not found at {BANDAI}")


def _same_rotations(a, b, order, atol=1e-7):
    np.testing.assert_allclose(Rotation.from_euler(order, a).as_matrix(),
                               Rotation.from_euler(order, b).as_matrix(), atol=atol)


def test_twin_flips_are_repaired(x64):
    # A smooth path through pitch = 90 degrees: scipy's ZYX angles switch triples there.
    t = np.linspace(0, 1, 200)
    rot = Rotation.from_euler("ZYX", np.stack([0.3 * t, -0.3 + 2.2 * t, 0.5 - 0.4 * t], 1))
    raw = rot.as_euler("ZYX")
    assert np.max(np.abs(np.diff(raw, axis=0))) > 1.0
    out = np.asarray(rotations.make_euler_continuous(raw, "ZYX"))
    assert np.max(np.abs(np.diff(out, axis=0))) < 0.05
    _same_rotations(out, raw, "ZYX", 1e-9)
    np.testing.assert_allclose(out[0], raw[0], atol=1e-12)  # the first frame is kept
    # The same as the per-angle unwrap wherever the triple is unique.
    np.testing.assert_allclose(out, per_angle_unwrap(raw, "ZYX"), atol=1e-9)
    # Under jit, and for a proper Euler order with its own twin (a + pi, -b, c + pi).
    jitted = _jit.filter_jit(rotations.make_euler_continuous)
    np.testing.assert_allclose(np.asarray(jitted(raw, "ZYX")), out, atol=1e-12)
    a = np.array([[0.3, 0.4, -0.2], [0.3 + np.pi, -0.4, -0.2 + np.pi]])
    np.testing.assert_allclose(np.asarray(rotations.make_euler_continuous(a, "ZXZ"))[1], a[0],
                               atol=1e-12)


@pytest.mark.parametrize("order", ["ZXY", "XYZ", "YZX", "ZXZ"])
def test_exporter_split_at_gimbal_lock(x64, order):
    """At the pole only one combination of the first and third angle is defined; an exporter may
    split it any way per frame (here randomly, up to 150 degrees). Through the rotation the split
    follows the previous frame; the per-angle unwrap jumps with the file's split. (The true split
    is unobservable at the pole: over a long stay there the chosen one can drift from it, and the
    path rejoins the true angles with a step when it leaves the pole.)"""
    rng = np.random.default_rng(0)
    F = 120
    t = np.linspace(0, 1, F)
    pole = 0.0 if order[0] == order[2] else np.pi / 2
    true = np.stack([0.4 * np.sin(3 * t), pole + 0.5 * (t - 0.44), -0.2 + 0.3 * t], 1)
    true[50:56, 1] = pole  # 6 frames exactly at gimbal lock (an exporter's snapped pole)
    q0 = Rotation.from_euler(order, np.zeros((1, 3)) + [0.0, pole, 0.0])
    plus = np.allclose(Rotation.from_euler(order, [[0.5, pole, 0.5]]).as_quat(), q0.as_quat()) or \
        np.allclose(Rotation.from_euler(order, [[0.5, pole, 0.5]]).as_quat(), -q0.as_quat())
    s = 1.0 if plus else -1.0
    raw = true.copy()
    d = rng.uniform(-2.6, 2.6, 6)
    raw[50:56, 0] += d
    raw[50:56, 2] += s * d
    _same_rotations(raw, true, order)
    out = np.asarray(rotations.make_euler_continuous(raw, order))
    _same_rotations(out, true, order, 1e-6)
    assert np.max(np.abs(np.diff(out, axis=0))) < 0.1, order
    assert np.max(np.abs(np.diff(per_angle_unwrap(raw, order), axis=0))) > 1.0  # it jumps


def test_a_winding_channel_spans_hundreds_of_degrees_without_drift(x64):
    """A joint held 3 degrees from gimbal lock whose tilt circles the pole 5 times (Bandai
    walk_proud_001's Spine: 3.8 times, 1,680 degrees): the first and third angles wind by 5 turns
    each (that is the rotation's topology, every continuous Euler path does), their defined
    combination does not drift, and every frame is the input's rotation."""
    F = 600
    t = np.linspace(0, 1, F)
    tilt = np.radians(3.0) * (1 + 0.3 * np.sin(9 * t))
    a = 5 * 2 * np.pi * t + 0.2 * np.sin(17 * t)
    twist = 0.1 * np.sin(11 * t)
    # ZXY at X = 90 - tilt: R = Rz(a) Rx(-tilt) Rz(-a) Rz(a + c) Rx(90); here a + c = twist.
    true = np.stack([a, np.pi / 2 - tilt, twist - a], 1)
    raw = Rotation.from_euler("ZXY", true).as_euler("ZXY")  # wrapped to (-pi, pi], as files are
    out = np.asarray(rotations.make_euler_continuous(raw, "ZXY"))
    _same_rotations(out, raw, "ZXY", 1e-9)
    assert np.degrees(np.ptp(out[:, 0])) > 1700 and np.degrees(np.ptp(out[:, 2])) > 1700
    assert np.degrees(np.ptp(out[:, 0] + out[:, 2])) < 15  # the defined combination: no drift
    np.testing.assert_allclose(out[:, 0] + out[:, 2], twist + (out[0, 0] + out[0, 2] - twist[0]),
                               atol=1e-6)
    assert np.max(np.abs(np.diff(out, axis=0))) < 0.5


def test_invalid_frames_never_serve_as_reference(x64):
    t = np.linspace(0, 1, 50)
    raw = np.stack([0.5 * t, 0.2 + 0 * t, -0.3 * t], 1)
    glitch = raw.copy()
    glitch[20] = Rotation.from_euler("ZYX", [[0.5 + np.pi, np.pi - 0.2, np.pi]]).as_euler("ZYX")
    valid = np.ones(50, bool)
    valid[20] = False
    out = np.asarray(rotations.make_euler_continuous(glitch, "ZYX", valid))
    np.testing.assert_allclose(np.delete(out, 20, 0), np.delete(raw, 20, 0), atol=1e-9)
    with pytest.raises(UserError, match="valid"):
        rotations.make_euler_continuous(raw, "ZYX", np.ones(3, bool))
    with pytest.raises(UserError, match="order"):
        rotations.make_euler_continuous(raw, "ZQX")


def test_gradient_is_finite():
    t = np.linspace(0, 1, 30)
    x = np.stack([0.5 * t, 1.5 + 0.1 * t, -0.3 * t], 1).astype(np.float32)
    g = jax.grad(lambda v: rotations.make_euler_continuous(v, "ZYX").sum())(x)
    assert np.all(np.isfinite(np.asarray(g)))


@needs_bandai
def test_bandai_spine_near_gimbal_lock():
    """walk_proud_001's `Spine` sits 0.1-4.3 degrees from ZXY gimbal lock and its tilt circles the
    pole: its Z and Y channels span 1,677 and 1,680 degrees. The repair through the rotation gives
    the same angles as the per-angle unwrap (the winding is the rotation's, not drift): Z + Y, the
    angle defined at the pole, spans 8 degrees."""
    from fourierjax.io.bvh import read_bvh

    m = read_bvh(BANDAI / "dataset-1_walk_proud_001.bvh")
    j = m.topology.names.index("Spine")
    idx = [m.topology.channel_offsets[j] + k for k, c in enumerate(m.topology.channels[j])
           if c.endswith("rotation")]
    raw = np.radians(m.channels[:, idx])
    with jax.enable_x64(True):
        out = np.asarray(rotations.make_euler_continuous(raw, "ZXY"))
    _same_rotations(out, raw, "ZXY", 1e-9)
    np.testing.assert_allclose(out, per_angle_unwrap(raw, "ZXY"), atol=1e-9)
    assert 1600 < np.degrees(np.ptp(out[:, 0])) < 1750
    assert np.degrees(np.ptp(out[:, 0] + out[:, 2])) < 10


@needs_bandai
def test_bandai_winding_joint_still_needs_leaving_out_of_the_omega_search():
    """The repair cannot unwind walk_proud_001's Spine (above), so the omega search still leaves
    out joints whose Euler channels span more than pi (`motion._search_weights`): with them the
    fit finds 0.63 Hz (steps: 0.625 Hz); with every joint in the search, 0.54 Hz."""
    import jax.numpy as jnp

    from fourierjax import fourier
    from fourierjax import motion as M
    from fourierjax.io.bvh import read_bvh

    m = read_bvh(BANDAI / "dataset-1_walk_proud_001.bvh")
    default = M.fit_motions([m], 3)[0]
    assert abs(default.omega_fit / default.omega_steps - 1) < 0.05
    x, names = M.features_from_motion(m[default.frame_start:default.frame_stop])
    every = M.fit_motions([m], 3, channel_weights=jnp.asarray(fourier.angle_channel_mask(names), float))[0]
    assert abs(every.omega_fit / every.omega_steps - 1) > 0.1


def _euler_blocks(motion):
    """`{order: [F, K, 3]}` radians: every joint's file Euler angles grouped by order, as
    `features._joint_rotations` hands them to the continuity repair."""
    t = motion.topology
    groups: dict[str, list[list[int]]] = {}
    for j, chans in enumerate(t.channels):
        rot = [k for k, c in enumerate(chans) if c.endswith("rotation")]
        if len(rot) == 3:
            groups.setdefault("".join(chans[k][0] for k in rot), []).append([t.channel_offsets[j] + k for k in rot])
    return {o: np.radians(motion.channels[:, np.array(idx)]) for o, idx in groups.items()}


def _padded_jax(block, order, valid=None):
    """The JAX repair on `block` padded to a length bucket and 32 joints (one program per bucket:
    the scan is causal, so padding after the clip changes nothing before it)."""
    from fourierjax._fourier._buckets import length_bucket

    F, K, _ = block.shape
    Fp = length_bucket(F)
    pad = np.concatenate([block, np.repeat(block[-1:], Fp - F, axis=0)])
    pad = np.concatenate([pad, np.zeros((Fp, 32 - K, 3))], axis=1)
    ok = np.ones((Fp, 32), bool)
    if valid is not None:
        ok[:F, :K] = valid
    return np.asarray(_EULER_F64(pad, order, ok))[:F, :K]


_EULER_F64 = _jit.filter_jit(rotations.make_euler_continuous)


def test_jax_repair_matches_the_numpy_one_on_real_clips(x64):
    """Item 6 of issue 20's residual: `rotations.make_euler_continuous` (JAX) equals
    `features.make_euler_continuous` (NumPy float64, the fit's) on every bundled clip and 4
    Bandai clips, every joint, all frames, and with a per-joint glitch mask; so `features` can
    hand off to it. (They differ only at exact gimbal lock, where the JAX one splits the first
    and third angle and the NumPy one keeps the file's split: no frame of these clips is there.)"""
    from fourierjax import data
    from fourierjax.io.bvh import read_bvh

    clips = [data.load(n) for n in data.list()]
    names = ["walk_proud_001", "walk-back_musical_001", "run_normal_001", "dash_old_001"]
    if BANDAI.is_dir():
        clips += [read_bvh(BANDAI / f"dataset-1_{n}.bvh") for n in names]
    rng = np.random.default_rng(3)
    checked = 0
    for m in clips:
        for order, block in _euler_blocks(m).items():
            assert block.shape[1] <= 32
            np.testing.assert_allclose(_padded_jax(block, order), per_angle_unwrap(block, order), atol=1e-8,
                                       err_msg=f"{m.source} {order}")
            valid = rng.random(block.shape[:2]) > 0.02  # 2% of (frame, joint) entries glitch
            np.testing.assert_allclose(_padded_jax(block, order, valid), per_angle_unwrap(block, order, valid),
                                       atol=1e-8, err_msg=f"{m.source} {order} masked")
            checked += 1
    assert checked >= len(data.list())


def test_a_long_clip_stays_continuous_across_row_blocks():
    """The library's NumPy-facing rotation helpers run long clips in blocks of `ROW_BLOCK`
    rows. A joint that spins steadily through a clip longer than one block (5,000 frames, 40 s at
    120 fps: 2,500 degrees) must come out as one continuous expmap path, like
    `rotations.make_expmap_continuous` of the whole clip (it restarted at frame 4,096, a jump of
    2 pi times the turns wound so far)."""
    import dataclasses

    from fourierjax import data
    from fourierjax._fourier._layout import ROW_BLOCK
    from fourierjax.features import joint_expmaps

    m = data.load("02_01")
    F = ROW_BLOCK + 904
    col = m.topology.flat_channel_names.index("LeftArm.Yrotation")
    ch = np.repeat(m.channels[:1], F, axis=0)
    ch[:, col - 1:col + 2] = 0.0  # LeftArm's ZYX triple: a pure turn about its Y axis
    spin = 0.5 * np.arange(F)  # degrees: ~7 turns
    ch[:, col] = (spin + 180.0) % 360.0 - 180.0  # wrapped to [-180, 180), as files are
    v, names = joint_expmaps(dataclasses.replace(m, channels=ch))
    k = names.index("LeftArm.expmap0")
    j = v[:, k:k + 3]
    assert np.max(np.linalg.norm(np.diff(j, axis=0), axis=1)) < 0.01  # 0.5 deg a frame, no jump
    np.testing.assert_allclose(j[:, [0, 2]], 0.0, atol=1e-9)
    np.testing.assert_allclose(j[:, 1], np.radians(spin), rtol=1e-6, atol=1e-6)  # unwrapped
