"""Eq. 5 (Neff & Fiume 2004, sec. 5.2), its forward-mode gradient, and the solution both solvers return."""

import equinox as eqx
import jax
import jax.numpy as jnp
from jaxtyping import Array, Bool, Float, Int

from fourierjax._linalg import PRECISION
from fourierjax.stance._pose import BalancedBuild, balanced_rotations, balanced_rotations_with_tangents
from fourierjax.stance._problem import BEND_MAX_RAD, BEND_MIN_RAD, NUM_AMPLITUDES, StanceProblem, desired_balance_point
from fourierjax.stance.penalties import hermite_penalty
from fourierjax.stance.skeleton48 import StancePose


class StanceResult(eqx.Enumeration):
    """Outcome of a stance solve (`StanceSolution.result`), after `optimistix.RESULTS`."""

    successful = ""
    max_steps_reached = "the stance solver ran out of steps (max_steps / maxiter) before meeting its tolerances"
    not_converged = (
        "the stance solver stopped without meeting its tolerances, or the balance was not solved "
        "(the COM error exceeds COM_TOLERANCE_M)"
    )
    invalid_input = (
        f"a knee or elbow bend of the shape vector is outside [{BEND_MIN_RAD}, {BEND_MAX_RAD}] rad "
        "(or not finite); the problem was not solved and its derivatives are zero"
    )


def amplitudes_from_unknowns(problem: StanceProblem, y: Float[Array, "6"]) -> Float[Array, "6"]:
    """Torso amplitudes: desired values plus the solver's offsets where they are free."""
    return problem.shape[:NUM_AMPLITUDES] + problem.free * y


def objective_given_shoulders(y: Float[Array, "6"], problem: StanceProblem, shoulders) -> Float[Array, ""]:
    """Eq. 5 from the offsets and the two shoulder positions of the balanced pose."""
    pen = hermite_penalty(problem.amplitude_penalty, problem.free * y)
    total = jnp.sum(problem.amplitude_weights * problem.free * pen)
    total = total + 0.5 * jnp.sum((1.0 - problem.free) * y * y)
    dist = jnp.sqrt(jnp.sum((shoulders - problem.targets) ** 2, axis=-1) + 1e-12)
    reach = hermite_penalty(problem.reach, dist)
    return total + jnp.sum(problem.target_active * problem.reach_weights * reach)


def value_grad_build(y: Float[Array, "6"], problem: StanceProblem):
    """`(objective, grad_y objective, balanced pose)` in forward mode from one traced pose builder.

    The six amplitude directions ride along the balance solve's own derivatives
    (`balanced_rotations_with_tangents`), so the solver's loop holds one copy of the
    pose builder (primal plus 8 batched tangents) instead of a balance loop, a linearisation,
    its 2-direction balance Jacobian and a transposed copy for reverse mode: about half the
    XLA kernels for value and gradient, and 1.4x faster per evaluation (2 cores).
    Derivatives with respect to the problem are NOT defined here (the implicit derivatives
    of the solve use `objective`).
    """
    directions = jnp.diag(problem.free)  # d amplitudes / d y
    built, d_built = balanced_rotations_with_tangents(
        problem, amplitudes_from_unknowns(problem, y), directions
    )
    value, vjp = jax.vjp(lambda yy, sh: objective_given_shoulders(yy, problem, sh), y,
                         built.info.shoulders)
    g_y, g_sh = vjp(jnp.ones_like(value))
    grad = g_y + jnp.einsum("ihx,hx->i", d_built.info.shoulders, g_sh, precision=PRECISION)
    return value, grad, built


def objective(y: Float[Array, "6"], problem: StanceProblem) -> Float[Array, ""]:
    """Eq. 5, obj = sum_i w_i f_i: amplitude penalties plus active reach penalties.

    Held amplitudes (`free == 0`) get a unit quadratic on their (ignored) offset, which keeps
    the minimiser and its Hessian well defined.

    Arguments:
        y: `[6]` offsets of the six torso amplitudes from their desired points (rad).
        problem: a `StanceProblem`.

    Returns:
        The objective, a scalar.
    """
    built = balanced_rotations(problem, amplitudes_from_unknowns(problem, y))
    return objective_given_shoulders(y, problem, built.info.shoulders)


class StanceSolution(eqx.Module):
    """A solved stance (one problem; batched solutions have a leading batch axis).

    - `amplitudes`: `[6]` sagittal, coronal, transverse, collar Y, collar Z, abdomen X.
    - `pose`: the `StancePose`; `balance_xz`: `[2]` dominant-ankle X/Z offsets (rad).
    - `objective`: eq. 5 at the solution; `iterations`: solver steps; `converged`: bool, the
      solver met its tolerances AND the balance was solved (`com_error_m <= COM_TOLERANCE_M`)
      AND the input was valid; the same as `result == StanceResult.successful`.
    - `result`: a `StanceResult` (successful, max_steps_reached, not_converged, invalid_input).
    - `com_error_m`: distance of the COM ground projection from the desired point.
    - `reach_error_m`: `[2]` wrist-to-target distance (0 for an inactive hand; see
      `target_active`); `reach_gap_m`: `[2]` how far a target lies beyond the arm.
    - `free_foot_gap_m`: > 0 if the free foot could not be planted.
    """

    amplitudes: Float[Array, "6"]
    pose: StancePose
    balance_xz: Float[Array, "2"]
    objective: Float[Array, ""]
    iterations: Int[Array, ""]
    converged: Bool[Array, ""]
    result: StanceResult
    com_error_m: Float[Array, ""]
    reach_error_m: Float[Array, "2"]
    reach_gap_m: Float[Array, "2"]
    target_active: Float[Array, "2"]
    free_foot_gap_m: Float[Array, ""]


#: Largest COM error (m) of a converged solution. Newton's balance solve reaches float32
#: round-off (worst 1.8e-7 m over the posture sweeps); more means it did not converge.
COM_TOLERANCE_M = 1e-4


def finish(problem: StanceProblem, y, steps, ok, maxed, invalid, built: BalancedBuild) -> StanceSolution:
    """The `StanceSolution` of offsets `y` and the solver's last accepted pose `built`.

    `ok`: the solver met its tolerances; `maxed`: it ran out of steps; `invalid`: the problem
    was refused (`valid_or_substitute`). `built` carries derivatives by the implicit function
    theorem: the pose is not built again.
    """
    obj = objective_given_shoulders(y, problem, built.info.shoulders)
    info, b = built.info, built.balance_xz
    goal = desired_balance_point(problem)
    com_err = jnp.sqrt((info.com[0] - goal[0]) ** 2 + (info.com[2] - goal[1]) ** 2)
    reach_err = problem.target_active * jnp.sqrt(
        jnp.sum((info.wrists - problem.targets) ** 2, axis=-1) + 1e-24
    )
    good = ok & (com_err <= COM_TOLERANCE_M)
    failed = StanceResult.where(maxed, StanceResult.max_steps_reached, StanceResult.not_converged)
    result = StanceResult.where(good, StanceResult.successful, failed)
    result = StanceResult.where(invalid, StanceResult.invalid_input, result)
    return StanceSolution(
        amplitudes=amplitudes_from_unknowns(problem, y),
        pose=built.pose(),
        balance_xz=b,
        objective=obj,
        iterations=steps,
        converged=good & ~invalid,
        com_error_m=com_err,
        reach_error_m=reach_err,
        reach_gap_m=info.reach_gaps,
        target_active=problem.target_active,
        free_foot_gap_m=info.free_foot_gap,
        result=result,
    )
