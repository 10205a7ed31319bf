"""Whole-file writes: an output file is either written completely or left as it was."""

from __future__ import annotations

import contextlib
import os
import tempfile
from collections.abc import Iterator


@contextlib.contextmanager
def temporary_beside(path: str | os.PathLike) -> Iterator[str]:
    """A temporary file name in `path`'s folder (same extension), renamed over `path` when the
    block completes and removed if it fails. A failed write (disk full, file-size limit,
    interrupt) then leaves no partial file behind (a BVH cut at frame 214 of 480 read back as
    a malformed file) and any earlier `path` untouched.

    Raises:
        OSError: as the writes would (the folder does not exist, permission denied, `path` is
            a directory, no space left), naming `path`, with the temporary file removed.
    """
    path = os.fspath(path)
    base = os.path.basename(path)
    try:
        fd, tmp = tempfile.mkstemp(prefix=f".{base}.", suffix=".part" + os.path.splitext(base)[1],
                                   dir=os.path.dirname(path) or ".")
    except OSError as err:  # name the file asked for, not the temporary one
        raise OSError(err.errno, err.strerror, path) from None
    os.close(fd)
    try:
        yield tmp
        os.chmod(tmp, 0o666 & ~_umask())  # mkstemp makes 0600; give the usual permissions
        os.replace(tmp, path)
    except BaseException as err:
        with contextlib.suppress(OSError):
            os.unlink(tmp)
        if isinstance(err, OSError) and err.filename in (None, tmp):
            raise OSError(err.errno, err.strerror, path) from None
        raise


def write_bytes_atomic(path: str | os.PathLike, data: bytes) -> None:
    """Write `data` to `path` whole or not at all (`temporary_beside`)."""
    with temporary_beside(path) as tmp, open(tmp, "wb") as f:
        f.write(data)


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask
