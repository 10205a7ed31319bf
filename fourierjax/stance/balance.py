"""Balance (Neff & Fiume 2004, sec. 4): COM projection at a point of the support polygon."""


from collections.abc import Callable

import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float

from fourierjax import rotations
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
    """Desired ground point (X, Z) of the COM projection, always inside the support polygon.

    Each foot contributes the point between its heel and toe midpoints set by
    `forward_shift` (-1 heel, 0 middle, +1 toe); `weight_shift` moves between the right
    (-1) and left (+1) foot. Both are convex combinations of monitor points, so for values
    in [-1, 1] the point lies in their convex hull, the support polygon.

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


def broyden_2d(
    residual: Callable[[Float[Array, "2"]], Float[Array, "2"]],
    x0: Float[Array, "2"],
    inverse_jacobian0: Float[Array, "2 2"],
    num_steps: int = 10,
) -> Float[Array, "2"]:
    """Solve `residual(x) = 0` for two unknowns by Broyden's ("good") method.

    One residual evaluation per step, a fixed number of steps in a `fori_loop` (compiled
    once), the inverse Jacobian estimate updated in closed form: no LAPACK call (safe in
    batched code on 2 cores, STYLE.md) and no derivative of the residual. Start from a good
    `inverse_jacobian0` (the balance solve passes the rigid-body estimate). Differentiate
    the solution by the implicit function theorem, not through this loop.
    """

    def step(_, carry):
        x, x_prev, r_prev, B = carry
        r = residual(x)
        dx, dr = x - x_prev, r - r_prev
        Bdr = B @ dr
        denom = dx @ Bdr
        ok = jnp.abs(denom) > 1e-20
        B = B + jnp.where(ok, jnp.outer(dx - Bdr, dx @ B) / jnp.where(ok, denom, 1.0), 0.0)
        # A quarter radian per step at most: the COM is near-linear in the offsets.
        x_new = x - jnp.clip(B @ r, -0.25, 0.25)
        return x_new, x, r, B

    carry = (x0, x0, jnp.zeros_like(x0), inverse_jacobian0)
    return jax.lax.fori_loop(0, num_steps, step, carry)[0]


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
