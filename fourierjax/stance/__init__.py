"""Expressive stance (Neff & Fiume 2004): 48-DOF skeleton, lower-body IK, balance, shape solver."""

from fourierjax.stance.animation import animate, ease_in_out
from fourierjax.stance.fit import TorsoFit, cmu_torso_directions, fit_torso, torso_directions
from fourierjax.stance.ik import Feet, LowerBody, lower_body_ik, make_feet
from fourierjax.stance.penalties import HermitePenalty, hermite_penalty, quadratic_penalty, reach_penalty
from fourierjax.stance.problem import (
    AMPLITUDES,
    SHAPE_PARAMS,
    BalancedBuild,
    StanceProblem,
    balance_margin_m,
    balance_offsets,
    balanced_pose,
    balanced_rotations,
    build_pose,
    make_problem,
)
from fourierjax.stance.shape_sets import (
    ShapeSet,
    anticipation,
    builtin_shape_sets,
    get_shape_set,
    load_shape_set,
    parse_shape_set,
    perturb,
)
from fourierjax.stance.skeleton48 import (
    DOF_NAMES,
    DOFS,
    TOPOLOGY,
    Body,
    StancePose,
    center_of_mass,
    dof_vector,
    make_body,
    pose_fk,
    rest_pose,
)
from fourierjax.stance.solver import (
    StanceResult,
    StanceSolution,
    objective,
    solve_stance,
    solve_stances,
    stack_problems,
)

__all__ = [
    "AMPLITUDES", "DOFS", "DOF_NAMES", "SHAPE_PARAMS", "TOPOLOGY", "Body", "Feet",
    "BalancedBuild", "HermitePenalty", "LowerBody", "ShapeSet", "StancePose", "StanceProblem",
    "StanceResult", "StanceSolution",
    "TorsoFit", "animate", "anticipation", "balance_margin_m", "balance_offsets", "balanced_pose",
    "balanced_rotations", "build_pose",
    "builtin_shape_sets", "center_of_mass", "cmu_torso_directions", "dof_vector",
    "ease_in_out", "fit_torso", "get_shape_set", "hermite_penalty", "load_shape_set",
    "lower_body_ik", "make_body", "make_feet", "make_problem", "objective", "parse_shape_set",
    "perturb", "pose_fk", "pose_to_motion", "quadratic_penalty", "reach_penalty", "rest_pose",
    "solve_stance", "solve_stance_bounded", "solve_stances", "stack_problems", "torso_directions", "write_stance_bvh",
]  # fmt: skip


def __getattr__(name):
    # jaxopt (for the bounded solver only) is imported on first use, not with the package; so
    # are the BVH writers, which live at the edge (`fourierjax.io.stance_bvh`).
    if name == "solve_stance_bounded":
        from fourierjax.stance.bounded import solve_stance_bounded

        return solve_stance_bounded
    if name in ("pose_to_motion", "write_stance_bvh"):
        from fourierjax.io import stance_bvh

        return getattr(stance_bvh, name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
