"""Shape buckets of batched fits: clip lengths and batch sizes padded to a few sizes, so that a
new clip length or batch size reuses compiled code; and the per-channel masks' gap filling."""

from __future__ import annotations

from typing import TYPE_CHECKING

import jax
import jax.numpy as jnp
import numpy as np

from fourierjax._memory import check_bytes

if TYPE_CHECKING:
    from jaxtyping import Array, Bool, Float

#: Batch sizes of the compiled fit programs: a batch is cut into chunks of `LARGE_BATCH` clips
#: and a remainder in chunks of `SMALL_BATCH` (padded with copies of the last clip), so any
#: batch size runs at most these two programs per clip-length bucket.
SMALL_BATCH = 16
LARGE_BATCH = 128


def length_bucket(num_frames: int) -> int:
    """The padded clip length of `num_frames`: the next power of two, at least 64.

    Arguments:
        num_frames: frames of the longest clip of a chunk.

    Returns:
        The bucket (frames).
    """
    return max(64, int(2 ** np.ceil(np.log2(max(int(num_frames), 1)))))


def batch_plan(total: int, bytes_per_clip: int, limit: int, *, name: str = "fit") -> list[tuple[int, int]]:
    """Chunks of a batch of `total` clips, each of a bucketed size: ``[(start, size), ...]``.

    Whole chunks of `LARGE_BATCH` clips, then the remainder in chunks of `SMALL_BATCH` (one more
    large chunk instead when the remainder is over half of one). The last chunk of each size may
    reach past `total`: its clips are padded with copies of the last one. When a large chunk does
    not fit the memory `limit`, only small chunks are used; when a small one does not either,
    chunks of the largest size that fits (a third program size, which only a tight budget sees).

    Arguments:
        total: clips in the batch (>= 1); bytes_per_clip: `_memory.fit_bytes_per_clip`;
        limit: the memory budget in bytes; name: what an error names when one clip does not fit.

    Returns:
        ``(start, size)`` per chunk, covering ``range(total)``.

    Raises:
        UserError: when one clip alone needs more than `limit`.
    """
    check_bytes(name, bytes_per_clip, limit, hint="raise max_memory or make the clips shorter")
    fits = max(1, int(limit // max(bytes_per_clip, 1)))
    large = LARGE_BATCH if fits >= LARGE_BATCH else 0
    small = SMALL_BATCH if fits >= SMALL_BATCH else fits
    plan, start = [], 0
    if large:
        while total - start >= large:
            plan.append((start, large))
            start += large
        if total - start > large // 2:
            plan.append((start, large))
            start = total
    while start < total:
        plan.append((start, small))
        start += small
    return plan


def fill_masked(features: Float[Array, "T C"], mask: Bool[Array, "T C"]) -> Float[Array, "T C"]:
    """Entries left out by a per-channel mask, filled by linear interpolation in time between
    the channel's nearest used frames (the nearest one at the ends; 0 for a channel with none):
    the first guess of the per-channel masked fit, which then replaces them by its model's values.

    Arguments:
        features: ``[T, C]`` samples (masked entries may hold NaN); mask: ``[T, C]`` True where used.

    Returns:
        ``[T, C]``: the used entries unchanged, the others filled.
    """
    T = features.shape[0]
    idx = jnp.broadcast_to(jnp.arange(T)[:, None], mask.shape)
    prev = jax.lax.cummax(jnp.where(mask, idx, -1), axis=0)
    nxt = jax.lax.cummin(jnp.where(mask, idx, T), axis=0, reverse=True)
    x = jnp.where(mask, features, jnp.zeros((), features.dtype))
    xp = jnp.take_along_axis(x, jnp.clip(prev, 0, T - 1), axis=0)
    xn = jnp.take_along_axis(x, jnp.clip(nxt, 0, T - 1), axis=0)
    has_p, has_n = prev >= 0, nxt < T
    span = jnp.maximum(nxt - prev, 1).astype(features.dtype)
    alpha = (idx - prev).astype(features.dtype) / span
    both = xp + alpha * (xn - xp)
    fill = jnp.where(has_p & has_n, both, jnp.where(has_p, xp, jnp.where(has_n, xn, 0.0)))
    return jnp.where(mask, features, fill)
