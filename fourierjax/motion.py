"""The clip-fitting pipeline: steady segments, per-joint glitch masks, contacts, `fit_motions`.

The feature layout itself (channel names, Motion <-> features) lives in `fourierjax.features`;
its names are re-exported here for old imports. The work is done in `fourierjax._motion`.
"""

from __future__ import annotations

from fourierjax._motion._clip import ClipFit
from fourierjax._motion._pipeline import STREAM_CHUNK, fit_motions, iter_fit_motions
from fourierjax._motion._poses import (
    foot_contacts_of,
    foot_positions_of,
    model_joint_positions,
    motion_joint_positions,
)
from fourierjax._motion._segment import feature_mask, glitch_frames, glitch_joints, steady_segment
from fourierjax._passes import heading_over_time, straight_passes  # noqa: F401  (public here: issue 21)
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
    "iter_fit_motions",
    "ClipFit",
    "STREAM_CHUNK",
]
