"""Unuma 1995 §3.1 step constraints: step, speed, the hip-height rule (gait, jump), root motion.

Conventions: Y up unless `up_axis` says otherwise; lengths in file units; `jump` in
√(file units) (eq. 5 adds `jump · √(Lmax − L)`); phases in radians of the gait cycle.

The hip-height rule, as implemented here
----------------------------------------
* Each foot is a few points (ankle, toe base, toe tip: see `contacts.foot_points`). The
  *lowest point* of a foot is `min_p (y_p − c_p)` where `c_p` is the point's *sole clearance*:
  how far above the ground that point sits when the foot is planted flat (the ankle joint is
  ~1 CMU unit above the heel; the toe tip sits on the ground). With clearances the ankle
  stands in for the heel at heel strike and the toe tip carries the push-off. Unuma does not
  model the toe joint angles ("tiptoe's landing is treated differently"): here the toe angle is
  whatever the pose says (a fitted model carries it), and the toe *tip* is a candidate lowest
  point, so a foot rolling onto its toes stays on the ground through its tip.
* `L_L`, `L_R` (eq. 4): vertical distance from each groin (CMU: `LeftUpLeg`, `RightUpLeg`) to
  the lowest point of that foot, from FK with the pelvis at the origin.
  `L = max(L_L, L_R)`, `Lmax = max_t L` over one cycle, `N = (Lmax − L) / Lmax`.
* The rule gives a *lift* ≥ 0 added above ground contact, `L_run = L + lift`:
  - `"unuma1995"` (faithful, eq. 5): `lift = jump √(Lmax − L)` where `N > gait`, else 0. As
    written it jumps at the threshold: at `N = gait` the added height is `jump √(gait Lmax)`,
    not 0.
  - `"continuous"`: `lift = jump · max(0, √(Lmax − L) − √(gait Lmax))`: the same flight frames,
    no jump at the threshold (0 there, growing like eq. 5 beyond it).
  - `"smooth"`: eq. 5 with `max` replaced by a log-sum-exp (temperature `τ`) and the threshold
    by a sigmoid of width `κ` in N, with `√` softened at 0 (`√(x + ε) − √ε`,
    `√ε = 1e-4 Lmax`); differentiable
    in `gait`, `jump` and the pose, for fitting by gradient. The sigmoid is centred on the
    threshold, so frames just below it are partly lifted and their stance foot floats (09_01,
    gait 0.06, jump 5, κ = 0.01: up to 2.44 units where eq. 5 lifts nothing): for synthesis
    use `"unuma1995"` or `"continuous"`.
* The root (pelvis) height above the ground is `D(t) + lift(t)` where `D(t)` is the height
  that puts the lowest point of both feet exactly on the ground (`−min` of the lowest points,
  pelvis at the origin). This equals Unuma's `L_run` measured at the pelvis when the two
  groins are level, and keeps the stance foot exactly on the ground when they are not (a
  tilted pelvis would otherwise push a foot through the floor).

Root motion: the horizontal root advance comes from the feet on the ground: the foot point
carrying the body (a soft argmin of the point heights over both feet) stays put, so the root
moves by minus its displacement. In flight (no point within the contact threshold) the root
moves with the model's own root velocity at the current pace (`synthesize_gait`), or keeps its
last velocity per radian of phase (`root_trajectory` alone); either way slowing the phase
(speed → 0) brings the root to rest. A limit worth knowing: Unuma's N(t) does not tell a
run's flight from its mid-stance knee bend (both have N ≈ 0.06-0.08 on CMU 09_01), so runs
synthesized with the rule advance slower than captured (09_01: ~55 vs 63 units/s).
"""

from __future__ import annotations

import math
from typing import NamedTuple

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float

from fourierjax._checks import concrete, integer
from fourierjax.errors import UserError

RULES = ("unuma1995", "continuous", "smooth")
CMU_GROINS = ("LeftUpLeg", "RightUpLeg")


# --------------------------------------------------------------------------- small helpers


def _safe_sqrt(x):
    """√max(x, 0) with a zero (not infinite/NaN) gradient at and below 0."""
    # Shim to avoid NaNs in jnp.where branches, which cause failures for reverse-mode AD.
    pos = x > 0
    return jnp.where(pos, jnp.sqrt(jnp.where(pos, x, 1.0)), 0.0)


def _soft_sqrt(x, eps):
    """√(max(x, 0) + ε) − √ε: smooth, finite slope 1/(2√ε) at 0."""
    return jnp.sqrt(jnp.maximum(x, 0.0) + eps) - jnp.sqrt(eps)


def _check_finite(where: str, name: str, value) -> None:
    v = concrete(value)
    if v is not None and not np.all(np.isfinite(v)):
        raise UserError(f"{where}: `{name}` must be finite, got {v if v.ndim == 0 else 'non-finite entries'}")


def _check_jump(where: str, jump) -> None:
    # Eq. 5 lifts the hip by jump·√(Lmax − L) in flight: the flight height, so jump ≥ 0 (the
    # lift is ≥ 0 by construction). A negative jump would push the stance foot into the ground.
    _check_finite(where, "jump", jump)
    v = concrete(jump)
    if v is not None and np.any(v < 0):
        raise UserError(f"{where}: `jump` must be >= 0 (the flight height of eq. 5), got {v}")


def _check_rule(rule: str) -> str:
    if rule not in RULES:
        raise UserError(f"hip rule {rule!r} is not one of {RULES}")
    return rule


def groin_joints(topology, names=CMU_GROINS) -> tuple[int, int]:
    """Indices of the left and right groin (hip) joints; CMU names by default.

    Raises `UserError` naming the skeleton's joints when a name is missing.
    """
    joints = tuple(topology.names)
    missing = [n for n in names if n not in joints]
    if missing:
        raise UserError(
            f"groin_joints: the skeleton has no joint(s) {missing}; its joints are {list(joints)}."
            " Pass names=(left, right) for a skeleton that does not use the CMU names"
        )
    return joints.index(names[0]), joints.index(names[1])


# ------------------------------------------------------------------------------ step, speed


def apply_step(model, step):
    """Unuma 1995 §3.1 *step*: replace every `A_n` (n ≥ 1) by `step · A_n`.

    **Arguments:** `model`: a `FourierModel`; `step`: scalar (≥ 0; 1 leaves the model as is).

    **Returns:** the scaled model (offsets, phases and ω unchanged).
    """
    return eqx.tree_at(lambda m: m.amplitude, model, model.amplitude * step)


def integrate_phase(speed, omega, num_frames: int, frame_time_s: float, phase0=0.0):
    """Unuma 1995 §3.1 *speed*: the cycle phase integrated frame by frame.

    Frame `k` is at phase `phase0 + ω · Δt · Σ_{i<k} speed_i`: `speed` scales the time step
    Δτ through the cycle, so changing it (even to 0) never jumps the pose; at `speed = 1` the
    phase is `ω · k Δt` exactly as `synthesize` computes it.

    **Arguments:**

    - `speed`: scalar or `[T]` schedule (dimensionless; 1 = the captured pace).
    - `omega`: fundamental in rad/s; `num_frames`: T; `frame_time_s`: Δt in seconds.
    - `phase0`: phase of frame 0 (radians).

    **Returns:** `[T]` phases in radians.
    """
    speed = jnp.broadcast_to(jnp.asarray(speed, dtype=jnp.result_type(float)), (num_frames,))
    ticks = jnp.concatenate([jnp.zeros((1,), speed.dtype), jnp.cumsum(speed)[:-1]])
    return phase0 + omega * (ticks * frame_time_s)


# --------------------------------------------------------------------------- hip-height rule


def lowest_points(foot_local, clearance, *, up_axis: int = 1, temperature=None):
    """Height of the lowest point of each foot, `min_p (y_p − c_p)`.

    **Arguments:**

    - `foot_local`: `[..., 2, P, 3]` foot points (left, right).
    - `clearance`: `[2, P]` (or broadcastable) sole clearance of each point (file units).
    - `temperature`: `None` for the exact min; a length τ for a soft min `−τ LSE(−y/τ)`.

    **Returns:** `[..., 2]` heights.
    """
    y = jnp.asarray(foot_local)[..., up_axis]
    y = y - jnp.broadcast_to(jnp.asarray(clearance, y.dtype), y.shape)
    if temperature is None:
        return jnp.min(y, axis=-1)
    return -temperature * jax.nn.logsumexp(-y / temperature, axis=-1)


def leg_heights(groins, foot_local, clearance, *, up_axis: int = 1, temperature=None):
    """Unuma eq. 4 inputs `L_L`, `L_R`: groin height above the lowest point of each foot.

    **Arguments:**

    - `groins`: `[..., 2, 3]` left and right groin positions (pelvis at the origin).
    - `foot_local`: `[..., 2, P, 3]` foot points in the same frame.
    - `clearance`: `[2, P]` sole clearances; `temperature`: see `lowest_points`.

    **Returns:** `[..., 2]` lengths (file units).
    """
    low = lowest_points(foot_local, clearance, up_axis=up_axis, temperature=temperature)
    return groins[..., up_axis] - low


class HipRule(NamedTuple):
    """Output of `hip_rule`, per frame: `L` (eq. 4), `N`, `lift` (`L_run − L`, eq. 5),
    `flight` (1 where N > gait; a sigmoid weight for the smooth rule) and the scalar `l_max`."""

    L: Array
    N: Array
    lift: Array
    flight: Array
    l_max: Array


def hip_rule(
    leg: Float[Array, "T 2"],
    gait,
    jump,
    *,
    rule: str = "unuma1995",
    l_max=None,
    temperature=None,
    width: float = 0.01,
) -> HipRule:
    """Unuma 1995 eq. 4-5: hip position of a walk or run from the two leg heights.

    **Arguments:**

    - `leg`: `[T, 2]` `(L_L, L_R)` per frame (`leg_heights`), file units.
    - `gait`: scalar in [0, 1]: flight where `N(t) > gait` (1: never, a walk).
    - `jump`: scalar ≥ 0 in √(file units): height of the flight.
    - `rule`: `"unuma1995"` (faithful, jumps at the threshold), `"continuous"` (no jump) or
      `"smooth"` (differentiable): see the module docstring.
    - `l_max`: `Lmax`; `None` takes the max of `L` over the given frames (pass the max over a
      whole cycle when the frames do not cover one).
    - `temperature`: smooth rule only: log-sum-exp temperature τ (file units) for
      `max(L_L, L_R)`; default `0.002 · max L`.
    - `width`: smooth rule only: sigmoid width κ of the threshold, in units of N.

    **Returns:** a `HipRule`. Gradients are finite everywhere, `L = Lmax` included.

    `N = (Lmax − L)/Lmax` needs `Lmax > 0`: the groins above the feet, true of any standing
    figure. Concrete input with `Lmax ≤ 0` or non-finite (all-zero legs: the groins level with
    the lowest foot points, usually wrong groin or foot indices or `up_axis`) raises
    `UserError`, as do a concrete `jump < 0` or non-finite `gait`/`jump`. Under jit/vmap/grad
    (no value checks) a degenerate `Lmax ≤ 0` gives `N = 0` (no flight) and finite gradients
    instead of 0/0.
    """
    _check_rule(rule)
    leg = jnp.asarray(leg)
    if leg.shape[-1] != 2:
        raise UserError(f"hip_rule: `leg` must be [T, 2] (L_L, L_R), got shape {leg.shape}")
    _check_finite("hip_rule", "gait", gait)
    _check_jump("hip_rule", jump)
    # Lmax > 0 for any standing figure; the soft max of the smooth rule is >= max(leg), so
    # max(leg) > 0 covers every rule (and the default temperature, 0.002 max(leg), needs it).
    ref = jnp.max(leg) if l_max is None else jnp.asarray(l_max)
    v = concrete(ref)
    if v is not None and not (np.all(np.isfinite(v)) and np.all(v > 0)):
        what = "the largest leg height in `leg`" if l_max is None else "`l_max`"
        raise UserError(
            f"hip_rule: Lmax ({what}) must be finite and > 0, got {v}; leg heights are groin "
            "heights above the lowest foot point, so legs that are all <= 0 mean the groins are not "
            "above the feet (check the groin and foot indices and `up_axis`)"
        )
    if rule == "smooth":
        if temperature is None:
            t0 = 0.002 * jnp.max(leg)
            # Shim: a traced all-zero leg would give τ = 0 and 0/0 in the log-sum-exp.
            temperature = jnp.where(t0 > 0, t0, 1.0)
        L = temperature * jax.nn.logsumexp(leg / temperature, axis=-1)
    else:
        L = jnp.max(leg, axis=-1)
    lmax = jnp.max(L) if l_max is None else jnp.asarray(l_max)
    # N is only used for the flight decision. Shim to avoid the 0/0 of a (traced) degenerate
    # Lmax <= 0, NaN in both value and gradient: N = 0 there (no flight).
    ok = lmax > 0
    N = jnp.where(ok, (lmax - L) / jnp.where(ok, lmax, 1.0), 0.0)
    gap = lmax - L
    if rule == "unuma1995":
        flight = (N > gait).astype(L.dtype)
        lift = jnp.where(N > gait, jump * _safe_sqrt(gap), 0.0)
    elif rule == "continuous":
        over = _safe_sqrt(gap) - _safe_sqrt(gait * lmax)
        flight = (N > gait).astype(L.dtype)
        lift = jump * jnp.where(over > 0, over, 0.0)
    else:
        flight = jax.nn.sigmoid((N - gait) / width)
        lift = flight * jump * _soft_sqrt(gap, (1e-4 * lmax) ** 2)
    return HipRule(L=L, N=N, lift=lift, flight=flight, l_max=lmax)


def hip_rule_curves(leg, gait, jump, *, l_max=None, temperature=None, width: float = 0.01):
    """The three rules on the same input, for a side-by-side plot (one call).

    **Arguments:** as `hip_rule`.

    **Returns:** `dict` with `"L"` (eq. 4), `"N"`, and `"unuma1995"`, `"continuous"`,
    `"smooth"`: each `L_run = L + lift` `[T]` (the smooth one on its own soft `L`).
    """
    out = {}
    for rule in RULES:
        h = hip_rule(leg, gait, jump, rule=rule, l_max=l_max, temperature=temperature,
                     width=width)
        out[rule] = h.L + h.lift
        if rule == "unuma1995":
            out["L"], out["N"] = h.L, h.N
    return out


def contact_height(foot_local, clearance, *, up_axis: int = 1):
    """`D(t)`: the root height that puts the lowest foot point exactly on the ground.

    **Arguments:** `foot_local`: `[..., 2, P, 3]` (pelvis at the origin); `clearance`: `[2, P]`.

    **Returns:** `[...]` heights (file units).
    """
    return -jnp.min(lowest_points(foot_local, clearance, up_axis=up_axis), axis=-1)


def root_height(groins, foot_local, clearance, gait, jump, *, rule="unuma1995", l_max=None,
                up_axis: int = 1, temperature=None, width: float = 0.01):
    """Root (pelvis) height above the ground from the hip rule: `D(t) + lift(t)`.

    **Arguments:** `groins` `[T, 2, 3]`, `foot_local` `[T, 2, P, 3]` (pelvis at the origin),
    `clearance` `[2, P]`, and the `hip_rule` arguments.

    **Returns:** `(height [T], HipRule)`.
    """
    leg = leg_heights(groins, foot_local, clearance, up_axis=up_axis,
                      temperature=temperature if rule == "smooth" else None)
    h = hip_rule(leg, gait, jump, rule=rule, l_max=l_max, temperature=temperature, width=width)
    return contact_height(foot_local, clearance, up_axis=up_axis) + h.lift, h


# ------------------------------------------------------------------------------- root motion


#: `root_trajectory` with the model's root velocity: the least fraction of the model's own move
#: (along its direction) that a stance move keeps.
_MIN_ALONG = 0.1


def root_trajectory(
    foot_local: Float[Array, "T 2 P 3"],
    height: Float[Array, " T"],
    phase: Float[Array, " T"],
    clearance,
    *,
    up_axis: int = 1,
    contact_threshold=None,
    temperature=None,
    flight_step=None,
) -> Float[Array, "T 3"]:
    """Root positions over time from the feet on the ground (the carrying foot point stays put).

    Between two frames the root moves horizontally by minus the displacement of the foot point
    that carries the body: a soft argmin (temperature τ) of the points' heights above the
    ground, taken over both feet. A planted point therefore stays put, and a rolling foot hands
    over from heel to toe tip without a jump (each move compares the *same* point at both
    frames). When even the lowest point is above `contact_threshold` (flight) the root keeps
    its last horizontal velocity per radian of phase, so it comes to rest with the phase.

    **Arguments:**

    - `foot_local`: `[T, 2, P, 3]` foot points with the pelvis at the origin (root rotation
      applied, translation not).
    - `height`: `[T]` root height above the ground (e.g. `root_height`).
    - `phase`: `[T]` cycle phase of each frame (radians).
    - `clearance`: `[2, P]` sole clearances.
    - `contact_threshold`: height (file units) below which the lowest point is on the ground;
      default `0.03 · mean(height)` (CMU: ~0.5 units ≈ 3 cm).
    - `temperature`: τ in file units; default `0.003 · mean(height)` (CMU: ~0.05 units).
    - `flight_step`: optional `[T - 1, 2]` horizontal root moves to use in flight instead of
      the carried velocity (`synthesize_gait` passes the model's own root velocity there).
      With it, every stance move keeps at least 10% of `flight_step` along its direction (the
      deficit is added). A fitted run's landing foot is lowest while still swinging forward,
      and carrying the root it dragged the pelvis backwards (09_01, default hip rule: down to
      -45 units/s in 64 of 480 frames; now never: min +6, mean 47 units/s against 43 before
      and 63.5 captured), at the price of that foot sliding by the deficit for a few frames
      (skating metric 6.6 -> 10.5 units/s on that run; walks unchanged: 07_01 7.7).

    **Returns:** `[T, 3]` root positions; horizontal components start at 0, the up component
    is `height`. Validated on real clips: from their own poses it recovers 93% (07_01) of the
    captured root advance; the rest is skating in the capture. On a fitted 07_01 model
    (`synthesize_gait`, 4 s) the lowest point (after sole clearance) moves at a median 0.1-0.4
    units/s; where the support hands over (heel to toe, foot to foot) the soft argmin mixes
    points that move differently, and the carrying point slides for a few frames (90th
    percentile 8-16 units/s).
    """
    T = foot_local.shape[0]
    # Scale-relative defaults; differentiated like everything else (true derivatives).
    scale = jnp.mean(height)
    th = 0.03 * scale if contact_threshold is None else contact_threshold
    tau = 0.003 * scale if temperature is None else temperature
    y = foot_local[..., up_axis]
    h = height[:, None, None] + y - jnp.broadcast_to(clearance, y.shape)  # [T, 2, P]
    h_mid = (0.5 * (h[1:] + h[:-1])).reshape(T - 1, -1)
    w = jax.nn.softmax(-h_mid / tau, axis=-1)
    horiz = [k for k in range(3) if k != up_axis]
    xz = foot_local[..., horiz].reshape(T, -1, 2)
    stance_step = -jnp.sum(w[..., None] * (xz[1:] - xz[:-1]), axis=1)  # [T-1, 2]
    low = -tau * jax.nn.logsumexp(-h_mid / tau, axis=-1)  # soft min height
    ground = jax.nn.sigmoid((th - low) / (0.1 * th))  # 1 on the ground, 0 in flight
    dphase = phase[1:] - phase[:-1]

    if flight_step is not None:
        # A foot may not carry the root backwards against the model's own travel: a run's
        # landing foot, lowest while still swinging forward, dragged the pelvis back (09_01
        # defaults: -45 units/s, 64 of 480 frames). Each stance move keeps at least
        # `_MIN_ALONG` of the model's move along its direction (the deficit is added), so the
        # root never reverses and the landing foot slides only by the deficit.
        f2 = jnp.sum(flight_step * flight_step, axis=-1)
        along = jnp.sum(stance_step * flight_step, axis=-1) / (f2 + 0.01 * jnp.mean(f2) + 1e-30)
        stance_step = stance_step + jnp.maximum(_MIN_ALONG - along, 0.0)[:, None] * flight_step
        moves = ground[:, None] * stance_step + (1.0 - ground[:, None]) * flight_step
    else:

        def body(vel, inputs):
            step, a, dth = inputs
            # Velocity per radian of phase, learned on the ground; shim the 0/0 at rest.
            moving = jnp.abs(dth) > 1e-12
            safe = jnp.where(moving, dth, 1.0)
            vel_new = jnp.where((a > 0.5) & moving, step / safe, vel)
            return vel_new, a * step + (1.0 - a) * vel * dth

        vel0 = jnp.zeros((2,), foot_local.dtype)
        _, moves = jax.lax.scan(body, vel0, (stance_step, ground, dphase))
    path = jnp.concatenate([jnp.zeros((1, 2), moves.dtype), jnp.cumsum(moves, axis=0)])
    out = jnp.zeros((T, 3), foot_local.dtype)
    out = out.at[:, horiz[0]].set(path[:, 0]).at[:, horiz[1]].set(path[:, 1])
    return out.at[:, up_axis].set(height)


# ------------------------------------------------------------------------------------ metrics


class SkatingStats(NamedTuple):
    """Foot skating: horizontal speed of foot points while on the ground.

    `mean_speed` (file units / s) and `mean_per_frame` (file units / frame) over the contact
    samples; `max_speed` (units / s); `contact_fraction` of point-frames in contact."""

    mean_speed: Array
    mean_per_frame: Array
    max_speed: Array
    contact_fraction: Array


def foot_skating(foot_positions, frame_time_s, floor, *, height_threshold=0.5, up_axis=1):
    """Foot skating of world foot points (pure jnp).

    A point counts as on the ground when it is less than `height_threshold` above its floor;
    its skating is its horizontal speed there (central differences).

    **Arguments:**

    - `foot_positions`: `[T, F, P, 3]` world foot points.
    - `frame_time_s`: seconds per frame.
    - `floor`: floor height under each point, broadcastable to `[T, F, P]` (ground + sole
      clearance; for a real clip `contacts.floor_heights`).
    - `height_threshold`: file units.

    **Returns:** `SkatingStats`.
    """
    from fourierjax.contacts import point_speeds

    p = jnp.asarray(foot_positions)
    y = p[..., up_axis]
    above = y - jnp.broadcast_to(jnp.asarray(floor, y.dtype), y.shape)
    on = above < height_threshold
    v = point_speeds(p, frame_time_s, up_axis=up_axis)
    n = jnp.maximum(jnp.sum(on), 1)
    mean = jnp.sum(jnp.where(on, v, 0.0)) / n
    return SkatingStats(
        mean_speed=mean,
        mean_per_frame=mean * frame_time_s,
        max_speed=jnp.max(jnp.where(on, v, 0.0)),
        contact_fraction=jnp.mean(on),
    )


def ground_penetration(foot_positions, clearance, *, ground=0.0, up_axis=1):
    """Depth of the lowest foot points below the ground: `(max, mean over frames)` ≥ 0.

    **Arguments:** `foot_positions` `[T, 2, P, 3]` world; `clearance` `[2, P]`; `ground` height.
    """
    low = jnp.min(lowest_points(foot_positions, clearance, up_axis=up_axis), axis=-1) - ground
    depth = jnp.maximum(-low, 0.0)
    return jnp.max(depth), jnp.mean(depth)


def flight_fraction(lowest, *, tolerance=1e-3):
    """Fraction of frames with both feet off the ground (`lowest`: `[T, 2]` heights)."""
    return jnp.mean(jnp.min(lowest, axis=-1) > tolerance)


def estimate_sole_clearance(foot_local, *, up_axis: int = 1):
    """Sole clearance of each foot point, estimated from poses (e.g. one cycle of a model).

    For each foot, over the frames where it is the lower foot (stance), the median height of
    each point above the foot's lowest point; the lowest point of a planted foot gets 0.
    (`contacts.sole_clearance` measures the same from a real clip's fitted floor.)

    **Arguments:** `foot_local`: `[K, 2, P, 3]` foot points over K poses.

    **Returns:** `[2, P]` clearances ≥ 0 (file units). Pure jnp.
    """
    y = jnp.asarray(foot_local)[..., up_axis]  # [K, 2, P]
    low = jnp.min(y, axis=-1)  # [K, 2]
    rel = y - low[..., None]
    stance = jnp.stack([low[:, 0] <= low[:, 1], low[:, 1] <= low[:, 0]], axis=-1)  # [K, 2]
    vals = jnp.where(stance[..., None], rel, jnp.nan)
    c = jnp.nanmedian(vals, axis=0)
    c = jnp.where(jnp.isnan(c), 0.0, c)
    return c - jnp.min(c, axis=-1, keepdims=True)


# ------------------------------------------------------------------------ gait synthesis


class GaitResult(eqx.Module):
    """A synthesized gait with step constraints (one character; vmap adds a leading axis).

    - `features`: `[T, C]` model channels per frame (`fourier` layout). With root motion the
      root channels are replaced: `root.y` by the hip-rule height, `root.vx, root.vz` by the
      velocity of `root_position` (central differences).
    - `phase`: `[T]` cycle phase of each frame (radians).
    - `root_position`: `[T, 3]` world root (pelvis) position, file units.
    - `foot_positions`: `[T, 2, P, 3]` world foot points (left, right).
    - `lowest`: `[T, 2]` height of each foot's lowest point above the ground (sole clearance
      taken off).
    - `hip`: the `HipRule` (L, N, lift, flight, l_max).
    - `clearance`: `[2, P]` the sole clearances used.
    """

    features: Array
    phase: Array
    root_position: Array
    foot_positions: Array
    lowest: Array
    hip: HipRule
    clearance: Array


def _pose_points(skeleton, representation, idx, groins, feat):
    from fourierjax.kinematics import forward_kinematics
    from fourierjax.motion import local_pose_from_features

    fk = forward_kinematics(skeleton, *local_pose_from_features(skeleton, feat, representation))
    allp = jnp.concatenate([fk.positions, fk.end_site_positions], axis=0)
    return allp[idx], fk.positions[jnp.asarray(groins)]


def _is_index(i, n: int) -> bool:
    return isinstance(i, int | np.integer) and not isinstance(i, bool) and -n <= i < n


def _check_indices(where: str, skeleton, feet, groins) -> tuple[int, int]:
    """The groin joint indices as non-negative Python ints; UserError for an index outside the
    skeleton (JAX would clamp it: a wrong joint and a wrong leg length, silently)."""
    num_joints = skeleton.topology.num_joints
    groins = tuple(groins)
    if len(groins) != 2 or not all(_is_index(g, num_joints) for g in groins):
        raise UserError(
            f"{where}: `groins`={groins!r}; expected (left, right) joint indices of the skeleton's "
            f"{num_joints} joints (see `groin_joints`)"
        )
    num_points = num_joints + skeleton.topology.num_end_sites
    for side in ("left", "right"):
        points = tuple(getattr(feet, side))
        if not all(_is_index(i, num_points) for i in points):
            raise UserError(
                f"{where}: `feet.{side}`={points!r}; expected point indices below {num_points} "
                f"({num_joints} joints, then End Sites; see `contacts.foot_points`)"
            )
    return tuple(int(g) % num_joints for g in groins)


def _integrate_trapezoid(v, dt):
    return jnp.concatenate([jnp.zeros((1,), v.dtype), jnp.cumsum(0.5 * (v[1:] + v[:-1]) * dt)])


@eqx.filter_jit
def _synthesize_gait(model, skeleton, clearance, step, speed, t_eff, gait, jump, phase0,
                     root_motion, *,
                     num_frames, frame_time_s, feet, groins, rule, width, temperature,
                     num_cycle_samples, up_axis):
    from fourierjax.fourier import synthesize_phase

    stepped = apply_step(model, step)
    # t_eff (the integrated time, computed by the caller) makes speed = 1 bit-identical to
    # `synthesize(model, k dt)`.
    phase = stepped.omega * t_eff + phase0
    feats = synthesize_phase(stepped, phase)
    idx = jnp.asarray([feet.left, feet.right])
    rep = model.representation

    def points(f):
        return _pose_points(skeleton, rep, idx, groins, f)

    # Lmax over one whole cycle of the (stepped) model, whatever the speed schedule; the sole
    # clearances (if not given) from a cycle of the unstepped model (the foot's geometry must
    # not change with the step length). One vmapped FK over all poses: one FK graph to compile.
    K = num_cycle_samples
    grid = jnp.linspace(0.0, 2 * jnp.pi, K, endpoint=False, dtype=phase.dtype)
    poses = [feats, synthesize_phase(stepped, grid)]
    if clearance is None:
        poses.append(synthesize_phase(model, grid))
    all_feet, all_groins = jax.vmap(points)(jnp.concatenate(poses, axis=0))
    foot_local, groin_local = all_feet[:num_frames], all_groins[:num_frames]
    cyc_feet = all_feet[num_frames : num_frames + K]
    cyc_groins = all_groins[num_frames : num_frames + K]
    if clearance is None:
        clearance = estimate_sole_clearance(all_feet[num_frames + K :], up_axis=up_axis)
    soft = temperature if rule == "smooth" else None
    cyc_leg = leg_heights(cyc_groins, cyc_feet, clearance, up_axis=up_axis, temperature=soft)
    leg = leg_heights(groin_local, foot_local, clearance, up_axis=up_axis, temperature=soft)
    # The frames themselves may reach past the grid's max: include them, so N >= 0.
    both = jnp.concatenate([cyc_leg, leg], axis=0)
    l_max = hip_rule(both, gait, jump, rule=rule, temperature=temperature, width=width).l_max
    hip = hip_rule(leg, gait, jump, rule=rule, l_max=l_max, temperature=temperature,
                   width=width)
    horiz = [k for k in range(3) if k != up_axis]
    # Both roots are cheap next to FK: compute both and select, so `root_motion` is traced
    # (one compilation serves both).
    speed_t = jnp.broadcast_to(jnp.asarray(speed, feats.dtype), (num_frames,))
    height = contact_height(foot_local, clearance, up_axis=up_axis) + hip.lift
    # In flight the root moves with the model's own (captured) root velocity at this pace.
    v_model = feats[:, :2] * speed_t[:, None]
    flight_step = 0.5 * (v_model[1:] + v_model[:-1]) * frame_time_s
    root_on = root_trajectory(foot_local, height, phase, clearance, up_axis=up_axis,
                              flight_step=flight_step)
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
    lowest = lowest_points(foot_world, clearance, up_axis=up_axis)
    return GaitResult(feats, phase, root, foot_world, lowest, hip, clearance)


def synthesize_gait(
    model,
    skeleton,
    num_frames: int,
    frame_time_s: float,
    *,
    feet,
    groins: tuple[int, int],
    clearance=None,
    step=1.0,
    speed=1.0,
    gait=1.0,
    jump=0.0,
    rule: str = "unuma1995",
    root_motion: bool = True,
    phase0=0.0,
    width: float = 0.01,
    temperature=None,
    num_cycle_samples: int = 64,
    up_axis: int = 1,
) -> GaitResult:
    """Synthesize a gait under Unuma's step constraints (§3.1): step, speed, gait, jump.

    Joint angles come from the model at the integrated phase (`apply_step`,
    `integrate_phase`); with `root_motion` the root height is the hip-height rule's
    (`root_height`: the lowest foot point on the ground, plus the flight lift of eq. 5) and its
    horizontal path comes from the feet on the ground (`root_trajectory`; in flight, from the
    model's own root velocity at the current pace). Without it, the root
    follows the model's own `root.*` channels (velocities scaled by `speed`). `Lmax` is taken
    over one cycle of the stepped model (`num_cycle_samples` phases).

    With `step = 1`, `speed = 1`, `gait = 1`, `jump = 0` the joint channels equal
    `synthesize(model, k Δt)` exactly, the lift is 0, and without root motion every channel is
    unchanged.

    **Arguments:**

    - `model`: a `FourierModel` on `motion.channel_names_for(topology, representation)`.
    - `skeleton`: the `Skeleton` it animates; `num_frames`, `frame_time_s`: output sampling.
    - `feet`: `contacts.FootPoints`; `groins`: `(left, right)` joint indices (`groin_joints`).
    - `clearance`: `[2, P]` sole clearances (`contacts.sole_clearance` of the source clip);
      default `None` estimates them from one cycle of the model (`estimate_sole_clearance`).
    - `step`, `gait`, `jump`: scalars (`jump ≥ 0`); `speed`: scalar or `[num_frames]` schedule.
    - `rule`: `"unuma1995" | "continuous" | "smooth"`; `width`, `temperature`: `hip_rule`.
    - `phase0`: phase of the first frame (radians).

    **Returns:** a `GaitResult`. Jitted; differentiable in the model, `step`, `speed`, `gait`,
    `jump` and `clearance`; vmap over characters (models, parameters) at the call site.

    Raises `UserError` for a non-integer `num_frames` (or < 2), a `frame_time_s` that is not
    finite and > 0, `groins` or foot points out of the skeleton's range, and, when concrete
    (not traced), a non-finite `step`, `speed`, `gait`, `jump` or `phase0` or a `jump < 0`.
    """
    where = "synthesize_gait"
    _check_rule(rule)
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
    if up_axis not in (0, 1, 2):
        raise UserError(f"{where}: `up_axis` must be 0, 1 or 2, got {up_axis!r}")
    groins = _check_indices(where, skeleton, feet, groins)
    if len(feet.left) != len(feet.right):
        raise UserError("synthesize_gait: both feet must have the same number of points")
    for name, value in (("step", step), ("speed", speed), ("gait", gait), ("phase0", phase0)):
        _check_finite(where, name, value)
    _check_jump(where, jump)
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
    ticks = jnp.concatenate([jnp.zeros((1,), dtype), jnp.cumsum(speed)[:-1]])
    t_eff = ticks * dt
    return _synthesize_gait(
        model, skeleton, clearance,
        jnp.asarray(step, dtype), speed, t_eff, jnp.asarray(gait, dtype),
        jnp.asarray(jump, dtype), jnp.asarray(phase0, dtype), jnp.asarray(root_motion, bool),
        num_frames=num_frames, frame_time_s=dt,
        feet=feet, groins=groins,
        rule=rule, width=float(width),
        temperature=None if temperature is None else float(temperature),
        num_cycle_samples=num_cycle_samples, up_axis=int(up_axis),
    )


@eqx.filter_jit
def _cycle_points(model, skeleton, feet, groins, num_samples):
    from fourierjax.fourier import synthesize_phase

    idx = jnp.asarray([feet.left, feet.right])
    grid = jnp.linspace(0.0, 2 * jnp.pi, num_samples, endpoint=False,
                        dtype=jnp.asarray(model.offset).dtype)
    foot_local, groin_local = jax.vmap(
        lambda f: _pose_points(skeleton, model.representation, idx, groins, f)
    )(synthesize_phase(model, grid))
    return grid, foot_local, groin_local


def model_hip_curves(model, skeleton, *, feet, groins, gait, jump, clearance=None,
                     num_samples: int = 128, width: float = 0.01, temperature=None,
                     up_axis: int = 1):
    """The three hip rules over one cycle of a model: the data of a side-by-side plot.

    **Arguments:** `model`, `skeleton`, `feet`, `groins`, `clearance` as `synthesize_gait`;
    `gait`, `jump`, `width`, `temperature` as `hip_rule`; `num_samples` phases per cycle.

    **Returns:** `dict`: `"phase"` `[K]` (radians), `"L_L"`, `"L_R"`, and the
    `hip_rule_curves` entries (`"L"`, `"N"`, `"unuma1995"`, `"continuous"`, `"smooth"`).
    """
    groins = _check_indices("model_hip_curves", skeleton, feet, groins)
    num_samples = integer(num_samples, "model_hip_curves: `num_samples`", 1)
    grid, foot_local, groin_local = _cycle_points(model, skeleton, feet, groins, num_samples)
    if clearance is None:
        clearance = estimate_sole_clearance(foot_local, up_axis=up_axis)
    leg = leg_heights(groin_local, foot_local, jnp.asarray(clearance), up_axis=up_axis)
    out = hip_rule_curves(leg, gait, jump, width=width, temperature=temperature)
    out.update(phase=grid, L_L=leg[:, 0], L_R=leg[:, 1])
    return out


def gait_motion(template, result: GaitResult, channel_names, frame_time_s: float):
    """A writeable `Motion` of a synthesized gait, carrying its root trajectory (edge, NumPy).

    Joint rotations go through `motion.motion_from_features`; the root position channels are
    then set to `result.root_position` exactly (no re-integration).

    **Arguments:** `template`: a `Motion` of the model's skeleton; `result`: from
    `synthesize_gait`; `channel_names`: the model's channel names; `frame_time_s`: seconds.

    **Returns:** a `Motion` with `T` frames.
    """
    import dataclasses

    import numpy as np

    from fourierjax.motion import motion_from_features

    mot = motion_from_features(template, np.asarray(result.features), channel_names,
                               frame_time_s)
    ch = np.array(mot.channels)
    root = np.asarray(result.root_position, dtype=np.float64)
    base = mot.topology.channel_offsets[0]
    for k, name in enumerate(mot.topology.channels[0]):
        if name.endswith("position"):
            ch[:, base + k] = root[:, "XYZ".index(name[0])]
    return dataclasses.replace(mot, channels=ch)


# ------------------------------------------------------------------- fitting gait and jump


class HipFit(NamedTuple):
    """Result of `fit_hip_rule`: fitted `gait`, `jump`; RMS root-height error (file units)
    `rms_before` (the walk rule: gait = 1, jump = 0) and `rms_after`; optimistix `result` code
    and `num_steps`."""

    gait: Array
    jump: Array
    rms_before: Array
    rms_after: Array
    result: object
    num_steps: Array


def fit_hip_rule(
    groins,
    foot_local,
    clearance,
    target_height,
    *,
    rule: str = "smooth",
    init=(0.03, 1.0),
    l_max=None,
    width: float = 0.01,
    temperature=None,
    up_axis: int = 1,
    max_steps: int = 200,
) -> HipFit:
    """Fit `gait` and `jump` by least squares so the hip rule's root height matches a target.

    Minimises `Σ_t (root_height(t; gait, jump) − target(t))²` with optimistix
    Levenberg-Marquardt (gradients through the rule: use `"smooth"`, or `"continuous"` whose
    gait enters continuously; the faithful rule has no gradient in `gait`).

    **Arguments:**

    - `groins` `[T, 2, 3]`, `foot_local` `[T, 2, P, 3]`: pose points, pelvis at the origin.
    - `clearance`: `[2, P]` sole clearances.
    - `target_height`: `[T]` measured root height above the ground (file units).
    - `rule`, `l_max`, `width`, `temperature`: as `hip_rule`; `init`: `(gait, jump)` start.

    **Returns:** a `HipFit`.
    """
    import optimistix as optx

    _check_rule(rule)
    groins = jnp.asarray(groins)
    foot_local = jnp.asarray(foot_local)
    clearance = jnp.asarray(clearance, foot_local.dtype)
    target = jnp.asarray(target_height, foot_local.dtype)

    def residual(y, _):
        h, _ = root_height(groins, foot_local, clearance, y[0], y[1], rule=rule, l_max=l_max,
                           up_axis=up_axis, temperature=temperature, width=width)
        return h - target

    def rms(r):
        return jnp.sqrt(jnp.mean(r * r))

    y0 = jnp.asarray(init, foot_local.dtype)
    sol = optx.least_squares(residual, optx.LevenbergMarquardt(rtol=1e-6, atol=1e-6), y0,
                             max_steps=max_steps, throw=False)
    before = rms(residual(jnp.asarray([1.0, 0.0], foot_local.dtype), None))
    after = rms(residual(sol.value, None))
    return HipFit(sol.value[0], sol.value[1], before, after, sol.result, sol.stats["num_steps"])
