"""Bad input to the stance API is refused naming the function and argument; traced values pass."""

import itertools

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from fourierjax import rotations
from fourierjax.errors import UserError
from fourierjax.io.stance_bvh import animate, write_stance_bvh
from fourierjax.stance import _util as u
from fourierjax.stance.fit import fit_torso, torso_directions
from fourierjax.stance.ik import Feet, lower_body_ik, make_feet
from fourierjax.stance.problem import BEND_MAX_RAD, BEND_MIN_RAD, SHAPE_PARAMS, P, make_problem
from fourierjax.stance.shape_sets import get_shape_set
from fourierjax.stance.skeleton48 import StancePose, make_body, rest_pose

BODY = make_body(1.75)
NAN, INF = float("nan"), float("inf")


def _turned(feet: Feet, yaw: float) -> Feet:
    """`feet` turned as a rigid pair by `yaw` about +Y (the character facing elsewhere)."""
    R = np.asarray(u.rot(1, jnp.asarray(yaw, jnp.float32)))
    q = rotations.quat_multiply(u.quat_axis(1, jnp.asarray(yaw, jnp.float32)), feet.quats)
    return Feet(jnp.asarray(np.asarray(feet.positions) @ R.T, jnp.float32), q)


def _crossed(width: float) -> Feet:
    """Feet facing +Z with the right foot `width` m to the LEFT (+X) of the left foot."""
    f = make_feet(BODY, 0.0)
    return Feet(f.positions.at[:, 0].set(jnp.array([0.5 * width, -0.5 * width])), f.quats)


# --- make_feet ---------------------------------------------------------------------------


@pytest.mark.parametrize(
    "kwargs, match",
    [
        ({"stance_width_m": -0.02}, "make_feet: stance_width_m must be >= 0"),
        ({"stance_width_m": -0.3}, "crossed feet turn the body around"),
        ({"stance_width_m": NAN}, "make_feet: stance_width_m must be finite, got nan"),
        ({"stance_width_m": INF}, "make_feet: stance_width_m must be finite"),
        ({"stagger_m": INF}, "make_feet: stagger_m must be finite, got inf"),
        ({"stagger_m": NAN}, "make_feet: stagger_m must be finite"),
        ({"turn_out_rad": NAN}, "make_feet: turn_out_rad must be finite"),
        ({"stance_width_m": [0.1, 0.2]}, r"make_feet: stance_width_m must be a single number, got shape \(2,\)"),
        ({"turn_out_rad": "out"}, "make_feet: turn_out_rad must be a number"),
    ],
)
def test_make_feet_refuses_bad_values(kwargs, match):
    """A negative width used to cross the feet (the solver then turned the body by 180
    degrees, converged=True); NaN/inf gave a NaN pose."""
    with pytest.raises(UserError, match=match):
        make_feet(BODY, **kwargs)


def test_make_feet_accepts_zero_width_and_traced_values():
    np.testing.assert_allclose(make_feet(BODY, 0.0).positions[:, 0], 0.0)
    make_feet(BODY, -0.0)
    # Traced widths cannot be checked and pass (sweeps and gradients over the stance).
    pos = jax.vmap(lambda w, t, s: make_feet(BODY, w, t, s).positions)(
        jnp.array([-0.1, 0.2]), jnp.array([NAN, 0.1]), jnp.array([0.0, 0.1])
    )
    assert pos.shape == (2, 2, 3)
    np.testing.assert_allclose(jax.grad(lambda w: make_feet(BODY, w).positions[1, 0])(0.2), 0.5)


YAWS = [0.0, 0.7, np.pi / 2, 2.5, np.pi, -np.pi / 2]


# --- make_problem: feet ------------------------------------------------------------------


@pytest.mark.parametrize(
    "feet, match",
    [
        (Feet(make_feet(BODY).positions.at[0, 2].set(NAN), make_feet(BODY).quats),
         r"make_problem: feet\.positions holds NaN"),
        (Feet(make_feet(BODY).positions, make_feet(BODY).quats.at[1, 0].set(INF)),
         r"make_problem: feet\.quats holds NaN or infinite"),
        (Feet(make_feet(BODY).positions[:1], make_feet(BODY).quats),
         r"feet\.positions must have shape \(2, 3\), got \(1, 3\)"),
        (Feet(make_feet(BODY).positions, 2.0 * make_feet(BODY).quats),
         r"feet\.quats must be unit quaternions"),
        ("wide", "make_problem: feet must be a Feet"),
    ],
)
def test_make_problem_checks_feet(feet, match):
    with pytest.raises(UserError, match=match):
        make_problem(BODY, feet=feet)


@pytest.mark.parametrize("yaw", YAWS)
@pytest.mark.parametrize("width", [0.3, 0.02, 1e-5])
def test_make_problem_refuses_crossed_feet_facing_any_way(width, yaw):
    """Crossed feet made the pelvis, square to the right->left ankle line, face away from the
    toes: the body stood turned around on its feet and the solve still converged."""
    with pytest.raises(UserError, match="make_problem: feet are crossed: the right foot"):
        make_problem(BODY, feet=_turned(_crossed(width), yaw))


LEGAL_FEET = [
    (width, turn_out, stagger, yaw)
    for width, turn_out, stagger in [(None, 0.0, 0.0), (0.0, 0.0, 0.0), (0.0, 0.3, 0.25), (0.3, 0.4, -0.1),
                                     (0.6, np.pi / 2, 0.0), (0.2, 1.2, 0.3)]
    for yaw in YAWS
    # Both ankles at one point: the IK faces the pelvis +Z, so such feet must face forward
    # (see the next test).
    if not (width == 0.0 and stagger == 0.0 and np.cos(yaw) < 0.0)
]


@pytest.mark.parametrize("width, turn_out, stagger, yaw", LEGAL_FEET)
def test_make_problem_accepts_feet_that_are_not_crossed(width, turn_out, stagger, yaw):
    """Zero width, stagger, turn-out up to 90 degrees, and the feet turned together by any yaw
    (pi included: the character then faces -Z) are legal."""
    make_problem(BODY, feet=_turned(make_feet(BODY, width, turn_out, stagger), yaw))


def test_turn_out_beyond_90_degrees_is_crossed_feet_turned_around():
    """Each foot turned out by pi is the crossed stance turned by 180 degrees (same pose), so
    it is refused too; with both ankles at one point the pelvis faces +Z whatever the feet do,
    and feet pointing backwards there are refused."""
    with pytest.raises(UserError, match="feet are crossed"):
        make_problem(BODY, feet=make_feet(BODY, 0.17, turn_out_rad=np.pi))
    with pytest.raises(UserError, match=r"\+Z when the ankles coincide"):
        make_problem(BODY, feet=_turned(make_feet(BODY, 0.0), np.pi))


def test_crossed_feet_check_agrees_with_the_ik():
    """The check refuses exactly the feet for which the lower-body IK's pelvis faces away from
    where the toes point (the 180-degree flip the audit found)."""
    cases = list(itertools.product([-0.3, -0.02, 0.02, 0.3], [0.0, 1.0, 2.2], [0.0, 0.2], [0.0, 2.0, np.pi]))
    feet = []
    for width, turn, stagger, yaw in cases:
        f = make_feet(BODY, abs(width), turn, stagger)
        if width < 0:
            f = Feet(f.positions.at[:, 0].multiply(-1.0), f.quats)
        feet.append(_turned(f, yaw))
    stacked = jax.tree.map(lambda *xs: jnp.stack(xs), *feet)

    def pelvis_forward_dot_toes(f):
        lb = lower_body_ik(BODY, f, jnp.full(2, 0.1), jnp.zeros(2), jnp.zeros(3))
        toes = rotations.matrix_from_quat(f.quats)[:, :, 2].sum(axis=0)
        return lb.pelvis[0, 2] * toes[0] + lb.pelvis[2, 2] * toes[2]

    dots = np.asarray(jax.jit(jax.vmap(pelvis_forward_dot_toes))(stacked))
    for case, f, dot in zip(cases, feet, dots):
        assert abs(dot) > 0.1, case  # no borderline cases in the sweep
        try:
            make_problem(BODY, feet=f)
            refused = False
        except UserError:
            refused = True
        assert refused == (dot < 0.0), (case, dot)


def test_traced_feet_are_not_checked():
    crossed = _crossed(0.2)
    probs = jax.vmap(lambda p: make_problem(BODY, feet=Feet(p, crossed.quats)))(
        jnp.stack([crossed.positions, crossed.positions])
    )
    assert probs.feet.positions.shape == (2, 2, 3)


def test_known_feet_are_checked_under_an_outer_jit():
    crossed, good = _crossed(0.2), make_feet(BODY, 0.2, 0.3)
    f = jax.jit(lambda a: make_problem(BODY, {"sagittal": a}, feet=crossed).shape)
    with pytest.raises(UserError, match="feet are crossed"):
        f(0.5)
    assert jax.jit(lambda a: make_problem(BODY, {"sagittal": a}, feet=good).shape)(0.5).shape == (len(SHAPE_PARAMS),)


# --- make_problem: amplitude_scale, reach_weight -----------------------------------------


@pytest.mark.parametrize(
    "kwargs, match",
    [
        ({"amplitude_scale": 0.0}, "make_problem: amplitude_scale must be > 0, got 0"),
        ({"amplitude_scale": -1.0}, "make_problem: amplitude_scale must be > 0, got -1"),
        ({"amplitude_scale": NAN}, "make_problem: amplitude_scale holds NaN"),
        ({"amplitude_scale": INF}, "make_problem: amplitude_scale holds NaN or infinite"),
        ({"amplitude_scale": 1e-40}, r"make_problem: amplitude_scale=\S+: slopes holds NaN or infinite"),
        ({"amplitude_scale": [0.1, 0.2]}, "make_problem: amplitude_scale must be a single number"),
        ({"reach_weight": NAN}, "make_problem: reach_weight holds NaN"),
        ({"reach_weight": -5.0}, "make_problem: reach_weight must be >= 0, got -5"),
        ({"reach_weight": "high"}, "make_problem: reach_weight must be numbers"),
    ],
)
def test_make_problem_checks_penalty_settings(kwargs, match):
    """A zero scale or a NaN weight used to give a NaN objective (NaN reach weight even
    without a target: 0 * NaN)."""
    with pytest.raises(UserError, match=match):
        make_problem(BODY, {"sagittal": 0.5}, **kwargs)


def test_penalty_settings_allowed_values_and_tracing():
    p = make_problem(BODY, target_right=[-0.3, 1.0, 0.4], reach_weight=0.0)  # arm IK only
    np.testing.assert_array_equal(p.reach_weights, 0.0)
    d = jax.jacfwd(lambda a: make_problem(BODY, amplitude_scale=a).amplitude_penalty.widths.sum())(0.25)
    assert np.isfinite(d) and d > 0
    w = jax.vmap(lambda r: make_problem(BODY, reach_weight=r).reach_weights)(jnp.array([-1.0, 2.0]))
    assert w.shape == (2, 2)


# --- shape sets ----------------------------------------------------------------------------


def test_huge_intensity_is_refused_when_the_shape_vector_overflows():
    """1e30 passed the finiteness check but the (squared) knee curves overflowed to inf."""
    s = get_shape_set("posture")
    with pytest.raises(UserError, match=r"shape set 'posture': intensity 1e\+30 gives a shape vector "
                                        r"with infinite or NaN values in \['knee_right', 'knee_left'\]"):
        s.problem(BODY, 1e30)
    assert np.isfinite(np.asarray(get_shape_set("beauty_line").problem(BODY, 5.0).shape)).all()
    probs = jax.vmap(lambda i: s.problem(BODY, i))(jnp.array([0.5, 1e30]))  # traced: not checked
    assert probs.shape.shape == (2, len(SHAPE_PARAMS))


def test_knee_bends_past_a_knee_range_are_refused():
    """The posture set's late knee curve grows as the square of the intensity: at 1.8 it asked
    for 180 degrees (the thighs lay on the shins), at 2.0 for 246 (the IK bent the knee
    backwards), each solved with converged=True. Refused now, naming the knee and the value."""
    s = get_shape_set("posture")
    assert float(s.problem(BODY, 1.5).shape[P["knee_right"]]) < BEND_MAX_RAD  # 102 degrees: fine
    with pytest.raises(UserError, match=r"shape set 'posture': intensity 1\.8: knee_right = 3\.150 rad "
                                        r"\(180 degrees\) is past a knee's range"):
        s.problem(BODY, 1.8)
    with pytest.raises(UserError, match=r"make_problem: shape: knee_left = 3\.000 rad"):
        make_problem(BODY, {"knee_left": 3.0})
    make_problem(BODY, {"knee_left": BEND_MAX_RAD})  # the bound itself is allowed
    # Traced intensities are not checked (no values to read).
    probs = jax.vmap(lambda i: s.problem(BODY, i))(jnp.array([1.0, 2.0]))
    assert float(probs.shape[1, P["knee_right"]]) > BEND_MAX_RAD


def test_joints_bent_backwards_are_refused():
    """A knee bend of -0.3 was solved as a knee bent 17 degrees backwards and an elbow bend of
    -0.3 as a 17-degree hyperextension, both converged=True. Refused below BEND_MIN_RAD, and
    elbows past BEND_MAX_RAD too."""
    with pytest.raises(UserError, match=r"make_problem: shape: knee_right = -0\.300 rad \(-17 degrees\) is "
                                        r"past a knee's range \(-0\.1 to 2\.6 rad.*bend backwards"):
        make_problem(BODY, {"knee_right": -0.3})
    with pytest.raises(UserError, match=r"elbow_left = -0\.300 rad \(-17 degrees\) is past an elbow's range"):
        make_problem(BODY, {"elbow_left": -0.3})
    with pytest.raises(UserError, match=r"elbow_right = 3\.000 rad .*fold onto itself"):
        make_problem(BODY, {"elbow_right": 3.0})
    make_problem(BODY, {"knee_right": BEND_MIN_RAD, "elbow_left": BEND_MIN_RAD})  # the bound is allowed


def test_intensity_must_be_one_number():
    with pytest.raises(UserError, match=r"shape set 'posture': intensity must be a single number, got shape \(2,\)"):
        get_shape_set("posture").problem(BODY, [0.1, 0.2])


def test_shape_set_problem_checks_feet():
    with pytest.raises(UserError, match="feet are crossed"):
        get_shape_set("posture").problem(BODY, 0.5, feet=_crossed(0.1))


# --- fit_torso -----------------------------------------------------------------------------


def _dirs():
    return torso_directions(BODY, jnp.zeros(6), jnp.zeros(4), jnp.zeros(4), jnp.ones(2))


@pytest.mark.parametrize(
    "dirs, match",
    [
        (jnp.full((6, 3), jnp.nan), r"fit_torso: target_dirs holds NaN or infinite values for \['abdomen'"),
        (_dirs().at[4, 1].set(jnp.inf), r"target_dirs holds NaN or infinite values for \['r_collar'\]"),
        (_dirs()[:5], r"fit_torso: target_dirs must have shape \(6, 3\).*got shape \(5, 3\)"),
        (_dirs().reshape(-1), r"target_dirs must have shape \(6, 3\)"),
        (2.0 * _dirs(), r"fit_torso: target_dirs must be unit directions.*abdomen \(2\)"),
        ("up", "fit_torso: target_dirs must be numbers"),
    ],
)
def test_fit_torso_checks_its_input(dirs, match):
    """NaN directions used to give a confident class combination with amplitudes 0 and rms
    NaN; a (5, 3) input a raw TypeError."""
    with pytest.raises(UserError, match=match):
        fit_torso(BODY, dirs)


def test_fit_torso_checks_known_input_under_an_outer_jit():
    nan = np.full((6, 3), np.nan)
    with pytest.raises(UserError, match="target_dirs holds NaN"):
        jax.jit(lambda a: fit_torso(BODY, nan).amplitudes + a)(0.5)


# --- BVH export ----------------------------------------------------------------------------


def test_write_stance_bvh_to_a_missing_directory(tmp_path):
    path = tmp_path / "no" / "such" / "pose.bvh"
    with pytest.raises(UserError, match=f"write_stance_bvh: cannot write {path}"):
        write_stance_bvh(path, BODY, rest_pose(BODY))
    assert not path.parent.exists()  # not created (as io.bvh.write_bvh)


@pytest.mark.parametrize("n", [2.5, 0, -1, True, "3", 3.0])
def test_animate_wants_a_whole_number_of_frames(n):
    a = rest_pose(BODY)
    with pytest.raises(UserError, match="animate: frames_per_transition must be a whole number >= 1"):
        animate([a, a], n)


def test_animate_accepts_numpy_integers():
    a = rest_pose(BODY)
    b = StancePose(a.root_position + jnp.array([0.0, 0.0, 0.1]), a.quats)
    assert animate([a, b], np.int64(3)).quats.shape[0] == 4


def test_stack_problems_names_what_cannot_be_stacked():
    from fourierjax.stance.problem import make_problem
    from fourierjax.stance.skeleton48 import make_body
    from fourierjax.stance.solver import stack_problems

    body = make_body(1.75)
    right, left = make_problem(body), make_problem(body, dominant="left")
    assert stack_problems([right, right]).shape.shape == (2, right.shape.shape[0])
    with pytest.raises(UserError, match="no problems"):
        stack_problems([])
    with pytest.raises(UserError, match="problem 1 is a dict"):
        stack_problems([right, {}])
    with pytest.raises(UserError, match=r"problem 1 differs .*'left' vs 'right'"):
        stack_problems([right, left])
