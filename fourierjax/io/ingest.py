"""Read many BVH files in parallel worker processes, with a progress bar and per-file errors."""

from __future__ import annotations

import concurrent.futures as cf
import multiprocessing
import os
from collections.abc import Iterable

from fourierjax.errors import UserError
from fourierjax.io.bvh import BVHError, Motion, read_bvh

__all__ = ["load_many"]


def _read_one(path: str) -> Motion | BVHError:
    # Runs in a worker: return the error instead of raising, so one bad file never takes the
    # batch (or the pool) down with it. BVHError pickles (its args are kept).
    try:
        return read_bvh(path)
    except BVHError as err:
        return err
    except Exception as err:  # a reader bug: still report it against the file
        return BVHError(path, None, f"unexpected {type(err).__name__}: {err}")


def _read_chunk(paths: list[str]) -> list[Motion | BVHError]:
    return [_read_one(p) for p in paths]


#: Most files per worker task (default `chunk_size`): the progress bar moves and an interrupt
#: is honoured after at most this many files per worker (chunks of 342 files kept the bar at
#: 0 of 2730 for 7 s).
_MAX_CHUNK = 16


def _expand(paths) -> list[str]:
    """The BVH paths: a list as given, or one path; a folder stands for its *.bvh files
    (sorted; case-insensitive suffix), not for the characters of its name."""
    if isinstance(paths, str | os.PathLike):
        one = os.fspath(paths)
        if os.path.isdir(one):
            return sorted(os.path.join(one, f) for f in os.listdir(one) if f.lower().endswith(".bvh"))
        return [one]
    try:
        return [os.fspath(p) for p in paths]
    except TypeError:
        raise UserError(f"load_many: `paths` must be BVH paths (a list, one path or a folder), "
                        f"got {type(paths).__name__}") from None


def _default_workers(num_files: int) -> int:
    try:
        cpus = len(os.sched_getaffinity(0))
    except AttributeError:  # not on Linux
        cpus = os.cpu_count() or 1
    return max(1, min(cpus, num_files))


def load_many(
    paths: Iterable[str | os.PathLike],
    workers: int | None = None,
    progress: bool = True,
    chunk_size: int | None = None,
) -> tuple[list[Motion], list[BVHError]]:
    """Read BVH files in parallel processes; bad files are reported, not raised.

    Files are split into chunks that worker processes parse with `read_bvh` (the parse is
    NumPy-bound and holds the GIL, so processes, not threads, are what scale). Workers are
    started with the "spawn" method: forking a process that has initialised JAX can deadlock.

    Arguments:
        paths: BVH file paths, one path, or a folder (its `*.bvh` files, sorted).
        workers: number of worker processes; `None` uses every CPU this process may run on
            (at most one per file); `1` (or `0`) reads in this process without a pool.
        progress: show a tqdm progress bar (files done, errors so far) on stderr.
        chunk_size: files per task; default about 4 tasks per worker, at most 16 files each.

    Returns:
        `(motions, errors)`: the motions that loaded, in input order (each carries its
        path as `Motion.source`), and one `BVHError` per file that did not (`err.path`,
        `err.line`, `str(err)` = "path:line: message"), in input order.
    """
    paths = _expand(paths)
    if workers is not None and (isinstance(workers, bool) or not isinstance(workers, int) or workers < 0):
        raise UserError(f"load_many: `workers` must be a non-negative int or None, got {workers!r}")
    if chunk_size is not None and (isinstance(chunk_size, bool) or not isinstance(chunk_size, int)
                                   or chunk_size < 1):
        raise UserError(f"load_many: `chunk_size` must be a positive int or None, got {chunk_size!r}")
    n = len(paths)
    workers = _default_workers(n) if workers is None else max(1, min(workers, max(n, 1)))
    results: list[Motion | BVHError | None] = [None] * n

    bar = None
    if progress:
        from tqdm.auto import tqdm

        bar = tqdm(total=n, unit="file", desc="reading BVH", disable=n == 0)
    num_errors = 0

    def done(start: int, chunk_results: list[Motion | BVHError]) -> None:
        nonlocal num_errors
        for k, r in enumerate(chunk_results):
            results[start + k] = r
            num_errors += isinstance(r, BVHError)
        if bar is not None:
            bar.update(len(chunk_results))
            if num_errors:
                bar.set_postfix(errors=num_errors)

    try:
        if workers == 1:
            for i, p in enumerate(paths):
                done(i, [_read_one(p)])
        else:
            size = chunk_size or max(1, min(_MAX_CHUNK, -(-n // (4 * workers))))
            starts = range(0, n, size)
            ctx = multiprocessing.get_context("spawn")
            pool = cf.ProcessPoolExecutor(max_workers=workers, mp_context=ctx)
            try:
                futures = {pool.submit(_read_chunk, paths[s : s + size]): s for s in starts}
                for fut in cf.as_completed(futures):
                    done(futures[fut], fut.result())
            except BaseException:
                # Ctrl-C (or an error): drop the chunks not started instead of reading every
                # file first (2730 files: the pool ran on for 12 s after the interrupt).
                pool.shutdown(wait=False, cancel_futures=True)
                raise
            pool.shutdown()
    finally:
        if bar is not None:
            bar.close()

    motions = [r for r in results if isinstance(r, Motion)]
    errors = [r for r in results if isinstance(r, BVHError)]
    return motions, errors
