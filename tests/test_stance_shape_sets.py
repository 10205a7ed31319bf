"""Shape sets as data: loading, validation messages, interpolation rules, BVH export, skeleton."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from fourierjax.errors import UserError
from fourierjax.io.bvh import read_bvh
from fourierjax.io.stance_bvh import animate, ease_in_out, write_stance_bvh
from fourierjax.kinematics import forward_kinematics
from fourierjax.stance.problem import MAGNITUDE_PARAMS, SHAPE_PARAMS, P
from fourierjax.stance.shape_sets import (
    anticipation,
    builtin_shape_sets,
    get_shape_set,
    parse_shape_set,
    perturb,
)
from fourierjax.stance.skeleton48 import (
    DOF_NAMES,
    DOFS,
    StancePose,
    center_of_mass,
    center_of_mass_matrices,
    dof_vector,
    fk_matrices,
    make_body,
    pose_fk,
)
from fourierjax.stance.solver import solve_stance
from fourierjax.stance.torso import CORONAL_WEIGHTS, SAGITTAL_WEIGHTS

BODY = make_body(1.75)


def test_48_dofs_and_de_leva_masses():
    assert len(DOF_NAMES) == 48 and sum(len(a) for a in DOFS.values()) == 45
    np.testing.assert_allclose(float(jnp.sum(BODY.mass_fractions)), 1.0, rtol=1e-6)
    # Standing upright, the whole-body COM is at ~55-57% of the stature (de Leva).
    fk = pose_fk(BODY, StancePose(BODY.offsets[0], jnp.zeros((19, 4)).at[:, 0].set(1.0)))
    assert 0.53 < float(center_of_mass(BODY, fk)[1]) / 1.75 < 0.59
    taller = make_body(2.0)
    np.testing.assert_allclose(taller.offsets, BODY.offsets * 2.0 / 1.75, rtol=1e-6)
    with pytest.raises(UserError, match="height_m"):
        make_body(float("nan"))


def test_matrix_fk_matches_foundation_fk():
    key = jax.random.PRNGKey(0)
    q = jax.random.normal(key, (19, 4))
    q = q / jnp.linalg.norm(q, axis=-1, keepdims=True)
    root = jnp.array([0.1, 0.9, -0.2])
    from fourierjax.rotations import matrix_from_quat

    R, Pw = fk_matrices(BODY, root, matrix_from_quat(q))
    fk = forward_kinematics(BODY.skeleton, BODY.offsets.at[0].set(root), q)
    np.testing.assert_allclose(Pw, fk.positions, atol=1e-5)
    np.testing.assert_allclose(center_of_mass_matrices(BODY, R, Pw), center_of_mass(BODY, fk), atol=1e-5)


def test_builtin_sets_load_and_cover_the_paper():
    sets = builtin_shape_sets()
    assert {"posture", "strong_recoil", "weak_recoil", "interest", "beauty_line"} <= set(sets)
    assert sets["strong_recoil"].needs_object and not sets["posture"].needs_object


def test_posture_switches_class_and_bends_knees_late():
    s = get_shape_set("posture")
    ev = {i: s.evaluate(i) for i in (-1.0, -0.3, 0.0, 0.3, 0.7, 1.0, 1.5)}
    np.testing.assert_allclose(ev[1.0]["sagittal_weights"], SAGITTAL_WEIGHTS["large_c"])
    np.testing.assert_allclose(ev[-1.0]["sagittal_weights"], SAGITTAL_WEIGHTS["small_s"])
    sag = {i: float(e["shape"][P["sagittal"]]) for i, e in ev.items()}
    assert sag[-1.0] < sag[-0.3] < 0.0 == sag[0.0] < sag[0.3] < sag[1.0] < sag[1.5]
    knee = {i: float(e["shape"][P["knee_right"]]) for i, e in ev.items()}
    assert knee[0.3] == 0.0 and knee[-1.0] == 0.0 and 0.0 < knee[0.7] < knee[1.0] < knee[1.5]
    np.testing.assert_allclose(ev[0.0]["shape"], 0.0)  # the neutral origin


def test_beauty_line_bent_knee_switches_with_sign():
    s = get_shape_set("beauty_line")
    pos, neg = s.evaluate(0.8)["shape"], s.evaluate(-0.8)["shape"]
    assert pos[P["knee_left"]] > 0 and pos[P["knee_right"]] == 0
    assert neg[P["knee_right"]] > 0 and neg[P["knee_left"]] == 0
    np.testing.assert_allclose(s.evaluate(1.0)["coronal_weights"], CORONAL_WEIGHTS["large_s"])


def test_recoil_direction_comes_from_the_object():
    s = get_shape_set("strong_recoil")
    front = s.evaluate(1.0, jnp.array([0.0, 1.2, 1.0]))["shape"]
    left = s.evaluate(1.0, jnp.array([1.0, 1.2, 0.0]))["shape"]
    right = s.evaluate(1.0, jnp.array([-1.0, 1.2, 0.0]))["shape"]
    assert front[P["sagittal"]] < 0  # leans back from an object in front
    assert front[P["forward_shift"]] < 0
    assert left[P["weight_shift"]] < 0 < right[P["weight_shift"]]  # weight away from it
    with pytest.raises(UserError, match="needs an object"):
        s.problem(BODY, 1.0)


def test_intensity_is_differentiable_and_vmappable():
    s = get_shape_set("posture")
    g = jax.grad(lambda i: s.evaluate(i)["shape"][P["sagittal"]])(0.5)
    np.testing.assert_allclose(g, 1.1, rtol=1e-6)
    shapes = jax.vmap(lambda i: s.evaluate(i)["shape"])(jnp.linspace(-1, 1, 5))
    assert shapes.shape == (5, len(SHAPE_PARAMS))


@pytest.mark.parametrize(
    "text, key",
    [
        ('name = "x"\n[positive]\nsagittal_class = "huge"', "positive.sagittal_class"),
        ('name = "x"\n[positive.vector]\nsagital = 1.0', "positive.vector.sagital"),
        ('name = "x"\n[positive.vector]\nsagittal = "a"', "positive.vector.sagittal"),
        ('name = "x"\nobject = "maybe"\n[positive]', "object"),
        ('name = "x"\n[positive.curves]\nknee_left = {kind = "late", start = 2}',
         "positive.curves.knee_left.start"),
        ('name = "x"\n[positive.away]\ncoronal = {sideways = 1}', "positive.away.coronal.sideways"),
        ('name = "x"\n[negative]', "positive"),
        ('name = "x"\ncolour = 1\n[positive]', "colour"),
        ("name = [", "not valid TOML"),
    ],
)
def test_validation_names_the_key(text, key):
    with pytest.raises(UserError, match=key.replace(".", r"\.")):
        parse_shape_set(text, "my.toml")


@pytest.mark.parametrize(
    "call, match",
    [
        (lambda s: s.problem(BODY, float("nan")), "intensity holds NaN"),
        (lambda s: s.problem(BODY, "strong"), "intensity must be numbers"),
        (lambda s: s.problem(BODY, 0.5, target_right=[0.1, float("inf"), 0.3]), "target_right holds NaN"),
        (lambda s: s.problem(BODY, 0.5, target_left="front"), "target_left must be numbers"),
        (lambda s: s.problem(BODY, 0.5, object_xyz=[0.0, 1.0]), "object_xyz must be 3 coordinates"),
        (lambda s: s.problem(BODY, 0.5, object_xyz=[0.0, float("nan"), 1.0]), "object_xyz holds NaN"),
    ],
)
def test_problem_arguments_are_checked_when_their_values_are_known(call, match):
    """A NaN target or intensity used to flow into the solver and come out as a NaN pose."""
    with pytest.raises(UserError, match=match):
        call(get_shape_set("posture"))


def test_problem_shape_and_gaze_are_checked():
    from fourierjax.stance.problem import make_problem

    with pytest.raises(UserError, match=r"shape\['sagittal'\] holds NaN"):
        make_problem(BODY, {"sagittal": float("nan")})
    with pytest.raises(UserError, match="single numbers; not \\['coronal'\\]"):
        make_problem(BODY, {"coronal": [0.1, 0.2]})
    with pytest.raises(UserError, match="gaze_point must be 3 coordinates"):
        make_problem(BODY, gaze_point=[0.0, 1.6])
    with pytest.raises(UserError, match="gaze_point holds NaN"):
        make_problem(BODY, gaze_point=[0.0, float("nan"), 2.0])
    # Traced values cannot be checked and pass through (vmapped sweeps, gradients).
    s = get_shape_set("posture")
    probs = jax.vmap(lambda i, t: s.problem(BODY, i, target_right=t))(
        jnp.linspace(-1.0, 1.0, 3), jnp.tile(jnp.array([-0.3, 1.2, 0.4]), (3, 1))
    )
    assert probs.shape.shape == (3, len(SHAPE_PARAMS))


def test_user_shape_set_from_configs():
    s = get_shape_set("configs/shape_sets/slouch.toml")
    assert s.name == "slouch" and s.positive.abdomen_offset
    with pytest.raises(UserError, match="unknown shape set 'nope'"):
        get_shape_set("nope")


def test_perturb_and_anticipation():
    v = get_shape_set("posture").evaluate(1.0)["shape"]
    w = perturb(v, jax.random.PRNGKey(1), 0.02)
    assert 0 < float(jnp.max(jnp.abs(w - v))) < 0.1
    np.testing.assert_array_equal(w[v == 0], 0.0)
    # The wind-up negates the directions and keeps the bends and the gaze weight.
    a = np.asarray(anticipation(v, 0.3))
    for name, x in zip(SHAPE_PARAMS, np.asarray(v)):
        sign = 1.0 if name in MAGNITUDE_PARAMS else -1.0
        assert a[P[name]] == pytest.approx(sign * 0.3 * x, abs=1e-7), name
    assert v[P["sagittal"]] != 0 and v[P["elbow_right"]] > 0  # both kinds are exercised


def test_object_sets_point_the_other_way_below_zero():
    """Sets without a [negative] table (the recoils, interest) negate their directions below
    zero and keep their bends and gaze: strong_recoil at -1 leans towards the object with the
    elbows bent and the eyes on it. Negating everything had hyperextended the elbows by 34
    degrees (solved, converged) and turned the head away."""
    obj = jnp.array([0.35, 1.3, 0.55])
    for name in ("strong_recoil", "weak_recoil", "interest"):
        s = get_shape_set(name)
        assert s.negative is None
        pos, neg = (np.asarray(s.evaluate(i, obj)["shape"]) for i in (1.0, -1.0))
        for k, param in enumerate(SHAPE_PARAMS):
            sign = 1.0 if param in MAGNITUDE_PARAMS else -1.0
            assert neg[k] == pytest.approx(sign * pos[k], abs=1e-7), (name, param)
        assert neg[P["elbow_right"]] > 0 and neg[P["gaze_weight"]] > 0
    sol = solve_stance(get_shape_set("strong_recoil").problem(BODY, -1.0, obj))
    assert bool(sol.converged)
    dof = dict(zip(DOF_NAMES, np.asarray(dof_vector(sol.pose))))
    # An elbow flexion is a negative X rotation in this skeleton (0.6 rad asked for).
    for side in ("r", "l"):
        assert dof[f"{side}_elbow.Xrotation"] == pytest.approx(-0.6, abs=1e-4)


def test_bvh_roundtrip_and_eased_animation(tmp_path):
    q0 = jnp.zeros((19, 4)).at[:, 0].set(1.0)
    q1 = q0.at[1].set(jnp.array([np.cos(0.2), np.sin(0.2), 0.0, 0.0]))  # abdomen 0.4 rad X
    a = StancePose(BODY.offsets[0], q0)
    b = StancePose(BODY.offsets[0] + jnp.array([0.0, -0.05, 0.0]), q1)
    anim = animate([a, b], 10)
    assert anim.quats.shape == (11, 19, 4)
    path = tmp_path / "anim.bvh"
    write_stance_bvh(path, BODY, anim)
    m = read_bvh(path)
    assert m.num_frames == 11 and m.topology.num_joints == 19
    ab = m.channels[:, 6 + 1]  # abdomen Xrotation (channels: root 6, abdomen Z X Y)
    np.testing.assert_allclose(ab[[0, -1]], [0.0, np.degrees(0.4)], atol=1e-4)
    np.testing.assert_allclose(ab[5], np.degrees(0.4) * float(ease_in_out(0.5)), atol=1e-3)
    assert ab[1] - ab[0] < ab[5] - ab[4]  # eases in
    fk = pose_fk(BODY, b)
    np.testing.assert_allclose(m.offsets, BODY.offsets, atol=1e-6)
    assert np.isfinite(np.asarray(fk.positions)).all()


def test_feedback_balance_converges_for_animation():
    # The paper's animation-time balance: feed the COM error back into the dominant ankle.
    from fourierjax.stance.balance import feedback_update
    from fourierjax.stance.problem import build_rotations, desired_balance_point, make_problem

    prob = make_problem(BODY, {"sagittal": 0.4, "weight_shift": 0.3, "knee_left": 0.2},
                        sagittal_class="large_c")  # fmt: skip
    goal = desired_balance_point(prob)
    b = jnp.zeros(2)
    errors = []
    for _ in range(12):  # eager: no compile for a handful of steps
        com = build_rotations(prob, prob.shape[:6], b)[2].com
        err = jnp.stack([com[0], com[2]]) - goal
        errors.append(float(jnp.linalg.norm(err)))
        b = feedback_update(b, err, BODY.offsets[0, 1])
    assert errors[0] > 0.01 and errors[-1] < 1e-3
    assert all(e1 < e0 for e0, e1 in zip(errors, errors[1:]))


def _elbow_bent(deg):
    from fourierjax.stance.skeleton48 import JOINT_NAMES, rest_pose

    p = rest_pose(BODY)
    h = np.radians(deg) / 2
    q = p.quats.at[JOINT_NAMES.index("r_elbow")].set(jnp.array([np.cos(h), np.sin(h), 0.0, 0.0]))
    return StancePose(p.root_position, q)


def test_bvh_channels_take_the_small_euler_triple_and_stay_continuous():
    """An elbow bent past 90 degrees was written (180, -78, 180) in Z X Y, and an animation
    through 90 degrees jumped by 180 on Z and Y (X going -60 -> -90 -> -60 for a -60 -> -120
    bend): now (0, -102, 0), and the animation's X runs monotonically with Z = Y = 0."""
    from fourierjax.io.stance_bvh import pose_to_motion
    from fourierjax.kinematics import joint_positions
    from fourierjax.stance.skeleton48 import JOINT_NAMES

    m = pose_to_motion(BODY, _elbow_bent(-102.0))
    c = m.topology.channel_offsets[JOINT_NAMES.index("r_elbow")]
    np.testing.assert_allclose(m.channels[0, c:c + 3], [0.0, -102.0, 0.0], atol=1e-3)
    m = pose_to_motion(BODY, animate([_elbow_bent(-60.0), _elbow_bent(-120.0)], 10))
    zxy = m.channels[:, c:c + 3]
    np.testing.assert_allclose(zxy[:, [0, 2]], 0.0, atol=1e-3)
    assert zxy[0, 1] == pytest.approx(-60.0, abs=1e-3) and zxy[-1, 1] == pytest.approx(-120.0, abs=1e-3)
    assert (np.diff(zxy[:, 1]) < 0).all()
    # Any pose: the channels are the same rotations (FK of the BVH channels = the pose's FK).
    rng = np.random.default_rng(3)
    q = rng.normal(size=(2, len(JOINT_NAMES), 4))
    poses = StancePose(jnp.tile(BODY.offsets[0], (2, 1)), jnp.asarray(q / np.linalg.norm(q, axis=-1, keepdims=True)))
    m = pose_to_motion(BODY, poses)
    got = np.asarray(joint_positions(m.skeleton(), jnp.asarray(m.channels, jnp.float32)))
    for f in range(2):
        want = forward_kinematics(BODY.skeleton, BODY.offsets.at[0].set(poses.root_position[f]), poses.quats[f])
        np.testing.assert_allclose(got[f], np.asarray(want.positions), atol=2e-5)
