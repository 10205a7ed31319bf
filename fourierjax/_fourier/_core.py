"""The numeric core of a fit for one clip: ω search by variable projection, then the coefficients."""

from __future__ import annotations

from typing import NamedTuple

import jax
import jax.numpy as jnp
from jaxtyping import Array

from fourierjax._fourier._linear import _basis_rows_sc, _masked_mean, _model_arrays_from_coef, _solve_basis
from fourierjax._fourier._omega import (
    _FLOOR_TOLERANCE,
    MIN_CYCLES,
    _golden_best,
    _golden_iterations_needed,
    _golden_point,
    _golden_start,
    _golden_update,
    _odd_energy_fraction,
    _omega_floor,
    _omega_guess,
    _spectral_omega,
)
from fourierjax._fourier._status import clip_status
from fourierjax._linalg import matmul as _mm


class _Search(NamedTuple):
    """What every step of the ω search reads: the centred clip, the search's constants and the
    loop's static layout (steps 0, 1: guard; 2 .. 2+G-1: grid; g0 .. last-1: golden section;
    last: the final fit)."""

    x: Array  # [T, C] centred features, frames left out zeroed
    xt: Array  # [C, T] its transpose (the residual's fast layout)
    xwx: Array  # [C] weighted sum of squares of x
    w: Array  # [T] frame weights
    cw: Array  # [C] channel weights
    t_s: Array  # [T] sample times
    omega_spec: Array
    omega_steps: Array
    omega_floor: Array
    duration: Array
    ratios: Array  # [G] grid ratios around the guess
    search_on: Array | None  # [nh] harmonics the search uses (None: all)
    odd_threshold: float
    nh: int  # harmonics of the basis (>= 2 for the guard)
    G: int
    g0: int
    last: int


def _fit_arrays(features, mask, frame_time_s, omega_steps, channel_weights, num_harmonics,
                f_min_hz, f_max_hz, search_halfwidth, grid_points, golden_iterations,
                odd_threshold):
    """Numeric core of :func:`fit` for one clip (plain arrays in and out).

    Every linear solve of the fit (2 for the subharmonic guard, ``grid_points`` for the grid,
    ``golden_iterations + 2`` for the golden section, 1 for the final coefficients) is one step
    of a single ``fori_loop`` (`_search_step`) around one call of ``_solve_basis``: the solve is
    traced and compiled once instead of once per stage (compile time ~2.5x lower, the same
    evaluation points; golden steps past the dtype's resolution are skipped, see
    ``_golden_iterations_needed``).
    """
    dtype = features.dtype
    N = num_harmonics
    w = jnp.asarray(mask, dtype)
    raw = features
    # Frames left out may hold anything (NaN for missing markers): 0 * NaN would still poison
    # every weighted sum, so they are zeroed first.
    features = jnp.where(w[:, None] > 0, features, jnp.zeros((), dtype))
    mean = _masked_mean(features, w)
    n_valid = jnp.sum(w)
    ctx = _search_context(features, mean, w, frame_time_s, omega_steps, channel_weights, N,
                          f_min_hz, f_max_hz, search_halfwidth, grid_points, golden_iterations,
                          odd_threshold)
    odd, golden, coef, sse_c = _run_search(ctx)
    om = _golden_best(golden)
    omega_guess = _guess(ctx, odd)
    if ctx.nh != N:  # drop the switched-off harmonic (its coefficients are exactly 0)
        nh = ctx.nh
        keep = [0, *range(1, N + 1), *range(nh + 1, nh + N + 1)]
        coef = coef[jnp.asarray(keep)]

    offset, amplitude, phase = _model_arrays_from_coef(mean, coef, N)
    result = clip_status(raw, w, channel_weights, frame_time_s, om, N, MIN_CYCLES,
                         _FLOOR_TOLERANCE, omega_steps)
    return dict(offset=offset, amplitude=amplitude, phase=phase, omega=om,
                omega_spectral=ctx.omega_spec, omega_steps=omega_steps, omega_guess=omega_guess,
                **_fit_metrics(sse_c, ctx.xwx, channel_weights, n_valid), result=result)


def _search_context(features, mean, w, frame_time_s, omega_steps, cw, num_harmonics, f_min_hz,
                    f_max_hz, search_halfwidth, grid_points, golden_iterations,
                    odd_threshold) -> _Search:
    """Step 1: the spectral ω, the search's floor, grid and loop layout."""
    dtype = features.dtype
    T = features.shape[0]
    N, G = num_harmonics, grid_points
    x = features - mean[None, :]
    omega_spec, _, _ = _spectral_omega(features, frame_time_s, w, cw, f_min_hz, f_max_hz)
    # The guard measures odd-harmonic energy with >= 2 harmonics; the search uses N. One basis
    # of nh harmonics serves both, the ones above N switched off in the search (N = 1 only).
    nh = max(N, 2)
    # Grid over [guess / (1 + h), guess * (1 + h)] (log spaced), then golden section in the
    # best cell (40 golden steps shrink it 1e-8-fold; no autodiff, so compiling stays fast).
    ratios = jnp.exp(jnp.linspace(-jnp.log1p(search_halfwidth), jnp.log1p(search_halfwidth),
                                  G, dtype=dtype))
    g0 = 2 + G
    last = g0 + _golden_iterations_needed(golden_iterations, search_halfwidth, G, dtype) + 2
    return _Search(
        x=x, xt=x.T, xwx=_mm(w, x * x), w=w, cw=cw, t_s=jnp.arange(T, dtype=dtype) * frame_time_s,
        omega_spec=omega_spec, omega_steps=omega_steps,
        # The search skips frequencies whose cycle is longer than the used frames can show
        # (`_omega_floor`): with many harmonics a period just past the clip fits too well.
        omega_floor=_omega_floor(w, frame_time_s), duration=jnp.sum(w) * frame_time_s,
        ratios=ratios,
        search_on=None if nh == N else (jnp.arange(1, nh + 1) <= N).astype(dtype),
        odd_threshold=odd_threshold, nh=nh, G=G, g0=g0, last=last,
    )


def _guess(ctx: _Search, odd):
    """The subharmonic guard's candidate from the two guard steps' odd-harmonic energies."""
    return _omega_guess(ctx.omega_spec, ctx.omega_steps, odd[0], odd[1], ctx.duration,
                        ctx.odd_threshold)


def _sin_cos_at(ctx: _Search, om):
    theta = om * ctx.t_s
    return jnp.sin(theta), jnp.cos(theta)


def _solve_step(ctx: _Search, k, sin_cos):
    """One linear solve at the step's ω: ``(weighted SSE, coef [P, C], SSE per channel)``."""
    on = ctx.search_on
    if on is not None:  # the guard steps use every harmonic
        on = jnp.where(k < 2, jnp.ones_like(on), on)
    B, coef, rhs = _solve_basis(ctx.x, ctx.w, _basis_rows_sc(*sin_cos, ctx.nh), on)

    # The grid only ranks cells 2% apart: x'Wx - rhs'coef (cancels, to ~1e-6 of x'Wx in
    # float32) is enough and saves a [T, C] residual. The golden section and the final fit
    # need the exact residual near the minimum. `k` is not batched under vmap, so this is
    # a real branch (both sides are not computed).
    def residual_sse(_):
        r = ctx.xt - _mm(coef.T, B)  # [C, T]: this layout's matmul is 3x faster than [T, P] @ [P, C]
        return _mm(r * r, ctx.w)

    def projected_sse(_):
        return ctx.xwx - jnp.sum(rhs * coef, axis=0)

    sse_c = jax.lax.cond(k >= ctx.g0, residual_sse, projected_sse, None)  # [C]
    return _mm(sse_c, ctx.cw), coef, sse_c


def _next_omega(ctx: _Search, k, odd, values, golden):
    """ω of step k (and the golden state, its bracket set when the golden phase starts)."""
    G, g0 = ctx.G, ctx.g0
    grid = _guess(ctx, odd) * ctx.ratios
    j = jnp.argmin(values)
    start = _golden_start(grid[jnp.maximum(j - 1, 0)], grid[jnp.minimum(j + 1, G - 1)])
    golden = jax.tree.map(lambda s0, s: jnp.where(k == g0, s0, s), start, golden)
    om = jnp.where(
        k < 2, jnp.where(k == 0, ctx.omega_spec / 2, ctx.omega_spec),
        jnp.where(k < g0, grid[jnp.clip(k - 2, 0, G - 1)],
                  jnp.where(k < ctx.last, _golden_point(k - g0, golden), _golden_best(golden))))
    return om, golden


def _search_step(ctx: _Search, k, state):
    """Step k of the search loop: solve at the carried ω, rank it, choose the next ω."""
    # The step's ω and sin/cos(ω t) come in the carry, computed at the end of the step
    # before: a loop carry is materialised, so XLA cannot fuse the ω bookkeeping and the
    # trig calls into every row of the basis (4x slower steps).
    om, sin_cos, odd, values, golden, coef_fit, sse_fit = state
    golden = tuple(golden)  # carried stacked: one small kernel instead of six
    fx, coef, sse_c = _solve_step(ctx, k, sin_cos)
    # Below the floor the search ranks nothing, if its guess lies above (a guess below
    # it sees less than a cycle itself: the fit is left alone and the cycle check refuses).
    floor = jnp.where(_guess(ctx, odd) >= ctx.omega_floor, ctx.omega_floor,
                      jnp.zeros((), om.dtype))
    fx = jnp.where((k < 2) | (om >= floor), fx, jnp.inf)  # the guard steps are not ranked
    in_golden = (k >= ctx.g0) & (k < ctx.last)
    golden = jax.tree.map(lambda n, o: jnp.where(in_golden, n, o),
                          _golden_update(k - ctx.g0, golden, fx), golden)
    odd = jnp.where(jnp.arange(2) == k, _odd_energy_fraction(coef, ctx.cw), odd)
    values = jnp.where(jnp.arange(ctx.G) == k - 2, fx, values)
    final = k == ctx.last
    om_next, golden = _next_omega(ctx, k + 1, odd, values, golden)
    return (om_next, _sin_cos_at(ctx, om_next), odd, values, jnp.stack(golden),
            jnp.where(final, coef, coef_fit), jnp.where(final, sse_c, sse_fit))


def _run_search(ctx: _Search):
    """Step 2: the whole search loop. Returns ``(odd [2], golden state, coef, sse per channel)``
    of the final fit."""
    dtype = ctx.x.dtype
    C = ctx.x.shape[1]
    zero = jnp.zeros((), dtype)
    P = 2 * ctx.nh + 1
    om0 = ctx.omega_spec / 2
    init = (om0, _sin_cos_at(ctx, om0), jnp.zeros((2,), dtype),
            jnp.full((ctx.G,), jnp.inf, dtype), jnp.stack(_golden_start(zero, zero)),
            jnp.zeros((P, C), dtype), jnp.zeros((C,), dtype))
    _, _, odd, _, golden, coef, sse_c = jax.lax.fori_loop(
        0, ctx.last + 1, lambda k, st: _search_step(ctx, k, st), init)
    return odd, tuple(golden), coef, sse_c


def _fit_metrics(sse_c, xwx, cw, n_valid):
    """RMS per channel, RMS in degrees and variance explained over the angle channels
    (``cw > 0``), from the per-channel SSE and the centred sum of squares ``xwx``."""
    ms = sse_c / jnp.maximum(n_valid, 1.0)
    angle = cw > 0
    rms_deg = jnp.degrees(jnp.sqrt(jnp.sum(jnp.where(angle, ms, 0.0))
                                   / jnp.maximum(jnp.sum(angle), 1)))
    ve = 1.0 - jnp.sum(jnp.where(angle, ms * n_valid, 0.0)) / jnp.maximum(
        jnp.sum(jnp.where(angle, xwx, 0.0)), 1e-30)
    return dict(rms=jnp.sqrt(ms), rms_deg=rms_deg, variance_explained_angles=ve,
                num_frames=n_valid.astype(jnp.int32))
