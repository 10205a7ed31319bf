"""The body shape solver (Neff & Fiume 2004, sec. 5.2, eq. 5): gradient-based, batched, differentiable."""

import functools

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import optimistix as optx
from jaxtyping import Array, Float, Int

from fourierjax._jit import filter_jit
from fourierjax._linalg import PRECISION, matmul, spd_solve
from fourierjax.errors import UserError
from fourierjax.stance.penalties import hermite_penalty
from fourierjax.stance.problem import (
    NUM_AMPLITUDES,
    BalancedBuild,
    StanceProblem,
    _build_output_like,
    _zero_tangent,
    balanced_rotations,
    balanced_rotations_with_tangents,
    desired_balance_point,
)
from fourierjax.stance.skeleton48 import StancePose


def amplitudes_from_unknowns(problem: StanceProblem, y: Float[Array, "6"]) -> Float[Array, "6"]:
    """Torso amplitudes: desired values plus the solver's offsets where they are free."""
    return problem.shape[:NUM_AMPLITUDES] + problem.free * y


def _objective_given_shoulders(y: Float[Array, "6"], problem: StanceProblem, shoulders) -> Float[Array, ""]:
    """Eq. 5 from the offsets and the two shoulder positions of the balanced pose."""
    pen = hermite_penalty(problem.amplitude_penalty, problem.free * y)
    total = jnp.sum(problem.amplitude_weights * problem.free * pen)
    total = total + 0.5 * jnp.sum((1.0 - problem.free) * y * y)
    dist = jnp.sqrt(jnp.sum((shoulders - problem.targets) ** 2, axis=-1) + 1e-12)
    reach = hermite_penalty(problem.reach, dist)
    return total + jnp.sum(problem.target_active * problem.reach_weights * reach)


def _value_grad_build(y: Float[Array, "6"], problem: StanceProblem):
    """`(objective, grad_y objective, balanced pose)` in forward mode from one traced pose builder.

    The six amplitude directions ride along the balance solve's own derivatives
    (`problem.balanced_rotations_with_tangents`), so the solver's loop holds one copy of the
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
    value, vjp = jax.vjp(lambda yy, sh: _objective_given_shoulders(yy, problem, sh), y,
                         built.info.shoulders)
    g_y, g_sh = vjp(jnp.ones_like(value))
    grad = g_y + jnp.einsum("ihx,hx->i", d_built.info.shoulders, g_sh, precision=PRECISION)
    return value, grad, built


def _loop_objective(y: Float[Array, "6"], problem: StanceProblem):
    """`(objective, pose)` for optimistix, whose derivative in y is `_value_grad_build`'s gradient.

    The value is f + g . (y - y), with f and g computed from a stopped copy of y: linearising
    this gives exactly g, so BFGS's `jax.linearize` + transpose never traces the pose
    builder again. Only for the solver's loop: no derivatives with respect to `problem`.
    """
    y_s = jax.lax.stop_gradient(y)
    value, grad, built = _value_grad_build(y_s, jax.lax.stop_gradient(problem))
    return value + jnp.dot(grad, y - y_s, precision=PRECISION), built


def objective(y: Float[Array, "6"], problem: StanceProblem) -> Float[Array, ""]:
    """Eq. 5, obj = sum_i w_i f_i: amplitude penalties plus active reach penalties.

    `y` are offsets of the six torso amplitudes from their desired points. Held amplitudes
    (`free == 0`) get a unit quadratic on their (ignored) offset, which keeps the minimiser
    and its Hessian well defined.
    """
    built = balanced_rotations(problem, amplitudes_from_unknowns(problem, y))
    return _objective_given_shoulders(y, problem, built.info.shoulders)


class StanceSolution(eqx.Module):
    """A solved stance (one problem; batched solutions have a leading batch axis).

    - `amplitudes`: `[6]` sagittal, coronal, transverse, collar Y, collar Z, abdomen X.
    - `pose`: the `StancePose`; `balance_xz`: `[2]` dominant-ankle X/Z offsets (rad).
    - `objective`: eq. 5 at the solution; `iterations`: solver steps; `converged`: bool, BFGS
      met its tolerances AND the balance was solved (`com_error_m <= COM_TOLERANCE_M`).
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
    converged: Array
    com_error_m: Float[Array, ""]
    reach_error_m: Float[Array, "2"]
    reach_gap_m: Float[Array, "2"]
    target_active: Float[Array, "2"]
    free_foot_gap_m: Float[Array, ""]


#: Largest COM error (m) of a converged solution. Newton's balance solve reaches float32
#: round-off (worst 1.8e-7 m over the posture sweeps); more means it did not converge.
COM_TOLERANCE_M = 1e-4


def _finish(problem: StanceProblem, y, steps, ok, built: BalancedBuild) -> StanceSolution:
    # `built` is the pose of the solver's last accepted step (`_optimum`), which carries
    # derivatives by the implicit function theorem: the pose is not built again.
    obj = _objective_given_shoulders(y, problem, built.info.shoulders)
    info, b = built.info, built.balance_xz
    goal = desired_balance_point(problem)
    com_err = jnp.sqrt((info.com[0] - goal[0]) ** 2 + (info.com[2] - goal[1]) ** 2)
    reach_err = problem.target_active * jnp.sqrt(
        jnp.sum((info.wrists - problem.targets) ** 2, axis=-1) + 1e-24
    )
    return StanceSolution(
        amplitudes=amplitudes_from_unknowns(problem, y),
        pose=built.pose(),
        balance_xz=b,
        objective=obj,
        iterations=steps,
        converged=ok & (com_err <= COM_TOLERANCE_M),
        com_error_m=com_err,
        reach_error_m=reach_err,
        reach_gap_m=info.reach_gaps,
        target_active=problem.target_active,
        free_foot_gap_m=info.free_foot_gap,
    )


def _solve_spd(H: Float[Array, "n n"], rhs: Float[Array, " n"]) -> Float[Array, " n"]:
    """Solve H x = rhs for the small SPD Hessian (`_linalg.spd_solve`, no LAPACK), with a relative
    ridge of 1e-10 against a singular pivot.

    The inverse is formed from H alone and applied to `rhs` by a product. In the implicit JVP
    rules H holds primal values and `rhs` is a tangent: the result is then visibly linear in
    the tangent, which reverse mode must transpose. Eliminating on `[H | rhs]` put both in one
    loop carry, and `jax.grad` through a solve failed to transpose it.
    """
    eye = jnp.eye(H.shape[0], dtype=H.dtype)
    ridge = 1e-10 * (jnp.max(jnp.abs(jnp.diagonal(H))) + 1e-30)
    return matmul(spd_solve(H + ridge * eye, eye), rhs[:, None])[:, 0]


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
    """`(y*, steps, converged, pose)`: BFGS on eq. 5; derivatives by the implicit function theorem.

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
        y, steps, _, _, _, runs = carry
        sol = optx.minimise(
            _loop_objective, solver, y, args=problem, max_steps=max_steps, has_aux=True, throw=False
        )
        ok = sol.result == optx.RESULTS.successful
        f_info = sol.state.f_info
        stuck = jnp.linalg.norm(f_info.grad) > _RESTART_GRAD * jnp.maximum(1.0, jnp.abs(f_info.f))
        return sol.value, steps + sol.stats["num_steps"], ok, sol.state.aux, stuck, runs + 1

    # BFGS's Cauchy test stops when steps get short, which a stale inverse-Hessian estimate can
    # cause away from a stationary point (measured on a reach problem of the stance benchmark:
    # stopped with |grad| = 0.83 at objective 156.8914, where the direction-set reference finds
    # 156.8896). Where the gradient is not small BFGS runs once more from its answer with a
    # fresh estimate (156.8898 there); one copy of the solver in the compiled program.
    r, (root, local, info) = _build_output_like(dtype)
    start = (jnp.zeros(NUM_AMPLITUDES, dtype), jnp.zeros((), jnp.int32), jnp.array(False),
             BalancedBuild(jnp.zeros(2, dtype), root, local, info), jnp.array(True),
             jnp.zeros((), jnp.int32))
    y, steps, ok, built, _, _ = jax.lax.while_loop(
        lambda c: c[4] & (c[5] < _RUNS), run, start
    )
    return y, steps, ok, built


def _implicit_terms(y, problem: StanceProblem, dp):
    """`(H, mixed)` at an optimum y of eq. 5: the (symmetrised) 6x6 Hessian in y and
    `(d grad_y f / dp) dp`, both from one linearisation of grad_y f."""
    _, lin = jax.linearize(jax.grad(objective), y, problem)
    zero_p = _zero_tangent(problem)
    H = jax.vmap(lambda e: lin(e, zero_p))(jnp.eye(y.shape[0], dtype=y.dtype))
    return 0.5 * (H + H.T), lin(jnp.zeros_like(y), dp)


@_optimum.defjvp
def _optimum_jvp(rtol, atol, max_steps, primals, tangents):
    (problem,), (dp,) = primals, tangents
    y, steps, ok, built = _optimum(problem, rtol, atol, max_steps)
    H, mixed = _implicit_terms(y, problem, dp)
    dy = -_solve_spd(H, mixed)
    _, d_built = jax.jvp(
        lambda p, yy: balanced_rotations(p, amplitudes_from_unknowns(p, yy)), (problem, y), (dp, dy)
    )
    zero = np.zeros((), jax.dtypes.float0)
    return (y, steps, ok, built), (dy, zero, zero, d_built)


def _solve_one(problem: StanceProblem, rtol: float, atol: float, max_steps: int):
    return _finish(problem, *_optimum(problem, rtol, atol, max_steps))


@filter_jit
def solve_stance(
    problem: StanceProblem, rtol: float = 1e-6, atol: float = 1e-6, max_steps: int = 200
) -> StanceSolution:
    """Solve one stance: torso amplitudes minimising eq. 5 with balance and analytic IK inside.

    Differentiable with respect to every array in `problem` (intensity, targets, feet, body)
    through the optimum by implicit differentiation (`_optimum`: the implicit function theorem
    with the 6x6 Hessian at the solution).

    Arguments:
        problem: a `StanceProblem` (`make_problem` or a shape set's `problem`).
        rtol, atol: BFGS tolerances on the step and gradient.
        max_steps: iteration limit (`converged` is False if hit).

    Returns:
        A `StanceSolution`.
    """
    return _solve_one(problem, rtol, atol, max_steps)


@filter_jit
def solve_stances(
    problems: StanceProblem,
    rtol: float = 1e-6,
    atol: float = 1e-6,
    max_steps: int = 200,
    batch_size: int | str | None = "auto",
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

    Returns:
        A `StanceSolution` whose leaves have a leading batch axis.
    """
    arrays, static = eqx.partition(problems, eqx.is_array)

    def one(a):
        return _solve_one(eqx.combine(a, static), rtol, atol, max_steps)

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
