"""The stance solver: balance and reach accuracy on batched sweeps, the direction-set reference,
implicit gradients (Neff & Fiume 2004, secs. 4-6)."""

import time

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from experiments.benchmarks.stance_reference import solve_reference
from fourierjax.errors import UserError
from fourierjax.stance.balance import inside_polygon_margin, monitor_points_world, support_polygon
from fourierjax.stance.problem import desired_balance_point
from fourierjax.stance.shape_sets import get_shape_set
from fourierjax.stance.skeleton48 import ANKLE, DOF_NAMES, dof_vector, make_body, pose_fk
from fourierjax.stance.solver import solve_stances, stack_problems

BODY = make_body(1.75)
OBJECT = jnp.array([0.35, 1.3, 0.55])  # in front, to the character's left
POSTURE = jnp.array([-1.0, -0.5, 0.0, 0.5, 1.0])
RECOIL = [0.25, 0.5, 0.75, 1.0]
REACHABLE = jnp.array([-0.35, 1.05, 0.55])  # right hand, in front: needs some lean
UNREACHABLE = jnp.array([-0.4, 1.2, 2.5])


def _problems():
    posture = get_shape_set("posture")
    # The posture sweep is one vmap over the intensity knob.
    sweep = jax.vmap(lambda i: posture.problem(BODY, i))(POSTURE)
    recoil = get_shape_set("strong_recoil")
    rec = [recoil.problem(BODY, i, OBJECT) for i in RECOIL]
    reach = [posture.problem(BODY, 0.3, target_right=t) for t in (REACHABLE, UNREACHABLE)]
    rest = stack_problems(rec + reach)
    return jax.tree.map(lambda a, b: jnp.concatenate([a, b]), sweep, rest)


@pytest.fixture(scope="module")
def solved():
    problems = _problems()
    sol = solve_stances(problems)  # one batched call for all 11 problems
    return problems, sol


def _row(tree, i):
    return jax.tree.map(lambda a: a[i], tree)


def test_all_converge_and_balance_within_1mm(solved):
    _, sol = solved
    assert np.all(np.asarray(sol.converged))
    assert float(np.max(sol.com_error_m)) < 1e-3, np.asarray(sol.com_error_m)


def test_balance_point_inside_support_polygon_and_feet_planted(solved):
    problems, sol = solved
    for i in range(len(sol.objective)):
        prob, pose = _row(problems, i), _row(sol.pose, i)
        fk = pose_fk(BODY, pose)
        np.testing.assert_allclose(fk.positions[jnp.array(ANKLE)], prob.feet.positions, atol=1e-4)
        mon = np.asarray(monitor_points_world(BODY, prob.feet))[..., [0, 2]].reshape(-1, 2)
        goal = np.asarray(desired_balance_point(prob))
        assert inside_polygon_margin(support_polygon(mon), goal) > 0.0


def test_reach_met_and_unreachable_reported(solved):
    _, sol = solved
    reach_err, gap = np.asarray(sol.reach_error_m), np.asarray(sol.reach_gap_m)
    assert reach_err[9, 0] < 1e-3 and gap[9, 0] == 0.0
    assert gap[10, 0] > 0.5 and np.isfinite(reach_err[10, 0])
    pose = _row(sol.pose, 10)
    fk = pose_fk(BODY, pose)
    sh, wr = np.asarray(fk.positions[6]), np.asarray(fk.positions[8])
    d, c = wr - sh, np.asarray(UNREACHABLE) - sh
    assert d @ c / np.linalg.norm(d) / np.linalg.norm(c) > 0.999  # the arm points at it
    assert np.all(np.isfinite(np.asarray(sol.pose.quats)))


def test_posture_scale_shape(solved):
    _, sol = solved
    dofs = np.asarray(jax.vmap(dof_vector)(_row(sol.pose, slice(0, 5))))
    knee = dofs[:, DOF_NAMES.index("r_knee.Xrotation")]
    np.testing.assert_allclose(knee[:4], 0.0, atol=1e-6)  # straight legs until near the end
    assert knee[4] > 0.3
    chest = dofs[:, DOF_NAMES.index("chest.Xrotation")]
    assert chest[4] > 0.1 and chest[0] > 0.0  # hunched Large C; over-erect Small S (chest +)
    ab = dofs[:, DOF_NAMES.index("abdomen.Xrotation")]
    assert ab[0] < -0.1 and ab[4] > 0.1  # the sagittal class switches as the amplitude passes 0
    # Intensity 0 is the neutral pose: upper body at rest (the legs lean only to balance).
    upper = [k for k, n in enumerate(DOF_NAMES) if not n.startswith(("pelvis", "r_hip", "l_hip",
                                                                       "r_ankle", "l_ankle"))]
    np.testing.assert_allclose(dofs[2, upper], 0.0, atol=1e-5)


def test_recoil_leans_away_from_the_object(solved):
    _, sol = solved
    com_goal_x = []
    for i in range(5, 9):
        com_goal_x.append(float(sol.amplitudes[i, 1]))  # coronal amplitude
    # Object on the left (+X): lean right (positive coronal), growing with the intensity.
    assert np.all(np.diff(com_goal_x) > 0) and com_goal_x[0] > 0


def test_gradient_solver_no_worse_than_direction_set(solved):
    problems, sol = solved
    rows, ref_seconds = [], 0.0
    for i in range(len(sol.objective)):
        ref = solve_reference(_row(problems, i))
        ours = float(sol.objective[i])
        ref_seconds += ref["seconds"]
        rows.append((ours, ref["objective"], int(sol.iterations[i]), ref["iterations"],
                     ref["evaluations"]))  # fmt: skip
        assert ours <= ref["objective"] + 1e-5 * (1.0 + abs(ref["objective"])), (i, ours, ref)
    # Throughput, for the report only (tests never assert times).
    t0 = time.perf_counter()
    jax.block_until_ready(solve_stances(problems))
    ours_seconds = time.perf_counter() - t0
    n = len(rows)
    print(f"\nstance solver, {n} problems: ours {n / ours_seconds:.1f} solves/s (one batched "
          f"call), direction-set reference {n / ref_seconds:.1f} solves/s")
    print("  ours objective, reference objective, BFGS steps, direction-set sweeps, evaluations")
    for r in rows:
        print("  {:.6g}  {:.6g}  {}  {}  {}".format(*r))


def test_batch_strategies_agree_and_bad_batch_size_is_refused(solved):
    """The default (one by one on CPU), vmapped and chunked batches solve the same problems."""
    problems, sol = solved
    part = jax.tree.map(lambda a: a[-3:], problems)  # two recoil problems and the reach ones
    ref = jax.tree.map(lambda a: a[-3:], sol)
    for batch_size in (None, 2):
        other = solve_stances(part, batch_size=batch_size)
        np.testing.assert_allclose(other.objective, ref.objective, rtol=1e-4, atol=1e-6)
        np.testing.assert_allclose(other.com_error_m, ref.com_error_m, atol=1e-4)
    for bad in (0, -1, 2.5, "fast"):
        with pytest.raises(UserError, match="batch_size"):
            solve_stances(part, batch_size=bad)


def test_gaze_straight_up_or_down_keeps_the_balance():
    # Looking straight up, world up x forward vanishes: the head's twist once jumped with the
    # tiny head moves of the balance solve, which then missed the goal by 4.3 mm while
    # reporting converged. The neck's side axis is blended in near vertical.
    from fourierjax.stance.gaze import gaze_rotation
    from fourierjax.stance.problem import make_problem
    from fourierjax.stance.solver import solve_stance

    body = make_body(1.75)
    head = np.array([0.0, 1.6044, 0.0655])
    for offset in ([0, 2, 0], [0, 2, 0.001], [0, -2, 0], [0, 2, 0.2]):
        sol = solve_stance(make_problem(body, {"gaze_weight": 1.0}, gaze_point=head + np.array(offset)))
        assert bool(sol.converged) and float(sol.com_error_m) < 1e-6, offset
    # The look-at frame is continuous through vertical: a 1e-4 rad change of the gaze
    # direction near straight up turns the head by about as much, not by a large twist.
    R_neck = jnp.eye(3)

    def look(x):
        return gaze_rotation(jnp.eye(3), R_neck, jnp.zeros(3), jnp.array([x, 1.0, 0.0]), 1.0)

    a, b = look(1e-4), look(-1e-4)
    assert float(jnp.max(jnp.abs(a - b))) < 1e-3
    # Away from vertical nothing changes: up to world up, side = up x forward.
    R = gaze_rotation(jnp.eye(3), R_neck, jnp.zeros(3), jnp.array([1.0, 0.2, 1.0]), 1.0)
    fwd = np.array([1.0, 0.2, 1.0]) / np.linalg.norm([1.0, 0.2, 1.0])
    side = np.cross([0.0, 1.0, 0.0], fwd)
    np.testing.assert_allclose(R[:, 0], side / np.linalg.norm(side), atol=1e-6)
    np.testing.assert_allclose(R[:, 2], fwd, atol=1e-6)


def test_balance_newton_damps_a_diverging_step():
    """Newton on r = arctan(x - a) (a = 2) from 0 diverges undamped (steps unclipped here:
    0 -> 5.54 -> -11.9 -> ...); the damped solve reaches the root x = a, and its tangents
    (dr/da = -1, dr/dx = 1 there) describe the point it returns. The second unknown is a
    decoupled r = y."""
    from fourierjax.stance.balance import newton_2d_with_tangents

    def fn(a, x):
        return jnp.stack([jnp.arctan(x[0] - a[0]), x[1]]), x[0] ** 2

    x, (r, aux), (dr, daux) = newton_2d_with_tangents(
        fn, jnp.array([2.0]), jnp.zeros(2), jnp.eye(1), max_step=100.0
    )
    np.testing.assert_allclose(np.asarray(x), [2.0, 0.0], atol=1e-6)
    assert float(jnp.max(jnp.abs(r))) < 1e-6
    np.testing.assert_allclose(float(aux), float(x[0]) ** 2, rtol=1e-6)
    # Rows: along the direction in a, then along x0 and x1.
    np.testing.assert_allclose(np.asarray(dr), [[-1.0, 0.0], [1.0, 0.0], [0.0, 1.0]], atol=1e-6)
    np.testing.assert_allclose(np.asarray(daux), [0.0, 2 * float(x[0]), 0.0], rtol=1e-6, atol=1e-7)


def test_random_posture_reaches_its_balance():
    # A random shape vector whose balance root lies past a sign change of the balance
    # Jacobian: five undamped Newton evaluations left the COM 73 mm off its goal
    # (converged=False for a feasible pose); the damped solve reaches round-off.
    from fourierjax.stance.problem import make_problem
    from fourierjax.stance.solver import solve_stance

    shape = {"sagittal": 0.998, "coronal": 0.907, "transverse": 0.335, "collar_y": -0.389,
             "collar_z": 0.256, "abdomen_x": -0.304, "knee_right": 1.216, "knee_left": 0.206,
             "pelvis_x": -0.075, "pelvis_y": 0.682, "pelvis_z": -0.091, "weight_shift": 0.202,
             "forward_shift": -0.803, "elbow_right": 0.43, "elbow_left": 0.909,
             "arm_out_right": 0.314, "arm_out_left": -0.27, "swivel_right": 0.034,
             "swivel_left": 0.55, "gaze_weight": 0.787}  # fmt: skip
    sol = solve_stance(make_problem(BODY, shape, gaze_point=[-1.047, 1.277, 0.109]))
    assert bool(sol.converged)
    assert float(sol.com_error_m) < 1e-6


def test_converged_requires_the_balance(monkeypatch):
    # One Newton evaluation cannot solve the balance of a shifted weight: BFGS may still meet
    # its tolerances, but the solution must not claim convergence with the COM off its goal.
    from fourierjax.stance import _pose
    from fourierjax.stance import problem as P
    from fourierjax.stance import solver as S

    prob = P.make_problem(make_body(1.75), {"weight_shift": 0.6})
    monkeypatch.setattr(_pose, "BALANCE_EVALUATIONS", 1)  # where the balance solve reads it
    jax.clear_caches()  # inner jits (optimistix's) would reuse a trace with 5 evaluations
    try:
        sol = jax.jit(lambda p: S._solve_one(p, 1e-6, 1e-6, 200))(prob)
    finally:
        jax.clear_caches()  # and later tests must not reuse this one
    assert float(sol.com_error_m) > S.COM_TOLERANCE_M
    assert not bool(sol.converged)
    assert bool(sol.result != S.StanceResult.successful)


def test_balance_margin_by_hand():
    """`balance_margin_m` against the feet's geometry worked by hand: default flat feet side by
    side, facing +Z, so the support polygon's heel and toe edges are lines of constant Z."""
    from fourierjax.stance import balance_margin_m, make_problem

    mon = np.asarray(BODY.monitor_points)  # [foot, heel/heel/toe/toe, xyz] in the foot frame
    z_heel, z_toe = float(mon[0, 0, 2]), float(mon[0, 2, 2])
    # Centred: the nearest edges are the heel and toe lines, half a foot away.
    assert balance_margin_m(make_problem(BODY)) == pytest.approx((z_toe - z_heel) / 2, abs=1e-6)
    # forward_shift = 3 extrapolates to heel + 2 (toe - heel): a foot length past the toe line.
    ahead = balance_margin_m(make_problem(BODY, {"forward_shift": 3.0}))
    assert ahead == pytest.approx(-(z_toe - z_heel), abs=1e-6)
    # A stacked batch gives one value each, in order; weight_shift = 5 is off to the left.
    both = balance_margin_m(stack_problems([make_problem(BODY), make_problem(BODY, {"weight_shift": 5.0})]))
    assert both.shape == (2,) and both[0] > 0 > both[1]
    # A shape set extrapolated past intensity 1 can leave the feet (weak recoil: 0.044 m inside
    # at intensity 1, 0.084 m outside at 3).
    recoil = get_shape_set("weak_recoil")
    assert balance_margin_m(recoil.problem(BODY, 1.0, OBJECT)) > 0 > balance_margin_m(recoil.problem(BODY, 3.0, OBJECT))
