"""Foot locking for a crowd, one frame at a time: held foot points and leg IK on joint positions."""

from __future__ import annotations

from typing import TYPE_CHECKING

import jax
import jax.numpy as jnp
from jaxtyping import Array, ArrayLike, Float

from fourierjax._gait.footlock import (
    CONTACT_HEIGHT_FRACTION,
    REACH_KNEE,
    REACH_LIMIT,
    contact_weights,
    hold_step,
    hold_weights,
    init_hold_state,
)
from fourierjax._jit import filter_jit
from fourierjax._legik import safe_norm, soft_reach, sphere_circle_point
from fourierjax.errors import UserError

if TYPE_CHECKING:
    from fourierjax.body import BodyMap


def _crowd_lock(positions, phase, intervals, state, floor, clearance, band, *, body_map, points):
    contact = jax.vmap(lambda p, i: contact_weights(p[None], i)[0])(phase, intervals)
    up = int(body_map.up_axis)
    sign = float(body_map.up_sign)
    upv = jnp.zeros(3, positions.dtype).at[up].set(1.0)
    idx = jnp.asarray(points)  # [2, P] joint indices
    feet = positions[:, idx]  # [B, 2, P, 3]
    rel = sign * feet[..., up] - floor[:, None, None] - clearance[None]
    lam = hold_weights(rel, contact, band)
    state, shift = hold_step(state, feet, lam, 1.0 - upv)
    gap = jnp.min(rel, -1)
    dy = -gap * jnp.where(gap > 0, jnp.max(lam, -1), 1.0)
    shift = shift + (sign * dy)[..., None] * upv[None, None]
    out = positions
    for f, leg in enumerate((body_map.left, body_map.right)):
        H, K, A = positions[:, leg.hip], positions[:, leg.knee], positions[:, leg.ankle]
        G = A + shift[:, f]
        l1, l2 = safe_norm(K - H), safe_norm(A - K)
        d = safe_norm(G - H)
        eased = soft_reach(d, l1 + l2, REACH_KNEE, REACH_LIMIT, safe_norm(A - H))
        G = H + (G - H) * (eased / jnp.maximum(d, 1e-9))[:, None]
        K2, _ = jax.vmap(sphere_circle_point)(H, G, l1, l2, K - H)
        below = _subtree(body_map, leg.ankle)
        out = out.at[:, leg.knee].set(K2)
        out = out.at[:, jnp.asarray(below)].add((G - A)[:, None, :])
    return out, state


def _subtree(body_map, joint: int) -> tuple[int, ...]:
    # The joints at and below `joint`: a joint's descendants follow it in BVH file order.
    parents = body_map.parents
    out = [joint]
    for j in range(joint + 1, len(parents)):
        if parents[j] in out:
            out.append(j)
    return tuple(out)


def lock_crowd(
    positions: Float[ArrayLike, "B J 3"],
    phase: Float[ArrayLike, " B"],
    intervals: Float[ArrayLike, "B 2 2"],
    state: tuple[Array, Array] | None,
    *,
    body_map: BodyMap,
    parents: tuple[int, ...],
    floor: Float[ArrayLike, " B"] | None = None,
    clearance: Float[ArrayLike, "2 P"] | None = None,
) -> tuple[Float[Array, "B J 3"], tuple[Array, Array]]:
    """Foot locking for a crowd, one frame at a time: post-processes `crowd.crowd_positions`.

    Per character: stance weights from its phase (`contact_weights`), the held foot points of
    `hold_step` (planted where they land, carried in `state` from frame to frame), and the
    two-bone leg IK on positions (the knee on its circle, the foot below the ankle translated).
    Only the body map's foot points that are joints are used (the crowd poses joints, not End
    Sites).

    Arguments:
        positions: `[B, J, 3]` world joint positions of this frame.
        phase: `[B]` each character's cycle phase (`omega * t`, radians).
        intervals: `[B, 2, 2]` contact intervals (`contact_intervals` per model).
        state: the previous frame's state, or None on the first frame.
        body_map: the skeleton's map; parents: its topology's parent indices (static).
        floor: `[B]` floor heights (default 0); clearance: `[2, P]` sole clearances (default 0).

    Returns:
        `(positions [B, J, 3], state)`. Jitted; differentiable in the positions.
    """
    positions = jnp.asarray(positions)
    B, J, _ = positions.shape
    pts = tuple(tuple(int(i) for i in leg.foot_points if i < J) for leg in (body_map.left, body_map.right))
    n = min(len(pts[0]), len(pts[1]))
    if n == 0:
        raise UserError("lock_crowd: the body map's feet have no joints among the crowd's positions")
    pts = (pts[0][:n], pts[1][:n])
    phase = jnp.asarray(phase, positions.dtype)
    iv = jnp.asarray(intervals, positions.dtype)
    if iv.shape != (B, 2, 2) or phase.shape != (B,):
        raise UserError(f"lock_crowd: `phase` must be [B={B}] and `intervals` [B, 2, 2], got {phase.shape}, {iv.shape}")
    if state is None:
        state = init_hold_state(positions[:, jnp.asarray(pts)])
    floor = jnp.zeros((B,), positions.dtype) if floor is None else jnp.asarray(floor, positions.dtype)
    if clearance is None:
        clearance = jnp.zeros((2, n), positions.dtype)
    clearance = jnp.asarray(clearance, positions.dtype)[:, :n]
    band = jnp.asarray(CONTACT_HEIGHT_FRACTION * float(body_map.height), positions.dtype)
    return _crowd_lock_jit(positions, phase, iv, state, floor, clearance, band,
                           body_map=_CrowdMap(body_map, parents), points=pts)


class _CrowdMap:
    """A body map with its topology's parents (hashable: a static argument)."""

    def __init__(self, body_map, parents):
        self.map, self.parents = body_map, tuple(int(p) for p in parents)

    def __getattr__(self, name):
        return getattr(self.map, name)

    def __hash__(self):
        return hash((self.map, self.parents))

    def __eq__(self, other):
        return isinstance(other, _CrowdMap) and (self.map, self.parents) == (other.map, other.parents)


_crowd_lock_jit = filter_jit(_crowd_lock)
