"""Per-clip outcome of a fit (as optimistix's `RESULTS`): one integer code per clip and its message."""

from __future__ import annotations

import enum

import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Bool, Float, Int


class FitStatus(enum.IntEnum):
    """Outcome of one clip's fit; `FitResult.result` holds these codes (int32)."""

    SUCCESSFUL = 0
    TOO_SHORT = 1
    TOO_FEW_CYCLES = 2
    CONSTANT = 3
    NONFINITE = 4
    BAD_FRAME_TIME = 5
    ON_SEARCH_FLOOR = 6
    BAD_WEIGHTS = 7

    @property
    def message(self) -> str:
        """One line saying what is wrong with a clip of this status."""
        return _MESSAGES[self]


_MESSAGES = {
    FitStatus.SUCCESSFUL: "fitted",
    FitStatus.TOO_SHORT: "too few used frames for the number of harmonics (2N + 1 coefficients "
                         "per channel, plus omega)",
    FitStatus.TOO_FEW_CYCLES: "the used frames cover fewer than MIN_CYCLES (0.95) cycles of the "
                              "fitted fundamental; give a longer clip (at least one whole cycle)",
    FitStatus.ON_SEARCH_FLOOR: "the least-squares fundamental lies on the lowest frequency the "
                               "used frames cover MIN_CYCLES (0.95) times, and the residual falls "
                               "further below it; give a longer clip (at least one whole cycle)",
    FitStatus.CONSTANT: "features are constant over the used frames on every weighted channel: no "
                        "fundamental frequency to fit",
    FitStatus.NONFINITE: "features hold NaN or infinite values in frames the fit uses",
    FitStatus.BAD_FRAME_TIME: "frame_time_s is not positive and finite",
    FitStatus.BAD_WEIGHTS: "mask holds negative or NaN weights, omega_steps is not positive (NaN: "
                           "unknown), or channel_weights are negative, NaN or all zero",
}

#: Messages by code, for `equinox.branched_error_if`.
MESSAGES = tuple(_MESSAGES[s] for s in FitStatus)


def clip_status(
    features: Float[Array, "T C"],
    w: Float[Array, " T"],
    channel_weights: Float[Array, " C"],
    frame_time_s: Float[Array, ""],
    omega: Float[Array, ""],
    num_harmonics: int,
    min_cycles: float,
    floor_tolerance: float,
    omega_steps: Float[Array, ""],
) -> Int[Array, ""]:
    """`FitStatus` code of one clip from its raw features (before masked frames are zeroed) and
    its fitted omega; traceable, so the checks hold under jit and vmap. The first failing check
    in the order of `FitStatus` wins.

    Arguments:
        features: the clip's samples; w: frame weights (0: left out); channel_weights: the ω
            search's weights; frame_time_s: seconds; omega: the fitted fundamental (rad/s);
        num_harmonics: N; min_cycles, floor_tolerance: the cycle rule of `fit`;
        omega_steps: the step-based ω (NaN: unknown).

    Returns:
        int32 scalar.
    """
    used = w > 0
    need = 2 * num_harmonics + 2
    too_short = jnp.sum(used) < need
    nonfinite = jnp.any(~jnp.isfinite(features) & used[:, None])
    seen = used[:, None] & jnp.isfinite(features)
    lo = jnp.min(jnp.where(seen, features, jnp.inf), axis=0)
    hi = jnp.max(jnp.where(seen, features, -jnp.inf), axis=0)
    varies = (hi - lo) > 1e-6 * (1.0 + jnp.maximum(jnp.abs(hi), jnp.abs(lo)))
    constant = ~jnp.any(varies & (channel_weights > 0))
    bad_dt = ~(jnp.isfinite(frame_time_s) & (frame_time_s > 0))
    first = jnp.argmax(used)
    last = used.shape[0] - 1 - jnp.argmax(used[::-1])
    cycles = (last - first + 1).astype(omega.dtype) * frame_time_s * omega / (2 * np.pi)
    few_cycles = ~(cycles >= min_cycles)
    on_floor = ~(cycles >= min_cycles * (1 + floor_tolerance))
    bad_weights = (~jnp.all(jnp.isfinite(w) & (w >= 0))
                   | ~(jnp.isnan(omega_steps) | (jnp.isfinite(omega_steps) & (omega_steps > 0)))
                   | ~jnp.all(jnp.isfinite(channel_weights) & (channel_weights >= 0))
                   | ~jnp.any(channel_weights > 0))
    code = jnp.int32(FitStatus.SUCCESSFUL)
    # Later checks first, so that the earlier (more basic) ones overwrite them.
    for flag, status in ((on_floor, FitStatus.ON_SEARCH_FLOOR),
                         (few_cycles, FitStatus.TOO_FEW_CYCLES), (constant, FitStatus.CONSTANT),
                         (nonfinite, FitStatus.NONFINITE), (too_short, FitStatus.TOO_SHORT),
                         (bad_dt, FitStatus.BAD_FRAME_TIME), (bad_weights, FitStatus.BAD_WEIGHTS)):
        code = jnp.where(flag, jnp.int32(status), code)
    return code


def describe(result: Int[Array, "*B"] | int) -> list[str] | str:
    """Messages of status codes (a list for an array of codes)."""
    codes = np.asarray(result)
    if codes.ndim == 0:
        return FitStatus(int(codes)).message
    return [FitStatus(int(c)).message for c in codes.ravel()]


def ok(result: Int[Array, "*B"]) -> Bool[Array, "*B"]:
    """True where a clip was fitted."""
    return jnp.asarray(result) == FitStatus.SUCCESSFUL
