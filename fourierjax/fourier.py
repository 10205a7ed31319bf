"""Fourier gait models (Unuma 1995 eq. 1; Tilmanne & Dutoit eq. 1-6): model, synthesis, fits, ω.

Contract (for `fourierjax.style` and other users)
------------------------------------------------
``FourierModel(offset[C], amplitude[C, N], phase[C, N], omega[], representation, channel_names)``
is an all-leaves equinox Module (``representation`` and ``channel_names`` are static). Per channel
``c`` it is Unuma's rescaled Fourier functional model (eq. 1, sine convention)::

    x_c(theta) = offset[c] + sum_n amplitude[c, n-1] * sin(n * theta + phase[c, n-1])
    theta = omega * t_s                        (phase of the gait cycle, radians)

with ``amplitude >= 0``, ``phase`` in ``(-pi, pi]`` and ``omega`` the fundamental in rad/s (one
gait cycle = two steps). Stack models with ``jax.tree.map(lambda *x: jnp.stack(x), *models)``
(same static fields) and vmap: ``jax.vmap(synthesize, in_axes=(0, None))(models, t_s)``.

* ``synthesize(model, t_s[T]) -> [T, C]``, ``synthesize_phase(model, phase[T]) -> [T, C]``.
* ``synthesize_batch(models, t_s[T] or [B, T]) -> [B, T, C]``: that vmap, equal to float32
  round-off and faster: one elementwise loop over the output (channels innermost) with a stored
  basis of one sin/cos per character and frame and the harmonic recurrence, at about the speed
  of writing the output at 1024 characters (see the notes above ``_store``).
* ``model.sin_cos() -> (a[C, N], b[C, N])`` with ``x = offset + sum a sin(n th) + b cos(n th)``
  (the linear coordinates: PCA and averaging belong here); ``FourierModel.from_sin_cos(...)``.
* ``model.to_cosine() -> (offset, amplitude, phase_cos)``: Tilmanne eq. 1,
  ``x = p0 + sum p_n cos(n th + phase_cos_n)``, ``phase_cos = wrap(phase - pi/2)``.
* ``model.style_vector(convention="sine") -> [C * (2N + 1) + 1]``: per channel
  ``(A0, A1, phi1, ..., AN, phiN)`` then ``omega`` (Tilmanne: 54 x 5 + 1 = 271).
  ``FourierModel.from_style_vector(v, num_channels, num_harmonics, ...)`` inverts it.
* ``shift_phase(model, delta) -> model`` with ``x'(theta) = x(theta + delta)``
  (``phase_n += n * delta``); fitted models are aligned so that theta = 0 is the canonical gait
  event (left heel strike; see ``align_to_events`` / ``channel_event_phase``).

Channels (built by ``fourierjax.motion.features_from_motion``) are joint rotations in radians,
either the file's Euler angles (``"LeftUpLeg.Xrotation"``, unwrapped over time and repaired at
gimbal flips) or the continuous exponential map (``"LeftUpLeg.expmap0..2"``), plus three root
channels: ``"root.vx"``, ``"root.vz"`` (horizontal root velocity in file units per second,
expressed in the heading frame: +z forward, +x left of the walker's heading) and ``"root.y"``
(root height, file units). The root's own rotation channels hold its orientation relative to the
heading frame and are treated like any joint. Root position is never a channel: it is integrated
from the velocity channels when a motion is written back. The heading frame is fixed per fitted
stretch (the circular mean of the root's facing direction), so a synthesized motion walks
straight along +Z.

Fitting (``fit``): for a fixed ω the coefficients are a closed-form linear least-squares solve
(one small (2N+1)x(2N+1) Gram matrix shared by all channels, solved by Gauss-Jordan elimination
in plain jnp: batched LAPACK calls hang on 2-core CPUs). ω itself is found by variable projection
(the residual with the coefficients solved exactly inside): a grid then a golden-section search
around the spectral (or step-based) estimate. Clips of different lengths are batched by padding
at the end and a frame mask. Compile time is watched as closely as run time: every solve of a
fit (guard, grid, golden section, final coefficients) is one step of a single loop around one
traced solve, so the whole fit is one XLA program of ~60 kernels (~2-3 s to compile on 2 cores).
"""

from __future__ import annotations

import math
import operator

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Bool, Float, Int

from fourierjax import _jit
from fourierjax._checks import integer
from fourierjax._linalg import matmul as _mm
from fourierjax._linalg import spd_solve as _spd_solve
from fourierjax._sincos import sincos as _sincos
from fourierjax.errors import UserError

REPRESENTATIONS = ("euler", "expmap")
ROOT_CHANNELS = ("root.vx", "root.vz", "root.y")

__all__ = [
    "REPRESENTATIONS",
    "ROOT_CHANNELS",
    "FourierModel",
    "FitResult",
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


def wrap_angle(x: Array) -> Array:
    """Wrap angles (radians) to ``(-pi, pi]``."""
    y = jnp.remainder(x + jnp.pi, 2 * jnp.pi) - jnp.pi  # [-pi, pi)
    return jnp.where(y <= -jnp.pi, y + 2 * jnp.pi, y)


def _safe_norm_atan2(a: Array, b: Array) -> tuple[Array, Array]:
    """(sqrt(a^2 + b^2), atan2(b, a)) with finite gradients at a = b = 0."""
    r2 = a * a + b * b
    small = r2 < 1e-30
    # Shim to avoid NaNs in jnp.where branches, which cause failures for reverse-mode AD.
    r2_safe = jnp.where(small, 1.0, r2)
    a_safe = jnp.where(small, 1.0, a)
    b_safe = jnp.where(small, 0.0, b)
    amplitude = jnp.where(small, 0.0, jnp.sqrt(r2_safe))
    phase = jnp.where(small, 0.0, jnp.arctan2(b_safe, a_safe))
    phase = jnp.where(phase <= -jnp.pi, phase + 2 * jnp.pi, phase)
    return amplitude, phase


# ---------------------------------------------------------------------------------- input checks
# Shape checks read static shapes only (free under jit, vmap and grad). Value checks run only on
# concrete inputs (a traced value cannot be read), and never in the synthesis hot paths, where
# reading a device array back to the host would be a sync per call.


def _is_traced(*values) -> bool:
    return any(isinstance(v, jax.core.Tracer) for v in values)


def _check_real(fn: str, name: str, value) -> float:
    """``value`` as a float (a static option: a real number, not NaN), else a UserError."""
    if isinstance(value, bool | np.bool_) or not isinstance(value, int | float | np.integer
                                                             | np.floating):
        raise UserError(f"{fn}: {name} must be a real number, got {value!r} "
                        f"({type(value).__name__})")
    if math.isnan(value):
        raise UserError(f"{fn}: {name} must be a real number, got NaN")
    return float(value)


def _check_representation(fn: str, representation) -> None:
    if representation not in REPRESENTATIONS:
        raise UserError(f"{fn}: representation {representation!r} not in {REPRESENTATIONS}")


def _check_frame_time(fn: str, frame_time_s) -> np.ndarray | None:
    """Frame times (scalar or array) must be positive and finite; skipped when traced.
    Returns them as a host array (None when traced)."""
    if _is_traced(frame_time_s):
        return None
    try:
        dt = np.asarray(frame_time_s, float)
    except (TypeError, ValueError):
        dt = np.asarray(np.nan)
    if not (np.isfinite(dt).all() and (dt > 0).all()):
        bad = int((~(np.isfinite(dt) & (dt > 0))).sum())
        got = dt.tolist() if dt.size <= 8 else f"{dt.size} values, {bad} of them bad"
        raise UserError(f"{fn}: frame_time_s must be positive seconds, got {got}")
    return dt


def _as_float_features(fn: str, features):
    """Real floating features: integer and bool samples are cast to the default float dtype
    (as ``fourierjax.rotations`` does); complex or non-numeric ones are a UserError."""
    dtype = np.dtype(features.dtype)
    if jnp.issubdtype(dtype, jnp.floating):
        return features
    if dtype == np.bool_ or jnp.issubdtype(dtype, jnp.integer):
        return features.astype(jnp.result_type(float))
    raise UserError(f"{fn}: features must be real numbers, got dtype {dtype}")


def _used_frames(mask) -> np.ndarray:
    """Frames a (concrete) mask uses, per clip: its nonzero entries along the last axis."""
    return np.sum(np.asarray(mask) != 0, axis=-1)


def _check_mask_values(fn: str, mask) -> None:
    """A concrete mask is booleans, or weights that are finite and >= 0."""
    m = np.asarray(mask)
    if m.dtype == np.bool_:
        return
    try:
        m = m.astype(float)
    except (TypeError, ValueError):
        raise UserError(f"{fn}: mask must be booleans, got dtype {m.dtype}") from None
    if not (np.isfinite(m).all() and (m >= 0).all()):
        raise UserError(f"{fn}: mask must be booleans (or finite weights >= 0); it holds "
                        f"{int((~(np.isfinite(m) & (m >= 0))).sum())} negative or NaN value(s)")


def _check_finite_used(fn: str, features, mask) -> None:
    """The frames a fit uses must be finite (frames left out by ``mask`` may hold NaN). A JAX
    array is read back to the host for this (zero-copy on CPU)."""
    bad = ~np.isfinite(np.asarray(features))
    if mask is not None:
        bad &= (np.asarray(mask) != 0)[..., None]
    if bad.any():
        first = tuple(int(i) for i in np.argwhere(bad)[0])
        raise UserError(
            f"{fn}: features hold {int(bad.sum())} NaN or infinite value(s) in frames the fit "
            f"uses, the first at index {first}; leave such frames out with mask="
        )


def _check_varies(fn: str, features, mask, channel_weights) -> None:
    """A clip whose weighted channels are all constant over the used frames has no fundamental
    frequency: the omega search would return an arbitrary value. Refused, naming the clip."""
    x = np.asarray(features)
    used = np.ones(x.shape[:-1], bool) if mask is None else np.broadcast_to(
        np.asarray(mask) != 0, x.shape[:-1])
    lo = np.where(used[..., None], x, np.inf).min(axis=-2)
    hi = np.where(used[..., None], x, -np.inf).max(axis=-2)
    varies = (hi - lo) > 1e-6 * (1.0 + np.maximum(np.abs(hi), np.abs(lo)))
    weighted = np.asarray(channel_weights, float) > 0
    flat = np.atleast_1d(~np.any(varies & weighted, axis=-1))
    if flat.any():
        i = int(np.flatnonzero(flat)[0])
        where = "" if x.ndim == 2 else f" in clip {i}" + (
            f" (and {int(flat.sum()) - 1} other clip(s))" if flat.sum() > 1 else "")
        raise UserError(
            f"{fn}: features are constant over the used frames on every weighted channel{where}: "
            "a motion that does not move has no fundamental frequency to fit; leave it out (or "
            "build its model directly: FourierModel with zero amplitudes)"
        )


def _check_one_model(fn: str, model) -> None:
    """One (unstacked) model: vmap over stacked ones (static shapes only)."""
    if model.offset.ndim != 1:
        raise UserError(
            f"{fn}: `model` must be one model (offset [C]), got offset shape "
            f"{model.offset.shape}; vmap over stacked models (or use synthesize_batch)"
        )


def _names_tuple(names):
    """`channel_names` as a tuple (a static field must be hashable) when given as a list, tuple
    or 1-D NumPy string array; anything else is left for `__check_init__` to refuse."""
    if isinstance(names, np.ndarray) and names.ndim == 1 and names.dtype.kind == "U":
        return tuple(str(n) for n in names)
    if isinstance(names, list | tuple):
        return tuple(names)
    return names


class FourierModel(eqx.Module):
    """Per-channel Fourier series with one fundamental (Unuma 1995 eq. 1, sine convention).

    Fields: ``offset [C]`` (A0), ``amplitude [C, N]`` (A_n >= 0), ``phase [C, N]`` (phi_n in
    (-pi, pi]), ``omega []`` (rad/s); static ``representation`` ("euler" | "expmap") and
    ``channel_names`` (tuple of str, empty or length C).
    """

    offset: Float[Array, " C"]
    amplitude: Float[Array, "C N"]
    phase: Float[Array, "C N"]
    omega: Float[Array, ""]
    representation: str = eqx.field(static=True, default="euler")
    channel_names: tuple[str, ...] = eqx.field(static=True, default=(), converter=_names_tuple)

    def __check_init__(self):
        off, amp, ph, om = (jnp.shape(x) for x in (self.offset, self.amplitude, self.phase,
                                                     self.omega))
        if len(amp) < 2 or amp != ph:
            raise UserError(
                f"FourierModel: amplitude {amp} and phase {ph} must both be [..., C, N]"
            )
        if off != amp[:-1]:
            raise UserError(f"FourierModel: offset {off} must be [..., C] with C = {amp[-2]}")
        if om != off[:-1]:
            raise UserError(f"FourierModel: omega {om} must be a scalar (per model)")
        if self.representation not in REPRESENTATIONS:
            raise UserError(
                f"FourierModel: representation {self.representation!r} not in {REPRESENTATIONS}"
            )
        names = self.channel_names
        if not isinstance(names, tuple) or not all(isinstance(n, str) for n in names):
            bad = names if not isinstance(names, tuple) else next(n for n in names if not isinstance(n, str))
            raise UserError(
                f"FourierModel: channel_names must be a sequence of str (or empty), got {bad!r}"
            )
        if self.channel_names and len(self.channel_names) != amp[-2]:
            raise UserError(
                f"FourierModel: {len(self.channel_names)} channel_names for {amp[-2]} channels"
            )

    @property
    def num_channels(self) -> int:
        return self.amplitude.shape[-2]

    @property
    def num_harmonics(self) -> int:
        return self.amplitude.shape[-1]

    @property
    def fundamental_hz(self) -> Array:
        return self.omega / (2 * jnp.pi)

    def sin_cos(self) -> tuple[Array, Array]:
        """Linear coordinates ``(a, b)`` [C, N]: ``x = A0 + sum a_n sin(n th) + b_n cos(n th)``."""
        return self.amplitude * jnp.cos(self.phase), self.amplitude * jnp.sin(self.phase)

    @classmethod
    def from_sin_cos(cls, offset, a, b, omega, representation="euler", channel_names=()):
        """Inverse of :meth:`sin_cos` (amplitudes made >= 0, phases in (-pi, pi])."""
        amplitude, phase = _safe_norm_atan2(jnp.asarray(a), jnp.asarray(b))
        return cls(jnp.asarray(offset), amplitude, phase, jnp.asarray(omega),
                   representation, tuple(channel_names))

    def to_cosine(self) -> tuple[Array, Array, Array]:
        """Tilmanne & Dutoit eq. 1 convention: ``x = p0 + sum p_n cos(n w t + phase_cos_n)``.

        Returns ``(offset [C], amplitude [C, N], phase_cos [C, N])``, ``phase_cos = phase - pi/2``
        wrapped to (-pi, pi].
        """
        return self.offset, self.amplitude, wrap_angle(self.phase - jnp.pi / 2)

    @classmethod
    def from_cosine(cls, offset, amplitude, phase_cos, omega, representation="euler",
                    channel_names=()):
        """Inverse of :meth:`to_cosine`."""
        return cls(jnp.asarray(offset), jnp.asarray(amplitude),
                   wrap_angle(jnp.asarray(phase_cos) + jnp.pi / 2), jnp.asarray(omega),
                   representation, tuple(channel_names))

    def style_vector(self, convention: str = "sine") -> Float[Array, " S"]:
        """Flat view ``[C * (2N + 1) + 1]``: per channel (A0, A1, phi1, ..., AN, phiN), then omega.

        ``convention="cosine"`` gives Tilmanne's phases (eq. 1; 54 x 5 + 1 = 271 numbers).
        """
        if convention not in ("sine", "cosine"):
            raise UserError(f"style_vector: convention {convention!r} not 'sine' or 'cosine'")
        amp = self.amplitude
        ph = wrap_angle(self.phase - jnp.pi / 2) if convention == "cosine" else self.phase
        pairs = jnp.stack([amp, ph], axis=-1).reshape(*amp.shape[:-1], -1)  # [C, 2N]
        per_channel = jnp.concatenate([self.offset[..., None], pairs], axis=-1)
        flat = per_channel.reshape(*per_channel.shape[:-2], -1)
        return jnp.concatenate([flat, self.omega[..., None]], axis=-1)

    @classmethod
    def from_style_vector(cls, vector, num_channels: int, num_harmonics: int,
                          representation="euler", channel_names=(), convention: str = "sine"):
        """Inverse of :meth:`style_vector` for one model (amplitudes/phases are canonicalised)."""
        vector = jnp.asarray(vector)
        expected = num_channels * (2 * num_harmonics + 1) + 1
        if vector.shape != (expected,):
            raise UserError(
                f"from_style_vector: vector shape {vector.shape}, expected ({expected},) for "
                f"{num_channels} channels x {num_harmonics} harmonics"
            )
        per_channel = vector[:-1].reshape(num_channels, 2 * num_harmonics + 1)
        offset = per_channel[:, 0]
        amp = per_channel[:, 1::2]
        ph = per_channel[:, 2::2]
        if convention == "cosine":
            ph = ph + jnp.pi / 2
        elif convention != "sine":
            raise UserError(f"from_style_vector: convention {convention!r} not 'sine' or 'cosine'")
        # Negative amplitudes (e.g. after PCA) are legal points: flip sign into the phase.
        a, b = amp * jnp.cos(ph), amp * jnp.sin(ph)
        return cls.from_sin_cos(offset, a, b, vector[-1], representation, channel_names)


def stack_models(models) -> FourierModel:
    """Stack models with identical static fields along a new leading axis (for vmap)."""
    return jax.tree.map(lambda *xs: jnp.stack(xs), *models)


# ----------------------------------------------------------------------------------- synthesis


def harmonic_basis(theta: Float[Array, " T"], num_harmonics: int) -> Float[Array, "T P"]:
    """Design matrix ``[1, sin(n th) (n=1..N), cos(n th) (n=1..N)]``, P = 2N + 1."""
    return _basis_rows(theta, num_harmonics).T


def _basis_rows(theta: Float[Array, " T"], num_harmonics: int) -> Float[Array, "P T"]:
    """``harmonic_basis(theta, N).T``: one row per basis function (the fit's fast layout)."""
    return _basis_rows_sc(jnp.sin(theta), jnp.cos(theta), num_harmonics)


def _basis_rows_sc(s1, c1, num_harmonics: int):
    """Basis rows ``[P, T]`` from ``sin(theta)``, ``cos(theta)`` by the angle-addition recurrence.

    Two trig calls per sample instead of 2N (XLA's CPU sin/cos dominate a fit's cost); as
    accurate as ``sin(n * theta)`` in float32 (both carry the rounding of theta times n). Pass
    materialised ``s1``, ``c1`` (loop-carried in the fit): XLA fuses producers into the stack
    and would recompute them for each of its 2N + 1 rows.
    """
    sin_n, cos_n = [s1], [c1]
    for _ in range(num_harmonics - 1):
        s, c = sin_n[-1], cos_n[-1]
        sin_n.append(s * c1 + c * s1)
        cos_n.append(c * c1 - s * s1)
    return jnp.stack([jnp.ones_like(s1), *sin_n, *cos_n], axis=0)


# Batched synthesis (`synthesize_batch`) is laid out for XLA:CPU (measured at 1024 characters x
# 57 channels x 240 frames, N = 3, on 2 cores; experiments/benchmarks/synthesis.py):
#
# * Under vmap, the [T, 2N] @ [2N, C] product of `synthesize_phase` becomes a batched
#   dot_general of 1024 tiny matrices, which XLA:CPU runs as a slow loop. The elementwise form
#   (`_synthesize_phase_elementwise`) is, under vmap, one loop over [B, T, C] with channels
#   innermost, the layout of the result, so it is written once, contiguously (LLVM vectorizes
#   it 8 channels at a time): per sample the offset plus 2N multiply-adds of a per-frame basis
#   value and a per-channel coefficient. It runs at about the speed of merely writing the output.
# * The basis sin(n theta), cos(n theta) is computed once per frame (one sin, one cos, then the
#   angle-addition recurrence over harmonics): O(B T) trig calls, not O(B T C). XLA fuses cheap
#   producers into every consumer, which would put the basis inside the output loop; dividing
#   by a runtime 1 (`_store`, the trick of `fourierjax.crowd`) makes each basis row and the
#   coefficient table "expensive" to XLA, so they are computed once and stored. The 1 is made
#   from the value itself (`1 + 0 * x`, which XLA does not fold for floats), so it has the
#   value's shape under any vmap: a 1 broadcast from a scalar would be rewritten into a cheap
#   multiplication and fused again. It changes speed only, never finite values or gradients.
# * `synthesize` itself keeps the product: callers compare jitted and eager synthesis bit for
#   bit, and the elementwise loop is fused (multiply-adds contracted) under jit but run op by op
#   when eager, which changes the last bit (about 1e-7 relative).


def _store(x: Array) -> Array:
    """``x / (1 + 0 * x)``: the value of ``x`` (for finite ``x``), computed once and stored.

    A division is too expensive for XLA to duplicate into each consumer, and ``1 + 0 * x`` is
    not folded (``0 * x`` is nan for infinite ``x``).
    """
    return x / (1.0 + 0.0 * x)


def _harmonic_rows(theta: Array, num_harmonics: int) -> list[Array]:
    """``[sin(n theta) for n = 1..N] + [cos(n theta) for n = 1..N]``, each stored once.

    One sine and cosine per sample (in float32 `fourierjax._sincos`: one shared range reduction,
    about 1 ulp for |theta| < 1e4 rad, 1.5 ms less than XLA's sin and cos at 1024 x 240; beyond
    that the float32 theta itself is off by more than 1e-3 rad), harmonics by the angle-addition
    recurrence (as accurate as ``sin(n * theta)`` in float32: both carry the rounding of theta).
    """
    s1, c1 = (_store(v) for v in _sincos(theta))
    sines, cosines = [s1], [c1]
    for _ in range(num_harmonics - 1):
        s, c = sines[-1], cosines[-1]
        sines.append(_store(s * c1 + c * s1))
        cosines.append(_store(c * c1 - s * s1))
    return sines[:num_harmonics] + cosines[:num_harmonics]


def synthesize_phase(model: FourierModel, phase: Float[Array, " T"]) -> Float[Array, "T C"]:
    """Evaluate the model at cycle phases ``phase`` (radians), Unuma 1995 eq. 1.

    Arguments:
        model: one FourierModel (vmap for several, or ``synthesize_batch``).
        phase: ``[T]`` cycle phase theta in radians (any values; 2 pi = one gait cycle).
    Returns:
        ``[T, C]`` channel values (radians for angle channels).
    Raises:
        UserError for a stacked ``model`` or a ``phase`` that is not 1-D (static shapes only).
    """
    _check_one_model("synthesize_phase", model)
    phase = jnp.asarray(phase, dtype=model.amplitude.dtype)
    if phase.ndim != 1:
        raise UserError(f"synthesize_phase: phase must be [T] (radians), got shape {phase.shape}")
    a, b = model.sin_cos()
    n = jnp.arange(1, model.num_harmonics + 1, dtype=phase.dtype)
    nt = phase[:, None] * n[None, :]  # T x N trig calls, not T x C x N
    # One [T, 2N] basis and one contraction (one character at a time; for many, the elementwise
    # form of `synthesize_batch` is faster under vmap).
    basis = jnp.concatenate([jnp.sin(nt), jnp.cos(nt)], axis=1)
    return model.offset[None, :] + _mm(basis, jnp.concatenate([a, b], axis=1).T)


def _synthesize_phase_elementwise(model: FourierModel, phase: Float[Array, " T"]) -> Float[Array, "T C"]:
    """``synthesize_phase`` as one elementwise loop over the output (fast under vmap)."""
    phase = jnp.asarray(phase, dtype=model.amplitude.dtype)
    a, b = model.sin_cos()  # [C, N]
    rows = _harmonic_rows(phase, model.num_harmonics)  # 2N x [T]
    coef = _store(jnp.concatenate([a.T, b.T], axis=0))  # [2N, C]: rows contiguous along channels
    out = model.offset[None, :]
    for k, row in enumerate(rows):
        out = out + row[:, None] * coef[k][None, :]
    return jnp.broadcast_to(out, (phase.shape[0], model.num_channels))


def synthesize(model: FourierModel, t_s: Float[Array, " T"]) -> Float[Array, "T C"]:
    """Evaluate the model at times ``t_s`` (seconds): ``synthesize_phase(model, omega * t_s)``.

    Arguments:
        model: one FourierModel (vmap for several, or ``synthesize_batch``).
        t_s: ``[T]`` times in seconds (any length and frame rate).
    Returns:
        ``[T, C]`` channel values.
    Raises:
        UserError for a stacked ``model`` or a ``t_s`` that is not 1-D (static shapes only).
    """
    _check_one_model("synthesize", model)
    t_s = jnp.asarray(t_s, dtype=model.amplitude.dtype)
    if t_s.ndim != 1:
        raise UserError(f"synthesize: t_s must be [T] (seconds), got shape {t_s.shape}")
    return synthesize_phase(model, model.omega * t_s)


def _synthesize_batch(offset, amplitude, phase, omega, t_s, dtype):
    models = FourierModel(*(jnp.asarray(x, dtype) for x in (offset, amplitude, phase, omega)))
    t_s = jnp.asarray(t_s, dtype)
    theta = models.omega[:, None] * (t_s if t_s.ndim == 2 else t_s[None, :])  # [B, T]
    # XLA:GPU runs the vmapped product well and fuses the elementwise form worse (measured on
    # an H100 at 1024 x 57 x 240: 54 G channel-samples/s against 18 G, 0.71 and 0.22 of the
    # output-write bound): the layout above is XLA:CPU's.
    form = _synthesize_phase_elementwise if jax.default_backend() == "cpu" else synthesize_phase
    return jax.vmap(form)(models, theta)


# Arrays, not the Module, through jit: filter_jit's pytree handling and a Module rebuild cost
# ~0.4 ms per call, more than the whole synthesis of a few characters.
_synthesize_batch_jit = _jit.jit(_synthesize_batch, static_argnames="dtype")


def synthesize_batch(models: FourierModel, t_s: Float[Array, "*B T"]) -> Float[Array, "B T C"]:
    """Evaluate ``B`` stacked models at shared (or per-character) times, Unuma 1995 eq. 1.

    Equal to ``jax.vmap(synthesize, in_axes=(0, None))(models, t_s)`` to float32 round-off, and
    about 2x faster on 2 CPU cores at 1024 x 57 x 240 (0.8 of the speed of merely writing the
    output, against 0.45 for the vmap): one elementwise loop over the ``[B, T, C]`` output with
    a basis of one sin and one cos per character and frame (harmonics by the angle-addition
    recurrence). On other backends it is that vmap, which XLA:GPU runs 3x faster than the
    elementwise loop. Jitted; differentiable in every model leaf and in ``t_s``; also fine
    inside jit, vmap and grad.

    Arguments:
        models: a FourierModel with a leading character axis (``stack_models``): offset
            ``[B, C]``, amplitude and phase ``[B, C, N]``, omega ``[B]`` (rad/s).
        t_s: ``[T]`` times in seconds shared by all characters, or ``[B, T]`` one row each.
    Returns:
        ``[B, T, C]`` channel values (radians for angle channels), in the models' dtype.
    Raises:
        UserError (a ValueError) naming ``models`` or ``t_s`` when the shapes do not fit.
    """
    if not isinstance(models, FourierModel):
        raise UserError(f"synthesize_batch: `models` must be a FourierModel, got {type(models).__name__}")
    if models.offset.ndim != 2:
        raise UserError(
            "synthesize_batch: `models` need exactly one leading character axis (stack_models): "
            f"offset [B, C], got offset shape {models.offset.shape}"
        )
    num_chars = models.offset.shape[0]
    shape = np.shape(t_s)
    if len(shape) not in (1, 2) or (len(shape) == 2 and shape[0] != num_chars):
        raise UserError(
            f"synthesize_batch: `t_s` must be [T] (shared) or [{num_chars}, T] (one row per "
            f"character), got shape {shape}"
        )
    dtype = jnp.result_type(models.offset, models.amplitude, models.phase, models.omega, float)
    return _synthesize_batch_jit(models.offset, models.amplitude, models.phase, models.omega, t_s,
                                 dtype=np.dtype(dtype).name)


# ------------------------------------------------------------------------------- linear solves


def _masked_mean(x: Float[Array, "T C"], w: Float[Array, " T"]) -> Float[Array, " C"]:
    return _mm(w, x) / jnp.maximum(jnp.sum(w), 1.0)


def _solve_coefficients(features, w, theta, num_harmonics, harmonics_on=None):
    """Least-squares coefficients ``[P, C]`` of centred data for the basis at phases theta.

    Returns ``(basis_rows [P, T], coef [P, C], rhs [P, C])`` (``rhs``: the normal equations'
    right-hand side). ``harmonics_on`` (``[N]`` of 0/1, optional) switches harmonics off: their
    basis rows are zeroed and their coefficients come out exactly 0, as if the basis had only
    the others (one traced solve serves fits with different numbers of harmonics).
    """
    return _solve_basis(features, w, _basis_rows(theta, num_harmonics), harmonics_on)


def _solve_basis(features, w, B, harmonics_on=None):
    """:func:`_solve_coefficients` for given basis rows ``B [P, T]``."""
    if harmonics_on is not None:
        on = jnp.concatenate([jnp.ones((1,), B.dtype), harmonics_on, harmonics_on])
        B = B * on[:, None]
    Bw = B * w[None, :]
    G = _mm(Bw, B.T)
    # Relative jitter: keeps the factorisation defined when a column vanishes (omega -> 0).
    eye = jnp.eye(G.shape[0], dtype=G.dtype)
    num_on = G.shape[0] if harmonics_on is None else jnp.sum(on)
    scale = jnp.trace(G) / num_on
    G = G + (10 * jnp.finfo(G.dtype).eps * scale + jnp.finfo(G.dtype).tiny) * eye
    if harmonics_on is not None:
        G = G + eye * (1 - on)[None, :]  # unit pivots for the switched-off columns
    rhs = _mm(Bw, features)
    coef = _spd_solve(G, rhs)
    return B, coef, rhs


def _model_arrays_from_coef(mean, coef, num_harmonics):
    N = num_harmonics
    a = coef[1 : N + 1].T  # [C, N] sine coefficients
    b = coef[N + 1 :].T  # [C, N] cosine coefficients
    amplitude, phase = _safe_norm_atan2(a, b)
    return mean + coef[0], amplitude, phase


def projected_residual(
    omega: Float[Array, ""],
    features: Float[Array, "T C"],
    t_s: Float[Array, " T"],
    num_harmonics: int,
    mask: Float[Array, " T"] | None = None,
    channel_weights: Float[Array, " C"] | None = None,
) -> Float[Array, ""]:
    """Variable-projection objective: weighted SSE of the best N-harmonic fit at ``omega``.

    ``sum_t mask_t sum_c w_c (x_tc - xhat_tc(omega))^2`` with the linear coefficients solved
    exactly for this omega (the objective whose minimiser is the nonlinear least-squares omega).
    """
    T, C = features.shape
    w = jnp.ones((T,), features.dtype) if mask is None else jnp.asarray(mask, features.dtype)
    cw = jnp.ones((C,), features.dtype) if channel_weights is None else channel_weights
    x = features - _masked_mean(features, w)[None, :]
    B, coef, _ = _solve_coefficients(x, w, omega * t_s, num_harmonics)
    r = x - _mm(B.T, coef)
    return jnp.sum(w[:, None] * cw[None, :] * r * r)


def fit_linear(
    features: Float[Array, "T C"],
    t_s: Float[Array, " T"],
    omega: Float[Array, ""],
    num_harmonics: int,
    mask: Bool[Array, " T"] | None = None,
    representation: str = "euler",
    channel_names: tuple[str, ...] = (),
) -> FourierModel:
    """Closed-form least-squares Fourier coefficients for a fixed fundamental.

    Minimises ``sum_t mask_t |x_t - model(omega t_t)|^2`` per channel; the frames need not span
    a whole number of cycles (a plain projection, Tilmanne eq. 3-4, would need that).

    Arguments:
        features: ``[T, C]`` samples (frames left out by ``mask`` may hold NaN); t_s: ``[T]``
        sample times (s); omega: rad/s; num_harmonics: N (static); mask: ``[T]`` frames to
        use (default all; at least 2N + 1 of them).
    Returns:
        FourierModel with the given omega.
    Raises:
        UserError naming the argument for bad shapes, ``num_harmonics`` or ``representation``;
        and, for concrete (untraced) values, NaN in used frames, non-finite ``t_s`` or
        ``omega``, or fewer used frames than the 2N + 1 coefficients per channel.
    """
    fn = "fit_linear"
    num_harmonics = integer(num_harmonics, f"{fn}: num_harmonics", 1)
    _check_representation(fn, representation)
    features = _as_float_features(fn, _as_array(features))
    if features.ndim != 2:
        raise UserError(f"{fn}: features must be [T, C], got shape {features.shape}")
    T = features.shape[0]
    if np.shape(t_s) != (T,):
        raise UserError(f"{fn}: t_s shape {np.shape(t_s)}, expected ({T},) (one time per frame "
                        f"of features {features.shape})")
    if mask is not None and np.shape(mask) != (T,):
        raise UserError(f"{fn}: mask shape {np.shape(mask)}, expected ({T},)")
    if np.shape(omega) != ():
        raise UserError(f"{fn}: omega must be a scalar (rad/s), got shape {np.shape(omega)}")
    need = 2 * num_harmonics + 1
    if T < need:
        raise UserError(f"{fn}: features have {T} frame(s), fewer than the {need} coefficients "
                        f"per channel of {num_harmonics} harmonic(s) (2N + 1)")
    mask_host = None if mask is None or _is_traced(mask) else np.asarray(mask)
    if mask_host is not None:
        _check_mask_values(fn, mask_host)
        used = int(_used_frames(mask_host))
        if used < need:
            raise UserError(f"{fn}: mask leaves {used} used frame(s), fewer than the {need} "
                            f"coefficients per channel of {num_harmonics} harmonic(s) (2N + 1)")
    if not _is_traced(features, mask):
        _check_finite_used(fn, features, mask_host)
    if not _is_traced(t_s) and not np.isfinite(np.asarray(t_s, float)).all():
        raise UserError(f"{fn}: t_s holds NaN or infinite times")
    if not _is_traced(omega) and not np.isfinite(float(omega)):
        raise UserError(f"{fn}: omega must be finite (rad/s), got {float(omega)}")
    features = jnp.asarray(features)
    w = jnp.ones((T,), features.dtype) if mask is None else jnp.asarray(mask, features.dtype)
    if mask is not None:
        # Frames left out may hold NaN (as in `fit`): 0 * NaN would poison the weighted sums.
        features = jnp.where(w[:, None] > 0, features, jnp.zeros((), features.dtype))
    mean = _masked_mean(features, w)
    omega = jnp.asarray(omega, features.dtype)
    _, coef, _ = _solve_coefficients(features - mean[None, :], w, omega * jnp.asarray(t_s),
                                     num_harmonics)
    offset, amplitude, phase = _model_arrays_from_coef(mean, coef, num_harmonics)
    return FourierModel(offset, amplitude, phase, omega, representation, tuple(channel_names))


# -------------------------------------------------------------------------- fundamental frequency


def spectral_omega(
    features: Float[Array, "T C"],
    frame_time_s: Float[Array, ""],
    mask: Bool[Array, " T"] | None = None,
    channel_weights: Float[Array, " C"] | None = None,
    f_min_hz: float = 0.4,
    f_max_hz: float = 3.0,
    pad_factor: int = 8,
) -> tuple[Float[Array, ""], Float[Array, " K"], Float[Array, " K"]]:
    """Fundamental from the power spectrum summed over channels, refined below one bin.

    Each channel is centred, Hann-windowed over the span of its used frames (first to last;
    frames left out inside the span count as zeros), zero-padded ``pad_factor``x and transformed; the weighted power
    spectra are summed (Tilmanne Fig. 1) and the highest peak in ``[f_min_hz, f_max_hz]`` is
    refined by a parabola through the log power of its three bins.

    Returns:
        ``(omega [rad/s], freqs_hz [K], power [K])``.
    Raises:
        UserError for features not ``[T, C]``, bad ``mask`` / ``channel_weights`` shapes, an
        empty band, ``pad_factor < 1`` or (when concrete) a ``frame_time_s`` that is not
        positive and finite.
    """
    fn = "spectral_omega"
    if np.ndim(features) != 2:
        raise UserError(f"{fn}: features must be [T, C], got shape {np.shape(features)}")
    features = jnp.asarray(features)
    T, C = features.shape
    if mask is not None and np.shape(mask) != (T,):
        raise UserError(f"{fn}: mask shape {np.shape(mask)}, expected ({T},)")
    if channel_weights is not None and np.shape(channel_weights) != (C,):
        raise UserError(f"{fn}: channel_weights shape {np.shape(channel_weights)}, expected "
                        f"({C},)")
    if not _is_traced(f_min_hz, f_max_hz) and not f_min_hz < f_max_hz:
        raise UserError(f"{fn}: the band f_min_hz={f_min_hz} .. f_max_hz={f_max_hz} Hz is empty")
    pad_factor = integer(pad_factor, f"{fn}: pad_factor", 1)
    _check_frame_time(fn, frame_time_s)
    w = jnp.ones((T,), features.dtype) if mask is None else jnp.asarray(mask, features.dtype)
    cw = jnp.ones((C,), features.dtype) if channel_weights is None else channel_weights
    # The window spans the used frames, first to last: a mask that leaves out the start of a
    # clip was windowed from frame 0, which put the taper's peak on unused frames.
    k = jnp.arange(T, dtype=features.dtype)
    first, last = (i.astype(features.dtype) for i in _used_range(w > 0, jnp))
    hann = 0.5 - 0.5 * jnp.cos(2 * jnp.pi * (k - first) / jnp.maximum(last - first, 1.0))
    win = hann * w
    x = (features - _masked_mean(features, w)[None, :]) * win[:, None]
    nfft = int(2 ** math.ceil(math.log2(max(T, 2) * pad_factor)))
    spec = jnp.fft.rfft(x, n=nfft, axis=0)
    power = _mm(jnp.abs(spec) ** 2, cw)
    # In the features' dtype: rfftfreq is float64 under jax_enable_x64 whatever the data.
    freqs = jnp.fft.rfftfreq(nfft, d=1.0).astype(features.dtype) / frame_time_s
    band = (freqs >= f_min_hz) & (freqs <= f_max_hz)
    i = jnp.argmax(jnp.where(band, power, -jnp.inf))
    i = jnp.clip(i, 1, power.shape[0] - 2)
    lp = jnp.log(jnp.maximum(power[jnp.stack([i - 1, i, i + 1])], 1e-30))
    denom = lp[0] - 2 * lp[1] + lp[2]
    delta = jnp.where(denom < 0, 0.5 * (lp[0] - lp[2]) / jnp.where(denom < 0, denom, -1.0), 0.0)
    f_peak = (i + jnp.clip(delta, -0.5, 0.5)) * (freqs[1] - freqs[0])
    return 2 * jnp.pi * f_peak, freqs, power


def _odd_energy_fraction(coef, cw):
    """Fraction of the (weighted) harmonic energy in odd harmonics, from coefficients [P, C]."""
    N = (coef.shape[0] - 1) // 2
    e = _mm(coef[1 : N + 1] ** 2 + coef[N + 1 :] ** 2, cw)  # [N]
    odd = (jnp.arange(1, N + 1) % 2) == 1
    return jnp.sum(jnp.where(odd, e, 0.0)) / jnp.maximum(jnp.sum(e), 1e-30)


class FitResult(eqx.Module):
    """Outcome of :func:`fit` for one clip (all leaves; a batched fit has a leading axis).

    ``model`` is the fitted model (omega = ``omega_fit``), before phase alignment; the ω
    estimates are rad/s: ``omega_spectral`` (a), ``omega_steps`` (b; NaN if no step events were
    given), ``omega_guess`` (the candidate after the subharmonic guard), ``omega_fit`` (c;
    variable projection). Metrics cover the masked frames: ``rms`` per channel (channel units),
    ``rms_deg`` (angle channels), ``variance_explained_angles``; ``num_frames`` used.
    """

    model: FourierModel
    omega_spectral: Float[Array, ""]
    omega_steps: Float[Array, ""]
    omega_guess: Float[Array, ""]
    omega_fit: Float[Array, ""]
    rms: Float[Array, " C"]
    rms_deg: Float[Array, ""]
    variance_explained_angles: Float[Array, ""]
    num_frames: Int[Array, ""]


_INVPHI = (math.sqrt(5) - 1) / 2


def _golden_start(lo, hi):
    """Golden-section state ``(a, b, c, d, f(c), f(d))`` on ``[lo, hi]``, nothing evaluated yet."""
    inf = jnp.full_like(lo, jnp.inf)
    return lo, hi, hi - _INVPHI * (hi - lo), lo + _INVPHI * (hi - lo), inf, inf


def _golden_shrunk(state):
    """The bracket after one shrink: around the smaller of ``f(c)``, ``f(d)``."""
    a, b, c, d, fc, fd = state
    left = fc < fd  # minimum in [a, d]
    a2 = jnp.where(left, a, c)
    b2 = jnp.where(left, d, b)
    # Reuse one interior point; the other is new.
    c2 = jnp.where(left, b2 - _INVPHI * (b2 - a2), d)
    d2 = jnp.where(left, c, a2 + _INVPHI * (b2 - a2))
    return left, (a2, b2, c2, d2)


def _golden_point(g, state):
    """Where golden-section step ``g`` evaluates: steps 0 and 1 the initial interior points,
    later steps the new point of the shrunk bracket."""
    _, _, c, d, _, _ = state
    left, (_, _, c2, d2) = _golden_shrunk(state)
    return jnp.where(g == 0, c, jnp.where(g == 1, d, jnp.where(left, c2, d2)))


def _golden_update(g, state, fx):
    """State after step ``g`` evaluated ``fx = f(_golden_point(g, state))``."""
    a, b, c, d, fc, fd = state
    left, shrunk = _golden_shrunk(state)
    shrink = g >= 2
    fc2 = jnp.where(shrink, jnp.where(left, fx, fd), jnp.where(g == 0, fx, fc))
    fd2 = jnp.where(shrink, jnp.where(left, fc, fx), jnp.where(g == 1, fx, fd))
    new = tuple(jnp.where(shrink, n, o) for n, o in zip(shrunk, (a, b, c, d), strict=True))
    return (*new, fc2, fd2)


def _golden_iterations_needed(golden_iterations, search_halfwidth, grid_points, dtype):
    """``golden_iterations``, capped where the bracket is already below the dtype's resolution.

    The golden section starts on two grid cells, ``4 log1p(h) / (grid_points - 1)`` of ω, and
    shrinks by 1/φ per step whatever the data: past ``eps`` of ω its points are neighbouring
    floats and further steps only re-evaluate them (float32: 28 of the default 40 steps).
    """
    width = 4 * math.log1p(search_halfwidth) / max(grid_points - 1, 1)
    eps = float(jnp.finfo(dtype).eps)
    needed = math.ceil(math.log(max(width / eps, 1.0)) / math.log(1 / _INVPHI)) + 1
    return max(0, min(golden_iterations, needed))


def _golden_best(state):
    a, b, c, d, fc, fd = state
    return jnp.where(fc < fd, c, d)


def _omega_guess(omega_spec, omega_steps, odd_half, odd_full, duration, odd_threshold):
    """Subharmonic / harmonic guard: the candidate ω around which variable projection searches.

    A gait cycle is two steps; the N-harmonic model at w/2 contains the one at w, so residuals
    alone prefer subharmonics. With step events the candidate (w/2, w, 2w) closest to
    1 / (2 mean step) wins; without them, w/2 wins only if its odd harmonics carry real energy
    (> odd_threshold of the harmonic energy, and the clip holds >= 2 of its cycles), 2w wins if
    the odd harmonics of w are nearly empty.
    """
    cands = jnp.stack([omega_spec / 2, omega_spec, omega_spec * 2])
    steps_safe = jnp.where(jnp.isfinite(omega_steps), omega_steps, 1.0)
    log_err = jnp.abs(jnp.log(cands / steps_safe))
    by_steps = cands[jnp.argmin(log_err)]
    # Steps within 25% of a candidate pick it (the spectral value is the more precise one).
    have_steps = jnp.isfinite(omega_steps) & (jnp.min(log_err) < jnp.log(1.25))
    half_ok = duration * omega_spec / 2 / (2 * jnp.pi) >= 2.0
    by_energy = jnp.where(
        half_ok & (odd_half > odd_threshold),
        omega_spec / 2,
        jnp.where(odd_full < odd_threshold / 4, omega_spec * 2, omega_spec),
    )
    # Step events that match no spectral candidate mean the spectrum is dominated by drift or
    # style (a spectral peak below the gait band's content): the steps themselves are the guess.
    return jnp.where(have_steps, by_steps,
                     jnp.where(jnp.isfinite(omega_steps), omega_steps, by_energy))


def _fit_arrays(features, mask, frame_time_s, omega_steps, channel_weights, num_harmonics,
                f_min_hz, f_max_hz, search_halfwidth, grid_points, golden_iterations,
                odd_threshold):
    """Numeric core of :func:`fit` for one clip (plain arrays in and out).

    Every linear solve of the fit (2 for the subharmonic guard, ``grid_points`` for the grid,
    ``golden_iterations + 2`` for the golden section, 1 for the final coefficients) is one step
    of a single ``fori_loop`` around one call of ``_solve_basis``: the solve is traced and
    compiled once instead of once per stage (compile time ~2.5x lower, the same evaluation
    points; golden steps past the dtype's resolution are skipped, see
    ``_golden_iterations_needed``).
    """
    dtype = features.dtype
    T, C = features.shape
    N, G = num_harmonics, grid_points
    w = jnp.asarray(mask, dtype)
    # Frames left out may hold anything (NaN for missing markers): 0 * NaN would still poison
    # every weighted sum, so they are zeroed first.
    features = jnp.where(w[:, None] > 0, features, jnp.zeros((), dtype))
    t_s = jnp.arange(T, dtype=dtype) * frame_time_s
    n_valid = jnp.sum(w)
    duration = n_valid * frame_time_s
    cw = channel_weights
    mean = _masked_mean(features, w)
    x = features - mean[None, :]

    omega_spec, _, _ = spectral_omega(features, frame_time_s, w, cw, f_min_hz, f_max_hz)
    # The search skips frequencies whose cycle is longer than the used frames can show
    # (`_omega_floor`): with many harmonics a period just past the clip fits too well.
    omega_floor = _omega_floor(w, frame_time_s)

    # The guard measures odd-harmonic energy with >= 2 harmonics; the search uses N. One basis
    # of nh harmonics serves both, the ones above N switched off in the search (N = 1 only).
    nh = max(N, 2)
    search_on = None if nh == N else (jnp.arange(1, nh + 1) <= N).astype(dtype)

    # Grid over [guess / (1 + h), guess * (1 + h)] (log spaced), then golden section in the
    # best cell (40 golden steps shrink it 1e-8-fold; no autodiff, so compiling stays fast).
    ratios = jnp.exp(jnp.linspace(-jnp.log1p(search_halfwidth), jnp.log1p(search_halfwidth),
                                  G, dtype=dtype))
    # Loop steps: 0, 1 guard; 2 .. 2+G-1 grid; g0 .. g0+I+1 golden section; last: final fit.
    g0 = 2 + G
    last = g0 + _golden_iterations_needed(golden_iterations, search_halfwidth, G, dtype) + 2
    zero = jnp.zeros((), dtype)
    P = 2 * nh + 1

    xwx = _mm(w, x * x)  # [C]
    xt = x.T

    def solve(k, sin_cos, guard):
        on = search_on
        if on is not None:
            on = jnp.where(guard, jnp.ones_like(on), on)
        B, coef, rhs = _solve_basis(x, w, _basis_rows_sc(*sin_cos, nh), on)

        # The grid only ranks cells 2% apart: x'Wx - rhs'coef (cancels, to ~1e-6 of x'Wx in
        # float32) is enough and saves a [T, C] residual. The golden section and the final fit
        # need the exact residual near the minimum. `k` is not batched under vmap, so this is
        # a real branch (both sides are not computed).
        def residual_sse(_):
            r = xt - _mm(coef.T, B)  # [C, T]: this layout's matmul is 3x faster than [T, P] @ [P, C]
            return _mm(r * r, w)

        def projected_sse(_):
            return xwx - jnp.sum(rhs * coef, axis=0)

        sse_c = jax.lax.cond(k >= g0, residual_sse, projected_sse, None)  # [C]
        return _mm(sse_c, cw), coef, sse_c

    def next_omega(k, odd, values, golden):
        """ω of step k (and the golden state, its bracket set when the golden phase starts)."""
        guess = _omega_guess(omega_spec, omega_steps, odd[0], odd[1], duration, odd_threshold)
        grid = guess * ratios
        j = jnp.argmin(values)
        start = _golden_start(grid[jnp.maximum(j - 1, 0)], grid[jnp.minimum(j + 1, G - 1)])
        golden = jax.tree.map(lambda s0, s: jnp.where(k == g0, s0, s), start, golden)
        om = jnp.where(
            k < 2, jnp.where(k == 0, omega_spec / 2, omega_spec),
            jnp.where(k < g0, grid[jnp.clip(k - 2, 0, G - 1)],
                      jnp.where(k < last, _golden_point(k - g0, golden), _golden_best(golden))))
        return om, golden

    def sin_cos_at(om):
        theta = om * t_s
        return jnp.sin(theta), jnp.cos(theta)

    def body(k, state):
        # The step's ω and sin/cos(ω t) come in the carry, computed at the end of the step
        # before: a loop carry is materialised, so XLA cannot fuse the ω bookkeeping and the
        # trig calls into every row of the basis (4x slower steps).
        om, sin_cos, odd, values, golden, coef_fit, sse_fit = state
        golden = tuple(golden)  # carried stacked: one small kernel instead of six
        fx, coef, sse_c = solve(k, sin_cos, k < 2)
        # Below the floor the search ranks nothing, if its guess lies above (a guess below
        # it sees less than a cycle itself: the fit is left alone and `_check_cycles` refuses).
        guess = _omega_guess(omega_spec, omega_steps, odd[0], odd[1], duration, odd_threshold)
        floor = jnp.where(guess >= omega_floor, omega_floor, zero)
        fx = jnp.where((k < 2) | (om >= floor), fx, jnp.inf)  # the guard steps are not ranked
        in_golden = (k >= g0) & (k < last)
        golden = jax.tree.map(lambda n, o: jnp.where(in_golden, n, o),
                              _golden_update(k - g0, golden, fx), golden)
        odd = jnp.where(jnp.arange(2) == k, _odd_energy_fraction(coef, cw), odd)
        values = jnp.where(jnp.arange(G) == k - 2, fx, values)
        final = k == last
        om_next, golden = next_omega(k + 1, odd, values, golden)
        return (om_next, sin_cos_at(om_next), odd, values, jnp.stack(golden),
                jnp.where(final, coef, coef_fit), jnp.where(final, sse_c, sse_fit))

    init = (omega_spec / 2, sin_cos_at(omega_spec / 2), jnp.zeros((2,), dtype),
            jnp.full((G,), jnp.inf, dtype), jnp.stack(_golden_start(zero, zero)),
            jnp.zeros((P, C), dtype), jnp.zeros((C,), dtype))
    _, _, odd, _, golden, coef, sse_c = jax.lax.fori_loop(0, last + 1, body, init)
    golden = tuple(golden)
    om = _golden_best(golden)
    omega_guess = _omega_guess(omega_spec, omega_steps, odd[0], odd[1], duration, odd_threshold)
    if nh != N:  # drop the switched-off harmonic (its coefficients are exactly 0)
        keep = [0, *range(1, N + 1), *range(nh + 1, nh + N + 1)]
        coef = coef[jnp.asarray(keep)]

    offset, amplitude, phase = _model_arrays_from_coef(mean, coef, N)
    ms = sse_c / jnp.maximum(n_valid, 1.0)
    sst = xwx
    angle = cw > 0
    rms_deg = jnp.degrees(jnp.sqrt(jnp.sum(jnp.where(angle, ms, 0.0))
                                   / jnp.maximum(jnp.sum(angle), 1)))
    ve = 1.0 - jnp.sum(jnp.where(angle, ms * n_valid, 0.0)) / jnp.maximum(
        jnp.sum(jnp.where(angle, sst, 0.0)), 1e-30)
    return dict(offset=offset, amplitude=amplitude, phase=phase, omega=om,
                omega_spectral=omega_spec, omega_steps=omega_steps, omega_guess=omega_guess,
                rms=jnp.sqrt(ms), rms_deg=rms_deg, variance_explained_angles=ve,
                num_frames=n_valid.astype(jnp.int32))


_FIT_STATIC = ("num_harmonics", "f_min_hz", "f_max_hz", "search_halfwidth", "grid_points",
               "golden_iterations", "odd_threshold")


def _fit_batched_impl(features, mask, frame_time_s, omega_steps, channel_weights, **static):
    # Defaults, broadcasts and dtype casts happen here, inside the one compiled program: done
    # eagerly, each would compile a small XLA program of its own on the first call.
    Bn, T, C = features.shape
    dtype = features.dtype
    mask = jnp.ones((Bn, T), dtype) if mask is None else jnp.asarray(mask, dtype)
    frame_time_s = jnp.broadcast_to(jnp.asarray(frame_time_s, dtype), (Bn,))
    omega_steps = (jnp.full((Bn,), jnp.nan, dtype) if omega_steps is None
                   else jnp.broadcast_to(jnp.asarray(omega_steps, dtype), (Bn,)))
    cw = jnp.asarray(channel_weights, dtype)
    fn = lambda f, m, dt, os: _fit_arrays(f, m, dt, os, cw, **static)  # noqa: E731
    return jax.vmap(fn)(features, mask, frame_time_s, omega_steps)


def _fit_single_impl(features, mask, frame_time_s, omega_steps, channel_weights, **static):
    add = lambda v: None if v is None else jnp.asarray(v)[None]  # noqa: E731
    out = _fit_batched_impl(features[None], add(mask), add(frame_time_s), add(omega_steps),
                            channel_weights, **static)
    return jax.tree.map(lambda v: v[0], out)


# `_jit.jit`: the classic XLA:CPU emitters compile the fit ~1.5x faster at the same run time.
_fit_batched = _jit.jit(_fit_batched_impl, static_argnames=_FIT_STATIC)
_fit_single = _jit.jit(_fit_single_impl, static_argnames=_FIT_STATIC)


def _as_array(x):
    # numpy for host data: jit transfers it itself, while an eager `jnp.asarray` compiles a
    # small program of its own on a first call. JAX arrays (sharded ones too) pass through.
    return x if isinstance(x, jax.Array) else np.asarray(x)


def _default_channel_weights(channel_names, num_channels):
    # numpy, not jnp: a constant built eagerly by JAX would compile a program of its own.
    if not channel_names:
        return np.ones((num_channels,), np.float32)
    return np.asarray(angle_channel_mask(channel_names), np.float32)


def angle_channel_mask(channel_names: tuple[str, ...]) -> tuple[bool, ...]:
    """True for rotation channels, False for the root translation channels ``root.*``."""
    return tuple(not name.startswith("root.") for name in channel_names)


def fit_batch(
    features: Float[Array, "B T C"],
    frame_time_s: Float[Array, " B"],
    num_harmonics: int,
    *,
    mask: Bool[Array, "B T"] | None = None,
    omega_steps: Float[Array, " B"] | None = None,
    channel_weights: Float[Array, " C"] | None = None,
    representation: str = "euler",
    channel_names: tuple[str, ...] = (),
    f_min_hz: float = 0.4,
    f_max_hz: float = 3.0,
    search_halfwidth: float = 0.25,
    grid_points: int = 33,
    golden_iterations: int = 40,
    odd_threshold: float = 0.1,
) -> FitResult:
    """Fit many clips in one jit/vmap call: ω three ways and the coefficients.

    Clips of different lengths are padded at the end to a common ``T`` and flagged by ``mask``.
    Per clip: (a) spectral ω (:func:`spectral_omega`), (b) ω from step events if given
    (``omega_steps`` rad/s, NaN where unknown; Tilmanne §2.2: cycle = two steps), the
    subharmonic guard, then (c) the nonlinear least-squares ω by variable projection (grid,
    golden section on :func:`projected_residual`) and the closed-form coefficients.
    ``channel_weights`` weigh channels in the ω search (default: 1 for rotations, 0 for ``root.*``).
    Step-based ω picks ω_spectral / 2, ω_spectral or 2 ω_spectral when one lies within 25% of
    it, and is used itself otherwise (the spectrum is then dominated by drift or style);
    ``search_halfwidth`` is the relative half-width of the variable-projection search around the chosen candidate.
    ``golden_iterations`` is an upper bound: steps that would only re-evaluate neighbouring
    floats of ω are skipped (float32 with the defaults: 27 of 40). The search does not go
    below the ω whose cycle the used frames cover ``MIN_CYCLES`` (0.95) times (a period longer
    than the clip is not determined, and many harmonics fit it too well).

    One XLA program per call signature (shapes, dtype, whether ``mask`` / ``omega_steps`` are
    given, and the static options): batch sizes that differ compile separately, so pad batches
    to a few fixed sizes when fitting many differently sized sets.

    Returns:
        FitResult with a leading batch axis on every leaf.
    Raises:
        UserError naming the argument, before any work: features not ``[B, T, C]`` real numbers
        (integers are cast to float) with ``C >= 1`` and ``T >= 2N + 2``; ``num_harmonics``,
        ``grid_points`` (>= 2) or ``golden_iterations`` (>= 0) not integers; an unknown
        ``representation``; an empty band (``f_min_hz >= f_max_hz``, or ``f_min_hz`` at or
        above Nyquist); ``search_halfwidth <= 0``; bad shapes. For concrete (untraced) values
        also: ``frame_time_s`` not positive; a mask leaving a clip fewer than 2N + 2 frames
        (2N + 1 coefficients per channel, plus omega); NaN in used frames; a clip constant over
        its used frames on every weighted channel (no fundamental to fit); ``omega_steps`` not
        positive (NaN: unknown); ``channel_weights`` negative, NaN or all zero. After the
        fit: a clip whose used frames cover fewer than ``MIN_CYCLES`` cycles of its fitted
        fundamental, or whose fit ends on the search's floor (see above).
    """
    features = _as_array(features)
    if features.ndim != 3:
        raise UserError(f"fit_batch: features must be [B, T, C], got shape {features.shape}")
    return _run_fit(_fit_batched, "fit_batch", features, frame_time_s, num_harmonics, mask=mask,
                    omega_steps=omega_steps, channel_weights=channel_weights,
                    representation=representation, channel_names=channel_names, f_min_hz=f_min_hz,
                    f_max_hz=f_max_hz, search_halfwidth=search_halfwidth, grid_points=grid_points,
                    golden_iterations=golden_iterations, odd_threshold=odd_threshold)


def _check_fit_options(name, num_harmonics, representation, f_min_hz, f_max_hz, search_halfwidth,
                       grid_points, golden_iterations, odd_threshold) -> dict:
    """Checks of the static options of `fit` / `fit_batch` (before any work), naming the
    argument. Returns them normalised (Python ints and floats)."""
    num_harmonics = integer(num_harmonics, f"{name}: num_harmonics", 1)
    _check_representation(name, representation)
    f_min_hz = _check_real(name, "f_min_hz", f_min_hz)
    f_max_hz = _check_real(name, "f_max_hz", f_max_hz)
    if not (f_min_hz < f_max_hz and f_max_hz > 0):
        raise UserError(f"{name}: the search band f_min_hz={f_min_hz} .. f_max_hz={f_max_hz} Hz "
                        "is empty: expected f_min_hz < f_max_hz and f_max_hz > 0")
    search_halfwidth = _check_real(name, "search_halfwidth", search_halfwidth)
    if not (0 < search_halfwidth < math.inf):
        raise UserError(f"{name}: search_halfwidth must be a finite relative half-width > 0 "
                        f"(0.25: omega within [guess / 1.25, guess * 1.25]), got {search_halfwidth}")
    return dict(num_harmonics=num_harmonics, f_min_hz=f_min_hz, f_max_hz=f_max_hz,
                search_halfwidth=search_halfwidth,
                grid_points=integer(grid_points, f"{name}: grid_points", 2),
                golden_iterations=integer(golden_iterations, f"{name}: golden_iterations", 0),
                odd_threshold=_check_real(name, "odd_threshold", odd_threshold))


def _min_fit_frames(num_harmonics: int) -> int:
    """Frames a fit needs: 2N + 1 linear coefficients per channel, plus omega."""
    return 2 * num_harmonics + 2


def _check_fit_args(name, shape, num_harmonics, channel_names, mask, frame_time_s, omega_steps,
                    channel_weights):
    """Trace-time checks naming the argument (``shape``: ``[B, T, C]`` or ``[T, C]``).

    Returns ``(mask, frame_time_s, omega_steps, channel_weights)`` with Python scalars and lists
    made numpy arrays (JAX arrays, sharded ones included, pass through untouched).
    """
    batch, (T, C) = tuple(shape[:-2]), shape[-2:]
    if C == 0:
        raise UserError(f"{name}: features have no channels (shape {tuple(shape)})")
    need = _min_fit_frames(num_harmonics)
    if T < need:
        raise UserError(
            f"{name}: features have {T} frame(s), fewer than the {need} a fit of "
            f"{num_harmonics} harmonic(s) needs (2N + 1 coefficients per channel, plus omega)"
        )
    if channel_names and len(channel_names) != C:
        raise UserError(f"{name}: {len(channel_names)} channel_names for {C} channels")
    out = []
    for arg, value, expected, exact in (("mask", mask, (*batch, T), True),
                                         ("frame_time_s", frame_time_s, batch, False),
                                         ("omega_steps", omega_steps, batch, False),
                                         ("channel_weights", channel_weights, (C,), True)):
        if value is not None:
            value = _as_array(value)
        if value is not None and (np.shape(value) != expected if exact else
                                  not _broadcasts_to(np.shape(value), expected)):
            raise UserError(f"{name}: {arg} shape {np.shape(value)}, expected {expected}")
        out.append(value)
    return tuple(out)


def _check_fit_values(name, features, mask, frame_time_s, omega_steps, num_harmonics,
                      f_min_hz, channel_weights) -> None:
    """Value checks where the values are known (not traced), each skipped when its value is
    traced: frame times positive, with the band's f_min_hz below Nyquist; the mask booleans
    (or weights >= 0) leaving at least 2N + 2 frames per clip; the frames the fit uses finite
    (frames left out by ``mask`` may hold NaN) and not constant on every weighted channel;
    ``omega_steps`` positive or NaN (unknown). A JAX
    array is read back to the host for this (zero-copy on CPU; small arrays but ``features``)."""
    dt = _check_frame_time(name, frame_time_s)
    if dt is not None:
        nyquist = 0.5 / np.max(dt)
        if f_min_hz >= nyquist:
            raise UserError(f"{name}: f_min_hz={f_min_hz} is not below the Nyquist frequency "
                            f"{nyquist:g} Hz of frame_time_s: the search band holds no frequency")
    if mask is not None and not _is_traced(mask):
        mask = np.asarray(mask)  # read back once (JAX arrays: zero-copy on CPU)
        _check_mask_values(name, mask)
        used = np.atleast_1d(_used_frames(mask))
        need = _min_fit_frames(num_harmonics)
        few = np.flatnonzero(used < need)
        if few.size:
            i = int(few[0])
            where = "" if np.ndim(mask) == 1 else f" in clip {i}" + (
                f" (and {few.size - 1} other clip(s))" if few.size > 1 else "")
            raise UserError(
                f"{name}: mask leaves {int(used[i])} used frame(s){where}, fewer than the {need} "
                f"a fit of {num_harmonics} harmonic(s) needs (2N + 1 coefficients per channel, "
                "plus omega)"
            )
    if omega_steps is not None and not _is_traced(omega_steps):
        om = np.asarray(omega_steps, float)
        bad = ~(np.isnan(om) | (np.isfinite(om) & (om > 0)))
        if bad.any():
            raise UserError(
                f"{name}: omega_steps must be positive rad/s, or NaN where no step events are "
                f"known; got {float(om[bad].ravel()[0])}"
                + (f" at index {int(np.flatnonzero(bad.ravel())[0])}" if om.ndim else "")
            )
    if not _is_traced(features, mask):  # last: the checks that read all of the features
        _check_finite_used(name, features, mask)
        if not _is_traced(channel_weights):
            _check_varies(name, features, mask, channel_weights)


def _check_channel_weights(name, channel_weights, defaulted: bool) -> None:
    """Concrete channel weights must be finite, >= 0 and not all zero (they weigh the omega
    search: all zero, nothing drives it)."""
    if _is_traced(channel_weights):
        return
    try:
        cw = np.asarray(channel_weights, float)
    except (TypeError, ValueError):
        raise UserError(f"{name}: channel_weights must be real numbers, got dtype "
                        f"{np.asarray(channel_weights).dtype}") from None
    bad = ~(np.isfinite(cw) & (cw >= 0))
    if bad.any():
        i = int(np.flatnonzero(bad)[0])
        raise UserError(f"{name}: channel_weights must be finite and >= 0, got {float(cw[i])} for "
                        f"channel {i}")
    if not (cw > 0).any():
        hint = (" (by default only rotation channels are weighed, and every channel in "
                "channel_names is root.*: pass channel_weights=)") if defaulted else ""
        raise UserError(f"{name}: channel_weights are all zero, so no channel drives the omega "
                        f"search{hint}")


def _broadcasts_to(shape, target) -> bool:
    try:
        return np.broadcast_shapes(shape, target) == tuple(target)
    except ValueError:
        return False


def _fit_result(out, representation, channel_names) -> FitResult:
    model = FourierModel(out["offset"], out["amplitude"], out["phase"], out["omega"],
                         representation, tuple(channel_names))
    return FitResult(model, out["omega_spectral"], out["omega_steps"], out["omega_guess"],
                     out["omega"], out["rms"], out["rms_deg"],
                     out["variance_explained_angles"], out["num_frames"])


def fit(
    features: Float[Array, "T C"],
    frame_time_s: float,
    num_harmonics: int,
    *,
    mask: Bool[Array, " T"] | None = None,
    omega_steps: float | None = None,
    **kwargs,
) -> FitResult:
    """Fit one clip (``fit_batch`` with a batch of one; same arguments without the batch axis).

    Arguments:
        features: ``[T, C]`` channel samples (frame 0 at t = 0); frame_time_s: seconds;
        num_harmonics: N; mask: ``[T]`` frames to use; omega_steps: ω from step events (rad/s).
    Returns:
        FitResult (no batch axis).
    Raises:
        UserError naming the argument, as :func:`fit_batch`.
    """
    features = _as_array(features)
    if features.ndim != 2:
        raise UserError(f"fit: features must be [T, C], got shape {features.shape}")
    return _run_fit(_fit_single, "fit", features, frame_time_s, num_harmonics, mask=mask,
                    omega_steps=omega_steps, **kwargs)


def _run_fit(program, name, features, frame_time_s, num_harmonics, *, mask=None, omega_steps=None,
             channel_weights=None, representation="euler", channel_names=(), f_min_hz=0.4,
             f_max_hz=3.0, search_halfwidth=0.25, grid_points=33, golden_iterations=40,
             odd_threshold=0.1) -> FitResult:
    """Check the arguments of `fit` / `fit_batch` (`name`) and run its jitted `program`."""
    options = _check_fit_options(name, num_harmonics, representation, f_min_hz, f_max_hz,
                                 search_halfwidth, grid_points, golden_iterations, odd_threshold)
    num_harmonics = options["num_harmonics"]
    features = _as_float_features(name, features)
    mask, frame_time_s, omega_steps, channel_weights = _check_fit_args(
        name, features.shape, num_harmonics, channel_names, mask, frame_time_s, omega_steps,
        channel_weights)
    defaulted = channel_weights is None
    if defaulted:
        channel_weights = _default_channel_weights(channel_names, features.shape[-1])
    _check_channel_weights(name, channel_weights, defaulted)
    _check_fit_values(name, features, mask, frame_time_s, omega_steps, num_harmonics,
                      options["f_min_hz"], channel_weights)
    out = program(features, mask, frame_time_s, omega_steps, channel_weights, **options)
    result = _fit_result(out, representation, channel_names)
    _check_cycles(name, features.shape[-2], mask, frame_time_s, result.omega_fit)
    return result


#: Fewest cycles of its fitted fundamental a clip must cover. With less than one period in
#: view the period is not identified: a 0.9 Hz signal cut to 0.37 of a cycle was fitted at
#: 1.85 Hz with 0.9999 of the variance explained, and the first 0.5 s of 07_01 at 1.58 Hz
#: (0.93 for the whole clip). One whole cycle sampled without its repeated end frame covers
#: exactly 1; the 5% leeway is for a fitted omega a little off. Where the spectral / step guess
#: covers more, the least-squares search does not go below it (`_omega_floor`), and an answer on
#: that floor (within `_FLOOR_TOLERANCE`) is refused as well: the residual falls further below.
MIN_CYCLES = 0.95
_FLOOR_TOLERANCE = 1e-3


def _used_range(used, xp):
    """`(first, last)` index of the True frames of ``used`` along its last axis (NumPy or
    jax.numpy: ``xp``); for a mask that leaves frames out at either end."""
    return xp.argmax(used, axis=-1), used.shape[-1] - 1 - xp.argmax(used[..., ::-1], axis=-1)


def _omega_floor(w, frame_time_s):
    """Lowest ω the least-squares search ranks for a clip with frame weights ``w`` [T] (when its
    guess lies above): the one whose cycle the used frames (first to last) cover `MIN_CYCLES`
    times. An answer on this floor is a boundary, not a minimum: `_check_cycles` refuses it.

    Below it the fit is not identified, and with many harmonics it is also where the residual
    is smallest: measured on a benchmark clip (N = 7, 1.29 cycles of 4.06 rad/s in 2 s, five
    harmonics, drift and noise) the global minimum lay at 2.87 rad/s, 0.91 cycle, where the 7th
    harmonic meets the true 5th (SSE 2.41 against 2.83 at the true ω; scipy from the same guess
    finds 4.06).
    """
    first, last = _used_range(w > 0, jnp)
    span_s = (last - first + 1).astype(w.dtype) * frame_time_s
    return (2 * np.pi * MIN_CYCLES) / span_s


def _check_cycles(name, num_frames, mask, frame_time_s, omega) -> None:
    """Refuse fits whose clips cover fewer than `MIN_CYCLES` of their fitted fundamental: the
    span of used frames (first to last) times the frame time, times omega / 2 pi (concrete
    values only)."""
    if _is_traced(mask, frame_time_s, omega):
        return
    omega = np.asarray(omega, float)
    if mask is None:
        span = np.full(omega.shape, float(num_frames))
    else:
        first, last = _used_range(np.asarray(mask) > 0, np)
        span = (last - first + 1).astype(float)
    cycles = span * np.broadcast_to(np.asarray(frame_time_s, float), omega.shape) * omega / (2 * np.pi)
    short = np.flatnonzero(np.atleast_1d(cycles < MIN_CYCLES * (1 + _FLOOR_TOLERANCE)))
    if short.size:
        i = int(short[0])
        c, om = float(np.atleast_1d(cycles)[i]), float(np.atleast_1d(omega)[i])
        others = ", ".join(str(int(j)) for j in short[1:11]) + (", ..." if short.size > 11 else "")
        where = "" if omega.ndim == 0 else f" clip {i}" + (
            f" (and {short.size - 1} other clip(s): {others})" if short.size > 1 else "") + ":"
        if c < MIN_CYCLES:
            what = (f"the used frames cover {np.floor(c * 100) / 100:.2f} cycle(s) of the fitted fundamental "
                    f"({om / (2 * np.pi):.3f} Hz), fewer than {MIN_CYCLES}")
        else:
            what = (f"the least-squares fundamental ({om / (2 * np.pi):.3f} Hz) lies on the "
                    f"lowest frequency the used frames cover {MIN_CYCLES} times, and the "
                    "residual falls further below it")
        raise UserError(
            f"{name}:{where} {what}: with less than one period in view the frequency is not "
            "determined by the data; give a longer clip (at least one whole cycle)"
        )


# ---------------------------------------------------------------------------- phase alignment


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
    return wrap_angle(jnp.pi / 2 - model.phase[channel, 0])


# --------------------------------------------------------------------------------- metrics


def rms_error(
    model: FourierModel, features: Float[Array, "T C"], t_s: Float[Array, " T"],
    mask: Bool[Array, " T"] | None = None,
) -> Float[Array, " C"]:
    """Per-channel RMS of ``features - synthesize(model, t_s)`` over the masked frames.

    Raises:
        UserError when ``features`` is not ``[T, C]`` with the model's C, or ``t_s`` / ``mask``
        are not ``[T]`` (static shapes only).
    """
    fn = "rms_error"
    _check_one_model(fn, model)
    shape, C = np.shape(features), model.num_channels
    if len(shape) != 2 or shape[1] != C:
        raise UserError(f"{fn}: features shape {shape}, expected [T, {C}] (the model's "
                        f"{C} channel(s))")
    if np.shape(t_s) != shape[:1]:
        raise UserError(f"{fn}: t_s shape {np.shape(t_s)}, expected {shape[:1]} (one time per "
                        "frame of features)")
    if mask is not None and np.shape(mask) != shape[:1]:
        raise UserError(f"{fn}: mask shape {np.shape(mask)}, expected {shape[:1]}")
    r = jnp.asarray(features) - synthesize(model, t_s)
    w = jnp.ones(r.shape[:1], r.dtype) if mask is None else jnp.asarray(mask, r.dtype)
    return jnp.sqrt(_mm(w, r * r) / jnp.maximum(jnp.sum(w), 1.0))


def variance_explained(
    target: Float[Array, "T D"], approx: Float[Array, "T D"],
    mask: Bool[Array, " T"] | None = None,
) -> Float[Array, ""]:
    """``1 - sum |target - approx|^2 / sum |target - mean(target)|^2`` over masked frames.

    Raises:
        UserError when ``target`` and ``approx`` differ in shape, or ``mask`` is not ``[T]``.
    """
    fn = "variance_explained"
    shape = np.shape(target)
    if np.shape(approx) != shape or len(shape) < 1:
        raise UserError(f"{fn}: target shape {shape} and approx shape {np.shape(approx)} must "
                        "be the same [T, ...]")
    if mask is not None and np.shape(mask) != shape[:1]:
        raise UserError(f"{fn}: mask shape {np.shape(mask)}, expected {shape[:1]}")
    target, approx = jnp.asarray(target), jnp.asarray(approx)
    target = target.reshape(target.shape[0], -1)
    approx = approx.reshape(approx.shape[0], -1)
    w = jnp.ones(target.shape[:1], target.dtype) if mask is None else jnp.asarray(mask,
                                                                                 target.dtype)
    mean = _masked_mean(target, w)
    sse = jnp.sum(_mm(w, (target - approx) ** 2))
    sst = jnp.sum(_mm(w, (target - mean[None, :]) ** 2))
    return 1.0 - sse / jnp.maximum(sst, 1e-30)


def energy_per_harmonic(model: FourierModel) -> Float[Array, "C N"]:
    """Mean power of each harmonic per channel, ``A_n^2 / 2`` (channel units squared)."""
    return 0.5 * model.amplitude**2


def amplitude_spectrum(
    features: Float[Array, "T C"], frame_time_s: float
) -> tuple[Float[Array, " K"], Float[Array, "K C"]]:
    """Single-sided DFT amplitude spectrum per channel (Tilmanne Fig. 1).

    Returns ``(freqs_hz [K], amplitude [K, C])`` with ``amplitude = 2 |c_k|``, but ``|c_k|`` at
    0 Hz and, for even T, at the Nyquist frequency (bins with no mirror image), so that a
    sinusoid of amplitude A on a bin shows A.
    Raises:
        UserError for an empty ``features`` or (when concrete) a ``frame_time_s`` that is not
        positive and finite.
    """
    fn = "amplitude_spectrum"
    x = jnp.asarray(features)
    if x.ndim < 1 or x.shape[0] < 1:
        raise UserError(f"{fn}: features must be [T, C] with T >= 1, got shape {x.shape}")
    _check_frame_time(fn, frame_time_s)
    T = x.shape[0]
    c = jnp.fft.rfft(x, axis=0) / T
    k = np.arange(T // 2 + 1)
    # The 0 Hz bin and (even T) the Nyquist bin are real and not mirrored: no doubling.
    scale = np.where((k == 0) | (2 * k == T), 1.0, 2.0).reshape((-1,) + (1,) * (x.ndim - 1))
    amp = jnp.abs(c)
    amp = amp * scale.astype(amp.dtype)
    return jnp.fft.rfftfreq(T, d=frame_time_s), amp
