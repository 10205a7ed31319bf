"""Style algebra on Fourier gait models (Unuma 1995; Tilmanne & Dutoit): inter/extrapolation,
transitions, characteristics and superposition, transfer across contents, noise harmonics, style space
and PCA.

Every function takes `fourierjax.fourier.FourierModel`s, `Θ_c(θ) = A0_c + Σ_n A_cn sin(nθ + φ_cn)`
at a common cycle phase θ, and returns new models or channel values; angle offsets of two
models are compared on one branch (see `interpolate`).
"""

import warnings

from fourierjax._math import wrap_angle
from fourierjax._style import (
    Characteristic,
    Ease,
    Method,
    OmegaMode,
    SpeedLimit,
    StylePCA,
    TransferMethod,
    TransferWeight,
    add_noise,
    blend_time_domain,
    characteristic,
    characteristic_function,
    check_compatible,
    content_mean,
    cycle_distance,
    cycle_distance_shift,
    cycle_distances,
    cycle_positions,
    ease,
    fit_style_weights,
    fit_transfer_gains,
    fit_transfer_weight,
    interpolate,
    interpolate_omega,
    joint_speed_limit,
    model_from_style_vector,
    pad_harmonics,
    pca_project,
    pca_reconstruct,
    peak_joint_speed,
    phasor,
    stack,
    style_matrix,
    style_pca,
    style_vector,
    superpose,
    transfer,
    transition,
    transition_schedule,
)
from fourierjax._style.transitions import GroundedTransition, grounded_transition

__all__ = [
    "Characteristic",
    "Ease",
    "GroundedTransition",
    "Method",
    "OmegaMode",
    "SpeedLimit",
    "StylePCA",
    "TransferMethod",
    "TransferWeight",
    "add_noise",
    "blend_time_domain",
    "characteristic",
    "characteristic_function",
    "check_compatible",
    "content_mean",
    "cycle_distance",
    "cycle_distance_shift",
    "cycle_distances",
    "cycle_positions",
    "ease",
    "fit_style_weights",
    "fit_transfer_gains",
    "fit_transfer_weight",
    "grounded_transition",
    "interpolate",
    "interpolate_omega",
    "joint_speed_limit",
    "model_from_style_vector",
    "pad_harmonics",
    "pca_project",
    "pca_reconstruct",
    "peak_joint_speed",
    "phasor",
    "stack",
    "style_matrix",
    "style_pca",
    "style_vector",
    "superpose",
    "transfer",
    "transition",
    "transition_schedule",
    "wrap_angle",
]


def __getattr__(name: str):
    # `OmegaInterp`, the type of the old `omega=` keyword: a deprecated alias of `OmegaMode`.
    if name == "OmegaInterp":
        warnings.warn("fourierjax.style.OmegaInterp is deprecated, use OmegaMode", DeprecationWarning, stacklevel=2)
        return OmegaMode
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
