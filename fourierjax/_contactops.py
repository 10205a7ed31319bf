"""Contact detection's per-frame rules as array ops along time (no loop over frames or runs)."""

from __future__ import annotations

import numpy as np


def run_bounds(code: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Start and stop (exclusive) of the run of equal values each entry of ``code [T, ...]``
    belongs to, along axis 0."""
    T = code.shape[0]
    t = np.arange(T).reshape((T,) + (1,) * (code.ndim - 1))
    new = np.ones(code.shape, bool)
    new[1:] = code[1:] != code[:-1]
    start = np.maximum.accumulate(np.where(new, t, 0), axis=0)
    nxt = np.full(code.shape, T)
    nxt[:-1] = np.where(new[1:], t[1:], T)
    stop = np.minimum.accumulate(nxt[::-1], axis=0)[::-1]
    return start, stop


def cleanup(c: np.ndarray, min_len: int, max_gap: int, lengths=None) -> np.ndarray:
    """Gaps of at most ``max_gap`` frames inside contacts closed (never at a clip's ends),
    then contacts shorter than ``min_len`` dropped: along axis 0 of ``c [T, ...]``, each column
    ``lengths [...]`` frames long (default T; frames after are ignored and come back False)."""
    c = np.asarray(c, bool)
    T = c.shape[0]
    n = np.full(c.shape[1:], T) if lengths is None else np.asarray(lengths)
    live = np.arange(T).reshape((T,) + (1,) * (c.ndim - 1)) < n
    code = np.where(live, c.astype(np.int8), 2)  # 2: after the clip, a run of its own
    start, stop = run_bounds(code)
    code = np.where((code == 0) & (start > 0) & (stop < n) & (stop - start <= max_gap), 1, code)
    start, stop = run_bounds(code)
    return (code == 1) & (stop - start >= min_len)


def hysteresis(enter: np.ndarray, stay: np.ndarray) -> np.ndarray:
    """``on[t] = enter[t] or (on[t - 1] and stay[t])`` along axis 0, without a loop: on when
    the last frame that entered comes after (or is) the last frame that did not stay."""
    T = enter.shape[0]
    t = np.arange(T).reshape((T,) + (1,) * (enter.ndim - 1))
    last_enter = np.maximum.accumulate(np.where(enter, t, -1), axis=0)
    last_break = np.maximum.accumulate(np.where(stay, -1, t), axis=0)
    return (last_enter >= 0) & (last_break <= last_enter)


def speeds(p: np.ndarray, frame_time_s: float) -> np.ndarray:
    """`point_speeds` in float64 NumPy (the detection's thresholds; no eager JAX op, which
    would compile for every new clip length)."""
    v = np.empty_like(p)
    v[0], v[-1] = p[1] - p[0], p[-1] - p[-2]
    v[1:-1] = (p[2:] - p[:-2]) * 0.5
    v /= frame_time_s
    return np.sqrt(np.sum(v * v, axis=-1))
