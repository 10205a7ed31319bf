"""Memory budgets: the bytes a user-set count implies, checked before any work, and chunk sizes."""

from __future__ import annotations

import math
import os

from fourierjax.errors import UserError

#: Fraction of the machine's memory (or of the process's cgroup limit, if lower) that one call
#: may use by default.
DEFAULT_FRACTION = 0.25

#: Used when the machine's memory cannot be read (no `os.sysconf`): 16 GiB.
_FALLBACK_TOTAL = 16 * 2**30

#: Peak values of `fit_batch` per clip, in units of one clip's features (`T * C` values): XLA's
#: temporaries, measured with `Compiled.memory_analysis()` (jax 0.10.2, CPU), are 19.2 (T = 240)
#: to 22.6 (T = 200) per feature for C = 5..120 and N = 1..12, linear in the batch and nearly
#: independent of N and `grid_points`; plus the input, its copy in a chunk, and leeway.
FIT_VALUES_PER_FEATURE = 26


def machine_memory() -> int:
    """Bytes of memory this process can use: physical memory, or the cgroup limit if lower.

    Returns:
        The bytes (a fallback of 16 GiB when the platform does not tell).
    """
    total = None
    try:
        total = os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES")
    except (AttributeError, ValueError, OSError):
        pass
    for path in ("/sys/fs/cgroup/memory.max", "/sys/fs/cgroup/memory/memory.limit_in_bytes"):
        try:
            with open(path) as f:
                text = f.read().strip()
        except OSError:
            continue
        if text.isdigit() and int(text) > 0:
            total = int(text) if total is None else min(total, int(text))
    return int(total) if total and total > 0 else _FALLBACK_TOTAL


def default_limit() -> int:
    """The default budget of one call: `DEFAULT_FRACTION` of `machine_memory()`.

    Returns:
        Bytes.
    """
    return int(machine_memory() * DEFAULT_FRACTION)


def format_bytes(nbytes: float) -> str:
    """`nbytes` for a message: ``"24.0 GB"``, ``"512 kB"`` (decimal units)."""
    nbytes = float(nbytes)
    if not math.isfinite(nbytes):
        return str(nbytes)
    for unit, size in (("TB", 1e12), ("GB", 1e9), ("MB", 1e6), ("kB", 1e3)):
        if abs(nbytes) >= size:
            return f"{nbytes / size:.1f} {unit}"
    return f"{int(nbytes)} bytes"


def resolve_limit(name: str, max_memory) -> int:
    """`max_memory` checked (a positive number of bytes), or the default budget for None.

    Arguments:
        name: what an error names, e.g. ``"fit_batch: max_memory"``.
        max_memory: bytes, or None.

    Returns:
        The budget in bytes (an int).
    """
    if max_memory is None:
        return default_limit()
    if isinstance(max_memory, bool):
        raise UserError(f"{name} must be a number of bytes, got {max_memory!r}")
    try:
        value = float(max_memory)
    except (TypeError, ValueError):
        raise UserError(f"{name} must be a number of bytes, got {max_memory!r}") from None
    if not (value > 0) or math.isnan(value):
        raise UserError(f"{name} must be a positive number of bytes, got {max_memory!r}")
    return int(min(value, 2**62))


def check_bytes(name: str, nbytes, limit=None, *, hint: str = "ask for less") -> int:
    """Refuse a request that would need more than `limit` bytes, before anything is allocated.

    Arguments:
        name: the argument (or arguments) that set the size, named in the error, e.g.
            ``"add_noise: harmonics=1000000000"``.
        nbytes: the bytes the request implies (any non-negative number; Python ints do not
            overflow, so compute it from the counts with Python integers).
        limit: the budget in bytes; None: `default_limit()`.
        hint: what the message suggests.

    Returns:
        `nbytes` as an int, when it fits.

    Raises:
        UserError: naming `name`, the bytes it would need and the limit.
    """
    limit = default_limit() if limit is None else int(limit)
    nbytes = float(nbytes) if not isinstance(nbytes, int) else nbytes
    if not (nbytes <= limit):  # NaN and inf are refused too
        raise UserError(
            f"{name} would need {format_bytes(nbytes)} of memory, more than the limit of "
            f"{format_bytes(limit)}; {hint}"
        )
    return int(nbytes)


def fit_bytes_per_clip(num_frames: int, num_channels: int, num_harmonics: int,
                       itemsize: int) -> int:
    """Peak bytes `fit_batch` needs per clip (`FIT_VALUES_PER_FEATURE` values per feature, plus
    the basis and the coefficients).

    Arguments:
        num_frames: T; num_channels: C; num_harmonics: N; itemsize: bytes per value (4 or 8).

    Returns:
        Bytes (a Python int).
    """
    T, C, k = int(num_frames), int(num_channels), 2 * int(num_harmonics) + 1
    return itemsize * (FIT_VALUES_PER_FEATURE * T * C + 2 * T * k + 4 * C * k + 64)


def chunk_sizes(total: int, per_item: int, limit: int, *, name: str = "batch") -> tuple[int, int]:
    """Split `total` items into equal chunks whose cost (`per_item` bytes each) fits `limit`.

    Arguments:
        total: items in the batch (>= 1).
        per_item: bytes one item needs.
        limit: the budget in bytes.
        name: what an error names when a single item does not fit (it names one item).

    Returns:
        `(num_chunks, chunk)`: `num_chunks * chunk >= total`, with fewer than `num_chunks` items of
        padding; one chunk when everything fits.

    Raises:
        UserError: when even one item needs more than `limit`.
    """
    check_bytes(name, per_item, limit, hint="raise max_memory or make the items smaller")
    fits = max(1, int(limit // max(per_item, 1)))
    num_chunks = -(-int(total) // fits)
    return num_chunks, -(-int(total) // num_chunks)


def synthesis_bytes(num_frames: int, num_channels: int, num_harmonics: int,
                    itemsize: int = 4) -> int:
    """Peak bytes of synthesizing and writing `num_frames` frames of a model: the sine and
    cosine basis `[T, N]`, the channels `[T, C]` with their float64 copy, and the BVH text
    (~12 bytes a value).

    Arguments:
        num_frames: T; num_channels: C; num_harmonics: N (after noise harmonics);
        itemsize: bytes per value of the synthesis (4 or 8).

    Returns:
        Bytes (a Python int, exact for any count).
    """
    T, C, N = int(num_frames), int(num_channels), int(num_harmonics)
    return itemsize * (4 * T * N + 3 * T * C) + 8 * T * C + 12 * T * C


def check_synthesis(name: str, num_frames: int, num_channels: int, num_harmonics: int,
                    limit=None, itemsize: int = 4) -> int:
    """`check_bytes` of `synthesis_bytes`: for commands that synthesize a user-set length.

    Arguments:
        name: what the error names, e.g. ``"--seconds 1e5 at 120 fps"``.
        num_frames, num_channels, num_harmonics, itemsize: as `synthesis_bytes`.
        limit: bytes; None: `default_limit()`.

    Returns:
        The bytes, when they fit.
    """
    return check_bytes(name, synthesis_bytes(num_frames, num_channels, num_harmonics, itemsize),
                       limit, hint="ask for fewer frames or harmonics")


def crowd_bytes(num_characters: int, num_joints: int, num_frames: int = 1,
                itemsize: int = 4) -> int:
    """Bytes of a crowd's positions over `num_frames` frames, with the per-frame world
    rotations and translations (12 values a joint) of the pose being computed.

    Arguments:
        num_characters: B; num_joints: J; num_frames: frames evaluated at once;
        itemsize: bytes per value.

    Returns:
        Bytes (a Python int).
    """
    B, J, T = int(num_characters), int(num_joints), int(num_frames)
    return itemsize * B * J * (3 * T + 12)
