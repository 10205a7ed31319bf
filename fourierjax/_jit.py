"""`filter_jit`, the one jit wrapper of fourierjax's entry points (CPU compile options, full precision)."""

from __future__ import annotations

import contextlib
import functools
import logging
from collections.abc import Callable

import jax
from jax._src import core as _core  # `_trace_state_clean`, on every call: imported once

_log = logging.getLogger(__name__)

#: XLA:CPU options for every public jitted entry point. The new CPU fusion emitters compile
#: each of the many small fusions of a pose or fit graph separately; the classic emitters
#: compile the stance objective's value-and-gradient in 12 s instead of 20 s (measured on
#: 2 cores, jax 0.10.2) at the same run time. Only passed to CPU compilations, and only
#: those the installed jaxlib knows (`_cpu_options`): jaxlib 0.11 has no such option.
CPU_COMPILER_OPTIONS: dict[str, bool] = {"xla_cpu_use_fusion_emitters": False}


@functools.cache
def _cpu_options() -> dict[str, bool]:
    """The `CPU_COMPILER_OPTIONS` this jaxlib accepts."""
    return _known_options(CPU_COMPILER_OPTIONS)


def _known_options(options: dict) -> dict:
    """The `options` this jaxlib accepts (one tiny compile per option, cached per option).

    An unknown option fails every compilation that names it ("No such compile option"), so
    a newer jaxlib that dropped one would otherwise break every entry point on CPU.
    """
    return {name: value for name, value in options.items() if _option_known(name, value)}


#: (option, jaxlib version) pairs known to be accepted: no probe compile for them. The probe
#: is one more program (trace, lowering, compile or cache read) in every process, which a
#: command line call pays before its first entry point.
_ACCEPTED: frozenset[tuple[str, str]] = frozenset({("xla_cpu_use_fusion_emitters", "0.10.2"),
                                                   ("xla_cpu_prefer_vector_width", "0.10.2")})


@functools.cache
def _option_known(name: str, value) -> bool:
    import jaxlib

    if (name, jaxlib.__version__) in _ACCEPTED:
        return True
    lowered = jax.jit(lambda x: x + 1).lower(jax.ShapeDtypeStruct((), "float32"))
    try:
        lowered.compile(compiler_options={name: value})
    except jax.errors.JaxRuntimeError as err:
        if "No such compile option" not in str(err):
            raise
        _log.info("fourierjax: this jaxlib has no XLA option %s; compiling without it", name)
        return False
    return True


def _precision_context():
    """Full-precision matrix products for third-party code inside an entry point (optimistix's
    BFGS, lineax) on backends whose default is lower (TensorFloat-32 GPUs), unless the user set
    `jax_default_matmul_precision`; fourierjax's own products name their precision
    (`_linalg.PRECISION`). A no-op on CPU, whose programs stay exactly as they were."""
    if _products_are_full_precision() or jax.config.jax_default_matmul_precision is not None:
        return contextlib.nullcontext()
    return jax.default_matmul_precision("highest")


def _products_are_full_precision() -> bool:
    """Whether the default backend computes float32 products in full whatever the precision
    (XLA:CPU does)."""
    return jax.default_backend() == "cpu"


def filter_jit(fun: Callable | None = None, *, cpu_compiler_options: dict | None = None, **jit_kwargs) -> Callable:
    """The one jit wrapper for fourierjax's public entry points: `equinox.filter_jit` (every
    array argument traced, everything else static) compiled with `CPU_COMPILER_OPTIONS` on CPU.

    The backend is read at the first call (not at import, which would initialise JAX before
    a user could configure it); one jitted function is kept per backend. A Python number that
    varies per call is static here: turn it into an array first, or each value retraces.

    Arguments:
        fun: the function; without it, a decorator.
        cpu_compiler_options: XLA:CPU options for this entry point instead of
            `CPU_COMPILER_OPTIONS` (`{}`: XLA's defaults, for graphs that run faster with the
            new fusion emitters); options the installed jaxlib does not know are dropped.
        **jit_kwargs: passed to `equinox.filter_jit` (e.g. `donate`).

    Returns:
        The jitted function, with `.lower(*args)` and `.num_traces()` (how many times it was
        traced: the retracing guard of the tests).
    """
    if fun is None:
        return functools.partial(filter_jit, cpu_compiler_options=cpu_compiler_options, **jit_kwargs)
    return _per_backend(_filter_jit, fun, jit_kwargs, cpu_compiler_options)


def jit(fun: Callable | None = None, *, cpu_compiler_options: dict | None = None, **jit_kwargs) -> Callable:
    """`filter_jit`'s mechanism over `jax.jit`: every argument not named in `static_argnums` /
    `static_argnames` is traced (Python numbers included), and a call costs less Python (jax's
    C++ dispatch instead of equinox's filtering): for array-only entry points called per frame.

    Arguments:
        fun: the function; without it, a decorator.
        cpu_compiler_options: as for `filter_jit`.
        **jit_kwargs: passed to `jax.jit` (e.g. `static_argnames`).

    Returns:
        The jitted function, with `.lower(*args)` and `.num_traces()`.
    """
    if fun is None:
        return functools.partial(jit, cpu_compiler_options=cpu_compiler_options, **jit_kwargs)
    return _per_backend(jax.jit, fun, jit_kwargs, cpu_compiler_options)


def is_entry_point(fun: object) -> bool:
    """Whether `fun` was made by `filter_jit` (or `jit`).

    Arguments:
        fun: any object.

    Returns:
        True for the wrapper's functions: the check behind the test that every jitted function
        of the package goes through the one wrapper.
    """
    return getattr(fun, "__fourierjax_jit__", False) is True


def _filter_jit(fun: Callable, **kwargs) -> Callable:
    # equinox is imported at the first call of a filtered entry point, not with this module:
    # reading a BVH file and posing it (`jit` entry points only) never imports it.
    import equinox as eqx

    return eqx.filter_jit(fun, **kwargs)


def _per_backend(make: Callable, fun: Callable, jit_kwargs: dict, cpu_options: dict | None) -> Callable:
    jitted: dict[tuple[str, bool], Callable] = {}
    traces = [0]

    def get() -> Callable:
        backend = jax.default_backend()
        # JAX accepts compiler options on top-level calls only: inside a transformation
        # (jit, vmap, grad of a caller) the function is staged into the caller's program,
        # which is compiled with the caller's options.
        top = _trace_state_clean()
        f = jitted.get((backend, top))
        if f is None:
            opts = {}
            if backend == "cpu" and top:
                opts = {"compiler_options": _cpu_options() if cpu_options is None else _known_options(cpu_options)}
            f = jitted[(backend, top)] = make(traced, **opts, **jit_kwargs)
        return f

    # The precision is chosen while tracing, inside the program, not by a context around each
    # call (measured on an H100: a jitted synthesis of 1024 characters took 225 us a call
    # inside `default_matmul_precision`, 166 us outside).
    @functools.wraps(fun)
    def traced(*args, **kwargs):
        traces[0] += 1
        with _precision_context():
            return fun(*args, **kwargs)

    @functools.wraps(fun)
    def wrapper(*args, **kwargs):
        # `get`'s lookup inline: a per-frame or single-character call pays ~0.3 us less Python.
        f = jitted.get((jax.default_backend(), _core.trace_state_clean()))
        return (get() if f is None else f)(*args, **kwargs)

    wrapper.lower = lambda *args, **kwargs: get().lower(*args, **kwargs)  # type: ignore[attr-defined]
    wrapper.num_traces = lambda: traces[0]  # type: ignore[attr-defined]
    wrapper.__fourierjax_jit__ = True  # type: ignore[attr-defined]
    return wrapper


def _trace_state_clean() -> bool:
    """True outside any JAX transformation (jax has no public API for this)."""
    return _core.trace_state_clean()
