"""Unuma 1995 §3.1 step constraints: step, speed, the hip-height rule (gait, jump), root motion.

Y up unless `up_axis` says otherwise; lengths in file units; `jump` in √(file units) (eq. 5
adds `jump · √(Lmax − L)`); phases in radians of the gait cycle.
"""

from __future__ import annotations

import warnings
from collections.abc import Sequence
from typing import TYPE_CHECKING

from fourierjax._gait.common import RULES, deprecated_cmu_groins, feet_of, groin_joints, model_body_map
from fourierjax._gait.contactphase import blend_contact_intervals
from fourierjax._gait.crowdlock import lock_crowd
from fourierjax._gait.fit import HipFit, fit_hip_rule
from fourierjax._gait.footlock import (
    contact_intervals,
    contact_weights,
    fit_contact_intervals,
    hold_step,
    hold_weights,
    init_hold_state,
    integrate_root,
    intervals_from_contacts,
    intervals_from_model,
    lock_feet,
    lock_supersampling,
)
from fourierjax._gait.hip import (
    HipRule,
    contact_height,
    hip_rule,
    hip_rule_curves,
    leg_heights,
    lowest_points,
    root_height,
)
from fourierjax._gait.kneespeed import fit_knee_speed, knee_angles, knee_speed_limit
from fourierjax._gait.metrics import (
    SkatingStats,
    contact_flight_fraction,
    contact_skating,
    estimate_sole_clearance,
    flight_fraction,
    foot_skating,
    ground_penetration,
)
from fourierjax._gait.path import GroundPath, circle_path, follow_path, polyline_path
from fourierjax._gait.root import apply_step, integrate_phase, root_trajectory
from fourierjax._gait.synthesis import GaitResult, ground_features, model_ground, model_hip_curves, synthesize_gait

if TYPE_CHECKING:
    from fourierjax.io.bvh import Motion

__all__ = [
    "RULES",
    "GaitResult",
    "GroundPath",
    "HipFit",
    "HipRule",
    "SkatingStats",
    "apply_step",
    "blend_contact_intervals",
    "circle_path",
    "contact_flight_fraction",
    "contact_height",
    "contact_intervals",
    "contact_skating",
    "contact_weights",
    "estimate_sole_clearance",
    "feet_of",
    "fit_contact_intervals",
    "fit_hip_rule",
    "fit_knee_speed",
    "flight_fraction",
    "follow_path",
    "foot_skating",
    "gait_motion",
    "ground_features",
    "groin_joints",
    "ground_penetration",
    "hip_rule",
    "hip_rule_curves",
    "hold_step",
    "hold_weights",
    "init_hold_state",
    "integrate_phase",
    "integrate_root",
    "knee_angles",
    "knee_speed_limit",
    "intervals_from_contacts",
    "intervals_from_model",
    "leg_heights",
    "lock_crowd",
    "lock_feet",
    "lock_supersampling",
    "lowest_points",
    "model_body_map",
    "model_ground",
    "model_hip_curves",
    "polyline_path",
    "root_height",
    "root_trajectory",
    "synthesize_gait",
]


def gait_motion(template: Motion, result: GaitResult, channel_names: Sequence[str], frame_time_s: float) -> Motion:
    """Deprecated: use `fourierjax.io.gait_bvh.gait_motion` (the core does not import `io`).

    Arguments:
        template, result, channel_names, frame_time_s: as `io.gait_bvh.gait_motion`.

    Returns:
        The `Motion` of `io.gait_bvh.gait_motion`.
    """
    warnings.warn(
        "fourierjax.gait.gait_motion moved to fourierjax.io.gait_bvh.gait_motion; the old name "
        "will be removed in the next release",
        DeprecationWarning,
        stacklevel=2,
    )
    from fourierjax.io.gait_bvh import gait_motion as _gait_motion

    return _gait_motion(template, result, channel_names, frame_time_s)


def __getattr__(name: str):
    # `CMU_GROINS` (deprecated): the groins come from the body map, whatever the rig's names.
    if name == "CMU_GROINS":
        return deprecated_cmu_groins(__name__)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
