"""Persistent XLA compilation cache (public as `fourierjax.enable_compile_cache`)."""

from __future__ import annotations

import os
import sys

#: Set (to anything but "" or "0") to keep the cache off, e.g. by `fourierjax --no-cache`: later
#: calls of `enable_compile_cache` (the demo's, an experiment's) then do nothing.
NO_CACHE_ENV = "FOURIERJAX_NO_CACHE"
CACHE_DIR_ENV = "FOURIERJAX_CACHE_DIR"
#: The cache folder's size budget in MiB (default `DEFAULT_MAX_MB`): past it, the least recently
#: used files are removed when a command starts, down to `_PRUNE_TO` of the budget.
CACHE_MAX_MB_ENV = "FOURIERJAX_CACHE_MAX_MB"
DEFAULT_MAX_MB = 2048
_PRUNE_TO = 0.8
#: Files used less than this many seconds ago are never removed: another process may be writing
#: or reading them (a temporary file before its rename, a program being loaded).
_PRUNE_MIN_AGE_S = 600.0

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
    try:
        limit = cache_max_bytes()
    except ValueError:
        limit = DEFAULT_MAX_MB * 2**20  # a malformed budget never fails a command
    prune_cache(limit, path)  # one walk of the folder; removes nothing within the budget
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


def cache_max_bytes() -> int:
    """The cache folder's size budget: ``$FOURIERJAX_CACHE_MAX_MB`` MiB, else `DEFAULT_MAX_MB`.

    Returns:
        The budget in bytes.

    Raises:
        ValueError: the variable is not a positive number.
    """
    raw = os.environ.get(CACHE_MAX_MB_ENV, "").strip()
    if not raw:
        return DEFAULT_MAX_MB * 2**20
    try:
        mb = float(raw)
    except ValueError:
        mb = float("nan")
    if not mb > 0 or mb == float("inf"):
        raise ValueError(f"${CACHE_MAX_MB_ENV} must be a positive number of MiB, got {raw!r}")
    return int(mb * 2**20)


def _files(path: str) -> list[tuple[float, int, str]]:
    """Every file under ``path`` as ``(last use, bytes, path)``; last use is the later of the
    access and modification times (JAX's cache rewrites nothing on a read)."""
    out = []
    for root, _dirs, names in os.walk(path):
        for name in names:
            full = os.path.join(root, name)
            try:
                st = os.stat(full, follow_symlinks=False)
            except OSError:  # removed meanwhile by another process
                continue
            out.append((max(st.st_atime, st.st_mtime), st.st_size, full))
    return out


def cache_usage(path: str | None = None) -> tuple[int, int]:
    """How much the cache folder holds: JAX's compiled programs and the saved programs.

    Arguments:
        path: the folder (default `cache_dir()`).

    Returns:
        ``(files, bytes)``; ``(0, 0)`` when the folder does not exist.
    """
    files = _files(path or cache_dir())
    return len(files), sum(size for _, size, _ in files)


def prune_cache(max_bytes: int, path: str | None = None, *, min_age_s: float = _PRUNE_MIN_AGE_S,
                now: float | None = None) -> tuple[int, int]:
    """Keep the cache folder within a budget: when it holds more than ``max_bytes``, remove the
    least recently used files until it holds at most 0.8 of it. Files used within the last
    ``min_age_s`` seconds stay (another process may be writing or loading them), so the folder
    can stay over budget until they age. A removed program is only compiled again when needed.

    Arguments:
        max_bytes: the budget in bytes.
        path: the folder (default `cache_dir()`).
        min_age_s: files used more recently than this are kept.
        now: the current time in seconds since the epoch (default: `time.time()`).

    Returns:
        ``(files removed, bytes removed)``.
    """
    import time

    files = sorted(_files(path or cache_dir()))
    total = sum(size for _, size, _ in files)
    if total <= max_bytes:
        return 0, 0
    cutoff = (time.time() if now is None else now) - min_age_s
    target = _PRUNE_TO * max_bytes
    removed = freed = 0
    for used, size, full in files:  # oldest first
        if total <= target or used > cutoff:
            break
        try:
            os.remove(full)
        except OSError:
            continue
        total -= size
        removed += 1
        freed += size
    return removed, freed


def clear_cache(path: str | None = None) -> tuple[int, int]:
    """Remove every file of the cache folder (JAX's compiled programs and the saved programs).

    Arguments:
        path: the folder (default `cache_dir()`).

    Returns:
        ``(files removed, bytes removed)``.
    """
    removed = freed = 0
    for _, size, full in _files(path or cache_dir()):
        try:
            os.remove(full)
        except OSError:
            continue
        removed += 1
        freed += size
    return removed, freed


def _set(option: str, value) -> None:
    # Before JAX is imported, its options are read from the environment on import: the command
    # line sets them without importing JAX (`fourierjax info` and `stance --list` never need it).
    if "jax" in sys.modules:
        sys.modules["jax"].config.update(option, value)
    else:
        os.environ[option.upper()] = str(value).lower() if isinstance(value, bool) else str(value)
