"""Fitting Fourier models to motion clips: steady segments, glitch frames, contacts, `fit_motions`.

The feature layout itself (channel names, Motion <-> features) lives in `fourierjax.features`;
its names are re-exported here for old imports.
"""

from __future__ import annotations

import dataclasses

import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import ArrayLike, Bool, Float, Int

from fourierjax import _jit, _passes
from fourierjax._fourier._layout import bucket as _bucket
from fourierjax._fourier._layout import root_joints as _root_joints
from fourierjax._fourier._layout import rot as _rot
from fourierjax._fourier._layout import rotation_joints as _rotation_joints
from fourierjax._fourier._layout import world_pose as _world_pose
from fourierjax._fourier._model import FourierModel
from fourierjax._passes import heading_over_time, straight_passes  # noqa: F401  (public here: issue 21)
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


def glitch_frames(
    motion, max_joint_speed_deg_s: float = 5000.0, pad_s: float = 0.1
) -> Bool[np.ndarray, " F"]:
    """Capture glitches: ``bool [F]``, True within ``pad_s`` of a frame where some joint turns
    faster than ``max_joint_speed_deg_s`` (CMU 142_02's left arm jumps 60 degrees in one frame
    at frame 1140; captured motion stays under ~3200 deg/s, even at toes and fingers).

    ``fit_motions`` masks these frames out of the fit (time stays continuous around them).
    """
    F = motion.num_frames
    glitch = np.zeros(F, bool)
    joints = _rotation_joints(motion.topology)
    for order in dict.fromkeys(o for _, o, _ in joints):
        idx = np.array([i for _, o, i in joints if o == order])
        q = _rot("quat_from_euler", np.radians(motion.channels[:, idx]), order=order)
        dot = np.clip(np.abs(np.sum(q[1:] * q[:-1], axis=-1)), 0.0, 1.0)  # [F-1, J_g]
        fast = np.degrees(2 * np.arccos(dot)) / motion.frame_time_s > max_joint_speed_deg_s
        glitch[1:] |= fast.any(axis=1)
    out = glitch.copy()
    pad = max(1, int(round(pad_s / motion.frame_time_s)))
    for i in np.nonzero(glitch)[0]:
        out[max(0, i - pad) : i + pad + 1] = True
    return out


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
    ``masked_frames`` counts capture-glitch frames left out of the fit (:func:`glitch_frames`).
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
    passes: str = "longest",
    **fit_kwargs,
) -> list[ClipFit]:
    """Fit Fourier models to clips: segment, convert, find ω three ways, fit, align, score.

    Per clip: the steady straight stretch (:func:`steady_segment`, unless ``segment=False``)
    with capture glitches masked out (:func:`glitch_frames`),
    its features (:func:`features_from_motion`), heel strikes from FK foot contacts
    (``fourierjax.contacts``; ω from steps, Tilmanne §2.2), then ONE batched
    :func:`fourierjax.fourier.fit_batch` call for all clips that share a channel layout (padding
    and masks), phase alignment to the left heel strike (fallback: the peak of the left hip
    flexion fundamental: the body map's left hip channel with the largest fundamental), and the
    metrics. Feet, legs, pelvis and trajectory come from each clip's body map.

    Arguments:
        motions: a sequence of Motions (e.g. after dropping a rest frame).
        num_harmonics: N; representation: "euler" | "expmap".
        throw: raise a UserError (the first failed clip's message, naming its file) after the
            fit instead of returning failed clips.
        body_map: a `fourierjax.body.BodyMap` for every clip, a sequence of one per clip, or
            None to infer each clip's (``fourierjax.body.infer_body_map``).
        start_frame, stop_frame: only frames ``[start_frame, stop_frame)`` of each clip are
            used (the steady segment is looked for inside them); None: the clip's ends.
        passes: ``"longest"`` fits the steady segment; ``"auto"`` fits a clip that walks back
            and forth over every straight pass, each in its own heading frame with the passes'
            heel strikes phase-aligned (``fourierjax._passes.prepare_passes``; its frames are
            then rows of that layout, the turns masked).
        fit_kwargs: passed on to ``fit_batch`` (search band, grid...).

    Returns:
        One :class:`ClipFit` per motion, in order. A clip that cannot be fitted (e.g. too short
        for a cycle) does not stop the others: its ``result`` and ``message`` say why.
    """
    from fourierjax import fourier as fr

    motions = list(motions)
    if not motions:
        raise UserError("fit_motions: no motions given")
    from fourierjax.body import BodyMap, BodyMapError, infer_body_map

    dtype = dtype or jnp.zeros(()).dtype
    if body_map is None or isinstance(body_map, BodyMap):
        maps = [body_map] * len(motions)
    else:
        maps = list(body_map)
        if len(maps) != len(motions):
            raise UserError(f"fit_motions: {len(maps)} body maps for {len(motions)} motions")
    _passes.check_mode(passes)
    prepared = []
    for m, bm in zip(motions, maps):
        lo, hi = _frame_range(m, start_frame, stop_frame)
        clip = m[lo:hi]
        if bm is None:
            try:
                bm = infer_body_map(clip)
            except BodyMapError:
                bm = None  # no legs: joint 0 carries the root, no contacts, no alignment
        # --- hook (issue 21 item 4, fourierjax._passes): every straight pass of a walk that turns
        got = _passes.prepare_passes(clip, lo, representation, bm, use_contacts) if segment and passes == "auto" \
            else None
        if got is not None:
            prepared.append((m, *got[1:], bm))
            continue
        # --- end of hook
        a, b = steady_segment(clip, body_map=bm) if segment else (0, clip.num_frames)
        a, b = a + lo, b + lo
        sub = m[a:b]
        keep = ~glitch_frames(sub)
        x, names = features_from_motion(sub, representation, valid=keep, body_map=bm)
        c = foot_contacts_of(sub, body_map=bm) if use_contacts and bm is not None else None
        left, right, om = _steps(c, sub.frame_time_s)
        prepared.append((m, a, b, sub, x, names, left, right, om, keep, bm))
    groups: dict[tuple[str, ...], list[int]] = {}
    for i, p in enumerate(prepared):
        w = None if "channel_weights" in fit_kwargs else _search_weights(p[4], p[5], p[9])
        groups.setdefault((p[5], w), []).append(i)
    results: list[ClipFit | None] = [None] * len(prepared)
    for (names, weights), idx in groups.items():
        kw = dict(fit_kwargs)
        if weights is not None:
            kw["channel_weights"] = jnp.asarray(weights, dtype)
        T = _bucket(max(prepared[i][4].shape[0] for i in idx))
        C = len(names)
        feats = np.zeros((len(idx), T, C))
        mask = np.zeros((len(idx), T), bool)
        for k, i in enumerate(idx):
            x = prepared[i][4]
            feats[k, : len(x)] = x
            feats[k, len(x):] = x[-1]
            mask[k, : len(x)] = prepared[i][9]
        dts = np.array([prepared[i][3].frame_time_s for i in idx])
        om_steps = np.array([prepared[i][8] for i in idx])
        res = fr.fit_batch(jnp.asarray(feats, dtype), jnp.asarray(dts, dtype), num_harmonics,
                           mask=jnp.asarray(mask), omega_steps=jnp.asarray(om_steps, dtype),
                           representation=representation, channel_names=names, throw=False,
                           **kw)
        for k, i in enumerate(idx):
            m, a, b, sub, x, _, left, right, _, keep, bm = prepared[i]
            raw = jax.tree.map(lambda v: v[k], res.model)
            dt = sub.frame_time_s
            if len(left):
                # Circular mean of the strikes' phases (fourier.align_to_events, in NumPy so
                # that clips with different strike counts share compiled code).
                th = float(raw.omega) * np.asarray(left) * dt
                delta = float(np.arctan2(np.sin(th).sum(), np.cos(th).sum()))
                model = fr.shift_phase(raw, delta)
                alignment = "left_heel_strike"
            else:
                hip = None if bm is None else _hip_flexion_channel(raw, names, bm)
                if hip is not None:
                    delta = _hip_flexion_phase(raw, sub, hip, bm)
                    model = fr.shift_phase(raw, delta)
                    alignment = "left_hip_flexion"
                else:
                    model, delta, alignment = raw, jnp.zeros(()), "none"
            t = jnp.arange(T, dtype=dtype) * dt
            xhat = fr.synthesize(raw, t)
            pve = _position_ve(sub.skeleton(), representation, jnp.asarray(feats[k], dtype),
                               xhat, jnp.asarray(mask[k]), 0 if bm is None else bm.pelvis)
            status = fr.FitStatus(int(res.result[k]))
            message = "" if status == fr.FitStatus.SUCCESSFUL else (
                f"fit_motions: clip {i} ({m.source or 'no file'}): {status.message} (fitted "
                f"fundamental {float(res.omega_fit[k]) / (2 * np.pi):.3f} Hz)")
            results[i] = ClipFit(
                source=m.source, frame_start=int(a), frame_stop=int(b), frame_time_s=float(dt),
                model=model, raw_model=raw, alignment=alignment, phase_shift=float(delta),
                omega_spectral=float(res.omega_spectral[k]), omega_steps=float(om_steps[k]),
                omega_fit=float(res.omega_fit[k]), rms=np.asarray(res.rms[k]),
                rms_deg=float(res.rms_deg[k]),
                variance_explained_angles=float(res.variance_explained_angles[k]),
                variance_explained_positions=float(pve),
                left_heel_strikes=tuple(int(v) for v in left),
                right_heel_strikes=tuple(int(v) for v in right),
                masked_frames=int(np.sum(~keep)), result=status.name.lower(), message=message,
                body_map=bm,
            )
    failed = [r for r in results if r is not None and not r.successful]
    if throw and failed:
        more = f" (and {len(failed) - 1} other clip(s))" if len(failed) > 1 else ""
        raise UserError(failed[0].message + more)
    return results  # type: ignore[return-value]
