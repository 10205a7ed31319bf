"""fourierjax._saved: programs saved with jax.export give the traced program's results, skip the
trace, and are ignored when stale, corrupt or turned off (issue 25)."""

import pathlib
import shutil

import equinox as eqx
import jax.numpy as jnp
import numpy as np
import pytest

from fourierjax import _compile_cache, _saved
from fourierjax._jit import filter_jit
from fourierjax.fourier import FourierModel, synthesize


def _program(model, t, *, scale):
    """A small program with a custom pytree in and out, a static argument and a None leaf."""
    x = synthesize(model, t) * scale
    faster = eqx.tree_at(lambda m: m.omega, model, model.omega * 2.0)
    return {"x": x, "model": faster, "none": None, "peak": jnp.max(jnp.abs(x), axis=0)}


@pytest.fixture
def inputs():
    rng = np.random.default_rng(0)
    model = FourierModel(offset=rng.normal(size=4).astype(np.float32),
                         amplitude=rng.normal(size=(4, 2)).astype(np.float32),
                         phase=rng.normal(size=(4, 2)).astype(np.float32),
                         omega=np.float32(5.5), channel_names=("a", "b", "c", "d"))
    return model, np.arange(40, dtype=np.float32) / 30


@pytest.fixture
def cache_on(monkeypatch, tmp_path):
    """Saved programs on, as after `enable_compile_cache` in a command (the XLA cache stays off)."""
    monkeypatch.delenv(_compile_cache.NO_CACHE_ENV, raising=False)
    monkeypatch.setenv(_compile_cache.CACHE_DIR_ENV, str(tmp_path / "cache"))
    monkeypatch.setattr(_compile_cache, "_enabled", True)
    return pathlib.Path(_compile_cache.saved_dir())


def _fresh():
    """A new wrapper over a new jit, as in a new process: nothing in memory, traces counted."""
    jitted = filter_jit(_program)
    return _saved.saved(jitted), jitted


def _same(a, b):
    import jax

    la, ta = jax.tree.flatten(a)
    lb, tb = jax.tree.flatten(b)
    assert ta == tb
    for x, y in zip(la, lb, strict=True):
        assert np.asarray(x).dtype == np.asarray(y).dtype
        np.testing.assert_array_equal(np.asarray(x), np.asarray(y))  # bit for bit on CPU


def test_a_loaded_program_gives_the_traced_result_without_tracing(cache_on, inputs):
    model, t = inputs
    plain = filter_jit(_program)(model, t, scale=2.0)
    first, jitted = _fresh()
    _same(first(model, t, scale=2.0), plain)
    assert first.stats["exported"] == 1 and jitted.num_traces() == 1
    assert len(list(cache_on.glob("_program-*.jaxexp"))) == 1
    second, jitted = _fresh()
    out = second(model, t, scale=2.0)
    _same(out, plain)
    assert isinstance(out["model"], FourierModel) and out["model"].channel_names == model.channel_names
    assert second.stats == {"loaded": 1, "exported": 0, "plain": 0, "rejected": 0}
    assert jitted.num_traces() == 0  # the function itself was never traced
    second(model, t, scale=2.0)  # in memory now: no second read
    assert second.stats["loaded"] == 1
    # Another static argument or input shape is another program.
    second(model, t[:20], scale=2.0)
    second(model, t, scale=3.0)
    assert second.stats["exported"] == 2
    assert len(list(cache_on.glob("_program-*.jaxexp"))) == 3


@pytest.mark.parametrize("damage", ["garbage", "truncated", "other_key"])
def test_a_corrupt_or_stale_file_is_ignored_and_replaced(cache_on, inputs, damage):
    model, t = inputs
    plain = filter_jit(_program)(model, t, scale=2.0)
    _fresh()[0](model, t, scale=2.0)
    (path,) = cache_on.glob("_program-*.jaxexp")
    blob = path.read_bytes()
    if damage == "garbage":
        path.write_bytes(b"not a program at all")
    elif damage == "truncated":
        path.write_bytes(blob[: len(blob) // 2])
    else:  # a file saved for other code under this name: its stored key differs
        import pickle

        record = pickle.loads(blob[len(_saved._MAGIC):])
        record["key"] = record["key"].replace("format=", "format=stale-")
        path.write_bytes(_saved._MAGIC + pickle.dumps(record))
    wrapped, jitted = _fresh()
    _same(wrapped(model, t, scale=2.0), plain)
    assert wrapped.stats["rejected"] == 1 and wrapped.stats["exported"] == 1 and jitted.num_traces() == 1
    again, jitted = _fresh()  # the replacement loads
    _same(again(model, t, scale=2.0), plain)
    assert again.stats["loaded"] == 1 and jitted.num_traces() == 0


def test_the_key_changes_with_the_source(cache_on, inputs, monkeypatch, tmp_path):
    model, t = inputs
    real = _saved.source_hash()
    _fresh()[0](model, t, scale=2.0)
    monkeypatch.setattr(_saved, "source_hash", lambda: "edited")
    wrapped, jitted = _fresh()
    wrapped(model, t, scale=2.0)
    assert wrapped.stats["exported"] == 1 and jitted.num_traces() == 1
    assert len(list(cache_on.glob("_program-*.jaxexp"))) == 2
    # The hash itself: a copy of the package hashes the same until one source file changes.
    root = pathlib.Path(_saved.__file__).parent
    copy = tmp_path / "pkg"
    shutil.copytree(root, copy, ignore=shutil.ignore_patterns("__pycache__", "*.bvh", "*.npz", "*.json"))
    assert _saved.tree_hash(copy) == real
    with open(copy / "_gait" / "synthesis.py", "a") as f:
        f.write("\n# an edit\n")
    assert _saved.tree_hash(copy) != real


@pytest.mark.parametrize("off", ["no_cache_env", "never_enabled", "disabled"])
def test_without_the_cache_nothing_is_written(cache_on, inputs, monkeypatch, off):
    model, t = inputs
    if off == "no_cache_env":
        monkeypatch.setenv(_compile_cache.NO_CACHE_ENV, "1")
    elif off == "never_enabled":  # a library user who never called enable_compile_cache
        monkeypatch.setattr(_compile_cache, "_enabled", False)
    else:  # what `fourierjax --no-cache` calls
        monkeypatch.setattr(_compile_cache, "_set", lambda option, value: None)
        _compile_cache.disable_compile_cache()
    wrapped, jitted = _fresh()
    _same(wrapped(model, t, scale=2.0), filter_jit(_program)(model, t, scale=2.0))
    assert wrapped.stats["plain"] == 1 and jitted.num_traces() == 1
    assert not cache_on.parent.exists()


def test_inside_a_transformation_the_plain_function_runs(cache_on, inputs):
    import jax

    model, t = inputs
    wrapped, _ = _fresh()
    grad = jax.grad(lambda s: wrapped(model, t, scale=2.0)["x"].sum() * s)(1.0)
    assert np.isfinite(float(grad)) and wrapped.stats["plain"] == 1
    assert not cache_on.exists()


def test_a_function_that_cannot_be_exported_runs_unsaved(cache_on, inputs):
    model, t = inputs

    def checked(model, t):  # eqx.error_if is a host callback: no exported program holds it
        x = synthesize(model, t)
        return eqx.error_if(x, jnp.any(jnp.isnan(x)), "nan")

    wrapped = _saved.saved(filter_jit(checked))
    np.testing.assert_array_equal(np.asarray(wrapped(model, t)), np.asarray(filter_jit(checked)(model, t)))
    wrapped(model, t)
    assert wrapped.stats["plain"] == 2 and wrapped.stats["exported"] == 0
    assert not list(cache_on.glob("*.jaxexp"))
