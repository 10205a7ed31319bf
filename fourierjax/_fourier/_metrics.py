"""Fit quality and spectra: RMS error, variance explained, harmonic energy, amplitude spectrum."""

from __future__ import annotations

import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Bool, Float

from fourierjax._fourier._linear import _masked_mean
from fourierjax._fourier._model import FourierModel
from fourierjax._fourier._synthesis import synthesize
from fourierjax._fourier._validate import _check_one_model, _guard_frame_time
from fourierjax._linalg import matmul as _mm
from fourierjax.errors import UserError


def rms_error(
    model: FourierModel, features: Float[Array, "T C"], t_s: Float[Array, " T"],
    mask: Bool[Array, " T"] | None = None,
) -> Float[Array, " C"]:
    """Per-channel RMS of ``features - synthesize(model, t_s)`` over the masked frames.

    Raises:
        UserError when ``features`` is not ``[T, C]`` with the model's C, or ``t_s`` / ``mask``
        are not ``[T]`` (static shapes only).
    """
    fn = "rms_error"
    _check_one_model(fn, model)
    shape, C = np.shape(features), model.num_channels
    if len(shape) != 2 or shape[1] != C:
        raise UserError(f"{fn}: features shape {shape}, expected [T, {C}] (the model's "
                        f"{C} channel(s))")
    if np.shape(t_s) != shape[:1]:
        raise UserError(f"{fn}: t_s shape {np.shape(t_s)}, expected {shape[:1]} (one time per "
                        "frame of features)")
    if mask is not None and np.shape(mask) != shape[:1]:
        raise UserError(f"{fn}: mask shape {np.shape(mask)}, expected {shape[:1]}")
    r = jnp.asarray(features) - synthesize(model, t_s)
    w = jnp.ones(r.shape[:1], r.dtype) if mask is None else jnp.asarray(mask, r.dtype)
    return jnp.sqrt(_mm(w, r * r) / jnp.maximum(jnp.sum(w), 1.0))


def variance_explained(
    target: Float[Array, "T D"], approx: Float[Array, "T D"],
    mask: Bool[Array, " T"] | None = None,
) -> Float[Array, ""]:
    """``1 - sum |target - approx|^2 / sum |target - mean(target)|^2`` over masked frames.

    Raises:
        UserError when ``target`` and ``approx`` differ in shape, or ``mask`` is not ``[T]``.
    """
    fn = "variance_explained"
    shape = np.shape(target)
    if np.shape(approx) != shape or len(shape) < 1:
        raise UserError(f"{fn}: target shape {shape} and approx shape {np.shape(approx)} must "
                        "be the same [T, ...]")
    if mask is not None and np.shape(mask) != shape[:1]:
        raise UserError(f"{fn}: mask shape {np.shape(mask)}, expected {shape[:1]}")
    target, approx = jnp.asarray(target), jnp.asarray(approx)
    target = target.reshape(target.shape[0], -1)
    approx = approx.reshape(approx.shape[0], -1)
    w = jnp.ones(target.shape[:1], target.dtype) if mask is None else jnp.asarray(mask,
                                                                                 target.dtype)
    mean = _masked_mean(target, w)
    sse = jnp.sum(_mm(w, (target - approx) ** 2))
    sst = jnp.sum(_mm(w, (target - mean[None, :]) ** 2))
    return 1.0 - sse / jnp.maximum(sst, 1e-30)


def energy_per_harmonic(model: FourierModel) -> Float[Array, "C N"]:
    """Mean power of each harmonic per channel, ``A_n^2 / 2`` (channel units squared)."""
    return 0.5 * model.amplitude**2


def amplitude_spectrum(
    features: Float[Array, "T C"], frame_time_s: float
) -> tuple[Float[Array, " K"], Float[Array, "K C"]]:
    """Single-sided DFT amplitude spectrum per channel (Tilmanne Fig. 1).

    Returns ``(freqs_hz [K], amplitude [K, C])`` with ``amplitude = 2 |c_k|``, but ``|c_k|`` at
    0 Hz and, for even T, at the Nyquist frequency (bins with no mirror image), so that a
    sinusoid of amplitude A on a bin shows A.
    Raises:
        UserError for an empty ``features`` or (when concrete) a ``frame_time_s`` that is not
        positive and finite.
    """
    fn = "amplitude_spectrum"
    x = jnp.asarray(features)
    if x.ndim < 1 or x.shape[0] < 1:
        raise UserError(f"{fn}: features must be [T, C] with T >= 1, got shape {x.shape}")
    frame_time_s = _guard_frame_time(fn, frame_time_s)
    T = x.shape[0]
    c = jnp.fft.rfft(x, axis=0) / T
    k = np.arange(T // 2 + 1)
    # The 0 Hz bin and (even T) the Nyquist bin are real and not mirrored: no doubling.
    scale = np.where((k == 0) | (2 * k == T), 1.0, 2.0).reshape((-1,) + (1,) * (x.ndim - 1))
    amp = jnp.abs(c)
    amp = amp * scale.astype(amp.dtype)
    return jnp.fft.rfftfreq(T, d=frame_time_s), amp
