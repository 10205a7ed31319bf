"""`filter_jit` with the XLA options that keep fourierjax's compile times down on CPU, and
full-precision matrix products elsewhere."""

from __future__ import annotations

import contextlib
import functools
import logging
from collections.abc import Callable

import equinox as eqx
import jax

_log = logging.getLogger(__name__)

#: XLA:CPU options for every public jitted entry point. The new CPU fusion emitters compile
#: each of the many small fusions of a pose or fit graph separately; the classic emitters
#: compile the stance objective's value-and-gradient in 12 s instead of 20 s (measured on
#: 2 cores, jax 0.10.2) at the same run time. Only passed to CPU compilations, and only
#: those the installed jaxlib knows (`_cpu_options`): jaxlib 0.11 has no such option.
CPU_COMPILER_OPTIONS: dict[str, bool] = {"xla_cpu_use_fusion_emitters": False}


@functools.cache
def _cpu_options() -> dict[str, bool]:
    """The `CPU_COMPILER_OPTIONS` this jaxlib accepts (one tiny compile per option, once).

    An unknown option fails every compilation that names it ("No such compile option"), so
    a newer jaxlib that dropped one would otherwise break every entry point on CPU.
    """
    lowered = jax.jit(lambda x: x + 1).lower(jax.ShapeDtypeStruct((), "float32"))
    accepted = {}
    for name, value in CPU_COMPILER_OPTIONS.items():
        try:
            lowered.compile(compiler_options={name: value})
        except jax.errors.JaxRuntimeError as err:
            if "No such compile option" not in str(err):
                raise
            _log.info("fourierjax: this jaxlib has no XLA option %s; compiling without it", name)
        else:
            accepted[name] = value
    return accepted


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


def filter_jit(fun: Callable | None = None, **jit_kwargs) -> Callable:
    """`equinox.filter_jit` that compiles with `CPU_COMPILER_OPTIONS` when the backend is CPU.

    The backend is read at the first call (not at import, which would initialise JAX before
    a user could configure it); one jitted function is kept per backend.
    """
    if fun is None:
        return functools.partial(filter_jit, **jit_kwargs)
    return _per_backend(eqx.filter_jit, fun, jit_kwargs)


def jit(fun: Callable | None = None, **jit_kwargs) -> Callable:
    """`jax.jit` (static arguments and all) with `CPU_COMPILER_OPTIONS` on CPU; see `filter_jit`."""
    if fun is None:
        return functools.partial(jit, **jit_kwargs)
    return _per_backend(jax.jit, fun, jit_kwargs)


def _per_backend(make: Callable, fun: Callable, jit_kwargs: dict) -> Callable:
    jitted: dict[tuple[str, bool], Callable] = {}

    def get() -> Callable:
        backend = jax.default_backend()
        # JAX accepts compiler options on top-level calls only: inside a transformation
        # (jit, vmap, grad of a caller) the function is staged into the caller's program,
        # which is compiled with the caller's options.
        top = _trace_state_clean()
        f = jitted.get((backend, top))
        if f is None:
            opts = {"compiler_options": _cpu_options()} if backend == "cpu" and top else {}
            f = jitted[(backend, top)] = make(traced, **opts, **jit_kwargs)
        return f

    # The precision is chosen while tracing, inside the program, not by a context around each
    # call (measured on an H100: a jitted synthesis of 1024 characters took 225 us a call
    # inside `default_matmul_precision`, 166 us outside).
    @functools.wraps(fun)
    def traced(*args, **kwargs):
        with _precision_context():
            return fun(*args, **kwargs)

    @functools.wraps(fun)
    def wrapper(*args, **kwargs):
        return get()(*args, **kwargs)

    wrapper.lower = lambda *args, **kwargs: get().lower(*args, **kwargs)  # type: ignore[attr-defined]
    return wrapper


def _trace_state_clean() -> bool:
    """True outside any JAX transformation (jax has no public API for this)."""
    from jax._src import core

    return core.trace_state_clean()
