"""The steady segment of a clip and its capture glitches, per joint and per feature channel."""

from __future__ import annotations

import numpy as np
from jaxtyping import ArrayLike, Bool

from fourierjax._fourier._layout import root_joints as _root_joints
from fourierjax._fourier._layout import rot as _rot
from fourierjax._fourier._layout import rotation_joints as _rotation_joints
from fourierjax._fourier._layout import world_pose as _world_pose
from fourierjax.features import ROOT_CHANNELS


def glitch_joints(
    motion, max_joint_speed_deg_s: float = 5000.0, pad_s: float = 0.1
) -> Bool[np.ndarray, "F J"]:
    """Capture glitches per joint: ``bool [F, J]`` (joints in file order), True within
    ``pad_s`` of a frame where that joint turns faster than ``max_joint_speed_deg_s`` (CMU
    142_02's left arm jumps 60 degrees in one frame at frame 1140; captured motion stays under
    ~3200 deg/s, even at toes and fingers). Joints without 3 rotation channels are never flagged.

    ``fit_motions`` masks the glitchy joint's feature channels at these frames (one glitchy
    thumb or toe does not drop the whole frame: :func:`feature_mask`).

    Arguments:
        motion: a Motion; max_joint_speed_deg_s: the speed above which a joint glitches;
        pad_s: seconds masked on either side.
    Returns:
        ``bool [F, J]``.
    """
    F, J = motion.num_frames, len(motion.topology.names)
    fast = np.zeros((F, J), bool)
    joints = _rotation_joints(motion.topology)
    for order in dict.fromkeys(o for _, o, _ in joints):
        group = [(j, i) for j, o, i in joints if o == order]
        q = _rot("quat_from_euler", np.radians(motion.channels[:, np.array([i for _, i in group])]),
                 order=order)
        dot = np.clip(np.abs(np.sum(q[1:] * q[:-1], axis=-1)), 0.0, 1.0)  # [F-1, J_g]
        fast[1:, [j for j, _ in group]] = (np.degrees(2 * np.arccos(dot)) / motion.frame_time_s
                                           > max_joint_speed_deg_s)
    return _dilate(fast, max(1, int(round(pad_s / motion.frame_time_s))))


def _dilate(flags: np.ndarray, pad: int) -> np.ndarray:
    """True within ``pad`` frames (first axis) of a True: a running count over a window."""
    F = flags.shape[0]
    c = np.concatenate([np.zeros((1, *flags.shape[1:]), np.int64), np.cumsum(flags, axis=0)])
    t = np.arange(F)
    hi, lo = np.minimum(t + pad + 1, F), np.maximum(t - pad, 0)
    return (c[hi] - c[lo]) > 0


def glitch_frames(
    motion, max_joint_speed_deg_s: float = 5000.0, pad_s: float = 0.1
) -> Bool[np.ndarray, " F"]:
    """Frames where some joint glitches: ``bool [F]``, :func:`glitch_joints` of any joint.

    Arguments:
        motion: a Motion; max_joint_speed_deg_s, pad_s: as :func:`glitch_joints`.
    Returns:
        ``bool [F]``.
    """
    return glitch_joints(motion, max_joint_speed_deg_s, pad_s).any(axis=1)


def feature_mask(
    glitch: Bool[ArrayLike, "F J"], topology, pelvis: int = 0
) -> Bool[np.ndarray, "F C"]:
    """The per-channel fit mask of a clip's features (:func:`features_from_motion`'s layout):
    False where the channel's joint glitches (:func:`glitch_joints`); the root channels
    (``root.*``, from the pelvis's world pose) where the pelvis or one of its ancestors does.

    Arguments:
        glitch: ``bool [F, J]``; topology: the clip's Topology; pelvis: the body map's pelvis.
    Returns:
        ``bool [F, C]``, True where used.
    """
    g = np.asarray(glitch, bool)
    chain = [pelvis]
    while topology.parents[chain[-1]] >= 0:
        chain.append(topology.parents[chain[-1]])
    joints = [j for j, _, _ in _rotation_joints(topology)]
    root = g[:, chain].any(axis=1)
    cols = np.concatenate([np.repeat(root[:, None], len(ROOT_CHANNELS), axis=1),
                           np.repeat(g[:, joints], 3, axis=1)], axis=1)
    return ~cols


def steady_segment(
    motion,
    *,
    body_map=None,
    window_s: float = 0.5,
    min_speed_fraction: float = 0.75,
    max_turn_deg_s: float = 30.0,
    min_duration_s: float = 0.5,
    turn_window_s: float = 1.0,
    trim_fraction: float = 0.9,
) -> tuple[int, int]:
    """The longest steady, straight stretch of a clip: frames ``[start, stop)``.

    The horizontal velocity of the body map's pelvis (world, through its ancestors: the
    trajectory joint's travel; CMU: joint 0) is smoothed over ``+-window_s`` (which averages out the
    in-step sway); a frame is steady when its smoothed speed is at least
    ``min_speed_fraction`` of the clip's 90th-percentile speed and its heading, of the velocity
    smoothed over ``+-turn_window_s`` (a slow walk sways by 20 degrees each step), turns slower
    than ``max_turn_deg_s``. The run's ends are then trimmed while their smoothed speed is
    under ``trim_fraction`` of the run's median (the acceleration from a standing start and the
    deceleration to a stop: Bandai clips start at 0.6-0.9 of their speed). Clips that start
    from standing, stop, or walk back and forth (CMU 142_02, 142_08) keep their longest steady
    run; if no run lasts ``min_duration_s`` the whole
    clip is returned. (Capture glitches inside it are masked by ``fit_motions``, see
    :func:`glitch_frames`.)

    Arguments:
        motion: a Motion (Y up); body_map: its `fourierjax.body.BodyMap` (None: inferred).
    Returns: ``(start, stop)`` frame indices into ``motion``.
    """
    pos, _ = _world_pose(motion, _root_joints(motion, body_map).pelvis)
    return steady_from_positions(pos[:, [0, 2]], motion.frame_time_s, window_s=window_s,
                                 min_speed_fraction=min_speed_fraction,
                                 max_turn_deg_s=max_turn_deg_s, min_duration_s=min_duration_s,
                                 turn_window_s=turn_window_s, trim_fraction=trim_fraction)


def steady_from_positions(p, frame_time_s, *, window_s=0.5, min_speed_fraction=0.75,
                          max_turn_deg_s=30.0, min_duration_s=0.5, turn_window_s=1.0,
                          trim_fraction=0.9) -> tuple[int, int]:
    """:func:`steady_segment` of the pelvis's ground-plane track ``p [F, 2]`` (world X, Z)."""
    F = len(p)
    w = max(1, int(round(window_s / frame_time_s)))
    idx = np.arange(F)
    hi, lo = np.minimum(idx + w, F - 1), np.maximum(idx - w, 0)
    span = np.maximum(hi - lo, 1) * frame_time_s
    v = (p[hi] - p[lo]) / span[:, None]
    speed = np.hypot(v[:, 0], v[:, 1])
    wt = max(w, int(round(turn_window_s / frame_time_s)))
    thi, tlo = np.minimum(idx + wt, F - 1), np.maximum(idx - wt, 0)
    vt = p[thi] - p[tlo]
    heading = np.unwrap(np.arctan2(vt[:, 0], vt[:, 1]))
    turn = np.abs(np.gradient(heading, frame_time_s)) if F > 1 else np.zeros(F)
    ref = np.percentile(speed, 90)
    if ref <= 0:
        return 0, F
    steady = (speed >= min_speed_fraction * ref) & (np.degrees(turn) <= max_turn_deg_s)
    # Runs of steady frames (the first of the longest wins).
    edges = np.diff(np.concatenate([[0], steady.astype(np.int8), [0]]))
    starts, stops = np.flatnonzero(edges == 1), np.flatnonzero(edges == -1)
    best = (0, 0)
    if starts.size:
        i = int(np.argmax(stops - starts))
        best = (int(starts[i]), int(stops[i]))
    if (best[1] - best[0]) * frame_time_s < min_duration_s:
        return 0, F
    a, b = best
    med = np.median(speed[a:b])
    while a < b - 1 and speed[a] < trim_fraction * med:
        a += 1
    while b - 1 > a and speed[b - 1] < trim_fraction * med:
        b -= 1
    if (b - a) * frame_time_s < min_duration_s:
        return best
    return a, b


# ----------------------------------------------------------------------------- clip fitting
