"""Gait synthesis under the step constraints (Unuma 1995 §3.1), and the hip curves of a model."""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, ArrayLike, Float

from fourierjax._checks import concrete, integer
from fourierjax._gait.common import (
    check_finite,
    check_jump,
    check_positive,
    check_rule,
    pose_points,
    resolve_body,
)
from fourierjax._gait.footlock import lock_supersampling
from fourierjax._gait.hip import (
    HipRule,
    captured_floor,
    contact_height,
    cycle_lowest,
    hip_rule,
    hip_rule_curves,
    leg_heights,
    lowest_points,
)
from fourierjax._gait.metrics import estimate_sole_clearance
from fourierjax._gait.root import apply_step, root_trajectory
from fourierjax._jit import filter_jit
from fourierjax._saved import saved
from fourierjax.errors import UserError

if TYPE_CHECKING:
    from fourierjax._gait.path import GroundPath
    from fourierjax.body import BodyMap
    from fourierjax.contacts import FootPoints
    from fourierjax.fourier import FourierModel
    from fourierjax.skeleton import Skeleton


class GaitResult(eqx.Module):
    """A synthesized gait with step constraints (one character; vmap adds a leading axis).

    - `features`: `[T, C]` model channels per frame (`fourier` layout). With root motion the
      root channels are replaced: `root.y` by the hip-rule height, `root.vx, root.vz` by the
      velocity of `root_position` (central differences).
    - `phase`: `[T]` cycle phase of each frame (radians).
    - `root_position`: `[T, 3]` world root (pelvis) position, file units.
    - `foot_positions`: `[T, 2, P, 3]` world foot points (left, right).
    - `lowest`: `[T, 2]` height of each foot's lowest point above the floor (sole clearance
      taken off).
    - `hip`: the `HipRule` (L, N, lift, flight, l_max).
    - `clearance`: `[2, P]` the sole clearances used.
    - `floor`: the floor's height (file units, up axis): the model's captured floor
      (`captured_floor`), where the hip rule's lowest foot point stands; each foot point's
      floor is `floor + clearance`.
    """

    features: Array
    phase: Array
    root_position: Array
    foot_positions: Array
    lowest: Array
    hip: HipRule
    clearance: Array
    floor: Array


def _integrate_trapezoid(v, dt):
    return jnp.concatenate([jnp.zeros((1,), v.dtype), jnp.cumsum(0.5 * (v[1:] + v[:-1]) * dt)])


@saved
@filter_jit
def _synthesize_gait(model, skeleton, clearance, floor, step, speed, t_eff, gait, jump, phase0,
                     root_motion, frame_time_s, width, temperature, *,
                     num_frames, feet, groins, pelvis, rule, num_cycle_samples, up_axis,
                     check_traced=True):
    # Every number a caller may vary is an array (traced): filter_jit holds Python numbers
    # static, and each new frame time, width or temperature would compile again.
    from fourierjax.fourier import synthesize_phase

    stepped = apply_step(model, step)
    # t_eff (the integrated time, computed by the caller) makes speed = 1 bit-identical to
    # `synthesize(model, k dt)`.
    phase = stepped.omega * t_eff + phase0
    feats = synthesize_phase(stepped, phase)
    idx = jnp.asarray([feet.left, feet.right])
    rep = model.representation

    def points(f):
        return pose_points(skeleton, rep, idx, (*groins, pelvis), f, pelvis)

    # Lmax over one whole cycle of the (stepped) model, whatever the speed schedule; the sole
    # clearances (if not given) and the captured floor from a cycle of the unstepped model (the
    # foot's geometry and the floor must not change with the step length). One vmapped FK over
    # all poses: one FK graph to compile.
    K = num_cycle_samples
    grid = jnp.linspace(0.0, 2 * jnp.pi, K, endpoint=False, dtype=phase.dtype)
    own = synthesize_phase(model, grid)
    all_feet, all_joints = jax.vmap(points)(jnp.concatenate([feats, synthesize_phase(stepped, grid), own], axis=0))
    all_groins, pelvis_local = all_joints[:, :2], all_joints[:num_frames, 2]
    foot_local, groin_local = all_feet[:num_frames], all_groins[:num_frames]
    cyc_feet = all_feet[num_frames : num_frames + K]
    cyc_groins = all_groins[num_frames : num_frames + K]
    if clearance is None:
        clearance = estimate_sole_clearance(all_feet[num_frames + K :], up_axis=up_axis)
    if floor is None:
        floor = captured_floor(cycle_lowest(own[:, 2], all_feet[num_frames + K :], clearance, up_axis=up_axis))
    soft = temperature if rule == "smooth" else None
    cyc_leg = leg_heights(cyc_groins, cyc_feet, clearance, up_axis=up_axis, temperature=soft)
    leg = leg_heights(groin_local, foot_local, clearance, up_axis=up_axis, temperature=soft)
    # The frames themselves may reach past the grid's max: include them, so N >= 0.
    both = jnp.concatenate([cyc_leg, leg], axis=0)
    l_max = hip_rule(both, gait, jump, rule=rule, temperature=temperature, width=width,
                     check_traced=check_traced).l_max
    hip = hip_rule(leg, gait, jump, rule=rule, l_max=l_max, temperature=temperature,
                   width=width, check_traced=check_traced)
    horiz = [k for k in range(3) if k != up_axis]
    # Both roots are cheap next to FK: compute both and select, so `root_motion` is traced
    # (one compilation serves both).
    speed_t = jnp.broadcast_to(jnp.asarray(speed, feats.dtype), (num_frames,))
    height = contact_height(foot_local, clearance, up_axis=up_axis) + hip.lift  # over the floor
    # In flight the root moves with the model's own (captured) root velocity at this pace.
    v_model = feats[:, :2] * speed_t[:, None]
    flight_step = 0.5 * (v_model[1:] + v_model[:-1]) * frame_time_s
    root_on = root_trajectory(foot_local, height, phase, clearance, up_axis=up_axis,
                              flight_step=flight_step, pelvis_height=height + pelvis_local[:, up_axis])
    # The lowest foot point on the model's captured floor, not the file's height 0: Bandai-1's
    # synthesized walks stood 4 cm lower than their capture. (`root_trajectory` works over the
    # floor: its contacts are heights above it.)
    height = height + floor
    root_on = root_on.at[:, up_axis].set(height)
    vel = jnp.gradient(root_on, axis=0) / frame_time_s
    feats_on = feats.at[:, 0].set(vel[:, horiz[0]]).at[:, 1].set(vel[:, horiz[1]])
    feats_on = feats_on.at[:, 2].set(height)
    # Without root motion: the model's own root, velocities scaled with the pace.
    feats_off = feats.at[:, 0].multiply(speed_t).at[:, 1].multiply(speed_t)
    root_off = jnp.zeros((num_frames, 3), feats.dtype)
    root_off = root_off.at[:, horiz[0]].set(_integrate_trapezoid(feats_off[:, 0], frame_time_s))
    root_off = root_off.at[:, horiz[1]].set(_integrate_trapezoid(feats_off[:, 1], frame_time_s))
    root_off = root_off.at[:, up_axis].set(feats_off[:, 2])
    feats = jnp.where(root_motion, feats_on, feats_off)
    root = jnp.where(root_motion, root_on, root_off)
    foot_world = foot_local + root[:, None, None, :]  # explicit ranks: [T, 2, P, 3]
    lowest = lowest_points(foot_world, clearance, up_axis=up_axis) - floor
    return GaitResult(feats, phase, root, foot_world, lowest, hip, clearance, floor)


def synthesize_gait(
    model: FourierModel,
    skeleton: Skeleton,
    num_frames: int,
    frame_time_s: float,
    *,
    feet: FootPoints | None = None,
    groins: tuple[int, int] | None = None,
    body_map: BodyMap | None = None,
    clearance: Float[ArrayLike, "2 P"] | None = None,
    step: Float[ArrayLike, ""] = 1.0,
    speed: Float[ArrayLike, "*T"] = 1.0,
    gait: Float[ArrayLike, ""] = 1.0,
    jump: Float[ArrayLike, ""] = 0.0,
    rule: str = "unuma1995",
    root_motion: bool = True,
    phase0: Float[ArrayLike, ""] = 0.0,
    width: Float[ArrayLike, ""] = 0.01,
    temperature: Float[ArrayLike, ""] | None = None,
    num_cycle_samples: int = 64,
    up_axis: int | None = None,
    foot_lock: bool = True,
    contact_intervals: Float[ArrayLike, "2 2"] | None = None,
    path: GroundPath | None = None,
    path_smoothing: Float[ArrayLike, ""] | None = None,
    floor: Float[ArrayLike, ""] | None = None,
    knee_speed_rad_s: Float[ArrayLike, "*2"] | None = None,
) -> GaitResult:
    """Synthesize a gait under Unuma's step constraints (§3.1): step, speed, gait, jump.

    Joint angles come from the model at the integrated phase (`apply_step`,
    `integrate_phase`); with `root_motion` the root height is the hip-height rule's
    (`root_height`: the lowest foot point on the ground, plus the flight lift of eq. 5), the
    ground being the model's captured floor (`captured_floor`, as `grounded_transition`'s), and its
    horizontal path comes from the feet on the ground (`root_trajectory`; in flight, from the
    model's own root velocity at the current pace). Without it, the root
    follows the model's own `root.*` channels (velocities scaled by `speed`). `Lmax` is taken
    over one cycle of the stepped model (`num_cycle_samples` phases).

    With `step = 1`, `speed = 1`, `gait = 1`, `jump = 0` the joint channels equal
    `synthesize(model, k Δt)` exactly, the lift is 0, and without root motion every channel is
    unchanged.

    Arguments:
        model: a `FourierModel` on `motion.channel_names_for(topology, representation)`.
        skeleton: the `Skeleton` it animates.
        num_frames: number of output frames (≥ 2).
        frame_time_s: output frame spacing in seconds (a concrete number).
        feet: `contacts.FootPoints`; default the body map's feet.
        groins: `(left, right)` joint indices (`groin_joints`); default the body map's.
        body_map: a `body.BodyMap` of the skeleton (feet, groins, pelvis, up axis); default
            the map of the model's own cycle (`body.infer_body_map_from_positions`; a concrete
            model). `feet`, `groins` and `up_axis`, when given, win over it.
        clearance: `[2, P]` sole clearances (`contacts.sole_clearance` of the source clip);
            default `None` estimates them from one cycle of the model
            (`estimate_sole_clearance`).
        step: scalar amplitude scale (`apply_step`).
        speed: scalar or `[num_frames]` schedule (`integrate_phase`).
        gait, jump, rule, width, temperature: as `hip_rule` (`jump ≥ 0`).
        root_motion: root from the hip rule and the stance feet (True) or the model's own.
        phase0: phase of the first frame (radians).
        num_cycle_samples: phases of the cycle over which `Lmax` is taken.
        up_axis: index of the up axis; default the body map's (Y, 1, when `feet` and
            `groins` are given without a map).
        foot_lock: plant the feet (`lock_feet`, two-bone leg IK on the synthesized frames; on by
            default). `foot_lock=False` gives the frames of the step constraints alone. Under
            100 fps the lock runs on `lock_supersampling` times as many frames (4 at 30 fps),
            synthesized from the model, and every k-th is returned: the same motion
            locks alike at any frame rate. The lock also starts a whole contact before the first
            frame (a pre-roll of at least 1 s, dropped after it; with a `path`, walking up to its
            first point), so the first contact is planted like any other. The root then comes
            from the denser and longer frames too, re-anchored at the first frame (Bandai-1
            run_happy at 30 fps: 2.7 units from `foot_lock=False`'s over 5 s, 0.2% of the path;
            02_01 at 120 fps: 0.0044).
        contact_intervals: `[2, 2]` contact phases of the feet (`contact_intervals`: stored
            with the model by `fourierjax fit`); default estimated from the model's cycle
            (a concrete model; under vmap or grad pass them, and `body_map`).
        path: a `GroundPath` (file units) to walk along (`follow_path`, no sideways sway): the
            straight gait is bent onto it first and the feet are locked after, so they stay
            planted through the turns. The result's features, root and feet are the bent ones.
        path_smoothing: `follow_path`'s `smoothing` (file units: how far corners are rounded);
            default a quarter of the leg length (as `synth --path`).
        floor: the floor's height (file units, up axis) the hip rule stands the feet on; default
            the model's captured floor (`model_ground`). Pass the fitted model's `model_ground`
            (floor and clearance) for a model edited from it (`style.superpose`,
            `style.add_noise`): the default reads the floor under the model's own root height,
            which an edit moves off its legs.
        knee_speed_rad_s: the foot lock's cap on the knee's angular speed where the foot is
            free, `[2]` (left, right) or scalar, radians per second (`knee_speed_limit` of the
            captured clip, its largest knee speed), scaled per frame by `speed` and `|step|`;
            default None: no cap (`lock_feet`).

    Returns:
        A `GaitResult`. Jitted; differentiable in the model, `step`, `speed`, `gait`, `jump`
        and `clearance`; vmap over characters (models, parameters) at the call site.

    Raises `UserError` for a non-integer `num_frames` (or < 2), a `frame_time_s` that is not
    finite and > 0, `groins` or foot points out of the skeleton's range, and, when concrete
    (not traced), a non-finite `step`, `speed`, `gait`, `jump` or `phase0`, a `jump < 0`, or a
    `width` or `temperature` that is not finite and > 0 (traced `gait`, `jump`, `width` and
    `temperature` are checked by `eqx.error_if` in `hip_rule`).
    """
    where = "synthesize_gait"
    check_rule(rule)
    num_frames = integer(num_frames, f"{where}: `num_frames`", 2)
    num_cycle_samples = integer(num_cycle_samples, f"{where}: `num_cycle_samples`", 1)
    if isinstance(frame_time_s, jax.core.Tracer):
        raise UserError(
            f"{where}: `frame_time_s` sets the (static) frame spacing: pass a concrete number, not a traced value"
        )
    try:
        dt = float(frame_time_s)
    except TypeError:
        raise UserError(f"{where}: `frame_time_s` must be a number (seconds), got {frame_time_s!r}") from None
    if not (math.isfinite(dt) and dt > 0):
        raise UserError(f"{where}: `frame_time_s` must be finite and > 0 (seconds), got {frame_time_s}")
    feet, groins, pelvis, up_axis = resolve_body(where, model, skeleton, feet, groins, body_map, up_axis)
    if len(feet.left) != len(feet.right):
        raise UserError("synthesize_gait: both feet must have the same number of points")
    for name, value in (("step", step), ("speed", speed), ("gait", gait), ("phase0", phase0)):
        check_finite(where, name, value)
    check_jump(where, jump)
    check_positive(where, "width", width, "the sigmoid width of the smooth rule, in units of N")
    if temperature is not None:
        check_positive(where, "temperature", temperature, "the log-sum-exp temperature, file units")
    num_points = len(feet.left)
    # The model's float type as JAX holds it (a float64 NumPy model is float32 without x64).
    dtype = jnp.asarray(model.offset).dtype
    if clearance is not None:
        clearance = jnp.asarray(clearance, dtype=dtype)
    if clearance is not None and clearance.shape != (2, num_points):
        raise UserError(
            f"synthesize_gait: clearance must be [2, {num_points}], got {clearance.shape}"
        )
    speed = jnp.asarray(speed, dtype)
    if speed.ndim not in (0, 1) or (speed.ndim == 1 and speed.shape[0] != num_frames):
        raise UserError(
            f"synthesize_gait: speed must be a scalar or [num_frames={num_frames}], got shape "
            f"{speed.shape}"
        )
    # One shape for scalar and scheduled speeds: one compilation serves both.
    speed = jnp.broadcast_to(speed, (num_frames,))
    k = lock_supersampling(dt) if foot_lock else 1
    if foot_lock and contact_intervals is None and not isinstance(jnp.asarray(model.offset), jax.core.Tracer):
        from fourierjax._gait.common import model_body_map
        from fourierjax._gait.footlock import intervals_from_model

        body_map = model_body_map(model, skeleton) if body_map is None else body_map
        contact_intervals = intervals_from_model(model, skeleton, body_map=body_map)
    pre = _lock_preroll(model, contact_intervals, dt / k) if foot_lock else 0
    checked = dict(where=where, model=model, skeleton=skeleton, clearance=clearance, floor=floor, step=step, gait=gait,
                   jump=jump, root_motion=root_motion, width=width, temperature=temperature, feet=feet, groins=groins,
                   pelvis=pelvis, up_axis=up_axis, rule=rule, num_cycle_samples=num_cycle_samples, path=path,
                   path_smoothing=path_smoothing, body_map=body_map, foot_lock=foot_lock,
                   contact_intervals=contact_intervals, knee_speed_rad_s=knee_speed_rad_s, dtype=dtype)
    if k == 1 and pre == 0:
        return _synthesize_checked(num_frames=num_frames, dt=dt, speed=speed, phase0=phase0, path_start=0,
                                   **checked)
    # The feet are locked on denser frames under 100 fps (`lock_supersampling`: the phase at
    # frame k i of the dense frames is frame i's), and after `pre` frames of the cycle before
    # the first (`_lock_preroll`), dropped after the lock.
    fine = k * (num_frames - 1) + 1
    dense_speed = jnp.concatenate([jnp.broadcast_to(speed[:1], (pre,)), jnp.repeat(speed, k)[:fine]])
    omega = jnp.asarray(model.omega, dtype)
    dense = _synthesize_checked(num_frames=pre + fine, dt=dt / k, speed=dense_speed,
                                phase0=jnp.asarray(phase0, dtype) - omega * (pre * dt / k) * speed[0], path_start=pre,
                                **checked)
    return _every_kth_frame(dense, k, pre, int(up_axis))


def _synthesize_checked(*, where, model, skeleton, num_frames, dt, speed, phase0, clearance, floor, step, gait, jump,
                        root_motion, width, temperature, feet, groins, pelvis, up_axis, rule, num_cycle_samples, path,
                        path_smoothing, path_start, body_map, foot_lock, contact_intervals, knee_speed_rad_s, dtype):
    """`synthesize_gait` after its checks, on `num_frames` frames `dt` apart (`speed` `[num_frames]`);
    a path starts at frame `path_start` (after the lock's pre-roll)."""
    ticks = jnp.concatenate([jnp.zeros((1,), dtype), jnp.cumsum(speed)[:-1]])
    t_eff = ticks * dt
    if floor is not None:
        check_finite(where, "floor", floor)
        floor = jnp.asarray(floor, dtype)
        if floor.shape != ():
            raise UserError(f"{where}: `floor` must be a scalar (file units), got shape {floor.shape}")
    result = _synthesize_gait(
        model, skeleton, clearance, floor,
        jnp.asarray(step, dtype), speed, t_eff, jnp.asarray(gait, dtype),
        jnp.asarray(jump, dtype), jnp.asarray(phase0, dtype), jnp.asarray(root_motion, bool),
        jnp.asarray(dt, dtype), jnp.asarray(width, dtype),
        None if temperature is None else jnp.asarray(temperature, dtype),
        num_frames=num_frames, feet=feet, groins=groins, pelvis=pelvis, rule=rule,
        num_cycle_samples=num_cycle_samples, up_axis=int(up_axis),
        # Concrete values were checked above: no traced checks (their host callbacks would keep
        # the program out of the persistent compile cache). A caller's own jit, vmap or grad
        # leaves them traced, and `hip_rule` checks them with `eqx.error_if`.
        check_traced=any(isinstance(v, jax.core.Tracer) for v in (gait, jump, width, temperature)),
    )
    if path is not None:
        body_map = _path_body_map(where, model, skeleton, body_map)
        result = _bend(result, model, path, path_smoothing, dt, body_map, path_start)
        if not foot_lock:
            return _world_feet(result, skeleton, body_map=body_map, representation=model.representation)
    if not foot_lock:
        return result
    if knee_speed_rad_s is not None:
        knee_speed_rad_s = jnp.asarray(knee_speed_rad_s, dtype)
        if knee_speed_rad_s.shape not in ((), (2,)):
            raise UserError(f"{where}: `knee_speed_rad_s` must be a scalar or [2] (left, right), got "
                            f"{knee_speed_rad_s.shape}")
        # The knee turns faster by the speed schedule and by the step's amplitude scale.
        knee_speed_rad_s = (jnp.broadcast_to(knee_speed_rad_s, (2,))[None, :]
                            * (speed * jnp.abs(jnp.asarray(step, dtype)))[:, None])
    return _foot_lock(where, result, model, skeleton, body_map, contact_intervals, dt, knee_speed_rad_s)


def _lock_preroll(model, contact_intervals, dt) -> int:
    """Frames (static) of the cycle that `synthesize_gait` synthesizes and locks before the first
    frame, then drops: the longest contact of the two feet at speed 1 (`contact_intervals`),
    plus `PREROLL_MARGIN_S`, so that the first frame's contact is whole. A contact cut by the
    first frame was planted at the middle of its visible part and let go at toe-off: on a rig with
    rotated joint frames (`tests.rigs.rest_rotated`) the Euler fit of 02_01 stepped its knee 5.31 deg
    at the first toe-off, frame 26, against the capture's 3.49 (3.18 at most elsewhere; 3.18 with 30
    frames of this). At least `PREROLL_S` (1 s), in steps of half that, so that most models
    share one dense frame count (one compiled program); `PREROLL_S` when the model or the intervals
    are traced."""
    from fourierjax._gait.footlock import PREROLL_MARGIN_S, PREROLL_S

    omega, iv = model.omega, contact_intervals
    if isinstance(jnp.asarray(omega), jax.core.Tracer) or iv is None or isinstance(jnp.asarray(iv), jax.core.Tracer):
        return int(math.ceil(PREROLL_S / dt))
    try:
        omega, iv = float(jnp.asarray(omega)), jnp.asarray(iv, jnp.float32)
    except (TypeError, ValueError):
        return 0  # `_foot_lock` names a bad `contact_intervals`
    if iv.shape != (2, 2):
        return 0
    stance = float(jnp.max(jnp.mod(iv[:, 1] - iv[:, 0], 2 * math.pi)))
    if not (math.isfinite(omega) and omega > 0 and math.isfinite(stance)):
        return 0
    # In steps of `PREROLL_S / 2`, at least `PREROLL_S`: the dense frame count is static, and one
    # per model would compile a program per model.
    half = 0.5 * PREROLL_S
    seconds = max(PREROLL_S, half * math.ceil((stance / omega + PREROLL_MARGIN_S) / half))
    return int(math.ceil(seconds / dt))


def _every_kth_frame(result: GaitResult, k: int, pre: int = 0, up_axis: int = 1) -> GaitResult:
    """`result` with its per-frame arrays at every `k`-th frame from frame `pre`; after a pre-roll
    (`pre > 0`; on a path, the frame at its first point) the root's horizontal components (and
    the feet with them) are shifted to start at 0 there, as without one."""
    hip = result.hip._replace(L=result.hip.L[pre::k], N=result.hip.N[pre::k], lift=result.hip.lift[pre::k],
                              flight=result.hip.flight[pre::k])
    shift = result.root_position[pre].at[up_axis].set(0.0) * (1.0 if pre > 0 else 0.0)
    return eqx.tree_at(lambda r: (r.features, r.phase, r.root_position, r.foot_positions, r.lowest, r.hip), result,
                       (result.features[pre::k], result.phase[pre::k], result.root_position[pre::k] - shift[None],
                        result.foot_positions[pre::k] - shift[None, None, None], result.lowest[pre::k], hip))


def _path_body_map(where, model, skeleton, body_map):
    from fourierjax._gait.common import model_body_map

    if body_map is not None:
        return body_map
    if isinstance(jnp.asarray(model.offset), jax.core.Tracer):
        raise UserError(f"{where}: a path under jit, vmap or grad needs `body_map=`")
    return model_body_map(model, skeleton)


def _bend(result, model, path, smoothing, frame_time_s, body_map, start=0):
    """The unlocked straight result bent onto `path` from frame `start` (features and root; feet
    are recomputed)."""
    from fourierjax._gait.path import GroundPath, follow_path

    if not isinstance(path, GroundPath):
        raise UserError(f"synthesize_gait: `path` must be a gait.GroundPath, got {type(path).__name__}")
    if smoothing is None:
        smoothing = 0.25 * float(body_map.leg_length)
    feats, root, _ = follow_path(result.features, result.root_position, path, model.channel_names,
                                 body_map.name(body_map.pelvis), frame_time_s, up_axis=int(body_map.up_axis),
                                 smoothing=smoothing, start_frame=int(start))
    return eqx.tree_at(lambda r: (r.features, r.root_position), result, (feats, root))


@filter_jit
def _world_feet(result, skeleton, *, body_map, representation):
    idx = jnp.asarray([body_map.left.foot_points, body_map.right.foot_points])
    foot_local, _ = jax.vmap(lambda f: pose_points(skeleton, representation, idx, (body_map.pelvis,), f,
                                                   body_map.pelvis))(result.features)
    feet = foot_local + result.root_position[:, None, None, :]
    lowest = lowest_points(feet, result.clearance, up_axis=int(body_map.up_axis)) - result.floor
    return eqx.tree_at(lambda r: (r.foot_positions, r.lowest), result, (feet, lowest))


def _foot_lock(where, result, model, skeleton, body_map, contact_intervals, frame_time_s, knee_speed_rad_s=None):
    from fourierjax._gait.common import model_body_map
    from fourierjax._gait.footlock import SMOOTH_S, intervals_from_model

    traced = isinstance(jnp.asarray(model.offset), jax.core.Tracer)
    if body_map is None:
        if traced:
            raise UserError(f"{where}: foot locking under jit, vmap or grad needs `body_map=` (or foot_lock=False)")
        body_map = model_body_map(model, skeleton)
    if contact_intervals is None:
        if traced:
            raise UserError(f"{where}: foot locking under jit, vmap or grad needs `contact_intervals=` "
                            "(gait.contact_intervals of the concrete model), or foot_lock=False")
        contact_intervals = intervals_from_model(model, skeleton, body_map=body_map)
    iv = jnp.asarray(contact_intervals, result.features.dtype)
    if iv.shape != (2, 2):
        raise UserError(f"{where}: `contact_intervals` must be [2, 2] (foot, start/end), got {iv.shape}")
    return _locked_result(result, skeleton, iv, knee_speed_rad_s, body_map=body_map,
                          representation=model.representation,
                          smooth_frames=int(round(SMOOTH_S / frame_time_s)),
                          # static: only the knee cap reads it, so without one every rate shares a program
                          frame_time_s=None if knee_speed_rad_s is None else float(frame_time_s))


@saved
@filter_jit
def _locked_result(result, skeleton, intervals, knee_speed_rad_s, *, body_map, representation, smooth_frames,
                   frame_time_s):
    from fourierjax._gait.footlock import contact_weights, lock_feet

    weights = contact_weights(result.phase, intervals)  # in the program: 15 eager ones outside
    feats, feet = lock_feet(result.features, skeleton, weights, body_map=body_map, representation=representation,
                            root_position=result.root_position, clearance=result.clearance, ground=result.floor,
                            return_feet=True, smooth_frames=smooth_frames, knee_speed_rad_s=knee_speed_rad_s,
                            frame_time_s=frame_time_s)
    lowest = lowest_points(feet, result.clearance, up_axis=int(body_map.up_axis)) - result.floor
    return eqx.tree_at(lambda r: (r.features, r.foot_positions, r.lowest), result, (feats, feet, lowest))


@saved
@filter_jit
def _model_ground(model, skeleton, *, feet, pelvis, num_cycle_samples, up_axis):
    from fourierjax.fourier import synthesize_phase

    idx = jnp.asarray([feet.left, feet.right])
    grid = jnp.linspace(0.0, 2 * jnp.pi, num_cycle_samples, endpoint=False, dtype=jnp.asarray(model.offset).dtype)
    own = synthesize_phase(model, grid)
    foot_local, _ = jax.vmap(lambda f: pose_points(skeleton, model.representation, idx, (pelvis,), f, pelvis))(own)
    clearance = estimate_sole_clearance(foot_local, up_axis=up_axis)
    return captured_floor(cycle_lowest(own[:, 2], foot_local, clearance, up_axis=up_axis)), clearance


def model_ground(
    model: FourierModel,
    skeleton: Skeleton,
    *,
    body_map: BodyMap | None = None,
    num_cycle_samples: int = 64,
) -> tuple[Float[Array, ""], Float[Array, "2 P"]]:
    """The ground a fitted model was captured on: its floor (`captured_floor` of its own cycle)
    and its feet's sole clearances (`estimate_sole_clearance`), the ones `synthesize_gait` uses
    by default.

    Pass a fitted model's ground as `synthesize_gait(floor=, clearance=)` when synthesizing a
    model edited from it (`style.superpose`, `style.add_noise`): both are read from the model's
    own cycle, the floor under its own root height (its `root.y` channel), and an edit moves
    that height off its legs and the stance off the foot's geometry. CMU 02_01 plus half of the
    02_03-minus-02_01 characteristic read its floor 0.79 units (4.5 cm) under the walk's and its
    ankle's clearance 1.54 units against 0.84: its feet went 1.9 cm under the capture's floor;
    on the walk's ground they stand 2.6 cm over it, as the walk's own synthesis does.

    Arguments:
        model: a fitted `FourierModel` (its `root.y` channel the capture's).
        skeleton: the `Skeleton` it animates.
        body_map: a `body.BodyMap` of the skeleton; default the map of the model's own cycle.
        num_cycle_samples: phases of the cycle (as `synthesize_gait`'s).

    Returns:
        `(floor, clearance)`: the floor's height (file units, up axis) and `[2, P]` clearances
        (file units). Jitted; differentiable in the model.
    """
    num_cycle_samples = integer(num_cycle_samples, "model_ground: `num_cycle_samples`", 1)
    feet, _, pelvis, up_axis = resolve_body("model_ground", model, skeleton, None, None, body_map, None)
    return _model_ground(model, skeleton, feet=feet, pelvis=pelvis, num_cycle_samples=num_cycle_samples,
                        up_axis=int(up_axis))


@filter_jit
def _cycle_points(model, skeleton, feet, groins, num_samples, pelvis=0):
    from fourierjax.fourier import synthesize_phase

    idx = jnp.asarray([feet.left, feet.right])
    grid = jnp.linspace(0.0, 2 * jnp.pi, num_samples, endpoint=False,
                        dtype=jnp.asarray(model.offset).dtype)
    foot_local, groin_local = jax.vmap(
        lambda f: pose_points(skeleton, model.representation, idx, groins, f, pelvis)
    )(synthesize_phase(model, grid))
    return grid, foot_local, groin_local


def model_hip_curves(
    model: FourierModel,
    skeleton: Skeleton,
    *,
    feet: FootPoints | None = None,
    groins: tuple[int, int] | None = None,
    body_map: BodyMap | None = None,
    gait: Float[ArrayLike, ""] = 1.0,
    jump: Float[ArrayLike, ""] = 0.0,
    clearance: Float[ArrayLike, "2 P"] | None = None,
    num_samples: int = 128,
    width: Float[ArrayLike, ""] = 0.01,
    temperature: Float[ArrayLike, ""] | None = None,
    up_axis: int | None = None,
) -> dict[str, Float[Array, " K"]]:
    """The three hip rules over one cycle of a model: the data of a side-by-side plot.

    Arguments:
        model, skeleton, feet, groins, body_map, clearance, up_axis: as `synthesize_gait`.
        gait, jump, width, temperature: as `hip_rule` (default a walk: 1, 0).
        num_samples: K, phases per cycle.

    Returns:
        `dict`: `"phase"` `[K]` (radians), `"L_L"`, `"L_R"`, and the `hip_rule_curves`
        entries (`"L"`, `"N"`, `"unuma1995"`, `"continuous"`, `"smooth"`).
    """
    feet, groins, pelvis, up_axis = resolve_body("model_hip_curves", model, skeleton, feet, groins, body_map,
                                                 up_axis)
    num_samples = integer(num_samples, "model_hip_curves: `num_samples`", 1)
    grid, foot_local, groin_local = _cycle_points(model, skeleton, feet, groins, num_samples, pelvis)
    if clearance is None:
        clearance = estimate_sole_clearance(foot_local, up_axis=up_axis)
    leg = leg_heights(groin_local, foot_local, jnp.asarray(clearance), up_axis=up_axis)
    out = hip_rule_curves(leg, gait, jump, width=width, temperature=temperature)
    out.update(phase=grid, L_L=leg[:, 0], L_R=leg[:, 1])
    return out


@saved
@filter_jit
def _ground(features, skeleton, clearance, frame_time_s, *, representation, feet, groins, pelvis, up_axis,
            stance=None):
    idx = jnp.asarray([feet.left, feet.right])
    foot_local, joints = jax.vmap(
        lambda f: pose_points(skeleton, representation, idx, (*groins, pelvis), f, pelvis))(features)
    if clearance is None:
        clearance = estimate_sole_clearance(foot_local, up_axis=up_axis)
    height = contact_height(foot_local, clearance, up_axis=up_axis)
    horiz = [k for k in range(3) if k != up_axis]
    flight_step = 0.5 * (features[1:, :2] + features[:-1, :2]) * frame_time_s
    phase = jnp.zeros(features.shape[:1], features.dtype)  # unused with a flight step
    root = root_trajectory(foot_local, height, phase, clearance, up_axis=up_axis, flight_step=flight_step,
                           pelvis_height=height + joints[:, 2, up_axis], stance=stance)
    vel = jnp.gradient(root, axis=0) / frame_time_s
    out = features.at[:, 0].set(vel[:, horiz[0]]).at[:, 1].set(vel[:, horiz[1]]).at[:, 2].set(height)
    return out, root, foot_local + root[:, None, None, :], clearance


def ground_features(
    features: Float[ArrayLike, "T C"],
    skeleton: Skeleton,
    representation: str,
    frame_time_s: float,
    *,
    feet: FootPoints | None = None,
    groins: tuple[int, int] | None = None,
    body_map: BodyMap | None = None,
    clearance: Float[ArrayLike, "2 P"] | None = None,
    up_axis: int | None = None,
    stance: Float[ArrayLike, " T"] | None = None,
) -> tuple[Float[Array, "T C"], Float[Array, "T 3"], Float[Array, "T 2 P 3"], Float[Array, "2 P"]]:
    """Root motion from the stance feet for any gait features (a style interpolation, a transition).

    The walk rule of `synthesize_gait` (gait = 1, jump = 0) on given frames: the root height
    puts the lowest foot point on the ground and its path follows the foot carrying the body
    (`root_trajectory`; in flight, the features' own root velocity). For models whose root
    channels carry no travel (a rig whose trajectory joint is not joint 0).

    Arguments:
        features: `[T, C]` feature frames (`T ≥ 2`; `fourier` layout) on `skeleton`.
        skeleton: the `Skeleton`; representation: the features' ("euler" or "expmap").
        frame_time_s: seconds per frame.
        feet, groins, body_map, clearance, up_axis: as `synthesize_gait`; without `feet` or
            `groins` a `body_map` is required (the map of a model's cycle: `model_body_map`).
        stance: optional `[T]` weights in [0, 1] of frames known to stand on a foot (from
            contact intervals): there the stance feet carry the root even where the features'
            own root velocity disagrees with their stride (`root_trajectory`).

    Returns:
        `(features [T, C]` with `root.vx, root.vz, root.y` replaced, `root_position [T, 3]`,
        `foot_positions [T, 2, P, 3]` world, `clearance [2, P])`.
    """
    where = "ground_features"
    features = jnp.asarray(features)
    if features.ndim != 2 or features.shape[0] < 2:
        raise UserError(f"{where}: `features` must be [T >= 2, C], got shape {features.shape}")
    if body_map is None and (feet is None or groins is None):
        raise UserError(f"{where}: pass `body_map=` (or both `feet=` and `groins=`)")
    feet, groins, pelvis, up_axis = resolve_body(where, None, skeleton, feet, groins, body_map, up_axis)
    check_positive(where, "frame_time_s", frame_time_s, "seconds per frame")
    if clearance is not None:
        clearance = jnp.asarray(clearance, features.dtype)
    if stance is not None:
        if jnp.shape(stance) != features.shape[:1]:
            raise UserError(f"{where}: `stance` must be [T] = [{features.shape[0]}] weights in [0, 1], one a "
                            f"frame, got shape {jnp.shape(stance)}")
        w = concrete(stance)
        bad = None if w is None else ~((w >= 0) & (w <= 1))  # NaN is bad too
        if bad is not None and bad.any():
            raise UserError(f"{where}: `stance` must be weights in [0, 1] (finite), got {int(bad.sum())} "
                            f"outside, e.g. {w[bad][0]!r} at frame {int(np.flatnonzero(bad)[0])}")
    return _ground(features, skeleton, clearance, jnp.asarray(frame_time_s, features.dtype),
                   representation=representation, feet=feet, groins=groins, pelvis=pelvis, up_axis=up_axis,
                   stance=None if stance is None else jnp.asarray(stance, features.dtype))
