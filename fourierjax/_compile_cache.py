"""Persistent XLA compilation cache (public as `fourierjax.enable_compile_cache`)."""

from __future__ import annotations

import os


def enable_compile_cache() -> None:
    """Cache compiled XLA programs across runs (the stance solver takes long to compile).

    The folder is ``$FOURIERJAX_CACHE_DIR`` or ``~/.cache/fourierjax/jax``. A folder that cannot
    be created leaves caching off rather than failing the command. Used by the command line,
    the demo and the experiments; a user's script may call it once before its first jit.

    Returns:
        None.
    """
    import jax

    default = os.path.join(os.path.expanduser("~"), ".cache", "fourierjax", "jax")
    path = os.environ.get("FOURIERJAX_CACHE_DIR") or default
    try:
        os.makedirs(path, exist_ok=True)
        jax.config.update("jax_compilation_cache_dir", path)
    except OSError:
        pass
