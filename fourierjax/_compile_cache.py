"""Persistent XLA compilation cache for the command line and the demo (edge-only setting)."""

from __future__ import annotations

import os


def enable_compile_cache() -> None:
    """Cache compiled XLA programs across runs (the stance solver takes long to compile).

    The folder is ``$FOURIERJAX_CACHE_DIR`` or ``~/.cache/fourierjax/jax``. A folder that cannot
    be created leaves caching off rather than failing the command.
    """
    import jax

    default = os.path.join(os.path.expanduser("~"), ".cache", "fourierjax", "jax")
    path = os.environ.get("FOURIERJAX_CACHE_DIR") or default
    try:
        os.makedirs(path, exist_ok=True)
        jax.config.update("jax_compilation_cache_dir", path)
    except OSError:
        pass
