"""The harmonic basis and the closed-form linear fit for a fixed fundamental (variable projection's inner solve)."""

from __future__ import annotations

import equinox as eqx
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Bool, Float

from fourierjax._checks import integer
from fourierjax._fourier._model import FourierModel, _safe_norm_atan2
from fourierjax._fourier._validate import (
    _as_array,
    _as_float_features,
    _check_finite_used,
    _check_mask_values,
    _check_representation,
    _is_traced,
    _used_frames,
)
from fourierjax._linalg import matmul as _mm
from fourierjax._linalg import spd_solve as _spd_solve
from fourierjax.errors import UserError


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
    if representation == "tangent":
        raise UserError(f"{fn}: representation 'tangent' is fitted by `fit` (about the clip means); "
                        "use fit, or representation 'euler' / 'expmap' here")
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
    # The host checks above cannot read traced values: those are refused at run time instead.
    if _is_traced(features, mask):
        bad = jnp.any(~jnp.isfinite(features) & (w[:, None] > 0))
        features = eqx.error_if(features, bad, f"{fn}: features hold NaN or infinite values in "
                                "frames the fit uses; leave such frames out with mask=")
    if _is_traced(t_s):
        t_s = eqx.error_if(t_s, ~jnp.all(jnp.isfinite(t_s)), f"{fn}: t_s holds NaN or infinite times")
    if _is_traced(omega):
        omega = eqx.error_if(omega, ~jnp.isfinite(omega), f"{fn}: omega must be finite (rad/s)")
    if mask is not None:
        # Frames left out may hold NaN (as in `fit`): 0 * NaN would poison the weighted sums.
        features = jnp.where(w[:, None] > 0, features, jnp.zeros((), features.dtype))
    mean = _masked_mean(features, w)
    omega = jnp.asarray(omega, features.dtype)
    _, coef, _ = _solve_coefficients(features - mean[None, :], w, omega * jnp.asarray(t_s),
                                     num_harmonics)
    offset, amplitude, phase = _model_arrays_from_coef(mean, coef, num_harmonics)
    return FourierModel(offset, amplitude, phase, omega, representation, tuple(channel_names))
