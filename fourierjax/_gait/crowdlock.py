"""Foot locking for a crowd, one frame at a time: held foot points and leg IK on joint positions."""

from __future__ import annotations

from typing import TYPE_CHECKING, NamedTuple

import jax
import jax.numpy as jnp
from jaxtyping import Array, ArrayLike, Float

from fourierjax import _jit
from fourierjax._gait.footlock import (
    CONTACT_HEIGHT_FRACTION,
    REACH_KNEE,
    REACH_LIMIT,
    _over_axis,
    contact_weights,
    hold_step,
    hold_weights,
)
from fourierjax._legik import knee_pole, safe_norm, soft_reach, sphere_circle_point
from fourierjax.errors import UserError

if TYPE_CHECKING:
    from fourierjax.body import BodyMap

# Layout (measured on 2 loaded CPU cores, 10,000 characters of CMU 07_01; see
# experiments/benchmarks/footlock.py): as the crowd's FK, characters are the last (minor) axis,
# so a joint is a `[3, B]` row of the pose `[J, 3, B]` and every step is an elementwise loop over
# characters; the foot points, legs and the joints below each ankle are static rows (no gathers).
# The per-character functions of `_gait.footlock` and `_legik` are vmapped over that minor axis.


class LockPlan(NamedTuple):
    """The static part of a crowd's foot lock (hashable: a jit static argument).

    - `up`, `sign`: the up axis and its sign; `band`: the contact band (file units).
    - `points`: `(left, right)` joint indices of the foot points (as many on each foot).
    - `legs`: `(left, right)` of `(hip, knee, ankle, below)`, `below` the ankle and the joints
      under it (moved with the foot).
    """

    up: int
    sign: float
    band: float
    points: tuple[tuple[int, ...], tuple[int, ...]]
    legs: tuple[tuple[int, int, int, tuple[int, ...]], ...]


def lock_plan(body_map: BodyMap, parents: tuple[int, ...], num_joints: int, where: str = "lock_crowd") -> LockPlan:
    """The `LockPlan` of a skeleton's body map; `UserError` (naming `where`) when its feet have no
    joints among the crowd's `num_joints` positions (the crowd poses joints, not End Sites)."""
    pts = tuple(tuple(int(i) for i in leg.foot_points if i < num_joints) for leg in (body_map.left, body_map.right))
    n = min(len(pts[0]), len(pts[1]))
    if n == 0:
        raise UserError(f"{where}: the body map's feet have no joints among the crowd's positions")
    parents = tuple(int(p) for p in parents)
    legs = tuple((int(leg.hip), int(leg.knee), int(leg.ankle), _subtree(parents, int(leg.ankle)))
                 for leg in (body_map.left, body_map.right))
    band = CONTACT_HEIGHT_FRACTION * float(body_map.height)
    return LockPlan(int(body_map.up_axis), float(body_map.up_sign), band, (pts[0][:n], pts[1][:n]), legs)


def _subtree(parents: tuple[int, ...], joint: int) -> tuple[int, ...]:
    # The joints at and below `joint`: a joint's descendants follow it in BVH file order.
    out = [joint]
    for j in range(joint + 1, len(parents)):
        if parents[j] in out:
            out.append(j)
    return tuple(out)


def init_state(plan: LockPlan, num_characters: int, dtype) -> tuple[Array, Array]:
    """The lock state before the first frame (nothing planted), characters last:
    `(targets [2, P, 3, B], planted [2, P, B])`, as `footlock.init_hold_state` per character."""
    n = len(plan.points[0])
    return jnp.zeros((2, n, 3, num_characters), dtype), jnp.zeros((2, n, num_characters), dtype)


def _minor(f, in_axes=-1, out_axes=-1):
    """`f` of one character, over characters as the last axis."""
    return jax.vmap(f, in_axes=in_axes, out_axes=out_axes)


def _leg(H, K, A, G):
    # Two-bone leg IK on positions of one character: the knee on its circle, the goal eased
    # below the straight leg.
    l1, l2 = safe_norm(K - H), safe_norm(A - K)
    d = safe_norm(G - H)
    eased = soft_reach(d, l1 + l2, REACH_KNEE, REACH_LIMIT, safe_norm(A - H))
    G = H + (G - H) * (eased / jnp.maximum(d, 1e-9))
    K2, _ = sphere_circle_point(H, G, l1, l2, knee_pole(H, K, A))
    return K2, G


def lock_pose(
    pose: Float[Array, "J 3 B"],
    phase: Float[Array, " B"],
    intervals: Float[Array, "B 2 2"],
    state: tuple[Array, Array],
    floor: Float[Array, " B"],
    clearance: Float[Array, "2 P"],
    plan: LockPlan,
) -> tuple[Float[Array, "J 3 B"], tuple[Array, Array]]:
    """One frame of a crowd's foot lock on a pose laid out characters last (pure jnp; the body
    of `lock_crowd` and of `crowd.crowd_positions(foot_lock=True)`).

    Arguments:
        pose: `[J, 3, B]` world joint positions; phase: `[B]` cycle phases (radians);
        intervals: `[B, 2, 2]` contact intervals; state: `init_state` or the previous frame's;
        floor: `[B]` floor heights; clearance: `[2, P]` sole clearances; plan: `lock_plan`.

    Returns:
        `(pose [J, 3, B], state)`.
    """
    up, sign = plan.up, plan.sign
    contact = jax.vmap(lambda p, i: contact_weights(p[None], i)[0], out_axes=-1)(phase, intervals)  # [2, B]
    feet = jnp.stack([jnp.stack([pose[j] for j in foot]) for foot in plan.points])  # [2, P, 3, B]
    rel = sign * feet[:, :, up] - floor[None, None] - clearance[..., None]  # [2, P, B]
    band = jnp.asarray(plan.band, pose.dtype)
    # `hold_weights` is elementwise: the trailing axis of 1 lines `contact[..., None]` up with `rel`.
    lam = hold_weights(rel[..., None], contact[:, None, :], band)[..., 0]  # [2, P, B]
    horizontal = jnp.ones(3, pose.dtype).at[up].set(0.0)
    state, shift = hold_step(state, feet, lam, horizontal, characters_last=True)  # shift [2, 3, B]
    gap = _over_axis(jnp.minimum, rel, 1)  # [2, B]
    dy = -gap * jnp.where(gap > 0, _over_axis(jnp.maximum, lam, 1), 1.0)
    shift = shift.at[:, up].add(sign * dy)
    # The pose as joint rows `[3, B]`, stacked once at the end: updating `[J, 3, B]` in place per
    # leg copied the whole pose three times a leg.
    rows = [pose[j] for j in range(pose.shape[0])]
    for f, (hip, knee, ankle, below) in enumerate(plan.legs):
        K2, G = _minor(_leg)(pose[hip], pose[knee], pose[ankle], pose[ankle] + shift[f])
        move = G - pose[ankle]
        rows[knee] = K2
        for j in below:
            rows[j] = rows[j] + move
    return jnp.stack(rows), state


def _lock_crowd(positions, phase, intervals, state, floor, clearance, plan):
    pose, state = lock_pose(jnp.transpose(positions, (1, 2, 0)), phase, intervals, state, floor, clearance, plan)
    return jnp.transpose(pose, (2, 0, 1)), state


_lock_crowd_jit = _jit.jit(_lock_crowd, static_argnames=("plan",))


def check_inputs(where: str, plan: LockPlan, num_characters: int, dtype, phase, intervals, state, floor,
                 clearance) -> tuple:
    """The lock inputs as arrays of `dtype`, defaults filled in; `UserError` naming the argument
    whose shape does not fit `num_characters` characters and the plan's foot points."""
    B, n = num_characters, len(plan.points[0])
    iv = jnp.asarray(intervals, dtype)
    if iv.shape != (B, 2, 2):
        raise UserError(f"{where}: `intervals` must be [B={B}, 2, 2] (contact_intervals per model), got {iv.shape}")
    if phase is not None:
        phase = jnp.asarray(phase, dtype)
        if phase.shape != (B,):
            raise UserError(f"{where}: `phase` must be [B={B}], got {phase.shape}")
    if state is None:
        state = init_state(plan, B, dtype)
    targets, planted = state
    if jnp.shape(targets) != (2, n, 3, B) or jnp.shape(planted) != (2, n, B):
        raise UserError(f"{where}: `state` must be the state the previous frame returned: targets "
                        f"[2, {n}, 3, {B}] and planted [2, {n}, {B}], got {jnp.shape(targets)}, "
                        f"{jnp.shape(planted)}")
    floor = jnp.zeros((B,), dtype) if floor is None else jnp.asarray(floor, dtype)
    if floor.shape != (B,):
        raise UserError(f"{where}: `floor` must be [B={B}] floor heights, got {floor.shape}")
    clearance = jnp.zeros((2, n), dtype) if clearance is None else jnp.asarray(clearance, dtype)
    if clearance.ndim != 2 or clearance.shape[0] != 2 or clearance.shape[1] < n:
        raise UserError(f"{where}: `clearance` must be [2, P >= {n}] sole clearances, got {clearance.shape}")
    return phase, iv, (targets, planted), floor, clearance[:, :n]


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
    Sites). `crowd.crowd_positions(..., foot_lock=True)` runs the same lock inside the crowd's
    program (one dispatch a frame).

    Arguments:
        positions: `[B, J, 3]` world joint positions of this frame.
        phase: `[B]` each character's cycle phase (`omega * t`, radians).
        intervals: `[B, 2, 2]` contact intervals (`contact_intervals` per model).
        state: the previous frame's state, or None on the first frame.
        body_map: the skeleton's map; parents: its topology's parent indices (static).
        floor: `[B]` floor heights (default 0); clearance: `[2, P]` sole clearances (default 0).

    Returns:
        `(positions [B, J, 3], state)`; the state (characters last: targets `[2, P, 3, B]`,
        planted `[2, P, B]`) goes with the next frame. Jitted; differentiable in the positions.

    Raises:
        `UserError` naming the argument whose shape does not fit.
    """
    positions = jnp.asarray(positions)
    if positions.ndim != 3 or positions.shape[-1] != 3:
        raise UserError(f"lock_crowd: `positions` must be [B, J, 3], got {positions.shape}")
    B, J, _ = positions.shape
    plan = lock_plan(body_map, parents, J)
    args = check_inputs("lock_crowd", plan, B, positions.dtype, phase, intervals, state, floor, clearance)
    return _lock_crowd_jit(positions, *args, plan=plan)
