"""Contact intervals of the gait cycle: per foot, the phases where contact starts and ends."""

from __future__ import annotations

from typing import TYPE_CHECKING

import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, ArrayLike, Bool, Float

from fourierjax._jit import filter_jit
from fourierjax._saved import saved
from fourierjax.errors import UserError

if TYPE_CHECKING:
    from fourierjax.body import BodyMap
    from fourierjax.fourier import FourierModel
    from fourierjax.skeleton import Skeleton

TWO_PI = 2.0 * np.pi
#: Contact: a foot point within this fraction of the body height of its floor (issue 21).
CONTACT_HEIGHT_FRACTION = 0.02


def _circular_mean(th: np.ndarray) -> float:
    return float(np.mod(np.arctan2(np.sin(th).sum(), np.cos(th).sum()), TWO_PI))


def _longest_circular_run(on: np.ndarray) -> tuple[int, int] | None:
    """(first, last) sample of the longest run of True in a circular boolean array."""
    K = len(on)
    if on.all():
        return None
    if not on.any():
        return None
    shift = int(np.argmin(on))  # start the scan at a False sample: no run wraps
    rolled = np.roll(on, -shift)
    best, cur, best_end = 0, 0, 0
    for k in range(K):
        cur = cur + 1 if rolled[k] else 0
        if cur > best:
            best, best_end = cur, k
    first = (best_end - best + 1 + shift) % K
    return first, (best_end + shift) % K


def intervals_from_contacts(
    contacts: Bool[ArrayLike, "F 2"], omega_rad_s: float, frame_time_s: float, phase_shift: float = 0.0
) -> Float[np.ndarray, "2 2"] | None:
    """Contact intervals learned from a fitted clip's contacts (NumPy).

    Frame `k` of the fitted frames has aligned phase `omega k dt - phase_shift`
    (`motion.ClipFit`); each foot's start (end) is the circular mean of its touch-down
    (lift-off) phases.

    Arguments:
        contacts: `bool [F, 2]` (left, right) of the fitted frames (`motion.foot_contacts_of`).
        omega_rad_s: the model's fundamental; frame_time_s: the clip's.
        phase_shift: `ClipFit.phase_shift` (radians).

    Returns:
        `[2, 2]` (start, end) phases in [0, 2π), or None when a foot never both lands and lifts.
    """
    c = np.asarray(contacts, bool)
    if c.ndim != 2 or c.shape[1] != 2 or len(c) < 3:
        return None
    th = float(omega_rad_s) * np.arange(len(c)) * float(frame_time_s) - float(phase_shift)
    out = np.zeros((2, 2))
    for f in range(2):
        d = np.diff(c[:, f].astype(np.int8))
        on, off = np.flatnonzero(d == 1) + 1, np.flatnonzero(d == -1) + 1
        if len(on) == 0 or len(off) == 0:
            return None
        out[f] = _circular_mean(th[on]), _circular_mean(th[off])
    return out


def _cycle_feet(model, skeleton, body_map, num_samples):
    feet = tuple(body_map.left.foot_points), tuple(body_map.right.foot_points)
    if len(feet[0]) != len(feet[1]):
        raise UserError("contact_intervals: both feet must have the same number of points")
    grid, pts, root_v = _cycle_feet_jit(model, skeleton, feet, int(body_map.pelvis), int(num_samples))
    return np.asarray(grid), np.asarray(pts, np.float64), np.asarray(root_v, np.float64)


@saved
@filter_jit
def _cycle_feet_jit(model, skeleton, feet, pelvis, num_samples):
    # One program: run eagerly, the cycle's synthesis and FK were ~0.5 s of dispatches per call
    # (`fourierjax explore` estimates the intervals of each edited model).
    from fourierjax._gait.common import pose_points
    from fourierjax.fourier import synthesize_phase

    idx = jnp.asarray(feet)
    grid = jnp.linspace(0.0, TWO_PI, num_samples, endpoint=False, dtype=jnp.asarray(model.offset).dtype)
    feats = synthesize_phase(model, grid)
    pts, _ = jax.vmap(lambda f: pose_points(skeleton, model.representation, idx, (pelvis,), f, pelvis))(feats)
    return grid, pts, feats[:, :2]


def intervals_from_model(
    model: FourierModel, skeleton: Skeleton, *, body_map: BodyMap, num_samples: int = 128
) -> Float[np.ndarray, "2 2"]:
    """Contact intervals estimated from one cycle of the model (NumPy; a concrete model).

    A foot is in contact where its lowest point is low (within 2% of the body height of the
    lower foot's) and slow (world horizontal speed, the pelvis-frame velocity plus the model's
    own root velocity, under 30% of the mean root speed); its interval is the longest such run.

    Arguments:
        model: a `FourierModel`; skeleton: its `Skeleton`; body_map: the skeleton's.
        num_samples: phases of the cycle.

    Returns:
        `[2, 2]` (start, end) phases in [0, 2π) (left, right).
    """
    model = jax.tree_util.tree_map(jnp.asarray, model)  # NumPy float64 leaves as JAX holds them
    grid, pts, root_v = _cycle_feet(model, skeleton, body_map, num_samples)
    up = int(body_map.up_axis)
    horiz = [k for k in range(3) if k != up]
    K = num_samples
    omega = float(np.asarray(model.omega))
    dt = TWO_PI / K / omega
    y = pts[..., up] * body_map.up_sign
    low = y.min(axis=-1)  # [K, 2]
    thr = CONTACT_HEIGHT_FRACTION * float(body_map.height)
    is_low = low - low.min(axis=-1, keepdims=True) <= thr
    v_local = (np.roll(pts, -1, 0) - np.roll(pts, 1, 0))[..., horiz] / (2 * dt)  # [K, 2, P, 2]
    v_world = v_local + root_v[:, None, None, :]
    speed = np.linalg.norm(v_world, axis=-1).min(axis=-1)  # the foot's slowest point
    mean_root = float(np.mean(np.linalg.norm(root_v, axis=-1)))
    is_slow = speed <= 0.3 * mean_root + 1e-6 * float(body_map.leg_length) * omega
    out = np.zeros((2, 2))
    for f in range(2):
        run = _longest_circular_run(is_low[:, f] & is_slow[:, f])
        if run is None:  # never (or always) low and slow: the phases where it is the lower foot
            run = _longest_circular_run(low[:, f] <= low[:, 1 - f])
        if run is None:
            out[f] = 0.0, TWO_PI - 1e-3
            continue
        first, last = run
        out[f] = grid[first], np.mod(grid[last] + TWO_PI / K, TWO_PI)
    return out


def contact_intervals(
    model: FourierModel | None = None,
    skeleton: Skeleton | None = None,
    *,
    body_map: BodyMap | None = None,
    contacts: Bool[ArrayLike, "F 2"] | None = None,
    frame_time_s: float | None = None,
    phase_shift: float = 0.0,
    num_samples: int = 128,
) -> Float[Array, "2 2"]:
    """Per foot, the cycle phases where contact starts and ends.

    Learned from a fitted clip's contacts when `contacts` are given (`intervals_from_contacts`:
    the fitted frames' `motion.foot_contacts_of`, with `ClipFit.phase_shift`); estimated from
    the model's own cycle otherwise (`intervals_from_model`: old model files, interpolated or
    transitioned models), or when the clip's contacts do not show both feet landing and lifting.

    Arguments:
        model: the `FourierModel` (its ω phases the clip's frames; its cycle is the fallback).
        skeleton: its `Skeleton` (for the estimate).
        body_map: the skeleton's `BodyMap` (feet, up axis, height; for the estimate).
        contacts: `bool [F, 2]` contacts of the fitted frames, or None.
        frame_time_s: seconds per frame of `contacts`.
        phase_shift: the fit's phase alignment (radians).
        num_samples: phases of the cycle for the estimate.

    Returns:
        `[2, 2]` (left, right) × (start, end) radians in [0, 2π).
    """
    if model is None:
        raise UserError("contact_intervals: pass the model")
    if contacts is not None:
        if frame_time_s is None:
            raise UserError("contact_intervals: `contacts` need `frame_time_s`")
        iv = intervals_from_contacts(contacts, float(np.asarray(model.omega)), frame_time_s, phase_shift)
        if iv is not None:
            return jnp.asarray(iv, jnp.asarray(model.offset).dtype)
    if skeleton is None or body_map is None:
        raise UserError("contact_intervals: without the clip's contacts, pass `skeleton` and `body_map` "
                        "(the estimate from the model's cycle)")
    iv = intervals_from_model(model, skeleton, body_map=body_map, num_samples=num_samples)
    return jnp.asarray(iv, jnp.asarray(model.offset).dtype)



def fit_contact_intervals(fit, motion) -> Float[np.ndarray, "2 2"] | None:
    """The contact intervals of a fitted clip, to store with its model (`io.model_io.save_model`).

    Arguments:
        fit: a successful `motion.ClipFit`; motion: the `Motion` given to `motion.fit_motions`.

    Returns:
        `[2, 2]` phases (`contact_intervals` from the fitted frames' contacts, else from the
        model's cycle), or None without a body map.
    """
    from fourierjax.motion import foot_contacts_of

    if fit.body_map is None or not fit.successful:
        return None
    sub = motion[fit.frame_start:fit.frame_stop]
    iv = contact_intervals(fit.model, motion.skeleton(), body_map=fit.body_map,
                           contacts=foot_contacts_of(sub, body_map=fit.body_map),
                           frame_time_s=fit.frame_time_s, phase_shift=fit.phase_shift)
    return np.asarray(iv, np.float64)


def blend_contact_intervals(
    intervals_a: Float[ArrayLike, "*B 2 2"], intervals_b: Float[ArrayLike, "*B 2 2"], s: Float[ArrayLike, "*#B"]
) -> Float[Array, "*B 2 2"]:
    """Contact intervals of a blend of two gaits (`style.interpolate`), from its sources' (pure jnp).

    A blend's stance belongs to its sources: estimated from the blend's own cycle instead
    (`intervals_from_model`), the stance of two walks with different duty factors, which polar
    interpolation makes slide, is cut short and the foot lock lifts the sliding foot. Per foot,
    the start moves by s along the shorter arc, as polar interpolation moves a phase,
    `start = start_A + s wrap(start_B − start_A)`, and the duration `(end − start) mod 2π` moves
    linearly (clipped inside (0, 2π) when extrapolated): the end moves along its shorter arc
    too whenever the ends are closer than π, and the interval never flips to its complement.
    Both sources' phases must mean the same gait event (aligned fits, e.g. the left heel strike).

    Arguments:
        intervals_a: `[..., 2, 2]` (left, right) × (start, end) phases of A (radians;
            `contact_intervals`, stored in model files).
        intervals_b: B's, the same shape.
        s: the blend parameter of `style.interpolate` (0 gives A, 1 gives B; outside extrapolates),
            broadcastable to the leading dimensions.

    Returns:
        `[..., 2, 2]` phases in [0, 2π).
    """
    from fourierjax._math import wrap_angle

    a, b = jnp.asarray(intervals_a), jnp.asarray(intervals_b)
    if a.shape[-2:] != (2, 2) or b.shape != a.shape:
        raise UserError("blend_contact_intervals: both intervals must be [..., 2, 2] (foot, start/end) of "
                        f"the same shape, got {a.shape} and {b.shape}")
    dtype = jnp.result_type(a, b, jnp.asarray(s))
    if not jnp.issubdtype(dtype, jnp.floating):
        dtype = jnp.result_type(float)
    a, b = a.astype(dtype), b.astype(dtype)
    s = jnp.asarray(s, dtype)[..., None]  # [..., 1] against the feet
    start = a[..., 0] + s * wrap_angle(b[..., 0] - a[..., 0])
    dur_a, dur_b = (jnp.mod(m[..., 1] - m[..., 0], TWO_PI) for m in (a, b))
    tiny = TWO_PI / 1024
    duration = jnp.clip((1 - s) * dur_a + s * dur_b, tiny, TWO_PI - tiny)
    return jnp.mod(jnp.stack([start, start + duration], axis=-1), TWO_PI)
