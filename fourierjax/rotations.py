"""Rotation conversions: Euler angles (12 BVH orders), wxyz quaternions, expmaps, matrices."""

from __future__ import annotations

import math

import jax
import jax.numpy as jnp
from jaxtyping import Array, ArrayLike, Float

from fourierjax.errors import UserError

__all__ = [
    "EULER_ORDERS",
    "euler_from_matrix",
    "euler_from_quat",
    "euler_twin",
    "expmap_from_matrix",
    "expmap_from_quat",
    "make_expmap_continuous",
    "make_quat_continuous",
    "matrix_from_euler",
    "matrix_from_expmap",
    "matrix_from_quat",
    "matrix_multiply",
    "quat_apply",
    "quat_conjugate",
    "quat_from_axis_angle",
    "quat_from_euler",
    "quat_from_expmap",
    "quat_from_matrix",
    "quat_multiply",
    "quat_normalize",
    "quat_power",
    "quat_slerp",
]

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


def _taylor_threshold(dtype) -> float:
    # Below this squared angle the 3-term Taylor series are exact to machine precision.
    return float(jnp.finfo(dtype).eps) ** 0.5


def _safe_sqrt(x: Array) -> Array:
    """sqrt(x) for x >= 0 with a zero (not NaN / inf) gradient at 0."""
    zero = x <= _tiny(x.dtype)
    return jnp.where(zero, 0.0, jnp.sqrt(jnp.where(zero, 1.0, x)))


def _safe_atan2(y: Array, x: Array) -> Array:
    """atan2(y, x), with value 0 and zero gradient where (x, y) = (0, 0)."""
    zero = x * x + y * y <= _tiny(x.dtype)
    return jnp.where(zero, 0.0, jnp.arctan2(jnp.where(zero, 0.0, y), jnp.where(zero, 1.0, x)))


def _safe_normalize(v: Array) -> tuple[Array, Array]:
    """(v / |v|, |v| == 0) along the last axis; the zero vector maps to zero with zero gradient."""
    sq = jnp.sum(v * v, axis=-1, keepdims=True)
    zero = sq <= _tiny(v.dtype)
    inv = jnp.where(zero, 0.0, jax.lax.rsqrt(jnp.where(zero, 1.0, sq)))
    return v * inv, zero[..., 0]


def _wrap_angle(x: Array) -> Array:
    """Wrap angles in (-3 pi, 3 pi) into (-pi, pi]."""
    return jnp.where(x > math.pi, x - _TWO_PI, jnp.where(x <= -math.pi, x + _TWO_PI, x))


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


# ------------------------------------------------------------------------------- matrices


def matrix_multiply(a: Float[Array, "... n m"], b: Float[Array, "... m p"]) -> Float[Array, "... n p"]:
    """Batched matrix product ``a @ b`` written as a broadcast multiply and a sum.

    XLA on CPU fails to compile batched 3x3 ``@`` / ``einsum`` under ``jit(vmap(vmap(f)))``
    (see STYLE.md); this formulation compiles everywhere and fuses well for small matrices.

    Arguments:
        a: ``[..., n, m]`` matrices.
        b: ``[..., m, p]`` matrices; leading dims broadcast against ``a``'s.

    Returns:
        ``[..., n, p]`` products.
    """
    a = _as_float(a, "a", "matrix_multiply")
    b = _as_float(b, "b", "matrix_multiply")
    if a.ndim < 2 or b.ndim < 2 or a.shape[-1] != b.shape[-2]:
        raise UserError(
            f"matrix_multiply: a [..., n, m] and b [..., m, p] do not match: a {tuple(a.shape)}, b {tuple(b.shape)}"
        )
    a, b = _common_dtype(*_broadcast_batch(a, 2, b, 2))
    return jnp.sum(a[..., :, :, None] * b[..., None, :, :], axis=-2)


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


# ---------------------------------------------------------------------------- quaternions


def quat_multiply(q1: Float[Array, "... 4"], q2: Float[Array, "... 4"]) -> Float[Array, "... 4"]:
    """Hamilton product ``q1 * q2`` (apply ``q2`` first, then ``q1``; like ``R1 @ R2``).

    Arguments:
        q1: ``[..., 4]`` wxyz quaternions.
        q2: ``[..., 4]`` wxyz quaternions; leading dims broadcast against ``q1``'s.

    Returns:
        ``[..., 4]`` products.
    """
    q1 = _vec(q1, 4, "q1", "quat_multiply")
    q2 = _vec(q2, 4, "q2", "quat_multiply")
    q1, q2 = _common_dtype(*_broadcast_batch(q1, 1, q2, 1))
    w1, x1, y1, z1 = _unstack(q1)
    w2, x2, y2, z2 = _unstack(q2)
    return jnp.stack(
        [
            w1 * w2 - x1 * x2 - y1 * y2 - z1 * z2,
            w1 * x2 + x1 * w2 + y1 * z2 - z1 * y2,
            w1 * y2 - x1 * z2 + y1 * w2 + z1 * x2,
            w1 * z2 + x1 * y2 - y1 * x2 + z1 * w2,
        ],
        axis=-1,
    )


def quat_conjugate(q: Float[Array, "... 4"]) -> Float[Array, "... 4"]:
    """Conjugate ``(w, -x, -y, -z)``: the inverse of a unit quaternion.

    Arguments:
        q: ``[..., 4]`` wxyz quaternions.

    Returns:
        ``[..., 4]`` conjugates.
    """
    q = _vec(q, 4, "q", "quat_conjugate")
    w, xyz = jnp.split(q, [1], axis=-1)
    return jnp.concatenate([w, -xyz], axis=-1)


def quat_normalize(q: Float[Array, "... 4"]) -> Float[Array, "... 4"]:
    """Scale quaternions to unit norm (sign kept); the zero quaternion maps to the identity.

    Gradients are finite everywhere (zero at the zero quaternion).

    Arguments:
        q: ``[..., 4]`` wxyz quaternions.

    Returns:
        ``[..., 4]`` unit quaternions.
    """
    q = _vec(q, 4, "q", "quat_normalize")
    unit, zero = _safe_normalize(q)
    identity = jnp.zeros_like(q).at[..., 0].set(1.0)
    return jnp.where(zero[..., None], identity, unit)


def quat_apply(q: Float[Array, "... 4"], v: Float[Array, "... 3"]) -> Float[Array, "... 3"]:
    """Rotate vectors by unit quaternions: ``q * (0, v) * conj(q)``, i.e. ``R(q) @ v``.

    Arguments:
        q: ``[..., 4]`` unit wxyz quaternions.
        v: ``[..., 3]`` vectors; leading dims broadcast against ``q``'s.

    Returns:
        ``[..., 3]`` rotated vectors.
    """
    q = _vec(q, 4, "q", "quat_apply")
    v = _vec(v, 3, "v", "quat_apply")
    q, v = _common_dtype(*_broadcast_batch(q, 1, v, 1))
    w, u = jnp.split(q, [1], axis=-1)
    t = 2.0 * _cross(u, v)
    return v + w * t + _cross(u, t)


def matrix_from_quat(q: Float[Array, "... 4"]) -> Float[Array, "... 3 3"]:
    """Rotation matrices from unit quaternions (not renormalised: see ``quat_normalize``).

    Arguments:
        q: ``[..., 4]`` unit wxyz quaternions.

    Returns:
        ``[..., 3, 3]`` rotation matrices.
    """
    q = _vec(q, 4, "q", "matrix_from_quat")
    w, x, y, z = _unstack(q)
    xx, yy, zz = x * x, y * y, z * z
    xy, xz, yz = x * y, x * z, y * z
    wx, wy, wz = w * x, w * y, w * z
    return _stack_matrix(
        (
            (1.0 - 2.0 * (yy + zz), 2.0 * (xy - wz), 2.0 * (xz + wy)),
            (2.0 * (xy + wz), 1.0 - 2.0 * (xx + zz), 2.0 * (yz - wx)),
            (2.0 * (xz - wy), 2.0 * (yz + wx), 1.0 - 2.0 * (xx + yy)),
        )
    )


def _canonical_sign(q: Array) -> Array:
    """Flip q so that its first non-zero component (in w, x, y, z order) is positive."""
    w, x, y, z = _unstack(q)
    negative = jnp.where(w != 0, w < 0, jnp.where(x != 0, x < 0, jnp.where(y != 0, y < 0, z < 0)))
    return jnp.where(negative[..., None], -q, q)


def quat_from_matrix(R: Float[Array, "... 3 3"]) -> Float[Array, "... 4"]:
    """Unit quaternions from rotation matrices (Shepperd 1978, branch-free).

    All four of Shepperd's candidates are formed and the best-conditioned one (largest of
    ``trace, R00, R11, R22``) is selected arithmetically, so the result is accurate for every
    rotation (including 180 degrees) and gradients are finite everywhere.

    Arguments:
        R: ``[..., 3, 3]`` rotation matrices.

    Returns:
        ``[..., 4]`` unit wxyz quaternions in canonical sign: ``w >= 0`` (when ``w == 0``, the
        first non-zero of ``x, y, z`` is positive, as scipy's ``canonical=True``).
    """
    R = _mat(R, "R", "quat_from_matrix")
    (r00, r01, r02), (r10, r11, r12), (r20, r21, r22) = (_unstack(row) for row in _unstack_rows(R))
    trace = r00 + r11 + r22
    # Candidate c is 4 * q_c * q for a unit q: the largest q_c gives the best-conditioned one.
    candidates = (
        (r21 - r12, 1.0 + r00 - r11 - r22, r10 + r01, r20 + r02),
        (r02 - r20, r01 + r10, 1.0 + r11 - r22 - r00, r21 + r12),
        (r10 - r01, r02 + r20, r12 + r21, 1.0 + r22 - r00 - r11),
    )
    # Elementwise selects, not an argmax and a one-hot sum: they fuse (the stance solver's
    # gaze runs this inside its compiled loop).
    q, best = [1.0 + trace, r21 - r12, r02 - r20, r10 - r01], trace
    for diag, cand in zip((r00, r11, r22), candidates):
        pick = diag > best
        q = [jnp.where(pick, c, x) for c, x in zip(cand, q)]
        best = jnp.maximum(best, diag)
    q, _ = _safe_normalize(jnp.stack(q, axis=-1))
    return _canonical_sign(q)


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
    hypot_cd = _safe_sqrt(c * c + d * d)
    hypot_ab = _safe_sqrt(a * a + b * b)
    middle = 2.0 * _safe_atan2(hypot_cd, hypot_ab)
    half_sum = _safe_atan2(b, a)
    half_diff = _safe_atan2(d, c)
    first = half_sum - half_diff
    third = half_sum + half_diff
    if not symmetric:
        third = third * sign
        middle = middle - 0.5 * math.pi
    return jnp.stack([_wrap_angle(third), middle, _wrap_angle(first)], axis=-1)


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


def euler_twin(angles, order: str):
    """The other Euler triple of the same rotations (not wrapped): Tait-Bryan orders
    ``(a + pi, pi - b, c + pi)``, proper Euler orders ``(a + pi, -b, c + pi)``.

    NumPy in, NumPy out (for per-frame loops at the edges); JAX arrays and tracers stay JAX.
    """
    import numpy as np

    order = _check_order(order, "euler_twin")
    xp = jnp if isinstance(angles, jax.Array) else np
    a = angles
    middle = -a[..., 1] if order[0] == order[2] else math.pi - a[..., 1]
    return xp.stack([a[..., 0] + math.pi, middle, a[..., 2] + math.pi], axis=-1)


# ------------------------------------------------------------------------ exponential map


def quat_from_expmap(v: Float[Array, "... 3"]) -> Float[Array, "... 4"]:
    """Quaternion exponential: ``v = angle * axis`` to ``(cos(angle/2), sin(angle/2) * axis)``.

    A Taylor branch near the zero rotation keeps values and gradients exact there.

    Arguments:
        v: ``[..., 3]`` exponential maps (axis times angle in radians, any angle).

    Returns:
        ``[..., 4]`` unit wxyz quaternions (``w < 0`` when the angle exceeds pi).
    """
    v = _vec(v, 3, "v", "quat_from_expmap")
    theta_sq = jnp.sum(v * v, axis=-1)
    use_taylor = theta_sq < _taylor_threshold(v.dtype)
    # Shim to avoid NaNs in jnp.where branches, which cause failures for reverse-mode AD.
    theta = jnp.sqrt(jnp.where(use_taylor, 1.0, theta_sq))
    half = 0.5 * theta
    w = jnp.where(use_taylor, 1.0 - theta_sq / 8.0 + theta_sq * theta_sq / 384.0, jnp.cos(half))
    scale = jnp.where(use_taylor, 0.5 - theta_sq / 48.0 + theta_sq * theta_sq / 3840.0, jnp.sin(half) / theta)
    return jnp.concatenate([w[..., None], scale[..., None] * v], axis=-1)


def expmap_from_quat(q: Float[Array, "... 4"]) -> Float[Array, "... 3"]:
    """Quaternion logarithm: the exponential map (axis times angle) of a quaternion.

    Uses ``angle = 2 atan2(|xyz|, w)`` (accurate at every angle) and a Taylor branch near the
    zero rotation (finite, exact gradients there).

    Arguments:
        q: ``[..., 4]`` wxyz quaternions (any non-zero norm; ``q`` and ``-q`` give the same).

    Returns:
        ``[..., 3]`` exponential maps with angle in ``[0, pi]`` (scipy's ``as_rotvec``).
    """
    q = _vec(q, 4, "q", "expmap_from_quat")
    q = jnp.where(q[..., :1] < 0, -q, q)  # w >= 0: angle in [0, pi]
    w, xyz = jnp.split(q, [1], axis=-1)
    w = jnp.squeeze(w, axis=-1)
    n_sq = jnp.sum(xyz * xyz, axis=-1)
    use_taylor = n_sq <= _taylor_threshold(q.dtype) * w * w
    # Shim to avoid NaNs in jnp.where branches, which cause failures for reverse-mode AD.
    n = jnp.sqrt(jnp.where(use_taylor, 1.0, n_sq))
    w_t = jnp.where(use_taylor & (w > 0), w, 1.0)
    r = n_sq / (w_t * w_t)
    # 2 atan(n / w) / n = (2 / w) (1 - r / 3 + r^2 / 5 - ...), r = (n / w)^2.
    scale = jnp.where(
        use_taylor,
        (2.0 / w_t) * (1.0 - r / 3.0 + r * r / 5.0),
        2.0 * jnp.arctan2(n, w) / n,
    )
    return scale[..., None] * xyz


def matrix_from_expmap(v: Float[Array, "... 3"]) -> Float[Array, "... 3 3"]:
    """Rotation matrices from exponential maps (Rodrigues' formula, via half-angle quaternions).

    Arguments:
        v: ``[..., 3]`` exponential maps (axis times angle in radians).

    Returns:
        ``[..., 3, 3]`` rotation matrices.
    """
    v = _vec(v, 3, "v", "matrix_from_expmap")
    return matrix_from_quat(quat_from_expmap(v))


def expmap_from_matrix(R: Float[Array, "... 3 3"]) -> Float[Array, "... 3"]:
    """Exponential maps (matrix logarithm) of rotation matrices.

    Arguments:
        R: ``[..., 3, 3]`` rotation matrices.

    Returns:
        ``[..., 3]`` exponential maps with angle in ``[0, pi]`` (scipy's ``as_rotvec``).
    """
    R = _mat(R, "R", "expmap_from_matrix")
    return expmap_from_quat(quat_from_matrix(R))


def quat_from_axis_angle(axis: Float[Array, "... 3"], angle: Float[Array, "*batch"]) -> Float[Array, "... 4"]:
    """Quaternions rotating by ``angle`` about ``axis`` (right-handed).

    Arguments:
        axis: ``[..., 3]`` rotation axes (normalised here; a zero axis gives the identity).
        angle: ``[...]`` angles in radians; broadcasts against ``axis``'s leading dims.

    Returns:
        ``[..., 4]`` unit wxyz quaternions.
    """
    fn = "quat_from_axis_angle"
    axis = _vec(axis, 3, "axis", fn)
    angle = _as_float(angle, "angle", fn)
    axis, angle = _common_dtype(*_broadcast_batch(axis, 1, angle, 0))
    unit, zero = _safe_normalize(axis)
    half = 0.5 * angle
    w = jnp.where(zero, 1.0, jnp.cos(half))
    return jnp.concatenate([w[..., None], jnp.sin(half)[..., None] * unit], axis=-1)


def quat_power(q: Float[Array, "... 4"], t: Float[Array, "*batch"]) -> Float[Array, "... 4"]:
    """``q^t``: the rotation about ``q``'s axis by ``t`` times its angle, along the shortest arc.

    With ``q = |q| (cos phi, sin phi n)`` and ``w >= 0`` (``q`` and ``-q`` give the same),
    ``q^t = (cos t phi, sin t phi n)``, ``phi = atan2(|xyz|, w)``: one atan2 and no Taylor
    branches (a log and an exp map took two each). Exact with finite gradients at the identity
    (``sin(t phi) / |xyz| -> t / w``). ``t`` outside ``[0, 1]`` extrapolates.

    Arguments:
        q: ``[..., 4]`` wxyz quaternions (any non-zero norm).
        t: ``[...]`` exponents; leading dims broadcast.

    Returns:
        ``[..., 4]`` unit wxyz quaternions.
    """
    fn = "quat_power"
    q = _vec(q, 4, "q", fn)
    t = _as_float(t, "t", fn)
    q, t = _common_dtype(*_broadcast_batch(q, 1, t, 0))
    q = jnp.where(q[..., :1] < 0, -q, q)  # w >= 0: the shortest arc
    w, xyz = jnp.split(q, [1], axis=-1)
    w = jnp.squeeze(w, axis=-1)
    n_sq = jnp.sum(xyz * xyz, axis=-1)
    small = n_sq <= 1e-12 * w * w
    n = jnp.sqrt(jnp.where(small, 1.0, n_sq))
    phi = jnp.where(small, 0.0, jnp.arctan2(n, w))  # not atan2 of the shim's n = 1
    ratio = jnp.where(small, t / jnp.where(w > 0, w, 1.0), jnp.sin(t * phi) / n)
    return jnp.concatenate([jnp.cos(t * phi)[..., None], ratio[..., None] * xyz], axis=-1)


def quat_slerp(
    q0: Float[Array, "... 4"], q1: Float[Array, "... 4"], t: Float[Array, "*batch"]
) -> Float[Array, "... 4"]:
    """Spherical linear interpolation along the shortest arc: ``q0 * (q0^-1 q1)^t``.

    Written with `quat_power`, so it is exact and has finite gradients when ``q0 == q1``.
    ``t`` outside ``[0, 1]`` extrapolates.

    Arguments:
        q0: ``[..., 4]`` unit wxyz quaternions (at ``t = 0``).
        q1: ``[..., 4]`` unit wxyz quaternions (at ``t = 1``; ``q1`` and ``-q1`` give the same).
        t: ``[...]`` interpolation parameters; all leading dims broadcast.

    Returns:
        ``[..., 4]`` unit wxyz quaternions (``q0`` at ``t = 0``; ``+-q1`` at ``t = 1``).
    """
    fn = "quat_slerp"
    q0 = _vec(q0, 4, "q0", fn)
    q1 = _vec(q1, 4, "q1", fn)
    t = _as_float(t, "t", fn)
    q0, q1 = _common_dtype(*_broadcast_batch(q0, 1, q1, 1))
    q0, t = _common_dtype(*_broadcast_batch(q0, 1, t, 0))
    q1, t = _common_dtype(*_broadcast_batch(q1, 1, t, 0))
    delta = quat_multiply(quat_conjugate(q0), q1)
    return quat_multiply(q0, quat_power(delta, t))


# ---------------------------------------------------------------------- continuity over time


def _time_axis(x: Array, axis: int, name: str, fn: str) -> int:
    if not isinstance(axis, int):
        raise UserError(f"{fn}: axis must be an int, got {axis!r}")
    ax = axis + x.ndim if axis < 0 else axis
    if not 0 <= ax < x.ndim - 1:
        raise UserError(
            f"{fn}: axis={axis} is not a time axis of {name} with shape {tuple(x.shape)} "
            f"(the last axis holds the components)"
        )
    return ax


def make_quat_continuous(q: Float[Array, "... 4"], axis: int = 0) -> Float[Array, "... 4"]:
    """Remove sign flips over time: negate quaternions so that consecutive dots are ``>= 0``.

    The first frame is kept; frame ``t`` is multiplied by the cumulative product of the signs of
    the dots of consecutive input frames (exact, jit-able, no scan).

    Arguments:
        q: ``[..., T, ..., 4]`` wxyz quaternions with time along ``axis``.
        axis: the time axis (not the last one).

    Returns:
        Quaternions of the same shape representing the same rotations.
    """
    fn = "make_quat_continuous"
    q = _vec(q, 4, "q", fn)
    ax = _time_axis(q, axis, "q", fn)
    if q.shape[ax] < 2:
        return q
    qt = jnp.moveaxis(q, ax, 0)
    dots = jnp.sum(qt[1:] * qt[:-1], axis=-1)
    signs = jnp.where(dots < 0, -1.0, 1.0).astype(q.dtype)
    signs = jnp.concatenate([jnp.ones_like(signs[:1]), signs], axis=0)
    flips = jax.lax.stop_gradient(jnp.cumprod(signs, axis=0))
    return jnp.moveaxis(qt * flips[..., None], 0, ax)


def make_expmap_continuous(v: Float[Array, "... 3"], axis: int = 0) -> Float[Array, "... 3"]:
    """Remove 2 pi jumps and antipodal flips of exponential maps over time.

    Every ``(angle + 2 pi k) * axis`` (k integer) is the same rotation as ``angle * axis``; each
    frame takes the one closest to the previous (already corrected) frame, in closed form
    ``k = round((<v_prev, axis> - angle) / 2 pi)``. The first frame is kept. Like
    ``numpy.unwrap``, a joint that keeps spinning gets angles that keep growing.

    Arguments:
        v: ``[..., T, ..., 3]`` exponential maps with time along ``axis``.
        axis: the time axis (not the last one).

    Returns:
        Exponential maps of the same shape representing the same rotations.
    """
    fn = "make_expmap_continuous"
    v = _vec(v, 3, "v", fn)
    ax = _time_axis(v, axis, "v", fn)
    if v.shape[ax] < 2:
        return v
    vt = jnp.moveaxis(v, ax, 0)

    def step(prev, cur):
        n_cur, cur_zero = _safe_normalize(cur)
        # A (near-)identity frame has no axis of its own: continue along the previous one.
        n_prev, _ = _safe_normalize(prev)
        n = jnp.where(cur_zero[..., None], n_prev, n_cur)
        angle = jnp.sum(cur * n, axis=-1)
        k = jax.lax.stop_gradient(jnp.round((jnp.sum(prev * n, axis=-1) - angle) / _TWO_PI))
        out = cur + (_TWO_PI * k)[..., None] * n
        return out, out

    _, rest = jax.lax.scan(step, vt[0], vt[1:])
    return jnp.moveaxis(jnp.concatenate([vt[:1], rest], axis=0), 0, ax)
