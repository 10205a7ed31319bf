"""Gait transitions over time: ease curves, the integrated-phase schedule and the transition itself."""

from __future__ import annotations

import functools

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, ArrayLike, Float

from fourierjax._checks import concrete
from fourierjax._fourier import _tangent
from fourierjax._jit import filter_jit
from fourierjax._saved import saved
from fourierjax._style._common import (
    EASES,
    METHODS,
    Ease,
    Method,
    OmegaMode,
    check_choice,
    check_compatible,
    check_models_omega,
    check_omega,
    check_scalar,
    dtype_of,
    evaluate,
    omega_at,
    omega_mode_argument,
    on_branch_of,
)
from fourierjax._style.characteristics import common_harmonics
from fourierjax._style.interpolation import interpolate_core
from fourierjax.errors import UserError
from fourierjax.fourier import FourierModel
from fourierjax.rotations import quat_slerp

# Gauss-Legendre nodes on [-1, 1] for the phase integral over the transition window; the
# integrand ω(s(u)) is smooth there, so 16 nodes are exact to rounding in float64.
_GL_NODES, _GL_WEIGHTS = (np.asarray(x, dtype=np.float64) for x in np.polynomial.legendre.leggauss(16))


def ease(u: ArrayLike, kind: Ease = "smoothstep") -> Array:
    """An ease curve from 0 to 1, clamped outside [0, 1].

    Arguments:
        u: normalised time (any shape).
        kind: `"smoothstep"` (3u² − 2u³, zero slope at both ends, default), `"smootherstep"`
            (6u⁵ − 15u⁴ + 10u³, zero slope and curvature) or `"linear"`.

    Returns:
        s(u), same shape.
    """
    check_choice(kind, EASES, "kind", "ease")
    u = jnp.clip(jnp.asarray(u), 0.0, 1.0)
    if kind == "linear":
        return u
    if kind == "smoothstep":
        return u * u * (3 - 2 * u)
    return u * u * u * (u * (6 * u - 15) + 10)


def _schedule_one(t, omega_a, omega_b, start, duration, ease_kind, omega_mode):
    # s(t) and the integrated cycle phase θ(t) = ∫_0^t ω(s(τ)) dτ at one time t: F(t) − F(0)
    # for the antiderivative F below (F(0) = 0 unless the window starts before t = 0, where
    # F alone gave θ(0) = 0.30 rad for a window from −0.5 s).
    s, f_t = _phase_antiderivative(t, omega_a, omega_b, start, duration, ease_kind, omega_mode)
    _, f_0 = _phase_antiderivative(jnp.zeros_like(t), omega_a, omega_b, start, duration, ease_kind, omega_mode)
    return s, f_t - f_0


def _phase_antiderivative(t, omega_a, omega_b, start, duration, ease_kind, omega_mode):
    u_end = jnp.clip((t - start) / duration, 0.0, 1.0)
    s = ease(u_end, ease_kind)
    nodes = jnp.asarray(_GL_NODES, dtype=u_end.dtype)
    weights = jnp.asarray(_GL_WEIGHTS, dtype=u_end.dtype)
    u = 0.5 * u_end * (nodes + 1)
    window = duration * 0.5 * u_end * jnp.sum(weights * omega_at(omega_a, omega_b, ease(u, ease_kind), omega_mode))
    before = omega_a * jnp.minimum(t, start)
    after = omega_b * jnp.maximum(t - (start + duration), 0.0)
    return s, before + window + after


def _schedule_all(t_s, omega_a, omega_b, start, duration, ease_kind, omega_mode):
    """`_schedule_one` at every time of `t_s` `[T]`."""
    return jax.vmap(_schedule_one, in_axes=(0, None, None, None, None, None, None))(
        t_s, omega_a, omega_b, start, duration, ease_kind, omega_mode
    )


@filter_jit
def _schedule(t_s, omega_a, omega_b, start, duration, ease_kind: str, omega_mode: str):
    return _schedule_all(t_s, omega_a, omega_b, start, duration, ease_kind, omega_mode)


def _check_window(where: str, t_s, start_s, duration_s):
    """`(start_s, duration_s)` checked: shapes always; values (finite, duration > 0) concrete or
    traced: a zero duration divides by zero in the schedule and gives NaN frames."""
    if jnp.ndim(t_s) != 1:
        raise UserError(
            f"{where}: `t_s` must be [T] sample times in seconds, got shape {jnp.shape(t_s)}; "
            "flatten a grid of times (t_s.ravel()) and reshape the result"
        )
    start_s = check_scalar(where, "start_s", start_s)
    if jnp.ndim(duration_s) != 0:
        raise UserError(f"{where}: `duration_s` must be a scalar, got shape {jnp.shape(duration_s)}")
    d = concrete(duration_s)
    if d is None:
        duration_s = eqx.error_if(
            duration_s,
            ~(jnp.isfinite(duration_s) & (duration_s > 0)),
            f"{where}: `duration_s` must be finite and > 0; a transition needs a finite positive duration (seconds)",
        )
    elif not (np.isfinite(d) and d > 0):
        raise UserError(
            f"{where}: `duration_s`={d.item()!r}; a transition needs a finite positive duration (seconds)"
        )
    return start_s, duration_s


def transition_schedule(
    omega_a: ArrayLike,
    omega_b: ArrayLike,
    t_s: Float[ArrayLike, " frames"],
    start_s: ArrayLike,
    duration_s: ArrayLike,
    *,
    ease: Ease = "smoothstep",
    omega_mode: OmegaMode = "geometric",
    omega: OmegaMode | None = None,
) -> tuple[Float[Array, " frames"], Float[Array, " frames"]]:
    """The blend weight s(t) and the integrated cycle phase θ(t) of a transition.

    `s(t) = ease((t − start)/duration)`, 0 before the window and 1 after it. The phase is the
    integral of the instantaneous frequency, `θ(t) = ∫_0^t ω(s(τ)) dτ` (exact before and after
    the window, 16-point Gauss–Legendre inside it), so it is continuous and monotone however
    fast ω changes; the naive `ω(s(t))·t` instead jumps by `Δω·t` and plays the cycle at the
    wrong speed during the window.

    Arguments:
        omega_a: rad/s of the start gait.
        omega_b: rad/s of the end gait.
        t_s: `[T]` times in seconds (any order, θ(0) = 0).
        start_s: start of the window in seconds.
        duration_s: length of the window in seconds (> 0).
        ease: see `ease`.
        omega_mode: see `interpolate_omega`.
        omega: deprecated alias of `omega_mode`.

    Returns:
        `(s [T], theta [T])`, theta in radians. Raises `UserError` for a `t_s` that is not 1-D
        or a non-scalar window, and for `duration_s ≤ 0`, non-finite window values or an ω that
        is not > 0 (under jit, from `eqx.error_if`).
    """
    check_choice(ease, EASES, "ease", "transition_schedule")
    omega_mode = omega_mode_argument("transition_schedule", omega_mode, omega)
    start_s, duration_s = _check_window("transition_schedule", t_s, start_s, duration_s)
    omega_a = check_omega("transition_schedule", "omega_a", omega_a)
    omega_b = check_omega("transition_schedule", "omega_b", omega_b)
    t_s = jnp.asarray(t_s)
    dtype = jnp.result_type(t_s.dtype, jnp.asarray(omega_a).dtype, float)
    f = functools.partial(jnp.asarray, dtype=dtype)
    return _schedule(f(t_s), f(omega_a), f(omega_b), f(start_s), f(duration_s), ease, omega_mode)


@saved
@filter_jit
def _transition(a, b, t_s, start, duration, ease_kind: str, method: str, omega_mode: str):
    b = on_branch_of(a, b)
    s, theta = _schedule_all(t_s, a.omega, b.omega, start, duration, ease_kind, omega_mode)

    def frame(s_i, theta_i):
        m = interpolate_core(a, b, s_i, method, omega_mode)
        return evaluate(m.offset, m.amplitude, m.phase, theta_i)

    x = jax.vmap(frame)(s, theta)
    if a.representation == "tangent":
        # The tangent coordinates blend as above; each frame's clip means are slerped by its s.
        frames = jax.vmap(lambda s_i: quat_slerp(a.frames, b.frames, s_i))(s)
        x = _tangent.features_at(x, frames, _tangent.model_columns(a))
    return x, s, theta


def transition(
    a: FourierModel,
    b: FourierModel,
    t_s: Float[ArrayLike, " frames"],
    start_s: ArrayLike,
    duration_s: ArrayLike,
    *,
    ease: Ease = "smoothstep",
    method: Method = "polar",
    omega_mode: OmegaMode = "geometric",
    omega: OmegaMode | None = None,
    return_schedule: bool = False,
):
    """A gait transition from `a` to `b` over a time window (Unuma §2.3, walk → run).

    Frame `t` plays `Ξ(s(t), θ(t))`: the interpolated model (`interpolate`) at blend weight
    `s(t)` evaluated at the integrated cycle phase `θ(t) = ∫ ω(s(τ)) dτ` (see
    `transition_schedule`). Because the phase is integrated, the cycle never jumps when ω
    changes, so a run → walk transition is as smooth as walk → run (Unuma found his
    run → walk unnatural): the cadence decelerates continuously, the eased s(t) has zero slope at
    both ends of the window, and every channel, root velocity channels included, changes
    continuously (C¹ in time with `"smoothstep"`). b is played on a's angle branch (see
    `interpolate`), so an Euler thigh at +179° going to −179° turns by 2°, not 358°. Choose
    `start_s` at a gait event (θ a multiple of 2π) to begin the change at a foot strike.

    Tangent models (`representation="tangent"`): the tangent coordinates blend as above (no
    branch) and each frame's joint clip means are slerped by the same `s(t)` (a's frames before
    the window, b's after it); the values are expmap features, as `fourier.synthesize` returns.
    A change of rig maps every frame's rotations as it maps the models', so the transition of
    two rewritten models is the rewritten transition (exactly with `method="phasor"`; polar
    mixes each joint's three channels' phases differently in each frame).

    Arguments:
        a: FourierModel of the start gait.
        b: compatible FourierModel of the end gait, aligned to the same gait event.
        t_s: `[T]` sample times in seconds (θ(0) = 0).
        start_s: start of the transition window in seconds.
        duration_s: its length in seconds (> 0).
        ease: see `ease`.
        method: see `interpolate`.
        omega_mode: see `interpolate_omega`.
        omega: deprecated alias of `omega_mode`.
        return_schedule: also return `(s [T], theta [T])`.

    Returns:
        `[T, C]` channel values (model units), or `(values, s, theta)`. Raises `UserError` as
        `transition_schedule` does (and for a model whose ω is not > 0).
    """
    check_compatible(a, b)
    check_choice(ease, EASES, "ease", "transition")
    check_choice(method, METHODS, "method", "transition")
    omega_mode = omega_mode_argument("transition", omega_mode, omega)
    start_s, duration_s = _check_window("transition", t_s, start_s, duration_s)
    a, b = check_models_omega("transition", a=a, b=b)
    a, b = common_harmonics(a, b)
    dtype = dtype_of(a)
    values, s, theta = _transition(
        a,
        b,
        jnp.asarray(t_s, dtype=dtype),
        jnp.asarray(start_s, dtype=dtype),
        jnp.asarray(duration_s, dtype=dtype),
        ease,
        method,
        omega_mode,
    )
    return (values, s, theta) if return_schedule else values


# ------------------------------------------------------------------------- grounded transition

#: Phases of the cycle grid of a model's floor and own flight lift.
_FLIGHT_GRID = 64
#: In stance the blend's own height may lift the lowest foot point this many contact bands.
_STANCE_LIFT_BANDS = 0.5
#: Inside the blend the stance feet (by the contact intervals) carry the root with weight
#: `min(1, _BLEND_CARRY s (1 - s))`: fully for 0.15 <= s <= 0.85, fading to the two models' own
#: rule (`gait.ground_features`'s slip test) at the window's ends.
_BLEND_CARRY = 8.0


class GroundedTransition(eqx.Module):
    """A transition with the hip rule and root motion (one character).

    - `features`: `[T, C]` channels; `root.vx, root.vz, root.y` from the grounding.
    - `root_position`: `[T, 3]` world pelvis position, file units.
    - `foot_positions`: `[T, 2, P, 3]` world foot points (left, right).
    - `lowest`: `[T, 2]` height of each foot's lowest point above the floor (clearance off).
    - `s`, `theta`: `[T]` blend weight and integrated phase (`transition_schedule`).
    - `clearance`: `[2, P]` sole clearances.
    - `floor`: the floor's height (file units, up axis; a's captured floor): each foot point's
      floor is `floor + clearance` (`gait.contact_flight_fraction(foot_positions, floor=...)`).
    """

    features: Array
    root_position: Array
    foot_positions: Array
    lowest: Array
    s: Array
    theta: Array
    clearance: Array
    floor: Array


def _captured_floor(model, skeleton, representation, frame_time_s, bmap, clearance, intervals):
    """The floor under a model's own root height (`gait`'s one floor rule, `captured_floor`, as
    `synthesize_gait` stands on), and the model's own flight lift `[K]` on that cycle's
    phase grid (`_FLIGHT_GRID` phases from 0): its lowest point's height over the straight line
    joining that height at take-off and at landing, where no foot is in contact
    (`gait.contact_weights` < 1 for both), 0 in contact. A periodic fit drifts in stance (02_03,
    N = 5: the lowest point rises 0.67 units through the left foot's stance, 0.31 through the
    right's, against 0.5 for the contact band): the height over the floor would count that as
    flight, the height over the take-off line does not."""
    from fourierjax import gait
    from fourierjax._gait.hip import captured_floor, cycle_lowest
    from fourierjax.fourier import synthesize_phase

    K = _FLIGHT_GRID
    grid = jnp.linspace(0.0, 2 * jnp.pi, K, endpoint=False, dtype=dtype_of(model))
    x = synthesize_phase(model, grid)
    _, root, feet, _ = gait.ground_features(x, skeleton, representation, frame_time_s, body_map=bmap,
                                            clearance=clearance)
    own = cycle_lowest(x[:, 2], feet - root[:, None, None, :], clearance, up_axis=bmap.up_axis)
    floor = captured_floor(own)
    contact = jnp.tile(jnp.max(gait.contact_weights(grid, intervals), axis=-1) >= 1.0, 3)
    idx = jnp.arange(3 * K)
    prev = jax.lax.cummax(jnp.where(contact, idx, -1))[K : 2 * K]
    nxt = jax.lax.cummin(jnp.where(contact, idx, 3 * K), reverse=True)[K : 2 * K]
    h = jnp.tile(own, 3)
    ok = (prev >= 0) & (nxt < 3 * K)  # no contact at all: the height over the floor
    p, n = jnp.clip(prev, 0, 3 * K - 1), jnp.clip(nxt, 0, 3 * K - 1)
    u = (idx[K : 2 * K] - p) / jnp.maximum(n - p, 1)
    base = jnp.where(ok, h[p] + u * (h[n] - h[p]), floor)
    return floor, jnp.maximum(own - base, 0.0)


def _flight_lift(lift_grid, theta):
    """`[T]` a model's own flight lift (`_captured_floor`) at the integrated phase."""
    grid = jnp.linspace(0.0, 2 * jnp.pi, _FLIGHT_GRID, endpoint=False, dtype=lift_grid.dtype)
    return jnp.interp(jnp.mod(theta, 2 * jnp.pi), grid, lift_grid, period=2 * jnp.pi)


def grounded_transition(
    a: FourierModel,
    b: FourierModel,
    skeleton,
    num_frames: int,
    frame_time_s: float,
    start_s: ArrayLike,
    duration_s: ArrayLike,
    *,
    body_map=None,
    clearance: Float[ArrayLike, "2 P"] | None = None,
    ease: Ease = "smoothstep",
    method: Method = "polar",
    omega_mode: OmegaMode = "geometric",
    foot_lock: bool = True,
    contact_intervals: tuple[Float[ArrayLike, "2 2"], Float[ArrayLike, "2 2"]] | None = None,
    knee_speed_rad_s: tuple[Float[ArrayLike, "*2"], Float[ArrayLike, "*2"]] | None = None,
) -> GroundedTransition:
    """A walk ↔ run transition that stands on the floor: `transition`, grounded.

    The frames of `transition` (at `t = k Δt`) get their root from the stance feet
    (`gait.ground_features`: the planted foot point carries the body, in flight the blend's
    own root velocity does; inside the blend window, where that velocity and the stride come
    from two models and disagree, the feet in stance by the contact intervals carry it) and
    their height from the floor: the lowest foot point stands on a's captured floor
    (`_captured_floor`), lifted where both models' own cycles fly (no foot in contact by their
    contact intervals) by their own lowest point's height over its take-off-to-landing line,
    blended by s, so there is flight only where the run has it.

    Arguments:
        a, b: compatible models (start and end gait), aligned to the same gait event.
        skeleton: the `Skeleton` both animate.
        num_frames: T (≥ 2); frame_time_s: Δt in seconds.
        start_s, duration_s, ease, method, omega_mode: as `transition`.
        body_map: the `body.BodyMap` of the skeleton; default the map of `a`'s own cycle
            (`gait.model_body_map`, a concrete model).
        clearance: `[2, P]` sole clearances; default estimated from the frames.
        foot_lock: plant the feet with leg IK (`gait.lock_feet`; on by default), with stance
            weights from both models' contact intervals at the integrated phase, blended by s,
            and the feet's shifts eased over `SMOOTH_S` on each side, as `synthesize_gait` does.
            Unsmoothed, the locked walk -> run moved a joint 1.049 units in one frame on
            02_01 <-> 02_03 (N = 5) against the sources' 1.016 (a pop); eased: 0.923 (run -> walk
            0.899 either way).
        contact_intervals: `(A's, B's)` `[2, 2]` contact phases (`gait.contact_intervals`, stored
            with a model by `fourierjax fit`): where the feet are locked and where the models
            fly; default estimated from each model's cycle (concrete models: under jit, vmap or
            grad pass them).
        knee_speed_rad_s: `(A's, B's)` the foot lock's cap on the knee's angular speed where
            the foot is free (radians per second, each scalar or `[2]` left, right;
            `gait.fit_knee_speed` of each source clip, stored with a model by `fourierjax
            fit`), blended by s, as `synthesize_gait` takes one. Default None: no cap. Without
            one the lock stepped the knee 8.02 deg in a frame of CMU 02_03 -> 02_01 (N = 4,
            120 fps) against the captures' largest 5.28 (unlocked: 4.87).

    Returns:
        A `GroundedTransition`. Raises `UserError` as `transition` does.
    """
    from fourierjax import gait
    from fourierjax._checks import integer
    from fourierjax._gait.footlock import SMOOTH_S

    num_frames = integer(num_frames, "grounded_transition: `num_frames`", 2)
    # NumPy float64 leaves (a model file) as JAX holds them (float32 without x64).
    a, b = (jax.tree_util.tree_map(jnp.asarray, m) for m in (a, b))
    if body_map is None:
        body_map = gait.model_body_map(a, skeleton)
    dt = jnp.asarray(frame_time_s, dtype_of(a))
    t = jnp.arange(num_frames, dtype=dt.dtype) * dt
    x, s, theta = transition(a, b, t, start_s, duration_s, ease=ease, method=method, omega_mode=omega_mode,
                             return_schedule=True)
    a, b = common_harmonics(*check_models_omega("grounded_transition", a=a, b=b))
    b = _on_branch(a, b)
    if clearance is not None:
        clearance = jnp.asarray(clearance, x.dtype)
    smooth_frames = None
    if foot_lock:
        if isinstance(frame_time_s, jax.core.Tracer):
            raise UserError("grounded_transition: foot locking needs a concrete `frame_time_s` (it sets "
                            "the easing's frame count), or foot_lock=False")
        # At the frames' own rate, not `gait.lock_supersampling`'s denser ones (as
        # `synthesize_gait` does): on Bandai-1 walk_normal <-> run_normal (N = 5, 30 fps) locking
        # at 4x flew the run part 35% / 38% (walk -> run / run -> walk) against 43% at 1x and the
        # captured 17%, but the run's swing toe (which covers the offsets of the plants from the
        # model's own feet: `_plant`'s easing in the air) moved 21.25 units a frame against the
        # sources' largest 20.98, a pop by issue 21's rule (20.42 at 1x; 20.98 at 2x; session 30).
        smooth_frames = int(round(SMOOTH_S / float(frame_time_s)))
    contact_intervals = _contact_intervals(a, b, skeleton, body_map, contact_intervals)
    knee = None
    if foot_lock and knee_speed_rad_s is not None:
        knee = _knee_caps(knee_speed_rad_s, x.dtype)
    return _grounded(a, b, x, s, theta, skeleton, frame_time_s, body_map, clearance, contact_intervals,
                     smooth_frames, knee, None if knee is None else float(frame_time_s))


def _knee_caps(knee_speed_rad_s, dtype):
    """`[2, 2]` the knee speed caps `(A's, B's)` x (left, right), each given as a scalar or `[2]`;
    checked with NumPy when concrete (no eager XLA programs on the command line's path)."""
    if not isinstance(knee_speed_rad_s, (tuple, list)) or len(knee_speed_rad_s) != 2:
        raise UserError("grounded_transition: `knee_speed_rad_s` must be (A's, B's), each a scalar or [2] "
                        "(left, right) in radians per second")
    caps = []
    for which, k in zip("AB", knee_speed_rad_s):
        traced = isinstance(k, jax.core.Tracer)
        shape = jnp.shape(k)
        if shape not in ((), (2,)):
            raise UserError(f"grounded_transition: `knee_speed_rad_s` {which}'s must be a scalar or [2] (left, "
                            f"right), got shape {shape}")
        if not traced:
            k = np.asarray(k, np.float64)
            if not np.all(np.isfinite(k) & (k > 0)):
                raise UserError(f"grounded_transition: `knee_speed_rad_s` {which}'s must be finite and > 0 "
                                f"(radians per second), got {k}")
            k = np.broadcast_to(k, (2,)).astype(dtype)
        else:
            k = jnp.broadcast_to(jnp.asarray(k, dtype), (2,))
        caps.append(k)
    if any(isinstance(k, jax.core.Tracer) for k in caps):
        return jnp.stack([jnp.asarray(k) for k in caps])
    return np.stack(caps)


_on_branch = saved(filter_jit(on_branch_of))


# Everything after the blend is one saved program: run eagerly, the hip rule, root motion, floors,
# FK of all frames and foot locking were 551 small XLA programs (446 traces) of a warm
# `fourierjax transition` call, 8.9 s of it.
@saved
@filter_jit
def _grounded(a, b, x, s, theta, skeleton, frame_time_s, body_map, clearance, contact_intervals,
              smooth_frames, knee=None, knee_frame_time_s=None):
    """`grounded_transition` after the blend `x, s, theta`: ``b`` on ``a``'s branch,
    ``smooth_frames`` None for no foot lock, ``knee`` `[2, 2]` the lock's knee speed caps (A's,
    B's), blended by s, or None (with ``knee_frame_time_s``, static: the cap's window in frames)."""
    from fourierjax import gait
    from fourierjax._gait.footlock import CONTACT_HEIGHT_FRACTION
    from fourierjax._gait.hip import lowest_points

    rep, up = a.representation, int(body_map.up_axis)
    # Inside the blend the stance feet carry the root. The blend's root velocity and its stride
    # come from two models and disagree: on 02_03 -> 02_01 (N = 5, fitted files' intervals) the
    # walk's first stance foot slipped in the blend's own world (it moved 9-16 units/s over the
    # floor), so `ground_features`' slip test read it as flight, the root kept the blend's speed
    # (31 units/s) and the foot slid 8.5 units over the stance. The lock held it as a shift from
    # +3.8 to -4.7 units and let go of it at the blend's end: the knee stepped 12.33 deg in a frame
    # against the captures' 5.28 (8.20 with the intervals estimated from the models). Carried:
    # 5.23 and 5.21. The root then slows to the walk's speed about 0.5 s sooner (run -> walk,
    # 1.5 s blend: 45 -> 20 units/s over 0.75 s, was 1.25 s); walk -> run travels within 2% of
    # before. Outside the blend each model's root velocity matches its stride, and the slip test
    # keeps a run's landing foot (low, in contact, still swinging forward) from carrying it:
    # carried by the contact intervals there too, run parts travelled 9% short of their own speed.
    weights = _transition_contacts(s, theta, contact_intervals)
    held = jnp.max(weights, axis=-1)
    feats, root, feet, clearance = gait.ground_features(
        x, skeleton, rep, frame_time_s, body_map=body_map, clearance=clearance,
        stance=held * jnp.clip(_BLEND_CARRY * s * (1.0 - s), 0.0, 1.0))
    floor_a, lift_a = _captured_floor(a, skeleton, rep, frame_time_s, body_map, clearance, contact_intervals[0])
    floor_b, lift_b = _captured_floor(b, skeleton, rep, frame_time_s, body_map, clearance, contact_intervals[1])
    # The lowest point on a's floor (two captures need not share a floor level: 02_01 and 02_03
    # differ by 0.25 units, 1.4 cm; the motion keeps a's), lifted
    # - where the models' stance weights are off (flight), by their own cycles' flight lift at
    #   the integrated phase, blended by s: over the take-off-to-landing line, not the floor;
    # - where a foot is held (stance), by the blend's own height over its own floor, at most
    #   `_STANCE_LIFT_BANDS` contact bands: the foot stays within reach of the lock and in contact.
    # Kept whole in stance (the old rule), a periodic fit's stance drift (02_03, N = 5: 0.67 units,
    # 1.3 bands, through the left stance) put the locked run's stance foot out of reach and out
    # of contact: 34-36% flight against the captured 16%. None in stance (the hip rule alone),
    # the Bandai-1 run -> walk lock popped at a landing (21.98 against the sources' 20.98).
    lift = (1.0 - s) * _flight_lift(lift_a, theta) + s * _flight_lift(lift_b, theta)
    own = jnp.maximum(x[:, 2] - s * (floor_b - floor_a) - floor_a - feats[:, 2], 0.0)
    band = _STANCE_LIFT_BANDS * CONTACT_HEIGHT_FRACTION * body_map.height
    height = feats[:, 2] + lift * (1.0 - held) + jnp.minimum(own, band) * held + floor_a
    floor = jnp.broadcast_to(floor_a, height.shape)
    lift = height - feats[:, 2]
    feats = feats.at[:, 2].set(height)
    root = root.at[:, up].set(height)
    feet = feet.at[..., up].add(lift[:, None, None])
    if smooth_frames is not None:
        feats, feet = gait.lock_feet(feats, skeleton, weights, body_map=body_map, representation=rep,
                                     root_position=root, clearance=clearance, ground=floor_a, return_feet=True,
                                     smooth_frames=smooth_frames,
                                     knee_speed_rad_s=None if knee is None else (
                                         (1.0 - s)[:, None] * knee[0][None, :] + s[:, None] * knee[1][None, :]),
                                     frame_time_s=knee_frame_time_s)
    lowest = lowest_points(feet, clearance, up_axis=up) - floor[:, None]
    return GroundedTransition(feats, root, feet, lowest, s, theta, clearance, jnp.asarray(floor_a))


def _contact_intervals(a, b, skeleton, body_map, contact_intervals):
    """`(A's, B's)` `[2, 2]` contact phases: those given, or estimated from each model's cycle
    (``b`` on ``a``'s branch)."""
    from fourierjax import gait

    if contact_intervals is None:
        if isinstance(jnp.asarray(a.offset), jax.core.Tracer):
            raise UserError("grounded_transition under jit, vmap or grad needs `contact_intervals=` "
                            "(each model's stance and flight phases; `gait.contact_intervals`)")
        contact_intervals = tuple(gait.contact_intervals(m, skeleton, body_map=body_map) for m in (a, b))
    if len(contact_intervals) != 2:
        raise UserError("grounded_transition: `contact_intervals` must be (A's [2, 2], B's [2, 2])")
    return tuple(jnp.asarray(iv, dtype_of(a)) for iv in contact_intervals)


def _transition_contacts(s, theta, contact_intervals):
    """`[T, 2]` stance weights of a transition's frames: each model's `gait.contact_weights` at the
    integrated phase, blended by s (the contact intervals change with the gait, as ω does)."""
    from fourierjax import gait

    w_a, w_b = (gait.contact_weights(theta, jnp.asarray(iv, theta.dtype)) for iv in contact_intervals)
    return (1.0 - s)[:, None] * w_a + s[:, None] * w_b
