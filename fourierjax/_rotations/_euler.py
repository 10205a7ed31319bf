"""Euler angles in the 12 BVH (intrinsic) orders: to and from matrices and quaternions."""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

import jax
import jax.numpy as jnp

from fourierjax._math import wrap_angle
from fourierjax._rotations._common import (
    _AXIS_INDEX,
    _check_order,
    _mat,
    _safe_atan2,
    _sqrt_finite_grad,
    _stack_matrix,
    _unstack,
    _vec,
)
from fourierjax._rotations._quat import matrix_multiply, quat_from_matrix, quat_multiply

if TYPE_CHECKING:
    from jaxtyping import Array, ArrayLike, Float


def _axis_matrix(axis: int, c: Array, s: Array) -> Array:
    one, zero = jnp.ones_like(c), jnp.zeros_like(c)
    if axis == 0:
        rows = ((one, zero, zero), (zero, c, -s), (zero, s, c))
    elif axis == 1:
        rows = ((c, zero, s), (zero, one, zero), (-s, zero, c))
    else:
        rows = ((c, -s, zero), (s, c, zero), (zero, zero, one))
    return _stack_matrix(rows)


def matrix_from_euler(angles: Float[Array, "... 3"], order: str) -> Float[Array, "... 3 3"]:
    """Rotation matrices from Euler angles (BVH intrinsic semantics).

    For order ``"ZYX"`` and angles ``(a, b, c)``: ``R = Rz(a) @ Ry(b) @ Rx(c)``; angle ``i``
    goes with axis ``order[i]`` (scipy: ``Rotation.from_euler("ZYX", angles).as_matrix()``).

    Arguments:
        angles: ``[..., 3]`` angles in radians.
        order: one of ``EULER_ORDERS``.

    Returns:
        ``[..., 3, 3]`` rotation matrices (acting on column vectors).
    """
    fn = "matrix_from_euler"
    order = _check_order(order, fn)
    angles = _vec(angles, 3, "angles", fn)
    c, s = jnp.cos(angles), jnp.sin(angles)  # each trig value once
    mats = [_axis_matrix(_AXIS_INDEX[ax], ci, si) for ax, ci, si in zip(order, _unstack(c), _unstack(s))]
    return matrix_multiply(matrix_multiply(mats[0], mats[1]), mats[2])


# ---------------------------------------------------------------------------- Euler angles


def quat_from_euler(angles: Float[Array, "... 3"], order: str) -> Float[Array, "... 4"]:
    """Unit quaternions from Euler angles (BVH intrinsic semantics, see ``matrix_from_euler``).

    The result is the product of the three axis quaternions, smooth in the angles (not sign
    canonicalised, so ``w`` may be negative).

    Arguments:
        angles: ``[..., 3]`` angles in radians.
        order: one of ``EULER_ORDERS``.

    Returns:
        ``[..., 4]`` unit wxyz quaternions.
    """
    fn = "quat_from_euler"
    order = _check_order(order, fn)
    angles = _vec(angles, 3, "angles", fn)
    half = 0.5 * angles
    c, s = jnp.cos(half), jnp.sin(half)
    quats = []
    for ax, ci, si in zip(order, _unstack(c), _unstack(s)):
        comps = [ci] + [jnp.zeros_like(ci)] * 3
        comps[1 + _AXIS_INDEX[ax]] = si
        quats.append(jnp.stack(comps, axis=-1))
    return quat_multiply(quat_multiply(quats[0], quats[1]), quats[2])


def euler_from_quat(q: Float[Array, "... 4"], order: str) -> Float[Array, "... 3"]:
    """Euler angles (BVH intrinsic semantics) from quaternions.

    Bernardes & Viollet 2022, "Quaternion to Euler angles conversion: a direct, general and
    computationally efficient method" (the algorithm scipy uses). The middle angle comes from an
    ``atan2`` (no ``arcsin`` / ``arccos``), so it is accurate near gimbal lock; gradients are
    finite everywhere (large, as they must be, near gimbal lock).

    Arguments:
        q: ``[..., 4]`` wxyz quaternions (any non-zero norm; either sign).
        order: one of ``EULER_ORDERS``.

    Returns:
        ``[..., 3]`` angles in radians: the middle one in ``[-pi/2, pi/2]`` (Tait-Bryan orders)
        or ``[0, pi]`` (proper Euler orders), the first and last in ``(-pi, pi]``; equal to
        scipy's ``as_euler(order)`` away from gimbal lock. At gimbal lock the split between first
        and last angle is arbitrary but the angles reconstruct the rotation.
    """
    fn = "euler_from_quat"
    order = _check_order(order, fn)
    q = _vec(q, 4, "q", fn)
    # The paper's algorithm is extrinsic; intrinsic "ABC" equals extrinsic "CBA" with the angles
    # reversed.
    i, j, k = (_AXIS_INDEX[ax] for ax in order[::-1])
    symmetric = i == k
    if symmetric:
        k = 3 - i - j
    sign = (i - j) * (j - k) * (k - i) // 2  # +1 for an even permutation of (x, y, z), -1 odd
    comps = _unstack(q)
    w, qi, qj, qk = comps[0], comps[1 + i], comps[1 + j], comps[1 + k] * sign
    if symmetric:
        a, b, c, d = w, qi, qj, qk
    else:  # rotate the quaternion so that the Tait-Bryan case becomes a proper-Euler one
        a, b, c, d = w - qj, qi + qk, qj + w, qk - qi
    hypot_cd = _sqrt_finite_grad(c * c + d * d)
    hypot_ab = _sqrt_finite_grad(a * a + b * b)
    middle = 2.0 * _safe_atan2(hypot_cd, hypot_ab)
    half_sum = _safe_atan2(b, a)
    half_diff = _safe_atan2(d, c)
    first = half_sum - half_diff
    third = half_sum + half_diff
    if not symmetric:
        third = third * sign
        middle = middle - 0.5 * math.pi
    return jnp.stack([wrap_angle(third), middle, wrap_angle(first)], axis=-1)


def euler_from_matrix(R: Float[Array, "... 3 3"], order: str) -> Float[Array, "... 3"]:
    """Euler angles (BVH intrinsic semantics) from rotation matrices.

    Computed as ``euler_from_quat(quat_from_matrix(R), order)``: accurate and with finite
    gradients everywhere, gimbal lock included.

    Arguments:
        R: ``[..., 3, 3]`` rotation matrices.
        order: one of ``EULER_ORDERS``.

    Returns:
        ``[..., 3]`` angles in radians, in the canonical ranges of ``euler_from_quat``.
    """
    order = _check_order(order, "euler_from_matrix")
    R = _mat(R, "R", "euler_from_matrix")
    return euler_from_quat(quat_from_matrix(R), order)


def euler_twin(angles: Float[ArrayLike, "... 3"], order: str) -> Float[ArrayLike, "... 3"]:
    """The other Euler triple of the same rotations (not wrapped).

    NumPy in, NumPy out (for per-frame loops at the edges); JAX arrays and tracers stay JAX.

    Arguments:
        angles: ``[..., 3]`` angles ``(a, b, c)`` in radians.
        order: one of ``EULER_ORDERS``.

    Returns:
        ``[..., 3]``: ``(a + pi, pi - b, c + pi)`` for Tait-Bryan orders, ``(a + pi, -b, c + pi)``
        for proper Euler orders.
    """
    import numpy as np

    order = _check_order(order, "euler_twin")
    xp = jnp if isinstance(angles, jax.Array) else np
    a = angles
    middle = -a[..., 1] if order[0] == order[2] else math.pi - a[..., 1]
    return xp.stack([a[..., 0] + math.pi, middle, a[..., 2] + math.pi], axis=-1)


