"""Style algebra on Fourier gait models: interpolation, transitions, characteristics, style space.

Everything here works on `fourierjax.fourier.FourierModel` (Unuma 1995, eq. 1, sine convention)

    Θ_c(θ) = A0_c + Σ_{n=1..N} A_cn sin(n θ + φ_cn),      θ = cycle phase (rad), θ = ω t

and returns new models (or sampled channel values). All numeric functions are pure, jit-able,
vmap-able and differentiable; the public ones are jitted (`eqx.filter_jit`), Python numbers are
turned into arrays first so that a new `s` or weight never retraces.

Two coordinate systems for a harmonic, and why both exist:

* **polar** `(A, φ)`: Unuma's own parameters (eq. 3, 7, 8). Interpolating them moves a
  harmonic along an arc: the amplitude changes linearly and the timing of the peak (phase)
  slides; phases are differenced on the circle, along the SHORTER arc (φ_A = 3.0 and
  φ_B = −3.0 are 0.28 rad apart, not 6.0). Extrapolation (s < 0 or s > 1) can make an
  amplitude negative; `−A sin(x) = A sin(x + π)`, so we canonicalise to `A ≥ 0` by adding π to
  the phase. Polar coordinates are singular at `A = 0`, where the phase means nothing.
* **phasor** `c = A e^{iφ}` stored as `[..., 2] = (A cos φ, A sin φ)`: then
  `A sin(nθ + φ) = Im(c e^{inθ})` is LINEAR in `c`, so a linear combination of phasors is the
  same linear combination of the time signals played at the same cycle phase. Phasor
  interpolation is exactly Unuma's time-domain alternative `(1 − s)Θ(θ) + sΠ(θ)`, and the
  style space (stacking, PCA, least-squares style weights) lives in phasor coordinates.

The fundamental frequency is interpolated **geometrically** by default,
`ω(s) = ω_A^(1−s) ω_B^s`: ω is a scale parameter, geometric interpolation treats frequency and
period alike (interpolating periods gives the same answer), and ω stays positive under any
extrapolation. A characteristic carries `log(ω_A/ω_B)` so that superposition and interpolation
agree. `omega="linear"` is offered for interpolation and transitions.

The common phase: every model is evaluated at the same cycle phase θ (Unuma's "rescaled"
time, one cycle = 2π), so phase 0 must mean the same gait event in both models. Models fitted by
`fourierjax.fourier` are aligned to a canonical gait event; unaligned models interpolate fine
numerically but blend mismatched poses.
"""

from __future__ import annotations

import functools
import operator
from collections.abc import Sequence
from typing import TYPE_CHECKING, Literal

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, ArrayLike, Float, PRNGKeyArray

from fourierjax._checks import concrete
from fourierjax.errors import UserError

if TYPE_CHECKING:  # pragma: no cover
    from fourierjax.fourier import FourierModel

__all__ = [
    "Characteristic",
    "StylePCA",
    "add_noise",
    "blend_time_domain",
    "characteristic",
    "characteristic_function",
    "check_compatible",
    "ease",
    "fit_style_weights",
    "interpolate",
    "interpolate_omega",
    "model_from_style_vector",
    "pad_harmonics",
    "pca_project",
    "pca_reconstruct",
    "phasor",
    "stack",
    "style_matrix",
    "style_pca",
    "style_vector",
    "superpose",
    "transition",
    "transition_schedule",
    "wrap_angle",
]

Method = Literal["polar", "phasor"]
OmegaInterp = Literal["geometric", "linear"]
Ease = Literal["smoothstep", "smootherstep", "linear"]

_METHODS = ("polar", "phasor")
_OMEGA_INTERPS = ("geometric", "linear")
_EASES = ("smoothstep", "smootherstep", "linear")
# Gauss-Legendre nodes on [-1, 1] for the phase integral over the transition window; the
# integrand ω(s(u)) is smooth there, so 16 nodes are exact to rounding in float64.
_GL_NODES, _GL_WEIGHTS = (np.asarray(x, dtype=np.float64) for x in np.polynomial.legendre.leggauss(16))
# Below this squared norm a phasor is treated as zero (amplitude 0, phase 0).
_TINY = 1e-30


# -------------------------------------------------------------------------------------------
# Input checks (values only on concrete inputs: under jit/vmap/grad they are skipped)
# -------------------------------------------------------------------------------------------


def _show(value: np.ndarray, bad: np.ndarray) -> str:
    # The first offending value, short even for a stacked batch of models.
    if value.ndim == 0:
        return repr(value.item())
    first = tuple(int(i) for i in np.argwhere(bad)[0])
    return f"{value[first].item()!r} at index {first} ({int(np.sum(bad))} of {value.size} bad)"


def _check_omega(where: str, name: str, omega) -> None:
    """UserError unless the fundamental(s) are finite and > 0 rad/s (skipped when traced):
    log ω (geometric interpolation, characteristics, style vectors) is −inf at 0 and NaN below,
    and so are their gradients."""
    value = concrete(omega)
    if value is None:
        return
    bad = ~(np.isfinite(value) & (value > 0))
    if np.any(bad):
        raise UserError(f"{where}: `{name}` must be finite and > 0 (rad/s), got {_show(value, bad)}")


def _check_models_omega(where: str, **models) -> None:
    for name, model in models.items():
        _check_omega(where, f"{name}.omega", model.omega)


def _check_log_omega(where: str, chars) -> None:
    # A characteristic read from a file may carry log(ω_A/ω_B) = ±inf or NaN.
    value = concrete(chars.log_omega)
    if value is None:
        return
    bad = ~np.isfinite(value)
    if np.any(bad):
        raise UserError(
            f"{where}: `characteristics` log_omega must be finite (log of a ratio of two positive ω),"
            f" got {_show(value, bad)}"
        )


def _check_scalar(where: str, name: str, value, hint: str = "") -> None:
    """UserError unless `value` is a scalar (always checked) and finite (when concrete)."""
    if jnp.ndim(value) != 0:
        raise UserError(f"{where}: `{name}` must be a scalar, got shape {jnp.shape(value)}{hint}")
    v = concrete(value)
    if v is not None and not np.isfinite(v):
        raise UserError(f"{where}: `{name}` must be finite, got {v.item()!r}")


# -------------------------------------------------------------------------------------------
# Small helpers
# -------------------------------------------------------------------------------------------


def wrap_angle(x: ArrayLike) -> Array:
    """Wrap angles to (−π, π].

    **Arguments:** `x`: angles in radians, any shape.

    **Returns:** `x + 2πk` in (−π, π], same shape; the gradient is 1 everywhere.
    """
    x = jnp.asarray(x)
    return jnp.pi - jnp.mod(jnp.pi - x, 2 * jnp.pi)


def _canonical(amplitude: Array, phase: Array) -> tuple[Array, Array]:
    # −A sin(x) = A sin(x + π): keep amplitudes non-negative, as the model promises.
    negative = amplitude < 0
    return jnp.abs(amplitude), wrap_angle(jnp.where(negative, phase + jnp.pi, phase))


def _polar_from_phasor(c: Array) -> tuple[Array, Array]:
    re, im = c[..., 0], c[..., 1]
    r2 = re * re + im * im
    zero = r2 < _TINY
    # Shim to avoid NaNs in jnp.where branches (sqrt and atan2 at the origin), which cause
    # failures for reverse-mode AD.
    r2_safe = jnp.where(zero, 1.0, r2)
    amplitude = jnp.where(zero, 0.0, jnp.sqrt(r2_safe))
    phase = jnp.arctan2(jnp.where(zero, 0.0, im), jnp.where(zero, 1.0, re))
    return amplitude, wrap_angle(phase)


def _phasor_from_polar(amplitude: Array, phase: Array) -> Array:
    return jnp.stack([amplitude * jnp.cos(phase), amplitude * jnp.sin(phase)], axis=-1)


def phasor(model: FourierModel) -> Float[Array, "channels harmonics 2"]:
    """The harmonics of `model` as phasors `(A cos φ, A sin φ)`, so that
    `A sin(nθ + φ) = re·sin(nθ) + im·cos(nθ)`.

    **Arguments:** `model`: a FourierModel with `N` harmonics on `C` channels.

    **Returns:** `[C, N, 2]`.
    """
    return _phasor_from_polar(model.amplitude, model.phase)


def _evaluate(offset: Array, amplitude: Array, phase: Array, theta: Array) -> Array:
    # Θ_c(θ) = A0_c + Σ_n A_cn sin(n θ + φ_cn) for one scalar θ (Unuma eq. 1).
    n = jnp.arange(1, amplitude.shape[-1] + 1, dtype=amplitude.dtype)
    return offset + jnp.sum(amplitude * jnp.sin(n[None, :] * theta + phase), axis=-1)


def _replace(model, **fields):
    """A copy of an equinox module with some leaves replaced (shapes may change)."""
    names = tuple(fields)
    return eqx.tree_at(lambda m: tuple(getattr(m, k) for k in names), model, tuple(fields[k] for k in names))


def _dtype(model):
    # The float dtype JAX will compute in (model files hold float64 numpy arrays, which become
    # float32 unless x64 is enabled; asking for float64 then would warn).
    return jax.dtypes.canonicalize_dtype(model.offset.dtype)


def _num_harmonics(x) -> int:
    return int(x.amplitude.shape[-1])


def pad_harmonics(model, num_harmonics: int):
    """`model` with zero-amplitude harmonics appended up to `num_harmonics` (same signal).

    **Arguments:** `model`: a FourierModel or Characteristic with `N ≤ num_harmonics`
    harmonics; `num_harmonics`: the new count (a Python int).

    **Returns:** the same kind of object with `num_harmonics` harmonics.
    """
    n = _num_harmonics(model)
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
    return _replace(model, **fields)


def check_compatible(a, b, names: tuple[str, str] = ("a", "b")) -> None:
    """Raise `UserError` (a `ValueError`) naming the argument if two models (or characteristics)
    cannot be combined: different channel representation, channel names or channel counts.

    **Arguments:** `a`, `b`: FourierModels or Characteristics; `names`: the argument names to
    use in the message.
    """
    na, nb = names
    ra, rb = getattr(a, "representation", None), getattr(b, "representation", None)
    if ra != rb:
        raise UserError(
            f"{nb}: representation {rb!r} does not match {na}'s {ra!r}; refit both on the same channel representation"
        )
    ca, cb = tuple(getattr(a, "channel_names", ())), tuple(getattr(b, "channel_names", ()))
    if ca != cb:
        if len(ca) != len(cb):
            detail = f"{len(cb)} channels against {len(ca)}"
        else:
            i = next(i for i, (x, y) in enumerate(zip(ca, cb)) if x != y)
            detail = f"channel {i} is {cb[i]!r}, {na} has {ca[i]!r}"
        raise UserError(f"{nb}: channels do not match {na}'s ({detail})")
    if a.offset.shape[-1] != b.offset.shape[-1]:
        raise UserError(f"{nb}: {b.offset.shape[-1]} channels against {na}'s {a.offset.shape[-1]}")


def _common_harmonics(*models):
    n = max(_num_harmonics(m) for m in models)
    return tuple(pad_harmonics(m, n) for m in models)


def _check_choice(value: str, choices: tuple[str, ...], name: str, where: str) -> None:
    if value not in choices:
        raise UserError(f"{where}: `{name}`={value!r}; expected one of {choices}")


def interpolate_omega(omega_a: ArrayLike, omega_b: ArrayLike, s: ArrayLike, omega: OmegaInterp = "geometric") -> Array:
    """Fundamental frequency between two models.

    **Arguments:** `omega_a`, `omega_b`: rad/s (> 0); `s`: interpolation parameter (any real,
    any shape); `omega`: `"geometric"` (`ω_A^(1−s) ω_B^s`, default, positive for every s) or
    `"linear"` (`(1−s)ω_A + sω_B`).

    **Returns:** ω(s) in rad/s, shape of `s`. Raises `UserError` when a concrete `omega_a` or
    `omega_b` is not finite and > 0 (the geometric path and its gradient are NaN there).
    """
    _check_choice(omega, _OMEGA_INTERPS, "omega", "interpolate_omega")
    _check_omega("interpolate_omega", "omega_a", omega_a)
    _check_omega("interpolate_omega", "omega_b", omega_b)
    _check_linear_omega("interpolate_omega", omega_a, omega_b, s, omega)
    return _omega_at(omega_a, omega_b, jnp.asarray(s), omega)


def _check_linear_omega(where: str, omega_a, omega_b, s, omega: str) -> None:
    """Linear ω extrapolated far enough crosses zero (ω_A = 5, ω_B = 7 at s = −3: −1 rad/s): a
    model no function accepts back. Refused when the values are concrete."""
    if omega != "linear":
        return
    a, b, sv = concrete(omega_a), concrete(omega_b), concrete(s)
    if a is None or b is None or sv is None:
        return
    om = (1 - sv) * a + sv * b
    bad = ~(om > 0)
    if np.any(bad):
        raise UserError(
            f"{where}: linear ω interpolation gives {_show(np.asarray(om), bad)} rad/s at this `s`, "
            "not > 0; use omega=\"geometric\" (positive for every s) or a smaller extrapolation"
        )


def _omega_at(omega_a, omega_b, s, omega: str) -> Array:
    if omega == "linear":
        return (1 - s) * omega_a + s * omega_b
    return jnp.exp((1 - s) * jnp.log(omega_a) + s * jnp.log(omega_b))


# -------------------------------------------------------------------------------------------
# Inter/extrapolation (Unuma eq. 3) and the time-domain alternative
# -------------------------------------------------------------------------------------------


@eqx.filter_jit
def _interpolate(a, b, s, method: str, omega: str):
    offset = (1 - s) * a.offset + s * b.offset
    if method == "polar":
        # Shorter arc: step from φ_A by s times the wrapped difference.
        amplitude = (1 - s) * a.amplitude + s * b.amplitude
        phase = a.phase + s * wrap_angle(b.phase - a.phase)
        amplitude, phase = _canonical(amplitude, phase)
    else:
        amplitude, phase = _polar_from_phasor((1 - s) * phasor(a) + s * phasor(b))
    om = _omega_at(a.omega, b.omega, s, omega)
    return _replace(a, offset=offset, amplitude=amplitude, phase=phase, omega=om)


def interpolate(
    a: FourierModel,
    b: FourierModel,
    s: ArrayLike,
    *,
    method: Method = "polar",
    omega: OmegaInterp = "geometric",
) -> FourierModel:
    """Inter/extrapolation Ξ(s, ·) between two gait models (Unuma 1995, eq. 3).

    `s = 0` gives `a`, `s = 1` gives `b`, `0 < s < 1` interpolates and any other `s`
    extrapolates ("more tired than tired"). Offsets and amplitudes move linearly; with
    `method="polar"` (Unuma) phases move along the shorter arc and negative extrapolated
    amplitudes are canonicalised to `(|A|, φ + π)`; with `method="phasor"` the phasors move
    linearly, which is exactly the time-domain blend `(1 − s)Θ(θ) + sΠ(θ)` at a common phase θ
    (see `blend_time_domain`). Models with different harmonic counts are zero-padded.

    Which to use: polar keeps each harmonic's amplitude between the two (a harmonic whose
    phases oppose does not cancel halfway, as it does with phasors) and is what Unuma
    animates; phasor is linear in the signals (exact for averaging, PCA, least squares). Each
    harmonic takes its own shorter arc, so polar interpolation equals a time shift only when the
    two models are aligned to the same gait event (`nδ` small for every harmonic n); models from
    `fourierjax.motion.fit_motions` are.

    **Arguments:**

    - `a`, `b`: FourierModels on the same channels and representation.
    - `s`: scalar interpolation parameter (traced; vmap over it for a family of models:
      `jax.vmap(lambda s: interpolate(a, b, s))(s_values)`).
    - `method`: `"polar"` (default, Unuma eq. 3) or `"phasor"`.
    - `omega`: `"geometric"` (default) or `"linear"` interpolation of the fundamental.

    **Returns:** a FourierModel with the static fields of `a`. Raises `UserError` for a
    non-scalar `s`, and, when concrete, for a non-finite `s` or a model whose ω is not > 0.
    """
    check_compatible(a, b)
    _check_choice(method, _METHODS, "method", "interpolate")
    _check_choice(omega, _OMEGA_INTERPS, "omega", "interpolate")
    _check_scalar(
        "interpolate", "s", s, "; for a family of models vmap over s: "
        "jax.vmap(lambda s: style.interpolate(a, b, s))(s_values)"
    )
    _check_models_omega("interpolate", a=a, b=b)
    _check_linear_omega("interpolate", a.omega, b.omega, s, omega)
    a, b = _common_harmonics(a, b)
    return _interpolate(a, b, jnp.asarray(s, dtype=_dtype(a)), method, omega)


@eqx.filter_jit
def _blend(a, b, s, theta):
    return (1 - s) * _evaluate(a.offset, a.amplitude, a.phase, theta) + s * _evaluate(
        b.offset, b.amplitude, b.phase, theta
    )


def blend_time_domain(a: FourierModel, b: FourierModel, s: ArrayLike, phase: ArrayLike) -> Float[Array, " channels"]:
    """Unuma's time-domain alternative to eq. 3: `(1 − s) Θ(θ) + s Π(θ)`.

    Both models are played at the SAME cycle phase θ (their own time axes rescaled so that one
    cycle is 2π, which is what makes the blend well defined for different ω); to play it in
    seconds use `θ = interpolate_omega(a.omega, b.omega, s) · t`. The result equals
    `interpolate(a, b, s, method="phasor")` evaluated at θ.

    **Arguments:** `a`, `b`: compatible FourierModels; `s`: scalar; `phase`: scalar θ in rad
    (vmap over it for many frames).

    **Returns:** `[C]` channel values in the models' units.
    """
    check_compatible(a, b)
    _check_scalar("blend_time_domain", "s", s, "; vmap over s for several weights")
    _check_scalar("blend_time_domain", "phase", phase, "; vmap over phase for many frames")
    dtype = _dtype(a)
    return _blend(a, b, jnp.asarray(s, dtype=dtype), jnp.asarray(phase, dtype=dtype))


# -------------------------------------------------------------------------------------------
# Transitions over time
# -------------------------------------------------------------------------------------------


def ease(u: ArrayLike, kind: Ease = "smoothstep") -> Array:
    """An ease curve from 0 to 1, clamped outside [0, 1].

    **Arguments:** `u`: normalised time (any shape); `kind`: `"smoothstep"` (3u² − 2u³, zero
    slope at both ends, default), `"smootherstep"` (6u⁵ − 15u⁴ + 10u³, zero slope and
    curvature) or `"linear"`.

    **Returns:** s(u), same shape.
    """
    _check_choice(kind, _EASES, "kind", "ease")
    u = jnp.clip(jnp.asarray(u), 0.0, 1.0)
    if kind == "linear":
        return u
    if kind == "smoothstep":
        return u * u * (3 - 2 * u)
    return u * u * u * (u * (6 * u - 15) + 10)


def _schedule_one(t, omega_a, omega_b, start, duration, ease_kind, omega):
    # s(t) and the integrated cycle phase θ(t) = ∫_0^t ω(s(τ)) dτ at one time t: F(t) − F(0)
    # for the antiderivative F below (F(0) = 0 unless the window starts before t = 0, where
    # F alone gave θ(0) = 0.30 rad for a window from −0.5 s).
    s, f_t = _phase_antiderivative(t, omega_a, omega_b, start, duration, ease_kind, omega)
    _, f_0 = _phase_antiderivative(jnp.zeros_like(t), omega_a, omega_b, start, duration, ease_kind, omega)
    return s, f_t - f_0


def _phase_antiderivative(t, omega_a, omega_b, start, duration, ease_kind, omega):
    u_end = jnp.clip((t - start) / duration, 0.0, 1.0)
    s = ease(u_end, ease_kind)
    nodes = jnp.asarray(_GL_NODES, dtype=u_end.dtype)
    weights = jnp.asarray(_GL_WEIGHTS, dtype=u_end.dtype)
    u = 0.5 * u_end * (nodes + 1)
    window = duration * 0.5 * u_end * jnp.sum(weights * _omega_at(omega_a, omega_b, ease(u, ease_kind), omega))
    before = omega_a * jnp.minimum(t, start)
    after = omega_b * jnp.maximum(t - (start + duration), 0.0)
    return s, before + window + after


@functools.partial(jax.jit, static_argnames=("ease_kind", "omega"))
def _schedule(t_s, omega_a, omega_b, start, duration, ease_kind, omega):
    return jax.vmap(_schedule_one, in_axes=(0, None, None, None, None, None, None))(
        t_s, omega_a, omega_b, start, duration, ease_kind, omega
    )


def _check_window(where: str, t_s, start_s, duration_s) -> None:
    # Shapes always; values when concrete, whatever their type (Python, NumPy or JAX scalar):
    # a zero duration divides by zero in the schedule and gives NaN frames.
    if jnp.ndim(t_s) != 1:
        raise UserError(
            f"{where}: `t_s` must be [T] sample times in seconds, got shape {jnp.shape(t_s)}; "
            "flatten a grid of times (t_s.ravel()) and reshape the result"
        )
    _check_scalar(where, "start_s", start_s)
    if jnp.ndim(duration_s) != 0:
        raise UserError(f"{where}: `duration_s` must be a scalar, got shape {jnp.shape(duration_s)}")
    d = concrete(duration_s)
    if d is not None and not (np.isfinite(d) and d > 0):
        raise UserError(
            f"{where}: `duration_s`={d.item()!r}; a transition needs a finite positive duration (seconds)"
        )


def transition_schedule(
    omega_a: ArrayLike,
    omega_b: ArrayLike,
    t_s: Float[ArrayLike, " frames"],
    start_s: ArrayLike,
    duration_s: ArrayLike,
    *,
    ease: Ease = "smoothstep",
    omega: OmegaInterp = "geometric",
) -> tuple[Float[Array, " frames"], Float[Array, " frames"]]:
    """The blend weight s(t) and the integrated cycle phase θ(t) of a transition.

    `s(t) = ease((t − start)/duration)`, 0 before the window and 1 after it. The phase is the
    integral of the instantaneous frequency, `θ(t) = ∫_0^t ω(s(τ)) dτ` (exact before and after
    the window, 16-point Gauss–Legendre inside it), so it is continuous and monotone however
    fast ω changes; the naive `ω(s(t))·t` instead jumps by `Δω·t` and plays the cycle at the
    wrong speed during the window.

    **Arguments:** `omega_a`, `omega_b`: rad/s of the start and end gaits; `t_s`: `[T]` times
    in seconds (any order, θ(0) = 0); `start_s`, `duration_s`: the window in seconds
    (`duration_s > 0`); `ease`: see `ease`; `omega`: see `interpolate_omega`.

    **Returns:** `(s [T], theta [T])`, theta in radians. Raises `UserError` for a `t_s` that is
    not 1-D or a non-scalar window, and, when concrete, for `duration_s ≤ 0`, non-finite window
    values or an ω that is not > 0.
    """
    _check_choice(ease, _EASES, "ease", "transition_schedule")
    _check_choice(omega, _OMEGA_INTERPS, "omega", "transition_schedule")
    _check_window("transition_schedule", t_s, start_s, duration_s)
    _check_omega("transition_schedule", "omega_a", omega_a)
    _check_omega("transition_schedule", "omega_b", omega_b)
    t_s = jnp.asarray(t_s)
    dtype = jnp.result_type(t_s.dtype, jnp.asarray(omega_a).dtype, float)
    f = functools.partial(jnp.asarray, dtype=dtype)
    return _schedule(f(t_s), f(omega_a), f(omega_b), f(start_s), f(duration_s), ease_kind=ease, omega=omega)


@eqx.filter_jit
def _transition(a, b, t_s, start, duration, ease_kind, method, omega):
    s, theta = jax.vmap(_schedule_one, in_axes=(0, None, None, None, None, None, None))(
        t_s, a.omega, b.omega, start, duration, ease_kind, omega
    )

    def frame(s_i, theta_i):
        m = _interpolate(a, b, s_i, method, omega)
        return _evaluate(m.offset, m.amplitude, m.phase, theta_i)

    return jax.vmap(frame)(s, theta), s, theta


def transition(
    a: FourierModel,
    b: FourierModel,
    t_s: Float[ArrayLike, " frames"],
    start_s: ArrayLike,
    duration_s: ArrayLike,
    *,
    ease: Ease = "smoothstep",
    method: Method = "polar",
    omega: OmegaInterp = "geometric",
    return_schedule: bool = False,
):
    """A gait transition from `a` to `b` over a time window (Unuma §2.3, walk → run).

    Frame `t` plays `Ξ(s(t), θ(t))`: the interpolated model (`interpolate`) at blend weight
    `s(t)` evaluated at the integrated cycle phase `θ(t) = ∫ ω(s(τ)) dτ` (see
    `transition_schedule`). Because the phase is integrated, the cycle never jumps when ω
    changes, so a run → walk transition is as smooth as walk → run (Unuma found his
    run → walk unnatural): the cadence decelerates continuously, the eased s(t) has zero slope at
    both ends of the window, and every channel, root velocity channels included, changes
    continuously (C¹ in time with `"smoothstep"`). Choose `start_s` at a gait event (θ a
    multiple of 2π) to begin the change at a foot strike.

    **Arguments:**

    - `a`, `b`: compatible FourierModels (start and end gait), aligned to the same gait event.
    - `t_s`: `[T]` sample times in seconds (θ(0) = 0).
    - `start_s`, `duration_s`: the transition window in seconds (`duration_s > 0`).
    - `ease`, `method`, `omega`: see `ease`, `interpolate`, `interpolate_omega`.
    - `return_schedule`: also return `(s [T], theta [T])`.

    **Returns:** `[T, C]` channel values (model units), or `(values, s, theta)`. Raises
    `UserError` as `transition_schedule` does (and for a model whose ω is not > 0).
    """
    check_compatible(a, b)
    _check_choice(ease, _EASES, "ease", "transition")
    _check_choice(method, _METHODS, "method", "transition")
    _check_choice(omega, _OMEGA_INTERPS, "omega", "transition")
    _check_window("transition", t_s, start_s, duration_s)
    _check_models_omega("transition", a=a, b=b)
    a, b = _common_harmonics(a, b)
    dtype = _dtype(a)
    values, s, theta = _transition(
        a,
        b,
        jnp.asarray(t_s, dtype=dtype),
        jnp.asarray(start_s, dtype=dtype),
        jnp.asarray(duration_s, dtype=dtype),
        ease,
        method,
        omega,
    )
    return (values, s, theta) if return_schedule else values


# -------------------------------------------------------------------------------------------
# Fourier characteristics and superposition (Unuma eq. 6-8)
# -------------------------------------------------------------------------------------------


class Characteristic(eqx.Module):
    """Fourier characteristics `A − B` of two gait models (Unuma 1995, eq. 7).

    Stored in both coordinate systems, because they cannot be derived from one another without
    the two models: the polar differences (Unuma) and the phasor difference.

    **Fields** (a leading batch axis `[K, ...]` on every leaf when stacked with `stack`):

    - `offset` `[C]`: `A0_A − A0_B`.
    - `amplitude` `[C, N]`: `A_A − A_B` (may be negative).
    - `phase` `[C, N]`: `φ_A − φ_B` wrapped to (−π, π] (the shorter arc).
    - `phasor` `[C, N, 2]`: `c_A − c_B`, `c = (A cos φ, A sin φ)`.
    - `log_omega`: `log(ω_A / ω_B)` (scalar).
    - `representation`, `channel_names`: static, copied from the models.
    """

    offset: Float[Array, "*k channels"]
    amplitude: Float[Array, "*k channels harmonics"]
    phase: Float[Array, "*k channels harmonics"]
    phasor: Float[Array, "*k channels harmonics 2"]
    log_omega: Float[Array, "*k"]
    representation: str = eqx.field(static=True, default="")
    channel_names: tuple[str, ...] = eqx.field(static=True, default=())


def characteristic(a: FourierModel, b: FourierModel) -> Characteristic:
    """The Fourier characteristics `A − B` (Unuma 1995, eq. 7), e.g. briskness =
    `characteristic(brisk_walk, normal_walk)`.

    **Arguments:** `a`, `b`: compatible FourierModels (different harmonic counts are
    zero-padded).

    **Returns:** a Characteristic; `superpose(b, [it], [1.0])` reproduces `a` (both methods).
    Raises `UserError` when a concrete model's ω is not finite and > 0 (`log_omega` would be
    infinite).
    """
    check_compatible(a, b)
    _check_models_omega("characteristic", a=a, b=b)
    a, b = _common_harmonics(a, b)
    return _characteristic(a, b)


@eqx.filter_jit
def _characteristic(a, b):
    return Characteristic(
        offset=a.offset - b.offset,
        amplitude=a.amplitude - b.amplitude,
        phase=wrap_angle(a.phase - b.phase),
        phasor=phasor(a) - phasor(b),
        log_omega=jnp.log(a.omega) - jnp.log(b.omega),
        representation=getattr(a, "representation", ""),
        channel_names=tuple(getattr(a, "channel_names", ())),
    )


@eqx.filter_jit
def _characteristic_function(char, theta):
    return _evaluate(char.offset, char.amplitude, char.phase, theta)


def characteristic_function(char: Characteristic, phase: ArrayLike) -> Float[Array, " channels"]:
    """The characteristic function Ψ(θ) = ΔA0 + Σ ΔA_n sin(nθ + Δφ_n) (Unuma 1995, eq. 8).

    Note Ψ is NOT Θ_A(θ) − Θ_B(θ) (sines do not subtract that way); it is the curve Unuma
    plots for a characteristic.

    **Arguments:** `char`: one (unstacked) Characteristic; `phase`: scalar θ in radians.

    **Returns:** `[C]`.
    """
    if char.offset.ndim != 1:
        raise UserError(
            "characteristic_function: `char` must be one characteristic, got a stacked batch; vmap over it"
        )
    _check_scalar("characteristic_function", "phase", phase, "; vmap over phase for many frames")
    return _characteristic_function(char, jnp.asarray(phase, dtype=_dtype(char)))


def stack(items: Sequence):
    """Stack FourierModels (or Characteristics) along a new leading axis, padding harmonics.

    **Arguments:** `items`: a non-empty sequence of compatible models or characteristics.

    **Returns:** one object of the same type whose leaves have a leading axis `len(items)`;
    vmap over it with `eqx.filter_vmap` / `jax.vmap`.
    """
    items = list(items)
    if not items:
        raise UserError("stack: needs at least one model")
    for i, m in enumerate(items[1:], start=1):
        check_compatible(items[0], m, names=("items[0]", f"items[{i}]"))
    items = _common_harmonics(*items)
    return jax.tree.map(lambda *xs: jnp.stack(xs), *items)


def _stacked_characteristics(characteristics) -> Characteristic:
    # One Characteristic, a sequence of them, or a stacked batch -> a stacked batch [K, ...].
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
    return stack(characteristics)


def _prepare_superposition(base, characteristics, weights):
    chars = _stacked_characteristics(characteristics)
    check_compatible(base, chars, names=("base", "characteristics"))
    k = chars.offset.shape[0]
    weights = jnp.asarray(weights, dtype=_dtype(base))
    if weights.shape == () and k == 1:
        weights = weights[None]
    if weights.shape != (k,):
        raise UserError(
            f"superpose: `weights` has shape {weights.shape}, expected ({k},), one per characteristic"
        )
    w = concrete(weights)
    if w is not None and not np.isfinite(w).all():
        raise UserError(f"superpose: `weights` must be finite, got {_show(w, ~np.isfinite(w))}")
    n = max(_num_harmonics(base), _num_harmonics(chars))
    return pad_harmonics(base, n), pad_harmonics(chars, n), weights


@eqx.filter_jit
def _superpose(base, chars, weights, method: str, include_omega: bool):
    w = weights
    offset = base.offset + jnp.sum(w[:, None] * chars.offset, axis=0)
    if method == "polar":
        amplitude = base.amplitude + jnp.sum(w[:, None, None] * chars.amplitude, axis=0)
        phase = base.phase + jnp.sum(w[:, None, None] * chars.phase, axis=0)
        amplitude, phase = _canonical(amplitude, phase)
    else:
        c = phasor(base) + jnp.sum(w[:, None, None, None] * chars.phasor, axis=0)
        amplitude, phase = _polar_from_phasor(c)
    om = base.omega
    if include_omega:
        om = om * jnp.exp(jnp.sum(w * chars.log_omega))
    return _replace(base, offset=offset, amplitude=amplitude, phase=phase, omega=om)


def superpose(
    base: FourierModel,
    characteristics: Characteristic | Sequence[Characteristic],
    weights: Float[ArrayLike, " k"],
    *,
    method: Method = "polar",
    include_omega: bool = True,
) -> FourierModel:
    """Superposition of weighted Fourier characteristics onto a base motion (Unuma 1995, §3.2),
    e.g. a brisk run = `superpose(run, [characteristic(brisk_walk, walk)], [1.37])`.

    - `method="polar"` (Unuma): `A = A_base + Σ w_k ΔA_k`, `φ = φ_base + Σ w_k Δφ_k`, then
      negative amplitudes are canonicalised. Adding a characteristic rotates each harmonic's
      phase by the (shorter-arc) phase difference and scales its amplitude linearly.
    - `method="phasor"`: `c = c_base + Σ w_k Δc_k`. Each harmonic is a 2-vector, so this is
      plain vector addition: the synthesised signal is EXACTLY
      `Θ_base(θ) + Σ w_k (Θ_A,k(θ) − Θ_B,k(θ))` at a common phase θ. This is the form to use
      for least squares and PCA (linear in w).

    Both give `superpose(b, [characteristic(a, b)], [1]) == a` and `w = 0 → base`; they differ
    in between (an arc against a chord when the phases differ), and polar never shrinks an
    amplitude through zero when two phases oppose. The offset always adds linearly.

    **Arguments:**

    - `base`: FourierModel.
    - `characteristics`: one Characteristic, a sequence, or a stacked batch (leading `K`).
    - `weights`: `[K]` (a scalar for a single characteristic).
    - `method`: `"polar"` (default) or `"phasor"`.
    - `include_omega`: also scale ω by `Π_k (ω_A,k/ω_B,k)^w_k` (default True).

    **Returns:** a FourierModel with the static fields of `base`.
    """
    _check_choice(method, _METHODS, "method", "superpose")
    _check_models_omega("superpose", base=base)
    base, chars, weights = _prepare_superposition(base, characteristics, weights)
    _check_log_omega("superpose", chars)
    return _superpose(base, chars, weights, method, bool(include_omega))


# -------------------------------------------------------------------------------------------
# Noise (Unuma §3.3: shivering)
# -------------------------------------------------------------------------------------------


@eqx.filter_jit
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
    amplitude_new, phase_new = _canonical(amplitude_new, phase_new)
    return _replace(model, amplitude=amplitude_new, phase=phase_new)


def add_noise(
    model: FourierModel,
    key: PRNGKeyArray,
    amplitude: ArrayLike,
    harmonics: int | Sequence[int] = 3,
) -> FourierModel:
    """Randomised higher harmonics, e.g. a shivering walk (Unuma 1995, §3.3).

    Adds harmonics above the model's `N` with the given amplitude and phases drawn uniformly in
    (−π, π) from `key`. Integer harmonics keep the motion periodic with the gait cycle (the
    same tremor repeats every cycle, as in Unuma); draw a new key per cycle for aperiodic noise.

    **Arguments:**

    - `model`: FourierModel with `N` harmonics on `C` channels.
    - `key`: a JAX PRNG key.
    - `amplitude`: in model units (radians for angle channels): a scalar, `[C]` (zero for the
      channels to keep still, e.g. root translation) or `[C, K]` per added harmonic.
    - `harmonics`: an int `K` (the harmonics `N+1 … N+K`, default 3) or explicit harmonic
      numbers, each `> N` (Python ints).

    **Returns:** a FourierModel with `max(harmonics)` harmonics (unused ones at zero).
    """
    n = _num_harmonics(model)
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
    amplitude = jnp.asarray(amplitude, dtype=_dtype(model))
    c = model.offset.shape[-1]
    if amplitude.shape not in ((), (c,), (c, len(harmonics))):
        raise UserError(
            f"add_noise: `amplitude` has shape {amplitude.shape}; expected (), ({c},) or ({c}, {len(harmonics)})"
        )
    a = concrete(amplitude)
    if a is not None and not np.isfinite(a).all():
        raise UserError(f"add_noise: `amplitude` must be finite, got {_show(a, ~np.isfinite(a))}")
    return _add_noise(model, key, amplitude, harmonics)


# -------------------------------------------------------------------------------------------
# Style space (Tilmanne & Dutoit; Troje)
# -------------------------------------------------------------------------------------------


@eqx.filter_jit
def _style_vector(model):
    c = phasor(model) / jnp.sqrt(2.0)  # [C, N, 2]
    per_channel = jnp.concatenate([model.offset[:, None], jnp.reshape(c, (c.shape[0], -1))], axis=1)
    return jnp.concatenate([jnp.reshape(per_channel, (-1,)), jnp.log(model.omega)[None]])


def style_vector(model: FourierModel) -> Float[Array, " dim"]:
    """The flat style vector of one model (Tilmanne & Dutoit §2.2: C × 5 + 1 = 271 numbers for
    54 channels and N = 2), in PHASOR coordinates.

    Layout: per channel `[A0, re_1, im_1, …, re_N, im_N]` with `(re, im) = A(cos φ, sin φ)/√2`,
    channels in order, then `log ω`. Why not Tilmanne's raw `(p, φ)`: phases wrap (the mean of
    3.0 and −3.0 is 0, the wrong way round) and are undefined at zero amplitude, so linear
    combinations and PCA of raw phases are meaningless; phasors add like the signals do. The
    `1/√2` makes the Euclidean norm match the signal (Parseval): for two models with the same
    ω, `|v_A − v_B|²` (without the last entry) is the mean over one cycle of
    `Σ_c (Θ_A,c(θ) − Θ_B,c(θ))²`. The fundamental enters as `log ω` (unscaled).

    **Arguments:** `model`: FourierModel with `C` channels and `N` harmonics.

    **Returns:** `[C (1 + 2N) + 1]`. Raises `UserError` when a concrete `model.omega` is not
    finite and > 0 (`log ω` would be −inf or NaN).
    """
    _check_models_omega("style_vector", model=model)
    return _style_vector(model)


def model_from_style_vector(vector: Float[ArrayLike, " dim"], like: FourierModel) -> FourierModel:
    """Inverse of `style_vector`: a FourierModel shaped like `like` (channels, harmonics and
    static fields) from a style vector, e.g. a PCA reconstruction.

    **Arguments:** `vector`: `[C (1 + 2N) + 1]`; `like`: a FourierModel giving C, N and the
    static fields.

    **Returns:** a FourierModel.
    """
    c, n = like.amplitude.shape
    vector = jnp.asarray(vector, dtype=_dtype(like))
    if vector.shape != (c * (1 + 2 * n) + 1,):
        raise UserError(
            f"model_from_style_vector: `vector` has shape {vector.shape}, expected "
            f"({c * (1 + 2 * n) + 1},) for {c} channels and {n} harmonics"
        )
    return _model_from_style_vector(vector, like)


@eqx.filter_jit
def _model_from_style_vector(vector, like):
    c, n = like.amplitude.shape
    per_channel = jnp.reshape(vector[:-1], (c, 1 + 2 * n))
    amplitude, phase = _polar_from_phasor(jnp.reshape(per_channel[:, 1:], (c, n, 2)) * jnp.sqrt(2.0))
    return _replace(like, offset=per_channel[:, 0], amplitude=amplitude, phase=phase, omega=jnp.exp(vector[-1]))


def style_matrix(models) -> Float[Array, "models dim"]:
    """Stack models into a matrix of style vectors (one row per model, see `style_vector`).

    **Arguments:** `models`: a sequence of compatible FourierModels (harmonic counts are padded
    to the largest) or a stacked batch (leading axis).

    **Returns:** `[M, C (1 + 2N) + 1]`.
    """
    if isinstance(models, Sequence):
        models = stack(models)
    _check_models_omega("style_matrix", models=models)
    return eqx.filter_vmap(_style_vector)(models)


class StylePCA(eqx.Module):
    """Principal components of a set of style vectors (Troje 2002; Tilmanne & Dutoit).

    - `mean` `[D]`: the mean style vector.
    - `components` `[K, D]`: orthonormal principal directions, largest variance first (sign
      fixed so that each direction's largest-magnitude entry is positive).
    - `explained_variance` `[K]`: variance along each direction (divided by `M − 1`).
    - `explained_variance_ratio` `[K]`: fraction of the total variance.
    """

    mean: Float[Array, " dim"]
    components: Float[Array, "k dim"]
    explained_variance: Float[Array, " k"]
    explained_variance_ratio: Float[Array, " k"]


def style_pca(matrix: Float[ArrayLike, "models dim"], num_components: int | None = None) -> StylePCA:
    """PCA over style vectors (rows of `style_matrix`).

    **Arguments:** `matrix`: `[M, D]` with `M ≥ 2`; `num_components`: how many to keep
    (default `min(M − 1, D)`, the rank of the centred data).

    **Returns:** a StylePCA.
    """
    matrix = jnp.asarray(matrix)
    if matrix.ndim != 2 or matrix.shape[0] < 2:
        raise UserError(f"style_pca: `matrix` has shape {matrix.shape}; need [M, D] with at least 2 rows")
    m, d = matrix.shape
    k = min(m - 1, d) if num_components is None else int(num_components)
    if not 1 <= k <= min(m, d):
        raise UserError(f"style_pca: `num_components`={num_components}; must be in 1..{min(m, d)}")
    return _style_pca(matrix, k)


@functools.partial(jax.jit, static_argnums=1)
def _style_pca(matrix, k):
    mean = jnp.mean(matrix, axis=0)
    centred = matrix - mean[None, :]
    _, sv, vt = jnp.linalg.svd(centred, full_matrices=False)
    signs = jnp.sign(vt[jnp.arange(vt.shape[0]), jnp.argmax(jnp.abs(vt), axis=1)])
    vt = vt * jnp.where(signs == 0, 1.0, signs)[:, None]
    var = sv**2 / (matrix.shape[0] - 1)
    total = jnp.sum(var)
    return StylePCA(
        mean=mean,
        components=vt[:k],
        explained_variance=var[:k],
        explained_variance_ratio=var[:k] / jnp.where(total > 0, total, 1.0),
    )


def pca_project(pca: StylePCA, vectors: Float[ArrayLike, "*batch dim"]) -> Float[Array, "*batch k"]:
    """Coordinates of style vectors in the principal basis: `(v − mean) · components`.

    **Arguments:** `pca`: a StylePCA; `vectors`: `[..., D]`.

    **Returns:** `[..., K]`.
    """
    vectors = jnp.asarray(vectors)
    d = pca.mean.shape[-1]
    if vectors.ndim < 1 or vectors.shape[-1] != d:
        raise UserError(
            f"pca_project: `vectors` must be [..., {d}] style vectors (the PCA's dimension), "
            f"got shape {vectors.shape}"
        )
    centred = vectors - jnp.broadcast_to(pca.mean, vectors.shape)
    components = jnp.broadcast_to(pca.components, (*vectors.shape[:-1], *pca.components.shape))
    return jnp.sum(centred[..., None, :] * components, axis=-1)


def pca_reconstruct(pca: StylePCA, coords: Float[ArrayLike, "*batch k"]) -> Float[Array, "*batch dim"]:
    """Style vectors from principal coordinates: `mean + coords · components`.

    **Arguments:** `pca`: a StylePCA; `coords`: `[..., K]`.

    **Returns:** `[..., D]` (map back to a model with `model_from_style_vector`).
    """
    coords = jnp.asarray(coords)
    k = pca.components.shape[-2]
    if coords.ndim < 1 or coords.shape[-1] != k:
        raise UserError(
            f"pca_reconstruct: `coords` must be [..., {k}] (one per principal component), "
            f"got shape {coords.shape}"
        )
    components = jnp.broadcast_to(pca.components, (*coords.shape[:-1], *pca.components.shape))
    combo = jnp.sum(coords[..., :, None] * components, axis=-2)
    return jnp.broadcast_to(pca.mean, combo.shape) + combo


@eqx.filter_jit
def _fit_style_weights(base, chars, target, ridge, include_omega: bool):
    scale = 1.0 / jnp.sqrt(2.0)
    k, c, n, _ = chars.phasor.shape
    # Columns: style-space direction of each characteristic in phasor coordinates; the
    # phasor superposition is linear in w, so least squares is exact and closed form.
    cols = jnp.concatenate([chars.offset[:, :, None], jnp.reshape(chars.phasor * scale, (k, c, 2 * n))], axis=2)
    cols = jnp.reshape(cols, (k, -1))
    residual = _style_vector(target)[:-1] - _style_vector(base)[:-1]
    if include_omega:
        cols = jnp.concatenate([cols, chars.log_omega[:, None]], axis=1)
        residual = jnp.concatenate([residual, (jnp.log(target.omega) - jnp.log(base.omega))[None]])
    gram = jnp.sum(cols[:, None, :] * cols[None, :, :], axis=-1)
    rhs = jnp.sum(cols * residual[None, :], axis=-1)
    # Relative jitter keeps the factorisation defined for collinear characteristics.
    jitter = 10 * jnp.finfo(gram.dtype).eps * jnp.trace(gram) / k + jnp.finfo(gram.dtype).tiny
    return _spd_solve(gram + (ridge + jitter) * jnp.eye(k, dtype=gram.dtype), rhs)


def _spd_solve(gram: Array, rhs: Array) -> Array:
    # Cholesky solve of a small K x K SPD system, unrolled in plain jnp: LAPACK calls hang
    # when batched under vmap on 2-core CPUs (STYLE.md), and users vmap this over clips.
    k = gram.shape[0]
    lower = [[None] * k for _ in range(k)]
    for j in range(k):
        d2 = gram[j, j] - sum((lower[j][m] ** 2 for m in range(j)), start=jnp.zeros(()))
        d = jnp.sqrt(jnp.maximum(d2, jnp.finfo(gram.dtype).tiny))
        lower[j][j] = d
        for i in range(j + 1, k):
            acc = sum((lower[i][m] * lower[j][m] for m in range(j)), start=jnp.zeros(()))
            lower[i][j] = (gram[i, j] - acc) / d
    y = []
    for i in range(k):
        y.append((rhs[i] - sum((lower[i][m] * y[m] for m in range(i)), start=jnp.zeros(()))) / lower[i][i])
    x = [None] * k
    for i in reversed(range(k)):
        acc = sum((lower[m][i] * x[m] for m in range(i + 1, k)), start=jnp.zeros(()))
        x[i] = (y[i] - acc) / lower[i][i]
    return jnp.stack(x)


def fit_style_weights(
    base: FourierModel,
    characteristics: Characteristic | Sequence[Characteristic],
    target: FourierModel,
    *,
    ridge: ArrayLike = 0.0,
    include_omega: bool = True,
) -> Float[Array, " k"]:
    """Style weights that best explain `target` as `base + Σ w_k characteristic_k`.

    Least squares in phasor style space (see `style_vector`): minimises
    `|style_vector(superpose(base, chars, w, method="phasor")) − style_vector(target)|²`, which
    (by Parseval) is the mean squared angle error over one cycle, plus `(log ω)²` mismatch when
    `include_omega`. The problem is linear in `w`, so the solution is closed form (normal
    equations, `K × K`); differentiable in every input. Fit the target clip first
    (`fourierjax.fourier`), aligned to the same gait event as the characteristics.

    **Arguments:**

    - `base`: FourierModel the characteristics are added to.
    - `characteristics`: one Characteristic, a sequence, or a stacked batch `[K, ...]`.
    - `target`: FourierModel of the motion to explain (same channels and representation).
    - `ridge`: Tikhonov weight `λ` added to the normal matrix (use > 0 when characteristics are
      nearly collinear).
    - `include_omega`: also match `log ω`.

    **Returns:** `[K]` weights.
    """
    check_compatible(base, target, names=("base", "target"))
    chars = _stacked_characteristics(characteristics)
    check_compatible(base, chars, names=("base", "characteristics"))
    _check_models_omega("fit_style_weights", base=base, target=target)
    _check_log_omega("fit_style_weights", chars)
    n = max(_num_harmonics(base), _num_harmonics(chars), _num_harmonics(target))
    base, chars, target = (pad_harmonics(x, n) for x in (base, chars, target))
    _check_scalar("fit_style_weights", "ridge", ridge)
    r = concrete(ridge)
    if r is not None and r < 0:
        raise UserError(f"fit_style_weights: `ridge` must be >= 0 (a Tikhonov weight), got {r.item()!r}")
    ridge = jnp.asarray(ridge, dtype=_dtype(base))
    return _fit_style_weights(base, chars, target, ridge, bool(include_omega))
