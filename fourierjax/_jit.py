"""`filter_jit` with the XLA options that keep fourierjax's compile times down on CPU."""

from __future__ import annotations

import functools
from collections.abc import Callable

import equinox as eqx
import jax

#: XLA:CPU options for every public jitted entry point. The new CPU fusion emitters compile
#: each of the many small fusions of a pose or fit graph separately; the classic emitters
#: compile the stance objective's value-and-gradient in 12 s instead of 20 s (measured on
#: 2 cores, jax 0.10.2) at the same run time. Only passed to CPU compilations.
CPU_COMPILER_OPTIONS: dict[str, bool] = {"xla_cpu_use_fusion_emitters": False}


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
            opts = {"compiler_options": dict(CPU_COMPILER_OPTIONS)} if backend == "cpu" and top else {}
            f = jitted[(backend, top)] = make(fun, **opts, **jit_kwargs)
        return f

    @functools.wraps(fun)
    def wrapper(*args, **kwargs):
        return get()(*args, **kwargs)

    wrapper.lower = lambda *args, **kwargs: get().lower(*args, **kwargs)  # type: ignore[attr-defined]
    return wrapper


def _trace_state_clean() -> bool:
    """True outside any JAX transformation (jax has no public API for this)."""
    from jax._src import core

    return core.trace_state_clean()
