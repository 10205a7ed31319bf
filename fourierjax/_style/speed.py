"""Joint speed over a gait cycle, and a limit on it for superposition (no limb flips).

A limb flip (an angle moved onto another branch, a swing extrapolated past what a body does) shows
as a joint that moves faster than in any clip the style algebra read. The limit measures the
largest pelvis-relative joint speed of a model's cycle through forward kinematics and scales the
weights of a superposition down, along their own line, until it is no faster than the clips.
"""

from __future__ import annotations

import functools
from typing import TYPE_CHECKING, Literal

import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float

from fourierjax._checks import concrete
from fourierjax._fourier._model import FourierModel
from fourierjax._jit import filter_jit
from fourierjax._math import safe_sqrt
from fourierjax._pytree import Record
from fourierjax._style.distance import _pelvis, _positions
from fourierjax.errors import UserError
from fourierjax.skeleton import Skeleton

if TYPE_CHECKING:
    from collections.abc import Sequence

    from fourierjax.body import BodyMap

Per = Literal["second", "radian", "both"]
_PER = ("second", "radian", "both")


def _cycle_speeds(model: FourierModel, skeleton: Skeleton, num_samples: int, pelvis: int):
    """(units per radian of phase, units per second): the largest chord between consecutive
    phase samples of the pelvis-relative cycle, over the phase step (unjitted)."""
    p = _positions(model, skeleton, num_samples, pelvis)  # [K, J, 3]
    d = jnp.roll(p, -1, axis=0) - p
    per_radian = jnp.max(safe_sqrt(jnp.sum(d * d, axis=-1))) * (num_samples / (2 * np.pi))
    return per_radian, per_radian * model.omega


_cycle_speeds_jit = filter_jit(_cycle_speeds)


def _check_int(where: str, name: str, value, low: int, high: int) -> int:
    if not isinstance(value, int | np.integer) or isinstance(value, bool) or not low <= value <= high:
        raise UserError(f"{where}: `{name}` must be an int in [{low}, {high}], got {value!r}")
    return int(value)


def _check_model(where: str, model) -> None:
    if not isinstance(model, FourierModel):
        raise UserError(f"{where}: expected a FourierModel, got {type(model).__name__}")
    if model.amplitude.ndim != 2:
        raise UserError(f"{where}: a stacked model (amplitude {model.amplitude.shape}); pass one model, or vmap")


def _check_skeleton(where: str, skeleton) -> None:
    if not isinstance(skeleton, Skeleton):
        raise UserError(f"{where}: `skeleton` must be a Skeleton, got {type(skeleton).__name__}")


def peak_joint_speed(
    model: FourierModel, skeleton: Skeleton, *, per: Literal["second", "radian"] = "second",
    num_samples: int = 256, body_map: BodyMap | None = None,
) -> Float[Array, ""]:
    """The largest joint speed over one synthesized cycle, relative to the pelvis.

    The cycle is posed at `num_samples` evenly spaced phases (`style.cycle_positions`: forward
    kinematics, the pelvis at the origin of the heading frame); the speed is the largest
    distance a joint covers between two consecutive phases, divided by the phase step
    (`per="radian"`, file units per radian of phase: how fast the POSE changes along the cycle,
    independent of the cadence) or by the time that step takes at the model's ω
    (`per="second"`, file units per second). A joint moved onto another angle branch, or a swing
    extrapolated beyond a body's, reads far above the clips the model was built from.

    Arguments:
        model: one FourierModel; skeleton: its Skeleton.
        per: `"second"` (default) or `"radian"`.
        num_samples: phases per cycle (static; the chord underestimates the true peak by
            about `(π / num_samples)² / 6` of it for a sinusoid).
        body_map: the rig's body map (its pelvis is the origin); None: inferred from the model's
            own cycle once per topology (`style.cycle_positions`).

    Returns:
        A scalar, differentiable in the model's coefficients and the skeleton's offsets.
    """
    where = "peak_joint_speed"
    _check_model(where, model)
    _check_skeleton(where, skeleton)
    if per not in ("second", "radian"):
        raise UserError(f"{where}: `per` must be 'second' or 'radian', got {per!r}")
    n = _check_int(where, "num_samples", num_samples, 3, 1 << 16)
    per_radian, per_second = _cycle_speeds_jit(model, skeleton, n, _pelvis(where, body_map, skeleton, model))
    return per_second if per == "second" else per_radian


class SpeedLimit(Record):
    """A bound on the joint speed of a superposition's result (`style.superpose(speed_limit=)`).

    Build it from the clips a style was taken from with `style.joint_speed_limit`, or give the
    bounds directly. At least one bound is needed; both act together.

    Arguments:
        skeleton: the Skeleton the models were fitted on.
        max_speed: largest pelvis-relative joint speed in file units per second, or None.
        max_phase_speed: largest in file units per radian of phase, or None.
        body_map: the rig's body map (its pelvis); None: inferred from the base at use.
        num_samples: phases per cycle of the measure (`style.peak_joint_speed`).
        iterations: halvings of the weight scale's bisection (its resolution is `2**-iterations`).
    """

    __leaves__ = ("skeleton", "max_speed", "max_phase_speed")
    __static__ = ("pelvis", "num_samples", "iterations")
    skeleton: Skeleton
    max_speed: Float[Array, ""] | None
    max_phase_speed: Float[Array, ""] | None
    pelvis: int | None
    num_samples: int
    iterations: int

    def __init__(self, skeleton: Skeleton, *, max_speed=None, max_phase_speed=None,
                 body_map: BodyMap | None = None, num_samples: int = 256, iterations: int = 20):
        where = "SpeedLimit"
        _check_skeleton(where, skeleton)
        if max_speed is None and max_phase_speed is None:
            raise UserError(f"{where}: give `max_speed` (units per second), `max_phase_speed` (units per "
                            "radian) or both; `style.joint_speed_limit(models, skeleton)` measures them from clips")
        self._set("skeleton", skeleton)
        for name, value in (("max_speed", max_speed), ("max_phase_speed", max_phase_speed)):
            if value is not None:
                value = jnp.asarray(value, dtype=skeleton.offsets.dtype)
                if value.shape != ():
                    raise UserError(f"{where}: `{name}` must be a scalar, got shape {value.shape}")
                c = concrete(value)
                if c is not None and not (np.isfinite(c) and c > 0):
                    raise UserError(f"{where}: `{name}` must be finite and > 0, got {float(c)!r}")
            self._set(name, value)
        self._set("pelvis", None if body_map is None else _pelvis(where, body_map, skeleton))
        self._set("num_samples", _check_int(where, "num_samples", num_samples, 3, 1 << 16))
        self._set("iterations", _check_int(where, "iterations", iterations, 1, 52))


def joint_speed_limit(
    models: Sequence[FourierModel], skeleton: Skeleton, *, per: Per = "both", margin: float = 1.0,
    body_map: BodyMap | None = None, num_samples: int = 256, iterations: int = 20,
) -> SpeedLimit:
    """A `SpeedLimit` at the fastest of `models`: no joint of a superposition then moves faster
    than in any clip it was built from (`margin` times that; per second, per radian or both).

    Pass the models a characteristic or transfer reads (for Unuma's eq. 8, the base and the two
    clips of the characteristic). Raises `UserError` for an empty list, a model that is not a
    FourierModel, or a margin that is not finite and > 0.
    """
    where = "joint_speed_limit"
    models = list(models) if not isinstance(models, FourierModel) else [models]
    if not models:
        raise UserError(f"{where}: `models` is empty; pass the clips' fitted models")
    for m in models:
        _check_model(where, m)
    if per not in _PER:
        raise UserError(f"{where}: `per` must be one of {_PER}, got {per!r}")
    if isinstance(margin, bool) or not isinstance(margin, int | float) or not (np.isfinite(margin) and margin > 0):
        raise UserError(f"{where}: `margin` must be a finite number > 0, got {margin!r}")
    _check_skeleton(where, skeleton)
    n = _check_int(where, "num_samples", num_samples, 3, 1 << 16)
    pelvis = _pelvis(where, body_map, skeleton, *models)
    speeds = [_cycle_speeds_jit(m, skeleton, n, pelvis) for m in models]
    phase = margin * jnp.max(jnp.stack([s[0] for s in speeds]))
    second = margin * jnp.max(jnp.stack([s[1] for s in speeds]))
    for name, v in (("per radian", phase), ("per second", second)):
        c = concrete(v)
        if c is not None and not (np.isfinite(c) and c > 0):
            raise UserError(f"{where}: the models' largest joint speed {name} is {float(c)!r}; "
                            "a limit needs a moving, finite cycle")
    # Without a body map the pelvis inferred above is kept per topology (`style.cycle_positions`):
    # `superpose` finds the same one for the base.
    return SpeedLimit(skeleton, max_speed=second if per in ("second", "both") else None,
                      max_phase_speed=phase if per in ("radian", "both") else None,
                      body_map=body_map, num_samples=n, iterations=iterations)


def excess(model: FourierModel, limit: SpeedLimit, pelvis: int) -> Float[Array, ""]:
    """The model's peak joint speed over the limit (the larger of the two ratios; <= 1: within)."""
    per_radian, per_second = _cycle_speeds(model, limit.skeleton, limit.num_samples, pelvis)
    ratios = []
    if limit.max_speed is not None:
        ratios.append(per_second / limit.max_speed)
    if limit.max_phase_speed is not None:
        ratios.append(per_radian / limit.max_phase_speed)
    return ratios[0] if len(ratios) == 1 else jnp.maximum(*ratios)


def limited_scale(superposed, inputs, limit: SpeedLimit, pelvis: int) -> Float[Array, ""]:
    """The largest `a` in [0, 1] (to `2**-iterations`) with `superposed(a, inputs)` within `limit`.

    1 when `superposed(1)` is within; otherwise bisection from `a = 0`, the base (0 when the
    base itself is faster than the limit); every step it keeps is within the limit. Where the
    limit binds (`0 < a < 1`, `excess(a) = 1`), its derivative is the implicit one,
    `da/dx = −(∂excess/∂x) / (∂excess/∂a)` for every input `x` (the superposition's inputs and
    the limit's bounds); elsewhere `a` is locally constant. The derivative is a custom JVP, so a
    call that is not differentiated compiles no backward pass (the program was 2x larger with it).
    """
    return _limited_scale(superposed, pelvis, inputs, limit)


@functools.partial(jax.custom_jvp, nondiff_argnums=(0, 1))
def _limited_scale(superposed, pelvis: int, inputs, limit: SpeedLimit):
    def ok(a):
        return excess(superposed(a, inputs), limit, pelvis) <= 1.0

    def halve(_, bracket):
        lo, hi = bracket
        mid = 0.5 * (lo + hi)
        inside = ok(mid)
        return jnp.where(inside, mid, lo), jnp.where(inside, hi, mid)

    dtype = limit.skeleton.offsets.dtype
    one, zero = jnp.ones((), dtype), jnp.zeros((), dtype)
    lo, _ = jax.lax.fori_loop(0, limit.iterations, halve, (zero, one))
    return jnp.where(ok(one), one, lo)


@_limited_scale.defjvp
def _limited_scale_jvp(superposed, pelvis: int, primals, tangents):
    inputs, limit = primals
    a = _limited_scale(superposed, pelvis, inputs, limit)

    def excess_at(s, x, lim):
        return excess(superposed(s, x), lim, pelvis)

    # On the boundary the value stays `a` and the tangent is −(∂e/∂x · dx) / (∂e/∂a).
    _, de = jax.jvp(lambda x, lim: excess_at(a, x, lim), (inputs, limit), tangents)
    slope = jax.grad(lambda s: excess_at(s, inputs, limit))(a)
    binding = (a > 0) & (a < 1) & (slope > 0)
    return a, jnp.where(binding, -de / jnp.where(binding, slope, 1.0), jnp.zeros_like(de))
