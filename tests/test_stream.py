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
    ms = ms + ms[:3]  # 8 clips, 4 chunks of 2
    pulled = []

    def gen():
        for i, m in enumerate(ms):
            pulled.append(i)
            yield m

    it = M.iter_fit_motions(gen(), 2, body_map=bm, chunk_size=2, **OPTS)
    first = next(it)
    assert first.successful
    # Chunk 0's clips wait one chunk for more of their length bucket (a batch is 16 clips):
    # they are fitted with chunk 1 while chunk 2 is read; chunk 3 is not read yet.
    assert len(pulled) <= 6
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


def test_the_stream_fits_whole_small_batches_as_they_come(monkeypatch):
    # Of each group (layout, weights, length bucket), whole batches of SMALL_BATCH clips are
    # fitted with the chunk that brings them (the fit of chunk k overlaps the reading of chunk
    # k + 1); the rest waits one chunk at most, oldest first.
    from fourierjax._fourier._buckets import SMALL_BATCH

    class Clip:
        def __init__(self, index, group):
            self.index, self.group = index, group

    monkeypatch.setattr(_pipeline, "_group_key", lambda c, kw: c.group)
    B = SMALL_BATCH
    first = [Clip(i, i % 2) for i in range(2 * (B + 4))]  # B + 4 clips of each group
    now, held, _ = _pipeline._hold_back([], first, {}, final=False)
    assert len(now) == 2 * B and {c.index for c in held} == {c.index for c in first[-8:]}
    second = [Clip(100 + i, 0) for i in range(3)] + [Clip(200 + i, 1) for i in range(B)]
    now, held2, _ = _pipeline._hold_back(held, second, {}, final=False)
    # group 0: 4 held + 3 new, under a batch: fitted whole; group 1: its 4 held go with its
    # first batch, 4 new clips wait
    assert {c.index for c in held} <= {c.index for c in now}
    assert [c.index for c in held2] == [200 + i for i in range(B - 4, B)]
    now, held3, _ = _pipeline._hold_back(held2, [], {}, final=True)
    assert len(now) == 4 and not held3


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


# -- the stages before the fit, vectorised over a chunk (issue 25, item 3) ---------------------
def _euler_continuous_loop(angles, order, valid=None):
    """`features.make_euler_continuous` as it was: one frame at a time."""
    from fourierjax import rotations

    a = np.array(angles, dtype=np.float64, copy=True)
    F = a.shape[0]
    flat = a.reshape(F, -1, 3)
    K = flat.shape[1]
    ok = np.ones((F, K), bool) if valid is None else np.broadcast_to(
        np.asarray(valid, bool).reshape(F, -1), (F, K))
    ref, cols, two_pi = np.zeros(K, int), np.arange(K), 2 * np.pi
    twins = rotations.euler_twin(flat.copy(), order)
    for t in range(1, F):
        prev = np.where(ok[t][:, None], flat[ref, cols], flat[t - 1])
        c0 = flat[t] + two_pi * np.round((prev - flat[t]) / two_pi)
        c1 = twins[t] + two_pi * np.round((prev - twins[t]) / two_pi)
        d0, d1 = np.sum((c0 - prev) ** 2, axis=-1), np.sum((c1 - prev) ** 2, axis=-1)
        flat[t] = np.where((d1 < d0 - 1e-12)[:, None], c1, c0)
        ref = np.where(ok[t] | ~ok[ref, cols], t, ref)
    return a


def test_euler_continuity_without_a_frame_loop_equals_the_loop():
    rng = np.random.default_rng(7)
    for order in ("ZYX", "ZXY", "XZX"):
        for trial in range(12):
            F, K = int(rng.integers(2, 150)), int(rng.integers(1, 5))
            # Random walks that wrap and pass near gimbal lock.
            a = np.cumsum(rng.normal(0, 0.35, (F, K, 3)), axis=0)
            a = (a + np.pi) % (2 * np.pi) - np.pi
            valid = [None, rng.random((F, K)) > 0.2, rng.random(F) > 0.1][trial % 3]
            got = M.make_euler_continuous(a, order, valid)
            assert np.array_equal(got, _euler_continuous_loop(a, order, valid)), (order, trial)
    # A real clip with a glitch (142_02's left arm at frame 1140) and a winding spine.
    m = data.load("142_02")[1000:1300]
    e = np.radians(m.channels[:, 3:].reshape(m.num_frames, -1, 3))
    valid = ~M.glitch_joints(m)  # [F, J]: every joint has 3 rotation channels
    assert (~valid).any()
    got = M.make_euler_continuous(e, "ZYX", valid)
    assert np.array_equal(got, _euler_continuous_loop(e, "ZYX", valid))
    assert np.abs(got - e).max() > 1.0  # something was unwrapped


def test_euler_continuity_in_blocks_of_columns_equals_the_loop():
    # More columns than one block (`_eulerscan._BLOCK`): every column chained (slices of the
    # columns), then a few with a glitch (the others picked out by index).
    from fourierjax import _eulerscan

    rng = np.random.default_rng(3)
    F, K = 40, 2 * _eulerscan._BLOCK + 37
    a = np.cumsum(rng.normal(0, 0.4, (F, K, 3)), axis=0)
    a = (a + np.pi) % (2 * np.pi) - np.pi
    valid = np.ones((F, K), bool)
    assert np.array_equal(M.make_euler_continuous(a, "ZXY", valid), _euler_continuous_loop(a, "ZXY", valid))
    valid[rng.integers(1, F, 9), rng.integers(0, K, 9)] = False
    assert np.array_equal(M.make_euler_continuous(a, "ZXY", valid), _euler_continuous_loop(a, "ZXY", valid))


@pytest.fixture(scope="module")
def chunk():
    """Short clips (one length bucket) of different lengths and skeletons: a CMU walk and a run,
    142_02 around its glitch (clipped so that the glitch's padding meets the clip's start), and
    a Bandai walk (its trajectory joint above the pelvis) when ../shared has it."""
    import pathlib

    from fourierjax.io.bvh import read_bvh

    ms = [data.load("07_01")[:200], data.load("142_02")[1134:1360], data.load("09_01")]
    bandai = pathlib.Path(__file__).resolve().parents[1] / ".." / "shared" / "data" / "mocap" / "bandai1" / "data"
    files = sorted(bandai.glob("dataset-1_walk_*_001.bvh"))[:1] if bandai.is_dir() else []
    return ms + [read_bvh(p)[:250] for p in files]


def _same_map(a, b) -> bool:
    """Two body maps equal but for float64 rounding in their directions and lengths: the batched
    path's pelvis matrices are a view into all the clips' (numpy takes another SIMD path; on one
    machine `facing` came out 1 ulp apart, -0.02344579054170553 against -0.023445790541705525)."""
    da, db = a.to_dict(), b.to_dict()
    if da.keys() != db.keys():
        return False
    for k in da:
        x, y = da[k], db[k]
        if isinstance(x, float) or (isinstance(x, list | tuple) and x and all(isinstance(v, float) for v in x)):
            if not np.allclose(x, y, rtol=1e-12, atol=1e-12):
                return False
        elif x != y:
            return False
    return True


@pytest.mark.parametrize("representation", ["euler", "tangent", "expmap"])
def test_prepare_chunk_equals_the_per_clip_path(chunk, representation, monkeypatch):
    from fourierjax._motion import _batch

    opts = dict(representation=representation, segment=True, use_contacts=True, start_frame=None,
                stop_frame=None, timings=None)
    ref = [_pipeline._prepare(k, m, None, **opts) for k, m in enumerate(chunk)]
    batched = []
    prepare_group = _batch._prepare_group

    def spy(items, **kw):
        batched.extend(it.index for it in items)
        return prepare_group(items, **kw)

    monkeypatch.setattr(_batch, "_prepare_group", spy)
    got = _batch.prepare_chunk([(k, m, None) for k, m in enumerate(chunk)], **opts)
    assert sorted(batched) == list(range(len(chunk)))  # every clip on the batched path
    assert [g.index for g in got] == list(range(len(chunk)))
    for r, g in zip(ref, got, strict=True):
        assert (g.start, g.stop, g.names) == (r.start, r.stop, r.names)
        assert np.array_equal(g.mask, r.mask)
        assert np.array_equal(g.left, r.left) and np.array_equal(g.right, r.right)
        np.testing.assert_allclose(g.features, r.features, rtol=1e-6, atol=1e-6)
        np.testing.assert_allclose(g.omega_steps, r.omega_steps, rtol=1e-6)
        assert _same_map(g.body_map, r.body_map)
    # The chunk holds heel strikes. (Its 142_02 cut holds no glitch frame once segmented: the
    # glitch path of the continuity is tested on 142_02[1000:1300] above.)
    assert any(len(g.left) for g in got)


def test_body_maps_of_a_chunk_are_each_clips_own(chunk, monkeypatch):
    # `_batch.infer_body_maps` poses all the clips of one skeleton in one FK: two cuts of one
    # clip (one skeleton, other frames) and clips of other skeletons in the same chunk each get
    # the map that inference of the clip alone gives.
    from fourierjax._body import _infer
    from fourierjax._motion import _batch

    clips = [chunk[0], data.load("07_01")[150:300], *chunk[1:]]
    moments = []
    many = _infer.moments_arrays
    monkeypatch.setattr(_infer, "moments_arrays", lambda *a: moments.append(a[2]) or many(*a))
    got = _batch.infer_body_maps(clips)
    assert moments  # the pelvis-frame means of each skeleton's clips, computed together
    assert len({(c.topology, c.offsets.tobytes()) for c in clips}) >= 3
    for c, g in zip(clips, got, strict=True):
        assert _same_map(g, infer_body_map(c))
    assert got[0].to_dict() != got[1].to_dict()  # the same skeleton, its own motion's map


def _bandai_clips(step):
    """Every ``step``-th clip of Bandai-1 (read in place from ../shared; skip without it)."""
    import pathlib

    from fourierjax.io.bvh import read_bvh

    bandai = pathlib.Path(__file__).resolve().parents[1] / ".." / "shared" / "data" / "mocap" / "bandai1" / "data"
    files = sorted(bandai.glob("dataset-1_*.bvh"))[::step] if bandai.is_dir() else []
    if not files:
        pytest.skip("Bandai-1 is not in ../shared")
    return [read_bvh(p) for p in files]


def test_body_maps_of_many_bandai_clips_are_each_clips_own(monkeypatch):
    # The pelvis-frame means of a skeleton's clips computed together (`moments_arrays`) and
    # the maps of the clips whose names decide legs and head inferred together
    # (`_infer.infer_named_many`) give each clip the map it gets alone, bit for bit (BodyMap's
    # == compares its floats exactly), on every Bandai-1 clip (several actors, one skeleton
    # each) and every bundled CMU clip, whole and cut.
    from fourierjax._body import _infer
    from fourierjax._motion import _batch

    clips = _bandai_clips(1) + [data.load(n) for n in data.list()] + [
        data.load("07_01")[150:300], data.load("02_01")[:40], data.load("142_08")[:3]]
    named = []
    many = _infer.infer_named_many
    monkeypatch.setattr(_infer, "infer_named_many", lambda *a: named.extend(many(*a)) or named[-len(a[1]):])
    got = _batch.infer_body_maps(clips)
    assert sum(m is not None for m in named) == len(clips)  # all through the batched path
    for c, g in zip(clips, got, strict=True):
        assert _same_map(g, infer_body_map(c))


def test_body_maps_inferred_together_fall_back_per_clip(monkeypatch):
    # A skeleton whose names do not decide its legs and head takes `infer` per clip.
    from fourierjax._body import _infer
    from fourierjax._motion import _batch

    clips = [data.load("07_01")[:60], data.load("142_08")[20:90]]
    monkeypatch.setattr(_infer, "_named_plan", lambda topology: None)
    assert _infer.infer_named_many(clips[0].topology, np.zeros((1, 2, 1, 3)), None, [[]], {}) == [None]
    for c, g in zip(clips, _batch.infer_body_maps(clips), strict=True):
        assert _same_map(g, infer_body_map(c))


def test_closed_loops_of_a_chunk_are_each_clips_own():
    # Bandai-1's short gait loops (their last frame repeats the first pose) and longer clips
    # that are no loops, concatenated: `_batch._closed_loops` is `closed_loop` of each.
    from fourierjax._motion import _batch
    from fourierjax._motion._clip import closed_loop

    clips = _bandai_clips(3)
    clips = [c for c in clips if c.topology == clips[0].topology]
    clips += [clips[0][:2], clips[1][5:40]]  # under 3 frames: never a loop
    cat, starts = _batch._concat(clips)
    want = [closed_loop(c) for c in clips]
    assert _batch._closed_loops(cat, starts) == want
    assert any(want) and not all(want)


def test_a_clips_fit_does_not_depend_on_the_clips_fitted_with_it(monkeypatch):
    # A run cut to 120 frames (length bucket 128) fitted alone, and streamed with the whole run
    # (173 frames: bucket 256) in one chunk: each clip is padded to its own bucket (the last session's
    # stream padded it to its chunk's longest), and the short clip's fit is the same.
    m = data.load("02_03")
    bm = infer_body_map(m)
    short, long = m[:120], m[:200]
    alone = M.fit_motions([short], 2, body_map=bm, **OPTS)[0]
    batches = []
    fit_chunk = _pipeline._fit_chunk

    def spy(chunk, *args):
        batches.append(({c.index for c in chunk}, max(len(c.features) for c in chunk)))
        return fit_chunk(chunk, *args)

    monkeypatch.setattr(_pipeline, "_fit_chunk", spy)
    paired = M.fit_motions([short, long], 2, body_map=bm, **OPTS)
    assert sorted(batches, key=lambda b: b[1]) == [({0}, 120), ({1}, 173)]  # one batch each
    assert all(f.successful for f in (alone, *paired))
    a, b = alone.raw_model, paired[0].raw_model
    np.testing.assert_allclose(paired[0].omega_spectral, alone.omega_spectral, rtol=1e-7)
    np.testing.assert_allclose(paired[0].omega_fit, alone.omega_fit, rtol=1e-7)
    np.testing.assert_allclose(b.amplitude, a.amplitude, rtol=1e-6, atol=1e-6)


@pytest.mark.parametrize("representation", ["euler", "tangent"])
def test_fit_motions_equals_the_per_clip_path(chunk, representation, monkeypatch):
    # The fitted models of the batched preparation (`_batch.prepare_chunk`) and of each clip
    # prepared alone (`_pipeline._prepare`) are the same, on bundled and Bandai clips.
    got = M.fit_motions(chunk, 3, representation)

    def per_clip(entries, **opts):
        return [_pipeline._prepare(i, m, bm, **opts) for i, m, bm in entries]

    monkeypatch.setattr(_pipeline, "prepare_chunk", per_clip)
    ref = M.fit_motions(chunk, 3, representation)
    for g, r in zip(got, ref, strict=True):
        assert g.successful and r.successful
        assert (g.frame_start, g.frame_stop, g.alignment) == (r.frame_start, r.frame_stop, r.alignment)
        np.testing.assert_allclose(g.omega_fit, r.omega_fit, rtol=1e-5)
        a, b = g.model, r.model
        np.testing.assert_allclose(a.offset, b.offset, atol=1e-4)
        np.testing.assert_allclose(a.amplitude * np.cos(a.phase), b.amplitude * np.cos(b.phase),
                                   atol=1e-4)
        np.testing.assert_allclose(a.amplitude * np.sin(a.phase), b.amplitude * np.sin(b.phase),
                                   atol=1e-4)


def test_sorted_within_equals_a_lexsort_per_column():
    from fourierjax import contacts as C

    rng = np.random.default_rng(1)
    n = np.array([1, 4, 60, 3, 129])
    seg = np.repeat(np.arange(len(n)), n)
    x = rng.normal(size=(len(seg), 2, 3))
    x[10:14] = x[9]  # ties
    x[20, 0, 1], x[21, 1, 2] = np.inf, -np.inf

    def lexsorted(x):
        flat = x.reshape(len(x), -1)
        return np.stack([flat[np.lexsort((flat[:, c], seg)), c] for c in range(flat.shape[1])],
                        axis=1).reshape(x.shape)

    assert np.array_equal(C._sorted_within(x, seg), lexsorted(x))
    x[30, 1, 0] = np.nan  # NaNs sort last within their clip, as the lexsort puts them
    assert np.array_equal(C._sorted_within(x, seg), lexsorted(x), equal_nan=True)


def test_clip_models_are_the_chunk_models_rows_bit_for_bit(clips, monkeypatch):
    # Each ClipFit's raw and aligned model are rows of its chunk program's stacked models,
    # sliced by the program (`_pipeline._chunk_impl`'s ``rows``): the same values, bit for bit,
    # as the host rows of the stacked models that were put back on the device before.
    import jax

    ms, bm = clips
    seen = []
    program = _pipeline._chunk_program

    def spy(*args, **kwargs):
        out = program(*args, **kwargs)
        seen.append(out)
        return out

    monkeypatch.setattr(_pipeline, "_chunk_program", spy)
    fits = M.fit_motions(ms, 2, body_map=bm, segment=False)
    assert len(seen) == 1
    res, _, (_, shifted), _ = seen[0]
    assert any(f.alignment == "left_heel_strike" for f in fits)
    for k, f in enumerate(fits):
        pairs = [(f.raw_model, res.model)]
        if f.alignment == "left_heel_strike":  # (the other alignments shift on the host)
            pairs.append((f.model, shifted))
        for got, stacked in pairs:
            for a, b in zip(jax.tree.leaves(got), jax.tree.leaves(stacked), strict=True):
                assert isinstance(a, jax.Array)
                np.testing.assert_array_equal(np.asarray(a), np.asarray(b)[k])


def _fields(fit):
    """Every field of a ClipFit, arrays and models as bytes (a BodyMap's == is exact)."""
    import dataclasses

    import jax

    out = []
    for f in dataclasses.fields(fit):
        v = getattr(fit, f.name)
        if f.name in ("model", "raw_model", "rms"):
            v = [(np.asarray(a).dtype.str, np.asarray(a).tobytes()) for a in jax.tree.leaves(v)]
        out.append((f.name, v))
    return out


def test_a_chunk_prepared_in_two_halves_at_once_fits_the_same(chunk, monkeypatch):
    # `_pipeline._prepare_split`: a chunk's preparation in two threads gives every ClipFit field
    # bit for bit (the clips of the first chunk prepared whole, of the others in halves), and
    # the timings hold both threads' seconds.
    ms = [*chunk, *chunk]
    monkeypatch.setattr(_pipeline, "SPLIT_MIN", 10**9)
    ref = M.fit_motions(ms, 2, chunk_size=len(chunk))
    halves = []
    split = _pipeline._prepare_split

    def spy(entries, helper, opts):
        halves.append(len(entries))
        return split(entries, helper, opts)

    monkeypatch.setattr(_pipeline, "SPLIT_MIN", 2)
    monkeypatch.setattr(_pipeline, "_prepare_split", spy)
    timings = {}
    got = M.fit_motions(ms, 2, chunk_size=len(chunk), timings=timings)
    assert [n for n in halves if n] == [len(chunk)]  # the second chunk: the first ran its programs whole
    assert {"body_map", "segment", "glitch", "features", "contacts"} <= set(timings)
    for g, r in zip(got, ref, strict=True):
        assert _fields(g) == _fields(r)


def test_an_error_in_either_half_is_raised(chunk, monkeypatch):
    from fourierjax._motion import _batch

    monkeypatch.setattr(_pipeline, "SPLIT_MIN", 2)
    for bad in (0, 3):  # the helper's half, this thread's half
        def failing(entries, bad=bad, **opts):
            if any(i == len(chunk) + bad for i, _, _ in entries):
                raise UserError(f"clip {bad}")
            return _batch.prepare_chunk(entries, **opts)

        monkeypatch.setattr(_pipeline, "prepare_chunk", failing)
        with pytest.raises(UserError, match=f"clip {bad}"):
            M.fit_motions([*chunk, *chunk], 2, chunk_size=len(chunk))


def test_chunks_fitted_two_at_once_fit_the_same(clips, monkeypatch):
    # `_pipeline._fit_jobs`: with a pool, the chunks of a program that has run are fitted two at
    # once (this thread and the pool's); a program's first chunk runs alone first (it compiles
    # once, not in two threads at once); every ClipFit field is the one-thread fit's, bit for bit.
    import concurrent.futures
    import dataclasses
    import time

    ms, bm = clips
    opts = dict(representation="euler", segment=False, use_contacts=False, start_frame=None,
                stop_frame=None, timings=None)
    base = [_pipeline._prepare(i, m, bm, **opts) for i, m in enumerate(ms)]
    prepared = [dataclasses.replace(base[i % len(base)], index=i) for i in range(48)]  # 3 x 16
    ref = _pipeline._fit_clips(prepared, 1, "euler", np.float32, {}, None)
    monkeypatch.setattr(_pipeline, "_RUN_PROGRAMS", set())  # as if the program were new
    calls = []
    fit_chunk = _pipeline._fit_chunk
    both = threading.Barrier(2, timeout=60)  # broken unless the last two chunks overlap

    def spy(*args):
        start = time.perf_counter()
        if calls:
            both.wait()
        out = fit_chunk(*args)
        calls.append((start, time.perf_counter(), threading.get_ident()))
        return out

    monkeypatch.setattr(_pipeline, "_fit_chunk", spy)
    timings = {}
    with concurrent.futures.ThreadPoolExecutor(1) as pool:
        got = _pipeline._fit_clips(prepared, 1, "euler", np.float32, {}, timings, pool=pool)
    first = min(calls)
    assert len(calls) == 3 and all(first[1] <= c[0] for c in calls if c != first)
    assert len({c[2] for c in calls}) == 2  # the two others: one in each thread
    assert {"fit", "align_metrics"} <= set(timings)
    for g, r in zip(got, ref, strict=True):
        assert _fields(g) == _fields(r)


def _winding_reference(x, names, keep, euler_only):
    """The rule of `_clip.winding_joints` / `_search_weights`, name by name (as it was written
    before the channel names were read once per layout)."""
    from fourierjax._motion._clip import _WINDING_SPAN
    from fourierjax.fourier import angle_channel_mask

    out = []
    if np.any(keep):
        for n, sp in zip(names, np.ptp(x[np.asarray(keep, bool)], axis=0), strict=True):
            joint = n.rsplit(".", 1)[0]
            angle = n.endswith("rotation") if euler_only else not n.startswith("root.")
            if angle and sp > _WINDING_SPAN and joint not in out:
                out.append(joint)
    if euler_only:
        return tuple(out)
    w = np.where([n.rsplit(".", 1)[0] in out for n in names], 0.0,
                 np.asarray(angle_channel_mask(names), float))
    return tuple(out), (tuple(float(v) for v in w) if out and w.any() else None)


@pytest.mark.parametrize("euler_only", [True, False])
def test_winding_joints_follow_the_rule_name_by_name(euler_only):
    # `_clip.winding_joints` / `_search_weights` read each layout's channel names once (a
    # cached table); the same joints, in the same order, and the same weights as the rule read
    # name by name, on Bandai-1's windings (its `Spine` near gimbal lock), the bundled clips
    # and a few made-up spans.
    from fourierjax._motion import _clip
    from fourierjax.features import features_from_motion

    try:
        bandai = _bandai_clips(20)
    except pytest.skip.Exception:
        bandai = []
    cases = []
    for m in [*bandai, data.load("07_01"), data.load("142_02")]:
        for rep in ("euler", "tangent", "expmap"):
            x, names = features_from_motion(m, rep)
            cases += [(x, names, np.ones(len(x), bool)), (x, names, np.arange(len(x)) % 3 == 0)]
    x, names, _ = cases[0]
    rng = np.random.default_rng(0)
    for _ in range(20):  # random joints winding, some frames kept or none
        y = x + rng.normal(size=x.shape[1]) * 4.0 * np.linspace(0, 1, len(x))[:, None]
        cases.append((y, names, rng.random(len(x)) < rng.choice([0.0, 0.5, 1.0])))
    assert any(_clip.winding_joints(*c, euler_only=euler_only) for c in cases)
    for c in cases:
        ref = _winding_reference(*c, euler_only)
        if euler_only:
            assert _clip.winding_joints(*c) == ref
        else:
            assert _clip.winding_joints(*c, euler_only=False) == ref[0]
            assert _clip._search_weights(*c) == ref[1]
