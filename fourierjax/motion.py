"""Fitting Fourier models to motion clips: steady segments, glitch frames, contacts, `fit_motions`.

The feature layout itself (channel names, Motion <-> features) lives in `fourierjax.features`;
its names are re-exported here for old imports.
"""

from __future__ import annotations

import concurrent.futures
import dataclasses
import itertools
import os
import time

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import ArrayLike, Bool, Float, Int

from fourierjax import _jit
from fourierjax._fourier._buckets import length_bucket as _bucket
from fourierjax._fourier._layout import root_joints as _root_joints
from fourierjax._fourier._layout import rot as _rot
from fourierjax._fourier._layout import rotation_joints as _rotation_joints
from fourierjax._fourier._layout import world_pose as _world_pose
from fourierjax._fourier._model import FourierModel
from fourierjax.errors import UserError
from fourierjax.features import (  # noqa: F401  (re-exported: their old home)
    REPRESENTATIONS,
    ROOT_CHANNELS,
    channel_model,
    channel_names_for,
    features_from_motion,
    heading_of,
    joint_expmaps,
    local_pose_from_features,
    make_euler_continuous,
    motion_from_features,
    root_relative_positions,
)
from fourierjax.skeleton import Skeleton

__all__ = [
    "channel_names_for",
    "heading_of",
    "features_from_motion",
    "motion_from_features",
    "channel_model",
    "make_euler_continuous",
    "local_pose_from_features",
    "root_relative_positions",
    "joint_expmaps",
    "motion_joint_positions",
    "model_joint_positions",
    "foot_positions_of",
    "foot_contacts_of",
    "glitch_joints",
    "glitch_frames",
    "feature_mask",
    "steady_segment",
    "fit_motions",
    "ClipFit",
]


def motion_joint_positions(
    motion, frames: Int[ArrayLike, " K"] | None = None
) -> Float[np.ndarray, "K J 3"]:
    """World joint positions of a clip through forward kinematics of its BVH channels.

    Arguments:
        motion: a Motion; frames: optional frame indices (default: every frame).
    Returns:
        ``[F, J, 3]`` file units (JAX's default float dtype), joints in file order.
    """
    from fourierjax.kinematics import joint_positions

    ch = motion.channels if frames is None else motion.channels[np.asarray(frames)]
    return np.asarray(joint_positions(motion.skeleton(), jnp.asarray(ch)))


_root_relative_positions_jit = _jit.filter_jit(root_relative_positions)


def model_joint_positions(
    model: FourierModel, skeleton: Skeleton, phases: Float[ArrayLike, " K"], pelvis: int = 0
) -> Float[np.ndarray, "K J 3"]:
    """Joint positions of a Fourier gait model's pose at cycle phases (Unuma 1995 eq. 1).

    The pose is ``fourier.synthesize_phase(model, phases)`` through forward kinematics; the
    root stands above the origin of the heading frame (facing +Z) at the model's ``root.y``
    height, so poses of different models line up for side-by-side plots.

    Arguments:
        model: a ``FourierModel`` with the gait channel layout (:func:`channel_names_for`);
        skeleton: the Skeleton the model was fitted on; phases: ``[K]`` radians of the cycle;
        pelvis: the body map's pelvis (``BodyMap.pelvis``; CMU: joint 0).
    Returns:
        ``[K, J, 3]`` file units.
    """
    from fourierjax import fourier

    feats = fourier.synthesize_phase(model, jnp.asarray(phases, float))
    p = np.asarray(_root_relative_positions_jit(skeleton, feats, model.representation, pelvis))
    height = np.asarray(feats[:, ROOT_CHANNELS.index("root.y")])
    return p + height[:, None, None] * np.array([0.0, 1.0, 0.0])


def _hip_flexion_channel(model, names, bm) -> int | None:
    """The left hip's feature channel with the largest fundamental (its flexion), or None."""
    hip = bm.name(bm.left.hip) + "."
    cands = [i for i, n in enumerate(names) if n.startswith(hip)]
    if not cands:
        return None
    amp = np.asarray(model.amplitude)[np.array(cands), 0]
    return cands[int(np.argmax(amp))]


def _hip_flexion_phase(model, motion, channel: int, bm):
    """Phase of the left hip's peak flexion: the extreme of the hip channel's fundamental at
    which the body map's left knee is further forward (+Z in the heading frame, which is where
    the body faces) than at the other.

    The channel's peak alone (``fourier.channel_event_phase``) is not enough: whether flexion is
    its maximum or its minimum depends on the skeleton's axes (on CMU skeletons flexion is
    negative ``LeftUpLeg.Xrotation``, and the peak is full extension, half a cycle off).
    """
    from fourierjax import fourier as fr

    peak = float(fr.channel_event_phase(model, channel))
    hip, knee = bm.left.hip, bm.left.knee
    p = model_joint_positions(model, motion.skeleton(), np.array([peak, peak + np.pi]), bm.pelvis)
    ahead = p[:, knee, 2] - p[:, hip, 2]
    return jnp.asarray(peak if ahead[0] >= ahead[1] else peak + np.pi)


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
    F = motion.num_frames
    pos, _ = _world_pose(motion, _root_joints(motion, body_map).pelvis)
    p = pos[:, [0, 2]]
    w = max(1, int(round(window_s / motion.frame_time_s)))
    idx = np.arange(F)
    hi, lo = np.minimum(idx + w, F - 1), np.maximum(idx - w, 0)
    span = np.maximum(hi - lo, 1) * motion.frame_time_s
    v = (p[hi] - p[lo]) / span[:, None]
    speed = np.hypot(v[:, 0], v[:, 1])
    wt = max(w, int(round(turn_window_s / motion.frame_time_s)))
    thi, tlo = np.minimum(idx + wt, F - 1), np.maximum(idx - wt, 0)
    vt = p[thi] - p[tlo]
    heading = np.unwrap(np.arctan2(vt[:, 0], vt[:, 1]))
    turn = np.abs(np.gradient(heading, motion.frame_time_s)) if F > 1 else np.zeros(F)
    ref = np.percentile(speed, 90)
    if ref <= 0:
        return 0, F
    steady = (speed >= min_speed_fraction * ref) & (np.degrees(turn) <= max_turn_deg_s)
    best = (0, 0)
    start = None
    for i, s in enumerate(np.append(steady, False)):
        if s and start is None:
            start = i
        elif not s and start is not None:
            if i - start > best[1] - best[0]:
                best = (start, i)
            start = None
    if (best[1] - best[0]) * motion.frame_time_s < min_duration_s:
        return 0, F
    a, b = best
    med = np.median(speed[a:b])
    while a < b - 1 and speed[a] < trim_fraction * med:
        a += 1
    while b - 1 > a and speed[b - 1] < trim_fraction * med:
        b -= 1
    if (b - a) * motion.frame_time_s < min_duration_s:
        return best
    return a, b


# ----------------------------------------------------------------------------- clip fitting


@dataclasses.dataclass(frozen=True)
class ClipFit:
    """A fitted clip: the phase-aligned model plus what was used and how well it fits.

    Frames ``[frame_start, frame_stop)`` index the Motion given to :func:`fit_motions`. ω per
    method in rad/s (``omega_steps`` is NaN without step events). ``alignment`` names the event
    at phase 0 (``"left_heel_strike"``, the fallback ``"left_hip_flexion"`` or ``"none"``) and
    ``phase_shift`` the shift applied (a clip time t has aligned phase ``omega t - phase_shift``).
    Metrics are over the fitted frames: ``rms`` per channel (radians or file units),
    ``rms_deg`` and ``variance_explained_angles`` over rotation channels,
    ``variance_explained_positions`` over root-relative joint positions (through FK).
    ``masked_frames`` counts frames where some joint glitched (:func:`glitch_joints`) and
    ``masked_entries`` the feature samples (frame x channel) left out of the fit for it.
    ``result`` is the clip's `fourier.FitStatus` name in lower case (``"successful"``, else e.g.
    ``"too_few_cycles"``; the model and metrics are then meaningless) and ``message`` says what
    is wrong, naming the clip's file. ``body_map`` is the clip's `fourierjax.body.BodyMap` (None
    for a skeleton without recognisable legs).
    """

    source: str | None
    frame_start: int
    frame_stop: int
    frame_time_s: float
    model: object
    raw_model: object
    alignment: str
    phase_shift: float
    omega_spectral: float
    omega_steps: float
    omega_fit: float
    rms: np.ndarray
    rms_deg: float
    variance_explained_angles: float
    variance_explained_positions: float
    left_heel_strikes: tuple[int, ...]
    right_heel_strikes: tuple[int, ...]
    masked_frames: int = 0
    masked_entries: int = 0
    result: str = "successful"
    message: str = ""
    body_map: object = None

    @property
    def successful(self) -> bool:
        return self.result == "successful"

    @property
    def fundamental_hz(self) -> float:
        return self.omega_fit / (2 * np.pi)

    def summary(self) -> dict:
        """JSON-able summary (frequencies in Hz, metrics as floats)."""
        hz = 1 / (2 * np.pi)

        def f(v):
            return None if not np.isfinite(v) else float(v)

        return {
            "source": self.source,
            "frame_start": self.frame_start,
            "frame_stop": self.frame_stop,
            "num_frames": self.frame_stop - self.frame_start,
            "frame_time_s": self.frame_time_s,
            "num_harmonics": int(self.model.num_harmonics),
            "representation": self.model.representation,
            "fundamental_hz": f(self.omega_fit * hz),
            "fundamental_hz_spectral": f(self.omega_spectral * hz),
            "fundamental_hz_steps": f(self.omega_steps * hz),
            "fundamental_hz_fit": f(self.omega_fit * hz),
            "omega_rad_s": {"spectral": f(self.omega_spectral), "steps": f(self.omega_steps),
                            "fit": f(self.omega_fit)},
            "rms_deg": float(self.rms_deg),
            "variance_explained_angles": float(self.variance_explained_angles),
            "variance_explained_positions": float(self.variance_explained_positions),
            "alignment": self.alignment,
            "phase_shift_rad": float(self.phase_shift),
            "left_heel_strikes": list(self.left_heel_strikes),
            "right_heel_strikes": list(self.right_heel_strikes),
            "masked_glitch_frames": self.masked_frames,
            "masked_glitch_entries": self.masked_entries,
        }


def foot_positions_of(motion, points=None, *, body_map=None) -> Float[np.ndarray, "F P 3"]:
    """World positions of the foot points of every frame of a clip, through FK.

    Frames are padded to a few length buckets, so clips of similar lengths share one compiled
    FK.

    Arguments:
        motion: a Motion; points: ``contacts.FootPoints`` (default: the body map's feet,
        ``contacts.foot_points(motion.topology, body_map)``: ankle, toe, toe tip);
        body_map: the clip's `fourierjax.body.BodyMap` (None: inferred when ``points`` is None).
    Returns:
        ``[F, 2, P, 3]`` (left, right) file units, ready for ``contacts.foot_contacts`` and
        ``contacts.estimate_ground``.
    """
    from fourierjax import contacts
    from fourierjax.body import infer_body_map
    from fourierjax.kinematics import fk_frames

    if points is None:
        points = contacts.foot_points(motion.topology, body_map or infer_body_map(motion))
    F = motion.num_frames
    ch = np.concatenate([motion.channels, np.repeat(motion.channels[-1:], _bucket(F) - F, 0)])
    fk = fk_frames(motion.skeleton(), jnp.asarray(ch))
    return np.asarray(contacts.gather_foot_positions(fk.positions, fk.end_site_positions,
                                                     points))[:F]


def foot_contacts_of(motion, *, body_map=None) -> Bool[np.ndarray, "F 2"] | None:
    """Foot contacts ``bool [F, 2]`` (left, right) of a clip: ``fourierjax.contacts`` on FK of
    the body map's foot points (ankle, toe, toe tip), about its up axis. None when the skeleton
    has no body map (no legs can be found).

    Arguments:
        motion: a Motion; body_map: its `fourierjax.body.BodyMap` (None: inferred).
    Returns:
        ``bool [F, 2]`` or None.
    """
    from fourierjax import contacts
    from fourierjax.body import BodyMapError, infer_body_map

    if body_map is None:
        try:
            body_map = infer_body_map(motion)
        except BodyMapError:
            return None
    points = contacts.foot_points(motion.topology, body_map)
    return contacts.foot_contacts(foot_positions_of(motion, points), motion.frame_time_s,
                                  up_axis=body_map.up_axis)


def _steps(contacts_lr, frame_time_s):
    """(left strikes, right strikes, omega from steps or NaN): Tilmanne §2.2, cycle = 2 steps.

    The step period is the MEDIAN interval (``contacts.step_period_s``), so that a spurious
    extra strike (stumbling, CMU 142_02) does not halve the cycle.
    """
    from fourierjax import contacts

    if contacts_lr is None:
        return np.zeros(0, int), np.zeros(0, int), float("nan")
    left, right = contacts.step_events(contacts_lr)
    try:
        step = contacts.step_period_s(contacts_lr, frame_time_s, statistic="median")
    except UserError:  # fewer than two alternating heel strikes
        return left, right, float("nan")
    # Both feet striking together (two-footed hops) can give a zero median: no step frequency.
    return left, right, float(2 * np.pi / (2 * step)) if step > 0 else float("nan")


def _position_ve(skeleton, representation, x, xhat, mask, pelvis=0):
    return _position_ve_jit(skeleton, x, xhat, mask, representation, pelvis)


def _position_ve_impl(skeleton, x, xhat, mask, representation, pelvis):
    from fourierjax.fourier import variance_explained

    p = root_relative_positions(skeleton, x, representation, pelvis)
    ph = root_relative_positions(skeleton, xhat, representation, pelvis)
    return variance_explained(p, ph, mask)


_position_ve_jit = _jit.filter_jit(_position_ve_impl)


#: A joint whose continuous Euler channels span more than this (radians) passes near gimbal
#: lock: its first and third angles wind around the pole (a Bandai `Spine`: 1,680 degrees).
_WINDING_SPAN = np.pi


def _search_weights(x, names, keep) -> tuple[float, ...] | None:
    """Channel weights of the ω search: ``fourier.fit_batch``'s default (1 for rotations, 0 for
    ``root.*``), and 0 for every channel of a joint whose Euler angles wind near gimbal lock
    (their spectrum is the winding, not the gait). None when no joint winds (the default)."""
    from fourierjax.fourier import angle_channel_mask

    w = np.asarray(angle_channel_mask(names), float)
    span = np.ptp(x[np.asarray(keep, bool)], axis=0) if np.any(keep) else np.zeros(len(names))
    joints = {n.rsplit(".", 1)[0] for n, sp, a in zip(names, span, w) if a and sp > _WINDING_SPAN}
    if not joints:
        return None
    w = np.where([n.rsplit(".", 1)[0] in joints for n in names], 0.0, w)
    if not w.any():
        return None
    return tuple(float(v) for v in w)


def _frame_range(motion, start_frame, stop_frame) -> tuple[int, int]:
    F = motion.num_frames
    lo = 0 if start_frame is None else int(start_frame)
    hi = F if stop_frame is None else int(stop_frame)
    if not 0 <= lo < hi <= F:
        raise UserError(f"fit_motions: frames [{start_frame}, {stop_frame}) are outside "
                        f"{motion.source or 'the clip'} (frames 0..{F - 1})")
    return lo, hi


@dataclasses.dataclass
class _Clip:
    """A clip ready for the batched fit: frames ``[start, stop)`` of ``motion`` (``sub``), its
    features ``[F, C]`` and per-channel fit mask ``[F, C]`` (True: used), heel strikes and ω from
    steps. A mode that fits part of a clip (e.g. the straight passes of a turning walk) ANDs its
    frame mask ``[F]`` into ``mask`` here; per-pass time offsets would need the fit's sample
    times (``fit_batch`` assumes ``t = k * frame_time_s``)."""

    index: int
    motion: object
    start: int
    stop: int
    sub: object
    features: np.ndarray
    names: tuple[str, ...]
    mask: np.ndarray
    left: np.ndarray
    right: np.ndarray
    omega_steps: float
    body_map: object


def _prepare(index, m, bm, *, representation, segment, use_contacts, start_frame, stop_frame,
             timings) -> _Clip:
    """Everything before the fit for one clip: body map, steady segment, glitch masks,
    features, contacts and steps (``timings``: seconds added per stage)."""
    from fourierjax.body import BodyMapError, infer_body_map
    from fourierjax.io.bvh import read_bvh

    clock = _Clock(timings)
    if isinstance(m, (str, os.PathLike)):
        m = read_bvh(m)
        clock("read")
    lo, hi = _frame_range(m, start_frame, stop_frame)
    clip = m[lo:hi]
    if bm is None:
        try:
            bm = infer_body_map(clip)
        except BodyMapError:
            bm = None  # no legs: joint 0 carries the root, no contacts, no alignment
    clock("body_map")
    a, b = steady_segment(clip, body_map=bm) if segment else (0, clip.num_frames)
    a, b = a + lo, b + lo
    sub = m[a:b]
    clock("segment")
    glitch = glitch_joints(sub)
    clock("glitch")
    x, names = features_from_motion(sub, representation, valid=~glitch, body_map=bm)
    mask = feature_mask(glitch, sub.topology, 0 if bm is None else bm.pelvis)
    clock("features")
    c = foot_contacts_of(sub, body_map=bm) if use_contacts and bm is not None else None
    left, right, om = _steps(c, sub.frame_time_s)
    clock("contacts")
    return _Clip(index, m, a, b, sub, x, names, mask, left, right, om, bm)


class _Clock:
    """Adds the seconds since the last call to ``timings[stage]`` (no-op without timings)."""

    def __init__(self, timings):
        self.timings, self.t = timings, time.perf_counter()

    def __call__(self, stage):
        if self.timings is not None:
            now = time.perf_counter()
            self.timings[stage] = self.timings.get(stage, 0.0) + now - self.t
            self.t = now


def _fit_clips(clips, num_harmonics, representation, dtype, fit_kwargs, timings) -> list[ClipFit]:
    """The batched fit of prepared clips: grouped by channel layout, sorted by length, cut into
    bucketed chunks (`_fourier._buckets`), then aligned and scored; one ClipFit per clip, in
    order."""
    from fourierjax import fourier as fr
    from fourierjax._fourier._buckets import batch_plan, length_bucket
    from fourierjax._memory import fit_bytes_per_clip, resolve_limit

    limit = resolve_limit("fit_motions: max_memory", fit_kwargs.get("max_memory"))
    groups: dict[tuple, list[_Clip]] = {}
    for c in clips:
        w = None if "channel_weights" in fit_kwargs else _search_weights(c.features, c.names,
                                                                         c.mask.any(axis=1))
        groups.setdefault((c.names, w), []).append(c)
    out: dict[int, ClipFit] = {}
    itemsize = jnp.zeros((), dtype).dtype.itemsize
    for (names, weights), group in groups.items():
        kw = dict(fit_kwargs)
        if weights is not None:
            kw["channel_weights"] = jnp.asarray(weights, dtype)
        group = sorted(group, key=lambda c: len(c.features))
        C = len(names)
        per_clip = fit_bytes_per_clip(length_bucket(len(group[-1].features)), C, num_harmonics,
                                      itemsize)
        for start, size in batch_plan(len(group), per_clip, limit, name=(
                f"fit_motions: a clip of {len(group[-1].features)} frames x {C} channels")):
            chunk = group[start:start + size]
            for r in _fit_chunk(chunk, size, names, num_harmonics, representation, dtype, kw,
                                timings, fr, length_bucket):
                out[r[0]] = r[1]
    return [out[c.index] for c in clips]


def _fit_chunk(chunk, size, names, num_harmonics, representation, dtype, kw, timings, fr,
               length_bucket):
    """One bucketed fit_batch call of ``chunk`` (padded to ``size`` clips with copies of the
    last, and to a length bucket), then alignment and metrics: ``[(index, ClipFit), ...]``."""
    clock = _Clock(timings)
    T = length_bucket(max(len(c.features) for c in chunk))
    C = len(names)
    feats = np.zeros((size, T, C))
    mask = np.zeros((size, T, C), bool)
    for k in range(size):
        c = chunk[min(k, len(chunk) - 1)]
        n = len(c.features)
        feats[k, :n] = c.features
        feats[k, n:] = c.features[-1]
        mask[k, :n] = c.mask
    dts = np.array([chunk[min(k, len(chunk) - 1)].sub.frame_time_s for k in range(size)])
    om_steps = np.array([chunk[min(k, len(chunk) - 1)].omega_steps for k in range(size)])
    res = fr.fit_batch(jnp.asarray(feats, dtype), jnp.asarray(dts, dtype), num_harmonics,
                       mask=jnp.asarray(mask), omega_steps=jnp.asarray(om_steps, dtype),
                       representation=representation, channel_names=names, throw=False, **kw)
    res = jax.tree.map(np.asarray, res)  # one transfer, then host reads per clip
    clock("fit")
    t = np.arange(T) * dts[:, None]
    xhat = np.asarray(fr.synthesize_batch(jax.tree.map(jnp.asarray, res.model),
                                          jnp.asarray(t, dtype)))
    frames = mask.any(axis=2)
    pve = _position_ves(chunk, representation, feats, xhat, frames, dtype)
    rows = []
    for k, c in enumerate(chunk):
        rows.append((c.index, _clip_fit(c, k, res, names, representation, pve[k], dtype, fr)))
    clock("align_metrics")
    return rows


def _position_ves(chunk, representation, feats, xhat, frames, dtype) -> np.ndarray:
    """Position variance explained of each clip of a chunk: one vmapped call when the clips
    share a topology and pelvis (different bone lengths are fine), else one call per clip."""
    pelvis = [0 if c.body_map is None else c.body_map.pelvis for c in chunk]
    n = len(chunk)
    if len({c.sub.topology for c in chunk}) == 1 and len(set(pelvis)) == 1:
        skel = chunk[0].sub.skeleton()
        offsets = np.stack([np.asarray(c.sub.offsets) for c in chunk])
        ends = np.stack([np.asarray(c.sub.end_site_offsets) for c in chunk])
        skel = eqx.tree_at(lambda s: (s.offsets, s.end_site_offsets), skel,
                           (jnp.asarray(offsets, dtype), jnp.asarray(ends, dtype)))
        return np.asarray(_position_ve_batch_jit(
            skel, jnp.asarray(feats[:n], dtype), jnp.asarray(xhat[:n], dtype),
            jnp.asarray(frames[:n]), representation, pelvis[0]))
    return np.array([float(_position_ve(c.sub.skeleton(), representation,
                                        jnp.asarray(feats[k], dtype), jnp.asarray(xhat[k], dtype),
                                        jnp.asarray(frames[k]), pelvis[k]))
                     for k, c in enumerate(chunk)])


def _position_ve_batch_impl(skeleton, x, xhat, mask, representation, pelvis):
    return jax.vmap(lambda s, a, b, m: _position_ve_impl(s, a, b, m, representation, pelvis))(
        skeleton, x, xhat, mask)


_position_ve_batch_jit = _jit.filter_jit(_position_ve_batch_impl)


def _clip_fit(c: _Clip, k, res, names, representation, pve, dtype, fr) -> ClipFit:
    """The ClipFit of clip ``c`` (row ``k`` of the chunk's host-side FitResult ``res``)."""
    raw = jax.tree.map(lambda v: jnp.asarray(v[k]), res.model)
    dt = c.sub.frame_time_s
    if len(c.left):
        # Circular mean of the strikes' phases (fourier.align_to_events, in NumPy so that clips
        # with different strike counts share compiled code).
        th = float(res.omega_fit[k]) * np.asarray(c.left) * dt
        delta = float(np.arctan2(np.sin(th).sum(), np.cos(th).sum()))
        model = fr.shift_phase(raw, delta)
        alignment = "left_heel_strike"
    else:
        hip = None if c.body_map is None else _hip_flexion_channel(raw, names, c.body_map)
        if hip is not None:
            delta = _hip_flexion_phase(raw, c.sub, hip, c.body_map)
            model = fr.shift_phase(raw, delta)
            alignment = "left_hip_flexion"
        else:
            model, delta, alignment = raw, 0.0, "none"
    status = fr.FitStatus(int(res.result[k]))
    message = "" if status == fr.FitStatus.SUCCESSFUL else (
        f"fit_motions: clip {c.index} ({c.motion.source or 'no file'}): {status.message} (fitted "
        f"fundamental {float(res.omega_fit[k]) / (2 * np.pi):.3f} Hz)")
    return ClipFit(
        source=c.motion.source, frame_start=int(c.start), frame_stop=int(c.stop),
        frame_time_s=float(dt), model=model, raw_model=raw, alignment=alignment,
        phase_shift=float(delta), omega_spectral=float(res.omega_spectral[k]),
        omega_steps=float(c.omega_steps), omega_fit=float(res.omega_fit[k]),
        rms=np.asarray(res.rms[k]), rms_deg=float(res.rms_deg[k]),
        variance_explained_angles=float(res.variance_explained_angles[k]),
        variance_explained_positions=float(pve),
        left_heel_strikes=tuple(int(v) for v in c.left),
        right_heel_strikes=tuple(int(v) for v in c.right),
        masked_frames=int(np.sum(~c.mask.all(axis=1))), masked_entries=int(np.sum(~c.mask)),
        result=status.name.lower(), message=message, body_map=c.body_map,
    )


#: Clips per streamed chunk of `fit_motions` (fewer when the memory budget asks for it).
STREAM_CHUNK = 256


def fit_motions(
    motions,
    num_harmonics: int = 3,
    representation: str = "euler",
    *,
    segment: bool = True,
    use_contacts: bool = True,
    dtype=None,
    throw: bool = False,
    body_map=None,
    start_frame: int | None = None,
    stop_frame: int | None = None,
    chunk_size: int | None = None,
    progress: bool | None = False,
    timings: dict | None = None,
    **fit_kwargs,
) -> list[ClipFit]:
    """Fit Fourier models to clips: segment, convert, find ω three ways, fit, align, score.

    Per clip: the steady straight stretch (:func:`steady_segment`, unless ``segment=False``),
    capture glitches masked out per joint (:func:`glitch_joints`: a glitchy joint's channels at
    those frames, :func:`feature_mask`), its features (:func:`features_from_motion`), heel
    strikes from FK foot contacts (``fourierjax.contacts``; ω from steps, Tilmanne §2.2). Then
    batched :func:`fourierjax.fourier.fit_batch` calls for the clips that share a channel layout,
    padded to shape buckets (clip lengths to powers of two, batches to chunks of 16 or 128
    clips: `fourierjax._fourier._buckets`) so that new lengths and batch sizes reuse compiled
    code; phase alignment to the left heel strike (fallback: the peak of the left hip flexion
    fundamental: the body map's left hip channel with the largest fundamental), and the metrics.
    Feet, legs, pelvis and trajectory come from each clip's body map.

    ``motions`` is read as a stream, ``chunk_size`` clips at a time: the next chunk is read and
    prepared in a background thread while the current one is fitted, so a generator that reads
    the files of a large folder (or the paths themselves) never holds more than two chunks.

    Arguments:
        motions: an iterable of Motions (e.g. after dropping a rest frame) or BVH paths (read
            with ``io.bvh.read_bvh``); a generator is consumed lazily.
        num_harmonics: N; representation: "euler" | "expmap".
        throw: raise a UserError (the first failed clip's message, naming its file) after the
            fit instead of returning failed clips.
        body_map: a `fourierjax.body.BodyMap` for every clip, an iterable of one per clip (read
            alongside ``motions``), or None to infer each clip's
            (``fourierjax.body.infer_body_map``).
        start_frame, stop_frame: only frames ``[start_frame, stop_frame)`` of each clip are
            used (the steady segment is looked for inside them); None: the clip's ends.
        chunk_size: clips per streamed chunk (default `STREAM_CHUNK`, fewer when two chunks'
            features would not fit the memory budget, ``max_memory``).
        progress: show a tqdm progress bar on stderr (None: only when stderr is a terminal).
        timings: a dict that receives the seconds spent per stage (``read``, ``body_map``,
            ``segment``, ``glitch``, ``features``, ``contacts``, ``fit``, ``align_metrics``;
            the stages before ``fit`` run in the background thread, overlapping the fit).
        fit_kwargs: passed on to ``fit_batch`` (search band, grid, ``max_memory``...).

    Returns:
        One :class:`ClipFit` per motion, in order. A clip that cannot be fitted (e.g. too short
        for a cycle) does not stop the others: its ``result`` and ``message`` say why.
    """
    from fourierjax.body import BodyMap

    dtype = dtype or jnp.zeros(()).dtype
    if body_map is None or isinstance(body_map, BodyMap):
        maps = itertools.repeat(body_map)
    else:
        if hasattr(body_map, "__len__") and hasattr(motions, "__len__") and (
                len(body_map) != len(motions)):
            raise UserError(f"fit_motions: {len(body_map)} body maps for {len(motions)} motions")
        maps = iter(body_map)
    total = len(motions) if hasattr(motions, "__len__") else None
    items = iter(motions)
    opts = dict(representation=representation, segment=segment, use_contacts=use_contacts,
                start_frame=start_frame, stop_frame=stop_frame, timings=timings)
    count = [0]
    size = [chunk_size]

    def read_chunk() -> list[_Clip]:
        chunk = []
        while size[0] is None or len(chunk) < size[0]:
            try:
                m = next(items)
            except StopIteration:
                break
            try:
                bm = next(maps)
            except StopIteration:
                raise UserError(f"fit_motions: fewer body maps than motions ({count[0]})") from None
            chunk.append(_prepare(count[0], m, bm, **opts))
            count[0] += 1
            if size[0] is None:
                size[0] = _stream_chunk(chunk[0], num_harmonics, fit_kwargs.get("max_memory"))
        return chunk

    from tqdm.auto import tqdm

    results: list[ClipFit] = []
    with (concurrent.futures.ThreadPoolExecutor(1) as pool,
          tqdm(total=total, unit="clip", desc="fit_motions", disable=_no_bar(progress),
               leave=False) as bar):
        ahead = pool.submit(read_chunk)
        while True:
            chunk = ahead.result()
            if not chunk:
                break
            ahead = pool.submit(read_chunk)  # chunk k + 1 is read while chunk k is fitted
            fits = _fit_clips(chunk, num_harmonics, representation, dtype, fit_kwargs, timings)
            results += fits
            bar.update(len(chunk))
    if not results:
        raise UserError("fit_motions: no motions given")
    if not isinstance(maps, itertools.repeat) and next(maps, None) is not None:
        raise UserError(f"fit_motions: more body maps than the {len(results)} motions")
    failed = [r for r in results if not r.successful]
    if throw and failed:
        more = f" (and {len(failed) - 1} other clip(s))" if len(failed) > 1 else ""
        raise UserError(failed[0].message + more)
    return results


def _no_bar(progress) -> bool | None:
    """tqdm's ``disable``: None (its rule: no bar unless stderr is a terminal) or a bool."""
    return None if progress is None else not progress


def _stream_chunk(first: _Clip, num_harmonics: int, max_memory) -> int:
    """Clips per streamed chunk: `STREAM_CHUNK`, fewer when two chunks of clips like ``first``
    (features and masks on the host, in float64, and the fit's working memory) exceed the
    budget; a multiple of the fit's batch buckets where it can be."""
    from fourierjax._fourier._buckets import LARGE_BATCH, SMALL_BATCH, length_bucket
    from fourierjax._memory import fit_bytes_per_clip, resolve_limit

    limit = resolve_limit("fit_motions: max_memory", max_memory)
    T, C = length_bucket(len(first.features)), first.features.shape[1]
    per_clip = 2 * (9 * T * C + first.motion.channels.nbytes) + fit_bytes_per_clip(
        T, C, num_harmonics, 8)
    n = max(1, min(STREAM_CHUNK, int(limit // max(per_clip, 1))))
    for step in (LARGE_BATCH, SMALL_BATCH):
        if n >= step:
            return n - n % step
    return n
