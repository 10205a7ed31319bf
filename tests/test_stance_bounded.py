"""Hard amplitude bounds (jaxopt L-BFGS-B): loose bounds change nothing, a tight one is met."""

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
