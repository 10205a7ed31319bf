"""fourierjax._jit: compiler options on top-level calls, plain jit inside transformations."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from fourierjax._jit import filter_jit, jit


def _f(x):
    return jnp.sin(x) * x


def test_wrapped_functions_work_at_top_level_and_under_transformations():
    for wrap in (filter_jit, jit):
        f = wrap(_f)
        x = jnp.linspace(0.0, 1.0, 4)
        np.testing.assert_allclose(f(x), _f(x), rtol=1e-6)
        # Compiler options are refused on nested jits: these must fall back to plain jit.
        np.testing.assert_allclose(jax.jit(f)(x), _f(x), rtol=1e-6)
        np.testing.assert_allclose(jax.vmap(f)(x), _f(x), rtol=1e-6)
        g = jax.grad(lambda v: f(v).sum())(x)
        np.testing.assert_allclose(g, jnp.cos(x) * x + jnp.sin(x), rtol=1e-5)
        assert f.lower(x).compile() is not None


def test_static_arguments_pass_through():
    f = jit(lambda x, n: x * n, static_argnums=1)
    assert float(f(jnp.float32(2.0), 3)) == 6.0


def test_unknown_cpu_compiler_options_are_dropped(monkeypatch):
    """A jaxlib without one of the options (jaxlib 0.11 has no `xla_cpu_use_fusion_emitters`)
    must still compile every entry point: it used to fail with "No such compile option"."""
    from fourierjax import _jit

    known = dict(_jit.CPU_COMPILER_OPTIONS)
    monkeypatch.setattr(_jit, "CPU_COMPILER_OPTIONS", {**known, "xla_cpu_no_such_option_here": True})
    _jit._cpu_options.cache_clear()
    try:
        f = jit(lambda x: x * 3.0)
        assert float(f(jnp.float32(2.0))) == 6.0
        if jax.default_backend() == "cpu":
            assert _jit._cpu_options() == known  # the known option is still passed
    finally:
        _jit._cpu_options.cache_clear()


def _dots(text: str) -> list[str]:
    return [line for line in text.splitlines() if "stablehlo.dot_general" in line]


def test_fourierjax_products_name_full_precision():
    """Every matrix product fourierjax writes asks for full precision, also when a user jits the
    function themselves: XLA's default on TensorFloat-32 GPUs rounds float32 operands to 10
    mantissa bits (measured on an H100: `synthesize` off by up to 2.5e-4 from the elementwise
    `synthesize_batch`). On CPU the numbers are the same either way."""
    from fourierjax import fourier as F

    t48 = np.arange(48)[:, None] / 30  # 1.6 s of a 1.5 Hz gait-like signal with noise
    x = np.sin(2 * np.pi * 1.5 * t48 + np.arange(5)) + 0.1 * np.random.default_rng(0).normal(size=(48, 5))
    x = jnp.asarray(x, jnp.float32)
    model = F.fit(x, 1 / 30, 2).model
    t = jnp.arange(48, dtype=jnp.float32) / 30
    texts = {
        "synthesize": jax.jit(F.synthesize).lower(model, t),
        "fit": jax.jit(lambda v: F.fit(v, 1 / 30, 2).model).lower(x),
        "fit_batch": jax.jit(lambda v: F.fit_batch(v, jnp.full(3, 1 / 30), 3).model).lower(jnp.stack([x] * 3)),
        "variance_explained": jax.jit(F.variance_explained).lower(x, x + 1),
        "rms_error": jax.jit(F.rms_error).lower(model, x, t),
    }
    for name, lowered in texts.items():
        dots = _dots(lowered.as_text())
        assert dots, name
        assert all("precision = [HIGHEST, HIGHEST]" in d for d in dots), (name, dots)


def test_entry_points_run_third_party_products_at_full_precision(monkeypatch):
    """On a backend whose default precision is lower (a GPU), the products inside an entry
    point that are not fourierjax's (optimistix's BFGS, lineax) are traced at full precision
    too, unless the user chose a precision."""
    from fourierjax import _jit
    from fourierjax.stance.shape_sets import get_shape_set
    from fourierjax.stance.skeleton48 import make_body
    from fourierjax.stance.solver import solve_stance

    problem = get_shape_set("posture").problem(make_body(), 0.5)

    def dots():  # a fresh entry point each time (a jitted one keeps its first trace)
        return _dots(filter_jit(solve_stance.__wrapped__).lower(problem).as_text())

    monkeypatch.setattr(_jit, "_products_are_full_precision", lambda: True)  # as on CPU
    assert any("HIGHEST" not in d for d in dots())  # optimistix's own products
    monkeypatch.setattr(_jit, "_products_are_full_precision", lambda: False)  # as on a GPU
    full = dots()
    assert full and all("precision = [HIGHEST, HIGHEST]" in d for d in full)
    with jax.default_matmul_precision("tensorfloat32"):  # the user's choice is kept
        assert any("HIGHEST" not in d for d in dots())




def _package_modules() -> list[str]:
    import pkgutil

    import fourierjax

    names = ["fourierjax"]
    for info in pkgutil.walk_packages(fourierjax.__path__, "fourierjax."):
        if not info.name.startswith(("fourierjax.viz", "fourierjax.cli", "fourierjax.demo", "fourierjax.__main__")):
            names.append(info.name)  # the edges that import matplotlib or run on import are left out
    return sorted(names)


def _jitted_outside_the_wrapper(module) -> list[str]:
    """Module-level callables that carry a jit's `.lower` but were not made by `filter_jit`:
    bare `jax.jit`, `eqx.filter_jit`, or another wrapper."""
    from fourierjax._jit import is_entry_point

    found = []
    for name, obj in vars(module).items():
        if isinstance(obj, type) or not callable(obj) or not hasattr(obj, "lower"):
            continue
        if getattr(obj, "__module__", module.__name__) != module.__name__:
            continue  # imported from elsewhere: checked in its own module
        if not is_entry_point(obj):
            found.append(name)
    return found


@pytest.mark.parametrize(
    "module_name",
    _package_modules(),
)
def test_every_jitted_function_comes_from_the_one_wrapper(module_name):
    import importlib

    assert _jitted_outside_the_wrapper(importlib.import_module(module_name)) == []


def test_the_wrapper_check_finds_bare_jits():
    """The walk above can fail: a bare `jax.jit` and `eqx.filter_jit` are found, ours are not."""
    import types

    import equinox as eqx

    mod = types.ModuleType(_f.__module__)  # the wrapped functions' own module
    for name, obj in {"a": jax.jit(_f), "b": eqx.filter_jit(_f), "c": filter_jit(_f), "d": jit(_f)}.items():
        setattr(mod, name, obj)
    mod.e = jax.jit  # imported from elsewhere: not this module's
    assert sorted(_jitted_outside_the_wrapper(mod)) == ["a", "b"]


def test_num_traces_counts_retraces():
    f = filter_jit(lambda x, n: x * n)
    f(jnp.float32(1.0), 2)
    f(jnp.float32(3.0), 2)
    assert f.num_traces() == 1
    f(jnp.float32(3.0), 3)  # a Python number is static under filter_jit: a new trace
    assert f.num_traces() == 2
    f(jnp.float32(3.0), jnp.float32(4.0))
    f(jnp.float32(3.0), jnp.float32(5.0))
    assert f.num_traces() == 3


def test_cpu_compiler_options_per_entry_point():
    from fourierjax import _jit

    f = filter_jit(_f, cpu_compiler_options={})
    g = filter_jit(cpu_compiler_options={"xla_cpu_no_such_option_here": True})(_f)
    x = jnp.linspace(0.0, 1.0, 4)
    np.testing.assert_allclose(f(x), _f(x), rtol=1e-6)
    np.testing.assert_allclose(g(x), _f(x), rtol=1e-6)  # unknown options are dropped
    h = jit(_f, cpu_compiler_options={"xla_cpu_no_such_option_here": True})
    np.testing.assert_allclose(h(x), _f(x), rtol=1e-6)
    assert _jit._known_options({"xla_cpu_no_such_option_here": True}) == {}
