"""Solver outcomes: `StanceSolution.result`, `throw`, and refusals that hold under tracing."""

import subprocess
import sys

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

from fourierjax.errors import UserError
from fourierjax.stance.problem import BEND_MAX_RAD, P, make_problem
from fourierjax.stance.shape_sets import get_shape_set
from fourierjax.stance.skeleton48 import make_body
from fourierjax.stance.solver import StanceResult, solve_stance, solve_stances

BODY = make_body(1.75)
POSTURE = get_shape_set("posture")


def _is(result, item) -> np.ndarray:
    return np.asarray(result == item)


def test_intensity_3_is_refused_when_concrete_and_flagged_under_jit():
    """Intensity 3 asks for a 722-degree knee bend: refused when concrete; traced it used to be
    solved with converged=True."""
    with pytest.raises(UserError, match="past a knee's range"):
        POSTURE.problem(BODY, 3.0)
    f = jax.jit(lambda i: solve_stance(POSTURE.problem(BODY, i)))
    bad, good = f(jnp.float32(3.0)), f(jnp.float32(1.0))
    assert _is(bad.result, StanceResult.invalid_input) and not bool(bad.converged)
    assert np.isfinite(float(bad.objective)) and np.isfinite(np.asarray(bad.pose.quats)).all()
    assert _is(good.result, StanceResult.successful) and bool(good.converged)


def test_intensity_3_under_grad_is_flagged_with_finite_zero_gradient():
    target = jnp.array([-0.35, 1.05, 0.55])  # without a target the objective is 0 at any intensity

    def objective(i):
        sol = solve_stance(POSTURE.problem(BODY, i, target_right=target))
        return sol.objective, sol

    grad = jax.jit(jax.grad(objective, has_aux=True))
    g_bad, bad = grad(jnp.float32(3.0))
    assert _is(bad.result, StanceResult.invalid_input) and not bool(bad.converged)
    assert float(g_bad) == 0.0  # was NaN
    g_good, good = grad(jnp.float32(0.5))
    assert bool(good.converged) and np.isfinite(float(g_good)) and float(g_good) != 0.0


def test_a_batch_flags_its_invalid_problems_and_solves_the_others():
    probs = jax.vmap(lambda i: POSTURE.problem(BODY, i))(jnp.array([0.5, 3.0, 1e30, -0.5], jnp.float32))
    assert float(probs.shape[1, P["knee_right"]]) > BEND_MAX_RAD  # traced: built unchecked
    sols = solve_stances(probs)
    np.testing.assert_array_equal(_is(sols.result, StanceResult.invalid_input), [False, True, True, False])
    np.testing.assert_array_equal(np.asarray(sols.converged), [True, False, False, True])
    np.testing.assert_array_equal(
        np.asarray(sols.result == StanceResult.successful), np.asarray(sols.converged)
    )
    assert np.isfinite(np.asarray(sols.objective)).all()


@pytest.mark.parametrize("field, value", [("targets", jnp.nan), ("amplitude_scale", -1.0),
                                          ("reach_weight", -1.0), ("quats", 2.0)])
def test_other_values_checked_only_when_concrete_are_flagged_when_traced(field, value):
    def solve(v):
        if field == "amplitude_scale":
            p = make_problem(BODY, amplitude_scale=v)
        elif field == "reach_weight":
            p = make_problem(BODY, reach_weight=v)
        else:
            p = make_problem(BODY, target_right=jnp.array([-0.3, 1.1, 0.4]))
            p = eqx.tree_at(lambda q: q.targets if field == "targets" else q.feet.quats, p,
                            replace_fn=lambda x: x * v if field == "quats" else x + v)
        return solve_stance(p)

    sol = jax.jit(solve)(jnp.float32(value))
    assert _is(sol.result, StanceResult.invalid_input) and not bool(sol.converged)


def test_max_steps_reached_and_throw():
    prob = POSTURE.problem(BODY, 0.7, target_right=jnp.array([-0.35, 1.05, 0.55]))
    short = solve_stance(prob, max_steps=1)
    assert _is(short.result, StanceResult.max_steps_reached) and not bool(short.converged)
    with pytest.raises(eqx.EquinoxRuntimeError, match="ran out of steps"):
        solve_stance(prob, max_steps=1, throw=True)
    ok = solve_stance(prob, throw=True)
    assert _is(ok.result, StanceResult.successful)
    np.testing.assert_allclose(float(ok.objective), float(solve_stance(prob).objective))


def test_throw_refuses_a_traced_invalid_problem():
    # Under an outer jit, equinox needs `filter_jit` to raise its own error type.
    f = eqx.filter_jit(lambda i: solve_stance(POSTURE.problem(BODY, i), throw=True).objective)
    with pytest.raises(eqx.EquinoxRuntimeError, match="knee or elbow bend"):
        f(jnp.float32(3.0))


def test_bounded_solver_flags_a_traced_invalid_problem():
    from fourierjax.stance.bounded import solve_stance_bounded

    lo, hi = jnp.full(6, -0.4), jnp.full(6, 0.4)
    sol = jax.jit(lambda i: solve_stance_bounded(POSTURE.problem(BODY, i), lo, hi))(jnp.float32(3.0))
    assert _is(sol.result, StanceResult.invalid_input) and not bool(sol.converged)


def test_bvh_export_is_a_deprecated_lazy_alias():
    from fourierjax.io import stance_bvh
    from fourierjax.stance import bvh_export

    for name in ("animate", "ease_in_out", "pose_to_motion", "write_stance_bvh"):
        with pytest.warns(DeprecationWarning, match=f"import {name} from fourierjax.io.stance_bvh"):
            assert getattr(bvh_export, name) is getattr(stance_bvh, name)
    with pytest.raises(AttributeError):
        bvh_export.nothing  # noqa: B018


def test_the_stance_core_does_not_import_the_bvh_writer_or_scipy():
    code = ("import sys, fourierjax.stance, fourierjax.stance.bvh_export, fourierjax.stance.solver; "
            "print(sorted(m for m in sys.modules if m in ('fourierjax.io.stance_bvh', 'scipy', "
            "'matplotlib') or m.startswith('fourierjax.cli')))")  # fmt: skip
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "[]", out.stdout
    import fourierjax.stance as stance
    from fourierjax.io.stance_bvh import write_stance_bvh

    assert stance.write_stance_bvh is write_stance_bvh  # the package name still works
