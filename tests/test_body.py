"""Body maps (fourierjax.body): names first, geometry where names do not decide, overrides win."""

import dataclasses
import json
import pathlib

import jax
import numpy as np
import pytest

import fourierjax.data
from fourierjax._jit import filter_jit
from fourierjax.body import (
    BodyMap,
    BodyMapError,
    body_map_from_dict,
    body_map_from_toml,
    infer_body_map,
    infer_body_map_from_positions,
)
from fourierjax.errors import UserError
from fourierjax.io.axes import up_rotation
from fourierjax.io.bvh import Motion, read_bvh
from fourierjax.kinematics import fk_frames
from fourierjax.skeleton import Topology
from tests.conventions import CONVENTIONS, convert, rename, undo

BANDAI = pathlib.Path(__file__).resolve().parents[1] / ".." / "shared" / "data" / "mocap" / "bandai1" / "data"
CLIPS = fourierjax.data.list()
CMU_LEGS = (("LeftUpLeg", "LeftLeg", "LeftFoot", "LeftToeBase"),
            ("RightUpLeg", "RightLeg", "RightFoot", "RightToeBase"))


def _parts(bm: BodyMap):
    """The joint indices a map names (comparable across renamings that keep the joint order)."""
    return (bm.left.hip, bm.left.knee, bm.left.ankle, bm.left.toe, bm.left.foot_points,
            bm.right.hip, bm.right.knee, bm.right.ankle, bm.right.toe, bm.right.foot_points)


def _travel(motion: Motion, joint: int) -> np.ndarray:
    """Horizontal (Y-up) displacement of a joint's position channels over the clip."""
    first = motion.topology.channel_offsets[joint]
    d = motion.channels[-1, first:first + 3] - motion.channels[0, first:first + 3]
    return np.array([d[0], 0.0, d[2]])


@pytest.fixture(scope="module")
def maps():
    return {n: infer_body_map(fourierjax.data.load(n)) for n in CLIPS}


@pytest.mark.parametrize("name", CLIPS)
def test_bundled_clip(maps, name):
    bm = maps[name]
    motion = fourierjax.data.load(name)
    assert (bm.left.names, bm.right.names) == CMU_LEGS
    assert bm.left.foot_point_names == ("LeftFoot", "LeftToeBase", "LeftToeBase/End Site")
    assert bm.joint_names[bm.trajectory] == "Hips" and bm.joint_names[bm.pelvis] == "Hips"
    assert bm.joint_names[bm.head] == "Head" and bm.joint_names[bm.neck] == "Neck"
    assert [bm.joint_names[j] for j in bm.spine] == ["LowerBack", "Spine", "Spine1"]
    assert bm.left_arm.names == ("LeftShoulder", "LeftArm", "LeftForeArm", "LeftHand")
    assert (bm.up_axis, bm.up_sign, bm.units) == (1, 1, "cmu")
    assert bm.metres_per_unit == 0.0564
    assert 0.7 < bm.leg_length * bm.metres_per_unit < 0.95
    travel = _travel(motion, 0)
    if np.linalg.norm(travel) > bm.leg_length:
        assert np.dot(bm.forward, travel) / np.linalg.norm(travel) >= 0.95
    # left = up x forward, and the left hip is on that side of the right one (CMU: +X for +Z travel)
    assert bm.source("legs") == "names" and bm.source("up") == "geometry"
    hash(bm)


@pytest.mark.parametrize("convention", CONVENTIONS)
def test_fk_of_each_convention_equals_the_original(convention):
    motion = fourierjax.data.load("07_01")[:80]
    rewritten = convert(motion, convention)
    with jax.enable_x64(True):
        a = fk_frames(motion.skeleton(), motion.channels)
        b = fk_frames(rewritten.skeleton(), rewritten.channels)
        np.testing.assert_allclose(undo(np.asarray(b.positions), convention), a.positions, atol=1e-5)
        np.testing.assert_allclose(undo(np.asarray(b.end_site_positions), convention), a.end_site_positions,
                                   atol=1e-5)
    if convention not in ("zup", "metres"):
        np.testing.assert_allclose(undo(np.ones(3), convention), np.ones(3))


@pytest.mark.parametrize("name", ["07_01", "142_02"])
@pytest.mark.parametrize("convention", [*CONVENTIONS, "zup+scrambled"])
def test_each_convention_names_the_same_body(maps, name, convention):
    ref = maps[name]
    motion = fourierjax.data.load(name)
    rewritten = motion
    for c in convention.split("+"):
        rewritten = convert(rewritten, c)
    bm = infer_body_map(rewritten)
    assert _parts(bm) == _parts(ref)
    assert (bm.trajectory, bm.pelvis, bm.head) == (ref.trajectory, ref.pelvis, ref.head)
    axes = convention.split("+")[0]
    up = undo(np.asarray(bm.up), axes)
    assert np.allclose(up / np.linalg.norm(up), ref.up, atol=1e-12)
    forward = undo(np.asarray(bm.forward), axes)
    forward = forward / np.linalg.norm(forward)
    assert np.dot(forward, ref.forward) >= 0.95
    assert bm.units == ("m" if convention == "metres" else "cmu")
    if "scrambled" in convention:
        assert bm.source("legs") == "geometry" and bm.left_arm is None
    else:
        assert bm.source("legs") == "names"
        assert (bm.neck, bm.spine) == (ref.neck, ref.spine)
        assert (bm.left_arm.shoulder, bm.left_arm.elbow, bm.left_arm.wrist, bm.right_arm.wrist) == (
            ref.left_arm.shoulder, ref.left_arm.elbow, ref.left_arm.wrist, ref.right_arm.wrist)


def test_z_up_is_detected():
    bm = infer_body_map(convert(fourierjax.data.load("07_01"), "zup"))
    assert (bm.up_axis, bm.up_sign) == (2, 1)
    assert bm.source("up") == "geometry"
    assert np.dot(bm.forward, up_rotation("z").T @ np.array([0.0, 0.0, 1.0])) > 0.95  # +Z travel became -Y


@pytest.mark.parametrize("spell", [
    lambda n: "mixamorig1:" + n, lambda n: "Character1_" + n, lambda n: "rig:sub:" + n, str.upper, str.lower,
    lambda n: n.replace("Left", "L_").replace("Right", "R_"),
    lambda n: (n.replace("Left", "") + ".L") if n.startswith("Left") else
              (n.replace("Right", "") + ".R") if n.startswith("Right") else n,
    lambda n: (n.replace("Left", "") + "_l") if n.startswith("Left") else
              (n.replace("Right", "") + "_r") if n.startswith("Right") else n,
    lambda n: n.replace("Left", "Left ").replace("Right", "Right ").replace("Up", "Up-"),
])
def test_case_prefix_and_separator_variants(maps, spell):
    motion = fourierjax.data.load("07_01")
    bm = infer_body_map(rename(motion, [spell(n) for n in motion.topology.names]))
    assert bm.source("legs") == "names"
    assert _parts(bm) == _parts(maps["07_01"])


def test_scrambled_rig_gets_left_and_right_from_geometry():
    """With no usable names, left and right come from where the feet and knees point."""
    motion = convert(fourierjax.data.load("07_01"), "scrambled")
    t = motion.topology
    bm = infer_body_map(motion)
    # CMU: +Z travel, Y up, so left is +X, and the left thigh is joint 2.
    assert bm.left.hip == 2 and bm.right.hip == 7
    assert np.allclose(bm.left_direction, [1.0, 0.0, 0.0], atol=0.05)
    assert bm.joint_names == t.names


def test_positions_entry_point_matches(maps):
    motion = fourierjax.data.load("07_01")
    fk = fk_frames(motion.skeleton(), motion.channels)
    bm = infer_body_map_from_positions(motion.topology, fk.positions, fk.end_site_positions, fk.rotations)
    assert _parts(bm) == _parts(maps["07_01"]) and bm.trajectory == 0
    plain = infer_body_map_from_positions(motion.topology, fk.positions)
    assert plain.left.foot_points == (4, 5)  # no End Sites given, none become foot points
    with pytest.raises(BodyMapError, match="shape"):
        infer_body_map_from_positions(motion.topology, fk.positions[0])


def test_skeleton_without_legs_gets_a_clear_error():
    names = ("root", "a", "b", "c", "d")
    topo = Topology(names, (-1, 0, 1, 2, 3), (("Xposition", "Yposition", "Zposition", "Zrotation", "Yrotation",
                                                 "Xrotation"),) + (("Zrotation", "Yrotation", "Xrotation"),) * 4)
    motion = Motion(topo, np.tile([[0.0, 1.0, 0.0]], (5, 1)), np.zeros((0, 3)), np.zeros((3, 18)), 1 / 30)
    with pytest.raises(BodyMapError) as err:
        infer_body_map(motion)
    assert isinstance(err.value, UserError)
    text = str(err.value)
    assert "cannot find the legs" in text and "root, a, b, c, d" in text
    assert "[legs.left]" in text and 'hip = "' in text


def test_toml_round_trip(maps, tmp_path):
    bm = maps["07_01"]
    text = bm.to_toml()
    again = body_map_from_toml(text, bm_topology())
    assert dataclasses.replace(again, sources=()) == dataclasses.replace(bm, sources=())
    assert all(how == "file" for _, how in again.sources)
    path = tmp_path / "map.toml"
    path.write_text(text)
    from_file = infer_body_map(fourierjax.data.load("07_01"), overrides=path)
    # The facing is measured again from the clip: NumPy's SIMD sums can round the last bit
    # differently from one array to another (CI: 0.018963507926337147 against ...143).
    np.testing.assert_allclose(from_file.facing, bm.facing, rtol=0, atol=1e-12)
    assert dataclasses.replace(from_file, facing=bm.facing) == dataclasses.replace(bm, sources=from_file.sources)
    # the same TOML fits a renamed rig once its names are changed the same way
    stored = json.loads(json.dumps(bm.to_dict()))
    assert stored["version"] == 1
    assert body_map_from_dict(stored, bm_topology()) == dataclasses.replace(bm, sources=bm.sources)
    with pytest.raises(BodyMapError, match="version"):
        body_map_from_dict({**stored, "version": 99}, bm_topology())
    with pytest.raises(BodyMapError, match="missing"):
        body_map_from_dict({"version": 1, "up": "y"}, bm_topology())


def bm_topology():
    return fourierjax.data.load("07_01").topology


def test_override_wins(maps):
    motion = fourierjax.data.load("07_01")
    ov = """
up = "y"
units = "cm"
trajectory = "LowerBack"
[legs.left]
hip = "RightUpLeg"
knee = "RightLeg"
ankle = "RightFoot"
toe = "RightToeBase"
[legs.right]
hip = "LeftUpLeg"
knee = "LeftLeg"
ankle = "LeftFoot"
"""
    bm = infer_body_map(motion, overrides=ov)
    assert bm.left.names == CMU_LEGS[1]
    assert bm.right.names == CMU_LEGS[0]  # a toe the file leaves out is the ankle's only child
    assert bm.units == "cm" and bm.metres_per_unit == 0.01 and bm.source("units") == "file"
    assert bm.joint_names[bm.trajectory] == "LowerBack" and bm.source("trajectory") == "file"
    assert bm.source("up") == "file" and bm.source("legs") == "file"
    one = infer_body_map(motion, overrides={"legs": {"left": {"toe": ""}}}, up="y")
    assert one.left.toe == -1 and one.left.foot_point_names == ("LeftFoot",)  # CMU's ankle has no End Site
    assert one.source("up") == "argument" and one.right.toe == maps["07_01"].right.toe
    with pytest.raises(BodyMapError, match="not a joint"):
        infer_body_map(motion, overrides={"trajectory": "Pelvis"})
    with pytest.raises(BodyMapError, match="unknown field"):
        infer_body_map(motion, overrides={"feet": "x"})
    with pytest.raises(BodyMapError, match="unknown unit"):
        infer_body_map(motion, overrides={"units": "furlong"})


def test_map_is_a_static_argument(maps):
    bm = maps["07_01"]
    traces = []

    @filter_jit
    def hip_height(positions, body):
        traces.append(1)
        return positions[body.left.hip, body.up_axis]

    p = np.zeros((31, 3))
    hip_height(p, bm)
    hip_height(p + 1.0, dataclasses.replace(bm))  # an equal map does not retrace
    assert len(traces) == 1
    assert hash(bm) == hash(dataclasses.replace(bm))


def test_describe(maps):
    text = maps["07_01"].describe()
    assert "LeftUpLeg > LeftLeg > LeftFoot > LeftToeBase" in text
    assert "up (geometry): +y" in text and "cmu" in text


@pytest.fixture(scope="module")
def bandai_clips():
    files = sorted(BANDAI.glob("*.bvh")) if BANDAI.is_dir() else []
    if not files:
        pytest.skip(f"Bandai-Namco data set not present at {BANDAI}")
    return files


def test_bandai(bandai_clips):
    for path in bandai_clips:
        motion = read_bvh(path)
        bm = infer_body_map(motion)
        assert bm.left.names == ("UpperLeg_L", "LowerLeg_L", "Foot_L", "Toes_L"), path.name
        assert bm.right.names == ("UpperLeg_R", "LowerLeg_R", "Foot_R", "Toes_R"), path.name
        assert (bm.up_axis, bm.up_sign, bm.units) == (1, 1, "cm"), path.name
        # Hips carries the travel, except in the few loop clips that move joint_Root instead.
        root_moves = np.ptp(motion.channels[:, :3], axis=0).max() > 1e-3
        assert bm.joint_names[bm.trajectory] == ("joint_Root" if root_moves else "Hips"), path.name


def test_bandai_by_geometry(bandai_clips):
    """Names scrambled to j0..jN: geometry alone finds the same legs, sides and units on every clip."""
    for path in bandai_clips:
        motion = read_bvh(path)
        named = infer_body_map(motion)
        bm = infer_body_map(convert(motion, "scrambled"))
        assert bm.source("legs") == "geometry"
        assert _parts(bm) == _parts(named), path.name
        assert (bm.units, bm.up_axis, bm.up_sign) == ("cm", 1, 1), path.name


# -- the CMU-named defaults, replaced by the names' body map (issue 20 residual, item 3) -------

#: The table `anthropometry._CMU_SEGMENTS` held (the default of a bare CMU topology until the
#: names' body map replaced it); the new default must give it back on CMU rigs.
OLD_CMU_SEGMENTS = {
    "head": ("Neck", "Head/end"), "trunk": ("Neck", "Hips"),
    "left_upper_arm": ("LeftArm", "LeftForeArm"), "left_forearm": ("LeftForeArm", "LeftHand"),
    "left_hand": ("LeftHand", "LeftFingerBase"), "right_upper_arm": ("RightArm", "RightForeArm"),
    "right_forearm": ("RightForeArm", "RightHand"), "right_hand": ("RightHand", "RightFingerBase"),
    "left_thigh": ("LeftUpLeg", "LeftLeg"), "left_shank": ("LeftLeg", "LeftFoot"),
    "left_foot": ("LeftFoot", "LeftToeBase"), "right_thigh": ("RightUpLeg", "RightLeg"),
    "right_shank": ("RightLeg", "RightFoot"), "right_foot": ("RightFoot", "RightToeBase"),
}
NAMED = tuple(c for c in CONVENTIONS if c != "scrambled")


def _joints(bm: BodyMap):
    arms = tuple((a.collar, a.shoulder, a.elbow, a.wrist) for a in (bm.left_arm, bm.right_arm))
    return _parts(bm) + (bm.pelvis, bm.trajectory, bm.spine, bm.neck, bm.head, arms)


def test_names_body_map_of_a_bare_topology(maps):
    """`body_map_from_names` names the joints the clip's inferred map names, on CMU and on every
    renamed rig; geometry is marked "default"; names that decide nothing are refused."""
    from fourierjax.body import body_map_from_names

    m = fourierjax.data.load("07_01")
    ref = body_map_from_names(m.topology)
    assert _joints(ref) == _joints(maps["07_01"])
    assert ref.source("up") == "default" and ref.up_axis == 1 and ref.source("legs") == "names"
    for c in NAMED:
        assert _joints(body_map_from_names(convert(m, c).topology)) == _joints(ref), c
    with pytest.raises(BodyMapError, match="names do not decide"):
        body_map_from_names(convert(m, "scrambled").topology)


def test_groins_and_segments_of_renamed_bare_topologies():
    """`gait.groin_joints` and `anthropometry.segment_model` of a bare topology come from its
    names' body map: the CMU results (the old CMU-name defaults) on every renamed rig."""
    from fourierjax import anthropometry, gait

    m = fourierjax.data.load("07_01")
    topo = m.topology
    groins = gait.groin_joints(topo)
    assert groins == (topo.names.index("LeftUpLeg"), topo.names.index("RightUpLeg"))
    ref = anthropometry.segment_model(topo)
    assert ref == anthropometry.segment_model(topo, OLD_CMU_SEGMENTS)
    for c in NAMED:
        t = convert(m, c).topology
        assert gait.groin_joints(t) == groins, c
        got = anthropometry.segment_model(t)
        assert (got.names, got.proximal, got.distal, got.mass_fraction) == (
            ref.names, ref.proximal, ref.distal, ref.mass_fraction), c
    with pytest.raises(UserError, match="do not decide its legs"):
        gait.groin_joints(convert(m, "scrambled").topology)
    with pytest.warns(DeprecationWarning, match="CMU_GROINS"):
        assert gait.CMU_GROINS == ("LeftUpLeg", "RightUpLeg")


def test_rest_frames_of_a_z_up_export():
    """`data.detect_rest_frames` finds the T-pose of a Z-up export (whose root holds the 90 degree
    turn, off a whole degree by round-off) as in the original, and in metres."""
    from fourierjax.io.axes import to_y_up

    for name in ("07_01", "07_12", "142_08"):  # 1, 2 and 0 rest frames
        m = read_bvh(fourierjax.data.path(name))
        n = fourierjax.data.detect_rest_frames(m)
        assert n == {"07_01": 1, "07_12": 2, "142_08": 0}[name]
        z = convert(m, "zup")
        assert fourierjax.data.detect_rest_frames(z) == n, name
        assert fourierjax.data.detect_rest_frames(to_y_up(z, "z")) == n, name
        assert fourierjax.data.detect_rest_frames(convert(m, "metres")) == n, name


def test_an_arm_only_rig_has_no_legs():
    from tests.rigs import _Rig

    rig = _Rig.of(fourierjax.data.load("02_01")[:120])
    for side in ("Left", "Right"):
        for part in ("ToeBase", "Foot", "Leg", "UpLeg"):
            rig.drop_leaf(f"{side}{part}", end_site=False)
        rig.drop_leaf(f"{side[0]}HipJoint", end_site=False)
    # Geometry alone would take the arms (they reach lowest): the names say they are arms.
    with pytest.raises(BodyMapError, match="reach lowest are the arms by name"):
        infer_body_map(rig.motion())
