"""The paper's stance solver as a reference (scipy): coordinate direction set with Brent line minimisation."""

import time

import equinox as eqx
import jax
import numpy as np

from fourierjax.stance.problem import NUM_AMPLITUDES, StanceProblem
from fourierjax.stance.solver import objective

# A test oracle and benchmark baseline outside the package (scipy is a dev dependency), so it
# jits with equinox directly rather than with the package's private entry-point wrapper.
_objective_value = eqx.filter_jit(objective)


def solve_reference(problem: StanceProblem, xtol: float = 1e-6, ftol: float = 1e-10,
                    max_iterations: int = 100) -> dict:  # fmt: skip
    """Minimise eq. 5 the paper's way (sec. 5.2): line minimisations along each amplitude's
    unit vector in turn (Brent's method), repeated until the objective stops improving.

    This is scipy's Powell method started with the coordinate directions (`direc` = identity);
    Powell may replace a direction by the net displacement of an iteration, the classic
    direction-set refinement the paper mentions and did not need. scipy is a dev dependency:
    this reference is for tests and benchmarks.

    Returns:
        dict with `y` (`[6]` offsets from the desired amplitudes), `objective`, `iterations`
        (full sweeps over the directions), `evaluations`, `seconds`.
    """
    from scipy.optimize import minimize

    y0 = np.zeros(NUM_AMPLITUDES)
    dtype = problem.shape.dtype

    def f(y):
        return float(_objective_value(jax.numpy.asarray(y, dtype), problem))

    f(y0)  # compile outside the timing
    t0 = time.perf_counter()
    res = minimize(f, y0, method="Powell",
                   options={"xtol": xtol, "ftol": ftol, "maxiter": max_iterations,
                            "direc": np.eye(NUM_AMPLITUDES)})  # fmt: skip
    return {
        "y": res.x,
        "objective": float(res.fun),
        "iterations": int(res.nit),
        "evaluations": int(res.nfev),
        "seconds": time.perf_counter() - t0,
    }
