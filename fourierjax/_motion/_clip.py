"""`ClipFit`, a fitted clip, and the per-clip steps around the fit: steps, alignment, weights."""

from __future__ import annotations

import dataclasses
import functools

import jax.numpy as jnp
import numpy as np

from fourierjax._motion._poses import model_joint_positions
from fourierjax.errors import UserError


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
    for a skeleton without recognisable legs). ``winding_joints`` names the joints whose Euler
    channels span more than 180 degrees over the fitted frames (near gimbal lock; always empty
    for expmap and tangent fits): their series depend on the rig's joint frames.
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
    winding_joints: tuple[str, ...] = ()

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
            "winding_joints": list(self.winding_joints),
        }


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


def _steps(contacts_lr, frame_time_s, loop: bool = False):
    """(left strikes, right strikes, omega from steps or NaN): Tilmanne §2.2, cycle = 2 steps.

    The step period is the MEDIAN interval (``contacts.step_period_s``), so that a spurious
    extra strike (stumbling, CMU 142_02) does not halve the cycle. ``loop``: the clip is a
    closed loop (`closed_loop`), whose strikes recur across its seam.
    """
    from fourierjax import contacts

    if contacts_lr is None:
        return np.zeros(0, int), np.zeros(0, int), float("nan")
    left, right = contacts.step_events(contacts_lr)
    try:
        step = contacts.step_period_s(contacts_lr, frame_time_s, statistic="median", loop=loop)
    except UserError:  # fewer than two alternating heel strikes
        return left, right, float("nan")
    # Both feet striking together (two-footed hops) can give a zero median: no step frequency.
    return left, right, float(2 * np.pi / (2 * step)) if step > 0 else float("nan")


#: A clip is a closed loop when the step from its last frame to its first is under this fraction
#: of its median frame-to-frame step (RMS over rotation channels). Measured on Bandai-1: the
#: loops 0-0.09 (run_normal_001 0.09), the next clip 0.18 (call_normal_002, a gesture); CMU >= 8.
_LOOP_SEAM = 0.125


def closed_loop(motion) -> bool:
    """Whether a clip is one closed loop: its last frame repeats its first pose (the rotation
    channels' seam step under `_LOOP_SEAM` of a typical frame step; the travel may differ), as
    Bandai's 20-31 frame loops do."""
    t = motion.topology
    rot = [k for k, c in enumerate(t.flat_channel_names) if c.endswith("rotation")]
    a = np.asarray(motion.channels)[:, rot]
    if len(a) < 3 or not rot:
        return False

    def rms(d):
        return np.sqrt(np.mean(((d + 180.0) % 360.0 - 180.0) ** 2, axis=-1))

    typical = float(np.median(rms(np.diff(a, axis=0))))
    return typical > 0 and float(rms(a[-1] - a[0])) < _LOOP_SEAM * typical


#: A joint whose continuous Euler channels span more than this (radians) passes near gimbal
#: lock: its first and third angles wind around the pole (a Bandai `Spine`: 1,680 degrees).
_WINDING_SPAN = np.pi


@dataclasses.dataclass(frozen=True)
class _Channels:
    """What `winding_joints` reads of each channel name of a layout: its joint
    (``joint [C]``, an index into ``joints``), whether it is an Euler rotation channel
    (``*rotation``) and whether it is an angle (not ``root.*``)."""

    joints: tuple[str, ...]
    joint: np.ndarray
    euler: np.ndarray
    angle: np.ndarray


@functools.lru_cache(maxsize=64)
def _channels(names: tuple[str, ...]) -> _Channels:
    joint = [n.rsplit(".", 1)[0] for n in names]
    joints = tuple(dict.fromkeys(joint))
    index = {j: k for k, j in enumerate(joints)}
    return _Channels(joints, np.array([index[j] for j in joint], int),
                     np.array([n.endswith("rotation") for n in names], bool),
                     np.array([not n.startswith("root.") for n in names], bool))


def winding_joints(x, names, keep, *, euler_only: bool = True) -> tuple[str, ...]:
    """Joints whose continuous Euler channels (``*rotation``; with ``euler_only=False`` any
    channel but ``root.*``) span more than `_WINDING_SPAN` over the kept frames: they pass near
    gimbal lock, so their Fourier series depend on the rig's joint frames and fit poorly
    (``representation="tangent"`` has no such joints). In order of first channel. The channel
    names are read once per layout (`_channels`), not once per clip: 500 Bandai-1 clips parsed
    70,000 names, 0.1 CPU-s of the fitting thread; a layout without such channels reads no frame."""
    ch = _channels(tuple(names))
    cols = np.flatnonzero(ch.euler if euler_only else ch.angle)
    keep = np.asarray(keep, bool)
    if not len(cols) or not keep.any():
        return ()
    span = np.ptp(x[keep][:, cols], axis=0)
    return tuple(ch.joints[j] for j in dict.fromkeys(ch.joint[cols[span > _WINDING_SPAN]].tolist()))


def _search_weights(x, names, keep) -> tuple[float, ...] | None:
    """Channel weights of the ω search: ``fourier.fit_batch``'s default (1 for rotations, 0 for
    ``root.*``), and 0 for every channel of a joint whose Euler angles wind near gimbal lock
    (their spectrum is the winding, not the gait). None when no joint winds (the default)."""
    joints = winding_joints(x, names, keep, euler_only=False)
    if not joints:
        return None
    ch = _channels(tuple(names))
    w = np.where(np.isin(ch.joint, [ch.joints.index(j) for j in joints]), 0.0, ch.angle.astype(float))
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
