"""Argument checks of the Fourier entry points: static ones at trace time, value ones on concrete inputs."""

from __future__ import annotations

import math

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from fourierjax.errors import UserError
from fourierjax.features import REPRESENTATIONS


def _is_traced(*values) -> bool:
    return any(isinstance(v, jax.core.Tracer) for v in values)


def _check_real(fn: str, name: str, value) -> float:
    """``value`` as a float (a static option: a real number, not NaN), else a UserError."""
    if isinstance(value, bool | np.bool_) or not isinstance(value, int | float | np.integer
                                                             | np.floating):
        raise UserError(f"{fn}: {name} must be a real number, got {value!r} "
                        f"({type(value).__name__})")
    if math.isnan(value):
        raise UserError(f"{fn}: {name} must be a real number, got NaN")
    return float(value)


def _check_representation(fn: str, representation) -> None:
    if representation not in REPRESENTATIONS:
        raise UserError(f"{fn}: representation {representation!r} not in {REPRESENTATIONS}")


def _check_frame_time(fn: str, frame_time_s) -> np.ndarray | None:
    """Frame times (scalar or array) must be positive and finite; skipped when traced.
    Returns them as a host array (None when traced)."""
    if _is_traced(frame_time_s):
        return None
    try:
        dt = np.asarray(frame_time_s, float)
    except (TypeError, ValueError):
        dt = np.asarray(np.nan)
    if not (np.isfinite(dt).all() and (dt > 0).all()):
        bad = int((~(np.isfinite(dt) & (dt > 0))).sum())
        got = dt.tolist() if dt.size <= 8 else f"{dt.size} values, {bad} of them bad"
        raise UserError(f"{fn}: frame_time_s must be positive seconds, got {got}")
    return dt


def _guard_frame_time(fn: str, frame_time_s):
    """`_check_frame_time` that also holds under jit: a traced frame time is refused at run
    time (`equinox.error_if`). Returns ``frame_time_s`` (guarded when traced)."""
    if not _is_traced(frame_time_s):
        _check_frame_time(fn, frame_time_s)
        return frame_time_s
    dt = jnp.asarray(frame_time_s)
    return eqx.error_if(dt, ~jnp.all(jnp.isfinite(dt) & (dt > 0)),
                        f"{fn}: frame_time_s must be positive seconds")


def _as_float_features(fn: str, features):
    """Real floating features: integer and bool samples are cast to the default float dtype
    (as ``fourierjax.rotations`` does); complex or non-numeric ones are a UserError."""
    dtype = np.dtype(features.dtype)
    if jnp.issubdtype(dtype, jnp.floating):
        return features
    if dtype == np.bool_ or jnp.issubdtype(dtype, jnp.integer):
        return features.astype(jnp.result_type(float))
    raise UserError(f"{fn}: features must be real numbers, got dtype {dtype}")


def _used_frames(mask) -> np.ndarray:
    """Frames a (concrete) mask uses, per clip: its nonzero entries along the last axis."""
    return np.sum(np.asarray(mask) != 0, axis=-1)


def _check_mask_values(fn: str, mask) -> None:
    """A concrete mask is booleans, or weights that are finite and >= 0."""
    m = np.asarray(mask)
    if m.dtype == np.bool_:
        return
    try:
        m = m.astype(float)
    except (TypeError, ValueError):
        raise UserError(f"{fn}: mask must be booleans, got dtype {m.dtype}") from None
    if not (np.isfinite(m).all() and (m >= 0).all()):
        raise UserError(f"{fn}: mask must be booleans (or finite weights >= 0); it holds "
                        f"{int((~(np.isfinite(m) & (m >= 0))).sum())} negative or NaN value(s)")


def _check_finite_used(fn: str, features, mask) -> None:
    """The frames a fit uses must be finite (frames left out by ``mask`` may hold NaN). A JAX
    array is read back to the host for this (zero-copy on CPU)."""
    bad = ~np.isfinite(np.asarray(features))
    if mask is not None:
        bad &= (np.asarray(mask) != 0)[..., None]
    if bad.any():
        first = tuple(int(i) for i in np.argwhere(bad)[0])
        raise UserError(
            f"{fn}: features hold {int(bad.sum())} NaN or infinite value(s) in frames the fit "
            f"uses, the first at index {first}; leave such frames out with mask="
        )


def _check_varies(fn: str, features, mask, channel_weights) -> None:
    """A clip whose weighted channels are all constant over the used frames has no fundamental
    frequency: the omega search would return an arbitrary value. Refused, naming the clip."""
    x = np.asarray(features)
    used = np.ones(x.shape[:-1], bool) if mask is None else np.broadcast_to(
        np.asarray(mask) != 0, x.shape[:-1])
    lo = np.where(used[..., None], x, np.inf).min(axis=-2)
    hi = np.where(used[..., None], x, -np.inf).max(axis=-2)
    varies = (hi - lo) > 1e-6 * (1.0 + np.maximum(np.abs(hi), np.abs(lo)))
    weighted = np.asarray(channel_weights, float) > 0
    flat = np.atleast_1d(~np.any(varies & weighted, axis=-1))
    if flat.any():
        i = int(np.flatnonzero(flat)[0])
        where = "" if x.ndim == 2 else f" in clip {i}" + (
            f" (and {int(flat.sum()) - 1} other clip(s))" if flat.sum() > 1 else "")
        raise UserError(
            f"{fn}: features are constant over the used frames on every weighted channel{where}: "
            "a motion that does not move has no fundamental frequency to fit; leave it out (or "
            "build its model directly: FourierModel with zero amplitudes)"
        )


def _check_one_model(fn: str, model) -> None:
    """One (unstacked) model: vmap over stacked ones (static shapes only)."""
    if model.offset.ndim != 1:
        raise UserError(
            f"{fn}: `model` must be one model (offset [C]), got offset shape "
            f"{model.offset.shape}; vmap over stacked models (or use synthesize_batch)"
        )


def _names_tuple(names):
    """`channel_names` as a tuple (a static field must be hashable) when given as a list, tuple
    or 1-D NumPy string array; anything else is left for `__check_init__` to refuse."""
    if isinstance(names, np.ndarray) and names.ndim == 1 and names.dtype.kind == "U":
        return tuple(str(n) for n in names)
    if isinstance(names, list | tuple):
        return tuple(names)
    return names


def _as_array(x):
    # numpy for host data: jit transfers it itself, while an eager `jnp.asarray` compiles a
    # small program of its own on a first call. JAX arrays (sharded ones too) pass through.
    return x if isinstance(x, jax.Array) else np.asarray(x)
