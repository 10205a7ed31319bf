"""Memory bounds: `_memory.check_bytes`, chunked `fit_batch`, capped noise harmonics, the BVH
reader's working memory."""

import functools
import pathlib
import tracemalloc

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from fourierjax import _memory, data, fourier, style
from fourierjax._fourier import _fit
from fourierjax.errors import UserError
from fourierjax.io import _bvh_parse
from fourierjax.io.bvh import BVHError, parse_bvh, read_bvh

# -- check_bytes and the budget ------------------------------------------------------------


def test_check_bytes_names_the_argument_the_bytes_and_the_limit():
    assert _memory.check_bytes("x", 10, 10) == 10
    with pytest.raises(UserError) as e:
        _memory.check_bytes("synth: --frames=1e9", 24 * 10**9, 6 * 10**9)
    msg = str(e.value)
    assert "synth: --frames=1e9" in msg and "24.0 GB" in msg and "6.0 GB" in msg
    for bad in (float("nan"), float("inf"), 10**30):
        with pytest.raises(UserError):
            _memory.check_bytes("x", bad, 10**12)


def test_the_default_budget_is_a_quarter_of_the_machine():
    total = _memory.machine_memory()
    assert total > 2**28
    assert _memory.default_limit() == int(total * 0.25)
    assert _memory.resolve_limit("m", None) == _memory.default_limit()
    assert _memory.resolve_limit("m", 1e6) == 10**6
    for bad in (0, -1, float("nan"), "lots", True):
        with pytest.raises(UserError, match="m must be"):
            _memory.resolve_limit("m", bad)


def test_chunks_are_equal_and_fit_the_budget():
    assert _memory.chunk_sizes(100, 10, 10**6) == (1, 100)
    n, c = _memory.chunk_sizes(201, 10, 1000)  # 100 fit: 3 chunks of 67
    assert (n, c) == (3, 67) and n * c >= 201 and c * 10 <= 1000
    with pytest.raises(UserError, match="batch would need 2.0 kB"):
        _memory.chunk_sizes(5, 2000, 1000)


def test_the_fit_estimate_bounds_xla_s_own_count():
    """The per-clip estimate is at least the compiled program's temporaries plus its input,
    and not far above them (a 2x overestimate would halve the chunks for nothing)."""
    opts = _fit._check_fit_options("t", 4, "euler", 0.4, 3.0, 0.25, 33, 40, 0.1)
    B, T, C = 64, 200, 30
    f = jax.jit(functools.partial(_fit._fit_batched_impl, **opts))
    ma = f.lower(jax.ShapeDtypeStruct((B, T, C), jnp.float32), None,
                 jax.ShapeDtypeStruct((B,), jnp.float32), None,
                 jax.ShapeDtypeStruct((C,), jnp.float32)).compile().memory_analysis()
    measured = (ma.temp_size_in_bytes + ma.argument_size_in_bytes + ma.output_size_in_bytes) / B
    estimate = _memory.fit_bytes_per_clip(T, C, 4, 4)
    assert measured <= estimate <= 1.5 * measured


# -- fit_batch in chunks -------------------------------------------------------------------


def _clips(B, T=120, C=5, seed=0):
    rng = np.random.default_rng(seed)
    t = np.arange(T) / 60.0
    om = rng.uniform(4, 8, B)[:, None, None]
    ph = rng.uniform(-3, 3, (B, 1, C))
    x = np.sin(om * t[None, :, None] + ph) + 0.3 * np.sin(2 * om * t[None, :, None])
    x = x + 0.01 * rng.standard_normal((B, T, C))
    return x.astype(np.float32), np.full(B, 1 / 60, np.float32)


@pytest.fixture(scope="module")
def batch():
    """70 clips (>= 64: the batch size at which the 2-core LAPACK hang used to appear) and
    their unchunked fit."""
    feats, dt = _clips(70)
    return feats, dt, fourier.fit_batch(feats, dt, 3)


def _assert_same(a, b):
    for x, y in zip(jax.tree.leaves(a), jax.tree.leaves(b), strict=True):
        np.testing.assert_allclose(np.asarray(y, float), np.asarray(x, float), rtol=0, atol=1e-6)


def test_chunked_fit_equals_the_unchunked_fit_with_one_compiled_program(batch):
    feats, dt, whole = batch
    per_clip = _memory.fit_bytes_per_clip(120, 5, 3, 4)
    before = _fit._fit_batched.num_traces()
    chunked = fourier.fit_batch(feats, dt, 3, max_memory=per_clip * 16)  # 5 chunks of 14
    assert _fit._fit_batched.num_traces() - before == 1  # every chunk: one program
    _assert_same(whole, chunked)
    assert chunked.rms.shape == whole.rms.shape == (70, 5)
    assert isinstance(chunked.model.amplitude, jax.Array)


def test_chunked_fit_with_mask_and_steps_equals_the_unchunked_fit():
    feats, dt = _clips(9, seed=3)
    mask = np.ones(feats.shape[:2], bool)
    mask[2, -10:] = False
    steps = np.full(9, np.nan, np.float32)
    steps[4] = 6.0
    kw = dict(mask=mask, omega_steps=steps, throw=False)
    whole = fourier.fit_batch(feats, dt[0], 3, **kw)  # a shared frame time
    chunked = fourier.fit_batch(feats, dt[0], 3, max_memory=_memory.fit_bytes_per_clip(
        120, 5, 3, 4) * 4, **kw)
    _assert_same(whole, chunked)


def test_chunks_under_a_callers_jit_equal_the_unchunked_fit(batch):
    feats, dt, whole = batch
    per_clip = _memory.fit_bytes_per_clip(120, 5, 3, 4)
    amp = jax.jit(lambda f: fourier.fit_batch(f, dt, 3, max_memory=per_clip * 32,
                                              throw=False).model.amplitude)(feats)
    np.testing.assert_allclose(np.asarray(amp), np.asarray(whole.model.amplitude), atol=1e-6)


def test_a_budget_below_one_clip_is_refused_naming_it():
    feats, dt = _clips(2)
    with pytest.raises(UserError, match=r"fit_batch: a clip of 120 frames x 5 channels .* would "
                                        r"need 69.9 kB of memory, more than the limit of 1.0 kB; raise max_memory"):
        fourier.fit_batch(feats, dt, 3, max_memory=1000)
    with pytest.raises(UserError, match="max_memory must be"):
        fourier.fit_batch(feats, dt, 3, max_memory=-5)
    with pytest.raises(UserError, match="fit: a clip"):
        fourier.fit(feats[0], 1 / 60, 3, max_memory=1000)


# -- add_noise ------------------------------------------------------------------------------


def _model(C=4, N=2):
    return fourier.FourierModel(jnp.zeros(C), jnp.ones((C, N)) * 0.1, jnp.zeros((C, N)),
                                jnp.asarray(6.0))


@pytest.mark.parametrize("harmonics", [10**9, (3, 10**12), 10**18])
def test_add_noise_refuses_harmonics_beyond_the_budget_before_allocating(harmonics):
    tracemalloc.start()
    try:
        with pytest.raises(UserError, match=r"add_noise: `harmonics`.* would need .* more than "
                                            "the limit"):
            style.add_noise(_model(), jax.random.key(0), 0.1, harmonics)
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert peak < 50e6  # nothing of the requested size was built (10**9 ints: 36 GB)


def test_add_noise_within_the_budget_is_unchanged():
    m = style.add_noise(_model(), jax.random.key(0), 0.1, 3)
    assert m.amplitude.shape == (4, 5)
    with pytest.raises(UserError, match="limit of 1.0 kB"):
        style.add_noise(_model(), jax.random.key(0), 0.1, 100, max_memory=1000)


# -- the BVH reader ---------------------------------------------------------------------------


def _big_bvh(path: pathlib.Path, target_bytes: int) -> pathlib.Path:
    """A bundled clip with its frames repeated to about `target_bytes`."""
    text = pathlib.Path(data.path("02_01")).read_text()
    head, motion = text.split("MOTION", 1)
    lines = motion.strip().split("\n")
    rows = [ln for ln in lines[2:] if ln.strip()]
    block = "\n".join(rows) + "\n"
    reps = max(1, target_bytes // len(block))
    path.write_text(head + "MOTION\n" + f"Frames: {reps * len(rows)}\n" + lines[1].strip() + "\n"
                    + block * reps)
    return path


def test_the_reader_s_working_memory_is_bounded_by_4x_the_file(tmp_path):
    """8 MB (32 pieces): Python's and NumPy's allocations peak below 4x the file size (the bytes,
    the text, the values and one piece's temporaries; a one-pass parse peaked at ~16x)."""
    path = _big_bvh(tmp_path / "big.bvh", 8 * 2**20)
    size = path.stat().st_size
    tracemalloc.start()
    try:
        m = read_bvh(path)
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert m.num_frames > 10_000
    assert peak <= 4 * size, f"peak {peak / size:.1f}x the file"
    assert not m.channels.flags.writeable  # the reader's own array, frozen, not copied


def test_pieces_give_the_values_and_errors_of_one_pass(monkeypatch):
    text = pathlib.Path(data.path("07_01")).read_text()
    whole = parse_bvh(text)
    monkeypatch.setattr(_bvh_parse, "_CHUNK_BYTES", 700)  # ~2 rows per piece
    monkeypatch.setattr(_bvh_parse, "_MIN_CHUNK_BYTES", 1)
    pieces = parse_bvh(text)
    np.testing.assert_array_equal(pieces.channels, whole.channels)
    lines = text.split("\n")
    first = next(i for i, ln in enumerate(lines) if ln.startswith("Frame Time")) + 1
    # One defect late in the file, and two in different pieces: the single pass's order.
    for edits, expect in (
            ({first + 250: "1 2 3"}, f":{first + 251}: frame 250 has 3 values"),
            ({first + 200: lines[first + 200].replace(" ", " x ", 1).rsplit(" ", 1)[0]},
             f":{first + 201}: 'x' is not"),
            ({first + 10: lines[first + 10].replace(" ", " nan ", 1).rsplit(" ", 1)[0],
              first + 200: lines[first + 200].replace(" ", " x ", 1).rsplit(" ", 1)[0]},
             f":{first + 201}: 'x' is not a number"),
            ({first + 10: lines[first + 10].replace(" ", " 1e9 ", 1).rsplit(" ", 1)[0],
              first + 200: lines[first + 200].replace(" ", " nan ", 1).rsplit(" ", 1)[0]},
             f":{first + 201}: non-finite value nan in frame 200"),
            ({first + 300: lines[first + 300] + "\n" + lines[first + 300]},
             "'Frames: 317' but the file has 318 rows")):
        bad = list(lines)
        for k, v in edits.items():
            bad[k] = v
        for size in (700, 10**9):
            monkeypatch.setattr(_bvh_parse, "_CHUNK_BYTES", size)
            with pytest.raises(BVHError) as e:
                parse_bvh("\n".join(bad), source="f")
            assert expect in str(e.value), (size, str(e.value))


def test_synthesis_and_crowd_estimates_scale_with_their_counts():
    base = _memory.synthesis_bytes(240, 96, 3)
    assert _memory.synthesis_bytes(480, 96, 3) == 2 * base
    assert _memory.synthesis_bytes(10**6, 96, 10**12) > 2**63  # Python ints: no overflow
    assert _memory.check_synthesis("--seconds 2", 240, 96, 3, limit=10**9) == base
    with pytest.raises(UserError, match=r"--seconds 1e4 at 120 fps would need 1.9 TB .* limit of "
                                        "1.0 GB; ask for fewer frames"):
        _memory.check_synthesis("--seconds 1e4 at 120 fps", 1_200_000, 96, 10**5, limit=10**9)
    assert _memory.crowd_bytes(10_000, 31, 1) == 4 * 10_000 * 31 * 15
    assert _memory.crowd_bytes(20_000, 31, 1) == 2 * _memory.crowd_bytes(10_000, 31, 1)


def test_the_memory_benchmark_uses_fit_batch_s_estimate():
    from experiments.benchmarks import memory as bench

    assert bench.PER_CLIP_BYTES == _memory.fit_bytes_per_clip(bench.T, bench.C, bench.N, 4)


def test_synth_refuses_a_length_over_the_memory_budget(tmp_path, monkeypatch, capsys):
    """`fourierjax synth` checks the bytes its frame count implies before synthesizing."""
    from fourierjax import _memory
    from fourierjax.cli import main

    assert main(["fit", "07_01", "--harmonics", "2", "--out", str(tmp_path / "m.npz")]) == 0
    monkeypatch.setattr(_memory, "default_limit", lambda: 10_000)
    capsys.readouterr()
    assert main(["synth", str(tmp_path / "m.npz"), "--seconds", "2", "--out", str(tmp_path / "s.bvh")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "--seconds 2" in err[0] and "limit" in err[0], err
    assert not (tmp_path / "s.bvh").exists()
