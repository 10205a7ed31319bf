"""Parallel BVH ingest: same motions as a serial read, bad files reported per file, progress bar."""

import numpy as np
import pytest

from fourierjax import data
from fourierjax.io import BVHError, read_bvh
from fourierjax.io.ingest import load_many

CLIPS = ["07_01", "142_02", "02_03"]


@pytest.fixture
def files(tmp_path):
    good = [str(data.path(n)) for n in CLIPS]
    text = data.path("07_01").read_text()
    truncated = tmp_path / "truncated.bvh"
    truncated.write_text(text[: len(text) // 2])  # rows cut mid-file: frame count mismatch
    nohier = tmp_path / "nohier.bvh"
    nohier.write_text("MOTION\nFrames: 1\nFrame Time: 0.1\n0 0 0\n")
    missing = tmp_path / "missing.bvh"
    # Bad files interleaved with good ones: order must be kept on both sides.
    return [good[0], str(truncated), good[1], str(missing), str(nohier), good[2]]


def _check(files, motions, errors):
    assert [m.source for m in motions] == [files[0], files[2], files[5]]
    for m in motions:
        ref = read_bvh(m.source)
        np.testing.assert_array_equal(m.channels, ref.channels)
        assert m.topology == ref.topology
        assert m.frame_time_s == ref.frame_time_s
    assert [e.path for e in errors] == [files[1], files[3], files[4]]
    assert all(isinstance(e, BVHError) for e in errors)
    assert errors[0].line is not None and errors[2].line is not None
    assert errors[1].line is None and "no such file" in str(errors[1])
    # The same error a direct read raises (message and line), not a generic wrapper.
    with pytest.raises(BVHError) as info:
        read_bvh(files[1])
    assert str(errors[0]) == str(info.value)


def test_load_many_in_worker_processes(files, capsys):
    motions, errors = load_many(files, workers=2, progress=True, chunk_size=2)
    _check(files, motions, errors)
    err = capsys.readouterr().err
    assert "reading BVH" in err and "6/6" in err


def test_load_many_serial_matches(files):
    motions, errors = load_many(files, workers=1, progress=False)
    _check(files, motions, errors)


def test_load_many_empty_and_bad_arguments():
    assert load_many([], progress=False) == ([], [])
    with pytest.raises(ValueError, match="workers"):
        load_many(["x.bvh"], workers=-1)
    with pytest.raises(ValueError, match="chunk_size"):
        load_many(["x.bvh"], chunk_size=0)


def test_load_many_takes_a_folder_or_one_path(tmp_path):
    # A folder string was iterated character by character ("i: no such file", ...).
    for name in ("b.bvh", "a.BVH"):
        (tmp_path / name).write_text(data.path("07_01").read_text())
    (tmp_path / "notes.txt").write_text("not a clip")
    for folder in (str(tmp_path), tmp_path):
        motions, errors = load_many(folder, workers=1, progress=False)
        assert [m.source for m in motions] == [str(tmp_path / "a.BVH"), str(tmp_path / "b.bvh")]
        assert errors == []
    motions, _ = load_many(tmp_path / "b.bvh", workers=1, progress=False)
    assert [m.source for m in motions] == [str(tmp_path / "b.bvh")]
    with pytest.raises(ValueError, match="`paths` must be BVH paths"):
        load_many(3, progress=False)
