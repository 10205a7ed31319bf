"""`FourierModel` (Unuma 1995 eq. 1, sine convention), its coordinate conventions and `stack_models`."""

from __future__ import annotations

import warnings

import equinox as eqx
import jax
import jax.numpy as jnp
from jaxtyping import Array, Float

from fourierjax._fourier import _tangent
from fourierjax._fourier._validate import _names_tuple
from fourierjax._math import wrap_angle
from fourierjax.errors import UserError
from fourierjax.features import REPRESENTATIONS


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


class FourierModel(eqx.Module):
    """Per-channel Fourier series with one fundamental (Unuma 1995 eq. 1, sine convention).

    Fields: ``offset [C]`` (A0), ``amplitude [C, N]`` (A_n >= 0), ``phase [C, N]`` (phi_n in
    (-pi, pi]), ``omega []`` (rad/s); static ``representation`` ("euler" | "expmap" |
    "tangent") and ``channel_names`` (tuple of str, empty or length C); ``frames [K, 4]`` (wxyz),
    the clip-mean rotation of each joint that a "tangent" model's coefficients are about
    (`fourierjax._fourier._tangent`; required there, None for the other representations).
    """

    offset: Float[Array, " C"]
    amplitude: Float[Array, "C N"]
    phase: Float[Array, "C N"]
    omega: Float[Array, ""]
    representation: str = eqx.field(static=True, default="euler")
    channel_names: tuple[str, ...] = eqx.field(static=True, default=(), converter=_names_tuple)
    frames: Float[Array, "K 4"] | None = None

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
        if (self.frames is None) == (self.representation == "tangent"):
            raise UserError(
                "FourierModel: `frames` [K, 4] (the joints' clip means) is required for "
                f"representation 'tangent' and must be None otherwise (got {self.representation!r})")
        if self.frames is not None:
            _tangent.check_frames("FourierModel", self.frames, amp[-2], names, off[:-1])

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
    def from_sin_cos(cls, offset, a, b, omega, representation="euler", channel_names=(),
                     frames=None):
        """Inverse of :meth:`sin_cos` (amplitudes made >= 0, phases in (-pi, pi])."""
        amplitude, phase = _safe_norm_atan2(jnp.asarray(a), jnp.asarray(b))
        return cls(jnp.asarray(offset), amplitude, phase, jnp.asarray(omega),
                   representation, tuple(channel_names), frames)

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

    def tilmanne_vector(self, convention: str = "sine") -> Float[Array, " S"]:
        """Tilmanne & Dutoit's flat polar view: per channel (A0, A1, phi1, ..., AN, phiN), then omega.

        Not `fourierjax.style.style_vector` (the style space's linear coordinates).

        Arguments:
            convention: ``"sine"`` (this model's phases) or ``"cosine"`` (Tilmanne's, eq. 1;
                54 x 5 + 1 = 271 numbers).

        Returns:
            ``[C * (2N + 1) + 1]``, omega raw (rad/s) last.
        """
        if convention not in ("sine", "cosine"):
            raise UserError(f"tilmanne_vector: convention {convention!r} not 'sine' or 'cosine'")
        amp = self.amplitude
        ph = wrap_angle(self.phase - jnp.pi / 2) if convention == "cosine" else self.phase
        pairs = jnp.stack([amp, ph], axis=-1).reshape(*amp.shape[:-1], -1)  # [C, 2N]
        per_channel = jnp.concatenate([self.offset[..., None], pairs], axis=-1)
        flat = per_channel.reshape(*per_channel.shape[:-2], -1)
        return jnp.concatenate([flat, self.omega[..., None]], axis=-1)

    @classmethod
    def from_tilmanne_vector(cls, vector, num_channels: int, num_harmonics: int,
                                representation="euler", channel_names=(), convention: str = "sine"):
        """Inverse of :meth:`tilmanne_vector` for one model (amplitudes/phases are canonicalised)."""
        vector = jnp.asarray(vector)
        expected = num_channels * (2 * num_harmonics + 1) + 1
        if vector.shape != (expected,):
            raise UserError(
                f"from_tilmanne_vector: vector shape {vector.shape}, expected ({expected},) for "
                f"{num_channels} channels x {num_harmonics} harmonics"
            )
        per_channel = vector[:-1].reshape(num_channels, 2 * num_harmonics + 1)
        offset = per_channel[:, 0]
        amp = per_channel[:, 1::2]
        ph = per_channel[:, 2::2]
        if convention == "cosine":
            ph = ph + jnp.pi / 2
        elif convention != "sine":
            raise UserError(f"from_tilmanne_vector: convention {convention!r} not 'sine' or 'cosine'")
        # Negative amplitudes (e.g. after PCA) are legal points: flip sign into the phase.
        a, b = amp * jnp.cos(ph), amp * jnp.sin(ph)
        return cls.from_sin_cos(offset, a, b, vector[-1], representation, channel_names)

    def style_vector(self, convention: str = "sine") -> Float[Array, " S"]:
        """Deprecated alias of :meth:`tilmanne_vector` (it clashed with `style.style_vector`)."""
        warnings.warn("FourierModel.style_vector is deprecated: use FourierModel.tilmanne_vector",
                      DeprecationWarning, stacklevel=2)
        return self.tilmanne_vector(convention)

    @classmethod
    def from_style_vector(cls, vector, num_channels: int, num_harmonics: int,
                          representation="euler", channel_names=(), convention: str = "sine"):
        """Deprecated alias of :meth:`from_tilmanne_vector`."""
        warnings.warn("FourierModel.from_style_vector is deprecated: use "
                      "FourierModel.from_tilmanne_vector", DeprecationWarning, stacklevel=2)
        return cls.from_tilmanne_vector(vector, num_channels, num_harmonics, representation,
                                        channel_names, convention)


def stack_models(models) -> FourierModel:
    """Stack models with identical static fields along a new leading axis (for vmap)."""
    return jax.tree.map(lambda *xs: jnp.stack(xs), *models)

