"""Shape buckets of `fit_motions` (issue 25, item 2): new clip lengths and batch sizes reuse
compiled code. Counted with the fit program's trace counter, never with a clock."""

import dataclasses

import numpy as np
import pytest
from jax import monitoring

from fourierjax import data
from fourierjax import motion as M
from fourierjax._fourier import _fit
from fourierjax._fourier._buckets import LARGE_BATCH, SMALL_BATCH, batch_plan, length_bucket
from fourierjax._motion import _pipeline
from fourierjax.body import infer_body_map
from fourierjax.errors import UserError


@pytest.fixture(scope="module")
def walk():
    m = data.load("07_01")
    return m, infer_body_map(m)


def _covers(plan, total):
    seen = [i for start, size in plan for i in range(start, start + size)]
    return seen[:total] == list(range(total)) and len(seen) - total < max(s for _, s in plan)


@pytest.mark.parametrize("total", [1, 7, 8, 13, 16, 17, 50, 64, 65, 120, 128, 129, 191, 200, 500])
def test_batch_plan_covers_the_batch_with_two_sizes(total):
    plan = batch_plan(total, 1000, 10**9)
    assert _covers(plan, total)
    assert {size for _, size in plan} <= {SMALL_BATCH, LARGE_BATCH}
    padding = sum(size for _, size in plan) - total
    assert padding < max(SMALL_BATCH, LARGE_BATCH // 2 + 1)


def test_batch_plan_keeps_to_the_memory_budget():
    # A budget for 40 clips: only small chunks; for 10: chunks of 10; for less than one: an error.
    assert {s for _, s in batch_plan(300, 1000, 40_000)} == {SMALL_BATCH}
    plan = batch_plan(25, 1000, 10_000)
    assert {s for _, s in plan} == {10} and _covers(plan, 25)
    with pytest.raises(UserError, match="max_memory"):
        batch_plan(3, 1000, 999)


def test_length_bucket():
    assert [length_bucket(n) for n in (1, 64, 65, 128, 129, 300)] == [64, 64, 128, 128, 256, 512]


def test_ten_batches_of_different_sizes_and_lengths_compile_at_most_twice(walk):
    """Acceptance: 10 fit_motions calls, each of another batch size, of clips of other lengths
    (cut from one walk: 140 to 250 frames), trace the fit program at most twice."""
    m, bm = walk
    rng = np.random.default_rng(0)
    before = _fit._fit_batched.num_traces()
    fits = []
    for size in (1, 2, 3, 5, 7, 9, 12, 15, 18, 21):
        lengths = rng.integers(140, 251, size)
        clips = [m[int(s):int(s) + int(n)] for s, n in zip(rng.integers(0, 60, size), lengths)]
        fits += M.fit_motions(clips, 2, segment=False, use_contacts=False, body_map=bm)
    assert _fit._fit_batched.num_traces() - before <= 2
    # The counter counts: another static option (N = 1) is one more program.
    more = _fit._fit_batched.num_traces()
    M.fit_motions(clips[:1], 1, segment=False, use_contacts=False, body_map=bm)
    assert _fit._fit_batched.num_traces() == more + 1
    assert all(f.successful for f in fits)
    hz = np.array([f.fundamental_hz for f in fits])
    assert np.all(np.abs(hz / np.median(hz) - 1) < 0.1)  # the same walk: the same frequency


def test_batch_size_sweep_compiles_at_most_twice_and_keeps_results(walk):
    """Acceptance: batches of 8, 13, 50, 120 and 500 clips trigger at most 2 compilations of the
    fit, and a clip's fit does not change with the batch it is in (beyond float32 rounding)."""
    m, bm = walk
    opts = dict(representation="euler", segment=False, use_contacts=False, start_frame=None,
                stop_frame=None, timings=None)
    base = [_pipeline._prepare(i, m[10 * i:10 * i + 200], bm, **opts) for i in range(5)]
    before = _fit._fit_batched.num_traces()
    # One clip first: it compiles the small bucket's program and the eager ops around it.
    _pipeline._fit_clips(base[:1], 2, "euler", np.float32, {}, None)
    out = {}
    compiled = []
    listener = lambda event, duration_secs, **_: compiled.append(event)  # noqa: E731
    monitoring.register_event_duration_secs_listener(listener)
    try:
        for size in (8, 13, 50, 120, 500):
            clips = [dataclasses.replace(base[i % 5], index=i) for i in range(size)]
            out[size] = _pipeline._fit_clips(clips, 2, "euler", np.float32, {}, None)
    finally:
        monitoring.unregister_event_duration_listener(listener)
    # Every XLA program of the sweep (fit, synthesis, metrics and any eager op): only the large
    # bucket's program is new.
    assert compiled.count("/jax/core/compile/backend_compile_duration") <= 2
    assert _fit._fit_batched.num_traces() - before <= 2
    for size, fits in out.items():
        for i in (0, 3, size - 1):
            a, b = fits[i], out[8][i % 5]
            np.testing.assert_allclose(a.omega_fit, b.omega_fit, rtol=1e-5, err_msg=str(size))
            np.testing.assert_allclose(a.raw_model.amplitude, b.raw_model.amplitude, atol=1e-4)
            assert a.alignment == b.alignment


def test_batch_sizes_through_the_whole_pipeline_compile_nothing_new(walk):
    """Acceptance, end to end: after one clip, `fit_motions` of 8, 13 and 50 clips (segment,
    glitch masks, features, contacts, fit, metrics; all in the small batch bucket) compiles no
    XLA program at all. The sweep above starts at `_fit_clips`, after the stages before the fit,
    so it missed eager rotation and FK programs on each chunk's concatenated frames (7 new
    programs per batch size whose concatenation reached a new length bucket)."""
    from fourierjax._programs import ProgramCount

    m, bm = walk
    M.fit_motions([m], 2, body_map=bm)  # one clip: compiles every program of the small bucket
    counts = {}
    for size in (8, 13, 50):
        with ProgramCount() as count:
            fits = M.fit_motions([m[3 * (k % 5):] for k in range(size)], 2, body_map=bm)
        counts[size] = (count.programs, dict(count.where))
        assert all(f.successful for f in fits)
    assert all(n == 0 for n, _ in counts.values()), counts


def test_padding_a_clip_leaves_its_fit_alone():
    """A clip padded with masked frames (as a bucket pads it) is fitted as the clip alone: the
    spectral peak is looked for on the grid of the clip's own length, not of the padded one
    (600 frames: an FFT 4x longer, whose extra bins moved the refined peak by 5e-5)."""
    from fourierjax import fourier
    from fourierjax.features import features_from_motion

    m = data.load("02_03")
    x, names = features_from_motion(m[:150], "euler")
    x = np.asarray(x, np.float32)
    out = []
    for T in (150, 600):
        f = np.repeat(x[-1:][None], T, axis=1)
        f[0, :150] = x
        mask = np.arange(T)[None, :] < 150
        out.append(fourier.fit_batch(f, m.frame_time_s, 2, mask=mask, channel_names=names))
    a, b = out
    np.testing.assert_allclose(b.omega_spectral, a.omega_spectral, rtol=1e-6)
    np.testing.assert_allclose(b.omega_fit, a.omega_fit, rtol=2e-5)
    np.testing.assert_allclose(b.model.amplitude, a.model.amplitude, atol=2e-4)
