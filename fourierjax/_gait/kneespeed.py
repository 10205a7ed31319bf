"""The captured knee's largest angular speed: the foot lock's cap on the swing's knee (issue 21)."""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np
from jaxtyping import ArrayLike, Float

if TYPE_CHECKING:
    from fourierjax.body import BodyMap


def knee_angles(positions: Float[ArrayLike, "T J 3"], body_map: BodyMap) -> Float[np.ndarray, "T 2"]:
    """Knee angles (radians, pi = straight) of both legs (left, right) from joint positions
    `[T, J, 3]`: the angle at the knee between its hip and its ankle (NumPy)."""
    p = np.asarray(positions, np.float64)
    out = []
    for leg in (body_map.left, body_map.right):
        a = p[:, leg.hip] - p[:, leg.knee]
        b = p[:, leg.ankle] - p[:, leg.knee]
        n = np.maximum(np.linalg.norm(a, axis=-1) * np.linalg.norm(b, axis=-1), 1e-12)
        out.append(np.arccos(np.clip((a * b).sum(-1) / n, -1.0, 1.0)))
    return np.stack(out, -1)


def knee_speed_limit(
    positions: Float[ArrayLike, "T J 3"], frame_time_s: float, body_map: BodyMap
) -> Float[np.ndarray, 2]:
    """The largest frame-to-frame knee change of a captured clip per leg, as a speed.

    Issue 21 bounds the synthesized knee's largest frame-to-frame change by the capture's; as a
    speed (radians per second) the bound holds at any output frame rate, and the foot lock
    applies it where the foot is free (`synthesize_gait(..., knee_speed_rad_s=)`).

    Arguments:
        positions: `[T >= 2, J, 3]` world joint positions of the clip (`motion.motion_joint_positions`).
        frame_time_s: the clip's seconds per frame.
        body_map: the clip's `BodyMap` (its legs).

    Returns:
        `[2]` (left, right) radians per second (NumPy float64).
    """
    from fourierjax.errors import UserError

    p = np.asarray(positions)
    if p.ndim != 3 or p.shape[0] < 2 or p.shape[-1] != 3:
        raise UserError(f"knee_speed_limit: `positions` must be [T >= 2, J, 3], got shape {p.shape}")
    dt = float(frame_time_s)
    if not (np.isfinite(dt) and dt > 0):
        raise UserError(f"knee_speed_limit: `frame_time_s` must be finite and > 0 (seconds), got {frame_time_s}")
    return np.abs(np.diff(knee_angles(p, body_map), axis=0)).max(0) / dt


def fit_knee_speed(fit, motion) -> Float[np.ndarray, 2] | None:
    """The knee speed limit of a fitted clip's fitted frames (`knee_speed_limit`), to store with
    its model and pass to `synthesize_gait(..., knee_speed_rad_s=)`; None without a body map.

    Arguments:
        fit: a successful `motion.ClipFit`; motion: the `Motion` given to `motion.fit_motions`.
    """
    from fourierjax.motion import motion_joint_positions

    if fit.body_map is None or not fit.successful or fit.frame_stop - fit.frame_start < 2:
        return None
    sub = motion[fit.frame_start:fit.frame_stop]
    return knee_speed_limit(motion_joint_positions(sub), fit.frame_time_s, fit.body_map)
