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
