"""Bundled CMU clips: catalogue, integrity, the documented quirks, and rest-frame detection."""

import hashlib
import json
import pathlib

import numpy as np
import pytest

import fourierjax
from fourierjax import data
from fourierjax.errors import UserError
from fourierjax.io import Motion

MB = ["02_01", "02_03", "07_01", "07_04", "07_12", "09_01", "09_02"]
STYLIZED = ["142_02", "142_08"]
DESCRIPTIONS = {
    "02_01": "walk", "02_03": "run/jog", "07_01": "walk", "07_04": "slow walk",
    "07_12": "brisk walk", "09_01": "run", "09_02": "run",
    "142_02": "stylized walk (clumsy)", "142_08": "stylized walk (happy)",
}  # fmt: skip
# The converter's T-pose (CMU 2010 MotionBuilder-friendly release): the only nonzero angles.
T_POSE = {
    "LeftUpLeg.Zrotation": -21, "RightUpLeg.Zrotation": 21, "Neck.Xrotation": -16,
    "Neck1.Xrotation": 21, "Head.Xrotation": 11, "LeftArm.Zrotation": -8,
    "RightArm.Zrotation": 8,
}  # fmt: skip


def _rotations(motion):
    names = motion.topology.flat_channel_names
    return [k for k, n in enumerate(names) if n.endswith("rotation")]


def test_catalogue():
    assert data.list() == MB + STYLIZED
    for name in data.list():
        d = data.describe(name)
        assert d["description"] == DESCRIPTIONS[name]
        assert d["group"] == ("cmu_mb" if name in MB else "cmu_stylized")
        assert d["subject"] == name.split("_")[0] and d["fps"] == 120.0
        assert d["frames"] == d["frames_in_file"] - d["rest_frames"]
        assert d["notes"] and d["source"].count("@") == 1
        json.dumps(d)  # serialisable, for `fourierjax` commands and reports
        p = data.path(name)
        assert p == pathlib.Path(d["path"]) and p.suffix == ".bvh"
        # The package never reads the shared folder: clips live inside the package.
        assert pathlib.Path(fourierjax.__file__).parent in p.parents
    assert data.path("07_01.bvh") == data.path("07_01")


@pytest.mark.parametrize("name", data.list())
def test_files_are_the_recorded_bytes(name):
    assert hashlib.sha256(data.path(name).read_bytes()).hexdigest() == data.describe(name)["sha256"]


@pytest.mark.parametrize("bad", ["07_99", "", "walk", "02_01.amc", 7])
def test_unknown_name_lists_the_valid_ones(bad):
    for fn in (data.path, data.describe, data.load):
        with pytest.raises(UserError) as e:
            fn(bad)
        assert "02_01" in str(e.value) and "142_08" in str(e.value)
        assert isinstance(e.value, ValueError)


@pytest.mark.parametrize("name", data.list())
def test_load_drops_exactly_the_synthetic_frames(name):
    raw = data.load(name, raw=True)
    motion = data.load(name)
    d = data.describe(name)
    assert isinstance(motion, Motion)
    assert raw.num_frames == d["frames_in_file"] and motion.num_frames == d["frames"]
    n = d["rest_frames"]
    assert n == {"07_12": 2}.get(name, 1 if name in MB else 0)
    np.testing.assert_array_equal(motion.channels, raw.channels[n:])
    assert motion.topology == raw.topology and motion.frame_time_s == raw.frame_time_s
    assert data.detect_rest_frames(raw) == n
    assert data.detect_rest_frames(motion) == 0
    rot = _rotations(raw)
    # The first kept frame is captured motion: angles are not whole degrees.
    first = raw.channels[n, rot]
    assert (first != np.round(first)).sum() > 30
    if name in MB:
        # Frame 0 is the T-pose: exactly the converter's whole-degree angles, all else zero.
        names = raw.topology.flat_channel_names
        expected = np.array([T_POSE.get(names[k], 0) for k in rot], dtype=float)
        np.testing.assert_array_equal(raw.channels[0, rot], expected)
        # Its root position is copied from frame 1 (not the origin), as documented.
        np.testing.assert_array_equal(raw.channels[0, :3], raw.channels[1, :3])
    if name == "07_12":
        assert (raw.channels[1] == 0).all()  # root at the origin and every angle zero
    assert data.load(name, raw=True) is raw  # cached: arrays are read-only, sharing is safe


@pytest.mark.parametrize("name", STYLIZED)
def test_stylized_group_facts(name):
    m = data.load(name)
    assert data.path(name).read_bytes().count(b"\r\n") > m.num_frames  # CRLF endings
    np.testing.assert_array_equal(m.end_site_offsets, 0.0)
    # Back and forth: the path is much longer than the net displacement.
    xz = m.channels[:, [0, 2]]
    path = np.linalg.norm(np.diff(xz, axis=0), axis=1).sum()
    assert path > 4 * np.linalg.norm(xz[-1] - xz[0])


@pytest.mark.parametrize("name", MB)
def test_cmu_mb_group_facts(name):
    m = data.load(name)
    root = m.channels[:, :3]
    assert 14 < root[:, 1].mean() < 20  # Y up: hip height about 17 CMU units
    assert root[-1, 2] - root[0, 2] > 30  # they progress along +Z
    assert abs(root[-1, 0] - root[0, 0]) < 0.3 * (root[-1, 2] - root[0, 2])
    np.testing.assert_allclose(m.frame_time_s, 1 / 120, rtol=1e-4)
    assert np.any(m.end_site_offsets != 0)
    constant = {n for n, v in zip(m.topology.flat_channel_names, m.channels.T) if np.ptp(v) == 0}
    zyx = ("Zrotation", "Yrotation", "Xrotation")
    expected = {f"{j}.{c}" for j in ("LHipJoint", "RHipJoint", "LeftShoulder", "RightShoulder",
                                     "LeftHandIndex1", "RightHandIndex1") for c in zyx}  # fmt: skip
    expected |= {f"{j}.{c}" for j in ("LeftHand", "RightHand") for c in zyx[:2]}
    assert constant == expected  # 22 channels never move (documented in the data README)


def _geodesic_steps_deg(motion, joint):
    """Rotation change of `joint` from each frame to the next (degrees), via scipy."""
    from scipy.spatial.transform import Rotation

    k = motion.topology.flat_channel_names.index(f"{joint}.Zrotation")
    r = Rotation.from_euler("ZYX", motion.channels[:, k : k + 3], degrees=True)
    return np.degrees((r[1:] * r[:-1].inv()).magnitude()), motion.channels[:, k : k + 3]


@pytest.mark.parametrize("name", STYLIZED)
def test_stylized_root_euler_angles_wrap_but_the_rotation_is_smooth(name):
    """Documented quirk: fit rotations as quaternions/expmaps, not raw Euler channels."""
    steps, euler = _geodesic_steps_deg(data.load(name), "Hips")
    assert steps.max() < 4  # the root turns smoothly ...
    assert (np.abs(np.diff(euler, axis=0)) > 90).any(axis=1).sum() >= 10  # ... Euler Z/X jump
    assert np.abs(euler[:, 1]).max() > 85  # the middle (Y) angle reaches gimbal lock


def test_142_02_left_arm_glitch():
    """Documented quirk: a transient left-arm pop around frame 1140 of 142_02 (not in 142_08)."""
    steps, _ = _geodesic_steps_deg(data.load("142_02"), "LeftArm")
    assert int(np.argmax(steps)) == 1140 and steps[1140] > 45  # > 5000 deg/s
    calm = np.delete(steps, np.arange(1134, 1143))
    assert calm.max() < 15
    steps, _ = _geodesic_steps_deg(data.load("142_08"), "LeftArm")
    assert steps.max() < 15


def test_detect_rest_frames_on_synthetic_clips():
    base = data.load("09_02")
    rot = _rotations(base)
    ch = base.channels[:6].copy()
    assert data.detect_rest_frames(base.with_channels(ch)) == 0
    ch[0, rot] = 0.0  # all-zero rotations, whatever the root position
    ch[1, rot] = -0.0
    ch[1, rot[:3]] = [90, -45, 1]  # whole degrees, mostly zero: a synthetic rest pose
    assert data.detect_rest_frames(base.with_channels(ch)) == 2
    ch[2, rot] = np.round(ch[2, rot]) + 1  # whole degrees but mostly nonzero: not synthetic
    assert data.detect_rest_frames(base.with_channels(ch)) == 2
    zeros = base.with_channels(np.zeros((3, base.num_channels)))
    assert data.detect_rest_frames(zeros) == 3
    ch[0, rot[0]] = 1e-3  # not exactly zero: real data
    assert data.detect_rest_frames(base.with_channels(ch)) == 0
