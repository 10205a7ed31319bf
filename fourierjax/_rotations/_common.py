"""Shared pieces of the rotation modules: input checks, NaN-safe helpers, component splits."""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

import jax
import jax.numpy as jnp

from fourierjax.errors import UserError

if TYPE_CHECKING:
    from jaxtyping import Array, ArrayLike

#: The 6 Tait-Bryan and 6 proper Euler orders. BVH / intrinsic semantics: for order "ZYX" and
#: angles (a, b, c), R = Rz(a) @ Ry(b) @ Rx(c) (scipy: ``Rotation.from_euler("ZYX", ...)``).
EULER_ORDERS: tuple[str, ...] = (
    "XYZ", "XZY", "YXZ", "YZX", "ZXY", "ZYX",
    "XYX", "XZX", "YXY", "YZY", "ZXZ", "ZYZ",
)  # fmt: skip

_AXIS_INDEX = {"X": 0, "Y": 1, "Z": 2}
_TWO_PI = 2.0 * math.pi


# ----------------------------------------------------------------------------- input checks


def _as_float(x: ArrayLike, name: str, fn: str) -> Array:
    try:
        x = jnp.asarray(x)
    except TypeError as e:
        raise UserError(f"{fn}: {name} must be an array of numbers ({e})") from None
    if not jnp.issubdtype(x.dtype, jnp.floating):
        if jnp.issubdtype(x.dtype, jnp.complexfloating):
            raise UserError(f"{fn}: {name} must be real, got dtype {x.dtype}")
        x = x.astype(jnp.result_type(float))
    return x


def _check_tail(x: Array, tail: tuple[int, ...], name: str, fn: str) -> None:
    if x.ndim < len(tail) or tuple(x.shape[x.ndim - len(tail) :]) != tail:
        want = ", ".join(["..."] + [str(t) for t in tail])
        raise UserError(f"{fn}: {name} must have shape [{want}], got {tuple(x.shape)}")


def _vec(x: ArrayLike, n: int, name: str, fn: str) -> Array:
    x = _as_float(x, name, fn)
    _check_tail(x, (n,), name, fn)
    return x


def _mat(x: ArrayLike, name: str, fn: str) -> Array:
    x = _as_float(x, name, fn)
    _check_tail(x, (3, 3), name, fn)
    return x


def _check_order(order: str, fn: str) -> str:
    if isinstance(order, str) and order in EULER_ORDERS:
        return order
    hint = ""
    if isinstance(order, str) and order.upper() in EULER_ORDERS:
        hint = (
            " (orders are upper case: fourierjax uses BVH intrinsic semantics; in scipy a"
            " lower-case order means extrinsic)"
        )
    raise UserError(f"{fn}: order must be one of {', '.join(EULER_ORDERS)}; got {order!r}{hint}")


def _broadcast_batch(a: Array, na: int, b: Array, nb: int) -> tuple[Array, Array]:
    """Broadcast the leading (batch) dims of a and b explicitly (rank promotion may be 'raise')."""
    batch = jnp.broadcast_shapes(a.shape[: a.ndim - na], b.shape[: b.ndim - nb])
    a = jnp.broadcast_to(a, batch + a.shape[a.ndim - na :])
    b = jnp.broadcast_to(b, batch + b.shape[b.ndim - nb :])
    return a, b


def _common_dtype(a: Array, b: Array) -> tuple[Array, Array]:
    dtype = jnp.result_type(a, b)
    return a.astype(dtype), b.astype(dtype)


# ------------------------------------------------------------------------- NaN-safe helpers
# Both branches of jnp.where are differentiated, so sqrt(0), atan2(0, 0) or x / |x| at 0 give NaN
# gradients even in the branch not taken. Each helper substitutes a harmless input where the
# singular one would be (the "double-where" shim of jaxlie's _so3.py).


def _tiny(dtype) -> float:
    return float(jnp.finfo(dtype).tiny)


def zero_norm_threshold(dtype) -> float:
    """The norm at and below which a quaternion or an axis counts as zero, for one dtype.

    `finfo(dtype).tiny ** 0.25`: about 3.3e-10 in float32 and 1.2e-77 in float64. Above it,
    `v / |v|` and its derivative (which holds `|v|**-3`) are finite; at and below it the
    NaN-safe helpers return their zero-input value with a zero gradient.

    Arguments:
        dtype: a floating dtype.

    Returns:
        The threshold on `|v|` (a Python float).
    """
    return _tiny(dtype) ** 0.25


def _taylor_threshold(dtype) -> float:
    # Below this squared angle the 3-term Taylor series are exact to machine precision.
    return float(jnp.finfo(dtype).eps) ** 0.5


def _sqrt_finite_grad(x: Array) -> Array:
    """sqrt(x) for x >= 0 with a zero gradient at and below `tiny`, by `jnp.sqrt`.

    Kept instead of `fourierjax._math.safe_sqrt` on purpose: that one computes `x * rsqrt(x)`,
    whose derivative holds `x ** -1.5` and is -inf for x in (tiny, ~1e-26] in float32, which
    the squared hypotenuses of `euler_from_quat` reach at gimbal lock (`sqrt`'s `0.5 / sqrt(x)`
    stays finite there).
    """
    zero = x <= _tiny(x.dtype)
    return jnp.where(zero, 0.0, jnp.sqrt(jnp.where(zero, 1.0, x)))


def _safe_atan2(y: Array, x: Array) -> Array:
    """atan2(y, x), with value 0 and zero gradient where (x, y) = (0, 0)."""
    zero = x * x + y * y <= _tiny(x.dtype)
    return jnp.where(zero, 0.0, jnp.arctan2(jnp.where(zero, 0.0, y), jnp.where(zero, 1.0, x)))


def _safe_normalize(v: Array) -> tuple[Array, Array]:
    """(v / |v|, |v| <= zero_norm_threshold) along the last axis; a zero vector maps to zero
    with a zero gradient."""
    sq = jnp.sum(v * v, axis=-1, keepdims=True)
    # On the squared norm: tiny ** 0.5 keeps rsqrt's derivative (sq ** -1.5) below tiny ** -0.75.
    zero = sq <= zero_norm_threshold(v.dtype) ** 2
    inv = jnp.where(zero, 0.0, jax.lax.rsqrt(jnp.where(zero, 1.0, sq)))
    return v * inv, zero[..., 0]


def _unstack(x: Array) -> list[Array]:
    """The components along the last axis. A split (whose transpose is one concatenate) compiles
    much faster under grad than per-component indexing (each a slice, transposed to pad + add)."""
    return [jnp.squeeze(part, axis=-1) for part in jnp.split(x, x.shape[-1], axis=-1)]


def _unstack_rows(m: Array) -> list[Array]:
    return [jnp.squeeze(part, axis=-2) for part in jnp.split(m, m.shape[-2], axis=-2)]


def _cross(a: Array, b: Array) -> Array:
    ax, ay, az = _unstack(a)
    bx, by, bz = _unstack(b)
    return jnp.stack([ay * bz - az * by, az * bx - ax * bz, ax * by - ay * bx], axis=-1)


def _stack_matrix(rows) -> Array:
    return jnp.stack([jnp.stack(row, axis=-1) for row in rows], axis=-2)


