"""Fit of the hip rule's `gait` and `jump` to a measured root height (optimistix)."""

from __future__ import annotations

from typing import NamedTuple

import jax.numpy as jnp
from jaxtyping import Array, ArrayLike, Float

from fourierjax._gait.common import check_rule
from fourierjax._gait.hip import root_height


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
    groins: Float[ArrayLike, "T 2 3"],
    foot_local: Float[ArrayLike, "T 2 P 3"],
    clearance: Float[ArrayLike, "2 P"],
    target_height: Float[ArrayLike, " T"],
    *,
    rule: str = "smooth",
    init: tuple[float, float] = (0.03, 1.0),
    l_max: Float[ArrayLike, ""] | None = None,
    width: Float[ArrayLike, ""] = 0.01,
    temperature: Float[ArrayLike, ""] | None = None,
    up_axis: int = 1,
    max_steps: int = 200,
) -> HipFit:
    """Fit `gait` and `jump` by least squares so the hip rule's root height matches a target.

    Minimises `Σ_t (root_height(t; gait, jump) − target(t))²` with optimistix
    Levenberg-Marquardt (gradients through the rule: use `"smooth"`, or `"continuous"` whose
    gait enters continuously; the faithful rule has no gradient in `gait`).

    Arguments:
        groins: `[T, 2, 3]` groin positions, pelvis at the origin.
        foot_local: `[T, 2, P, 3]` foot points, pelvis at the origin.
        clearance: `[2, P]` sole clearances.
        target_height: `[T]` measured root height above the ground (file units).
        rule, l_max, width, temperature: as `hip_rule`.
        init: `(gait, jump)` start.
        up_axis: index of the up axis.
        max_steps: Levenberg-Marquardt step limit.

    Returns:
        A `HipFit`.
    """
    import optimistix as optx

    check_rule(rule)
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
