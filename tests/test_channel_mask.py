"""Per-channel fit masks (issue 20, item 5): a capture glitch on one joint masks that joint's
channels, not whole frames of every channel."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from fourierjax import data, fourier
from fourierjax import motion as M
from fourierjax._fourier._buckets import fill_masked
from fourierjax._memory import fit_bytes_per_clip
from fourierjax.body import infer_body_map
from fourierjax.errors import UserError

T, C, DT = 240, 6, 1 / 30
OMEGA = 2 * np.pi * 1.0


def _clip(seed=0):
    t = np.arange(T) * DT
    x = np.stack([np.sin(OMEGA * t + k) + 0.3 * np.cos(2 * OMEGA * t + k) + 0.1 * k
                  for k in range(C)], axis=1)
    return x + 0.01 * np.random.default_rng(seed).standard_normal(x.shape)


def _exact_amplitudes(x, keep, omega):
    """Least squares of one channel's used samples at a given omega (numpy, float64)."""
    t = np.arange(T) * DT
    basis = np.stack([np.ones(T)] + [f(k * omega * t) for f in (np.sin, np.cos) for k in (1, 2)], 1)
    c = np.linalg.lstsq(basis[keep], x[keep], rcond=None)[0]
    return np.hypot(c[1:3], c[3:5])


def test_a_glitch_on_one_channel_is_fitted_from_that_channels_other_frames():
    x = _clip()
    glitched = x.copy()
    glitched[100:130, 2] = np.nan  # a 1-s capture glitch of one channel
    mask = np.ones((T, C), bool)
    mask[100:130, 2] = False
    fit = fourier.fit(jnp.asarray(glitched, jnp.float32), DT, 2, mask=mask)
    clean = fourier.fit(jnp.asarray(x, jnp.float32), DT, 2)
    amp = np.asarray(fit.model.amplitude)
    # The glitchy channel: the least-squares fit of its used samples alone.
    np.testing.assert_allclose(amp[2], _exact_amplitudes(x[:, 2], mask[:, 2], float(fit.omega_fit)),
                               atol=2e-4)
    # The other channels keep every frame: as the fit of the clean clip.
    others = [0, 1, 3, 4, 5]
    np.testing.assert_allclose(amp[others], np.asarray(clean.model.amplitude)[others], atol=2e-5)
    assert int(fit.num_frames) == T  # no frame was dropped
    # A frame mask would have dropped 30 frames of every channel.
    frames = fourier.fit(jnp.asarray(np.nan_to_num(glitched), jnp.float32), DT, 2,
                         mask=mask.all(axis=1))
    assert int(frames.num_frames) == T - 30


def test_a_per_channel_mask_without_partial_frames_is_a_frame_mask():
    x = np.stack([_clip(0), _clip(1)])
    frames = np.ones((2, T), bool)
    frames[0, 200:] = False
    a = fourier.fit_batch(jnp.asarray(x, jnp.float32), jnp.full(2, DT), 2, mask=frames)
    b = fourier.fit_batch(jnp.asarray(x, jnp.float32), jnp.full(2, DT), 2,
                          mask=np.repeat(frames[..., None], C, axis=2))
    np.testing.assert_allclose(a.omega_fit, b.omega_fit, rtol=1e-6)
    np.testing.assert_allclose(a.model.amplitude, b.model.amplitude, atol=1e-6)
    np.testing.assert_array_equal(a.num_frames, b.num_frames)


def test_per_channel_mask_checks():
    x = _clip()
    mask = np.ones((T, C), bool)
    bad = x.copy()
    bad[5, 1] = np.nan  # NaN in a used entry: refused, as with a frame mask
    with pytest.raises(UserError, match="NaN"):
        fourier.fit(jnp.asarray(bad, jnp.float32), DT, 2, mask=mask)
    mask[5, 1] = False  # left out: fine
    assert np.isfinite(float(fourier.fit(jnp.asarray(bad, jnp.float32), DT, 2, mask=mask).omega_fit))
    with pytest.raises(UserError, match=r"mask shape \(240, 5\), expected \(240,\) or \(240, 6\)"):
        fourier.fit(jnp.asarray(x, jnp.float32), DT, 2, mask=np.ones((T, C - 1), bool))


def test_per_channel_mask_under_jit_and_in_chunks():
    x = np.stack([_clip(0), _clip(1), _clip(2)])
    mask = np.ones((3, T, C), bool)
    mask[1, 50:80, 4] = False
    ref = fourier.fit_batch(jnp.asarray(x, jnp.float32), jnp.full(3, DT), 2, mask=mask)
    jitted = jax.jit(lambda f, m: fourier.fit_batch(f, jnp.full(3, DT), 2, mask=m,
                                                    throw=False).omega_fit)
    np.testing.assert_allclose(jitted(jnp.asarray(x, jnp.float32), jnp.asarray(mask)),
                               ref.omega_fit, rtol=1e-5)
    # A memory budget of 2 clips: chunks (host loop), and under jit a lax.map of chunks.
    per_clip = fit_bytes_per_clip(T, C, 2, 4)
    small = fourier.fit_batch(jnp.asarray(x, jnp.float32), jnp.full(3, DT), 2, mask=mask,
                              max_memory=2 * per_clip)
    np.testing.assert_allclose(small.omega_fit, ref.omega_fit, rtol=1e-5)
    mapped = jax.jit(lambda f, m: fourier.fit_batch(f, jnp.full(3, DT), 2, mask=m, throw=False,
                                                    max_memory=2 * per_clip).omega_fit)
    np.testing.assert_allclose(mapped(jnp.asarray(x, jnp.float32), jnp.asarray(mask)),
                               ref.omega_fit, rtol=1e-5)


def test_fill_masked_interpolates_between_used_frames():
    x = jnp.asarray(np.arange(10.0)[:, None] * np.array([1.0, -2.0]))
    m = np.ones((10, 2), bool)
    m[3:6, 0] = False
    m[:2, 1] = False
    m[8:, 1] = False
    out = np.asarray(fill_masked(x.at[3:6, 0].set(jnp.nan), jnp.asarray(m)))
    np.testing.assert_allclose(out[:, 0], np.arange(10.0))  # linear inside
    np.testing.assert_allclose(out[:, 1], [-4, -4, -4, -6, -8, -10, -12, -14, -14, -14])  # ends held
    none = np.asarray(fill_masked(x, jnp.zeros((10, 2), bool)))
    np.testing.assert_array_equal(none, 0.0)


def test_one_glitchy_joint_masks_only_its_channels():
    """142_02's left arm glitches at frame 1140: the fit masks the arm's 3 channels at 25
    frames of its steady segment, and every other channel keeps them (before: 25 whole frames of
    all 96 channels were dropped)."""
    m = data.load("142_02")
    bm = infer_body_map(m)
    a, b = M.steady_segment(m, body_map=bm)
    sub = m[a:b]
    glitch = M.glitch_joints(sub)
    assert glitch.any(axis=0).sum() == 1 and sub.topology.names[int(np.argmax(glitch.any(0)))] == "LeftArm"
    np.testing.assert_array_equal(M.glitch_frames(sub), glitch.any(axis=1))
    mask = M.feature_mask(glitch, sub.topology, bm.pelvis)
    _, names = M.features_from_motion(sub, body_map=bm)
    assert mask.shape == (len(sub.channels), len(names))
    masked = {names[c] for c in np.flatnonzero(~mask.all(axis=0))}
    assert masked == {"LeftArm.Zrotation", "LeftArm.Yrotation", "LeftArm.Xrotation"}
    fit = M.fit_motions([m], 3, body_map=bm)[0]
    assert fit.successful
    assert fit.masked_frames == int(glitch.any(axis=1).sum()) > 0
    assert fit.masked_entries == 3 * fit.masked_frames
    assert fit.summary()["masked_glitch_entries"] == fit.masked_entries


def test_a_root_glitch_masks_the_root_channels():
    m = data.load("07_01")[:200]
    glitch = np.zeros((200, len(m.topology.names)), bool)
    glitch[50:60, 0] = True  # the pelvis (joint 0 on CMU)
    mask = M.feature_mask(glitch, m.topology, 0)
    _, names = M.features_from_motion(m)
    masked = {names[c] for c in np.flatnonzero(~mask.all(axis=0))}
    assert {"root.vx", "root.vz", "root.y"} <= masked
    assert not any(n.startswith("LeftUpLeg.") for n in masked)
