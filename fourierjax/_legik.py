"""Analytic two-bone leg IK shared by the stance lower body and the gait foot lock (NaN-safe, pure jnp)."""

import jax
import jax.numpy as jnp
from jaxtyping import Array, Float

from fourierjax._math import safe_sqrt

_EPS = 1e-12
_EY = jnp.array([0.0, 1.0, 0.0])
_EZ = jnp.array([0.0, 0.0, 1.0])


def _select(cond, x, y):
    # A bare select (no nested jit of jnp.where: the stance solver's compile time counts kernels).
    cond, x, y = jnp.asarray(cond), jnp.asarray(x), jnp.asarray(y)
    dtype = jnp.result_type(x, y)
    shape = jnp.broadcast_shapes(cond.shape, x.shape, y.shape)

    def full(v, dt):
        v = v if v.dtype == dt else v.astype(dt)
        return v if v.shape == shape else jnp.broadcast_to(v, shape)

    return jax.lax.select(full(cond, cond.dtype), full(x, dtype), full(y, dtype))


def _split3(x):
    return jnp.split(x, 3, axis=-1)


def _sum3(x):
    # Two adds, which XLA fuses into the consumers (a reduction is a kernel of its own).
    if x.shape[-1] != 3:
        return jnp.sum(x, axis=-1)
    a, b, c = _split3(x)
    return jax.lax.squeeze(a + b + c, (x.ndim - 1,))


def dot(a: Float[Array, "... 3"], b: Float[Array, "... 3"]) -> Float[Array, "..."]:
    """Dot product over the last axis."""
    return _sum3(a * b)


def cross(a: Float[Array, "... 3"], b: Float[Array, "... 3"]) -> Float[Array, "... 3"]:
    """Cross product over the last axis."""
    (a0, a1, a2), (b0, b1, b2) = _split3(a), _split3(b)
    return jnp.concatenate([a1 * b2 - a2 * b1, a2 * b0 - a0 * b2, a0 * b1 - a1 * b0], axis=-1)


def _rsqrt_where(sq, small):
    return _select(small, 0.0, jax.lax.rsqrt(_select(small, 1.0, sq)))


def safe_norm(v: Float[Array, "... 3"]) -> Float[Array, "..."]:
    """|v| with a zero (not NaN) gradient at v = 0 (double-where shim)."""
    sq = _sum3(v * v)
    return sq * _rsqrt_where(sq, sq < _EPS * _EPS)


def safe_normalize(v: Float[Array, "... 3"], fallback: Float[Array, "... 3"]) -> Float[Array, "... 3"]:
    """v / |v|, or `fallback` (assumed unit) where |v| is ~0; finite gradients everywhere."""
    sq = _sum3(v * v)[..., None]
    small = sq < 1e-20
    return _select(small, fallback, v * _rsqrt_where(sq, small))


def sphere_circle_point(
    centre_a: Float[Array, "3"],
    centre_b: Float[Array, "3"],
    radius_a: Float[Array, ""],
    radius_b: Float[Array, ""],
    pole: Float[Array, "3"],
) -> tuple[Float[Array, "3"], Float[Array, ""]]:
    """The point at `radius_a` from `centre_a` and `radius_b` from `centre_b` nearest `pole`.

    The two spheres meet in a circle in the plane perpendicular to `centre_b - centre_a`; the
    point returned is `centre + r * normalize(in-plane part of pole)`, which has no switch and
    stays differentiable. Two-bone IK: `centre_a` the hip, `centre_b` the ankle goal, the radii
    the thigh and shin lengths, `pole` the knee's bend direction (the knee then bends the way it
    did). Neff & Fiume 2004, appendix (Fig. 8): the free hip is the same construction.

    Arguments:
        centre_a, centre_b: `[3]` sphere centres; radius_a, radius_b: their radii (> 0).
        pole: `[3]` direction (from `centre_a`) the point should lie towards.

    Returns:
        `(point [3], gap)`; `gap > 0` when the spheres do not meet (the point is then on the
        line through the centres, as near both spheres as it can be).
    """
    A = centre_b - centre_a
    nA = safe_norm(A)
    Ahat = safe_normalize(A, -_EY)
    W, C = radius_a, radius_b
    a = (W * W - C * C + nA * nA) / (2.0 * jnp.maximum(nA, 1e-9))
    r = safe_sqrt(W * W - a * a)
    a_clamped = jnp.minimum(jnp.maximum(a, -W), W)
    gap = jnp.maximum(nA - (W + C), 0.0) + jnp.maximum(jnp.abs(W - C) - nA, 0.0)
    centre = centre_a + a_clamped * Ahat
    inplane = pole - dot(pole, Ahat) * Ahat
    fallback = safe_normalize(cross(Ahat, _EY), _EZ)
    return centre + r * safe_normalize(inplane, fallback), gap


def knee_pole(
    hip: Float[Array, "... 3"], knee: Float[Array, "... 3"], ankle: Float[Array, "... 3"]
) -> Float[Array, "... 3"]:
    """The direction a leg's knee bends, for `sphere_circle_point`'s `pole`: the knee's offset
    from the pose's own hip-to-ankle line, plus 1e-3 of the thigh: a fallback that weighs as
    much as the offset only within about 0.1 deg of a straight leg (the offset is the thigh's
    length times the sine of its angle to that line).

    The thigh itself (`knee - hip`) as the pole bends the knee towards wherever the new
    hip-to-goal line leaves the pose's own: for a near-straight pose leg that is the goal's
    shift, not the knee's bend. Bandai-1 run_happy (N = 5, 30 fps, locked at 4x): the pose's
    knee at 172-175 deg, the goal bending it to 152 deg, and the knee swung 23.5 units in one
    frame about the hip-to-ankle line (the capture's largest joint move 16.4) at an unchanged
    knee angle."""
    thigh = knee - hip
    axis = safe_normalize(ankle - hip, -_EY)
    return thigh - dot(thigh, axis)[..., None] * axis + 1e-3 * thigh


def quat_between(a: Float[Array, "... 3"], b: Float[Array, "... 3"]) -> Float[Array, "... 4"]:
    """The shortest rotation (wxyz) turning direction `a` onto direction `b`.

    Identity where either is ~0; finite gradients away from antiparallel directions (the leg's
    bones turn by a few degrees a frame).

    Arguments:
        a, b: `[..., 3]` directions (any length).

    Returns:
        `[..., 4]` unit quaternions.
    """
    ua = safe_normalize(a, jnp.broadcast_to(_EY.astype(a.dtype), a.shape))
    ub = safe_normalize(b, ua)
    w = 1.0 + dot(ua, ub)[..., None]
    q = jnp.concatenate([w, cross(ua, ub)], axis=-1)
    sq = _sum3(q[..., 1:] * q[..., 1:])[..., None] + q[..., :1] ** 2
    small = sq < 1e-20
    one = jnp.zeros_like(q).at[..., 0].set(1.0)
    return _select(small, one, q * _rsqrt_where(sq, small))


def soft_reach(
    d: Float[Array, "..."], reach: Float[Array, "..."], knee: float = 0.97, limit: float = 0.999,
    start: Float[Array, "..."] | None = None,
) -> Float[Array, "..."]:
    """Distances `d` eased below `reach` (smooth, monotone, identity below `knee * reach`).

    A goal beyond the straight leg would snap the knee straight (a pop) and could not be met:
    the eased distance approaches `limit * reach` (the knee never reaches full extension).

    Arguments:
        d: hip-to-goal distances; reach: thigh + shin; knee: where easing starts and limit
            what it approaches (fractions of the reach); start: distances that stay as they are
            (e.g. the pose's own hip-to-ankle distance: only what a goal adds is eased).

    Returns:
        Eased distances, same shape.
    """
    d0, d1 = knee * reach, limit * reach
    if start is not None:
        d0 = jnp.minimum(jnp.maximum(d0, start), d0 + 0.9 * (d1 - d0))
    x = jnp.maximum(d - d0, 0.0) / (d1 - d0)
    return jnp.where(d > d0, d0 + (d1 - d0) * jnp.tanh(x), d)
