"""Quaternions, exponential maps, axis-angle and matrices (wxyz, unit norm, NaN-safe near zero)."""

from __future__ import annotations

from typing import TYPE_CHECKING

import jax
import jax.numpy as jnp

from fourierjax._rotations._common import (
    _as_float,
    _broadcast_batch,
    _common_dtype,
    _cross,
    _mat,
    _safe_normalize,
    _stack_matrix,
    _taylor_threshold,
    _unstack,
    _unstack_rows,
    _vec,
)
from fourierjax.errors import UserError

if TYPE_CHECKING:
    from jaxtyping import Array, Float

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
    """Scale quaternions to unit norm (sign kept).

    A norm at or below ``zero_norm_threshold(q.dtype)`` (about 3.3e-10 in float32, 1.2e-77 in
    float64) maps to the identity with a zero gradient; values and gradients are finite for
    every ``q``.

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
        q: ``[..., 4]`` wxyz quaternions of any norm (``q`` and ``-q`` give the same); a norm
            at or below ``zero_norm_threshold(q.dtype)`` counts as the identity.

    Returns:
        ``[..., 3]`` exponential maps with angle in ``[0, pi]`` (scipy's ``as_rotvec``); values
        and gradients are finite for every ``q`` (zero gradient at and below the threshold).
    """
    q = _vec(q, 4, "q", "expmap_from_quat")
    # Unit norm first: the angle is scale-free, but `n_sq / w**2` under- or overflows for tiny q.
    q, _ = _safe_normalize(q)
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
        axis: ``[..., 3]`` rotation axes (normalised here; a norm at or below
            ``zero_norm_threshold(axis.dtype)`` gives the identity, with finite gradients).
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
        q: ``[..., 4]`` wxyz quaternions of any norm; a norm at or below
            ``zero_norm_threshold(q.dtype)`` counts as the identity.
        t: ``[...]`` exponents; leading dims broadcast.

    Returns:
        ``[..., 4]`` unit wxyz quaternions, finite with finite gradients for every ``q``.
    """
    fn = "quat_power"
    q = _vec(q, 4, "q", fn)
    t = _as_float(t, "t", fn)
    q, t = _common_dtype(*_broadcast_batch(q, 1, t, 0))
    # Unit norm first: atan2's derivative holds 1 / |q|**2, which overflows for tiny q.
    q, _ = _safe_normalize(q)
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


def nearest_rotation_vector(reference: Array, v: Array) -> tuple[Array, Array]:
    """The rotation vector equivalent to `v` nearest `reference`: `v − 2πk·v/|v|` for the
    integer k minimising the distance (k = 0 at |v| = 0), and the Jacobian factor `2πk/|v|`.

    Arguments:
        reference: `[..., 3]` rotation vectors (radians).
        v: `[..., 3]`, the vectors to move.

    Returns:
        `(v' [..., 3], g [...])` with `v' = v − g·v`; `dv'/dv = (1 − g) I + g v̂v̂ᵀ`.
    """
    n2 = jnp.sum(v * v, axis=-1)
    small = n2 < 1e-30
    # Shim to avoid NaNs in jnp.where branches (v/|v| at 0), which cause failures for AD.
    n = jnp.sqrt(jnp.where(small, 1.0, n2))
    unit = v / n[..., None]
    along = jnp.sum(reference * unit, axis=-1)
    k = jax.lax.stop_gradient(jnp.where(small, 0.0, jnp.round((n - along) / (2 * jnp.pi))))
    g = 2 * jnp.pi * k / n
    return v - g[..., None] * v, g
