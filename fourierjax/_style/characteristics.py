"""Fourier characteristics and their superposition (Unuma 1995, eq. 6-8), noise harmonics, stacking."""

from __future__ import annotations

import operator
from collections.abc import Sequence

import equinox as eqx
import jax
import jax.numpy as jnp
from jaxtyping import Array, ArrayLike, Float, PRNGKeyArray

from fourierjax._checks import concrete
from fourierjax._fourier import _tangent
from fourierjax._jit import filter_jit
from fourierjax._math import wrap_angle
from fourierjax._memory import check_bytes, resolve_limit
from fourierjax._style._common import (
    METHODS,
    Method,
    canonical,
    channel_kinds,
    check_choice,
    check_compatible,
    check_finite,
    check_log_omega,
    check_models_omega,
    check_scalar,
    dtype_of,
    evaluate,
    num_harmonics,
    on_branch_of,
    phasor,
    polar_from_phasor,
    replace,
    turns,
)
from fourierjax._style.distance import _pelvis
from fourierjax._style.speed import SpeedLimit, limited_scale
from fourierjax.errors import UserError
from fourierjax.fourier import FourierModel


class Characteristic(eqx.Module):
    """Fourier characteristics `A − B` of two gait models (Unuma 1995, eq. 7).

    Stored in both coordinate systems, because they cannot be derived from one another without
    the two models: the polar differences (Unuma) and the phasor difference. A leading batch
    axis `[K, ...]` on every leaf when stacked with `stack`.

    Attributes:
        offset: `[C]`, `A0_A − A0_B`, angle channels compared on one branch (see
            `characteristic`).
        amplitude: `[C, N]`, `A_A − A_B` (may be negative).
        phase: `[C, N]`, `φ_A − φ_B` wrapped to (−π, π] (the shorter arc).
        phasor: `[C, N, 2]`, `c_A − c_B`, `c = (A cos φ, A sin φ)`.
        log_omega: `log(ω_A / ω_B)` (scalar).
        representation: static, copied from the models.
        channel_names: static, copied from the models.
        frames: `[K, 4]` (wxyz) for tangent models, each joint's clip-mean difference
            `Δ_j = M_B⁻¹ M_A` (so that `M_B Δ_j = M_A`); None for Euler and expmap models.
        aligned: `[C, N, 2]` for tangent models, the per-joint polar difference: on each joint's
            three channels `z_A e^{−iD} − z_B`, D the joint's `phase` (see `characteristic`);
            None for Euler and expmap models.
        reference: `[C]` for exponential-map models, B's offsets: the branch the differences
            were taken on, which `superpose` brings its base onto before adding them; None for
            Euler and tangent models, and for characteristic files written before it was stored.
    """

    offset: Float[Array, "*k channels"]
    amplitude: Float[Array, "*k channels harmonics"]
    phase: Float[Array, "*k channels harmonics"]
    phasor: Float[Array, "*k channels harmonics 2"]
    log_omega: Float[Array, "*k"]
    representation: str = eqx.field(static=True, default="")
    channel_names: tuple[str, ...] = eqx.field(static=True, default=())
    frames: Float[Array, "*k joints 4"] | None = None
    aligned: Float[Array, "*k channels harmonics 2"] | None = None
    reference: Float[Array, "*k channels"] | None = None


def refuse_tangent(where: str, model) -> None:
    """Refuse a tangent model where the operation is defined on Euler and expmap coefficients only
    (per-channel transfer gains: a gain per tangent channel does not commute with a change of
    joint frame)."""
    if getattr(model, "representation", "") == "tangent":
        raise UserError(f"{where}: tangent models (coefficients about each joint's clip mean) are "
                        "not supported here (per-channel gains); fit with --representation euler (or "
                        "representation='euler')")


def pad_harmonics(model, num_harmonics: int):
    """`model` with zero-amplitude harmonics appended up to `num_harmonics` (same signal).

    Arguments:
        model: a FourierModel or Characteristic with `N ≤ num_harmonics` harmonics.
        num_harmonics: the new count (a Python int).

    Returns:
        The same kind of object with `num_harmonics` harmonics.
    """
    n = _count(model)
    if isinstance(num_harmonics, bool):
        raise UserError(f"pad_harmonics: num_harmonics must be an int, got {num_harmonics!r}")
    try:
        num_harmonics = operator.index(num_harmonics)  # ints and NumPy integers, never floats
    except TypeError:
        raise UserError(f"pad_harmonics: num_harmonics must be an int, got {num_harmonics!r}") from None
    if num_harmonics < n:
        raise UserError(f"pad_harmonics: num_harmonics={num_harmonics} is below the model's {n}")
    if num_harmonics == n:
        return model
    extra = num_harmonics - n

    def pad(x, axis_from_end):
        widths = [(0, 0)] * x.ndim
        widths[x.ndim - axis_from_end] = (0, extra)
        return jnp.pad(x, widths)

    fields = {"amplitude": pad(model.amplitude, 1), "phase": pad(model.phase, 1)}
    if isinstance(model, Characteristic):
        fields["phasor"] = pad(model.phasor, 2)
        if model.aligned is not None:
            fields["aligned"] = pad(model.aligned, 2)
    return replace(model, **fields)


_count = num_harmonics


def common_harmonics(*models):
    """The models zero-padded to the largest harmonic count among them."""
    n = max(_count(m) for m in models)
    return tuple(pad_harmonics(m, n) for m in models)


def characteristic(a: FourierModel, b: FourierModel) -> Characteristic:
    """The Fourier characteristics `A − B` (Unuma 1995, eq. 7), e.g. briskness =
    `characteristic(brisk_walk, normal_walk)`.

    Angle offsets are subtracted on one branch: Euler channels as `wrap(A0_A − A0_B)` in
    (−π, π] (a thigh at +179° against −179° differs by −2°, not 358°), exponential-map triples
    `J.expmap0..2` on b's branch: a's rotation vector is replaced by the equivalent one nearest
    b's (its cycle mapped sample by sample and projected back onto its harmonics,
    `on_branch_of`), and b's offsets are kept in `reference`, so that
    `superpose` adds the difference to a base on that same branch (near |r| = π a difference
    taken on one branch and added on the antipodal one flips the sign of its tangential part);
    `root.*` channels subtract plainly.

    Tangent models (`representation="tangent"`, `R_j(t) = M_j exp(d_j(t))`): the coefficients of
    the tangent coordinates `d` subtract as above but with no branch (they are about each
    model's own clip means), and `frames` holds `Δ_j = M_B⁻¹ M_A`. Unuma's polar form is taken
    per joint: each harmonic of a joint is a complex 3-vector `z` (its channels' phasors), its
    `phase` difference is `D = arg Σ_i z_A,i conj(z_B,i)` on all three channels (a single channel
    gives the wrapped `φ_A − φ_B`) and `aligned = z_A e^{−iD} − z_B`. A change of rig
    (`M' = C_pᵀ M C_j`, `d' = C_jᵀ d`, `z' = C_jᵀ z`) maps `Δ` to `C_jᵀ Δ C_j`, leaves `D` alone
    and maps `aligned` and `phasor` linearly, so the characteristic of two rewritten models is the
    rewritten characteristic (`amplitude` is per channel and informative only).

    Arguments:
        a: a FourierModel.
        b: a compatible FourierModel (different harmonic counts are zero-padded).

    Returns:
        A Characteristic; `superpose(b, [it], [1.0])` reproduces `a` (both methods) on b's
        branch. Raises `UserError` when a model's ω is not finite and > 0 (`log_omega` would
        be infinite; under jit the error comes from `eqx.error_if` when the program runs).
    """
    check_compatible(a, b)
    a, b = check_models_omega("characteristic", a=a, b=b)
    a, b = common_harmonics(a, b)
    return _characteristic(a, b)


@filter_jit
def _characteristic(a, b):
    tangent = getattr(a, "representation", "") == "tangent"
    _, triples = channel_kinds(a)
    if not tangent:
        # expmap: on b's branch, the one `superpose` adds on; Euler-only models: b onto a's as
        # before (bit for bit; the difference is the same up to rounding either way)
        if triples.size:
            a = on_branch_of(b, a)
        else:
            b = on_branch_of(a, b)
    phase = wrap_angle(a.phase - b.phase)
    aligned = None
    if tangent:
        cols = _tangent.model_columns(a)
        d, z = _tangent.polar_difference(*(_tangent.joint_phasors(phasor(m), cols) for m in (a, b)))
        phase = phase.at[cols].set(jnp.broadcast_to(d[..., None, :], z.shape[:-1]))
        aligned = (phasor(a) - phasor(b)).at[cols].set(z)
    return Characteristic(
        offset=a.offset - b.offset,
        amplitude=a.amplitude - b.amplitude,
        phase=phase,
        phasor=phasor(a) - phasor(b),
        log_omega=jnp.log(a.omega) - jnp.log(b.omega),
        representation=getattr(a, "representation", ""),
        channel_names=tuple(getattr(a, "channel_names", ())),
        frames=_tangent.frame_difference(a.frames, b.frames) if tangent else None,
        aligned=aligned,
        reference=b.offset if triples.size and not tangent else None,
    )


@filter_jit
def _characteristic_function(char, theta):
    return evaluate(char.offset, char.amplitude, char.phase, theta)


def characteristic_function(char: Characteristic, phase: ArrayLike) -> Float[Array, " channels"]:
    """The characteristic function Ψ(θ) = ΔA0 + Σ ΔA_n sin(nθ + Δφ_n) (Unuma 1995, eq. 8).

    Ψ is NOT Θ_A(θ) − Θ_B(θ) (sines do not subtract that way); it is the curve Unuma plots for
    a characteristic.

    Arguments:
        char: one (unstacked) Characteristic.
        phase: scalar θ in radians.

    Returns:
        `[C]`.
    """
    if char.offset.ndim != 1:
        raise UserError(
            "characteristic_function: `char` must be one characteristic, got a stacked batch; vmap over it"
        )
    phase = check_scalar("characteristic_function", "phase", phase, "; vmap over phase for many frames")
    return _characteristic_function(char, jnp.asarray(phase, dtype=dtype_of(char)))


def stack(items: Sequence):
    """Stack FourierModels (or Characteristics) along a new leading axis, padding harmonics.

    Arguments:
        items: a non-empty sequence of compatible models or characteristics.

    Returns:
        One object of the same type whose leaves have a leading axis `len(items)`; vmap over it
        with `eqx.filter_vmap` / `jax.vmap`.
    """
    items = list(items)
    if not items:
        raise UserError("stack: needs at least one model")
    for i, m in enumerate(items[1:], start=1):
        check_compatible(items[0], m, names=("items[0]", f"items[{i}]"))
    items = common_harmonics(*items)
    return jax.tree.map(lambda *xs: jnp.stack(xs), *items)


def stacked_characteristics(characteristics) -> Characteristic:
    """One Characteristic, a sequence of them, or a stacked batch, as a stacked batch `[K, ...]`."""
    if isinstance(characteristics, Characteristic):
        if characteristics.offset.ndim == 1:
            return jax.tree.map(lambda x: x[None], characteristics)
        return characteristics
    characteristics = list(characteristics)
    if not characteristics:
        raise UserError("characteristics: empty; pass at least one Characteristic")
    for i, c in enumerate(characteristics):
        if not isinstance(c, Characteristic):
            raise UserError(f"characteristics[{i}]: expected a Characteristic, got {type(c)}")
    if any(c.reference is None for c in characteristics):  # e.g. one read from an older file
        characteristics = [replace(c, reference=None) if c.reference is not None else c
                           for c in characteristics]
    return stack(characteristics)


def _prepare_superposition(base, characteristics, weights):
    chars = stacked_characteristics(characteristics)
    check_compatible(base, chars, names=("base", "characteristics"))
    k = chars.offset.shape[0]
    weights = jnp.asarray(weights, dtype=dtype_of(base))
    if weights.shape == () and k == 1:
        weights = weights[None]
    if weights.shape != (k,):
        raise UserError(
            f"superpose: `weights` has shape {weights.shape}, expected ({k},), one per characteristic"
        )
    weights = check_finite("superpose", "weights", weights)
    n = max(_count(base), _count(chars))
    return pad_harmonics(base, n), pad_harmonics(chars, n), weights


def saturate_weight(w, saturation):
    """The weight of a characteristic's harmonics and log ω under `superpose(saturation=)`:
    `w` on [0, 1], `1 + s tanh((w − 1)/s)` above 1 and `s tanh(w/s)` below 0 (`s`, the
    saturation, > 0). Equal to `w` with slope 1 and curvature 0 at both knees (twice
    differentiable), never beyond `[−s, 1 + s]`."""
    above = 1.0 + saturation * jnp.tanh((w - 1.0) / saturation)
    below = saturation * jnp.tanh(w / saturation)
    return jnp.where(w > 1.0, above, jnp.where(w < 0.0, below, w))


def _on_expmap_branch_of(reference, model):
    """`model` with its exponential-map triples moved onto the branch of the offsets
    `reference` `[C]` (`on_branch_of`); its other channels exactly as they are."""
    _, triples = channel_kinds(model)
    idx = jnp.asarray(triples)
    ref = replace(model, offset=model.offset.at[idx].set(reference[idx]))
    return on_branch_of(ref, model)


@filter_jit
def _superpose(base, chars, weights, method: str, include_omega: bool, saturation=None):
    _, triples = channel_kinds(base)
    if chars.reference is None or not triples.size or base.representation == "tangent":
        return _superpose_on_branch(base, chars, weights, method, include_omega, saturation)
    # Exponential maps: add the differences on the branch they were taken on (the first
    # characteristic's reference model), then return to the base's branch. Near |r| = π the
    # tangential part of a difference changes sign between antipodal branches.
    reference = chars.reference[0]
    moved = _on_expmap_branch_of(reference, base)
    out = _on_expmap_branch_of(base.offset, _superpose_on_branch(moved, chars, weights, method,
                                                                 include_omega, saturation))
    # A change of branch is not band-limited (`on_branch_of`): the base's own round trip is
    # off by its truncation. Adding the difference to the exact base cancels it, so w = 0 is
    # the base and the increment alone carries the branch changes.
    back = _on_expmap_branch_of(base.offset, moved)
    _, triples = channel_kinds(base)
    idx = jnp.asarray(triples).reshape(-1)
    amplitude, phase = polar_from_phasor(phasor(out)[idx] + phasor(base)[idx] - phasor(back)[idx])
    return replace(out, offset=out.offset.at[idx].add(base.offset[idx] - back.offset[idx]),
                   amplitude=out.amplitude.at[idx].set(amplitude), phase=out.phase.at[idx].set(phase))


def _superpose_on_branch(base, chars, weights, method: str, include_omega: bool, saturation=None):
    w = weights
    # the swings (harmonics) and the cadence saturate outside [0, 1]; the posture (offsets,
    # clip means) follows the weight (`superpose`, `saturation`)
    wh = w if saturation is None else saturate_weight(w, saturation)
    tangent = base.representation == "tangent"
    euler, _ = channel_kinds(base)
    # Characteristics written before offsets were compared on one branch may hold 2π too much
    # (tangent coordinates have no branch).
    char_offset = chars.offset if tangent else chars.offset - jnp.where(
        jnp.asarray(euler)[None, :], turns(chars.offset), 0.0)
    offset = base.offset + jnp.sum(w[:, None] * char_offset, axis=0)
    if method == "polar":
        amplitude = base.amplitude + jnp.sum(wh[:, None, None] * chars.amplitude, axis=0)
        phase = base.phase + jnp.sum(wh[:, None, None] * chars.phase, axis=0)
        amplitude, phase = canonical(amplitude, phase)
        if tangent:  # the joints' triples by the per-joint polar form (`characteristic`)
            cols = _tangent.model_columns(base)
            z = _tangent.polar_superpose(_tangent.joint_phasors(phasor(base), cols), chars.phase[:, cols[:, 0]],
                                         _tangent.joint_phasors(chars.aligned, cols), wh)
            amp_t, phase_t = polar_from_phasor(z)
            amplitude, phase = amplitude.at[cols].set(amp_t), phase.at[cols].set(phase_t)
    else:
        c = phasor(base) + jnp.sum(wh[:, None, None, None] * chars.phasor, axis=0)
        amplitude, phase = polar_from_phasor(c)
    om = base.omega
    if include_omega:
        om = om * jnp.exp(jnp.sum(wh * chars.log_omega))
    out = replace(base, offset=offset, amplitude=amplitude, phase=phase, omega=om)
    if tangent:
        out = replace(out, frames=_tangent.compose_frames(base.frames, chars.frames, w))
    return out


def superpose(
    base: FourierModel,
    characteristics: Characteristic | Sequence[Characteristic],
    weights: Float[ArrayLike, " k"],
    *,
    method: Method = "polar",
    include_omega: bool = True,
    saturation: Float[ArrayLike, ""] | None = None,
    speed_limit: SpeedLimit | None = None,
) -> FourierModel:
    """Superposition of weighted Fourier characteristics onto a base motion (Unuma 1995, §3.2),
    e.g. a brisk run = `superpose(run, [characteristic(brisk_walk, walk)], [1.37])`.

    - `method="polar"` (Unuma): `A = A_base + Σ w_k ΔA_k`, `φ = φ_base + Σ w_k Δφ_k`, then
      negative amplitudes are canonicalised. Adding a characteristic rotates each harmonic's
      phase by the (shorter-arc) phase difference and scales its amplitude linearly.
    - `method="phasor"`: `c = c_base + Σ w_k Δc_k`, plain vector addition: the synthesised
      signal is EXACTLY `Θ_base(θ) + Σ w_k (Θ_A,k(θ) − Θ_B,k(θ))` at a common phase θ. This is
      the form to use for least squares and PCA (linear in w).

    Both give `superpose(b, [characteristic(a, b)], [1]) == a` (on b's branch) and
    `w = 0 → base`; they differ in between (an arc against a chord when the phases differ),
    and polar never shrinks an amplitude through zero when two phases oppose. The offset
    always adds linearly; Euler offset differences are taken in (−π, π] (`characteristic`
    stores them so; older characteristic files are wrapped here), so half of a +179° → −179°
    characteristic moves a leg by 1°, not 179°. Exponential-map triples are added on the
    branch the characteristic was taken on (its `reference`, the first one's when several):
    the base is moved onto it, the differences added, and the result moved back onto the
    base's branch (`on_branch_of`; the base's own round trip is cancelled, so `w = 0` is the
    base exactly), so a base whose fit landed on the antipodal branch (|r| near π) gets the
    same rotations up to the harmonics above N that a change of branch creates (a characteristic
    from a file written before `reference` was stored has none: it adds on the base's branch).

    Arguments:
        base: FourierModel.
        characteristics: one Characteristic, a sequence, or a stacked batch (leading `K`).
        weights: `[K]` (a scalar for a single characteristic).
        method: `"polar"` (default) or `"phasor"`.
        include_omega: also scale ω by `Π_k (ω_A,k/ω_B,k)^w_k` (default True).
        saturation: `None` (default): every weight acts linearly (Unuma). A float `s > 0`:
            extrapolation moves the posture but not the swings: a weight outside [0, 1] acts
            on the offsets (and tangent clip means) as given, and on the harmonics and log ω
            as `1 + s tanh((w − 1)/s)` above 1, `s tanh(w/s)` below 0 (smooth, equal to `w`
            with slope 1 at the knees; weights in [0, 1] are unchanged). A characteristic
            then never adds more than `1 + s` of its swings or its cadence. On Bandai-1 the
            best content-mean transfer, extrapolated to 1.5 plainly, moved the toes 1.21x
            faster per radian of phase than any clip it was built from; with `s = 0.05` every
            weight in [0, 1.5] stays within 1 % of them (worst 1.008x; `s = 0.02`: 0.995x;
            `docs/findings.md`, section 3b).
        speed_limit: `None` (default), or a `style.SpeedLimit` (usually
            `style.joint_speed_limit([base, a, b], skeleton)`, the clips the characteristics
            were taken from): every weight is scaled by the largest `a` in [0, 1] whose result
            moves no joint faster (per second and/or per radian of phase, pelvis-relative,
            through FK) than the limit; weights already within it are unchanged. A limb flip
            (a channel on another branch, a swing extrapolated past a body's) is a joint faster
            than any clip, so the result never flips. Found by bisection under `jit` and `vmap`
            (`SpeedLimit.iterations` halvings); where the limit binds, `a` carries its implicit
            derivative (`speed.limited_scale`). A base already faster than the limit is
            returned as it is (`a = 0`).

    Returns:
        A FourierModel with the static fields of `base`. Raises `UserError` for non-finite
        weights or log_omega, a base ω that is not > 0 (under jit, from `eqx.error_if`) and a
        `saturation` that is not a finite scalar > 0.
    """
    check_choice(method, METHODS, "method", "superpose")
    base = check_models_omega("superpose", base=base)
    base, chars, weights = _prepare_superposition(base, characteristics, weights)
    if base.representation == "tangent" and (chars.frames is None or chars.aligned is None):
        raise UserError("superpose: the tangent characteristic has no `frames` or `aligned` (the "
                        "clip-mean and per-joint polar differences); recompute it with "
                        "style.characteristic(a, b)")
    chars = check_log_omega("superpose", chars)
    saturation, weights = check_saturation("superpose", saturation, weights)
    if speed_limit is None:
        return _superpose(base, chars, weights, method, bool(include_omega), saturation)
    if not isinstance(speed_limit, SpeedLimit):
        raise UserError("superpose: `speed_limit` must be a style.SpeedLimit or None, got "
                        f"{type(speed_limit).__name__}")
    pelvis = speed_limit.pelvis
    if pelvis is None:
        pelvis = _pelvis("superpose", None, speed_limit.skeleton, base)
    # `SpeedLimit` checks concrete bounds; traced ones (a bound under the caller's jit or grad)
    # are checked in the caller's program, not in `_superpose_limited`: a host callback there
    # would keep that program (12-20 s to compile on 2 cores) out of the persistent cache.
    bounds = [b for b in (speed_limit.max_speed, speed_limit.max_phase_speed) if b is not None]
    if any(isinstance(b, jax.core.Tracer) for b in bounds):
        bad = jnp.any(jnp.stack([~(jnp.isfinite(b) & (b > 0)) for b in bounds]))
        weights = eqx.error_if(weights, bad, "superpose: the speed limit's bounds must be finite and > 0")
    return _superpose_limited(base, chars, weights, method, bool(include_omega), saturation, speed_limit, pelvis)


@filter_jit
def _superpose_limited(base, chars, weights, method: str, include_omega: bool, saturation, limit, pelvis: int):
    def at(a, inputs):
        b, c, w, s = inputs
        return _superpose(b, c, a * w, method, include_omega, s)

    a = limited_scale(at, (base, chars, weights, saturation), limit, pelvis)
    return _superpose(base, chars, a * weights, method, include_omega, saturation)


def check_saturation(where: str, saturation, weights):
    """`saturation` (`superpose`, `transfer`) as a scalar array of `weights`' dtype (or None),
    and `weights`: a finite scalar > 0 (concrete: `UserError`; traced: `eqx.error_if` on the
    weights, which every output depends on)."""
    if saturation is None:
        return None, weights
    saturation = jnp.asarray(check_scalar(where, "saturation", saturation), dtype=jnp.result_type(weights))
    msg = f"{where}: `saturation` must be > 0 (None: no saturation)"
    s = concrete(saturation)
    if s is not None and not s > 0:
        raise UserError(f"{msg}, got {float(s)!r}")
    return saturation, eqx.error_if(weights, saturation <= 0, msg)


@filter_jit
def _add_noise(model, key, amplitude, harmonics: tuple[int, ...]):
    c, n = model.amplitude.shape
    k = len(harmonics)
    phase_dtype = jnp.result_type(model.phase)
    amp = jnp.broadcast_to(amplitude[:, None] if amplitude.ndim == 1 else amplitude, (c, k))
    phases = jax.random.uniform(key, (c, k), dtype=phase_dtype, minval=-jnp.pi, maxval=jnp.pi)
    new_n = max(max(harmonics), n)
    idx = jnp.asarray(harmonics) - 1
    amplitude_new = jnp.pad(model.amplitude, ((0, 0), (0, new_n - n))).at[:, idx].add(amp)
    phase_new = jnp.pad(model.phase, ((0, 0), (0, new_n - n))).at[:, idx].add(phases)
    amplitude_new, phase_new = canonical(amplitude_new, phase_new)
    return replace(model, amplitude=amplitude_new, phase=phase_new)


#: Arrays of `[C, max harmonic]` values alive at once in `_add_noise` (amplitude and phase,
#: their padded copies, the canonical form's temporaries), plus 3 of `[C, K]` (amplitudes,
#: phases, indices): counted before anything is built.
_NOISE_ARRAYS_PER_HARMONIC = 8


def _check_noise_bytes(model, max_harmonic: int, count: int, name: str, limit: int) -> None:
    c = int(model.offset.shape[-1])
    itemsize = jnp.dtype(dtype_of(model)).itemsize
    # Python ints: 10**18 harmonics do not overflow the estimate.
    nbytes = c * itemsize * (_NOISE_ARRAYS_PER_HARMONIC * int(max_harmonic) + 3 * int(count))
    # The tuple of harmonic numbers itself (a static argument): ~36 bytes per Python int.
    check_bytes(name, nbytes + 36 * int(count), limit)


def add_noise(
    model: FourierModel,
    key: PRNGKeyArray,
    amplitude: ArrayLike,
    harmonics: int | Sequence[int] = 3,
    *,
    max_memory: int | None = None,
) -> FourierModel:
    """Randomised higher harmonics, e.g. a shivering walk (Unuma 1995, §3.3).

    Adds harmonics above the model's `N` with the given amplitude and phases drawn uniformly in
    (−π, π) from `key`. Integer harmonics keep the motion periodic with the gait cycle (the
    same tremor repeats every cycle, as in Unuma); draw a new key per cycle for aperiodic noise.

    Arguments:
        model: FourierModel with `N` harmonics on `C` channels.
        key: a JAX PRNG key.
        amplitude: in model units (radians for angle channels): a scalar, `[C]` (zero for the
            channels to keep still, e.g. root translation) or `[C, K]` per added harmonic.
        harmonics: an int `K` (the harmonics `N+1 … N+K`, default 3) or explicit harmonic
            numbers, each `> N` (Python ints).
        max_memory: bytes the new model may need (default: a quarter of the machine's memory).

    Returns:
        A FourierModel with `max(harmonics)` harmonics (unused ones at zero).

    Raises:
        UserError: a bad argument, or harmonics whose model would need more than `max_memory`
            (checked before anything is allocated: 10**9 harmonics are refused at once).
    """
    n = _count(model)
    limit = resolve_limit("add_noise: max_memory", max_memory)
    bad = UserError(
        f"add_noise: `harmonics`={harmonics!r}; expected an int K or a sequence of int harmonic "
        "numbers (a float such as 2.0 is not a count)"
    )
    if isinstance(harmonics, bool | str):
        raise bad
    try:
        count = operator.index(harmonics)  # ints and NumPy integers, never floats
    except TypeError:
        count = None
    if count is not None:
        if count < 1:
            raise UserError(f"add_noise: `harmonics`={count}; add at least one harmonic")
        _check_noise_bytes(model, n + count, count, f"add_noise: `harmonics`={count}", limit)
        harmonics = tuple(range(n + 1, n + 1 + count))
    else:
        try:
            harmonics = tuple(operator.index(h) for h in harmonics)
        except TypeError:
            raise bad from None
        if not harmonics:
            raise UserError("add_noise: `harmonics` is empty; give at least one harmonic number")
        if min(harmonics) <= n:
            raise UserError(
                f"add_noise: `harmonics`={harmonics}: noise harmonics must be above the model's N={n}"
            )
        if len(set(harmonics)) != len(harmonics):
            raise UserError(f"add_noise: `harmonics`={harmonics}: repeated harmonic")
        _check_noise_bytes(model, max(harmonics), len(harmonics),
                           f"add_noise: `harmonics` up to {max(harmonics)}", limit)
    amplitude = jnp.asarray(amplitude, dtype=dtype_of(model))
    c = model.offset.shape[-1]
    if amplitude.shape not in ((), (c,), (c, len(harmonics))):
        raise UserError(
            f"add_noise: `amplitude` has shape {amplitude.shape}; expected (), ({c},) or ({c}, {len(harmonics)})"
        )
    amplitude = check_finite("add_noise", "amplitude", amplitude)
    return _add_noise(model, key, amplitude, harmonics)
