"""Style transfer across contents: Unuma eq. 8, the style relative to each content's mean, its weight and gains."""

from __future__ import annotations

from collections.abc import Sequence
from typing import TYPE_CHECKING, Literal, NamedTuple

import equinox as eqx
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, ArrayLike, Float

from fourierjax._checks import concrete
from fourierjax._jit import filter_jit
from fourierjax._style._common import (
    check_compatible,
    check_models_omega,
    on_branch_of,
    replace,
)
from fourierjax._style.characteristics import (
    characteristic,
    check_saturation,
    common_harmonics,
    refuse_tangent,
    saturate_weight,
    stack,
    superpose,
)
from fourierjax._style.distance import _pelvis, cycle_distance
from fourierjax._style.space import _model_from_style_vector, style_vector_core
from fourierjax.errors import UserError
from fourierjax.fourier import FourierModel

if TYPE_CHECKING:
    from fourierjax.body import BodyMap
    from fourierjax.skeleton import Skeleton

TransferMethod = Literal["eq8", "content_mean"]
TRANSFER_METHODS = ("eq8", "content_mean")
#: The weights `fit_transfer_weight` tries by default (the experiment's grid).
WEIGHT_GRID = (0.25, 0.5, 0.75, 1.0)


class TransferWeight(NamedTuple):
    """The cross-validated weight of a content-mean transfer and the score of every weight tried."""

    weight: float
    grid: tuple[float, ...]
    scores: tuple[float, ...]


@filter_jit
def _content_mean(first, stacked):
    # Tangent models: the frames as rotation vectors about the first model's (`style_vector`),
    # averaged, so the mean frames are `M_1 exp(mean_i log(M_1⁻¹ M_i))` (None otherwise).
    vectors = eqx.filter_vmap(lambda m: style_vector_core(on_branch_of(first, m), first.frames))(stacked)
    return _model_from_style_vector(jnp.mean(vectors, axis=0), first)


def content_mean(models: Sequence[FourierModel]) -> FourierModel:
    """The mean of gait models in style space: the average motion of one content.

    Harmonics are averaged as phasors (so the mean synthesizes the mean signal at a common
    phase), ω geometrically, and angle offsets after every model is moved onto the first
    model's branch (Euler offsets of two clips can differ by whole turns and expmaps sit on
    antipodal branches; averaging across branches gives a pose that none of them has).
    Tangent models average their tangent coordinates' phasors and their clip means as rotation
    vectors about the first model's (`M_1 exp(mean_i log(M_1⁻¹ M_i))`, one step of the Karcher
    mean), which commutes with a change of rig.

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
    weight: Float[ArrayLike, ""] | Literal["cv"] = 1.0,
    gains: Float[ArrayLike, " C+1"] | None = None,
    skeleton: Skeleton | None = None,
    body_map: BodyMap | None = None,
    weight_grid: Sequence[float] = WEIGHT_GRID,
    saturation: Float[ArrayLike, ""] | None = None,
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
      (`docs/findings.md`). With `gains=fit_transfer_gains(...)` and the cross-validated
      weight: 0.73, and no joint moves faster than in the clips at any weight up to 1.5.
      What these transfers do not do is make the style recognisable: a classifier of the real
      runs (one per style) names the intended style for at most 43 % of them (w = 1), where it
      names a second real capture's style 83 % of the time (`docs/findings.md`, section 2b).

    Arguments:
        source: the styled source-content model (e.g. a happy walk), phase-aligned with the
            references (same gait event at phase 0).
        source_reference: the source content's neutral model (eq8), or a sequence of its
            models in other styles (content_mean).
        target_reference: the same for the target content.
        method: `"eq8"` or `"content_mean"`.
        weight: how much of the style (scalar; 1 = all of it), or `"cv"` (content_mean only):
            the weight `fit_transfer_weight(source_reference, target_reference, skeleton)`
            chooses, the references then being PAIRED sequences (`source_reference[i]` and
            `target_reference[i]` one style in the two contents, at least 3 styles).
        gains: content_mean only: per-channel gains `[C + 1]` (the last is log ω's) on the
            style offset, `m_t + weight · g ⊙ (source − m_s)` (`fit_transfer_gains` fits them
            across the reference styles); `None`: all 1.
        skeleton, body_map, weight_grid: for `weight="cv"` only (see `fit_transfer_weight`).
        saturation: `None` (default) or a float > 0: a weight outside [0, 1] moves the offsets
            as given and the harmonics and log ω by the saturated weight of
            `superpose(saturation=)` (exaggerate the posture, not the swings or the cadence).
            Weights in [0, 1] are unchanged. To exaggerate a finished transfer `t` (say one
            with `weight="cv"`), superpose its characteristic against the neutral target:
            `superpose(neutral, [characteristic(t, neutral)], [1.5], method="phasor",
            saturation=0.05)`; on Bandai-1 that keeps every weight in [0, 1.5] within 1 % of
            the clips' largest joint jump per radian of phase (worst 1.008x), where the plain
            extrapolation reached 1.21x (`docs/findings.md`, section 3b).

    Tangent models: eq8 and content_mean work through `characteristic`, `superpose` and
    `content_mean` (the clip means' differences composed on the target's, rig-invariant).
    Their `gains` may hold a log-ω gain only (`fit_transfer_gains(..., cadence_only=True)`):
    the transfer's ω is then `ω_t (ω_s / ω_ms)^(g w)`. A channel gain other than 1 is refused
    (a gain per tangent channel does not commute with a change of joint frame). On Bandai-1,
    tangent transfers come within 0.03 of Euler's distance ratios (`docs/findings.md`, section 4).

    Returns:
        A FourierModel with the static fields of the target reference. Raises `UserError`
        for an unknown method, incompatible models or a non-finite weight.
    """
    if method not in TRANSFER_METHODS:
        raise UserError(f"transfer: `method` must be one of {TRANSFER_METHODS}, got {method!r}")
    if isinstance(weight, str):
        if weight != "cv" or method != "content_mean":
            raise UserError(f"transfer: a string `weight` must be 'cv', with method='content_mean' "
                            f"(got weight={weight!r}, method={method!r})")
        if skeleton is None:
            raise UserError("transfer: weight='cv' scores candidate weights by `cycle_distance`: pass `skeleton=`")
        weight = fit_transfer_weight(source_reference, target_reference, skeleton, grid=weight_grid,
                                     body_map=body_map).weight

    def reference(x, name):
        if isinstance(x, FourierModel):
            if x.amplitude.ndim != 2:
                raise UserError(f"transfer: `{name}` is a stacked model; pass a sequence of models")
            return x
        if method == "eq8":
            raise UserError(f"transfer: method 'eq8' takes one model as `{name}` (the neutral clip), "
                            f"got {type(x).__name__}")
        return content_mean(x)

    if gains is not None and method != "content_mean":
        raise UserError("transfer: `gains` are a content_mean option")
    ms, mt = reference(source_reference, "source_reference"), reference(target_reference, "target_reference")
    if method == "eq8":
        return superpose(mt, [characteristic(source, ms)], jnp.asarray(weight)[None], saturation=saturation)
    if gains is None:
        return superpose(mt, [characteristic(source, ms)], jnp.asarray(weight)[None], method="phasor",
                         saturation=saturation)
    weight = jnp.asarray(weight, dtype=mt.amplitude.dtype)
    saturation, weight = check_saturation("transfer", saturation, weight)
    if getattr(source, "representation", "") == "tangent":
        return _cadence_transfer(source, ms, mt, gains, weight, saturation)
    check_compatible(mt, source, names=("target_reference", "source"))
    check_compatible(mt, ms, names=("target_reference", "source_reference"))
    source, ms, mt = common_harmonics(source, ms, mt)
    gains = jnp.asarray(gains, dtype=mt.amplitude.dtype)
    if gains.shape != (mt.offset.shape[0] + 1,):
        raise UserError(f"transfer: `gains` must have shape ({mt.offset.shape[0] + 1},) (channels, then log omega), "
                        f"got {gains.shape}")
    return _gain_transfer(source, ms, mt, gains, weight, saturation)


_TANGENT_GAINS = ("transfer(gains=): tangent models take the log-omega gain only (every channel's gain 1: "
                  "a gain per tangent channel does not commute with a change of joint frame); fit it with "
                  "fit_transfer_gains(..., cadence_only=True), or fit with --representation euler "
                  "(representation='euler')")


def _cadence_transfer(source, ms, mt, gains, weight, saturation=None):
    """The content-mean transfer of tangent models with a log-ω gain: the plain transfer (phasor
    form, clip means composed by `superpose`), its ω `ω_t (ω_s / ω_ms)^(g w)`. Channel gains
    other than 1 are refused (concrete: `UserError`; traced: `eqx.error_if`)."""
    gains = jnp.asarray(gains, dtype=mt.amplitude.dtype)
    if gains.shape != (mt.offset.shape[0] + 1,):
        raise UserError(f"transfer: `gains` must have shape ({mt.offset.shape[0] + 1},) (channels, then log omega), "
                        f"got {gains.shape}")
    g = concrete(gains)
    if g is not None and not np.all(g[:-1] == 1.0):
        raise UserError(_TANGENT_GAINS)
    gains = eqx.error_if(gains, jnp.any(gains[:-1] != 1.0), _TANGENT_GAINS)
    weight = jnp.asarray(weight, dtype=mt.amplitude.dtype)
    char = characteristic(source, ms)
    out = superpose(mt, [char], weight[None], method="phasor", include_omega=False, saturation=saturation)
    wh = weight if saturation is None else saturate_weight(weight, saturation)
    return replace(out, omega=mt.omega * jnp.exp(gains[-1] * wh * char.log_omega))


@filter_jit
def _gain_transfer(source, ms, mt, gains, weight, saturation=None):
    n = mt.amplitude.shape[1]
    # the style offset on the source mean's branch (Euler turns, expmap antipodes)
    d = style_vector_core(on_branch_of(ms, source)) - style_vector_core(ms)
    g = jnp.concatenate([jnp.repeat(gains[:-1], 1 + 2 * n), gains[-1:]])
    w = weight
    if saturation is not None:  # offsets by the weight, harmonics and log omega saturated
        wh = saturate_weight(weight, saturation)
        is_offset = jnp.concatenate([jnp.tile(jnp.arange(1 + 2 * n) == 0, g.shape[0] // (1 + 2 * n)),
                                     jnp.zeros(1, bool)])
        w = jnp.where(is_offset, weight, wh)
    return _model_from_style_vector(style_vector_core(mt) + w * g * d, mt)


def fit_transfer_gains(
    sources: Sequence[FourierModel], targets: Sequence[FourierModel], *, ridge: Float[ArrayLike, ""] = 0.25,
    max_gain: float = 2.0, cadence_only: bool = False,
) -> Float[Array, " C+1"]:
    """Per-channel gains of a content-mean transfer, fitted across styles.

    How much of a style's offset from its content's mean in the source content (a walk)
    reappears in the target content (a run), per channel and for log ω: for the style
    vectors' deviations from their content means, `dx` (sources) and `dy` (targets), the
    least-squares slope over the styles and a channel's coordinates (offset and phasors),
    shrunk toward 1 (plain transfer) by `ridge`: `g = (S_xy + ridge S_xx) / ((1 + ridge) S_xx)`,
    clipped to `[0, max_gain]`. A channel that does not vary with style (`S_xx = 0`) gets 1.
    On Bandai-1, runs vary their cadence with style about half as much as walks do (log-ω
    gain 0.5–0.6), and a gain of 1 carried the walk's cadence ratio onto the run in full:
    that, not an angle branch, made the limbs of the w = 1.5 transfers move faster than any
    real clip's (`docs/findings.md`; the default `ridge` is the better of 0.25 and 1 there).

    Arguments:
        sources, targets: paired sequences (one style each, at least 2) of compatible,
            phase-aligned models of the two contents. Leave the style to transfer out.
        ridge: shrinkage toward a gain of 1 (>= 0; 0: the plain least-squares slope).
        max_gain: the largest gain.
        cadence_only: fit the log-ω gain only and leave every channel's at 1: the cause of
            the fast limbs above w = 1 without the channel gains' cost in distance (on
            Bandai-1 run -> walk, the channel gains moved the median ratio from 0.74 to 0.82).
            The only form tangent models take (log ω is rig-invariant; a channel gain is not).

    Returns:
        `[C + 1]` gains: channels in order, then log ω; pass them as `transfer(..., gains=)`.
    """
    sources, targets = list(sources), list(targets)
    if not cadence_only:
        for m in sources[:1] + targets[:1]:
            refuse_tangent("fit_transfer_gains", m)
    if len(sources) != len(targets) or len(sources) < 2:
        raise UserError(f"fit_transfer_gains: `sources` and `targets` must be paired sequences of at least 2 "
                        f"models, got {len(sources)} and {len(targets)}")
    for name, ms in (("sources", sources), ("targets", targets)):
        for i, m in enumerate(ms):
            if not isinstance(m, FourierModel):
                raise UserError(f"fit_transfer_gains: `{name}[{i}]` is a {type(m).__name__}, not a FourierModel")
            check_compatible(targets[0], m, names=("targets[0]", f"{name}[{i}]"))
    ridge = eqx.error_if(jnp.asarray(ridge, dtype=targets[0].amplitude.dtype), jnp.asarray(ridge) < 0,
                         "fit_transfer_gains: `ridge` must be >= 0")
    models = list(common_harmonics(*sources, *targets))
    k = len(sources)
    if cadence_only and getattr(targets[0], "representation", "") == "tangent":
        log_w = jnp.log(jnp.stack([m.omega for m in models]))  # the only rig-invariant gain
        dx, dy = (v - jnp.mean(v) for v in (log_w[:k], log_w[k:]))
        g = _shrunk_slope(jnp.sum(dx * dy), jnp.sum(dx * dx), ridge, float(max_gain))
        return jnp.ones(targets[0].offset.shape[0] + 1, dtype=g.dtype).at[-1].set(g)
    gains = _fit_gains(stack(models[:k]), stack(models[k:]), models[0], models[k], ridge, float(max_gain))
    if cadence_only:
        return jnp.ones_like(gains).at[-1].set(gains[-1])
    return gains


@filter_jit
def _fit_gains(sources, targets, first_s, first_t, ridge, max_gain):
    c, n = first_t.amplitude.shape

    def deviations(stacked, first):
        v = eqx.filter_vmap(lambda m: style_vector_core(on_branch_of(first, m)))(stacked)
        return v - jnp.mean(v, axis=0, keepdims=True)

    dx, dy = deviations(sources, first_s), deviations(targets, first_t)  # [K, D]

    def per_channel(z):  # sums over styles and each channel's coordinates: [C + 1]
        z = jnp.sum(z, axis=0)
        return jnp.concatenate([jnp.sum(jnp.reshape(z[:-1], (c, 1 + 2 * n)), axis=1), z[-1:]])

    return _shrunk_slope(per_channel(dx * dy), per_channel(dx * dx), ridge, max_gain)


def _shrunk_slope(sxy, sxx, ridge, max_gain):
    """`(S_xy + ridge S_xx) / ((1 + ridge) S_xx)` clipped to `[0, max_gain]`; 1 where `S_xx` is 0."""
    flat = sxx <= 1e-12 * jnp.maximum(jnp.max(sxx), 1e-30)
    sxx_safe = jnp.where(flat, 1.0, sxx)  # shim: no division by zero in the branch not taken
    g = (sxy + ridge * sxx_safe) / ((1 + ridge) * sxx_safe)
    return jnp.clip(jnp.where(flat, 1.0, g), 0.0, max_gain)




def fit_transfer_weight(
    sources: Sequence[FourierModel],
    targets: Sequence[FourierModel],
    skeleton: Skeleton,
    *,
    grid: Sequence[float] = WEIGHT_GRID,
    baseline: FourierModel | None = None,
    held_out: Sequence[int] | None = None,
    body_map: BodyMap | None = None,
    num_samples: int = 32,
) -> TransferWeight:
    """The weight of `transfer(method="content_mean")`, chosen by leaving one style out.

    `sources[i]` and `targets[i]` are one style in the source and the target content (say
    happy walk and happy run). For each held-out style `i` and each weight `w` of `grid`,
    `sources[i]` is transferred with the content means of the OTHER styles, and scored by its
    `cycle_distance` to the real `targets[i]` divided by the baseline's (`baseline`, e.g. the
    neutral target clip; `None`: the mean of the other targets, the `w = 0` transfer). The
    weight of the smallest median ratio wins (the first on ties). To keep a style out of
    everything fitted, leave it out of `sources` and `targets`.

    Arguments:
        sources, targets: paired sequences of compatible, phase-aligned FourierModels (at least 3).
        skeleton: the Skeleton the target models synthesize on (for `cycle_distance`).
        grid: the candidate weights (finite floats).
        baseline: the model the ratios divide by (`None`: the leave-one-out target mean).
        held_out: the indices scored (default all; e.g. leave out the neutral style when
            it is the baseline).
        body_map: the target rig's body map (`cycle_distance`; `None`: inferred once).
        num_samples: phases per cycle of `cycle_distance` (static).

    Returns:
        `TransferWeight(weight, grid, scores)`: the chosen weight (a Python float), the grid and
        the median ratio of each weight.
    """
    sources, targets = list(sources), list(targets)
    if len(sources) != len(targets) or len(sources) < 3:
        raise UserError(f"fit_transfer_weight: `sources` and `targets` must be paired sequences of at least 3 "
                        f"models, got {len(sources)} and {len(targets)}")
    grid = tuple(float(w) for w in grid)
    if not grid or not all(np.isfinite(grid)):
        raise UserError(f"fit_transfer_weight: `grid` must hold finite weights, got {grid!r}")
    held = list(range(len(sources))) if held_out is None else [int(i) for i in held_out]
    if not held or any(not 0 <= i < len(sources) for i in held):
        raise UserError(f"fit_transfer_weight: `held_out` must index the {len(sources)} pairs, got {held_out!r}")
    body_map = body_map if body_map is not None else _pelvis_map(skeleton, targets[0])
    _pelvis("fit_transfer_weight", body_map, skeleton, targets[0])  # checks the map against the skeleton
    cands, reals, bases = [], [], []
    for i in held:
        keep = [k for k in range(len(sources)) if k != i]
        ms, mt = content_mean([sources[k] for k in keep]), content_mean([targets[k] for k in keep])
        for w in grid:
            cands.append(transfer(sources[i], ms, mt, method="content_mean", weight=jnp.asarray(w)))
            reals.append(targets[i])
        bases.append(mt if baseline is None else baseline)
    # one pair at a time: the program `cycle_distance` compiles for these shapes anyway
    kw = {"num_samples": num_samples, "body_map": body_map}
    d = np.array([float(cycle_distance(a, b, skeleton, **kw)) for a, b in zip(cands, reals, strict=True)])
    d0 = np.array([float(cycle_distance(a, targets[i], skeleton, **kw)) for a, i in zip(bases, held, strict=True)])
    ratios = d.reshape(len(held), len(grid)) / np.maximum(d0, 1e-12)[:, None]
    scores = tuple(float(v) for v in np.median(ratios, axis=0))
    return TransferWeight(grid[int(np.argmin(scores))], grid, scores)


def _pelvis_map(skeleton, model):
    from fourierjax.gait import model_body_map

    return model_body_map(model, skeleton)
