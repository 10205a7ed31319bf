"""Hard amplitude bounds (jaxopt L-BFGS-B): loose bounds change nothing, a tight one is met."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from fourierjax.errors import UserError
from fourierjax.stance.bounded import solve_stance_bounded
from fourierjax.stance.shape_sets import get_shape_set
from fourierjax.stance.skeleton48 import make_body
from fourierjax.stance.solver import solve_stance

REACHABLE = jnp.array([-0.35, 1.05, 0.55])


def test_bounded_solve_matches_the_free_solve_and_meets_a_tight_bound():
    body = make_body(1.75)
    prob = get_shape_set("posture").problem(body, 0.8, target_right=REACHABLE)
    free = solve_stance(prob)
    big = jnp.full(6, 10.0)
    loose = solve_stance_bounded(prob, -big, big)
    np.testing.assert_allclose(loose.amplitudes, free.amplitudes, atol=2e-3)
    assert float(loose.objective) <= float(free.objective) * (1 + 1e-4) + 1e-5
    # Half the free solution's sagittal amplitude as an upper bound: it must become active.
    up = big.at[0].set(0.5 * float(free.amplitudes[0]))
    tight = solve_stance_bounded(prob, -big, up)
    sag = float(tight.amplitudes[0])
    assert up[0] - 1e-4 <= sag <= up[0] + 1e-6
    assert float(tight.objective) > float(free.objective)
    # Balance and reach still hold in the bounded pose (the other amplitudes compensate).
    assert float(tight.com_error_m) < 1e-3 and float(tight.reach_error_m[0]) < 1e-3
    assert abs(float(tight.amplitudes[1]) - float(free.amplitudes[1])) + abs(
        float(tight.amplitudes[2]) - float(free.amplitudes[2])
    ) > 1e-3
    with pytest.raises(UserError, match="lower must have shape"):
        solve_stance_bounded(prob, jnp.zeros(5), big)


def test_bounded_solve_derivatives_match_finite_differences(x64):
    """Implicit derivatives on the active set against central differences: with respect to the
    intensity knob (free components move, the bounded one stays on its bound) and to the
    active bound itself (the bounded amplitude follows it one to one)."""
    body = make_body(1.75)
    posture = get_shape_set("posture")
    big = jnp.full(6, 10.0)
    free = solve_stance(posture.problem(body, 0.8, target_right=REACHABLE), rtol=1e-11, atol=1e-11)
    cap = 0.5 * float(free.amplitudes[0])

    def amplitudes(params):
        """Bounded solution's amplitudes for [intensity, upper bound on the sagittal amplitude]."""
        prob = posture.problem(body, params[0], target_right=REACHABLE)
        return solve_stance_bounded(prob, -big, big.at[0].set(params[1]), tol=1e-10, maxiter=300).amplitudes

    p = jnp.array([0.8, cap])
    jac = np.asarray(jax.jit(jax.jacfwd(amplitudes))(p))  # [6, 2]
    f = jax.jit(amplitudes)
    h = 1e-4
    fd = np.stack([(np.asarray(f(p.at[k].add(h))) - np.asarray(f(p.at[k].add(-h)))) / (2 * h) for k in range(2)], -1)
    np.testing.assert_allclose(jac, fd, atol=1e-6)  # measured: 1.4e-8 at h = 1e-4 (5.6e-7 at 1e-3)
    np.testing.assert_allclose(jac[0], [0.0, 1.0], atol=1e-9)  # on the bound: follows it only
    assert np.abs(jac[1:, 0]).max() > 1e-2 and np.abs(jac[1:, 1]).max() > 1e-3  # not trivially zero
