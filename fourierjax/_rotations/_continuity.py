"""Continuity over time: sign flips of quaternions, 2π jumps and antipodal flips of expmaps."""

from __future__ import annotations

import jax
import jax.numpy as jnp
from jaxtyping import Array, Float

from fourierjax._rotations._common import _TWO_PI, _safe_normalize, _vec
from fourierjax.errors import UserError


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
