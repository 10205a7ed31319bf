"""Streamed `fit_motions` (issue 25, item 3): chunks read in a background thread while the one
before is fitted, a progress bar, per-stage timings and a chunk size within the memory budget."""

import threading

import numpy as np
import pytest

from fourierjax import data
from fourierjax import motion as M
from fourierjax._motion import _pipeline
from fourierjax.body import infer_body_map
from fourierjax.errors import UserError

OPTS = dict(segment=False, use_contacts=False)


@pytest.fixture(scope="module")
def clips():
    m = data.load("07_01")
    return [m[s:s + 180] for s in (0, 20, 40, 60, 80)], infer_body_map(m)


def test_a_generator_in_chunks_fits_as_a_list(clips):
    ms, bm = clips
    ref = M.fit_motions(ms, 2, body_map=bm, **OPTS)
    threads = []

    def gen():
        for m in ms:
            threads.append(threading.get_ident())
            yield m

    got = M.fit_motions(gen(), 2, body_map=bm, chunk_size=2, **OPTS)
    assert [g.frame_start for g in got] == [r.frame_start for r in ref]
    for g, r in zip(got, ref, strict=True):
        np.testing.assert_allclose(g.omega_fit, r.omega_fit, rtol=1e-6)
        np.testing.assert_allclose(g.raw_model.amplitude, r.raw_model.amplitude, atol=1e-6)
    # The clips are read by the background thread, not by the caller's.
    assert threads and threading.get_ident() not in threads


def test_iter_fit_motions_yields_each_chunk_as_it_is_fitted(clips):
    ms, bm = clips
    pulled = []

    def gen():
        for i, m in enumerate(ms):
            pulled.append(i)
            yield m

    it = M.iter_fit_motions(gen(), 2, body_map=bm, chunk_size=2, **OPTS)
    first = next(it)
    assert first.successful
    assert len(pulled) < len(ms)  # the last chunk is not read yet
    rest = list(it)
    assert len(rest) == len(ms) - 1 and pulled == list(range(len(ms)))


def test_paths_body_maps_per_clip_progress_and_timings(clips, capsys):
    _, bm = clips
    timings = {}
    paths = [data.path("07_01"), str(data.path("02_01"))]
    fits = M.fit_motions(paths, 2, body_map=iter([None, None]), progress=True, timings=timings,
                         **OPTS)
    assert [f.source for f in fits] == [str(p) for p in paths] and all(f.successful for f in fits)
    assert "fit_motions" in capsys.readouterr().err  # the tqdm bar
    assert {"read", "body_map", "segment", "glitch", "features", "contacts", "fit",
            "align_metrics"} <= set(timings)
    assert all(v >= 0 for v in timings.values())


def test_stream_errors(clips):
    ms, bm = clips
    with pytest.raises(UserError, match="no motions given"):
        M.fit_motions([], 2)
    with pytest.raises(UserError, match="2 body maps for 3 motions"):
        M.fit_motions(ms[:3], 2, body_map=[bm, bm])
    with pytest.raises(UserError, match="fewer body maps than motions"):
        M.fit_motions(iter(ms[:3]), 2, body_map=iter([bm]), **OPTS)
    with pytest.raises(UserError, match="more body maps than the 1 motions"):
        M.fit_motions(iter(ms[:1]), 2, body_map=iter([bm, bm]), **OPTS)


def test_stream_chunk_follows_the_memory_budget(clips):
    ms, bm = clips
    clip = _pipeline._prepare(0, ms[0], bm, representation="euler", start_frame=None,
                              stop_frame=None, timings=None, **OPTS)
    assert _pipeline._stream_chunk(clip, 3, None) == M.STREAM_CHUNK
    small = _pipeline._stream_chunk(clip, 3, 40 * 2**20)
    assert 1 <= small < M.STREAM_CHUNK
    tiny = _pipeline._stream_chunk(clip, 3, 1)
    assert tiny == 1
