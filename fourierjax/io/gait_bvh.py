"""A writeable BVH `Motion` of a synthesized gait (NumPy edge of `fourierjax.gait`)."""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence
from typing import TYPE_CHECKING

import numpy as np

from fourierjax.io.bvh import Motion

if TYPE_CHECKING:
    from fourierjax.gait import GaitResult


def gait_motion(
    template: Motion, result: GaitResult, channel_names: Sequence[str], frame_time_s: float
) -> Motion:
    """A writeable `Motion` of a synthesized gait, carrying its root trajectory.

    Joint rotations go through `motion.motion_from_features`; the root position channels are
    then set to `result.root_position` exactly (no re-integration).

    Arguments:
        template: a `Motion` of the model's skeleton.
        result: a `gait.GaitResult` from `synthesize_gait`.
        channel_names: the model's channel names.
        frame_time_s: seconds per frame.

    Returns:
        A `Motion` with `T` frames.
    """
    return grounded_motion(template, result.features, result.root_position, channel_names, frame_time_s)


def grounded_motion(
    template: Motion, features, root_position, channel_names: Sequence[str], frame_time_s: float
) -> Motion:
    """A writeable `Motion` of features `[T, C]` whose root path `[T, 3]` is given exactly
    (`gait.ground_features`, `synthesize_gait`): written to the root's position channels."""
    from fourierjax.motion import motion_from_features

    mot = motion_from_features(template, np.asarray(features), channel_names, frame_time_s)
    ch = np.array(mot.channels)
    root = np.asarray(root_position, dtype=np.float64)
    base = mot.topology.channel_offsets[0]
    for k, name in enumerate(mot.topology.channels[0]):
        if name.endswith("position"):
            ch[:, base + k] = root[:, "XYZ".index(name[0])]
    return dataclasses.replace(mot, channels=ch)
