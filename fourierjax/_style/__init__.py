"""Private implementation of `fourierjax.style`; import the public names from there."""

from fourierjax._style._common import Ease, Method, OmegaMode, check_compatible, phasor
from fourierjax._style._transfer import (
    TransferMethod,
    TransferWeight,
    content_mean,
    fit_transfer_gains,
    fit_transfer_weight,
    transfer,
)
from fourierjax._style.characteristics import (
    Characteristic,
    add_noise,
    characteristic,
    characteristic_function,
    pad_harmonics,
    stack,
    superpose,
)
from fourierjax._style.distance import (
    cycle_distance,
    cycle_distance_shift,
    cycle_distances,
    cycle_positions,
)
from fourierjax._style.interpolation import blend_time_domain, interpolate, interpolate_omega
from fourierjax._style.space import (
    StylePCA,
    fit_style_weights,
    model_from_style_vector,
    pca_project,
    pca_reconstruct,
    style_matrix,
    style_pca,
    style_vector,
)
from fourierjax._style.speed import SpeedLimit, joint_speed_limit, peak_joint_speed
from fourierjax._style.transitions import ease, transition, transition_schedule

__all__ = [
    "Characteristic",
    "Ease",
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
    "interpolate",
    "joint_speed_limit",
    "interpolate_omega",
    "model_from_style_vector",
    "pad_harmonics",
    "peak_joint_speed",
    "pca_project",
    "pca_reconstruct",
    "phasor",
    "stack",
    "style_matrix",
    "style_pca",
    "style_vector",
    "superpose",
    "transfer",
    "transition",
    "transition_schedule",
]
