"""Unuma 1995 eq. 3 inter/extrapolation (polar and phasor), ω interpolation, the time-domain blend."""

from __future__ import annotations

import equinox as eqx
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, ArrayLike, Float

from fourierjax._checks import concrete
from fourierjax._fourier import _tangent
from fourierjax._jit import filter_jit
from fourierjax._math import wrap_angle
from fourierjax._rotations._common import _safe_atan2
from fourierjax._style._common import (
    METHODS,
    Method,
    OmegaMode,
    canonical,
    check_choice,
    check_compatible,
    check_models_omega,
    check_omega,
    check_scalar,
    dtype_of,
    evaluate,
    omega_at,
    omega_mode_argument,
    on_branch_of,
    phasor,
    polar_from_phasor,
    replace,
    show,
)
from fourierjax._style.characteristics import common_harmonics
from fourierjax.errors import UserError
from fourierjax.fourier import FourierModel
from fourierjax.rotations import quat_slerp


def interpolate_omega(
    omega_a: ArrayLike,
    omega_b: ArrayLike,
    s: ArrayLike,
    omega_mode: OmegaMode = "geometric",
    *,
    omega: OmegaMode | None = None,
) -> Array:
    """Fundamental frequency between two models.

    Geometric by default, `ω(s) = ω_A^(1−s) ω_B^s`: ω is a scale parameter, geometric
    interpolation treats frequency and period alike, and ω stays positive under any
    extrapolation.

    Arguments:
        omega_a: rad/s (> 0).
        omega_b: rad/s (> 0).
        s: interpolation parameter (any real, any shape).
        omega_mode: `"geometric"` (`ω_A^(1−s) ω_B^s`, default) or `"linear"`
            (`(1−s)ω_A + sω_B`).
        omega: deprecated alias of `omega_mode`.

    Returns:
        ω(s) in rad/s, shape of `s`. Raises `UserError` when `omega_a` or `omega_b` is not
        finite and > 0, or a linear ω(s) is not > 0 (under jit, from `eqx.error_if`).
    """
    omega_mode = omega_mode_argument("interpolate_omega", omega_mode, omega)
    omega_a = check_omega("interpolate_omega", "omega_a", omega_a)
    omega_b = check_omega("interpolate_omega", "omega_b", omega_b)
    s = jnp.asarray(s)
    s = check_linear_omega("interpolate_omega", omega_a, omega_b, s, omega_mode)
    return omega_at(omega_a, omega_b, s, omega_mode)


def check_linear_omega(where: str, omega_a, omega_b, s, omega_mode: str):
    """`s` unless linear ω, extrapolated far enough, crosses zero (ω_A = 5, ω_B = 7 at s = −3:
    −1 rad/s): a model no function accepts back."""
    if omega_mode != "linear":
        return s
    message = (
        f"{where}: linear ω interpolation is not > 0 at this `s`; use omega_mode=\"geometric\" "
        "(positive for every s) or a smaller extrapolation"
    )
    a, b, sv = concrete(omega_a), concrete(omega_b), concrete(s)
    if a is None or b is None or sv is None:
        om = (1 - s) * jnp.asarray(omega_a) + s * jnp.asarray(omega_b)
        return eqx.error_if(s, ~jnp.all(om > 0), message)
    om = (1 - sv) * a + sv * b
    bad = ~(om > 0)
    if np.any(bad):
        raise UserError(
            f"{where}: linear ω interpolation gives {show(np.asarray(om), bad)} rad/s at this `s`, "
            "not > 0; use omega_mode=\"geometric\" (positive for every s) or a smaller extrapolation"
        )
    return s


def _body_polar(za, zb, s):
    """Eq. 3 with one phase turn per harmonic for the whole body (`[..., K, 3, N, 2]` joint
    phasors): `e^{isD}((1 − s) z_A + s z_B e^{−iD})`, `D = arg Σ_j <z_A,j, z_B,j>` (the per-joint
    `_tangent.polar_interpolate` summed over the joints; 0 where the sum vanishes)."""
    re = jnp.sum(zb[..., 0] * za[..., 0] + zb[..., 1] * za[..., 1], axis=(-3, -2))
    im = jnp.sum(zb[..., 1] * za[..., 0] - zb[..., 0] * za[..., 1], axis=(-3, -2))
    d = jnp.broadcast_to(_safe_atan2(im, re)[..., None, :], za.shape[:-3] + za.shape[-2:-1])
    return _tangent.turn_phase((1 - s) * za + s * _tangent.turn_phase(zb, -d), s * d)


def interpolate_core(a, b, s, method: str, omega_mode: str):
    """Eq. 3 at one `s`, `b` already on `a`'s branch (not jitted: the transition calls it per frame)."""
    offset = (1 - s) * a.offset + s * b.offset
    if method == "polar":
        # Shorter arc: step from φ_A by s times the wrapped difference.
        amplitude = (1 - s) * a.amplitude + s * b.amplitude
        phase = a.phase + s * wrap_angle(b.phase - a.phase)
        amplitude, phase = canonical(amplitude, phase)
        if a.representation == "tangent":  # a joint's triple by the per-joint polar form
            cols = _tangent.model_columns(a)
            z = _body_polar(*(_tangent.joint_phasors(phasor(m), cols) for m in (a, b)), s)
            amp_t, phase_t = polar_from_phasor(z)
            amplitude, phase = amplitude.at[cols].set(amp_t), phase.at[cols].set(phase_t)
    else:
        amplitude, phase = polar_from_phasor((1 - s) * phasor(a) + s * phasor(b))
    om = omega_at(a.omega, b.omega, s, omega_mode)
    return replace(a, offset=offset, amplitude=amplitude, phase=phase, omega=om)


@filter_jit
def _interpolate(a, b, s, method: str, omega_mode: str):
    if a.representation == "tangent":
        # Eq. 3 on the tangent coordinates, and the clip means slerped (s = 0, 1: a and b).
        out = interpolate_core(a, b, s, method, omega_mode)
        return replace(out, frames=quat_slerp(a.frames, b.frames, s))
    return interpolate_core(a, on_branch_of(a, b), s, method, omega_mode)


def interpolate(
    a: FourierModel,
    b: FourierModel,
    s: ArrayLike,
    *,
    method: Method = "polar",
    omega_mode: OmegaMode = "geometric",
    omega: OmegaMode | None = None,
) -> FourierModel:
    """Inter/extrapolation Ξ(s, ·) between two gait models (Unuma 1995, eq. 3).

    `s = 0` gives `a`, `s = 1` gives `b`, `0 < s < 1` interpolates and any other `s`
    extrapolates ("more tired than tired"). Offsets and amplitudes move linearly; with
    `method="polar"` (Unuma) phases move along the shorter arc and negative extrapolated
    amplitudes are canonicalised to `(|A|, φ + π)`; with `method="phasor"` the phasors move
    linearly, which is exactly the time-domain blend `(1 − s)Θ(θ) + sΠ(θ)` at a common phase θ
    (see `blend_time_domain`). Models with different harmonic counts are zero-padded.

    Angle offsets are interpolated on one branch: an Euler channel as `a + s·wrap(b − a)`
    (thighs at +179° and −179° meet at ±180°, not 0°), an exponential-map triple `J.expmap0..2`
    after b's rotation vector is replaced by the equivalent one nearest a's (`v − 2πk·v/|v|`,
    its cycle mapped sample by sample and projected back onto its harmonics, `on_branch_of`);
    `root.*` channels interpolate plainly. So `s = 1`
    gives b's motion on a's branch. Tangent models (`representation="tangent"`) interpolate
    their coefficients (the tangent coordinates) by eq. 3 and slerp the joints' clip means
    (`frames`), so `s = 0` and `s = 1` give exactly `a` and `b`. Their polar form turns the
    whole body: each harmonic of a joint is a complex 3-vector `z`, turned along the shorter arc
    by `s·D`, `D = arg Σ_j Σ_i z_B,ji conj(z_A,ji)` over all the joints `j`, as
    `e^{isD}((1 − s) z_A + s z_B e^{−iD})` (a single channel gives Unuma's form), so that a
    change of the rig's joint frames commutes with it. One `D` per joint broke the pelvis and
    legs' coordination: the stance foot slid (issue 20: Bandai walk_normal/walk_old at s = 0.5,
    0.33 of the root speed against 0.10/0.21 in the sources; one `D` for the body, 0.17).

    Which method: polar keeps each harmonic's amplitude between the two (a harmonic whose
    phases oppose does not cancel halfway, as it does with phasors) and is what Unuma
    animates; phasor is linear in the signals (exact for averaging, PCA, least squares). Each
    harmonic takes its own shorter arc, so polar interpolation equals a time shift only when the
    two models are aligned to the same gait event; models from `fourierjax.motion.fit_motions`
    are.

    Arguments:
        a: FourierModel.
        b: FourierModel on the same channels and representation.
        s: scalar interpolation parameter (traced; vmap over it for a family of models:
            `jax.vmap(lambda s: interpolate(a, b, s))(s_values)`).
        method: `"polar"` (default, Unuma eq. 3) or `"phasor"`.
        omega_mode: `"geometric"` (default) or `"linear"` interpolation of the fundamental
            (see `interpolate_omega`).
        omega: deprecated alias of `omega_mode`.

    Returns:
        A FourierModel with the static fields of `a`. Raises `UserError` for a non-scalar `s`,
        a non-finite `s`, a model whose ω is not > 0, or a linear ω(s) that is not > 0 (under
        jit the value errors come from `eqx.error_if` when the program runs).
    """
    check_compatible(a, b)
    check_choice(method, METHODS, "method", "interpolate")
    omega_mode = omega_mode_argument("interpolate", omega_mode, omega)
    s = check_scalar(
        "interpolate", "s", s, "; for a family of models vmap over s: "
        "jax.vmap(lambda s: style.interpolate(a, b, s))(s_values)"
    )
    a, b = check_models_omega("interpolate", a=a, b=b)
    s = check_linear_omega("interpolate", a.omega, b.omega, s, omega_mode)
    a, b = common_harmonics(a, b)
    return _interpolate(a, b, jnp.asarray(s, dtype=dtype_of(a)), method, omega_mode)


@filter_jit
def _blend(a, b, s, theta):
    x = (1 - s) * evaluate(a.offset, a.amplitude, a.phase, theta) + s * evaluate(
        b.offset, b.amplitude, b.phase, theta
    )
    if a.representation != "tangent":
        return x
    # The tangent coordinates blend as above, about the clip means slerped by the same weight.
    frames = quat_slerp(a.frames, b.frames, s)
    return _tangent.from_tangent(x[None], frames, _tangent.model_columns(a))[0]


def blend_time_domain(a: FourierModel, b: FourierModel, s: ArrayLike, phase: ArrayLike) -> Float[Array, " channels"]:
    """Unuma's time-domain alternative to eq. 3: `(1 − s) Θ(θ) + s Π(θ)`.

    Both models are played at the SAME cycle phase θ (their own time axes rescaled so that one
    cycle is 2π, which is what makes the blend well defined for different ω); to play it in
    seconds use `θ = interpolate_omega(a.omega, b.omega, s) · t`. The result equals
    `interpolate(a, b, s, method="phasor")` evaluated at θ when the models' offsets are on one
    branch (this blend takes the signals as they are).

    Tangent models: the tangent coordinates `d` blend as above and the joints' clip means are
    slerped by the same weight (`s = 0`: a's frames, `s = 1`: b's); the result is expmap features
    (what `fourier.synthesize_phase` returns), and still equals the phasor `interpolate` at θ.

    Arguments:
        a: FourierModel.
        b: a compatible FourierModel.
        s: scalar.
        phase: scalar θ in rad (vmap over it for many frames).

    Returns:
        `[C]` channel values in the models' units.
    """
    check_compatible(a, b)
    s = check_scalar("blend_time_domain", "s", s, "; vmap over s for several weights")
    phase = check_scalar("blend_time_domain", "phase", phase, "; vmap over phase for many frames")
    dtype = dtype_of(a)
    return _blend(a, b, jnp.asarray(s, dtype=dtype), jnp.asarray(phase, dtype=dtype))
