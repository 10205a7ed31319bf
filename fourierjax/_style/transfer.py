"""Style transfer across contents: Unuma eq. 8, and the style taken relative to each content's mean."""

from __future__ import annotations

from collections.abc import Sequence
from typing import Literal

import equinox as eqx
import jax.numpy as jnp
from jaxtyping import ArrayLike, Float

from fourierjax._jit import filter_jit
from fourierjax._style._common import (
    check_compatible,
    check_models_omega,
    on_branch_of,
    polar_from_phasor,
    replace,
)
from fourierjax._style.characteristics import characteristic, common_harmonics, stack, superpose
from fourierjax._style.space import style_vector_core
from fourierjax.errors import UserError
from fourierjax.fourier import FourierModel

TransferMethod = Literal["eq8", "content_mean"]
TRANSFER_METHODS = ("eq8", "content_mean")


@filter_jit
def _content_mean(first, stacked):
    vectors = eqx.filter_vmap(lambda m: style_vector_core(on_branch_of(first, m)))(stacked)
    mean = jnp.mean(vectors, axis=0)
    c, n = first.amplitude.shape
    per_channel = jnp.reshape(mean[:-1], (c, 1 + 2 * n))
    re_im = jnp.reshape(per_channel[:, 1:], (c, n, 2)) * jnp.sqrt(2.0)
    amplitude, phase = polar_from_phasor(re_im)
    return replace(first, offset=per_channel[:, 0], amplitude=amplitude, phase=phase, omega=jnp.exp(mean[-1]))


def content_mean(models: Sequence[FourierModel]) -> FourierModel:
    """The mean of gait models in style space: the average motion of one content.

    Harmonics are averaged as phasors (so the mean synthesizes the mean signal at a common
    phase), ω geometrically, and angle offsets after every model is moved onto the first
    model's branch (Euler offsets of two clips can differ by whole turns and expmaps sit on
    antipodal branches; averaging across branches gives a pose that none of them has).

    Arguments:
        models: one or more compatible, phase-aligned FourierModels (a sequence; harmonic
            counts are padded to the largest).

    Returns:
        A FourierModel with the first model's static fields. Raises `UserError` for an empty
        sequence, incompatible models or an ω that is not finite and > 0.
    """
    if isinstance(models, FourierModel) or not isinstance(models, Sequence) or not models:
        raise UserError("content_mean: `models` must be a non-empty sequence of FourierModels")
    for i, m in enumerate(models):
        if not isinstance(m, FourierModel):
            raise UserError(f"content_mean: `models[{i}]` is a {type(m).__name__}, not a FourierModel")
        check_compatible(models[0], m, names=("models[0]", f"models[{i}]"))
    models = list(common_harmonics(*models)) if len(models) > 1 else list(models)
    models = [check_models_omega("content_mean", model=m) for m in models]
    return _content_mean(models[0], stack(models))


def transfer(
    source: FourierModel,
    source_reference: FourierModel | Sequence[FourierModel],
    target_reference: FourierModel | Sequence[FourierModel],
    *,
    method: TransferMethod = "eq8",
    weight: Float[ArrayLike, ""] = 1.0,
) -> FourierModel:
    """A style carried from one content to another (a walk's style put on a run).

    - `method="eq8"` (default, Unuma 1995 eq. 8): the characteristic of the styled source
      against its neutral version, added to the neutral target in polar form:
      `superpose(target_reference, [characteristic(source, source_reference)], [weight])`.
      The references are single models (e.g. the "normal" walk and run).
    - `method="content_mean"`: the style relative to each content's MEAN instead of its
      neutral clip: `m_t + weight (source − m_s)` in phasor coordinates, with
      `m_s = content_mean(source_reference)` and `m_t = content_mean(target_reference)`
      (the references are sequences of clips of the two contents in other styles; a single
      model is used as it is). One neutral take carries its own take-to-take variation into
      both ends of eq. 8; a mean over several styles does not. On Bandai-1 walk -> run (14
      styles, the target style left out of both means) the transferred run is, in median,
      at 0.69 (`weight=0.5`) or 0.75 (the weight chosen by cross-validation over the other
      styles) of the neutral run's distance to the real styled run, against 0.98 for eq. 8
      (`docs/findings.md`).

    Arguments:
        source: the styled source-content model (e.g. a happy walk), phase-aligned with the
            references (same gait event at phase 0).
        source_reference: the source content's neutral model (eq8), or a sequence of its
            models in other styles (content_mean).
        target_reference: the same for the target content.
        method: `"eq8"` or `"content_mean"`.
        weight: how much of the style (scalar; 1 = all of it).

    Returns:
        A FourierModel with the static fields of the target reference. Raises `UserError`
        for an unknown method, incompatible models or a non-finite weight.
    """
    if method not in TRANSFER_METHODS:
        raise UserError(f"transfer: `method` must be one of {TRANSFER_METHODS}, got {method!r}")

    def reference(x, name):
        if isinstance(x, FourierModel):
            if x.amplitude.ndim != 2:
                raise UserError(f"transfer: `{name}` is a stacked model; pass a sequence of models")
            return x
        if method == "eq8":
            raise UserError(f"transfer: method 'eq8' takes one model as `{name}` (the neutral clip), "
                            f"got {type(x).__name__}")
        return content_mean(x)

    ms, mt = reference(source_reference, "source_reference"), reference(target_reference, "target_reference")
    if method == "eq8":
        return superpose(mt, [characteristic(source, ms)], jnp.asarray(weight)[None])
    return superpose(mt, [characteristic(source, ms)], jnp.asarray(weight)[None], method="phasor")


