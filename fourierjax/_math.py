"""Elementwise numerics shared by every module: angle wrapping and a NaN-safe square root."""

from __future__ import annotations

from typing import TYPE_CHECKING

import jax
import jax.numpy as jnp

if TYPE_CHECKING:
    from jaxtyping import Array, ArrayLike, Float


def wrap_angle(x: ArrayLike) -> Array:
    """Wrap angles to (−π, π].

    Arguments:
        x: angles in radians, any shape.

    Returns:
        `x + 2πk` in (−π, π], same shape; the gradient is 1 everywhere.
    """
    x = jnp.asarray(x)
    return jnp.pi - jnp.mod(jnp.pi - x, 2 * jnp.pi)


def safe_sqrt(x: Float[ArrayLike, "*shape"], floor: float = 0.0) -> Float[Array, "*shape"]:
    """`sqrt(max(x, floor))` with a zero (not NaN or infinite) gradient where `x <= floor`.

    One sqrt and two bare selects (no nested jit of `jnp.where`: the stance solver's compile
    time counts its kernels). Not `x * rsqrt(x)`: its gradient overflows to NaN in float32 for
    `0 < x < ~2e-26`.

    Arguments:
        x: any shape.
        floor: a Python float >= 0; at and below it the value is `sqrt(floor)`.

    Returns:
        Same shape as `x`.
    """
    x = jnp.asarray(x)
    lo = x <= max(floor, float(jnp.finfo(x.dtype).tiny) if jnp.issubdtype(x.dtype, jnp.floating) else floor)
    # Shim to avoid NaNs in the branch not taken, which cause failures for reverse-mode AD.
    x_safe = jax.lax.select(lo, jnp.ones_like(x), x)
    root = jax.lax.sqrt(x_safe)
    return jax.lax.select(lo, jnp.full_like(root, max(floor, 0.0) ** 0.5), root)
