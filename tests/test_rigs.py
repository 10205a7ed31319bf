"""Issue #20 on rigs the body map was never tuned on (`tests.rigs`): Daz Genesis 8 twist/bend
bones, Unreal leaf twist bones under a root joint, a Blender armature above the hips with bones
along Y, legs without toes, large rest rotations; and a rig that cannot be mapped.

The body maps and heel strikes here come from NumPy FK of the rewritten clips (no compile per
rig); `test_any_skeleton.py::test_composite_rig_end_to_end` fits and synthesizes a rig that has
all of these at once through the user's path (`fit_motions`, `synthesize_gait`).
"""

import numpy as np
import pytest

import fourierjax.data
from fourierjax import contacts
from fourierjax._motion._clip import _steps
from fourierjax.body import BodyMapError, infer_body_map_from_positions
from fourierjax.errors import UserError
from tests.conventions import convert
from tests.rigs import LEGS, RIGS, ROOTS, composite, no_knees, world

ALL = {**RIGS, "composite": composite}
CMU_LEGS = ("LeftUpLeg", "LeftLeg", "LeftFoot", "LeftToeBase"), ("RightUpLeg", "RightLeg", "RightFoot", "RightToeBase")
#: Rigs whose feet have other foot points than CMU's (ankle, toe, toe tip): no toe joint, so the
#: points are the ankle and its End Site at the ball (composite: a metatarsal joint as the toe).
OTHER_FEET = ("no_toes", "composite")


def _map_and_steps(motion):
    P, E, Q = world(motion)
    bm = infer_body_map_from_positions(motion.topology, P, E, Q)
    pts = np.concatenate([P, E], axis=1)
    feet = np.stack([pts[:, list(bm.left.foot_points)], pts[:, list(bm.right.foot_points)]], axis=1)
    c = contacts.foot_contacts(feet, motion.frame_time_s, up_axis=bm.up_axis)
    return bm, _steps(c, motion.frame_time_s), P


@pytest.fixture(scope="module")
def cmu():
    m = fourierjax.data.load("07_01")[:200]
    return m, *_map_and_steps(m)


@pytest.mark.parametrize("rig", ALL)
def test_rig_keeps_every_cmu_joint_in_place(cmu, rig):
    """The rewrite is exact: the legs and the pelvis are where the CMU clip has them."""
    m, ref, _, P_ref = cmu
    r = ALL[rig](m)
    P = world(r)[0]
    names = r.topology.names
    for got, want in zip(LEGS[rig], CMU_LEGS):
        for g, w in zip(got, want):
            if g and not (rig == "composite" and w.endswith("ToeBase")):  # its toe is the metatarsal
                np.testing.assert_allclose(P[:, names.index(g)], P_ref[:, m.topology.names.index(w)], atol=1e-9)
    np.testing.assert_allclose(P[:, names.index(ROOTS[rig][1])], P_ref[:, 0], atol=1e-9)


@pytest.mark.parametrize("names", ["named", "scrambled"])
@pytest.mark.parametrize("rig", ALL)
def test_rig_body_map_and_heel_strikes(cmu, rig, names):
    """Legs, trajectory, pelvis, up, forward and units as on the CMU clip, by names and (names
    scrambled to j0..jN) by geometry; the same heel strikes and omega from steps (1e-9), or
    within 2 frames and 1% where the rig's feet have no toe joint (measured: 1-2 frames later,
    omega 0.76% lower on both)."""
    m, ref, (l0, r0, om0), _ = cmu
    r = ALL[rig](m)
    rig_names = r.topology.names
    if names == "scrambled":
        r = convert(r, "scrambled")
    bm, (left, right, om), _ = _map_and_steps(r)
    legs = tuple(tuple(rig_names[j] if j >= 0 else "" for j in (g.hip, g.knee, g.ankle, g.toe))
                 for g in (bm.left, bm.right))
    assert legs == LEGS[rig]
    assert (rig_names[bm.trajectory], rig_names[bm.pelvis]) == ROOTS[rig]
    assert bm.source("legs") == ("names" if names == "named" else "geometry")
    assert (bm.up_axis, bm.up_sign, bm.units) == (1, 1, "cmu")
    assert np.dot(bm.forward, ref.forward) >= 0.99
    assert bm.leg_length == pytest.approx(ref.leg_length, rel=1e-6)
    head = rig_names[bm.head].lower()
    assert head.endswith("head") and bm.spine, (head, bm.spine)
    if rig in OTHER_FEET:
        assert (len(left), len(right)) == (len(l0), len(r0))
        assert np.abs(np.r_[left - l0, right - r0]).max() <= 2
        assert om == pytest.approx(om0, rel=0.01)
    else:
        assert (left.tolist(), right.tolist()) == (l0.tolist(), r0.tolist())
        assert om == pytest.approx(om0, rel=1e-9)


def test_genesis_trunk_hangs_from_hip_not_pelvis(cmu):
    """Daz's `hip -> pelvis -> thighs`, `hip -> abdomenLower`: the trunk's root is `hip` (before,
    the map took `pelvis`, found no spine below it and took lThighTwist for the head); with
    names scrambled the arms were taken for the legs (the chest was the shallowest joint with
    three branches)."""
    m = cmu[0]
    r = RIGS["genesis8"](m)
    for rig in (r, convert(r, "scrambled")):
        bm = _map_and_steps(rig)[0]
        n = r.topology.names
        assert n[bm.pelvis] == "hip" and n[bm.head] == "head"
        assert [n[j] for j in bm.spine][:3] == ["abdomenLower", "abdomenUpper", "chestUpper"]
        assert n[bm.left.hip] == "lThighBend"


def test_rig_without_knees_is_refused_with_the_missing_joint(cmu):
    """Legs of two bones (hip -> foot -> toe) cannot be mapped: one UserError that says which
    role no joint's name gives and how to pass a map by hand, by names and by geometry (geometry
    took the foot for the knee and the toe for the ankle before thigh and shin had to match)."""
    r = no_knees(cmu[0])
    for rig, said in ((r, "left leg: hip 'LeftUpLeg', no knee"), (convert(r, "scrambled"), "left leg: no hip")):
        with pytest.raises(BodyMapError) as err:
            _map_and_steps(rig)
        text = str(err.value)
        assert isinstance(err.value, UserError)
        assert "cannot find the legs" in text and said in text, text
        assert "body_map=" in text and "--body-map FILE" in text and "[legs.left]" in text


def test_composite_rig_end_to_end(cmu):
    """A rig none of the conventions has (`tests.rigs.composite`: Daz Genesis 8 bend/twist bones
    and `hip -> pelvis`, no toe joint, leaf twist bones, `Armature -> Root -> hip` with the travel
    on `Root`, large rest rotations, 6 ZXY channels a joint) through the user's path: its inferred
    map, heel strikes within 2 frames of the CMU clip's (its feet have no toe joint), a fit whose
    fundamental is within 1% of the steps' and whose mean speed is the captured one (1%), aligned
    to the left heel strike; its synthesis walks forward at that speed and stands on the floor."""
    from fourierjax import gait
    from fourierjax.motion import fit_motions

    m, _, (l0, r0, _), P_ref = cmu
    rig = composite(m)
    (f,) = fit_motions([rig], 3)
    bm = f.body_map
    assert f.successful and f.alignment == "left_heel_strike"
    assert (bm.name(bm.trajectory), bm.name(bm.pelvis), bm.left.names[0], bm.right.names[2]) == (
        "Root", "hip", "lThighBend", "rFoot")
    assert (len(f.left_heel_strikes), len(f.right_heel_strikes)) == (len(l0), len(r0))
    assert np.abs(np.r_[f.left_heel_strikes - l0, f.right_heel_strikes - r0]).max() <= 2
    assert f.omega_fit == pytest.approx(f.omega_steps, rel=0.01)
    a, b = f.frame_start, f.frame_stop - 1
    captured = np.linalg.norm((P_ref[b, 0] - P_ref[a, 0])[[0, 2]]) / ((b - a) * f.frame_time_s)
    advance = float(np.asarray(f.model.offset)[1])  # root.vz: the mean speed along the heading
    assert advance == pytest.approx(captured, rel=0.01)
    dt = f.frame_time_s
    n = int(round(2 * np.pi / f.omega_fit / dt)) + 1  # one cycle
    g = gait.synthesize_gait(f.model, rig.skeleton(), n, dt)
    root = np.asarray(g.root_position, np.float64)
    travel = (root[-1] - root[0])[[0, 2]]
    assert np.linalg.norm(travel) / ((n - 1) * dt) == pytest.approx(advance, rel=0.10)
    assert travel @ np.asarray(bm.forward)[[0, 2]] / np.linalg.norm(travel) >= 0.95
    low = np.asarray(g.lowest).min(axis=1)  # the lower foot above the ground, file units
    assert abs(np.median(low)) <= 0.35 and low.min() >= -0.1, (np.median(low), low.min())  # 2 cm, 0.5 cm
