"""Persistent XLA compilation cache (public as `fourierjax.enable_compile_cache`)."""

from __future__ import annotations

import os
import sys

#: Set (to anything but "" or "0") to keep the cache off, e.g. by `fourierjax --no-cache`: later
#: calls of `enable_compile_cache` (the demo's, an experiment's) then do nothing.
NO_CACHE_ENV = "FOURIERJAX_NO_CACHE"
CACHE_DIR_ENV = "FOURIERJAX_CACHE_DIR"

#: Whether `enable_compile_cache` turned the cache on in this process: saved programs
#: (`fourierjax._saved`) are read and written only then.
_enabled = False


def cache_dir() -> str:
    """The cache folder: ``$FOURIERJAX_CACHE_DIR``, else ``~/.cache/fourierjax/jax``.

    Returns:
        The folder's path (not created).
    """
    default = os.path.join(os.path.expanduser("~"), ".cache", "fourierjax", "jax")
    return os.environ.get(CACHE_DIR_ENV) or default


def saved_dir() -> str:
    """The folder of saved (exported) programs, `fourierjax._saved`: ``exported`` inside
    `cache_dir()` (JAX's cache reads only its own ``*-cache`` files there).

    Returns:
        The folder's path (not created).
    """
    return os.path.join(cache_dir(), "exported")


def saved_programs_on() -> bool:
    """Whether saved programs are read and written: `enable_compile_cache` turned the cache on
    in this process and ``$FOURIERJAX_NO_CACHE`` does not turn it off.

    Returns:
        True or False.
    """
    return _enabled and not cache_disabled()


def cache_disabled() -> bool:
    """Whether ``$FOURIERJAX_NO_CACHE`` turns the cache off.

    Returns:
        True when the variable is set to anything but ``""`` or ``"0"``.
    """
    return os.environ.get(NO_CACHE_ENV, "") not in ("", "0")


def enable_compile_cache() -> bool:
    """Cache compiled XLA programs across runs, so that a second call of a command compiles nothing.

    The folder is `cache_dir()`. Every program is cached, however quick its compile (JAX's
    default keeps only those over 1 s; a command compiles tens of smaller ones, and together
    they are most of a second call's time). A folder that cannot be created leaves caching off
    rather than failing the command. Used by every command of the command line, the demo and
    the experiments; a user's script may call it once before its first jit. It also turns on
    saved programs (`fourierjax._saved`: the largest programs' traces kept in `saved_dir()`).

    Returns:
        True when the cache is on; False when `cache_disabled()` or the folder cannot be made.
    """
    global _enabled
    if cache_disabled():
        disable_compile_cache()
        return False
    path = cache_dir()
    try:
        os.makedirs(path, exist_ok=True)
    except OSError:
        return False
    _enabled = True
    _set("jax_enable_compilation_cache", True)
    _set("jax_compilation_cache_dir", path)
    _set("jax_persistent_cache_min_compile_time_secs", 0.0)
    _set("jax_persistent_cache_min_entry_size_bytes", 0)
    return True


def disable_compile_cache() -> None:
    """Turn the persistent cache off for this process and for later `enable_compile_cache` calls.

    Returns:
        None.
    """
    global _enabled
    _enabled = False
    os.environ[NO_CACHE_ENV] = "1"
    _set("jax_enable_compilation_cache", False)


def _set(option: str, value) -> None:
    # Before JAX is imported, its options are read from the environment on import: the command
    # line sets them without importing JAX (`fourierjax info` and `stance --list` never need it).
    if "jax" in sys.modules:
        sys.modules["jax"].config.update(option, value)
    else:
        os.environ[option.upper()] = str(value).lower() if isinstance(value, bool) else str(value)
