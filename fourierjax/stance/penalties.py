"""Penalty functions (Neff & Fiume 2004, sec. 5.2, Fig. 4, eq. 5): four cubic Hermite segments."""


import equinox as eqx
import jax.numpy as jnp
from jaxtyping import Array, Float

from fourierjax.errors import UserError
from fourierjax.stance import _util as u


class HermitePenalty(eqx.Module):
    """A smooth penalty around a desired value: two cubic Hermite segments on each side.

    Distances from the desired point `t = |x - desired|` are measured separately on the
    left (`x < desired`, index 0) and right (index 1). On each side the penalty is 0 with
    zero slope at t = 0, reaches `values[side, 0]` with slope `slopes[side, 0]` at
    `t = widths[side, 0]`, then `values[side, 1]` with slope `slopes[side, 1]` at
    `t = widths[side, 0] + widths[side, 1]`, and continues linearly beyond. Slopes are with
    respect to t (positive = rising away from the desired point). Flat basins (small inner
    value and slope), steep walls (large outer ones) and asymmetry (different sides) are all
    expressible. All fields are arrays; leading batch dims are allowed (vmap over them).

    - `desired`: `[...]` the set point.
    - `widths`, `values`, `slopes`: `[..., 2, 2]` (side, segment).
    """

    desired: Float[Array, "..."]
    widths: Float[Array, "... 2 2"]
    values: Float[Array, "... 2 2"]
    slopes: Float[Array, "... 2 2"]

    def __call__(self, x: Float[Array, "..."]) -> Float[Array, "..."]:
        return hermite_penalty(self, x)


def quadratic_penalty(desired, scale, inner=1.0, outer=2.5) -> HermitePenalty:
    """A symmetric penalty equal to ((x - desired) / scale)^2 out to `outer * scale`.

    A cubic Hermite segment reproduces a parabola exactly, so this is the quadratic up to
    `outer` scales and linear (C1) beyond.
    """
    desired = jnp.asarray(desired, float)
    scale = jnp.asarray(scale, float)
    batch = jnp.broadcast_shapes(desired.shape, scale.shape)
    sc = jnp.broadcast_to(scale, batch)[..., None, None]
    knots = jnp.array([inner, outer])

    def per_side(row):  # the same [2] knot row on both sides, broadcast to the batch
        return jnp.broadcast_to(jnp.stack([row, row]), batch + (2, 2))

    return HermitePenalty(
        desired=jnp.broadcast_to(desired, batch),
        widths=per_side(jnp.array([inner, outer - inner])) * sc,
        values=per_side(knots**2),
        slopes=per_side(2.0 * knots) / sc,
    )


def reach_penalty(arm_length, desired_fraction=0.8, wall_fraction=0.97) -> HermitePenalty:
    """Penalty on the shoulder-to-target distance for an active wrist constraint (sec. 5.2).

    A flat basin inside the arm's reach (closer than desired costs little) and a steep wall
    beyond `wall_fraction` of the arm length: the solver moves the torso until the analytic
    arm IK can reach the target.
    """
    L = jnp.asarray(arm_length, float)
    d0 = desired_fraction * L
    wall = wall_fraction * L
    widths = jnp.stack(
        [jnp.stack([0.25 * L, 0.25 * L]), jnp.stack([wall - d0, 0.1 * L])]
    )
    values = jnp.array([[0.05, 0.5], [1.0, 60.0]])
    slopes = jnp.stack([jnp.stack([0.4 / L, 4.0 / L]), jnp.stack([12.0 / L, 1200.0 / L])])
    return HermitePenalty(desired=d0, widths=widths, values=values, slopes=slopes)


def _hermite(t, w, v0, s0, v1, s1):
    """Cubic Hermite on [0, w] at t (values v0, v1, slopes s0, s1 w.r.t. t)."""
    h = t / w
    h2, h3 = h * h, h * h * h
    return (
        (2 * h3 - 3 * h2 + 1) * v0
        + (h3 - 2 * h2 + h) * w * s0
        + (-2 * h3 + 3 * h2) * v1
        + (h3 - h2) * w * s1
    )


def hermite_penalty(p: HermitePenalty, x: Float[Array, "..."]) -> Float[Array, "..."]:
    """Value of the penalty `p` at `x` (see `HermitePenalty`); C1 everywhere."""
    dx = x - p.desired
    batch = jnp.broadcast_shapes(dx.shape, p.widths.shape[:-2])
    dx = jnp.broadcast_to(dx, batch)
    right = (dx > 0)[..., None]

    def pick(a):
        a = jnp.broadcast_to(a, batch + (2, 2))
        return u.where(right, a[..., 1, :], a[..., 0, :])

    w, v, s = pick(p.widths), pick(p.values), pick(p.slopes)
    t = jnp.abs(dx)
    w0, w1 = w[..., 0], w[..., 1]
    v0, v1, s0, s1 = v[..., 0], v[..., 1], s[..., 0], s[..., 1]
    # One cubic on the segment t falls in: [0, w0] from (0, 0) to (v0, s0), then [w0, w0 + w1]
    # from (v0, s0) to (v1, s1); a line beyond.
    second = t > w0
    zero = jnp.zeros_like(t)
    cubic = _hermite(
        u.where(second, u.clip(t - w0, 0.0, w1), t),
        u.where(second, w1, w0),
        u.where(second, v0, zero),
        u.where(second, s0, zero),
        u.where(second, v1, v0),
        u.where(second, s1, s0),
    )
    tail = v1 + s1 * (t - w0 - w1)  # only selected beyond the last knot
    return u.where(t <= w0 + w1, cubic, tail)


def check_penalty(p: HermitePenalty, name: str = "penalty") -> None:
    """Raise a UserError naming `name` if widths are not positive or values not finite."""
    import numpy as np

    for field in ("widths", "values", "slopes", "desired"):
        a = np.asarray(getattr(p, field))
        if not np.isfinite(a).all():
            raise UserError(f"{name}: {field} holds NaN or infinite values")
    if (np.asarray(p.widths) <= 0).any():
        raise UserError(f"{name}: segment widths must be positive")
