"""A stance problem (shape vector, states, constraints) and the pose it builds (sec. 5)."""

from fourierjax.stance._pose import (
    BALANCE_EVALUATIONS,
    BalancedBuild,
    PoseInfo,
    balance_offsets,
    balanced_pose,
    balanced_rotations,
    balanced_rotations_with_tangents,
    build_pose,
    build_rotations,
)
from fourierjax.stance._problem import (
    AMPLITUDES,
    BEND_MAX_RAD,
    BEND_MIN_RAD,
    HANDS,
    MAGNITUDE_PARAMS,
    NUM_AMPLITUDES,
    SHAPE_PARAMS,
    P,
    StanceProblem,
    arm_lengths,
    as_finite,
    balance_margin_m,
    check_bends,
    desired_balance_point,
    make_problem,
    negate_directions,
)

__all__ = [
    "AMPLITUDES", "BALANCE_EVALUATIONS", "BEND_MAX_RAD", "BEND_MIN_RAD", "HANDS", "MAGNITUDE_PARAMS",
    "NUM_AMPLITUDES", "P", "SHAPE_PARAMS", "BalancedBuild", "PoseInfo", "StanceProblem", "arm_lengths",
    "as_finite", "balance_margin_m", "balance_offsets", "balanced_pose", "balanced_rotations",
    "balanced_rotations_with_tangents", "build_pose", "build_rotations", "check_bends",
    "desired_balance_point", "make_problem", "negate_directions",
]  # fmt: skip
