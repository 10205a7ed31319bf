"""`fit` and `fit_batch`: argument checks, the jitted batched program and the cycle check."""

from __future__ import annotations

import math

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Bool, Float, Int

from fourierjax import _jit
from fourierjax._checks import integer
from fourierjax._fourier import _tangent
from fourierjax._fourier._buckets import fill_masked
from fourierjax._fourier._core import _fit_arrays
from fourierjax._fourier._linear import _masked_mean, _solve_coefficients
from fourierjax._fourier._model import FourierModel
from fourierjax._fourier._omega import _FLOOR_TOLERANCE, MIN_CYCLES, _used_range
from fourierjax._fourier._status import MESSAGES, FitStatus, describe
from fourierjax._fourier._validate import (
    _as_array,
    _as_float_features,
    _check_finite_used,
    _check_frame_time,
    _check_mask_values,
    _check_real,
    _check_representation,
    _check_varies,
    _is_traced,
    _used_frames,
)
from fourierjax._linalg import matmul as _mm
from fourierjax._memory import chunk_sizes, fit_bytes_per_clip, resolve_limit
from fourierjax.errors import UserError
from fourierjax.features import angle_channel_mask


class FitResult(eqx.Module):
    """Outcome of :func:`fit` for one clip (all leaves; a batched fit has a leading axis).

    ``model`` is the fitted model (omega = ``omega_fit``), before phase alignment; the ω
    estimates are rad/s: ``omega_spectral`` (a), ``omega_steps`` (b; NaN if no step events were
    given), ``omega_guess`` (the candidate after the subharmonic guard), ``omega_fit`` (c;
    variable projection). Metrics cover the masked frames: ``rms`` per channel (channel units),
    ``rms_deg`` (angle channels), ``variance_explained_angles``; ``num_frames`` used.
    ``result`` is the clip's `FitStatus` code (0: successful); with ``throw=True`` (the default)
    a fit that is not successful raises instead.
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
    result: Int[Array, ""]

    @property
    def successful(self) -> Bool[Array, ""]:
        """True where the clip was fitted (``result == FitStatus.SUCCESSFUL``)."""
        return self.result == FitStatus.SUCCESSFUL

    def messages(self) -> list[str] | str:
        """What went wrong per clip (``"fitted"`` for a successful one); concrete results only."""
        return describe(self.result)


#: Fixed-ω refills of the per-channel masked fit (`_fit_channel_masked`): each fills the
#: masked entries with the least-squares model of the filled data and solves again (EM for
#: missing data: at a fixed ω its fixed point is the fit of the used entries alone). A 1-s gap
#: in one channel of a 1 Hz sine: amplitude 2e-3 off after 2 refills, 1e-5 after 12.
CHANNEL_MASK_ITERATIONS = 12


def _fit_batched_impl(features, mask, frame_time_s, omega_steps, channel_weights, chunk=None,
                      **static):
    # Defaults, broadcasts and dtype casts happen here, inside the one compiled program: done
    # eagerly, each would compile a small XLA program of its own on the first call.
    Bn, T, C = features.shape
    dtype = features.dtype
    per_channel = mask is not None and jnp.ndim(mask) == 3
    mask = jnp.ones((Bn, T), dtype) if mask is None else jnp.asarray(mask, dtype)
    frame_time_s = jnp.broadcast_to(jnp.asarray(frame_time_s, dtype), (Bn,))
    omega_steps = (jnp.full((Bn,), jnp.nan, dtype) if omega_steps is None
                   else jnp.broadcast_to(jnp.asarray(omega_steps, dtype), (Bn,)))
    cw = jnp.asarray(channel_weights, dtype)
    fn = lambda f, m, dt, os: _fit_arrays(f, m, dt, os, cw, **static)  # noqa: E731
    run = jax.vmap(fn)
    if per_channel:
        run = lambda f, m, dt, os: _fit_channel_masked(fn, f, m, dt, os, static["num_harmonics"])  # noqa: E731
    if chunk is None or chunk >= Bn:
        return run(features, mask, frame_time_s, omega_steps)
    # Traced features (under a caller's jit) cannot be cut on the host: chunks of `chunk` clips
    # run one after the other in a `lax.map`, the batch padded with copies of its last clip so
    # that every chunk is the same program (no second copy of the body for a remainder).
    xs = (features, mask, frame_time_s, omega_steps)
    pad = -Bn % chunk
    if pad:
        xs = jax.tree.map(lambda x: jnp.concatenate([x, jnp.repeat(x[-1:], pad, axis=0)]), xs)
    if per_channel:  # whole chunks mapped, so that each chunk's refinement is a real branch
        xs = jax.tree.map(lambda x: x.reshape(-1, chunk, *x.shape[1:]), xs)
        out = jax.lax.map(lambda a: run(*a), xs)
        out = jax.tree.map(lambda v: v.reshape(-1, *v.shape[2:]), out)
    else:
        out = jax.lax.map(lambda a: fn(*a), xs, batch_size=chunk)
    return jax.tree.map(lambda v: v[:Bn], out)


def _fit_channel_masked(fn, features, mask, frame_time_s, omega_steps, num_harmonics):
    """The batched fit with a per-channel mask ``[B, T, C]``: a frame is used where any of its
    channels is, and an entry left out is first filled by interpolation (`fill_masked`) and
    fitted; then, at that fit's ω, `CHANNEL_MASK_ITERATIONS` times filled by the linear model of
    the filled data, and fitted again (ω search included). A batch with no partly masked frame
    skips the refinement (a real branch: it costs nothing there). The metrics count the filled
    entries as fitted (their residual is the change of the last refill, near 0)."""
    used = mask > 0
    frame = jnp.max(mask, axis=-1)
    x0 = jax.vmap(fill_masked)(features, used)
    out = jax.vmap(fn)(x0, frame, frame_time_s, omega_steps)
    partial = jnp.any(~used & (frame[..., None] > 0))
    t = jnp.arange(features.shape[1], dtype=features.dtype)

    def refill(x, u, w, dt, om, xf):
        theta = om * t * dt

        def step(_, xf):
            mean = _masked_mean(xf, w)
            basis, coef, _ = _solve_coefficients(xf - mean[None, :], w, theta, num_harmonics)
            return jnp.where(u, x, mean[None, :] + _mm(basis.T, coef))

        return jax.lax.fori_loop(0, CHANNEL_MASK_ITERATIONS, step, xf)

    def refine(out):
        x = jax.vmap(refill)(features, used, frame, frame_time_s, out["omega"], x0)
        return jax.vmap(fn)(x, frame, frame_time_s, omega_steps)

    return jax.lax.cond(partial, refine, lambda o: o, out)


def _fit_single_impl(features, mask, frame_time_s, omega_steps, channel_weights, **static):
    add = lambda v: None if v is None else jnp.asarray(v)[None]  # noqa: E731
    out = _fit_batched_impl(features[None], add(mask), add(frame_time_s), add(omega_steps),
                            channel_weights, **static)
    return jax.tree.map(lambda v: v[0], out)


# The static options (Python ints, floats) are static arguments of filter_jit; array values
# (frame times, masks) reach it as arrays (`_check_fit_args`), so they never retrace.
_fit_batched = _jit.filter_jit(_fit_batched_impl)
_fit_single = _jit.filter_jit(_fit_single_impl)


def _default_channel_weights(channel_names, num_channels):
    # numpy, not jnp: a constant built eagerly by JAX would compile a program of its own.
    if not channel_names:
        return np.ones((num_channels,), np.float32)
    return np.asarray(angle_channel_mask(channel_names), np.float32)


def fit_batch(
    features: Float[Array, "B T C"],
    frame_time_s: Float[Array, " B"],
    num_harmonics: int,
    *,
    mask: Bool[Array, "B T"] | Bool[Array, "B T C"] | None = None,
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
    throw: bool = True,
    max_memory: int | None = None,
) -> FitResult:
    """Fit many clips in one jit/vmap call: ω three ways and the coefficients.

    Clips of different lengths are padded at the end to a common ``T`` and flagged by ``mask``.
    A per-channel ``mask [B, T, C]`` leaves out single entries (one glitchy joint's channels,
    not the whole frame): the entries are filled by interpolation, then by the model, and fitted
    again (one more fit, only for batches that hold such entries).
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

    Memory: a clip costs about ``26 * T * C`` values at the peak of the fit
    (`fourierjax._memory.fit_bytes_per_clip`: 1.5 MB for 240 frames x 60 channels in float32).
    A batch whose cost exceeds ``max_memory`` bytes (default: a quarter of the machine's memory)
    is fitted in equal chunks that fit it, the last padded with copies of the last clip, so that
    every chunk runs one compiled program. Chunking changes no result beyond float32 rounding:
    XLA compiles one program per batch size, and programs of two sizes may sum in another
    order (chunks of 14 against one batch of 70: bit-identical; 500 against 64: offsets and
    amplitudes within ~1e-6 relative, ω of 3 clips in 64 a few ulps apart). Under a caller's
    jit the chunks are a ``jax.lax.map``. A budget smaller than one clip is a UserError.

    With ``throw=False`` a clip that cannot be fitted (too few used frames, NaN in used
    frames, constant features, too few cycles: `FitStatus`) gets its code in ``result`` and
    the other clips are fitted as usual; the argument errors below still raise. Under a
    caller's jit, ``throw=True`` refuses such clips at run time (``equinox.error_if``).

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
                    golden_iterations=golden_iterations, odd_threshold=odd_threshold,
                    throw=throw, max_memory=max_memory)


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
        if arg == "mask" and value is not None and np.shape(value) == (*batch, T, C):
            pass  # a per-channel mask
        elif value is not None and (np.shape(value) != expected if exact else
                                    not _broadcasts_to(np.shape(value), expected)):
            more = f" or {(*batch, T, C)} (per channel)" if arg == "mask" else ""
            raise UserError(f"{name}: {arg} shape {np.shape(value)}, expected {expected}{more}")
        out.append(value)
    return tuple(out)


def _check_fit_values(name, features, mask, frame_time_s, omega_steps, num_harmonics,
                      f_min_hz, channel_weights, per_clip: bool = True) -> None:
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
        if mask.ndim == np.ndim(features):  # per channel: checked per used entry
            if per_clip and not _is_traced(features):
                features, mask = _frame_view(features, mask)
            else:
                mask = mask.max(axis=-1)
        used = np.atleast_1d(_used_frames(mask))
        need = _min_fit_frames(num_harmonics)
        few = np.flatnonzero(used < need)
        if few.size and per_clip:
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
    if per_clip and not _is_traced(features, mask):  # last: the checks that read all of the features
        _check_finite_used(name, features, mask)
        if not _is_traced(channel_weights):
            _check_varies(name, features, mask, channel_weights)


def _frame_view(features, mask):
    """A per-channel mask's features and frame mask as the frame-mask checks see them: a frame
    is used where any channel is, and each entry left out holds its channel's mean over the used
    ones (0 where none is), so that only used entries are checked for NaN and for variation."""
    x = np.asarray(features)
    used = mask != 0
    with np.errstate(invalid="ignore", divide="ignore"):
        mean = np.where(used, x, 0.0).sum(axis=-2, keepdims=True) / used.sum(axis=-2, keepdims=True)
    fill = np.where(np.isfinite(mean), mean, 0.0)
    return np.where(used, x, fill), mask.max(axis=-1)


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


def _fit_result(out, representation, channel_names, frames=None) -> FitResult:
    model = FourierModel(out["offset"], out["amplitude"], out["phase"], out["omega"],
                         representation, tuple(channel_names), frames)
    return FitResult(model, out["omega_spectral"], out["omega_steps"], out["omega_guess"],
                     out["omega"], out["rms"], out["rms_deg"],
                     out["variance_explained_angles"], out["num_frames"], out["result"])


def fit(
    features: Float[Array, "T C"],
    frame_time_s: float,
    num_harmonics: int,
    *,
    mask: Bool[Array, " T"] | Bool[Array, "T C"] | None = None,
    omega_steps: float | None = None,
    **kwargs,
) -> FitResult:
    """Fit one clip (``fit_batch`` with a batch of one; same arguments without the batch axis).

    Arguments:
        features: ``[T, C]`` channel samples (frame 0 at t = 0); frame_time_s: seconds;
        num_harmonics: N; mask: ``[T]`` frames to use; omega_steps: ω from step events (rad/s);
        kwargs: the options of :func:`fit_batch`, ``throw`` included (default True: a clip that
        cannot be fitted raises; False: its ``result`` says why).

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
             odd_threshold=0.1, throw=True, max_memory=None) -> FitResult:
    """Check the arguments of `fit` / `fit_batch` (`name`) and run its jitted `program`, in
    chunks of clips that fit `max_memory` bytes (`fourierjax._memory`)."""
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
                      options["f_min_hz"], channel_weights, per_clip=throw)
    frames = None
    if representation == "tangent":  # fitted about each joint's clip mean (_tangent)
        features, frames = _tangent.fit_inputs(name, features, mask, channel_names)
    limit = resolve_limit(f"{name}: max_memory", max_memory)
    batch = features.shape[0] if features.ndim == 3 else 1
    per_clip = fit_bytes_per_clip(*features.shape[-2:], num_harmonics,
                                  jax.dtypes.canonicalize_dtype(features.dtype).itemsize)
    num_chunks, chunk = chunk_sizes(
        batch, per_clip, limit,
        name=f"{name}: a clip of {features.shape[-2]} frames x {features.shape[-1]} channels "
             f"at num_harmonics={num_harmonics}")
    if num_chunks == 1:
        out = program(features, mask, frame_time_s, omega_steps, channel_weights, **options)
    elif _is_traced(features, mask, frame_time_s, omega_steps):
        out = program(features, mask, frame_time_s, omega_steps, channel_weights, chunk=chunk,
                      **options)
    else:
        out = _fit_in_chunks(program, chunk, features, mask, frame_time_s, omega_steps,
                             channel_weights, options)
    result = _fit_result(out, representation, channel_names, frames)
    if not throw:
        return result
    if _is_traced(result.result):
        # Under the caller's jit the host checks above could not read the values: the
        # in-graph status refuses the same clips at run time.
        bad = result.result != FitStatus.SUCCESSFUL
        first = jnp.ravel(result.result)[jnp.argmax(jnp.ravel(bad))]
        # Every leaf is guarded: a caller that keeps only `model` still gets the check.
        return eqx.branched_error_if(result, jnp.any(bad), first,
                                     tuple(f"{name}: {m}" for m in MESSAGES))
    frames = mask if mask is None or np.ndim(mask) < features.ndim else np.asarray(mask).max(axis=-1)
    _check_cycles(name, features.shape[-2], frames, frame_time_s, result.omega_fit)
    _check_status(name, result.result)
    return result


def _fit_in_chunks(program, chunk, features, mask, frame_time_s, omega_steps, channel_weights,
                   options) -> dict:
    """`program` over concrete clips, `chunk` at a time; the last chunk is padded with copies of
    the batch's last clip, so that every chunk runs one compiled program. Each chunk's outputs
    come back to the host before the next chunk starts, so only one chunk's working memory is
    alive at a time."""
    B = features.shape[0]
    host = lambda x: None if x is None else np.asarray(x)  # noqa: E731 (zero-copy on CPU)
    features, mask = host(features), host(mask)
    frame_time_s = np.broadcast_to(host(frame_time_s), (B,))
    omega_steps = None if omega_steps is None else np.broadcast_to(host(omega_steps), (B,))
    outs = []
    for start in range(0, B, chunk):
        part = (slice(start, start + chunk) if start + chunk <= B
                else np.minimum(np.arange(start, start + chunk), B - 1))
        take = lambda x, part=part: None if x is None else x[part]  # noqa: E731
        out = program(take(features), take(mask), take(frame_time_s), take(omega_steps),
                      channel_weights, **options)
        outs.append(jax.tree.map(np.asarray, out))
    return jax.tree.map(lambda *parts: jnp.asarray(np.concatenate(parts)[:B]), *outs)


def _check_status(name, result) -> None:
    """Refuse a concrete result that the host checks let through, naming the first clip."""
    codes = np.atleast_1d(np.asarray(result))
    bad = np.flatnonzero(codes != FitStatus.SUCCESSFUL)
    if bad.size:
        i = int(bad[0])
        where = "" if np.ndim(result) == 0 else f" clip {i}" + (
            f" (and {bad.size - 1} other clip(s))" if bad.size > 1 else "") + ":"
        raise UserError(f"{name}:{where} {FitStatus(int(codes[i])).message}")


#: Fewest cycles of its fitted fundamental a clip must cover. With less than one period in
#: view the period is not identified: a 0.9 Hz signal cut to 0.37 of a cycle was fitted at
#: 1.85 Hz with 0.9999 of the variance explained, and the first 0.5 s of 07_01 at 1.58 Hz
#: (0.93 for the whole clip). One whole cycle sampled without its repeated end frame covers
#: exactly 1; the 5% leeway is for a fitted omega a little off. Where the spectral / step guess
#: covers more, the least-squares search does not go below it (`_omega_floor`), and an answer on


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
