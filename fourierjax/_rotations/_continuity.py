"""Continuity over time: sign flips of quaternions, 2π jumps and antipodal flips of expmaps, Euler branches."""

from __future__ import annotations

from typing import TYPE_CHECKING

import jax
import jax.numpy as jnp

from fourierjax._rotations._common import _TWO_PI, _safe_normalize, _vec
from fourierjax.errors import UserError

if TYPE_CHECKING:
    from jaxtyping import Array, Bool, Float


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


def _lock_sign(order: str, middle: Array) -> Array:
    """``s`` such that ``(a + d, b, c + s d)`` is the same rotation for every ``d`` at gimbal lock
    (middle angle ``b`` at its pole): ``-1`` or ``+1``, found from the rotations themselves."""
    from fourierjax._rotations._euler import quat_from_euler

    pole = jnp.where(jnp.cos(middle) >= 0, 0.0, jnp.pi) if order[0] == order[2] else \
        jnp.where(middle >= 0, 0.5 * jnp.pi, -0.5 * jnp.pi)
    z = jnp.zeros_like(pole)
    d = jnp.full_like(pole, 0.5)
    q0 = quat_from_euler(jnp.stack([z, pole, z], -1), order)
    q_plus = quat_from_euler(jnp.stack([d, pole, d], -1), order)
    plus = jnp.abs(jnp.sum(q0 * q_plus, -1)) > 1.0 - 1e-3
    return jnp.where(plus, 1.0, -1.0).astype(middle.dtype)


#: ``|cos b|`` (Tait-Bryan) or ``|sin b|`` (proper Euler) under which a triple counts as at
#: gimbal lock: there only one combination of the first and third angle is defined.
_LOCK = {"float32": 1e-4, "float64": 1e-8}


def make_euler_continuous(
    angles: Float[Array, "F *joints 3"], order: str,
    valid: Bool[Array, " F"] | Bool[Array, " F *joints"] | None = None,
) -> Float[Array, "F *joints 3"]:
    """Continuous Euler angles over time, repaired through the rotation (radians).

    Each frame's rotation (its quaternion) is converted back to the Euler triple, of all those
    that give it, nearest the previous frame: the principal triple and its twin
    (``rotations.euler_twin``), each shifted by whole turns per angle; at gimbal lock, where the
    first and third angles are free along a line (``(a + d, b, c + s d)``), the point of that
    line nearest the previous frame. So a clip that switches triples near gimbal lock, or whose
    exporter splits the first and third angle arbitrarily there, comes out continuous.

    A joint whose rotation circles the pole (a `Spine` held 2-4 degrees from gimbal lock,
    swaying around it) winds: every continuous Euler path of such a motion grows by a turn of
    the first angle (and the opposite turn of the third) per loop around the pole. That is the
    rotation's topology, not drift; fit such joints in another order or as exponential maps.

    Frames with ``valid`` False (capture glitches) are repaired too but never serve as the
    reference: the next valid frame follows the last valid one. The first frame is kept.

    Arguments:
        angles: ``[F, ..., 3]`` radians, time first.
        order: one of ``EULER_ORDERS`` (BVH intrinsic order).
        valid: optional ``bool [F]``, or ``bool [F, ...]`` per joint (a glitch of one joint),
            as ``features.make_euler_continuous`` takes it.

    Returns:
        ``[F, ..., 3]``: the same rotations, continuous over the first axis.
    """
    from fourierjax._rotations._common import _check_order
    from fourierjax._rotations._euler import euler_from_quat, euler_twin, quat_from_euler

    fn = "make_euler_continuous"
    order = _check_order(order, fn)
    angles = _vec(angles, 3, "angles", fn)
    if angles.ndim < 2:
        raise UserError(f"{fn}: `angles` must have shape [F, ..., 3], got {tuple(angles.shape)}")
    F = angles.shape[0]
    ok = jnp.ones((F,), bool) if valid is None else jnp.asarray(valid, bool)
    if ok.shape == (F,):
        ok = ok.reshape((F,) + (1,) * (angles.ndim - 2))
    elif ok.shape != angles.shape[:-1]:
        raise UserError(f"{fn}: `valid` must have shape ({F},) or {tuple(angles.shape[:-1])}, got "
                        f"{tuple(ok.shape)}")
    proper = order[0] == order[2]
    lock_tol = _LOCK.get(str(angles.dtype), 1e-4)
    principal = euler_from_quat(quat_from_euler(angles, order), order)
    first = angles[0]  # kept as given
    if F < 2:
        return first[None]
    sign = _lock_sign(order, principal[..., 1])

    def nearest(ref, cand):
        return cand + _TWO_PI * jax.lax.stop_gradient(jnp.round((ref - cand) / _TWO_PI))

    def step(carry, inp):
        ref, prev, ref_ok = carry
        e, s, good = inp
        target = jnp.where((good & ref_ok)[..., None], ref, prev)
        c1, c2 = nearest(target, e), nearest(target, euler_twin(e, order))
        d1 = jnp.sum((c1 - target) ** 2, -1)
        d2 = jnp.sum((c2 - target) ** 2, -1)
        best = jnp.where((d2 < d1 - 1e-12)[..., None], c2, c1)
        # At the pole only a - s c is defined: split its change evenly from the target.
        inv = e[..., 0] - s * e[..., 2]
        d = inv - (target[..., 0] - s * target[..., 2])
        d = d - _TWO_PI * jnp.round(d / _TWO_PI)
        split = jnp.stack([target[..., 0] + 0.5 * d, best[..., 1], target[..., 2] - 0.5 * s * d], -1)
        at_lock = jnp.abs(jnp.sin(e[..., 1]) if proper else jnp.cos(e[..., 1])) < lock_tol
        out = jnp.where(at_lock[..., None], split, best)
        new_ref = jnp.where((good | ~ref_ok)[..., None], out, ref)
        return (new_ref, out, ref_ok | good), out

    carry0 = (first, first, ok[0])
    _, rest = jax.lax.scan(step, carry0, (principal[1:], sign[1:], ok[1:]))
    return jnp.concatenate([first[None], rest], axis=0)
