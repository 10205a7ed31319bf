"""Tests of fourierjax.spectrum: amplitudes of sinusoids, the mean at 0 Hz, a direct DFT oracle."""

import numpy as np
import pytest

from fourierjax.errors import UserError
from fourierjax.spectrum import windowed_amplitude_spectrum


def test_sinusoids_read_their_amplitude_on_and_between_bins():
    dt, T = 1 / 120, 240
    t = np.arange(T) * dt
    # 3.0 Hz is on a bin of the unpadded DFT; 1.13 Hz is between them.
    x = np.stack([0.7 + 2.5 * np.sin(2 * np.pi * 3.0 * t), 1.5 * np.cos(2 * np.pi * 1.13 * t)],
                 axis=1)
    freqs, amp = windowed_amplitude_spectrum(x, dt)
    assert freqs.shape == (8 * T // 2 + 1,) and amp.shape == (len(freqs), 2)
    np.testing.assert_allclose(freqs[1], 1 / (8 * T * dt))
    np.testing.assert_allclose(amp[0], np.abs(x.mean(axis=0)))  # bin 0: |mean|
    for c, (f0, a0) in enumerate(((3.0, 2.5), (1.13, 1.5))):
        k = np.argmax(amp[1:, c]) + 1
        assert abs(freqs[k] - f0) <= freqs[1]
        assert amp[k, c] == pytest.approx(a0, rel=0.02)
    # A 1-D signal is one channel.
    f1, a1 = windowed_amplitude_spectrum(x[:, 0], dt)
    np.testing.assert_allclose(a1[:, 0], amp[:, 0], rtol=1e-12, atol=1e-12)


def test_matches_a_direct_windowed_dft():
    rng = np.random.default_rng(0)
    dt, T, pad = 0.01, 50, 4
    x = rng.normal(size=(T, 3))
    freqs, amp = windowed_amplitude_spectrum(x, dt, pad_factor=pad)
    w = 0.5 - 0.5 * np.cos(2 * np.pi * np.arange(T) / (T - 1))  # symmetric Hann
    t = np.arange(T) * dt
    for k in (1, 7, 33, len(freqs) - 1):
        e = np.exp(-2j * np.pi * freqs[k] * t)
        want = 2 * np.abs(((x - x.mean(0)) * w[:, None] * e[:, None]).sum(0)) / w.sum()
        np.testing.assert_allclose(amp[k], want, rtol=1e-9, atol=1e-12)


@pytest.mark.parametrize("args, message", [
    ((np.zeros((1, 2)), 0.01), "T >= 2"),
    ((np.zeros((4, 2, 2)), 0.01), "x must be"),
    ((np.zeros((4, 2)), 0.0), "frame_time_s"),
    ((np.zeros((4, 2)), float("inf")), "frame_time_s must be finite"),
    ((np.array([[0.0], [np.nan], [1.0]]), 0.01), r"NaN or infinite values \(first at sample 1, channel 0\)"),
    ((np.zeros((4, 2)), 0.01, 0), "pad_factor"),
    ((np.zeros((4, 2)), 0.01, 2.5), "pad_factor"),
])
def test_bad_input_names_the_argument(args, message):
    with pytest.raises(UserError, match=message):
        windowed_amplitude_spectrum(*args)
