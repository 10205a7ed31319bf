"""Balance (Neff & Fiume 2004, sec. 4): COM projection at a point of the support polygon."""


from collections.abc import Callable

import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float

from fourierjax import rotations
from fourierjax._linalg import matmul
from fourierjax.stance import _util as u
from fourierjax.stance.ik import Feet
from fourierjax.stance.skeleton48 import LEFT, RIGHT, Body


def monitor_points_world(body: Body, feet: Feet) -> Float[Array, "2 4 3"]:
    """World positions of the feet's monitor points (heel/toe, inner/outer) (m)."""
    return feet.positions[:, None, :] + rotations.quat_apply(
        feet.quats[:, None, :], body.monitor_points
    )


def balance_point(
    body: Body, feet: Feet, weight_shift: Float[Array, ""], forward_shift: Float[Array, ""]
) -> Float[Array, "2"]:
    """Desired ground point (X, Z) of the COM projection.

    Each foot contributes the point between its heel and toe midpoints set by
    `forward_shift` (-1 heel, 0 middle, +1 toe); `weight_shift` moves between the right
    (-1) and left (+1) foot. Both are convex combinations of monitor points, so for values
    in [-1, 1] the point lies in their convex hull, the support polygon. Beyond +-1 (a shape
    set extrapolated past intensity 1, say) they extrapolate and the point can leave the
    polygon: the solver still puts the COM there, a pose that is not statically balanced.
    `problem.balance_margin_m` measures it.

    Returns:
        `[2]` (x, z) in metres.
    """
    m = monitor_points_world(body, feet)
    heel = 0.5 * (m[:, 0] + m[:, 1])
    toe = 0.5 * (m[:, 2] + m[:, 3])
    a = 0.5 * (forward_shift + 1.0)
    per_foot = heel + a * (toe - heel)
    b = 0.5 * (weight_shift + 1.0)
    p = per_foot[RIGHT] + b * (per_foot[LEFT] - per_foot[RIGHT])
    return jnp.stack([p[0], p[2]])


def support_polygon(points_xz: np.ndarray) -> np.ndarray:
    """Convex hull (counter-clockwise in the X-Z plane) of monitor points `[N, 2]` (numpy)."""
    pts = sorted({(float(x), float(z)) for x, z in np.asarray(points_xz).reshape(-1, 2)})
    if len(pts) < 3:
        return np.array(pts)

    def turn(o, a, b):
        return (a[0] - o[0]) * (b[1] - o[1]) - (a[1] - o[1]) * (b[0] - o[0])

    lower: list = []
    for p in pts:
        while len(lower) >= 2 and turn(lower[-2], lower[-1], p) <= 0:
            lower.pop()
        lower.append(p)
    upper: list = []
    for p in reversed(pts):
        while len(upper) >= 2 and turn(upper[-2], upper[-1], p) <= 0:
            upper.pop()
        upper.append(p)
    return np.array(lower[:-1] + upper[:-1])


def inside_polygon_margin(polygon: np.ndarray, point: np.ndarray) -> float:
    """Signed distance (m) from `point` to the edges of a CCW convex polygon; > 0 inside."""
    margins = []
    n = len(polygon)
    for i in range(n):
        a, b = polygon[i], polygon[(i + 1) % n]
        e = b - a
        normal = np.array([-e[1], e[0]]) / np.linalg.norm(e)  # inward for CCW
        margins.append(float(np.dot(point - a, normal)))
    return min(margins)


#: Newton's balance solve stops once the residual is at most `RESIDUAL_TOLERANCE_EPS` times the
#: dtype's machine epsilon in metres (1.2e-7 m in float32: round-off of a COM about 1 m from
#: the origin) or, below `STALL_BELOW_EPS` epsilons (1.2e-5 m in float32), when an evaluation
#: no longer shrinks it by 4x (round-off reached: Newton's quadratic steps shrink it by far more).
RESIDUAL_TOLERANCE_EPS = 1.0
STALL_BELOW_EPS = 100.0


def newton_2d_with_tangents(
    fn: Callable,
    a: Float[Array, " n"],
    x0: Float[Array, "2"],
    a_directions: Float[Array, "m n"],
    max_evaluations: int = 12,
    max_step: float = 0.25,
    out_like=None,
):
    """Solve `fn(a, x)[0] = 0` for two unknowns x by damped Newton, with directional derivatives.

    `fn(a, x) -> (r [2], aux)`. Every evaluation is one forward-mode pass of `fn` with m + 2
    tangent directions at once (vmapped JVPs sharing one primal): `(da_i, 0)` for the rows of
    `a_directions` and `(0, e_k)` for the two unknowns. The last two give the exact Jacobian
    dr/dx for the Newton step; the others are returned with the answer, so a caller gets the
    solution *and* its tangents from one traced copy of `fn` (inside a `while_loop`): the
    stance solver's objective needs the pose, its balance Jacobian and its derivatives in the
    six torso amplitudes, and compiles about half the XLA kernels it did with a Broyden loop
    followed by a separate linearisation.

    Steps are clipped to `max_step` per component, and a point whose residual is not smaller
    than the best one's is rejected: the next try is halfway back to the best point. Where
    the Jacobian's determinant changes sign between the start and the root, undamped steps
    wandered without converging (measured: a random posture whose root, at offsets
    (0.18, 0.52) rad, took 12 undamped evaluations; the fixed 5 we had stopped 8.8 mm off).
    The loop stops at `RESIDUAL_TOLERANCE_EPS`, at round-off (`STALL_BELOW_EPS`) or after
    `max_evaluations`. On 60 random shape vectors and torso amplitudes: 3-6 evaluations for
    56, median 4 (the fixed count was 5), 11 and 12 for the two hard ones, one of which has
    no root (best residual 0.97 mm, flagged by the solver's `converged`).

    No LAPACK (a closed-form 2x2 inverse). Differentiate the solution by the implicit
    function theorem, not through this loop. `out_like` (optional): arrays shaped like
    `fn`'s output, for the loop's initial carry; without it `fn` is traced once more to get
    the shapes (for the stance builder that trace costs as much as the loop's, ~0.9 s).

    Returns:
        `(x, (r, aux), (dr, daux))` at the BEST EVALUATED x (smallest |r|), so that `r`,
        `aux` and the tangents describe exactly the returned x. `dr` is `[m + 2, 2]`, `daux`
        has a leading `m + 2` axis (the two balance directions last).
    """
    m = a_directions.shape[0]
    eps = float(jnp.finfo(x0.dtype).eps)
    da = jnp.concatenate([a_directions, jnp.zeros((2,) + a.shape, a.dtype)])
    dx = jnp.concatenate([jnp.zeros((m, 2), x0.dtype), jnp.eye(2, dtype=x0.dtype)])

    def evaluate(x):
        # Every evaluation carries all m + 2 directions: one traced copy of `fn`.
        def along(da_i, dx_i):
            return jax.jvp(fn, (a, x), (da_i, dx_i))

        return jax.vmap(along, out_axes=(None, 0))(da, dx)

    def keep_going(carry):
        k, *_, done = carry
        return (k < max_evaluations) & ~done

    def step(carry):
        k, x_try, x_best, best, out_best, _ = carry
        out = evaluate(x_try)
        (r, _), (dr, _) = out
        norm = jnp.sqrt(jnp.sum(r * r))
        better = norm < best
        newton = x_try - u.clip(matmul(inverse_2x2(dr[m:].T), r), -max_step, max_step)
        stalled = (jnp.minimum(norm, best) <= STALL_BELOW_EPS * eps) & (norm > 0.25 * best)
        x_best = u.where(better, x_try, x_best)
        out_best = jax.tree.map(lambda new, old: u.where(better, new, old), out, out_best)
        best = jnp.minimum(norm, best)
        x_next = u.where(better, newton, 0.5 * (x_best + x_try))
        done = (best <= RESIDUAL_TOLERANCE_EPS * eps) | stalled
        return k + 1, x_next, x_best, best, out_best, done

    primal = jax.eval_shape(fn, a, x0) if out_like is None else out_like
    empty = (jax.tree.map(lambda s: jnp.zeros(s.shape, s.dtype), primal),
             jax.tree.map(lambda s: jnp.zeros((m + 2,) + s.shape, s.dtype), primal))
    inf = jnp.array(jnp.inf, x0.dtype)
    start = (jnp.zeros((), jnp.int32), x0, x0, inf, empty, jnp.array(False))
    _, _, x, _, out, _ = jax.lax.while_loop(keep_going, step, start)
    return (x,) + out


def inverse_2x2(J: Float[Array, "2 2"]) -> Float[Array, "2 2"]:
    """Closed-form inverse of a 2x2 matrix; 0 where it is singular (|det| <= 1e-12)."""
    det = J[0, 0] * J[1, 1] - J[0, 1] * J[1, 0]
    ok = jnp.abs(det) > 1e-12
    inv_det = u.where(ok, 1.0 / u.where(ok, det, 1.0), 0.0)
    return inv_det * jnp.array([[J[1, 1], -J[0, 1]], [-J[1, 0], J[0, 0]]])


def feedback_update(
    offsets_xz: Float[Array, "2"],
    com_error_xz: Float[Array, "2"],
    leg_length_m: Float[Array, ""],
    gain: float = 0.8,
) -> Float[Array, "2"]:
    """One step of the paper's feedback balance control for animation (sec. 4).

    The X and Z errors of the COM projection (actual - desired, m) are fed back into the Z
    and X axes of the dominant ankle. Tilting the ankle->hip vector by an angle a moves the
    body by about `leg_length * a`, hence the gain per metre. The foot is planted, so a
    positive ankle X rotation tips the leg backward (-Z) and a positive Z rotation tips it
    toward +X.

    Returns:
        `[2]` updated (X, Z) ankle offsets (rad).
    """
    k = gain / leg_length_m
    return offsets_xz + k * jnp.stack([com_error_xz[1], -com_error_xz[0]])
