"""Shared pieces of the style algebra: argument checks, polar and phasor harmonics, angle branches."""

from __future__ import annotations

import warnings
from typing import Literal

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float

from fourierjax._checks import concrete
from fourierjax._math import wrap_angle
from fourierjax._rotations._quat import nearest_rotation_vector
from fourierjax.errors import UserError
from fourierjax.fourier import FourierModel, angle_channel_mask

Method = Literal["polar", "phasor"]
OmegaMode = Literal["geometric", "linear"]
Ease = Literal["smoothstep", "smootherstep", "linear"]

METHODS = ("polar", "phasor")
OMEGA_MODES = ("geometric", "linear")
EASES = ("smoothstep", "smootherstep", "linear")
# Below this squared norm a phasor is treated as zero (amplitude 0, phase 0).
_TINY = 1e-30


# ------------------------------------------------------------------------------ input checks
# Each check raises a UserError on a concrete value and, on a traced one, returns the value
# wrapped in `eqx.error_if` (the caller must use what it returns): a check that vanished under
# jit would not be a check.


def show(value: np.ndarray, bad: np.ndarray) -> str:
    """The first offending value, short even for a stacked batch of models."""
    if value.ndim == 0:
        return repr(value.item())
    first = tuple(int(i) for i in np.argwhere(bad)[0])
    return f"{value[first].item()!r} at index {first} ({int(np.sum(bad))} of {value.size} bad)"


def check_omega(where: str, name: str, omega):
    """`omega` unless a fundamental is not finite and > 0 rad/s: log ω (geometric
    interpolation, characteristics, style vectors) is −inf at 0 and NaN below, and so are
    their gradients."""
    message = f"{where}: `{name}` must be finite and > 0 (rad/s)"
    value = concrete(omega)
    if value is None:
        return eqx.error_if(omega, ~(jnp.isfinite(omega) & (omega > 0)), message)
    bad = ~(np.isfinite(value) & (value > 0))
    if np.any(bad):
        raise UserError(f"{message}, got {show(value, bad)}")
    return omega


def check_models_omega(where: str, **models):
    """The models (in the order given) with their ω checked as `check_omega` does. A traced
    check guards every leaf of its model, so that it runs whichever output is used (XLA drops
    an `error_if` whose result nothing reads)."""
    out = []
    for name, model in models.items():
        message = f"{where}: `{name}.omega` must be finite and > 0 (rad/s)"
        value = concrete(model.omega)
        if value is None:
            model = eqx.error_if(model, ~jnp.all(jnp.isfinite(model.omega) & (model.omega > 0)), message)
        else:
            check_omega(where, f"{name}.omega", value)
        out.append(model)
    return out[0] if len(out) == 1 else tuple(out)


def check_log_omega(where: str, chars):
    """`chars` unless its log(ω_A/ω_B) is ±inf or NaN (a characteristic read from a file may
    be); a traced check guards every leaf."""
    message = f"{where}: `characteristics` log_omega must be finite (log of a ratio of two positive ω)"
    value = concrete(chars.log_omega)
    if value is None:
        return eqx.error_if(chars, ~jnp.all(jnp.isfinite(chars.log_omega)), message)
    bad = ~np.isfinite(value)
    if np.any(bad):
        raise UserError(f"{message}, got {show(value, bad)}")
    return chars


def check_finite(where: str, name: str, value, detail: str = ""):
    """`value` unless an entry is not finite."""
    message = f"{where}: `{name}` must be finite{detail}"
    v = concrete(value)
    if v is None:
        return eqx.error_if(value, ~jnp.all(jnp.isfinite(value)), message)
    bad = ~np.isfinite(v)
    if np.any(bad):
        raise UserError(f"{message}, got {show(v, bad)}")
    return value


def check_scalar(where: str, name: str, value, hint: str = ""):
    """`value` unless it is not a scalar (a shape, checked at trace time) or not finite."""
    if jnp.ndim(value) != 0:
        raise UserError(f"{where}: `{name}` must be a scalar, got shape {jnp.shape(value)}{hint}")
    return check_finite(where, name, value)


def check_choice(value: str, choices: tuple[str, ...], name: str, where: str) -> None:
    if value not in choices:
        raise UserError(f"{where}: `{name}`={value!r}; expected one of {choices}")


def omega_mode_argument(where: str, omega_mode: str, omega: str | None, stacklevel: int = 3) -> str:
    """The ω interpolation mode from `omega_mode=` or its deprecated alias `omega=`."""
    if omega is not None:
        warnings.warn(
            f"{where}: the keyword `omega=` is deprecated, use `omega_mode=` (elsewhere `omega` is a "
            "frequency in rad/s)",
            DeprecationWarning,
            stacklevel=stacklevel,
        )
        if omega_mode != "geometric" and omega_mode != omega:
            raise UserError(f"{where}: give `omega_mode` only (got omega_mode={omega_mode!r} and omega={omega!r})")
        omega_mode = omega
    check_choice(omega_mode, OMEGA_MODES, "omega_mode", where)
    return omega_mode


def check_compatible(a, b, names: tuple[str, str] = ("a", "b")) -> None:
    """Raise `UserError` (a `ValueError`) naming the argument if two models (or
    characteristics) cannot be combined: different channel representation, channel names or
    channel counts.

    Arguments:
        a: a FourierModel or Characteristic.
        b: another one.
        names: the argument names to use in the message.
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


# ------------------------------------------------------------------------- small helpers


def canonical(amplitude: Array, phase: Array) -> tuple[Array, Array]:
    """`(|A|, φ + π)` where `A < 0`: −A sin(x) = A sin(x + π) keeps amplitudes non-negative."""
    negative = amplitude < 0
    return jnp.abs(amplitude), wrap_angle(jnp.where(negative, phase + jnp.pi, phase))


def polar_from_phasor(c: Array) -> tuple[Array, Array]:
    re, im = c[..., 0], c[..., 1]
    r2 = re * re + im * im
    zero = r2 < _TINY
    # Shim to avoid NaNs in jnp.where branches (sqrt and atan2 at the origin), which cause
    # failures for reverse-mode AD.
    r2_safe = jnp.where(zero, 1.0, r2)
    amplitude = jnp.where(zero, 0.0, jnp.sqrt(r2_safe))
    phase = jnp.arctan2(jnp.where(zero, 0.0, im), jnp.where(zero, 1.0, re))
    return amplitude, wrap_angle(phase)


def phasor_from_polar(amplitude: Array, phase: Array) -> Array:
    return jnp.stack([amplitude * jnp.cos(phase), amplitude * jnp.sin(phase)], axis=-1)


def phasor(model: FourierModel) -> Float[Array, "channels harmonics 2"]:
    """The harmonics of `model` as phasors `(A cos φ, A sin φ)`, so that
    `A sin(nθ + φ) = re·sin(nθ) + im·cos(nθ)`.

    Arguments:
        model: a FourierModel with `N` harmonics on `C` channels.

    Returns:
        `[C, N, 2]`.
    """
    return phasor_from_polar(model.amplitude, model.phase)


def evaluate(offset: Array, amplitude: Array, phase: Array, theta: Array) -> Array:
    """Θ_c(θ) = A0_c + Σ_n A_cn sin(n θ + φ_cn) for one scalar θ (Unuma 1995, eq. 1)."""
    n = jnp.arange(1, amplitude.shape[-1] + 1, dtype=amplitude.dtype)
    return offset + jnp.sum(amplitude * jnp.sin(n[None, :] * theta + phase), axis=-1)


def replace(model, **fields):
    """A copy of an equinox module with some leaves replaced (shapes may change)."""
    names = tuple(fields)
    return eqx.tree_at(lambda m: tuple(getattr(m, k) for k in names), model, tuple(fields[k] for k in names))


def dtype_of(model):
    # The float dtype JAX will compute in (model files hold float64 numpy arrays, which become
    # float32 unless x64 is enabled; asking for float64 then would warn).
    return jax.dtypes.canonicalize_dtype(model.offset.dtype)


def num_harmonics(x) -> int:
    return int(x.amplitude.shape[-1])


def omega_at(omega_a, omega_b, s, omega_mode: str) -> Array:
    """ω(s): `ω_A^(1−s) ω_B^s` (geometric) or `(1−s)ω_A + sω_B` (linear)."""
    if omega_mode == "linear":
        return (1 - s) * omega_a + s * omega_b
    return jnp.exp((1 - s) * jnp.log(omega_a) + s * jnp.log(omega_b))


# -------------------------------------------------------------------------- angle branches


def channel_kinds(model) -> tuple[np.ndarray, np.ndarray]:
    """Static channel layout: `(euler [C] bool, expmap [K, 3] int)` from the model's
    `channel_names`: rotation channels that are not part of an exponential map are Euler
    angles; `J.expmap0..2` triples are rotation vectors; `root.*` channels (and every channel
    of a model without names) are neither."""
    names = tuple(getattr(model, "channel_names", ()))
    if not names:
        return np.zeros(model.offset.shape[-1], bool), np.zeros((0, 3), int)
    index = {name: i for i, name in enumerate(names)}
    triples = []
    for name in names:
        if name.endswith(".expmap0"):
            joint = name[: -len(".expmap0")]
            idx = [index.get(f"{joint}.expmap{k}") for k in range(3)]
            if None not in idx:
                triples.append(idx)
    triples = np.asarray(triples, int).reshape(-1, 3)
    euler = np.asarray(angle_channel_mask(names), bool)
    euler[triples.ravel()] = False
    return euler, triples


def turns(d: Array) -> Array:
    """The whole turns `2πk` in `d`, so that `d − turns(d)` is `wrap_angle(d)`; exactly
    `d` when `|d| < π` (no rounding, bit for bit), and no gradient."""
    return jax.lax.stop_gradient(2 * jnp.pi * jnp.round(d / (2 * jnp.pi)))


def on_branch_of(a, b):
    """`b` with its angle offsets moved onto `a`'s branch (same rotations, same motion).

    Euler channels: `b.offset − 2πk` within π of a's offset (`a + wrap(b − a)`), which
    shifts b's whole signal by whole turns. Exponential-map triples: the turn `k` of the
    equivalent rotation vector nearest a's offset (`nearest_rotation_vector`), applied to b's
    synthesized cycle sample by sample (`r − 2πk r/|r|`, 32 phases or 8 per harmonic) and
    projected back onto b's harmonics: the rotations stay the same up to the harmonics above
    b's that the change creates (a change of branch is not band-limited). Root
    channels and tangent models are left alone. Works for a stacked `b` against one `a` by broadcasting.
    """
    if getattr(a, "representation", "") == "tangent":
        return b  # tangent coordinates are about each model's own clip means: no branch
    euler, triples = channel_kinds(a)
    if not euler.any() and not triples.size:
        return b
    offset = b.offset
    if euler.any():
        mask = jnp.broadcast_to(jnp.asarray(euler), offset.shape)
        offset = offset - jnp.where(mask, turns(offset - a.offset), 0.0)
    if not triples.size:
        return replace(b, offset=offset)
    idx = jnp.asarray(triples)
    v = offset[..., idx]  # [..., K, 3]
    _, g = nearest_rotation_vector(jnp.broadcast_to(a.offset[..., idx], v.shape), v)
    # The branch change r -> r - 2πk r/|r| is applied to the synthesized cycle, sample by
    # sample, and the result projected back onto the model's harmonics (a DFT of the samples).
    # Mapping the harmonics through the Jacobian at the offset alone (first order) is not
    # enough near |r| = π, where Bandai's thighs sit: the factor 1 - 2πk/|r| changes by
    # 2πk δ/|r|² along a swing δ, and a transfer rebuilt on the other branch moved its toes 5 %
    # faster than the transfer itself (`docs/findings.md`, section 3b).
    c = phasor(b)[..., idx, :, :]  # [..., K, 3, N, 2]
    n_h = c.shape[-2]
    num = max(32, 8 * n_h)
    theta = jnp.arange(num, dtype=v.dtype) * (2 * jnp.pi / num)
    nt = jnp.arange(1, n_h + 1, dtype=v.dtype)[:, None] * theta[None, :]  # [N, M]
    # leading axes made explicit (strict rank promotion): [..., K, 3, N, M]
    sin, cos = (t.reshape((1,) * (c.ndim - 2) + t.shape) for t in (jnp.sin(nt), jnp.cos(nt)))
    # broadcast sums, not einsum (nested-vmap XLA CPU trap, STYLE.md)
    x = v[..., None] + jnp.sum(c[..., 0, None] * sin + c[..., 1, None] * cos, axis=-2)  # [..., K, 3, M]
    x2 = jnp.sum(x * x, axis=-2, keepdims=True)  # [..., K, 1, M]
    # Shim to avoid NaNs in jnp.where branches (x/|x| at 0), which cause failures for AD.
    small = x2 < _TINY
    turns_k = jax.lax.stop_gradient(jnp.round(g * jnp.sqrt(jnp.sum(v * v, axis=-1)) / (2 * jnp.pi)))
    scale = jnp.where(small, 0.0, 2 * jnp.pi * turns_k[..., None, None] / jnp.sqrt(jnp.where(small, 1.0, x2)))
    y = x - scale * x  # [..., K, 3, M]
    projected = jnp.mean(y, axis=-1)
    y = y[..., None, :]  # [..., K, 3, 1, M]
    c_moved = jnp.stack([jnp.sum(y * sin, axis=-1), jnp.sum(y * cos, axis=-1)], axis=-1) * (2.0 / num)
    keep_offset = (g == 0)[..., None]
    offset = offset.at[..., idx].set(jnp.where(keep_offset, v, projected))
    amplitude_new, phase_new = polar_from_phasor(c_moved)
    keep = (g[..., None, None] == 0) & jnp.ones_like(amplitude_new, dtype=bool)
    amplitude = b.amplitude.at[..., idx, :].set(jnp.where(keep, b.amplitude[..., idx, :], amplitude_new))
    phase = b.phase.at[..., idx, :].set(jnp.where(keep, b.phase[..., idx, :], phase_new))
    return replace(b, offset=offset, amplitude=amplitude, phase=phase)
