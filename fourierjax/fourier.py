"""Fourier gait models (Unuma 1995 eq. 1; Tilmanne & Dutoit eq. 1-6): model, synthesis, fits, ω.

Per channel ``x_c(theta) = offset[c] + sum_n amplitude[c, n-1] sin(n theta + phase[c, n-1])``
with ``theta = omega * t_s``; the feature layout (channel names) lives in `fourierjax.features`.
"""

from fourierjax._fourier._align import align_to_events, channel_event_phase, shift_phase
from fourierjax._fourier._fit import FitResult, fit, fit_batch
from fourierjax._fourier._linear import fit_linear, harmonic_basis, projected_residual
from fourierjax._fourier._metrics import (
    amplitude_spectrum,
    energy_per_harmonic,
    rms_error,
    variance_explained,
)
from fourierjax._fourier._model import FourierModel, stack_models
from fourierjax._fourier._omega import MIN_CYCLES, spectral_omega
from fourierjax._fourier._status import FitStatus
from fourierjax._fourier._synthesis import synthesize, synthesize_batch, synthesize_phase
from fourierjax._math import wrap_angle
from fourierjax.features import REPRESENTATIONS, ROOT_CHANNELS, angle_channel_mask

__all__ = [
    "REPRESENTATIONS",
    "ROOT_CHANNELS",
    "MIN_CYCLES",
    "FourierModel",
    "FitResult",
    "FitStatus",
    "wrap_angle",
    "synthesize",
    "synthesize_phase",
    "synthesize_batch",
    "harmonic_basis",
    "fit_linear",
    "projected_residual",
    "fit",
    "fit_batch",
    "spectral_omega",
    "shift_phase",
    "align_to_events",
    "channel_event_phase",
    "rms_error",
    "variance_explained",
    "energy_per_harmonic",
    "amplitude_spectrum",
    "angle_channel_mask",
    "stack_models",
]
