"""Foot locking: contact intervals of the gait cycle, stance weights, planted feet by two-bone leg IK."""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

import jax
import jax.numpy as jnp
from jaxtyping import Array, ArrayLike, Float

from fourierjax import rotations
from fourierjax._checks import integer

# The contact intervals live in their own module; their old import path is this one.
from fourierjax._gait.contactphase import (  # noqa: F401, E402
    contact_intervals,
    fit_contact_intervals,
    intervals_from_contacts,
    intervals_from_model,
)
from fourierjax._legik import knee_pole, quat_between, safe_norm, soft_reach, sphere_circle_point
from fourierjax.errors import UserError

if TYPE_CHECKING:
    from fourierjax.body import BodyMap
    from fourierjax.skeleton import Skeleton

TWO_PI = 2.0 * math.pi
#: Leg-reach easing (fractions of thigh + shin): from where, and towards what (`_legik.soft_reach`).
REACH_KNEE, REACH_LIMIT = 0.9, 0.99
#: Default blend of the stance weights, radians of the cycle on each side of a contact (6%).
BLEND_RAD = 0.06 * TWO_PI
#: A foot point is still (planted) below this fraction of the mean root move per frame (easing
#: out at twice it), and a sliding point is lifted to `LIFT_BANDS` contact bands over its floor.
STILL_FRACTION, LIFT_BANDS = 0.15, 1.2
#: A landing point (before any point of its foot is still) is planted below this fraction instead.
PLANT_STILL_FRACTION = 2 * STILL_FRACTION
#: A stance (the phase's) in which a low foot point is still on less than half this share of
#: the frames slides (planted, not lifted), easing to a normal stance at this share.
SLIDING_SHARE = 0.4
#: `synthesize_gait` eases the feet's shifts over this many seconds on each side (`lock_feet`;
#: horizontally in the swing only).
SMOOTH_S = 0.04
#: `synthesize_gait` locks the feet on frames about this many per second
#: (`lock_supersampling` times as dense as the output, at most `MAX_SUPERSAMPLING`), synthesized
#: from the model, and keeps every k-th of them: the lock sees the same motion at any frame rate.
LOCK_FPS, MAX_SUPERSAMPLING = 120.0, 8
#: `synthesize_gait` locks at least this much more of the cycle before the first frame than its
#: longest contact (seconds at speed 1), then drops it (`_lock_preroll`): at least `PREROLL_S`,
#: in steps of half that (`PREROLL_S` when it cannot tell).
PREROLL_MARGIN_S, PREROLL_S = 0.2, 1.0
#: Contact: a foot point within this fraction of the body height of its floor (issue 21).
CONTACT_HEIGHT_FRACTION = 0.02
#: The toe's end point is held to the end of the stance at toe-off (horizontally and vertically)
#: with this many frames (or more) of easing on each side (`smooth_frames`); with fewer (but
#: some), horizontally only, faded out where it would stretch the leg by over `TOE_REACH_FADE`
#: of its length (thigh + shin) beyond the unheld foot's.
TOE_HOLD_FRAMES, TOE_REACH_FADE = 2, 0.03
#: With `TOE_HOLD_FRAMES` or more of easing, outside stance the foot turns toes up about its
#: ankle (at most `TOE_CLEAR_MAX` radians, eased over `TOE_CLEAR_SMOOTH` times the frames) so that
#: the toe's end point clears `LIFT_BANDS` contact bands (`_toe_clearance`).
TOE_CLEAR_MAX, TOE_CLEAR_SMOOTH = 0.35, 2
#: Heel-to-toe roll: in the second half of a stance, a foot point that has risen over its lowest
#: height of the stance by more than the foot's least-risen point has is let go horizontally,
#: from `ROLL_BANDS[0]` contact bands more (fully held) to `ROLL_BANDS[1]` (not held): the foot
#: pivots about the points still down (`_roll_off`).
ROLL_BANDS = (0.25, 0.5)
#: Each contact's hold starts the easing's frames early (`_plant`'s `lead`), and the swing's
#: easing towards it is warped by this power.
LEAD_WARP = 1.6
#: The knee-speed cap (`_knee_speed_cap`) is a Lipschitz envelope over this many seconds on each
#: side of a frame, aiming at this share of the cap (float32 rounding of the written motion).
KNEE_CAP_WINDOW_S, KNEE_CAP_MARGIN = 0.1, 0.99


def lock_supersampling(frame_time_s: float) -> int:
    """How many times as dense as `frame_time_s` the frames are on which `synthesize_gait` locks
    the feet (with `foot_lock`): the whole number nearest `LOCK_FPS` times the frame time,
    at least 1 and at most `MAX_SUPERSAMPLING` (1 from 100 fps up, 2 at 60 fps, 4 at 30, 5 at 24-25).

    The lock's rules count frames (its easing is `SMOOTH_S` rounded to frames: one at 30 fps,
    two at 60, five at 120), and at one frame it ran other rules (a horizontal-only toe hold, a
    slope-limited band lift, no toe clearance). The same clip resampled to 30 fps locked
    differently (N = 4 Euler, 5 s): CMU 02_01 stepped its knee 16.7 deg at lift-off against the
    capture's 13.1, 02_03 flew 35% of the frames against the captured 16%, and Bandai-1's runs
    flew 9-51% against the captured 0-50%. Locked at 4x and decimated: 02_01's knee 9.4 deg,
    02_03 15% flight, Bandai-1 25/30 walks and runs within issue 21's bounds (23/30 at 1x; 24/30
    at 2x)."""
    try:
        dt = float(frame_time_s)
    except (TypeError, ValueError):
        return 1  # the caller's own check names the bad frame time
    if not (math.isfinite(dt) and dt > 0):
        return 1
    return int(min(max(round(LOCK_FPS * dt), 1), MAX_SUPERSAMPLING))


def _smoothstep(x):
    x = jnp.clip(x, 0.0, 1.0)
    return x * x * (3.0 - 2.0 * x)


def contact_weights(
    phase: Float[ArrayLike, " T"], intervals: Float[ArrayLike, "2 2"], *, blend: Float[ArrayLike, ""] = BLEND_RAD
) -> Float[Array, "T 2"]:
    """Smooth stance weights of both feet from the cycle phase.

    1 inside each foot's contact interval `[start, end]` (circular), easing to 0 (smoothstep)
    over `blend` radians before the start and after the end: the lock takes hold while the foot
    is still descending and lets go as it lifts.

    Arguments:
        phase: `[T]` cycle phase of each frame (radians, any branch).
        intervals: `[2, 2]` (left, right) × (start, end) phases (radians; `contact_intervals`).
        blend: radians of the cycle over which a weight eases in and out (> 0).

    Returns:
        `[T, 2]` weights in [0, 1] (left, right). Pure jnp: jit, vmap and grad (in `phase`).
    """
    phase = jnp.asarray(phase)
    iv = jnp.asarray(intervals, phase.dtype if jnp.issubdtype(phase.dtype, jnp.floating) else None)
    if iv.shape != (2, 2):
        raise UserError(f"contact_weights: `intervals` must be [2, 2] (foot, start/end), got {iv.shape}")
    start, end = iv[:, 0], iv[:, 1]
    length = jnp.mod(end - start, TWO_PI)
    u = jnp.mod(phase[:, None] - start[None, :], TWO_PI)
    b = jnp.asarray(blend, u.dtype)
    ramp_out = _smoothstep(1.0 - (u - length[None]) / b)
    ramp_in = _smoothstep(1.0 - (TWO_PI - u) / b)
    return jnp.where(u <= length[None], 1.0, jnp.maximum(ramp_out, ramp_in))


# ------------------------------------------------------------------------------- foot locking


def _leg_columns(skeleton, representation, body_map):
    """Static: per leg, (joint, first feature column, euler order or "expmap") of hip, knee, ankle."""
    from fourierjax.features import channel_names_for

    names = channel_names_for(skeleton.topology, representation)
    first: dict[str, tuple[int, str]] = {}
    for c, n in enumerate(names):
        joint, _, chan = n.rpartition(".")
        if not joint or joint == "root":
            continue
        if joint not in first:
            first[joint] = (c, "")
        if representation == "euler":
            first[joint] = (first[joint][0], first[joint][1] + chan[0])
    topo_names = skeleton.topology.names
    legs = []
    for leg in (body_map.left, body_map.right):
        joints = []
        for j in (leg.hip, leg.knee, leg.ankle):
            name = topo_names[j]
            if name not in first:
                raise UserError(f"lock_feet: joint {name!r} (a leg joint of the body map) has no rotation "
                                "channels to lock the foot with")
            col, order = first[name]
            joints.append((int(j), col, order if representation == "euler" else "expmap"))
        legs.append(tuple(joints))
    return tuple(legs)


def _nearest_euler(new, old, order):
    from fourierjax._math import wrap_angle

    a = old + wrap_angle(new - old)
    twin = rotations.euler_twin(new, order)
    b = old + wrap_angle(twin - old)
    pick = jnp.sum((a - old) ** 2, -1, keepdims=True) <= jnp.sum((b - old) ** 2, -1, keepdims=True)
    return jnp.where(pick, a, b)


def _nearest_expmap(new, old):
    th = safe_norm(new)[..., None]
    axis = new / jnp.maximum(th, 1e-12)
    cands = jnp.stack([new + k * TWO_PI * axis for k in (-1.0, 0.0, 1.0)], 0)
    d = jnp.sum((cands - old[None]) ** 2, -1)
    k = jnp.argmin(d, 0)
    return jnp.take_along_axis(cands, k[None, ..., None], 0)[0]


def hold_weights(
    heights: Float[Array, "*B 2 P"], contact: Float[Array, "*B 2"], band: Float[ArrayLike, ""]
) -> Float[Array, "*B 2 P"]:
    """How firmly each foot point is held: 1 within `band` of its floor, easing to 0 at 1.5
    times that; in stance (`contact`, the phase's weight) from twice the band down, so the lock
    takes hold while the foot descends. Heel-to-toe roll follows: the heel is held while
    it is down, the toe while it is.

    Arguments:
        heights: `[..., 2, P]` height of each foot point above its floor (file units).
        contact: `[..., 2]` stance weights in [0, 1].
        band: the contact band (file units).

    Returns:
        `[..., 2, P]` weights in [0, 1].
    """
    low = _smoothstep((1.5 * band - heights) / (0.5 * band))
    wide = _smoothstep((2.0 * band - heights) / band)
    return jnp.maximum(low, contact[..., None] * wide)


def _over_axis(op, x, axis):
    # An unrolled reduction over a short axis (the foot points): fused by XLA into its consumers
    # (a reduction is a kernel of its own: 0.8 ms against 0.1 ms for the crowd's 10,000 rows).
    out = jax.lax.index_in_dim(x, 0, axis, keepdims=False)
    for p in range(1, x.shape[axis]):
        out = op(out, jax.lax.index_in_dim(x, p, axis, keepdims=False))
    return out


def hold_step(
    state: tuple[Float[Array, "*B 2 P 3"], Float[Array, "*B 2 P"]],
    points: Float[Array, "*B 2 P 3"],
    weights: Float[Array, "*B 2 P"],
    horizontal: Float[Array, " 3"],
    *,
    characters_last: bool = False,
) -> tuple[tuple[Float[Array, "*B 2 P 3"], Float[Array, "*B 2 P"]], Float[Array, "*B 2 3"]]:
    """One frame of foot holding: the horizontal shift of each foot that keeps its held points put.

    A point is planted where it is (after the shift) on the frame its weight rises above 0 and
    released when it falls to 0; the shift is the weighted mean of the held points' errors, times
    the largest weight (so it eases in and out). The state is per point: its planted position
    and whether it is planted.

    Arguments:
        state: `(targets [..., 2, P, 3], planted [..., 2, P])` from the previous frame
            (`init_hold_state`).
        points: `[..., 2, P, 3]` this frame's foot points before the lock.
        weights: `[..., 2, P]` from `hold_weights`.
        horizontal: `[3]` 1 on the ground-plane axes, 0 on the up axis.
        characters_last: the crowd's layout instead (static): state `([2, P, 3, B], [2, P, B])`,
            points `[2, P, 3, B]`, weights `[2, P, B]`, shift `[2, 3, B]`.

    Returns:
        `(state, shift [..., 2, 3])`; add the shift to the whole foot.
    """
    targets, planted = state
    pa = 1 if characters_last else weights.ndim - 1  # the points' axis; their components' is next
    ca = pa + 1
    held = weights * planted
    err = (targets - points) * jnp.reshape(horizontal, tuple(3 if k == ca else 1 for k in range(points.ndim)))
    total = _over_axis(jnp.add, held, pa)
    mean = _over_axis(jnp.add, jnp.expand_dims(held, ca) * err, pa) / jnp.expand_dims(jnp.maximum(total, 1e-9), pa)
    shift = mean * jnp.expand_dims(_over_axis(jnp.maximum, held, pa), pa)
    landed = (weights > 0) & (planted <= 0)
    moved = points + jnp.expand_dims(shift, pa)
    targets = jnp.where(jnp.expand_dims(landed, ca), moved, targets)
    planted = jnp.where(weights > 0, 1.0, 0.0).astype(planted.dtype)
    return (targets, planted), shift


def init_hold_state(points: Float[Array, "*B 2 P 3"]) -> tuple[Float[Array, "*B 2 P 3"], Float[Array, "*B 2 P"]]:
    """The state of `hold_step` before the first frame: nothing planted."""
    return jnp.zeros_like(points), jnp.zeros(points.shape[:-1], points.dtype)


def stillness(
    points: Float[Array, "T 2 P 3"], root_position: Float[Array, "T 3"], *, horizontal: Float[Array, " 3"],
    fraction: float = STILL_FRACTION,
) -> Float[Array, "T 2 P"]:
    """How still each foot point is in the world: 1 below `fraction` (default `STILL_FRACTION`)
    of the mean root move per frame, easing to 0 at twice that (horizontal moves, central
    differences).

    Arguments:
        points: `[T, 2, P, 3]` world foot points; root_position: `[T, 3]` the root path.
        horizontal: `[3]` 1 on the ground-plane axes, 0 on the up axis.

    Returns:
        `[T, 2, P]` weights in [0, 1].
    """
    d = (points[1:] - points[:-1]) * jnp.reshape(horizontal, (1, 1, 1, 3))
    move = safe_norm(d)  # [T-1, 2, P]
    move = jnp.concatenate([move[:1], 0.5 * (move[1:] + move[:-1]), move[-1:]], axis=0)
    ref = fraction * jnp.mean(safe_norm((root_position[1:] - root_position[:-1]) * horizontal[None]))
    ref = jnp.maximum(ref, 1e-6)
    return _smoothstep((2.0 * ref - move) / ref)


def _next(mask, idx, T):
    return jax.lax.cummin(jnp.where(mask, idx, T), axis=0, reverse=True)


def _plant(points, lam, low, lead=0):
    """Horizontal shift `[T, 3]` holding one foot's points where they land (offline: the
    landing of a contact is known before it happens, so a descending foot is drawn to it).

    A contact is a run of frames with a point down (`low`: the points that the skating metric
    counts). Every point is held at its place
    in mid-contact while its weight lasts: the heel while it is down, then the toe (heel-to-toe
    roll); the shift is the weighted mean of the held points' errors. With `lead` frames (static),
    each contact's hold starts that many frames earlier (but for one cut by the last frame), with
    the weights of its first frame, so that easing the shift over `lead` frames on each side
    (`_smooth`) has the foot stopped by the contact's first frame."""
    T, P = lam.shape
    idx = jnp.arange(T)
    down = jnp.any(low, -1)
    on = down
    for k in range(1, lead + 1):  # each contact starts `lead` frames earlier
        on = on | jnp.concatenate([down[k:], jnp.zeros((k,), bool)])
    if lead > 0:
        # A contact cut by the clip's end is not led in: led in, the last landing of a 5 s 02_01
        # popped the knee (4.4 deg against the capture's 3.5; 3.6 at 5.5 s, again the last
        # landing; the other landings 2.3 at most). Not led in: 2.6.
        prev_d = jnp.concatenate([jnp.zeros((1,), bool), on[:-1]])
        seg_d = jnp.clip(jax.lax.cummax(jnp.where(on & ~prev_d, idx, -1), axis=0), 0, T - 1)
        cut = jax.ops.segment_max(jnp.where(on, idx, -1), seg_d, num_segments=T)[seg_d] >= T - 1
        on = jnp.where(cut, down, on)
    prev_on = jnp.concatenate([jnp.zeros((1,), bool), on[:-1]])
    next_on = jnp.concatenate([on[1:], jnp.zeros((1,), bool)])
    seg_start = jax.lax.cummax(jnp.where(on & ~prev_on, idx, -1), axis=0)
    seg_start = jnp.clip(seg_start, 0, T - 1)
    # The planted place: the foot's pose in the middle of the frames of the contact where it
    # is down (mid-stance, the foot flat); segments are numbered by their first frame.
    down = down & on
    first = jax.ops.segment_min(jnp.where(down, idx, T), seg_start, num_segments=T)[seg_start]
    last = jax.ops.segment_max(jnp.where(down, idx, -1), seg_start, num_segments=T)[seg_start]
    s = jnp.where(first < T, (first + last) // 2, seg_start)  # [T]
    err = points[s] - points
    if lead > 0:
        # The lead-in frames hold with the weights of the contact's first frame.
        ref = jnp.where(first < T, jnp.clip(idx, first, jnp.maximum(first, last)), idx)
        lam = lam[ref]
    total = jnp.sum(lam, -1, keepdims=True)
    held = jnp.sum(lam[..., None] * err, -2) / jnp.maximum(total, 1e-9)
    # In the air the shift eases from the last contact's to the next one's (smoothstep over the
    # swing): no jump at lift-off or landing.
    last_end = jax.lax.cummax(jnp.where(on & ~next_on, idx, -1), axis=0)
    next_start = _next(on & ~prev_on, idx, T)
    prev_shift = held[jnp.clip(last_end, 0, T - 1)]
    next_shift = held[jnp.clip(next_start, 0, T - 1)]
    prev_shift = jnp.where((last_end >= 0)[:, None], prev_shift, next_shift)
    next_shift = jnp.where((next_start < T)[:, None], next_shift, prev_shift)
    x = jnp.clip((idx - last_end) / jnp.maximum(next_start - last_end, 1), 0.0, 1.0)
    if lead > 0:
        # The lead-in takes its frames from the swing's end: the easing is warped towards the
        # end (`x ** LEAD_WARP`) so the early swing keeps its pace. Not warped, the knee's
        # largest step, early in 02_03's swing, went 5.25 -> 5.33 deg (the capture's 5.28);
        # warped: 5.21.
        x = x ** LEAD_WARP
    u = _smoothstep(x)
    air = prev_shift + u[:, None] * (next_shift - prev_shift)
    return jnp.where(on[:, None], held, air), on


def _smooth(x, half):
    """A triangular moving average over the first axis, `half` frames each side (edges held)."""
    w = jnp.asarray([half + 1.0 - abs(k) for k in range(-half, half + 1)], x.dtype)
    w = w / jnp.sum(w)
    T = x.shape[0]
    xp = jnp.concatenate([jnp.repeat(x[:1], half, 0), x, jnp.repeat(x[-1:], half, 0)], axis=0)
    return sum(w[k] * xp[k:k + T] for k in range(2 * half + 1))


def _stance_mean(on, x):
    """Per frame, the mean of `x` over its run of `on` frames (a stance); 1 outside stance."""
    T = on.shape[0]
    idx = jnp.arange(T)
    prev_on = jnp.concatenate([jnp.zeros((1,), bool), on[:-1]])
    seg = jnp.clip(jax.lax.cummax(jnp.where(on & ~prev_on, idx, -1), axis=0), 0, T - 1)
    total = jax.ops.segment_sum(jnp.where(on, x, 0.0), seg, num_segments=T)[seg]
    count = jax.ops.segment_sum(on.astype(x.dtype), seg, num_segments=T)[seg]
    return jnp.where(on, total / jnp.maximum(count, 1.0), 1.0)


def _reach_on_floor(H, G, A, reach, upv):
    """Ankle goals `[T, 3]` whose horizontal distance from the hip is eased short of what the leg
    reaches at the goal's height: where the reach runs out, the plant slides with the hip and
    the foot stays on the floor (eased along the hip-to-goal line, `soft_reach`, it would lift).
    Goals within `REACH_KNEE` of the reach (or the pose's own hip-to-ankle distance) stay."""
    from fourierjax._math import safe_sqrt

    u = upv[None]
    HG = G - H
    v = jnp.sum(HG * u, -1, keepdims=True)
    h = HG - v * u
    hn = safe_norm(h)
    d0 = REACH_KNEE * reach
    d_ok = jnp.minimum(jnp.maximum(d0, safe_norm(A - H)), d0 + 0.9 * (REACH_LIMIT * reach - d0))
    h_max = jnp.maximum(safe_sqrt(jnp.maximum(d_ok ** 2 - v[:, 0] ** 2, 0.0)), 1e-3 * reach)
    AH = A - H
    start = safe_norm(AH - jnp.sum(AH * u, -1, keepdims=True) * u)
    hn2 = soft_reach(hn, h_max, 0.8, 1.0, start)
    return H + v * u + h * (hn2 / jnp.maximum(hn, 1e-9))[:, None]


def _toe_off(contact, heel_low, heel_still, late_frames):
    """`(off, late)` `[T, 2]`: the stance weight from the first frame of a stance at which the heel
    is down (low and still) to the stance's end (0 before: at the landing the tip swings in), and
    the same held `late_frames` frames longer (a moving maximum towards later frames)."""
    idx = jnp.arange(contact.shape[0])[:, None]
    heel_down = jax.lax.cummax(jnp.where(heel_low & heel_still, idx, -1), axis=0)
    stance_start = jax.lax.cummax(jnp.where(contact <= 0, idx, -1), axis=0)
    off = contact * (heel_down > stance_start)
    late = off
    for k in range(1, late_frames + 1):
        late = jnp.maximum(late, jnp.concatenate([jnp.repeat(off[:1], k, 0), off[:-k]], 0))
    return off, late


def _toe_clearance(P, A, G, contact, floor, band, up, sign, reach, smooth):
    """`(q [T, 4], angle [T])`: the world rotation of one foot about its ankle, toes up, that lifts
    the toe's end point (the last of the foot points `P [T, P, 3]`) to `LIFT_BANDS` bands over its
    `floor` (height along the up axis `up`) outside stance (weight `1 - contact`), once the ankle
    moved from `A` to `G` (`[T, 3]`); the angle is eased over `smooth` frames each side (a
    triangular moving average). The identity where the tip is higher or the foot in stance."""
    from fourierjax._legik import cross, safe_normalize

    tip = P[:, -1] - A  # [T, 3] ankle to tip
    h = sign * (G[:, up] + tip[:, up]) - floor
    need = jnp.maximum(LIFT_BANDS * band - h, 0.0) * (1.0 - contact)
    fwd = tip.at[:, up].set(0.0)
    angle = jnp.minimum(need / jnp.maximum(safe_norm(fwd), 1e-3 * reach), TOE_CLEAR_MAX)
    angle = _smooth(angle, smooth)
    upv = jnp.zeros_like(fwd).at[:, up].set(sign)
    axis = cross(safe_normalize(fwd, jnp.zeros_like(fwd)), upv)
    return rotations.quat_from_expmap(axis * angle[:, None]), angle


def _dilate(x, half):
    """A moving maximum over the first axis, `half` frames each side (edges held): eased by
    `_smooth` over the same frames, a lift never falls below what it was on any frame."""
    T = x.shape[0]
    xp = jnp.concatenate([jnp.repeat(x[:1], half, 0), x, jnp.repeat(x[-1:], half, 0)], axis=0)
    out = xp[:T]
    for k in range(1, 2 * half + 1):
        out = jnp.maximum(out, xp[k:k + T])
    return out


#: With one frame of easing (30 fps; `_band_lift`) a foot point inside the contact band that moves
#: faster than `BAND_LIFT_FRACTION` times `STILL_FRACTION`'s threshold (central differences, as
#: the skating metric) is lifted to `LIFT_BANDS` bands over where it rests, where its foot is not
#: held; the lift changes by at most `BAND_LIFT_SLOPE` bands a frame over `BAND_LIFT_REACH` frames.
BAND_LIFT_FRACTION = 1.0
BAND_LIFT_SLOPE, BAND_LIFT_REACH = 0.5, 3


def _band_lift(P, A, G, free, root_position, band, floor, up, sign):
    """`[T]` how far (file units, up) to raise one foot's ankle goal `G` `[T, 3]` so that its
    points `P` `[T, P, 3]` (moved with the ankle from `A`) are not inside the contact band while
    they move: a point there faster than the threshold (`BAND_LIFT_FRACTION`) is taken to
    `LIFT_BANDS` bands over its resting height, times `free` `[T]` (1 where the foot is not
    held), and the lift is slope-limited (`BAND_LIFT_SLOPE`) so the knee does not pop."""
    Q = P + (G - A)[:, None, :]  # [T, P, 3] the points where the goal puts them
    hz = jnp.ones(3, Q.dtype).at[up].set(0.0)
    g = jnp.concatenate([Q[1:2] - Q[:1], 0.5 * (Q[2:] - Q[:-2]), Q[-1:] - Q[-2:-1]], 0) * hz[None, None]
    speed = safe_norm(g)  # [T, P] per frame
    ref = BAND_LIFT_FRACTION * STILL_FRACTION * jnp.mean(safe_norm((root_position[1:] - root_position[:-1]) * hz[None]))
    ref = jnp.maximum(ref, 1e-6)
    moving = _smoothstep((speed - ref) / ref)
    h = sign * Q[..., up] - floor[None]
    # Measured from where each point rests: it may stand over its floor (the foot's lowest point
    # is the one put there). From the floor, Bandai-1 run_active's right toe, resting 0.33 bands
    # over it, swung through the band at 500 units/s.
    h = h - jnp.maximum(jnp.percentile(h, 5.0, axis=0), 0.0)[None]
    lift = jnp.max(jnp.maximum(LIFT_BANDS * band - h, 0.0) * moving, -1) * free
    # Slope-limited (an erosion with slope `r`): dropped at once onto the floor, the landing knee
    # popped (Bandai-1 walk_not-confident: 15.4 deg against the capture's 12.3).
    r = BAND_LIFT_SLOPE * band
    T = lift.shape[0]
    out = lift
    for k in range(1, BAND_LIFT_REACH + 1):
        pad = jnp.full((k,), jnp.inf, lift.dtype)
        out = jnp.minimum(out, jnp.concatenate([lift[k:], pad]) + k * r)
        out = jnp.minimum(out, jnp.concatenate([pad, lift[:T - k]]) + k * r)
    return out


def _roll_off(rel, contact, band):
    """`[T, 2, P]` in [0, 1]: how far each foot point is still held horizontally as its foot rolls
    (`ROLL_BANDS`). Per stance (a run of `contact >= 0.5`), in its second half, a point's rise is
    its height over its lowest height in the stance so far; a point that has risen by more than
    the foot's least-risen point is pivoting off it (the heel when the foot rolls onto its ball):
    held there, it drags the points that stay down. 1 elsewhere."""
    on = contact >= 0.5  # [T, 2]
    prev = jnp.concatenate([jnp.zeros_like(on[:1]), on[:-1]], 0)
    start = jnp.broadcast_to((on & ~prev)[..., None], rel.shape)

    def seg_min(a, b):
        fa, va = a
        fb, vb = b
        return fa | fb, jnp.where(fb, vb, jnp.minimum(va, vb))

    _, low = jax.lax.associative_scan(seg_min, (start, rel), axis=0)
    # The second half of each stance only (the heel-off): at the landing and in mid-stance the
    # foot settles, and a point let go there slid (07_04's landing heel 0.059 -> 0.075 units/s).
    idx = jnp.arange(on.shape[0])[:, None]
    first = jax.lax.cummax(jnp.where(on & ~prev, idx, -1), axis=0)
    nxt = jnp.concatenate([on[1:], jnp.zeros_like(on[:1])], 0)
    last = jax.lax.cummin(jnp.where(on & ~nxt, idx, on.shape[0]), axis=0, reverse=True)
    late = on & (2 * idx > first + last)
    rise = jnp.where(late[..., None], rel - low, 0.0)
    roll = rise - jnp.min(rise, -1, keepdims=True)
    lo, hi = ROLL_BANDS
    return _smoothstep((hi * band - roll) / ((hi - lo) * band))


def _heading_hold(q_foot, w, up):
    """`[T, 4]` world turns of one foot about the up axis (index `up`) that hold its heading at
    the one it has on the first frame of full weight (`w >= 0.5`) of each run of `w > 0` (a
    stance), by the weight `w` `[T]` (`quat_power`); the identity where `w` is 0. `q_foot`
    `[T, 4]`: the foot's world orientations (wxyz)."""
    T = w.shape[0]
    idx = jnp.arange(T)
    on = w > 0
    prev = jnp.concatenate([jnp.zeros((1,), bool), on[:-1]])
    seg = jnp.clip(jax.lax.cummax(jnp.where(on & ~prev, idx, -1), axis=0), 0, T - 1)
    first = jax.ops.segment_min(jnp.where(on & (w >= 0.5), idx, T), seg, num_segments=T)[seg]
    ref = jnp.where(first < T, first, seg)
    d = rotations.quat_multiply(q_foot[ref], rotations.quat_conjugate(q_foot))
    # Its twist about the up axis (swing-twist): the w and up components, renormalized.
    d = d * jnp.zeros(4, d.dtype).at[0].set(1.0).at[1 + up].set(1.0)[None]
    d = d / jnp.maximum(safe_norm(d), 1e-9)[..., None]
    return rotations.quat_power(d, jnp.where(on, w, 0.0))


def _before_still(down_loose, down_strict):
    """`[T, 2]`: the frames of each run of `down_loose` before its first `down_strict` frame."""
    idx = jnp.arange(down_loose.shape[0])[:, None]
    prev = jnp.concatenate([jnp.zeros_like(down_loose[:1]), down_loose[:-1]], 0)
    start = jax.lax.cummax(jnp.where(down_loose & ~prev, idx, -1), axis=0)
    seen = jax.lax.cummax(jnp.where(down_strict, idx, -1), axis=0) >= start
    return down_loose & ~seen


def _knee_speed_cap(H, G, l1, l2, step, free, window):
    """Ankle goals `[T, 3]` (from hip `H` to goal `G`, thigh `l1`, shin `l2`, `[T]`) whose knee
    angle changes by at most `step[t]` radians from frame t to t + 1 (`[T]`) where the foot is
    free (`free` `[T]` in [0, 1]; the stance keeps its goals), and whether a goal moved (`[T]`).

    The knee angle of the two-bone chain is a function of the hip-to-goal distance. Its series is
    replaced by the mean of its lower and upper Lipschitz envelopes over `window` frames each
    side (`min_k theta(t + k) + |S(t + k) - S(t)|` and `max_k theta(t + k) - |S(t + k) - S(t)|`,
    `S` the running sum of `step`): equal to it where it already changes slower, no lag
    (symmetric in time), and the goal moves along
    the hip-to-goal line to the new distance. Faster steps (the low-harmonic model's early swing,
    CMU 09_02's knee at 6.2 deg a frame against the capture's 5.7) are spread over their
    neighbours. An excess that lasts longer than the window is spread only in part."""
    from fourierjax._math import safe_sqrt

    HG = G - H
    d = safe_norm(HG)
    cos = jnp.clip((l1 ** 2 + l2 ** 2 - d ** 2) / (2.0 * l1 * l2), -1.0 + 1e-6, 1.0 - 1e-6)
    theta = jnp.arccos(cos)
    T = theta.shape[0]
    inf = jnp.full((window,), jnp.inf, theta.dtype)
    lo_p = jnp.concatenate([inf, theta, inf])
    hi_p = jnp.concatenate([-inf, theta, -inf])
    S = jnp.concatenate([jnp.zeros((1,), theta.dtype), jnp.cumsum(jnp.broadcast_to(step, (T,))[:-1])])
    S_p = jnp.concatenate([jnp.repeat(S[:1], window), S, jnp.repeat(S[-1:], window)])  # beside the inf
    lower, upper = theta, theta
    for k in range(1, window + 1):
        for off in (window - k, window + k):
            dist = jnp.abs(S_p[off:off + T] - S)
            lower = jnp.minimum(lower, lo_p[off:off + T] + dist)
            upper = jnp.maximum(upper, hi_p[off:off + T] - dist)
    capped = theta + free * (0.5 * (lower + upper) - theta)
    d2 = safe_sqrt(l1 ** 2 + l2 ** 2 - 2.0 * l1 * l2 * jnp.cos(capped))
    moved = capped != theta
    return jnp.where(moved[:, None], H + HG * (d2 / jnp.maximum(d, 1e-9))[:, None], G), moved


def _lock(features, skeleton, contact, root_position, clearance, ground, band, *, representation,
          body_map, legs, smooth_frames=0, knee_step=None, knee_window=0):
    from fourierjax.features import local_pose_from_features
    from fourierjax.kinematics import forward_kinematics

    up = int(body_map.up_axis)
    sign = float(body_map.up_sign)
    pelvis = int(body_map.pelvis)
    parents = skeleton.topology.parents
    foot_idx = jnp.asarray([body_map.left.foot_points, body_map.right.foot_points])  # [2, P]

    def fk(f):
        r = forward_kinematics(skeleton, *local_pose_from_features(skeleton, f, representation, pelvis))
        return r.rotations, jnp.concatenate([r.positions, r.end_site_positions], 0)

    quats, pts = jax.vmap(fk)(features)
    pts = pts + root_position[:, None, :]
    upv = jnp.zeros(3, features.dtype).at[up].set(1.0)
    feet_pts = pts[:, foot_idx]  # [T, 2, P, 3]
    rel = sign * feet_pts[..., up] - ground - clearance[None]  # [T, 2, P] above each point's floor
    # Heading hold: while a point of a foot is down in stance the foot keeps the heading (its
    # turn about the up axis through the ankle) it landed with (`_heading_hold`). The model's
    # foot yaws in stance, and a translation cannot hold both heel and ball of a turning foot:
    # the ankle slid against the planted ball (skating 02_03 0.251x -> 0.234x, 09_01 0.261x ->
    # 0.226x, 02_01 0.179x -> 0.132x). The turn leaves every height as it is.
    yaw_w = contact * jnp.max(hold_weights(rel, contact, band), -1)  # [T, 2]
    ankles = [leg[2][0] for leg in legs]
    q_yaw = jnp.stack([_heading_hold(quats[:, a], yaw_w[:, f], up) for f, a in enumerate(ankles)], 1)  # [T, 2, 4]
    A0 = pts[:, jnp.asarray(ankles)][:, :, None, :]  # [T, 2, 1, 3]
    feet_pts = A0 + rotations.quat_apply(q_yaw[:, :, None, :], feet_pts - A0)
    # Only a still point is planted. A low-harmonic model smooths the foot's sharp stop at heel
    # strike and its start at toe-off: the point is already (still) low while it slides at up
    # to the root's speed (CMU 07_01, N = 3: 77 units/s at 0.46 units over the floor, 9 units in
    # all). Held where it landed, the leg could not reach it (the foot lifted, the knee jumped);
    # held where it stops, the landing leg could not. A sliding point is lifted clear of the
    # band instead (it is not in contact), and the foot is planted where its points are still.
    still = stillness(feet_pts, root_position, horizontal=1.0 - upv)
    # A stance (the phase's) in which no low point is ever still slides on the floor: an
    # extrapolated model whose root outruns its stride (`synth A --add (A-B)=1` on Bandai
    # walk_normal slides the stance foot at 168 cm/s). Lifted as a sliding point, it stood 3.2 cm
    # over the floor for most of the walk; it is planted instead, and the plant slides with the
    # hip where the leg's reach runs out (`_reach_on_floor`).
    still_low = jnp.max(still * (rel <= band), axis=-1)  # [T, 2]
    still_share = jnp.stack([_stance_mean(contact[:, f] >= 0.5, still_low[:, f]) for f in range(2)], 1)
    sliding = _smoothstep((SLIDING_SHARE - still_share) / (0.5 * SLIDING_SHARE))
    slide_w = contact * sliding  # [T, 2]
    still = jnp.maximum(still, slide_w[..., None])
    # Toe-off: the low-harmonic foot slides forward on its tip before the tip lifts (02_03: up to
    # 19 units/s inside the contact band), and a point that moves is let go. So once the heel was
    # down in a stance, the toe's end point (the last foot point) is held for the rest of the
    # phase's stance weight (`still_v`: the lift waits for it), and horizontally a few frames
    # longer (`still`), so the tip rises before the foot swings on. Its release needs the easing:
    # with one frame of it (Bandai-1 at 30 fps) the leg held at its reach let go at once and the
    # knee popped (run_normal_001: 20.1 deg against 16.2 without the hold, the capture's 16.4),
    # so below `TOE_HOLD_FRAMES` of easing the tip is held horizontally only, not longer, and
    # faded where it stretches the leg (below: knee 16.1 deg, skating 0.231x -> 0.227x).
    still_v = still_free = still
    if smooth_frames >= 1:
        off, off_late = _toe_off(contact, rel[..., 0] <= band, still[..., 0] > 0.5, smooth_frames // 2)
        if smooth_frames >= TOE_HOLD_FRAMES:
            still_v = still.at[..., -1].set(jnp.maximum(still[..., -1], off))
        still = still.at[..., -1].set(jnp.maximum(still[..., -1], off_late))
    hold = hold_weights(rel, contact, band)
    # Horizontally a point pivoting off the foot's lowest ones is let go (`_roll_off`): held, the
    # rising heel dragged the ball (Bandai-1 walk_happy: the ball at 0.3-1.1 units a frame late in
    # stance, where the unlocked model's stood within 0.3).
    hold_h = hold * _roll_off(rel, contact, band)
    lam = hold_h * still
    # Tried for the landing (session 16, 02_03 / 09_01 against 0.39x / 0.50x skating, 28% / 25%
    # flight): counting a landing point still within 1 band of its planted target (or 0.5)
    # gave 0.43x / 0.56x (0.41x / 0.52x), flight 24% (27%); the heel then slides into the band at
    # the swing's speed (41 units/s at 2.5 bands from the target). Drawing it to the target as it
    # descends (height-weighted) gave 0.40x and 9% flight but popped the knee (7.9 deg against
    # the capture's 5.3; 09_01 13.4 against 8.2); eased in over 0.1-0.3 s it kept the knee but
    # skated 0.49-0.70x. Planting earlier needs the leg to reach forward faster than the bound.
    # Down: within the band; in stance (the phase's weight) also a foot that hovers under twice it.
    hover = (contact[..., None] >= 0.5) & (rel <= 2.0 * band) & jnp.any(rel <= band, 0, keepdims=True)
    low_in = (rel <= band) | hover
    low = low_in & (still > 0.5)
    # Landing: eased over `smooth_frames` on each side of its first frame, the plant stopped the
    # foot only `smooth_frames` after it, the heel sliding into the band at up to the swing's
    # speed (02_03: 21 units/s; 09_01: 34). Each contact's hold is led in by `smooth_frames`
    # (`_plant`): the foot is stopped when it lands (heel at landing 0.65 -> 0.24 units/s of the
    # 02_03 skating, 1.08 -> 0.39 on 09_01; at 30 fps, one frame, Bandai-1 run_normal 0.227x ->
    # 0.200x, knee 16.2 deg against 16.4). Not led out: held on past the contact's end, the leg
    # stretched and the knee popped (02_03 6.8 deg against 5.3).
    lead = smooth_frames
    # The landing (issue 21's run flight): a low-harmonic heel decelerates into the band over 6-12
    # frames (02_03 at N = 5: 38 units/s one band over the floor, 6 units/s at 0.1 band), so
    # by `stillness` it slid, was not planted and was lifted to `LIFT_BANDS` bands: frames with no
    # foot in contact, the run part of 02_01 -> 02_03 flying 29-31% against the captured 16%.
    # Until a point of the foot is still, a landing point is taken by the plant under twice
    # the stillness threshold (`PLANT_STILL_FRACTION`), so its hold is led in and the slide ends
    # sooner; the release keeps the strict threshold (loose there too, the ball and tip slid in
    # mid-stance: 02_03 0.306x -> 0.313x skating, against 0.298x landing only). With the lift
    # judged after the hold (below), the run part flies 23.7% / 24.5% (walk -> run / run -> walk);
    # the earlier plant alone left it at 29.3% / 31.1%, the lift after the hold alone gave 27.3% /
    # 29.1%, and 2.5 times the threshold (22.3% / 22.0%) stepped 02_03's knee 5.29 deg (the
    # capture's 5.28).
    still_land = jnp.maximum(stillness(feet_pts, root_position, horizontal=1.0 - upv, fraction=PLANT_STILL_FRACTION),
                             slide_w[..., None])
    if smooth_frames >= 1:
        still_land = still_land.at[..., -1].set(jnp.maximum(still_land[..., -1], off_late))
    low_land = low_in & (still_land > 0.5)
    landing = _before_still(jnp.any(low_land, -1), jnp.any(low, -1))[..., None]  # [T, 2, 1]
    lam_p = jnp.where(landing, hold_h * still_land, lam)
    low_p = jnp.where(landing, low_land, low)
    planted = [_plant(feet_pts[:, f], lam_p[:, f], low_p[:, f], lead) for f in range(2)]
    shift = jnp.stack([p[0] for p in planted], 1)
    on_plant = jnp.stack([p[1] for p in planted], 1).astype(shift.dtype)  # [T, 2]
    shift = shift * (1.0 - upv)[None, None]
    if 1 <= smooth_frames < TOE_HOLD_FRAMES:
        # With one frame of easing (30 fps) the tip is held horizontally only, and only as far
        # as it keeps the leg short of its reach: held on, the knee froze straight and then
        # caught up with the swing in one frame (the pop above). The shift the hold adds is faded
        # out (smoothstep) as it stretches the hip-to-ankle distance by up to `TOE_REACH_FADE`
        # of the leg's length over the unheld foot's.
        low_free = low_in & (still_free > 0.5)
        free = jnp.stack([_plant(feet_pts[:, f], (hold_h * still_free)[:, f], low_free[:, f])[0] for f in range(2)], 1)
        free = free * (1.0 - upv)[None, None]
        H, K, A = (jnp.stack([pts[:, leg[k][0]] for leg in legs], 1) for k in range(3))  # [T, 2, 3]
        reach = safe_norm(K - H) + safe_norm(A - K)
        excess = safe_norm(A + shift - H) - safe_norm(A + free - H)
        shift = free + (shift - free) * _smoothstep(1.0 - excess / (TOE_REACH_FADE * reach))[..., None]
    # Vertically: the foot's lowest point onto the floor while held, never below it.
    gap = jnp.min(rel, axis=-1)  # [T, 2]
    W = jnp.max(hold * still_v, axis=-1)
    dy = -gap * jnp.where(gap > 0, W, 1.0)
    # A sliding point is lifted to LIFT_BANDS bands over its floor, as far as the foot is not held.
    # A point is lifted only if it still slides once the feet are held (the horizontal shift
    # applied): a landing heel that the plant stops stays in contact.
    # (in contact the horizontal shift is not eased, below: `shift` is what is applied there)
    still_lift = jnp.maximum(still_v, stillness(feet_pts + shift[:, :, None], root_position, horizontal=1.0 - upv))
    need = jnp.max(jnp.maximum(LIFT_BANDS * band - rel, 0.0) * (1.0 - still_lift), axis=-1)  # [T, 2]
    dy = jnp.maximum(dy, need * (1.0 - W))
    shift = shift + (sign * dy)[..., None] * upv[None, None]
    if smooth_frames > 0:
        # The knee follows the shift: eased over a few frames it never pops (the capture's largest
        # knee step is the bound); the foot's lowest point stays on or over the floor.
        # The lowest point stays on or over the floor. (Easing the lift too costs skating where
        # the eased lift dips into the band: 07_01 0.17x against 0.08x unsmoothed, 09_01 1.04x
        # against 0.36x; lifting at once pops the knee: 10.3 and 9.3 deg against 4.7 and 6.8.)
        # The lift is a moving maximum before the easing, so it does not dip into the band where
        # a point still slides, faded (eased) where the foot is held: 02_03 0.73x -> 0.39x, 09_01
        # 1.04x -> 0.50x. Not faded it gave 0.55x and 0.28x but lifted held feet (Bandai
        # `interpolate` walk: median lowest foot 1.29 cm against 0.28); faded at once it popped
        # the knee (02_01 8.6 deg against 4.4).
        # Horizontally the easing is for the swing only: in a contact (`_plant`'s frames, eased
        # in over `smooth_frames`) the shift holds the planted points exactly. Eased there too (a
        # triangular moving average), a held point moved by a share of its neighbours' shift
        # changes (Bandai-1 run_chimpira at 30 fps: the planted toe at 5-17 units/s): skating
        # 02_03 0.298x -> 0.270x, 09_01 0.378x -> 0.297x, Bandai-1 21/30 -> 23/30 met (knee
        # steps unchanged or lower: walk_not-confident 12.27 -> 11.91 deg, the capture's 12.35).
        # Not eased in the swing either (0.257x, 0.290x), a short
        # swing (the 02_03 -> 02_01 transition's blend: 6 frames between toe-off and the next
        # lead-in) jumped the foot 1.24 units a frame against the sources' largest 1.02.
        eased = _smooth(shift, smooth_frames)
        mix = _smooth(on_plant, smooth_frames)[..., None] * (1.0 - upv)[None, None]  # [T, 2, 3]
        shift = eased + mix * (shift - eased)
        lifted = (_smooth(_dilate(need * (1.0 - W), smooth_frames), smooth_frames)
                  * _smooth(1.0 - W, smooth_frames))
        dy = jnp.maximum(sign * shift[..., up], jnp.maximum(-gap, lifted))
        shift = shift * (1.0 - upv)[None, None] + (sign * dy)[..., None] * upv[None, None]
    out = features
    feet_out = []
    for f, ((hip, c_hip, o_hip), (knee, c_knee, o_knee), (ankle, c_ankle, o_ankle)) in enumerate(legs):
        H, K, A = pts[:, hip], pts[:, knee], pts[:, ankle]
        P = feet_pts[:, f]
        G = A + shift[:, f]
        # Two-bone IK: the knee on the circle of points at thigh length from the hip and shin
        # length from the goal, on the side it bent to; a goal past reach is eased (no snap).
        l1, l2 = safe_norm(K - H), safe_norm(A - K)
        # In a sliding stance the plant slides where the reach runs out (the foot stays on the
        # floor); elsewhere an unreachable goal is eased along the leg, as before: on walks,
        # sliding on the floor there instead skated 0.98x the capture on 07_01 (0.07x lifted).
        G = G + slide_w[:, f, None] * (_reach_on_floor(H, G, A, l1 + l2, upv) - G)
        # Toe clearance (120 fps): the low-harmonic model's toe tip drags on the floor after the
        # stance (02_03: at up to 30 units/s, its height 0), and the lift (a moving maximum,
        # eased so the knee does not pop) takes it up through the band at 4-21 units/s. Outside
        # stance the foot turns toes up about its ankle instead, which the knee never sees, and
        # the ankle's goal moves back by as much as the turn moves the tip forward (about the
        # ankle it moves the tip forward by its depth under the ankle times the angle: the foot
        # is steep at toe-off). Eased over `smooth_frames` only, it popped 09_02's knee (8.2 deg
        # against 7.1); not moved back, it skated more (02_03 0.41x against 0.37x).
        if smooth_frames >= TOE_HOLD_FRAMES:
            q_clear, phi = _toe_clearance(P, A, G, contact[:, f], ground + clearance[f, -1], band, up, sign,
                                          l1 + l2, TOE_CLEAR_SMOOTH * smooth_frames)
            tip = P[:, -1] - A
            G = G - (rotations.quat_apply(q_clear, tip) - tip) * (1.0 - upv)[None]
        else:
            q_clear = None
        HG = G - H
        d = safe_norm(HG)
        G = H + HG * (soft_reach(d, l1 + l2, REACH_KNEE, REACH_LIMIT, safe_norm(A - H)) / jnp.maximum(d, 1e-9))[:, None]
        # At 30 fps (one frame of easing) the lift above, faded where the foot is held on the next
        # frame, left the landing point in the band at the swing's speed (Bandai-1 run_masculinity:
        # the ankle at 0.89 bands and 201 units/s the frame before it is planted), and the toe
        # swept through the band where it rests over its floor. The band lift takes them out
        # (`_band_lift`). Not at 120 fps: there it lifted CMU landings (02_03 0.298x -> 0.255x
        # skating) but the run part of the 02_01 -> 02_03 transition flew 33% (captured 16%).
        if 1 <= smooth_frames < TOE_HOLD_FRAMES:
            lift = _band_lift(P, A, G, 1.0 - W[:, f], root_position, band, ground + clearance[f], up, sign)
            G = G + lift[:, None] * (sign * upv)[None]
        if knee_step is not None:
            # The knee's speed where the foot is free (swing) stays within the capture's
            # (`knee_step`, radians a frame; `_knee_speed_cap`): the stance's hold is untouched.
            free = (1.0 - contact[:, f]) * (1.0 - W[:, f])
            G, capped = _knee_speed_cap(H, G, l1, l2, KNEE_CAP_MARGIN * knee_step[:, f], free, knee_window)
        else:
            capped = jnp.zeros(features.shape[:1], bool)
        K2, _ = jax.vmap(sphere_circle_point)(H, G, l1, l2, knee_pole(H, K, A))
        R1 = quat_between(K - H, K2 - H)
        R2 = quat_between(rotations.quat_apply(R1, A - K), G - K2)
        qm, qc = rotations.quat_multiply, rotations.quat_conjugate
        Q = quats
        q_hip = qm(qc(Q[:, parents[hip]]), qm(R1, Q[:, hip]))
        q_knee = qm(qc(Q[:, parents[knee]]), qm(qc(R1), qm(R2, qm(R1, Q[:, knee]))))
        q_foot = qm(q_yaw[:, f], Q[:, ankle])
        q_foot = q_foot if q_clear is None else qm(q_clear, q_foot)
        q_ankle = qm(qc(Q[:, parents[ankle]]), qm(qc(R1), qm(qc(R2), q_foot)))
        active = (W[:, f] > 0) | (gap[:, f] < 0) | jnp.any(shift[:, f] != 0, -1) | (yaw_w[:, f] > 0) | capped
        if q_clear is not None:
            active = active | (phi > 0)
        for q, col, order in ((q_hip, c_hip, o_hip), (q_knee, c_knee, o_knee), (q_ankle, c_ankle, o_ankle)):
            old = out[:, col:col + 3]
            if order == "expmap":
                new = _nearest_expmap(rotations.expmap_from_quat(q), old)
            else:
                new = _nearest_euler(rotations.euler_from_quat(q, order), old, order)
            out = out.at[:, col:col + 3].set(jnp.where(active[:, None], new, old))
        # The foot below the ankle keeps its world orientation (but for the toe clearance's
        # turn): its points move with the ankle.
        if q_clear is None:
            feet_out.append(P + jnp.where(active[:, None, None], (G - A)[:, None, :], 0.0))
        else:
            moved = G[:, None, :] + rotations.quat_apply(q_clear[:, None, :], P - A[:, None, :])
            feet_out.append(jnp.where(active[:, None, None], moved, P))
    return out, jnp.stack(feet_out, axis=1), lam


def lock_feet(
    features: Float[ArrayLike, "T C"],
    skeleton: Skeleton,
    contact: Float[ArrayLike, "T 2"],
    *,
    body_map: BodyMap,
    representation: str,
    root_position: Float[ArrayLike, "T 3"] | None = None,
    frame_time_s: float | None = None,
    clearance: Float[ArrayLike, "2 P"] | None = None,
    ground: Float[ArrayLike, ""] = 0.0,
    contact_band: Float[ArrayLike, ""] | None = None,
    return_feet: bool = False,
    smooth_frames: int = 0,
    knee_speed_rad_s: Float[ArrayLike, "*T 2"] | None = None,
) -> Float[Array, "T C"] | tuple[Float[Array, "T C"], Float[Array, "T 2 P 3"]]:
    """Planted feet for synthesized feature frames: a post-process by two-bone leg IK.

    Each contact (a run of `contact > 0` of one foot) gets one planted target, where the foot
    lands (its position at the first frame of full weight). The ankle is held there, then, as
    the heel lifts, the toe (heel-to-toe roll); the weights blend in and out. The hip stays
    where the synthesis put it; the knee goes on the circle of valid knee positions on the side
    it bent to (`_legik.sphere_circle_point`, shared with the stance lower body); goals past the
    leg's reach are eased short of it, so the knee never straightens fully, never hyperextends
    and never snaps. The foot keeps its world orientation, except that with `smooth_frames` of
    `TOE_HOLD_FRAMES` or more it turns toes up about its ankle outside stance where its toe's end
    point would pass under `LIFT_BANDS` contact bands (toe clearance: the ankle angle only, the
    ankle held where the turn leaves the tip); its lowest point is put on the floor in contact
    and is never below it. Frames the lock leaves alone (no contact, lift or turn) keep their
    features exactly.

    Arguments:
        features: `[T, C]` feature frames (`fourier` layout), the root already grounded
            (`synthesize_gait`, `ground_features`).
        skeleton: the `Skeleton`.
        contact: `[T, 2]` stance weights in [0, 1] (left, right; `contact_weights`).
        body_map: the skeleton's `BodyMap` (legs, feet, pelvis, up axis, height); static.
        representation: the features' ("euler" or "expmap"); static.
        root_position: `[T, 3]` world pelvis positions (`GaitResult.root_position`); default the
            trapezoid integral of `root.vx, root.vz` (needs `frame_time_s`) at height `root.y`.
        frame_time_s: seconds per frame (without `root_position`, and with `knee_speed_rad_s`).
        clearance: `[2, P]` sole clearances of the foot points (`GaitResult.clearance`); default 0.
        ground: floor height (file units; the hip rule's ground is 0).
        contact_band: a foot whose lowest point is within this height (file units) of the floor
            is held as in contact (weight 1, easing to 0 at twice the height); default 2% of
            the body height (the skating metric's band).
        return_feet: also return the locked world foot points `[T, 2, P, 3]`.
        smooth_frames: ease the feet's shifts over this many frames on each side (a triangular
            moving average; static), so the knee never pops: the vertical everywhere, the
            horizontal only in the swing (planted points stay put); 0 (default) keeps them as
            they are. The frames also set the landing's lead-in and, below `TOE_HOLD_FRAMES`,
            the 30 fps toe hold and band lift.
            `synthesize_gait` uses `SMOOTH_S` seconds of frames, on frames near 120 fps
            (`lock_supersampling`), so it never takes the 1-frame rules.
        knee_speed_rad_s: `[2]` (left, right), scalar or `[T, 2]` (per frame, e.g. scaled by a
            speed schedule): the largest knee angular speed (radians per second;
            `knee_speed_limit` of the captured clip) where the foot is free
            (out of stance and not held): the swing's knee is slowed to it (`_knee_speed_cap`,
            over `KNEE_CAP_WINDOW_S` each side). Needs `frame_time_s`. Default None: no cap.

    Returns:
        `[T, C]` features (and the foot points with `return_feet`). Pure: jit, vmap over
        characters and grad.
    """
    features = jnp.asarray(features)
    if features.ndim != 2 or features.shape[0] < 2:
        raise UserError(f"lock_feet: `features` must be [T >= 2, C], got shape {features.shape}")
    T = features.shape[0]
    contact = jnp.asarray(contact, features.dtype)
    if contact.shape != (T, 2):
        raise UserError(f"lock_feet: `contact` must be [T={T}, 2], got {contact.shape}")
    if tuple(body_map.joint_names) != tuple(skeleton.topology.names):
        raise UserError("lock_feet: `body_map` was made for another skeleton")
    P = len(body_map.left.foot_points)
    if len(body_map.right.foot_points) != P:
        raise UserError("lock_feet: both feet must have the same number of points")
    if root_position is None:
        if frame_time_s is None:
            raise UserError("lock_feet: pass `root_position` (or `frame_time_s` to integrate the root channels)")
        root_position = integrate_root(features, frame_time_s, body_map.up_axis)
    root_position = jnp.asarray(root_position, features.dtype)
    if root_position.shape != (T, 3):
        raise UserError(f"lock_feet: `root_position` must be [T={T}, 3], got {root_position.shape}")
    clearance = jnp.zeros((2, P), features.dtype) if clearance is None else jnp.asarray(clearance, features.dtype)
    if clearance.shape != (2, P):
        raise UserError(f"lock_feet: `clearance` must be [2, {P}], got {clearance.shape}")
    legs = _leg_columns(skeleton, representation, body_map)
    knee_step, knee_window = None, 0
    if knee_speed_rad_s is not None:
        if frame_time_s is None:
            raise UserError("lock_feet: `knee_speed_rad_s` needs `frame_time_s` (seconds per frame)")
        knee_speed = jnp.asarray(knee_speed_rad_s, features.dtype)
        if knee_speed.shape not in ((), (2,), (T, 2)):
            raise UserError(f"lock_feet: `knee_speed_rad_s` must be a scalar, [2] (left, right) or [T={T}, 2], "
                            f"got {knee_speed.shape}")
        knee_step = jnp.broadcast_to(knee_speed, (T, 2)) * float(frame_time_s)
        knee_window = max(1, int(round(KNEE_CAP_WINDOW_S / float(frame_time_s))))
    if contact_band is None:
        contact_band = CONTACT_HEIGHT_FRACTION * float(body_map.height)
    out, feet, _ = _lock(features, skeleton, contact, root_position, clearance,
                         jnp.asarray(ground, features.dtype),
                         jnp.asarray(contact_band, features.dtype),
                         representation=representation, body_map=body_map, legs=legs,
                         smooth_frames=integer(smooth_frames, "lock_feet: `smooth_frames`", 0),
                         knee_step=knee_step, knee_window=knee_window)
    return (out, feet) if return_feet else out


def integrate_root(features: Float[ArrayLike, "T C"], frame_time_s: float, up_axis: int = 1) -> Float[Array, "T 3"]:
    """World root path of feature frames: trapezoid integral of `root.vx, root.vz`, height `root.y`.

    Arguments:
        features: `[T, C]`; frame_time_s: seconds per frame; up_axis: index of the up axis.

    Returns:
        `[T, 3]` (starting at the origin in the ground plane).
    """
    x = jnp.asarray(features)
    dt = jnp.asarray(frame_time_s, x.dtype)
    horiz = [k for k in range(3) if k != up_axis]

    def integ(v):
        return jnp.concatenate([jnp.zeros((1,), v.dtype), jnp.cumsum(0.5 * (v[1:] + v[:-1]) * dt)])

    root = jnp.zeros((x.shape[0], 3), x.dtype)
    root = root.at[:, horiz[0]].set(integ(x[:, 0])).at[:, horiz[1]].set(integ(x[:, 1]))
    return root.at[:, up_axis].set(x[:, 2])
