"""Stance solve with hard bounds on the torso amplitudes: jaxopt's L-BFGS-B (Neff & Fiume eq. 5)."""

import functools
import warnings

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float

from fourierjax._jit import filter_jit
from fourierjax._linalg import matmul
from fourierjax.errors import UserError
from fourierjax.stance._implicit import implicit_terms, solve_spd
from fourierjax.stance._objective import StanceSolution, amplitudes_from_unknowns, finish, value_grad_build
from fourierjax.stance._pose import balanced_rotations
from fourierjax.stance._problem import NUM_AMPLITUDES, StanceProblem, substitute_invalid

with warnings.catch_warnings():
    # jaxopt announces on import that it is no longer maintained (STYLE.md); it is used here
    # only for its box-constrained L-BFGS-B, which optimistix lacks.
    warnings.filterwarnings("ignore", message="JAXopt is no longer maintained", category=DeprecationWarning)
    import jaxopt

_BIG = 1e3  # rad: "unbounded" for held amplitudes (L-BFGS-B needs finite bounds)


@functools.partial(jax.custom_jvp, nondiff_argnums=(3, 4))
def _bounded_optimum(problem: StanceProblem, lower, upper, tol: float, maxiter: int):
    """`(y*, iterations, converged)` of eq. 5 over the box `lower <= y <= upper`.

    Derivatives by the implicit function theorem on the active set: components on a bound
    follow the bound; the free ones solve the Hessian system restricted to them (the 6x6
    `_implicit.solve_spd`). No derivative runs through jaxopt's iterations.
    """
    def value_and_grad(y, p):
        value, grad, _ = value_grad_build(y, p)
        return value, grad

    solver = jaxopt.LBFGSB(
        fun=value_and_grad, value_and_grad=True, maxiter=maxiter, tol=tol, implicit_diff=False
    )
    y0 = jnp.clip(jnp.zeros(NUM_AMPLITUDES, problem.shape.dtype), lower, upper)
    y, state = solver.run(y0, (lower, upper), problem)
    return y, state.iter_num, state.error <= tol


@_bounded_optimum.defjvp
def _bounded_optimum_jvp(tol, maxiter, primals, tangents):
    problem, lower, upper = primals
    dp, dlo, dhi = tangents
    y, steps, ok = _bounded_optimum(problem, lower, upper, tol, maxiter)
    H, mixed = implicit_terms(y, problem, dp)
    span = jnp.maximum(upper - lower, 1.0)
    at_lo, at_hi = y <= lower + 1e-6 * span, y >= upper - 1e-6 * span
    active = at_lo | at_hi
    dy_active = jnp.where(at_lo, dlo, jnp.where(at_hi, dhi, 0.0))
    rhs = mixed + matmul(H, dy_active)
    mask = active[:, None] | active[None, :]
    M = jnp.where(mask, jnp.eye(y.shape[0], dtype=y.dtype), H)
    dy = -solve_spd(M, jnp.where(active, 0.0, rhs)) + dy_active
    zero = np.zeros((), jax.dtypes.float0)
    return (y, steps, ok), (dy, zero, zero)


@filter_jit
def solve_stance_bounded(
    problem: StanceProblem,
    lower: Float[Array, "6"],
    upper: Float[Array, "6"],
    tol: float = 1e-4,
    maxiter: int = 100,
) -> StanceSolution:
    """Solve one stance with hard bounds on the six torso amplitudes (jaxopt L-BFGS-B).

    The amplitude penalties (`penalties`) are soft walls; where a user needs a hard limit
    (a joint range, an amplitude that must not change sign) this keeps every amplitude inside
    `[lower, upper]` exactly. Held amplitudes (`problem.free == 0`) stay at their desired
    values whatever the bounds. Not batched: jaxopt's solvers are slow under vmap (STYLE.md);
    use `solver.solve_stances` for batches without hard bounds.

    Differentiable with respect to the problem and the bounds (implicit function theorem on
    the active set).

    Arguments:
        problem: a `StanceProblem`.
        lower, upper: `[6]` bounds on the amplitudes (rad; sagittal, coronal, transverse,
            collar Y, collar Z, abdomen X), absolute values, not offsets from the desired ones.
            The desired values (`problem.shape[:6]`) need not lie inside.
        tol: L-BFGS-B tolerance on the projected gradient; `converged` reports whether it
            was met within `maxiter` iterations (in float32 the gradient's round-off floor
            is about 1e-4: ask for less only in float64).

    Returns:
        A `StanceSolution` (`iterations` counts L-BFGS-B iterations; `result` as for
        `solver.solve_stance`, never raised).
    """
    problem, invalid = substitute_invalid(problem)  # flagged in `result` (see `solve_stance`)
    lower, upper = jnp.asarray(lower, problem.shape.dtype), jnp.asarray(upper, problem.shape.dtype)
    for name, b in (("lower", lower), ("upper", upper)):
        if b.shape != (NUM_AMPLITUDES,):
            raise UserError(f"solve_stance_bounded: {name} must have shape (6,), got {b.shape}")
    desired = problem.shape[:NUM_AMPLITUDES]
    free = problem.free > 0.5
    # Bounds on the solver's unknowns, the offsets y = amplitude - desired of free amplitudes.
    lo = jnp.where(free, lower - desired, -_BIG)
    hi = jnp.where(free, upper - desired, _BIG)
    bad = jnp.any(jnp.isnan(lo) | jnp.isnan(hi) | (lo > hi))
    lo = eqx.error_if(lo, bad, "solve_stance_bounded: bounds must be numbers with lower <= upper")
    y, steps, ok = _bounded_optimum(problem, lo, hi, tol, maxiter)
    built = balanced_rotations(problem, amplitudes_from_unknowns(problem, y))
    return finish(problem, y, steps, ok, ~ok & (steps >= maxiter), invalid, built)

