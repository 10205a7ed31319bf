"""fourierjax._saved.saved_executable: FK's compiled program saved and loaded whole (no trace, no
lowering), equal to the plain call, and never loaded when stale, corrupt or turned off (issue 25)."""

import hashlib
import json
import os
import pathlib
import pickle
import subprocess
import sys

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from fourierjax import _compile_cache, _jit, _saved, data, kinematics
from tests import test_saved

cache_on = test_saved.cache_on  # the fixture: saved programs on, in a temporary folder


def _fk(skeleton, channels):
    return kinematics._fk_batch(skeleton, channels, False)[1]


@pytest.fixture(scope="module")
def clip():
    m = data.load("07_01", raw=True)
    return m.skeleton(), np.asarray(m.channels[:64], np.float32)


def _fresh():
    """A new wrapper over a new jit, as in a new process: nothing in memory, traces counted."""
    jitted = _jit.jit(_fk)
    return _saved.saved_executable(jitted), jitted


def test_a_loaded_executable_gives_the_plain_result_without_tracing(cache_on, clip):
    skel, ch = clip
    plain = np.asarray(_jit.jit(_fk)(skel, ch))
    first, jitted = _fresh()
    np.testing.assert_array_equal(np.asarray(first(skel, ch)), plain)
    assert first.stats["saved"] == 1 and len(list(cache_on.glob("*.xlaexe"))) == 1
    second, jitted2 = _fresh()
    got = second(skel, jax.device_put(ch))  # a JAX array: the same avals, the same file
    np.testing.assert_array_equal(np.asarray(got), plain)
    assert second.stats["loaded"] == 1 and jitted2.num_traces() == 0
    # A repeated call uses the executable in memory; another shape is another file.
    second(skel, ch)
    second(skel, ch[:32])
    assert second.stats["loaded"] == 1 and second.stats["saved"] == 1
    assert len(list(cache_on.glob("*.xlaexe"))) == 2
    # float64 NumPy input has float32's key (x64 off): the executable takes it or refuses it, and
    # a refused call runs the plain function; the values are the same either way.
    np.testing.assert_allclose(np.asarray(second(skel, ch.astype(np.float64))), plain, atol=1e-5)


@pytest.mark.parametrize("damage", ["truncate", "flip", "garbage", "other_key"])
def test_a_damaged_or_foreign_file_is_compiled_again_and_replaced(cache_on, clip, damage):
    skel, ch = clip
    plain = np.asarray(_jit.jit(_fk)(skel, ch))
    _fresh()[0](skel, ch)
    (path,) = cache_on.glob("*.xlaexe")
    blob = path.read_bytes()
    if damage == "truncate":
        path.write_bytes(blob[: len(blob) // 2])
    elif damage == "flip":
        path.write_bytes(blob[:-100] + bytes([blob[-100] ^ 0xFF]) + blob[-99:])
    elif damage == "garbage":
        path.write_bytes(b"\x00" * 1000)
    else:  # a valid file, checksum included, made for another key (another machine or jaxlib)
        head, _, body = blob.partition(b"\n")
        _, _, body = body.partition(b"\n")
        record = pickle.loads(body)
        record["key"] = record["key"].replace("cpu=", "cpu=another-")
        body = pickle.dumps(record)
        path.write_bytes(head + b"\n" + hashlib.sha256(body).hexdigest().encode() + b"\n" + body)
    wrapper, jitted = _fresh()
    np.testing.assert_array_equal(np.asarray(wrapper(skel, ch)), plain)
    assert wrapper.stats["rejected"] == 1 and wrapper.stats["saved"] == 1 and jitted.num_traces() == 1
    again, _ = _fresh()
    again(skel, ch)
    assert again.stats["loaded"] == 1


def test_off_traced_or_not_all_arrays_is_the_plain_call(monkeypatch, tmp_path, clip):
    skel, ch = clip
    monkeypatch.setenv(_compile_cache.CACHE_DIR_ENV, str(tmp_path / "cache"))
    monkeypatch.setattr(_compile_cache, "_enabled", False)
    wrapper, _ = _fresh()
    wrapper(skel, ch)
    assert not (tmp_path / "cache").exists()
    monkeypatch.setattr(_compile_cache, "_enabled", True)
    out = jax.jit(lambda c: wrapper(skel, c))(jnp.asarray(ch))  # traced: staged into the caller
    assert out.shape == (64, 31, 3)
    assert wrapper.stats["saved"] == wrapper.stats["loaded"] == 0


def test_the_key_names_the_machine_the_versions_and_the_inputs(clip):
    skel, ch = clip
    leaves, treedef = jax.tree.flatten((skel, ch))
    avals = tuple((x.shape, x.dtype, False) for x in leaves)
    key = _saved._executable_key("f", treedef, avals)
    for part in ("jaxlib=", "cpu=", "device_kind=", "platform_version=", "xla_flags=", "source=",
                 "Hips", "float32[64, 96]"):
        assert part in key
    other = _saved._executable_key("f", treedef, (*avals[:-1], ((32, 96), np.dtype("float32"), False)))
    assert other != key


def test_fk_entry_points_load_their_executables(cache_on, clip):
    skel, ch = clip
    want = np.asarray(kinematics._joint_positions_jit.__wrapped__(skel, ch[:50 + 14]))[:50]
    got = kinematics.joint_positions(skel, ch[:50])
    np.testing.assert_allclose(np.asarray(got), want, atol=0)
    assert kinematics._joint_positions_jit.stats["saved"] + kinematics._joint_positions_jit.stats["loaded"] >= 1
    assert kinematics._joint_positions_jit.__fourierjax_jit__ is True


_RUN = """
import contextlib, hashlib, json, sys
import numpy as np
from fourierjax import _compile_cache, _saved, data, kinematics
if sys.argv[1] == "old":  # the behaviour before the fix: save whatever the compile cache returns
    _saved._compile_cache_bypassed = contextlib.nullcontext
_compile_cache.enable_compile_cache()
m = data.load("07_01", raw=True)
pos = np.asarray(kinematics.fk_frames(m.skeleton(), m.channels[:64]).positions)
print(json.dumps({"sha": hashlib.sha256(pos.tobytes()).hexdigest(), **kinematics._fk_frames_jit.stats}))
"""


def _process(cache: pathlib.Path, mode: str = "new") -> dict:
    """One fresh process: FK of a bundled clip with the cache in ``cache``; its stats and a hash."""
    env = {**os.environ, "FOURIERJAX_CACHE_DIR": str(cache)}
    env.pop("FOURIERJAX_NO_CACHE", None)
    done = subprocess.run([sys.executable, "-c", _RUN, mode], env=env, capture_output=True, text=True,
                          timeout=300, check=False)
    assert done.returncode == 0, done.stderr[-2000:]
    return json.loads(done.stdout.strip().splitlines()[-1])


def test_a_program_the_compile_cache_holds_is_saved_whole_and_a_broken_file_is_replaced(tmp_path):
    """jaxlib serializes an executable read from the persistent compile cache without some of its
    kernels; saved, it loaded in the next process and failed there ("Function gather.12_kernel
    not found"): every `fourierjax fit` failed after an upgrade. Across fresh processes: the
    program to save is compiled afresh, and a loaded file that fails to run is replaced."""
    first = _process(tmp_path, "old")  # compiled, saved, and written to the compile cache
    assert first["saved"] == 1
    exes = list(tmp_path.rglob("*.xlaexe"))
    assert len(exes) == 1
    # The executable is gone, the compile cache still holds the program (a new source hash).
    exes[0].unlink()
    broken = _process(tmp_path, "old")  # what the old code saved: the cache hit's executable
    assert broken["saved"] == 1 and broken["sha"] == first["sha"]
    mended = _process(tmp_path)  # loads the broken file, finds it fails, compiles and saves again
    assert mended["sha"] == first["sha"]
    assert mended["loaded"] == 1 and mended["rejected"] == 1 and mended["saved"] == 1
    loaded = _process(tmp_path)
    assert loaded == {**loaded, "sha": first["sha"], "loaded": 1, "rejected": 0, "saved": 0}
    # With the fix, a save from a cache hit is whole: delete, save afresh, load.
    next(tmp_path.rglob("*.xlaexe")).unlink()
    assert _process(tmp_path)["saved"] == 1
    again = _process(tmp_path)
    assert again["sha"] == first["sha"] and again["loaded"] == 1 and again["rejected"] == 0


def test_overlapping_compile_cache_bypasses_leave_the_cache_as_it_was():
    """Two threads compiling programs to save at once: the first out must not turn the cache
    back on under the second, nor the second leave it off for good."""
    from jax._src import compilation_cache as cc

    before = (cc._cache_checked, cc._cache_used)
    a, b = _saved._compile_cache_bypassed(), _saved._compile_cache_bypassed()
    a.__enter__()
    b.__enter__()
    assert cc._cache_used is False
    a.__exit__(None, None, None)  # the first in leaves first
    assert cc._cache_used is False
    b.__exit__(None, None, None)
    assert (cc._cache_checked, cc._cache_used) == before
