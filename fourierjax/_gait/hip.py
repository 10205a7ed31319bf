"""The hip-height rule (Unuma 1995 eq. 4-5): leg heights, lowest foot points, root height."""

from __future__ import annotations

from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, ArrayLike, Float

from fourierjax._checks import concrete
from fourierjax._gait.common import (
    RULES,
    check_finite,
    check_jump,
    check_rule,
    smooth_parameter_checks,
    traced_jump_checks,
)
from fourierjax._math import safe_sqrt
from fourierjax.errors import UserError

#: `_math.safe_sqrt` computes `x · rsqrt(x)`, whose float32 gradient overflows to NaN for
#: 0 < x < ~2e-26 (`x^-1.5` > float32 max; hypothesis found gait = 1e-30 in the continuous
#: rule). At and below this floor the root is `√floor` = 1e-12 file units, with zero gradient.
_SQRT_FLOOR = 1e-24


def _sqrt(x: Array) -> Array:
    return safe_sqrt(x, floor=_SQRT_FLOOR)


def _soft_sqrt(x: Array, eps: Array) -> Array:
    """√(max(x, 0) + ε) − √ε: smooth, finite slope 1/(2√ε) at 0, and finite gradients in ε at
    ε = 0 too (a traced `l_max` of 0 sets ε = 0)."""
    return _sqrt(jnp.maximum(x, 0.0) + eps) - _sqrt(eps)


def _soft_max(x: Array, temperature: ArrayLike, axis: int = -1) -> Array:
    """`τ LSE(x/τ)` along `axis`, shifted by the (stop-gradient) max so that a tiny τ does not
    overflow `x/τ` (inf − inf inside the log-sum-exp gave NaN under jit at τ = 1e-30)."""
    m = jax.lax.stop_gradient(jnp.max(x, axis=axis, keepdims=True))
    return jnp.squeeze(m, axis) + temperature * jax.nn.logsumexp((x - m) / temperature, axis=axis)


def lowest_points(
    foot_local: Float[ArrayLike, "*batch 2 P 3"],
    clearance: Float[ArrayLike, "2 P"],
    *,
    up_axis: int = 1,
    temperature: Float[ArrayLike, ""] | None = None,
) -> Float[Array, "*batch 2"]:
    """Height of the lowest point of each foot, `min_p (y_p − c_p)`.

    The lowest point stands in for the heel at heel strike (the ankle, less its clearance)
    and for the toe at push-off (the toe tip, clearance ~0): see `contacts.foot_points`.

    Arguments:
        foot_local: `[..., 2, P, 3]` foot points (left, right).
        clearance: `[2, P]` (or broadcastable) sole clearance of each point (file units): how
            far above the ground the point sits when the foot is planted flat.
        up_axis: index of the up axis.
        temperature: `None` for the exact min; a length τ > 0 for a soft min `−τ LSE(−y/τ)`.

    Returns:
        `[..., 2]` heights.
    """
    y = jnp.asarray(foot_local)[..., up_axis]
    y = y - jnp.broadcast_to(jnp.asarray(clearance, y.dtype), y.shape)
    if temperature is None:
        return jnp.min(y, axis=-1)
    return -_soft_max(-y, temperature)


def leg_heights(
    groins: Float[ArrayLike, "*batch 2 3"],
    foot_local: Float[ArrayLike, "*batch 2 P 3"],
    clearance: Float[ArrayLike, "2 P"],
    *,
    up_axis: int = 1,
    temperature: Float[ArrayLike, ""] | None = None,
) -> Float[Array, "*batch 2"]:
    """Unuma eq. 4 inputs `L_L`, `L_R`: groin height above the lowest point of each foot.

    Arguments:
        groins: `[..., 2, 3]` left and right groin positions (pelvis at the origin).
        foot_local: `[..., 2, P, 3]` foot points in the same frame.
        clearance: `[2, P]` sole clearances.
        up_axis: index of the up axis.
        temperature: see `lowest_points`.

    Returns:
        `[..., 2]` lengths (file units).
    """
    low = lowest_points(foot_local, clearance, up_axis=up_axis, temperature=temperature)
    return jnp.asarray(groins)[..., up_axis] - low


class HipRule(NamedTuple):
    """Output of `hip_rule`, per frame: `L` (eq. 4), `N`, `lift` (`L_run − L`, eq. 5),
    `flight` (1 where N > gait; a sigmoid weight for the smooth rule) and the scalar `l_max`."""

    L: Array
    N: Array
    lift: Array
    flight: Array
    l_max: Array


def hip_rule(
    leg: Float[ArrayLike, "T 2"],
    gait: Float[ArrayLike, ""],
    jump: Float[ArrayLike, ""],
    *,
    rule: str = "unuma1995",
    l_max: Float[ArrayLike, ""] | None = None,
    temperature: Float[ArrayLike, ""] | None = None,
    width: Float[ArrayLike, ""] = 0.01,
    check_traced: bool = True,
) -> HipRule:
    """Unuma 1995 eq. 4-5: hip position of a walk or run from the two leg heights.

    `L = max(L_L, L_R)`, `Lmax = max_t L`, `N = (Lmax − L) / Lmax`, and a lift ≥ 0 above
    ground contact, `L_run = L + lift`:

    - `"unuma1995"` (eq. 5 as written): `lift = jump √(Lmax − L)` where `N > gait`, else 0;
      it jumps at the threshold by `jump √(gait Lmax)`.
    - `"continuous"`: `lift = jump · max(0, √(Lmax − L) − √(gait Lmax))`: the same flight
      frames, no jump at the threshold.
    - `"smooth"`: `max` replaced by a log-sum-exp (temperature τ) and the threshold by a
      sigmoid of width κ in N, `√` softened at 0 (`√(x + ε) − √ε`, `√ε = 1e-4 Lmax`);
      differentiable in `gait`, `jump` and the pose. The sigmoid is centred on the threshold,
      so frames just below it are partly lifted and their stance foot floats (09_01, gait
      0.06, jump 5, κ = 0.01: up to 2.44 units where eq. 5 lifts nothing): for synthesis use
      `"unuma1995"` or `"continuous"`.

    Arguments:
        leg: `[T, 2]` `(L_L, L_R)` per frame (`leg_heights`), file units.
        gait: scalar in [0, 1]: flight where `N(t) > gait` (1: never, a walk).
        jump: scalar ≥ 0 in √(file units): height of the flight.
        rule: `"unuma1995"`, `"continuous"` or `"smooth"`.
        l_max: `Lmax`; `None` takes the max of `L` over the given frames (pass the max over a
            whole cycle when the frames do not cover one).
        temperature: smooth rule: log-sum-exp temperature τ > 0 (file units) for
            `max(L_L, L_R)`; default `0.002 · max L`.
        width: smooth rule: sigmoid width κ > 0 of the threshold, in units of N.
        check_traced: False when the caller has already checked `gait`, `jump`, `width` and
            `temperature` as concrete values (e.g. `synthesize_gait` before its jit): no
            `eqx.error_if` then, whose host callback keeps a program out of the persistent
            compile cache.

    Returns:
        A `HipRule`. Gradients are finite everywhere, `L = Lmax` and zero-length legs included.

    `N` needs `Lmax > 0`: the groins above the feet, true of any standing figure. Concrete
    input with `Lmax ≤ 0` or non-finite (usually wrong groin or foot indices or `up_axis`)
    raises `UserError`, as do a `jump < 0`, a non-finite `gait` or `jump`, and a `width` or
    `temperature` that is not finite and > 0; traced values of `gait`, `jump`, `width` and
    `temperature` are checked by `eqx.error_if` (the program fails when run). A traced
    degenerate `Lmax ≤ 0` gives `N = 0` (no flight) and finite gradients instead of 0/0.
    """
    check_rule(rule)
    leg = jnp.asarray(leg)
    if leg.shape[-1] != 2:
        raise UserError(f"hip_rule: `leg` must be [T, 2] (L_L, L_R), got shape {leg.shape}")
    check_finite("hip_rule", "gait", gait)
    check_jump("hip_rule", jump)
    if check_traced:
        leg = smooth_parameter_checks("hip_rule", leg, width, temperature)
        leg = traced_jump_checks("hip_rule", leg, gait, jump)
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
        L = _soft_max(leg, temperature)
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
        lift = jnp.where(N > gait, jump * _sqrt(gap), 0.0)
    elif rule == "continuous":
        over = _sqrt(gap) - _sqrt(gait * lmax)
        flight = (N > gait).astype(L.dtype)
        lift = jump * jnp.where(over > 0, over, 0.0)
    else:
        flight = jax.nn.sigmoid((N - gait) / width)
        lift = flight * jump * _soft_sqrt(gap, (1e-4 * lmax) ** 2)
    return HipRule(L=L, N=N, lift=lift, flight=flight, l_max=lmax)


def hip_rule_curves(
    leg: Float[ArrayLike, "T 2"],
    gait: Float[ArrayLike, ""],
    jump: Float[ArrayLike, ""],
    *,
    l_max: Float[ArrayLike, ""] | None = None,
    temperature: Float[ArrayLike, ""] | None = None,
    width: Float[ArrayLike, ""] = 0.01,
) -> dict[str, Float[Array, " T"]]:
    """The three rules on the same input, for a side-by-side plot (one call).

    Arguments:
        leg, gait, jump, l_max, temperature, width: as `hip_rule`.

    Returns:
        `dict` with `"L"` (eq. 4), `"N"`, and `"unuma1995"`, `"continuous"`, `"smooth"`: each
        `L_run = L + lift` `[T]` (the smooth one on its own soft `L`).
    """
    out = {}
    for rule in RULES:
        h = hip_rule(leg, gait, jump, rule=rule, l_max=l_max, temperature=temperature,
                     width=width)
        out[rule] = h.L + h.lift
        if rule == "unuma1995":
            out["L"], out["N"] = h.L, h.N
    return out


def contact_height(
    foot_local: Float[ArrayLike, "*batch 2 P 3"],
    clearance: Float[ArrayLike, "2 P"],
    *,
    up_axis: int = 1,
) -> Float[Array, "*batch"]:
    """`D(t)`: the root height that puts the lowest foot point exactly on the ground.

    With the root at `D(t) + lift(t)` the stance foot stays on the ground even when the groins
    are not level (a tilted pelvis would otherwise push a foot through the floor); for level
    groins it is Unuma's `L_run` measured at the pelvis.

    Arguments:
        foot_local: `[..., 2, P, 3]` foot points, pelvis at the origin.
        clearance: `[2, P]` sole clearances.
        up_axis: index of the up axis.

    Returns:
        `[...]` heights (file units).
    """
    return -jnp.min(lowest_points(foot_local, clearance, up_axis=up_axis), axis=-1)


#: The captured floor of a model: this quantile of its lowest foot point's height over one cycle
#: (`captured_floor`; a walk's every phase, a run's stance; a run is in flight at most ~40% of it).
FLOOR_QUANTILE = 0.2


def cycle_lowest(
    root_height: Float[ArrayLike, " K"],
    foot_local: Float[ArrayLike, "K 2 P 3"],
    clearance: Float[ArrayLike, "2 P"],
    *,
    up_axis: int = 1,
) -> Float[Array, " K"]:
    """`[K]` the lowest foot point's height (clearance off) over a model's own cycle, where the
    model's own root height (its `root.y` channel, the capture's) puts it.

    Arguments:
        root_height: `[K]` the model's own root height at K phases (file units).
        foot_local: `[K, 2, P, 3]` foot points, pelvis at the origin.
        clearance: `[2, P]` sole clearances.
        up_axis: index of the up axis.
    """
    return jnp.asarray(root_height) + jnp.min(lowest_points(foot_local, clearance, up_axis=up_axis), axis=-1)


def captured_floor(own_lowest: Float[ArrayLike, " K"]) -> Float[Array, ""]:
    """The floor a model was captured on: the `FLOOR_QUANTILE` of its own lowest foot point over
    one cycle (`cycle_lowest`). The one floor rule of every grounded synthesis (`synthesize_gait`,
    hence `synth` and `interpolate`, and `grounded_transition`): the hip rule's lowest foot point
    stands on it, so the feet stand where the capture's stood (Bandai-1's foot joints ~4 cm above
    the file's y = 0, CMU's toe tips about at it), not on the file's y = 0.

    Arguments:
        own_lowest: `[K]` heights from `cycle_lowest` (file units).

    Returns:
        The floor's height (file units, up axis).
    """
    return jnp.quantile(jnp.asarray(own_lowest), FLOOR_QUANTILE)


def root_height(
    groins: Float[ArrayLike, "T 2 3"],
    foot_local: Float[ArrayLike, "T 2 P 3"],
    clearance: Float[ArrayLike, "2 P"],
    gait: Float[ArrayLike, ""],
    jump: Float[ArrayLike, ""],
    *,
    rule: str = "unuma1995",
    l_max: Float[ArrayLike, ""] | None = None,
    up_axis: int = 1,
    temperature: Float[ArrayLike, ""] | None = None,
    width: Float[ArrayLike, ""] = 0.01,
) -> tuple[Float[Array, " T"], HipRule]:
    """Root (pelvis) height above the ground from the hip rule: `D(t) + lift(t)`.

    Arguments:
        groins: `[T, 2, 3]` groin positions, pelvis at the origin.
        foot_local: `[T, 2, P, 3]` foot points, pelvis at the origin.
        clearance: `[2, P]` sole clearances.
        gait, jump, rule, l_max, temperature, width: as `hip_rule`.
        up_axis: index of the up axis.

    Returns:
        `(height [T], HipRule)`.
    """
    leg = leg_heights(groins, foot_local, clearance, up_axis=up_axis,
                      temperature=temperature if rule == "smooth" else None)
    h = hip_rule(leg, gait, jump, rule=rule, l_max=l_max, temperature=temperature, width=width)
    return contact_height(foot_local, clearance, up_axis=up_axis) + h.lift, h
