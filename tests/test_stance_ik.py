"""Lower-body analytic IK (Neff & Fiume 2004 appendix): planted feet, knee angles, numerical IK."""

import itertools

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from scipy.optimize import minimize, minimize_scalar
from scipy.spatial.transform import Rotation

from fourierjax.stance import ik as ikm
from fourierjax.stance.skeleton48 import (
    ANKLE,
    DOF_NAMES,
    HIP,
    KNEE,
    LEFT,
    RIGHT,
    StancePose,
    dof_vector,
    make_body,
    non_dof_components,
    pose_fk,
    rest_pose,
)

BODY = make_body(1.75)


def _pose(lb):
    qs = lb.quats()
    q = rest_pose(BODY).quats.at[0].set(qs["pelvis"])
    q = q.at[jnp.array(HIP)].set(qs["hips"]).at[jnp.array(KNEE)].set(qs["knees"])
    q = q.at[jnp.array(ANKLE)].set(qs["ankles"])
    return StancePose(lb.root_position, q)


def _run(dominant):
    def one(knees, bal, pelvis, width, turn, stagger):
        feet = ikm.make_feet(BODY, width, turn, stagger)
        lb = ikm.lower_body_ik(BODY, feet, knees, bal, pelvis, dominant)
        pose = _pose(lb)
        fk = pose_fk(BODY, pose)
        pos_err = jnp.max(jnp.abs(fk.positions[jnp.array(ANKLE)] - feet.positions))
        dotq = jnp.abs(jnp.sum(fk.rotations[jnp.array(ANKLE)] * feet.quats, axis=-1))
        return pos_err, jnp.max(1.0 - dotq), lb.free_foot_gap_m, dof_vector(pose), non_dof_components(pose)

    return jax.jit(jax.vmap(one))


HIP_SPREAD = 2 * 0.087 * 1.75 / 1.741


def _sweep(dominant):
    knees = [(0.0, 0.0), (0.4, 0.3), (0.9, 0.8), (0.3, 0.5), (1.2, 1.1)]
    pelvis = [(0.0, 0.0, 0.0), (0.2, -0.3, 0.1), (-0.15, 0.4, -0.12)]
    # Feet together, hip width (the hip vector lies in the plane: the near-in-plane case), wide.
    widths = [0.0, HIP_SPREAD, 0.55]
    bal = [(0.0, 0.0), (0.06, -0.03)]
    rows = list(itertools.product(knees, pelvis, widths, bal))
    cols = [np.array([r[i] for r in rows], np.float32) for i in range(4)]
    # Centre the root hip over the stance as the balance solve would (else a wide stance with
    # straight legs is out of reach): tilt the root ankle about Z toward the other foot.
    side = 1.0 if dominant == "right" else -1.0
    cols[3][:, 1] += side * (cols[2] - HIP_SPREAD) / 2 / 0.86
    n = len(rows)
    turn = np.tile(np.array([0.0, 0.25], np.float32), n // 2 + 1)[:n]
    stagger = np.tile(np.array([0.0, 0.12, -0.08], np.float32), n // 3 + 1)[:n]
    return cols + [turn, stagger]


@pytest.fixture(scope="module", params=["right", "left"])
def sweep(request):
    k, p, w, b, t, s = _sweep(request.param)
    out = _run(request.param)(k, b, p, w, t, s)
    return request.param, (k, p, w, b), [np.asarray(o) for o in out]


def test_feet_stay_planted_over_sweep(sweep):
    _, _, (pos_err, rot_err, gap, _, _) = sweep
    assert np.all(gap == 0.0)
    assert pos_err.max() <= 1e-4, pos_err.max()
    assert rot_err.max() <= 1e-5


def test_knees_take_desired_angles_and_only_dofs_move(sweep):
    _, (knees, _, _, _), (_, _, _, dofs, rest) = sweep
    ik = [DOF_NAMES.index("r_knee.Xrotation"), DOF_NAMES.index("l_knee.Xrotation")]
    np.testing.assert_allclose(dofs[:, ik], knees, atol=2e-5)
    assert np.abs(rest).max() < 1e-4  # no motion on non-DOF axes (ankle Y, knee Y/Z, ...)


def test_unreachable_free_foot_is_reported_without_nan():
    feet = ikm.make_feet(BODY, 0.9)  # straight legs cannot span a 0.9 m stance from upright
    lb = ikm.lower_body_ik(BODY, feet, jnp.zeros(2), jnp.zeros(2), jnp.zeros(3))
    assert float(lb.free_foot_gap_m) > 0.1
    assert all(np.isfinite(np.asarray(x)).all() for x in jax.tree.leaves(lb))
    g = jax.grad(lambda w: ikm.lower_body_ik(BODY, ikm.make_feet(BODY, w), jnp.zeros(2),
                                             jnp.zeros(2), jnp.zeros(3)).hips.sum())(0.9)
    assert np.isfinite(g)


def test_pose_builder_world_frames_and_com_match_forward_kinematics():
    """The pose builder places joints and sums the COM from world frames it builds along the way
    (no separate FK); check them against FK of its own local rotations, including a free foot
    the leg cannot reach (its ankle is then not on its mark)."""
    from fourierjax.stance.problem import build_pose, make_problem
    from fourierjax.stance.skeleton48 import center_of_mass

    for width in (None, 0.9):
        feet = ikm.make_feet(BODY, width)
        prob = make_problem(BODY, {"knee_right": 0.3, "gaze_weight": 0.7}, feet=feet,
                            target_right=jnp.array([-0.3, 1.2, 0.4]))
        pose, info = build_pose(prob, jnp.array([0.2, -0.1, 0.15, 0.1, -0.05, 0.0]), jnp.array([0.04, -0.03]))
        fk = pose_fk(BODY, pose)
        np.testing.assert_allclose(info.com, center_of_mass(BODY, fk), atol=2e-6)
        np.testing.assert_allclose(info.shoulders, np.asarray(fk.positions)[[6, 10]], atol=2e-6)
        np.testing.assert_allclose(info.wrists, np.asarray(fk.positions)[[8, 12]], atol=2e-6)
        assert (float(info.free_foot_gap) > 0.1) == (width is not None)


def _primitives(jaxpr) -> set[str]:
    """Names of the primitives in a jaxpr and every jaxpr nested in it."""
    from jax.extend.core import jaxprs_in_params

    names = set()
    for e in jaxpr.eqns:
        names.add(e.primitive.name)
        for sub in jaxprs_in_params(e.params):
            names |= _primitives(sub)
    return names


def test_pose_builder_can_be_traced_with_jit_disabled():
    """The solver traces the pose builder under `jax.disable_jit` (no nested jits to trace,
    `_pose.build_with_residual`), which is only safe while the builder holds no `lax` loop
    or conditional: with jit disabled those run in Python (a loop unrolled into the solver's
    program). And the numbers are the same."""
    from fourierjax.stance._pose import build_with_residual
    from fourierjax.stance.problem import build_rotations, make_problem

    prob = make_problem(BODY, {"knee_right": 0.3, "gaze_weight": 0.7},
                        target_right=jnp.array([-0.3, 1.2, 0.4]))
    a, b = jnp.array([0.2, -0.1, 0.15, 0.1, -0.05, 0.0]), jnp.array([0.04, -0.03])
    names = _primitives(jax.make_jaxpr(build_rotations)(prob, a, b).jaxpr)
    assert {"mul", "sin", "select_n"} <= names  # it looked inside
    assert not names & {"scan", "while", "cond", "switch"}, names
    jitted = jax.jit(build_rotations)(prob, a, b)
    _, built = jax.jit(build_with_residual)(prob, a, b)
    for x, y in zip(jax.tree.leaves(jitted), jax.tree.leaves(built), strict=True):
        np.testing.assert_allclose(x, y, rtol=1e-6, atol=1e-6)


def test_rest_pose_is_reproduced():
    feet = ikm.make_feet(BODY)
    lb = ikm.lower_body_ik(BODY, feet, jnp.zeros(2), jnp.zeros(2), jnp.zeros(3))
    np.testing.assert_allclose(lb.root_position, BODY.offsets[0], atol=1e-6)
    np.testing.assert_allclose(lb.hips, np.broadcast_to(np.eye(3), (2, 3, 3)), atol=1e-6)
    np.testing.assert_allclose(lb.ankles, np.broadcast_to(np.eye(3), (2, 3, 3)), atol=1e-6)


def _paper_free_hip(root_hip, free_ankle, W, C, b_des, near_tol=0.05):
    """The appendix's construction, literally: intersect (or project), then closest circle point."""
    A = free_ankle - root_hip
    nA = np.linalg.norm(A)
    Ah = A / nA
    a = (W * W - C * C + nA * nA) / (2 * nA)
    centre = root_hip + a * Ah
    r = np.sqrt(W * W - a * a)
    cosphi = float(b_des @ Ah)
    if abs(cosphi) < near_tol:  # hip vector in or near the plane: project its end point
        x = root_hip + W * b_des
        x = x - ((x - centre) @ Ah) * Ah
    else:  # extend the hip vector to the plane
        x = root_hip + (a / cosphi) * b_des
    d = x - centre
    return centre + r * d / np.linalg.norm(d)


def test_free_hip_matches_paper_construction(x64):
    rng = np.random.default_rng(0)
    for i in range(40):
        root_hip = np.array([-0.09, 0.9, 0.0]) + rng.normal(scale=0.03, size=3)
        free_ankle = np.array([rng.uniform(-0.1, 0.4), 0.07, rng.uniform(-0.15, 0.15)])
        W = 0.175
        C = np.linalg.norm(free_ankle - root_hip) + rng.uniform(-0.05, 0.05)
        yaw, roll = rng.uniform(-0.5, 0.5), rng.uniform(-0.3, 0.3)
        if i % 4 == 0:  # near-in-plane: hip vector perpendicular to side A
            A = free_ankle - root_hip
            b = np.cross(A, [0.0, 0.0, 1.0])
        else:
            b = Rotation.from_euler("YZ", [yaw, roll]).apply([1.0, 0.0, 0.0])
        b = b / np.linalg.norm(b)
        A = free_ankle - root_hip
        a = (W * W - C * C + A @ A) / (2 * np.linalg.norm(A))
        if i % 4 != 0 and a / (b @ A) <= 0:
            continue  # the paper extends the vector forward; behind is not a pose it meets
        ref = _paper_free_hip(root_hip, free_ankle, W, C, b)
        ours, gap = ikm.free_hip_position(
            jnp.asarray(root_hip), jnp.asarray(free_ankle), W, C, jnp.asarray(b)
        )
        assert float(gap) == 0.0
        np.testing.assert_allclose(ours, ref, atol=1e-9)


# ----------------------------------------------------------------- numerical IK reference


def _np_legs(x, off, knees):
    """Independent numpy FK of pelvis + legs from 16 unknowns (scipy Rotation)."""
    root, pel = x[0:3], Rotation.from_rotvec(x[3:6])
    out = {}
    for s, (hip, knee, ank) in enumerate(zip(HIP, KNEE, ANKLE)):
        hip_rot = Rotation.from_rotvec(x[6 + 3 * s : 9 + 3 * s])
        k = knees[s]
        ax, az = x[12 + 2 * s], x[13 + 2 * s]
        p_hip = root + pel.apply(off[hip])
        thigh = pel * hip_rot
        p_knee = p_hip + thigh.apply(off[knee])
        shin = thigh * Rotation.from_euler("X", k)
        p_ank = p_knee + shin.apply(off[ank])
        foot = shin * Rotation.from_euler("ZX", [az, ax])
        out[s] = (p_hip, p_ank, foot)
    return out, pel


def test_agrees_with_numerical_ik(x64):
    off = np.asarray(BODY.offsets, np.float64)
    cases = [
        ((0.5, 0.2), (0.04, -0.03), (0.1, 0.25, -0.08), 0.35, "right"),
        ((0.3, 0.9), (-0.02, 0.05), (-0.1, -0.3, 0.1), 0.5, "left"),
        ((0.0, 0.4), (0.0, 0.0), (0.05, 0.1, 0.05), 0.2, "right"),
    ]
    for knees, bal, pelvis, width, dominant in cases:
        feet = ikm.make_feet(BODY, width, 0.2, 0.1)
        lb = ikm.lower_body_ik(BODY, feet, jnp.array(knees), jnp.array(bal), jnp.array(pelvis), dominant)
        d = RIGHT if dominant == "right" else LEFT
        f = 1 - d
        fpos = np.asarray(feet.positions, np.float64)
        fq = [Rotation.from_quat(np.roll(np.asarray(q, np.float64), -1)) for q in feet.quats]
        # The spec of the root leg, restated: the knee bent as asked, the ankle at
        # Rz(bz) Rx(bx - beta), where beta makes the ankle->hip vector vertical at zero offsets
        # (the foot is planted, so the leg turns by the inverse of the ankle rotation).
        t, sh = -off[KNEE[d], 1], -off[ANKLE[d], 1]
        k = knees[d]
        beta = np.arctan2(t * np.sin(k), sh + t * np.cos(k))
        root_ankle = np.array([bal[0] - beta, bal[1]])
        R_des = Rotation.from_matrix(np.asarray(ikm.pelvis_frame_desired(feet, jnp.array(pelvis)), np.float64))
        sign = 1.0 if f == LEFT else -1.0
        b_des = sign * R_des.apply([1.0, 0, 0])
        up_des = R_des.apply([0, 1.0, 0])

        def cons(x):
            legs, pel = _np_legs(x, off, knees)
            c = [x[12 + 2 * d : 14 + 2 * d] - root_ankle]
            for s in (0, 1):
                c.append(legs[s][1] - fpos[s])
                c.append((fq[s].inv() * legs[s][2]).as_rotvec())
            return np.concatenate(c)

        def hipdir(x):
            legs, _ = _np_legs(x, off, knees)
            v = legs[f][0] - legs[d][0]
            return v / np.linalg.norm(v)

        # Start from a perturbed analytic solution.
        def m2rv(m):
            return Rotation.from_matrix(np.asarray(m, np.float64)).as_rotvec()

        x0 = np.concatenate([
            np.asarray(lb.root_position, np.float64), m2rv(lb.pelvis),
            m2rv(lb.hips[0]), m2rv(lb.hips[1]), np.zeros(4),
        ])  # fmt: skip
        eul = [Rotation.from_matrix(np.asarray(m, np.float64)).as_euler("ZXY") for m in lb.ankles]
        x0[12:16] = [eul[0][1], eul[0][0], eul[1][1], eul[1][0]]
        x_ref = x0.copy()
        x0 = x0 + np.random.default_rng(1).normal(scale=0.03, size=16)
        assert np.abs(cons(x_ref)).max() < 1e-5  # the analytic solution meets the constraints
        bounds = [(v - 0.3, v + 0.3) for v in x_ref]
        st1 = minimize(lambda x: -hipdir(x) @ b_des, x0, method="SLSQP", bounds=bounds,
                       constraints=[{"type": "eq", "fun": cons}], options={"maxiter": 500, "ftol": 1e-14})  # fmt: skip
        np.testing.assert_allclose(-st1.fun, hipdir(x_ref) @ b_des, atol=1e-8)  # same optimum
        assert np.abs(cons(st1.x)).max() < 1e-6
        x = st1.x
        # Second criterion (pelvic X): with the hips where the first put them, the pelvis may
        # still turn about the hip axis (the legs keep their world orientation); take the turn
        # whose up vector is closest to the desired one (Brent on one angle).
        legs, pel = _np_legs(x, off, knees)
        axis = hipdir(x)
        thighs = [pel * Rotation.from_rotvec(x[6 + 3 * s_ : 9 + 3 * s_]) for s_ in (0, 1)]
        turn = lambda psi: Rotation.from_rotvec(psi * axis) * pel  # noqa: E731
        psi = minimize_scalar(lambda p: -turn(p).apply([0, 1.0, 0]) @ up_des, bounds=(-1, 1),
                              method="bounded", options={"xatol": 1e-10}).x  # fmt: skip
        for s_ in (0, 1):  # hip rotations agree (angle between them)
            ra = turn(psi).inv() * thighs[s_]
            rb = Rotation.from_matrix(np.asarray(lb.hips[s_], np.float64))
            assert (ra.inv() * rb).magnitude() < 1e-4, (dominant, s_)
        np.testing.assert_allclose(legs[f][0], np.asarray(lb.hip_positions[f]), atol=1e-5)
        np.testing.assert_allclose(x[12:16], x_ref[12:16], atol=2e-3)  # ankles


def test_dof_vector_reads_flexion_past_90_degrees():
    """ZXY Euler angles keep the middle (X) angle within +-90 degrees: a knee flexed 1.8 rad read
    as 1.34 with pi on Z and Y, an elbow at -2.0 as -1.14. Of the two Euler triples the one with
    zero non-DOF components is taken now."""
    from fourierjax import rotations
    from fourierjax.stance.skeleton48 import DOF_NAMES, DOFS, JOINT_NAMES, ROTATION_ORDER, StancePose, rest_pose

    def x_rot(a):
        return jnp.array([np.cos(a / 2), np.sin(a / 2), 0.0, 0.0], jnp.float32)

    p = rest_pose(BODY)
    q = p.quats.at[JOINT_NAMES.index("r_elbow")].set(x_rot(-2.0)).at[JOINT_NAMES.index("l_knee")].set(x_rot(1.8))
    # A 3-DOF joint with a large rotation: its three angles must give back the same rotation.
    shoulder = rotations.quat_from_euler(jnp.array([0.4, 2.2, -0.7]), ROTATION_ORDER)
    q = q.at[JOINT_NAMES.index("r_shoulder")].set(shoulder)
    pose = StancePose(p.root_position, q)
    dv = dict(zip(DOF_NAMES, np.asarray(dof_vector(pose)).tolist(), strict=True))
    assert dv["r_elbow.Xrotation"] == pytest.approx(-2.0, abs=1e-5)
    assert dv["l_knee.Xrotation"] == pytest.approx(1.8, abs=1e-5)
    assert float(jnp.max(jnp.abs(non_dof_components(pose)))) < 1e-5
    sh = jnp.array([dv[f"r_shoulder.{a}rotation"] for a in ROTATION_ORDER])
    back = rotations.quat_from_euler(sh, ROTATION_ORDER)
    assert abs(float(jnp.dot(back, q[JOINT_NAMES.index("r_shoulder")]))) == pytest.approx(1.0, abs=1e-6)
    assert DOFS["r_shoulder"] == "ZXY"


@pytest.mark.parametrize("width, stagger", [(0.9, 0.0), (0.6, 0.6)])
def test_unreachable_free_foot_misses_by_the_reported_gap(width, stagger):
    """With a plant the free leg cannot reach, its leg must point at it and miss by exactly
    `free_foot_gap_m`; it was turned ~20 degrees off (441 mm off the plant for a 294 mm gap)."""
    from fourierjax.stance.ik import make_feet
    from fourierjax.stance.problem import build_pose, make_problem
    from fourierjax.stance.skeleton48 import JOINT_NAMES

    feet = make_feet(BODY, width, 0.0, stagger)
    prob = make_problem(BODY, {"knee_left": 0.8, "weight_shift": -0.5}, feet=feet)
    pose, info = build_pose(prob, jnp.zeros(6), jnp.zeros(2))
    p = np.asarray(pose_fk(BODY, pose).positions)
    plants = np.asarray(feet.positions)
    gap = float(info.free_foot_gap)
    assert gap > 0.1
    miss = np.linalg.norm(p[JOINT_NAMES.index("l_ankle")] - plants[LEFT])
    assert miss == pytest.approx(gap, abs=1e-4)
    assert np.linalg.norm(p[JOINT_NAMES.index("r_ankle")] - plants[RIGHT]) < 1e-5  # the root foot stays
