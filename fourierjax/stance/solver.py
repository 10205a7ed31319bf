"""The body shape solver (Neff & Fiume 2004, sec. 5.2, eq. 5): gradient-based, batched, differentiable."""

import functools

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import optimistix as optx
from jaxtyping import Array, Float

from fourierjax._jit import filter_jit
from fourierjax._linalg import PRECISION
from fourierjax.errors import UserError
from fourierjax.stance._implicit import implicit_terms, solve_spd
from fourierjax.stance._objective import (
    COM_TOLERANCE_M,
    StanceResult,
    StanceSolution,
    amplitudes_from_unknowns,
    finish,
    objective,
    value_grad_build,
)
from fourierjax.stance._pose import BalancedBuild, balanced_rotations, build_output_like
from fourierjax.stance._problem import NUM_AMPLITUDES, StanceProblem, substitute_invalid

__all__ = [
    "COM_TOLERANCE_M", "StanceResult", "StanceSolution", "amplitudes_from_unknowns", "objective",
    "solve_stance", "solve_stances", "stack_problems",
]  # fmt: skip


def _loop_objective(y: Float[Array, "6"], problem: StanceProblem):
    """`(objective, pose)` for optimistix, whose derivative in y is `value_grad_build`'s gradient.

    The value is f + g . (y - y), with f and g computed from a stopped copy of y: linearising
    this gives exactly g, so BFGS's `jax.linearize` + transpose never traces the pose
    builder again. Only for the solver's loop: no derivatives with respect to `problem`.
    """
    y_s = jax.lax.stop_gradient(y)
    value, grad, built = value_grad_build(y_s, jax.lax.stop_gradient(problem))
    return value + jnp.dot(grad, y - y_s, precision=PRECISION), built


#: At most this many BFGS runs per solve (each from the previous answer, with a fresh
#: Hessian estimate), while the gradient norm exceeds `_RESTART_GRAD * max(1, |f|)`.
_RUNS = 2
_RESTART_GRAD = 1e-4

#: Longest BFGS step in the amplitude offsets (rad, 2-norm).
_MAX_STEP = 0.5


class _CappedNewton(optx.AbstractDescent):
    """optimistix's Newton descent with the direction capped to `max_length` (2-norm).

    BFGS starts from an identity Hessian, so its first step is the raw gradient, which a steep
    reach wall makes tens of radians long: measured on a reach problem of the posture sweep, it
    leapt into a far basin (collar amplitudes past 2 pi; objective 366.8 where the direction-set
    reference finds 117.0). Capping keeps the search local; near the optimum the Newton steps
    are short and unchanged.
    """

    max_length: float
    inner: optx.NewtonDescent = optx.NewtonDescent()

    def init(self, y, f_info_struct):
        return self.inner.init(y, f_info_struct)

    def query(self, y, f_info, state):
        state = self.inner.query(y, f_info, state)
        n = jnp.sqrt(sum(jnp.sum(x * x) for x in jax.tree.leaves(state.newton)))
        scale = jnp.minimum(1.0, self.max_length / jnp.maximum(n, 1e-30))
        return eqx.tree_at(lambda st: st.newton, state, jax.tree.map(lambda x: x * scale, state.newton))

    def step(self, step_size, state):
        return self.inner.step(step_size, state)


@functools.partial(jax.custom_jvp, nondiff_argnums=(1, 2, 3))
def _optimum(problem: StanceProblem, rtol: float, atol: float, max_steps: int):
    """`(y*, steps, converged, max steps reached, pose)`: BFGS on eq. 5; derivatives by the implicit function theorem.

    At the optimum grad_y f(y*, p) = 0, so dy* = -H^-1 (d/dp grad_y f) dp with H the 6x6
    Hessian. One linearisation of grad_y f at (y*, p) gives both the Hessian (applied to the
    six unit vectors) and the mixed term (applied to dp); the 6x6 system is solved in closed
    form. No derivative runs through the iterations; reverse mode and vmap work. The pose
    (a `BalancedBuild`) is the one of the last accepted step (optimistix keeps the aux of
    the accepted iterate in its state); its tangent is the JVP of `balanced_rotations`
    along (dp, dy*).
    """
    # BFGS keeps an inverse-Hessian estimate, so a step needs no linear solve (no LAPACK in
    # the batched path). Its steps are capped in length (`_CappedNewton`).
    solver = eqx.tree_at(lambda s: s.descent, optx.BFGS(rtol=rtol, atol=atol), _CappedNewton(_MAX_STEP))
    dtype = problem.shape.dtype

    def run(carry):
        y, steps, _, _, _, _, runs = carry
        sol = optx.minimise(
            _loop_objective, solver, y, args=problem, max_steps=max_steps, has_aux=True, throw=False
        )
        ok = sol.result == optx.RESULTS.successful
        maxed = (sol.result == optx.RESULTS.nonlinear_max_steps_reached) | (
            sol.result == optx.RESULTS.max_steps_reached
        )
        f_info = sol.state.f_info
        stuck = jnp.linalg.norm(f_info.grad) > _RESTART_GRAD * jnp.maximum(1.0, jnp.abs(f_info.f))
        return sol.value, steps + sol.stats["num_steps"], ok, maxed, sol.state.aux, stuck, runs + 1

    # BFGS's Cauchy test stops when steps get short, which a stale inverse-Hessian estimate can
    # cause away from a stationary point (measured on a reach problem of the stance benchmark:
    # stopped with |grad| = 0.83 at objective 156.8914, where the direction-set reference finds
    # 156.8896). Where the gradient is not small BFGS runs once more from its answer with a
    # fresh estimate (156.8898 there); one copy of the solver in the compiled program.
    r, (root, local, info) = build_output_like(dtype)
    start = (jnp.zeros(NUM_AMPLITUDES, dtype), jnp.zeros((), jnp.int32), jnp.array(False), jnp.array(False),
             BalancedBuild(jnp.zeros(2, dtype), root, local, info), jnp.array(True),
             jnp.zeros((), jnp.int32))
    y, steps, ok, maxed, built, _, _ = jax.lax.while_loop(
        lambda c: c[5] & (c[6] < _RUNS), run, start
    )
    return y, steps, ok, maxed, built


@_optimum.defjvp
def _optimum_jvp(rtol, atol, max_steps, primals, tangents):
    (problem,), (dp,) = primals, tangents
    y, steps, ok, maxed, built = _optimum(problem, rtol, atol, max_steps)
    H, mixed = implicit_terms(y, problem, dp)
    dy = -solve_spd(H, mixed)
    _, d_built = jax.jvp(
        lambda p, yy: balanced_rotations(p, amplitudes_from_unknowns(p, yy)), (problem, y), (dp, dy)
    )
    zero = np.zeros((), jax.dtypes.float0)
    return (y, steps, ok, maxed, built), (dy, zero, zero, zero, d_built)


def _solve_one(problem: StanceProblem, rtol: float, atol: float, max_steps: int, throw: bool = False):
    # A problem refused here is solved in its place (neutral shape) and flagged: see
    # `substitute_invalid`. Concrete problems were refused already by `make_problem`.
    problem, invalid = substitute_invalid(problem)
    y, steps, ok, maxed, built = _optimum(problem, rtol, atol, max_steps)
    sol = finish(problem, y, steps, ok, maxed, invalid, built)
    if throw:
        token = sol.result.error_if(sol.objective, sol.result != StanceResult.successful)
        sol = eqx.tree_at(lambda s: s.objective, sol, token)
    return sol


@filter_jit
def solve_stance(
    problem: StanceProblem,
    rtol: float = 1e-6,
    atol: float = 1e-6,
    max_steps: int = 200,
    throw: bool = False,
) -> StanceSolution:
    """Solve one stance: torso amplitudes minimising eq. 5 with balance and analytic IK inside.

    Differentiable with respect to every array in `problem` (intensity, targets, feet, body)
    through the optimum by implicit differentiation (`_optimum`: the implicit function theorem
    with the 6x6 Hessian at the solution).

    Arguments:
        problem: a `StanceProblem` (`make_problem` or a shape set's `problem`).
        rtol, atol: BFGS tolerances on the step and gradient.
        max_steps: iteration limit (`converged` is False if hit).
        throw: raise (`eqx.error_if`, an `EqxRuntimeError` naming the `StanceResult`) unless the
            solve succeeded. Default False, unlike optimistix, as before `result` existed: a
            solve that did not converge still returns, with `converged=False` and its `result`
            (max_steps_reached, not_converged). A problem with invalid values that were traced
            when it was built (e.g. a shape set's intensity under `jax.jit` or `jax.grad` asking
            for a knee bend past `BEND_MAX_RAD`) returns `result=invalid_input`,
            `converged=False`, the neutral pose and zero (never NaN) derivatives; built from
            concrete values, `make_problem` refuses it with a `UserError` before any solve.

    Returns:
        A `StanceSolution`.
    """
    return _solve_one(problem, rtol, atol, max_steps, throw)


@filter_jit
def solve_stances(
    problems: StanceProblem,
    rtol: float = 1e-6,
    atol: float = 1e-6,
    max_steps: int = 200,
    batch_size: int | str | None = "auto",
    throw: bool = False,
) -> StanceSolution:
    """Solve a batch of stances (problems stacked along a leading axis) in one call.

    One compiled program for the whole batch. `batch_size` says how the problems share it:
    `None` vmaps all of them (one BFGS loop whose steps run until the slowest problem is done);
    an integer k solves chunks of k vmapped problems one chunk after another (`jax.lax.map`),
    which bounds memory and the iterations a hard problem imposes on easy ones; 1 solves them
    one by one. "auto" (default) is 1 on CPU and None elsewhere: on CPU a solve is bound by
    kernel launches, not arithmetic, and the sequential program compiles like a single solve.
    Measured on 2 CPU cores, 256 problems of the stance benchmark, interleaved runs: 116-132
    solves/s one by one, 81-90 in chunks of 2 or 4, 25 vmapped at once (same objectives to
    float32 round-off).

    Arguments:
        problems: `StanceProblem`s stacked along a leading axis (`stack_problems`, or a
            shape set's `problem` under `jax.vmap`).
        rtol, atol, max_steps: as for `solve_stance`, shared by every problem.
        batch_size: "auto", None or a positive int (above).
        throw: as for `solve_stance`; the default False means a batch never fails for one
            problem: read each problem's `result`.

    Returns:
        A `StanceSolution` whose leaves have a leading batch axis.
    """
    arrays, static = eqx.partition(problems, eqx.is_array)

    def one(a):
        return _solve_one(eqx.combine(a, static), rtol, atol, max_steps, throw)

    if batch_size == "auto":
        batch_size = 1 if jax.default_backend() == "cpu" else None
    if batch_size is None:
        return jax.vmap(one)(arrays)
    if isinstance(batch_size, bool) or not isinstance(batch_size, int) or batch_size < 1:
        raise UserError(f"solve_stances: batch_size must be a positive int, None or 'auto', got {batch_size!r}")
    if batch_size == 1:
        return jax.lax.map(one, arrays)
    return jax.lax.map(one, arrays, batch_size=batch_size)


def stack_problems(problems: list[StanceProblem]) -> StanceProblem:
    """Stack same-structure problems along a new leading axis (for `solve_stances`).

    Arguments:
        problems: one or more `StanceProblem`s with the same static settings.

    Returns:
        One `StanceProblem` whose leaves have a leading axis of `len(problems)`.

    Raises:
        UserError: no problems, something that is not a `StanceProblem`, or problems whose
            static settings (e.g. `dominant`) differ from the first one's.
    """
    problems = list(problems)
    if not problems:
        raise UserError("stack_problems: no problems to stack")
    for i, p in enumerate(problems):
        if not isinstance(p, StanceProblem):
            raise UserError(f"stack_problems: problem {i} is a {type(p).__name__}, not a StanceProblem")
    first = jax.tree.structure(problems[0])
    for i, p in enumerate(problems[1:], 1):
        if jax.tree.structure(p) != first:
            raise UserError(
                f"stack_problems: problem {i} differs from problem 0 in its static settings "
                f"(dominant foot: {p.dominant!r} vs {problems[0].dominant!r}); solve such problems "
                "in separate batches"
            )
    return jax.tree.map(lambda *xs: jnp.stack(xs), *problems)
