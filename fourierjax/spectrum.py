"""Windowed amplitude spectra of sampled channels (NumPy; for plots and inspection of clips)."""

from __future__ import annotations

import numpy as np

from fourierjax._checks import number
from fourierjax.errors import UserError

__all__ = ["windowed_amplitude_spectrum"]


def windowed_amplitude_spectrum(x, frame_time_s: float,
                                pad_factor: int = 8) -> tuple[np.ndarray, np.ndarray]:
    """Hann-windowed, zero-padded single-sided amplitude spectrum per channel (Tilmanne Fig. 1).

    Each channel is centred, multiplied by a Hann window, zero-padded to ``pad_factor`` times
    its length and transformed; amplitudes are ``2 |c_k| / sum(window)``, so a sinusoid of
    amplitude A on a bin reads A (the window spreads it over neighbouring bins and the padding
    interpolates between them: the peaks of a short clip are smooth and easy to read). Bin 0
    holds ``|mean|`` of each channel. Unlike ``fourier.amplitude_spectrum`` (plain DFT, exact on
    bins), a frequency between bins loses little of its height.

    Arguments:
        x: ``[T, C]`` (or ``[T]``) samples, T >= 2; frame_time_s: seconds per sample;
        pad_factor: FFT length / T (>= 1).
    Returns:
        ``(freqs_hz [K], amplitude [K, C])`` with ``K = pad_factor * T // 2 + 1``.
    """
    x = np.asarray(x, np.float64)
    if x.ndim == 1:
        x = x[:, None]
    if x.ndim != 2 or x.shape[0] < 2:
        raise UserError(f"windowed_amplitude_spectrum: x must be [T >= 2, C], got {x.shape}")
    frame_time_s = number(frame_time_s, "windowed_amplitude_spectrum: frame_time_s", positive=True)
    if not np.isfinite(x).all():
        bad = np.argwhere(~np.isfinite(x))[0]
        raise UserError(f"windowed_amplitude_spectrum: x holds NaN or infinite values (first at "
                        f"sample {int(bad[0])}, channel {int(bad[1])})")
    if int(pad_factor) != pad_factor or pad_factor < 1:
        raise UserError(f"pad_factor: must be a whole number >= 1, got {pad_factor}")
    T = x.shape[0]
    n = int(pad_factor) * T
    w = np.hanning(T)
    mean = x.mean(axis=0)
    c = np.fft.rfft((x - mean) * w[:, None], n=n, axis=0)
    amp = 2 * np.abs(c) / w.sum()
    amp[0] = np.abs(mean)
    return np.fft.rfftfreq(n, d=frame_time_s), amp
