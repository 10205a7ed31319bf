"""Float32 sine and cosine sharing one range reduction (Cephes minimax polynomials), radians or degrees.

XLA's CPU `sin` is several times slower than numpy's and FK needs both the sine and the cosine
of every angle; one reduction and two short polynomials give both to about 1 ulp. Other dtypes
use `jnp.sin` / `jnp.cos`. The quadrant is piecewise constant, so gradients are those of the
polynomials (accurate to float32 rounding).
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import jax.numpy as jnp
import numpy as np

if TYPE_CHECKING:
    from jaxtyping import Array

# Cody-Waite split of pi/2 (float32) and Cephes sinf/cosf coefficients on [-pi/4, pi/4].
_PIO2 = (1.5703125, 4.837512969970703125e-4, 7.54978995489188216e-8)
_SIN = (-1.6666654611e-1, 8.3321608736e-3, -1.9515295891e-4)
_COS = (4.166664568298827e-2, -1.388731625493765e-3, 2.443315711809948e-5)


def _from_reduced(r: Array, n: Array) -> tuple[Array, Array]:
    """sin/cos of `r + n pi/2` for `r` in [-pi/4, pi/4] and an integer-valued float `n`."""
    r2 = r * r
    s = r + r * r2 * (_SIN[0] + r2 * (_SIN[1] + r2 * _SIN[2]))
    c = 1.0 - 0.5 * r2 + r2 * r2 * (_COS[0] + r2 * (_COS[1] + r2 * _COS[2]))
    q = n - 4.0 * jnp.floor(n * 0.25)  # quadrant 0..3, exact in floats (no int conversion)
    swap = (q == 1.0) | (q == 3.0)
    sin = jnp.where(swap, c, s)
    cos = jnp.where(swap, s, c)
    return jnp.where(q >= 2.0, -sin, sin), jnp.where((q == 1.0) | (q == 2.0), -cos, cos)


def sincos(x: Array) -> tuple[Array, Array]:
    """`(sin x, cos x)` of angles in radians; float32 to about 1 ulp for |x| < 1e4.

    Arguments:
        x: angles in radians, any shape.

    Returns:
        `(sin x, cos x)`, each of `x`'s shape and dtype.
    """
    if x.dtype != jnp.float32:
        return jnp.sin(x), jnp.cos(x)
    n = jnp.round(x * (2.0 / np.pi))
    r = ((x - n * _PIO2[0]) - n * _PIO2[1]) - n * _PIO2[2]
    return _from_reduced(r, n)


def sincos_degrees(x: Array) -> tuple[Array, Array]:
    """`(sin x, cos x)` of angles in degrees; the float32 reduction `x - 90 n` is exact.

    Arguments:
        x: angles in degrees, any shape.

    Returns:
        `(sin x, cos x)`, each of `x`'s shape and dtype.
    """
    if x.dtype != jnp.float32:
        r = jnp.deg2rad(x)
        return jnp.sin(r), jnp.cos(r)
    n = jnp.floor(x * np.float32(1 / 90) + 0.5)
    return _from_reduced((x - n * 90.0) * np.float32(np.pi / 180), n)


# Near-minimax (least squares on Chebyshev nodes, float64) on [-pi/2, pi/2]: sin and cos to
# ~1.3e-7 in float32 arithmetic (measured on 2e5 points), the float32 rounding level.
_SIN_HALF = (-0.16666657317261288, 0.008333021848736692, -0.00019806899913215898, 2.600609800457697e-06)
_COS_HALF = (0.041666666603122904, -0.0013888886261050407, 2.4801193907268004e-05, -2.752996344489731e-07,
             1.9976362434885597e-09)


def _horner(coefficients: tuple[float, ...], x: Array) -> Array:
    acc = coefficients[-1]
    for k in reversed(coefficients[:-1]):
        acc = k + x * acc
    return acc


def half_angle_sincos_degrees(x: Array) -> tuple[Array, Array]:
    """`s (sin(x / 2), cos(x / 2))` of angles `x` in degrees, with one sign `s = +-1` per angle.

    For rotations only: a quaternion's halves `cos(x / 2) + sin(x / 2) u` and their negation are
    the same rotation, and the positions FK derives from them are equal. The reduction
    `x - 360 n` (exact in float32) leaves `x / 2` in [-90, 90] degrees, where two longer
    polynomials need no quadrant fix-up: in float32, 0.25 against 0.48 ms for `sincos_degrees`
    of 72 x 10,000 half-angles (2 cores, one pinned; the fix-up's compares and selects cost as
    much as the polynomials).

    Arguments:
        x: angles in degrees, any shape.

    Returns:
        `(s sin(x / 2), s cos(x / 2))`, each of `x`'s shape and dtype (`s` = 1 outside float32).
    """
    if x.dtype != jnp.float32:
        r = jnp.deg2rad(0.5 * x)
        return jnp.sin(r), jnp.cos(r)
    n = jnp.floor(x * np.float32(1 / 360) + 0.5)
    r = (x - n * 360.0) * np.float32(np.pi / 360)
    r2 = r * r
    return r + r * r2 * _horner(_SIN_HALF, r2), 1.0 - 0.5 * r2 + (r2 * r2) * _horner(_COS_HALF, r2)
