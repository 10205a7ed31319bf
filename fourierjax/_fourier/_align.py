"""Phase alignment of fitted models to gait events."""

from __future__ import annotations

import operator

import equinox as eqx
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Bool, Float

from fourierjax._fourier._model import FourierModel, _safe_norm_atan2
from fourierjax._fourier._validate import _is_traced
from fourierjax._math import wrap_angle
from fourierjax.errors import UserError


def shift_phase(model: FourierModel, delta: Float[Array, ""]) -> FourierModel:
    """Model advanced by ``delta`` radians of cycle: ``x'(theta) = x(theta + delta)``.

    ``phase_n -> wrap(phase_n + n * delta)``; amplitudes, offset and omega are unchanged.
    """
    n = jnp.arange(1, model.num_harmonics + 1, dtype=model.phase.dtype)
    d = jnp.asarray(delta, model.phase.dtype)
    shift = jnp.expand_dims(d, (-2, -1)) * n.reshape((1,) * (d.ndim + 1) + (-1,))
    new_phase = wrap_angle(model.phase + shift)
    return eqx.tree_at(lambda m: m.phase, model, new_phase)


def align_to_events(
    model: FourierModel, event_times_s: Float[Array, " K"], valid: Bool[Array, " K"] | None = None
) -> tuple[FourierModel, Float[Array, ""]]:
    """Shift the phase so that theta = 0 falls on a gait event (e.g. left heel strikes).

    The event phase is the circular mean of ``omega * t_k`` over the events (times in the
    clip's fitting frame, t = 0 at its first frame). Returns ``(aligned_model, delta)``; a clip
    time t has aligned phase ``omega * t - delta``.
    """
    theta = model.omega * jnp.asarray(event_times_s, model.phase.dtype)
    v = jnp.ones_like(theta) if valid is None else jnp.asarray(valid, theta.dtype)
    s, c = jnp.sum(v * jnp.sin(theta)), jnp.sum(v * jnp.cos(theta))
    _, delta = _safe_norm_atan2(c, s)
    return shift_phase(model, delta), delta


def channel_event_phase(model: FourierModel, channel: int) -> Float[Array, ""]:
    """Phase (radians) where the fundamental of ``channel`` peaks: ``pi/2 - phase[channel, 0]``.

    ``shift_phase(model, channel_event_phase(model, c))`` puts the peak of the channel's
    fundamental at theta = 0. Whether a peak is an anatomical event depends on the skeleton's
    axes: on CMU skeletons the peak of ``LeftUpLeg.Xrotation`` is hip *extension* (flexion
    is negative); ``motion.fit_motions``' fallback alignment checks the knee's position.

    Raises:
        UserError when ``model`` is stacked, or ``channel`` (when concrete) is not an integer in
        ``[-C, C)`` (negative indices count from the end, as in Python).
    """
    fn = "channel_event_phase"
    if model.phase.ndim != 2:
        raise UserError(f"{fn}: `model` must be one model (phase [C, N]), got phase shape "
                        f"{model.phase.shape}")
    C = model.num_channels
    if not _is_traced(channel):
        try:
            if isinstance(channel, bool | np.bool_):
                raise TypeError
            index = operator.index(channel)
        except TypeError:
            raise UserError(f"{fn}: channel must be an integer index, got {channel!r}") from None
        if not -C <= index < C:
            raise UserError(f"{fn}: channel {index} out of range for a model of {C} channel(s) "
                            f"(valid: {-C} .. {C - 1})")
    else:  # a traced index would be clamped silently: refused at run time instead
        channel = eqx.error_if(channel, (channel < -C) | (channel >= C),
                               f"{fn}: channel out of range for a model of {C} channel(s)")
    return wrap_angle(jnp.pi / 2 - model.phase[channel, 0])
