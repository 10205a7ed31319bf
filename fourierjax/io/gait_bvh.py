"""A writeable BVH `Motion` of a synthesized gait (NumPy edge of `fourierjax.gait`)."""

from __future__ import annotations

from collections.abc import Sequence
from typing import TYPE_CHECKING

import numpy as np

from fourierjax.io.bvh import Motion

if TYPE_CHECKING:
    from fourierjax.gait import GaitResult


def gait_motion(
    template: Motion, result: GaitResult, channel_names: Sequence[str], frame_time_s: float, *, body_map=None
) -> Motion:
    """A writeable `Motion` of a synthesized gait, carrying its root trajectory.

    Joint rotations go through `motion.motion_from_features`; the root position channels are
    then set to `result.root_position` exactly (no re-integration).

    Arguments:
        template: a `Motion` of the model's skeleton.
        result: a `gait.GaitResult` from `synthesize_gait`.
        channel_names: the model's channel names.
        frame_time_s: seconds per frame.
        body_map: the skeleton's `fourierjax.body.BodyMap` (the synthesis's); None infers it
            from `template`, which a rest pose that is not a T-pose (Bandai) does not allow.

    Returns:
        A `Motion` with `T` frames.
    """
    return grounded_motion(template, result.features, result.root_position, channel_names, frame_time_s,
                           body_map=body_map)


def grounded_motion(
    template: Motion, features, root_position, channel_names: Sequence[str], frame_time_s: float, *,
    body_map=None,
) -> Motion:
    """A writeable `Motion` of features `[T, C]` whose pelvis path `[T, 3]` is given exactly
    (`gait.ground_features`, `synthesize_gait`): written through the trajectory joint's position
    channels (`features.place_root`; CMU: the root's)."""
    from fourierjax.features import motion_from_features, place_root

    mot = motion_from_features(template, np.asarray(features), channel_names, frame_time_s, body_map=body_map)
    return place_root(mot, np.asarray(root_position, dtype=np.float64), body_map=body_map)
