"""The position variance explained of `fit_motions` (batch axes minor FK) against the per-clip
formula it replaced (`_motion._poses._position_ve_impl`: vmapped FK of each frame)."""

import jax
import numpy as np
import pytest

from fourierjax import data, fourier
from fourierjax import motion as M
from fourierjax._motion import _pipeline
from fourierjax._motion._poses import _position_ve_impl
from tests import rigs


@pytest.fixture(scope="module")
def clips():
    walk, run = data.load("07_01"), data.load("09_01")
    # The Unreal rewrite has a root joint above the pelvis (the pelvis is not joint 0).
    return [walk[:150], run, rigs.unreal(walk)[:200], rigs.unreal(run)]


@pytest.mark.parametrize("representation", ["euler", "tangent", "expmap"])
def test_fit_motions_position_ve_equals_the_per_clip_formula(clips, representation, monkeypatch):
    calls = []
    program = _pipeline._chunk_program

    def recorded(*args, **kwargs):
        out = program(*args, **kwargs)
        calls.append((args, kwargs, out))
        return out

    monkeypatch.setattr(_pipeline, "_chunk_program", recorded)
    fits = M.fit_motions(clips, 3, representation)
    assert {kw["pelvis"] for _, kw, _ in calls} == {0, 1}
    for args, kw, (res, pve, *_) in calls:
        skeleton, feats, mask, dts = args[:4]
        t = np.arange(feats.shape[1])[None, :] * np.asarray(dts)[:, None]
        xhat = fourier.synthesize_batch(res.model, jax.numpy.asarray(t, feats.dtype))
        frames = mask.any(axis=2) if mask.ndim == 3 else mask
        old = jax.vmap(lambda s, a, b, m, kw=kw: _position_ve_impl(
            s, a, b, m, kw["representation"], kw["pelvis"]))(skeleton, feats, xhat, frames)
        np.testing.assert_allclose(np.asarray(pve), np.asarray(old), rtol=0, atol=2e-6)
    assert all(0.5 < f.variance_explained_positions < 1.0 for f in fits)
