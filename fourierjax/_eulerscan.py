"""Continuous Euler angles over time as array ops: a parallel prefix over frames (NumPy)."""

from __future__ import annotations

import numpy as np

_TWO_PI = 2 * np.pi


def continuous(flat: np.ndarray, twins: np.ndarray, ok: np.ndarray) -> np.ndarray:
    """`features.make_euler_continuous` of ``flat [F, K, 3]`` without a loop over frames.

    Each frame takes, of its two Euler triples (``flat`` and ``twins``, each shifted by 2 pi
    per angle towards its reference frame), the one closest to that reference: the previous
    frame, or for a valid frame the last valid one before it (``ok [F, K]``). Which triple is
    taken at a frame depends only on which was taken at its reference (the shifts drop out of
    the distance), so every frame's choice is a map of two states, and its 2 pi shift an offset
    per state. Maps and offsets compose along the reference chain by pointer jumping:
    ``ceil(log2 F)`` rounds of array ops over all frames and columns at once.

    Arguments:
        flat: ``[F, K, 3]`` radians (K columns: joints, clips); twins: the other triple of each
            (``rotations.euler_twin``); ok: ``bool [F, K]`` valid frames.

    Returns:
        ``[F, K, 3]``: the same values as the frame loop, frame 0 kept.
    """
    F, K, _ = flat.shape
    out = np.empty_like(flat)
    chain = ok[1:].all(axis=0)  # columns where every frame follows the frame before
    cols = np.flatnonzero(chain)
    # Blocks of columns stay in cache; slices (views, not copies) when every column chains.
    blocks = ([slice(b, b + _BLOCK) for b in range(0, K, _BLOCK)] if cols.size == K
              else [cols[b:b + _BLOCK] for b in range(0, cols.size, _BLOCK)])
    for c in blocks:
        out[:, c] = _chained(flat[:, c], twins[:, c])
    cols = np.flatnonzero(~chain)
    if cols.size:
        f, w, o = flat[:, cols], twins[:, cols], ok[:, cols]
        t = np.arange(F)[:, None]
        last = np.maximum.accumulate(np.where(o, t, -1), axis=0)
        ref = np.where(last >= 0, last, t)  # the last valid frame <= t, or t before any
        parent = np.zeros(o.shape, np.int64)
        parent[1:] = np.where(o[1:], ref[:-1], t[:-1])
        k = np.arange(cols.size)[None, :]
        state, shift = _transitions(f, w, f[parent[1:], k], w[parent[1:], k])
        out[:, cols] = _apply(f, w, *_jumping(state, shift, parent))
    return out


#: Columns per block of the chain case.
_BLOCK = 256


def _transitions(flat, twins, prev0, prev1):
    """For frames 1.. and each state of their reference (``prev0``: its raw triple,
    ``prev1``: its twin, ``[F - 1, K, 3]``): the state taken (``[2, F, K]`` int8) and the 2 pi
    shifts relative to the reference's (``[2, F, K, 3]``); frame 0 maps to itself."""
    F, K, _ = flat.shape
    state = np.zeros((2, F, K), np.int8)
    shift = np.zeros((2, F, K, 3), np.int64)
    cur, alt = flat[1:], twins[1:]
    for s, prev in ((0, prev0), (1, prev1)):
        k0, k1 = _turns(prev, cur), _turns(prev, alt)
        d0, d1 = _distance(cur, k0, prev), _distance(alt, k1, prev)
        pick = d1 < d0 - 1e-12
        state[s, 1:] = pick
        shift[s, 1:] = np.where(pick[..., None], k1, k0)
    state[1, 0] = 1
    return state, shift


# The two helpers below compute what `np.round((prev - cur) / 2 pi)` and
# `np.sum((cur + 2 pi k - prev) ** 2, axis=-1)` do, bit for bit, in place (fewer fresh
# temporaries) and without a reduction over a length-3 axis (numpy adds its three terms in
# order; its per-row cost is more than the arithmetic).
def _turns(prev, cur):
    k = np.subtract(prev, cur)
    k /= _TWO_PI
    return np.round(k, out=k)


def _distance(cur, k, prev):
    d = _TWO_PI * k
    d += cur
    d -= prev
    d *= d
    x = d[..., 0] + d[..., 1]
    x += d[..., 2]
    return x


def _apply(flat, twins, s, k):
    return np.where(s[..., None] == 1, twins, flat) + _TWO_PI * k.astype(np.float64)


def _chained(flat, twins):
    """`continuous` of columns where each frame's reference is the frame before: the states
    first (`_states`), then each frame's 2 pi shifts from the triples taken at it and at the
    frame before (the shift `_transitions` gives for that pair), summed along the frames
    (whole turns as float64: exact); no shift per state to store and select."""
    F, K, _ = flat.shape
    state = np.zeros((2, F, K), np.int8)
    cur, alt = flat[1:], twins[1:]
    for s, prev in ((0, flat[:-1]), (1, twins[:-1])):
        k0, k1 = _turns(prev, cur), _turns(prev, alt)
        state[s, 1:] = _distance(alt, k1, prev) < _distance(cur, k0, prev) - 1e-12
    state[1, 0] = 1
    taken = np.where((_states(state) == 1)[..., None], twins, flat)
    k = np.zeros_like(taken)
    k[1:] = _turns(taken[:-1], taken[1:])
    np.cumsum(k, axis=0, out=k)
    k *= _TWO_PI
    taken += k
    return taken


def _states(state):
    """The state taken at each frame, where each frame's reference is the frame before
    (``state``: `_transitions`'): a map of two states is constant, the identity or a flip, so
    the state is the last constant's value flipped by the parity of the flips since."""
    F = state.shape[1]
    t = np.arange(F)[:, None]
    const = state[0] == state[1]
    const[0] = True  # frame 0: state 0
    flip = (state[0] == 1) & (state[1] == 0)
    last = np.maximum.accumulate(np.where(const, t, 0), axis=0)
    value = np.take_along_axis(state[0], last, axis=0)
    flips = np.cumsum(flip, axis=0)
    return value ^ ((flips - np.take_along_axis(flips, last, axis=0)) & 1).astype(np.int8)


def _jumping(state, shift, parent):
    """States and accumulated shifts along any reference chains (glitches skip frames):
    pointer jumping, composing each frame's maps with its ancestor's, ``ceil(log2 F)``
    rounds."""
    _, F, K = state.shape
    cols = np.arange(K)[None, :]
    idx = (parent * K + cols).reshape(-1)
    st, sh = state.reshape(2, -1), shift.reshape(2, -1, 3)
    for _ in range(max(1, int(np.ceil(np.log2(max(F, 2)))))):
        a_st, a_sh = st[:, idx], sh[:, idx]  # the ancestor's, per state of its own ancestor
        st, sh = np.where(a_st == 1, st[1], st[0]), a_sh + np.where((a_st == 1)[..., None], sh[1], sh[0])
        idx = idx[idx]
    return st[0].reshape(F, K), sh[0].reshape(F, K, 3)
