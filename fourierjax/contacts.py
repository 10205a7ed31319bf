"""Foot contacts from foot-point trajectories: detection, step events, step period, soft weights."""

from __future__ import annotations

from typing import TYPE_CHECKING, NamedTuple

import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, ArrayLike, Bool, Float, Integer

from fourierjax._checks import number
from fourierjax._contactops import cleanup as _cleanup
from fourierjax._contactops import hysteresis as _hysteresis
from fourierjax._contactops import speeds as _speeds
from fourierjax._math import safe_sqrt
from fourierjax.errors import UserError

if TYPE_CHECKING:
    from fourierjax.skeleton import Topology

# The CMU skeleton's foot joints, ankle first (the heel strike is seen there), toes last.
CMU_FEET: tuple[tuple[str, ...], tuple[str, ...]] = (
    ("LeftFoot", "LeftToeBase"),
    ("RightFoot", "RightToeBase"),
)


class FootPoints(NamedTuple):
    """Which points of a skeleton make up each foot.

    Indices point into the concatenation of joint positions and End-Site positions
    (`[J + E, 3]`: joint `j` is index `j`, End Site `e` is index `J + e`), as built by
    `gather_foot_positions`.

    - `left`, `right`: point indices of each foot, ankle first, toe tip last.
    - `names`: the matching names (End Sites are named `"<parent>/End Site"`).
    """

    left: tuple[int, ...]
    right: tuple[int, ...]
    names: tuple[tuple[str, ...], tuple[str, ...]]


def foot_points(
    topology: Topology,
    feet=CMU_FEET,
    *,
    end_sites: bool = True,
) -> FootPoints:
    """The foot points of a skeleton: from its body map, or by joint name.

    Arguments:
        topology: a `fourierjax.skeleton.Topology` (uses `names` and `end_site_parents`).
        feet: a `fourierjax.body.BodyMap` of the skeleton (its `feet`: any rig; the points
            already hold the toe tip, so `end_sites` is not used), or `(left_names,
            right_names)`, the joints of each foot, ankle first. Defaults to the CMU naming
            (`LeftFoot, LeftToeBase` / `RightFoot, RightToeBase`).
        end_sites: also take the End Site(s) hanging from the last joint of each foot (the
            toe tip, the lowest point of a flat foot).

    Returns:
        A `FootPoints`. Both feet must have the same number of points.

    Raises `UserError` naming the missing joints and the skeleton's joints when the skeleton
    does not use the names asked for (pass `feet=` for other skeletons).
    """
    if hasattr(feet, "left") and hasattr(feet, "feet"):  # a BodyMap
        bm = feet
        if tuple(bm.joint_names) != tuple(topology.names):
            raise UserError("foot_points: the body map was made for another skeleton (its joint names differ)")
        left, right = bm.feet
        if len(left) != len(right):
            raise UserError(f"foot_points: the body map's feet have different point counts: "
                            f"{bm.left.foot_point_names} vs {bm.right.foot_point_names}")
        return FootPoints(tuple(left), tuple(right), (tuple(bm.left.foot_point_names),
                                                      tuple(bm.right.foot_point_names)))
    names = tuple(topology.names)
    num_joints = len(names)
    es_parents = tuple(getattr(topology, "end_site_parents", ()))
    out_idx, out_names = [], []
    for side in feet:
        missing = [n for n in side if n not in names]
        if missing:
            raise UserError(
                f"foot_points: the skeleton has no joint(s) {missing}; its joints are "
                f"{list(names)}. Pass feet=((left joints...), (right joints...)) for a skeleton "
                "that does not use the CMU names"
            )
        idx = [names.index(n) for n in side]
        nm = list(side)
        if end_sites:
            for e, p in enumerate(es_parents):
                if p == idx[-1]:
                    idx.append(num_joints + e)
                    nm.append(f"{side[-1]}/End Site")
        out_idx.append(tuple(idx))
        out_names.append(tuple(nm))
    if len(out_idx) != 2:
        raise UserError(f"foot_points: `feet` must name two feet (left, right), got {len(feet)}")
    if len(out_idx[0]) != len(out_idx[1]):
        raise UserError(
            f"foot_points: the feet have different point counts: {out_names[0]} vs {out_names[1]}"
        )
    return FootPoints(out_idx[0], out_idx[1], (out_names[0], out_names[1]))


def gather_foot_positions(
    joint_positions: Float[ArrayLike, "*batch J 3"],
    end_site_positions: Float[ArrayLike, "*batch E 3"],
    points: FootPoints,
) -> Float[Array, "*batch 2 P 3"]:
    """Stack the foot points of FK output into `[..., 2, P, 3]` (left, right).

    Arguments:
        joint_positions: `[..., J, 3]` joint positions (any leading batch/time axes).
        end_site_positions: `[..., E, 3]` End-Site positions.
        points: from `foot_points`.

    Returns:
        `[..., 2, P, 3]`. Pure jnp (numpy inputs give a JAX array).
    """
    allp = jnp.concatenate([jnp.asarray(joint_positions), jnp.asarray(end_site_positions)], -2)
    idx = jnp.asarray([points.left, points.right])
    return allp[..., idx, :]


def point_speeds(
    positions: Float[ArrayLike, "T ... 3"],
    frame_time_s: Float[ArrayLike, ""],
    *,
    up_axis: int | None = None,
) -> Float[Array, "T ..."]:
    """Speed of points over time by central differences (one-sided at the ends).

    Arguments:
        positions: `[T, ..., 3]` (T ≥ 2).
        frame_time_s: seconds per frame.
        up_axis: if given, that component is ignored (horizontal speed).

    Returns:
        `[T, ...]` in file units per second. Pure jnp, differentiable (a zero gradient, not
        NaN, where a point stands still).
    """
    p = jnp.asarray(positions)
    if up_axis is not None:
        keep = [k for k in range(3) if k != up_axis]
        p = p[..., keep]
    v = jnp.gradient(p, axis=0) / frame_time_s
    # sqrt(0) has an infinite derivative (a planted foot): safe_sqrt's is 0 there.
    return safe_sqrt(jnp.sum(v * v, axis=-1))


def soft_contact_weights(
    height: Float[ArrayLike, "*shape"],
    speed: Float[ArrayLike, "*shape"],
    height_threshold: Float[ArrayLike, ""],
    speed_threshold: Float[ArrayLike, ""],
    softness: Float[ArrayLike, ""] = 0.25,
) -> Float[Array, "*shape"]:
    """Differentiable contact weights in [0, 1]: low AND slow, with sigmoid edges.

    `w = σ((h_th − h) / (softness·h_th)) · σ((v_th − v) / (softness·v_th))`: 1/4 at both
    thresholds, → 1 well below both, → 0 above either.

    Arguments:
        height: `[...]` height above the floor (file units).
        speed: `[...]` point speed (file units / s), e.g. from `point_speeds`.
        height_threshold: positive scalar (file units).
        speed_threshold: positive scalar (file units / s).
        softness: edge width as a fraction of each threshold.

    Returns:
        `[...]` weights. Pure jnp.
    """
    import jax

    wh = jax.nn.sigmoid((height_threshold - height) / (softness * height_threshold))
    wv = jax.nn.sigmoid((speed_threshold - speed) / (softness * speed_threshold))
    return wh * wv


class GroundEstimate(NamedTuple):
    """The floor under each foot point: `floor = intercepts + slope · (horizontal position)`.

    - `intercepts`: `[F, P]` height of each point's floor at the horizontal origin (it includes
      the point's clearance when planted: an ankle sits above its floor by ~1 CMU unit).
    - `slope`: `[2]` rise per unit along the two horizontal axes (in axis order, up removed).
    - `height_threshold`, `speed_threshold`: the thresholds used (file units, units/s).
    """

    intercepts: np.ndarray
    slope: np.ndarray
    height_threshold: float
    speed_threshold: float


def floor_heights(
    ground: GroundEstimate, foot_positions: Float[ArrayLike, "T F *P 3"], *, up_axis: int = 1
) -> Float[np.ndarray, "T F P"]:
    """Height of each point's floor under it (NumPy).

    Arguments:
        ground: from `estimate_ground`.
        foot_positions: `[T, F, P, 3]` (or `[T, F, 3]`, read as P = 1) foot points.
        up_axis: index of the up axis.

    Returns:
        `[T, F, P]` floor heights (file units).
    """
    p = _as_points(foot_positions)
    return ground.intercepts + np.delete(p, up_axis, axis=-1) @ ground.slope


def sole_clearance(ground: GroundEstimate) -> Float[np.ndarray, "F P"]:
    """Height of each foot point above the foot's lowest point when planted.

    The point with the lowest floor (the toe tip on CMU feet) gets 0; the ankle ~1 CMU unit.
    These are the sole clearances the hip-height rule uses (`fourierjax.gait`).

    Arguments:
        ground: from `estimate_ground`.

    Returns:
        `[F, P]` clearances ≥ 0 (file units).
    """
    a = np.asarray(ground.intercepts)
    return a - a.min(axis=-1, keepdims=True)


def _as_points(foot_positions) -> np.ndarray:
    p = np.asarray(foot_positions, dtype=float)
    if p.ndim == 3:
        p = p[:, :, None, :]
    if p.ndim != 4 or p.shape[-1] != 3:
        raise UserError(
            f"foot_positions: expected shape [T, F, 3] or [T, F, P, 3], got {p.shape}"
        )
    if p.shape[0] < 3:
        raise UserError(f"foot_positions: need at least 3 frames, got {p.shape[0]}")
    if not np.all(np.isfinite(p)):
        raise UserError("foot_positions: contains NaN or inf")
    return p


def _scale(p: np.ndarray, up_axis: int) -> float:
    """A length for the default thresholds: the foot length (ankle → toe tip), if known."""
    if p.shape[2] >= 2:
        length = float(np.median(np.linalg.norm(p[:, :, 0] - p[:, :, -1], axis=-1)))
        if length > 0:
            return length
    # One point per foot: half the typical vertical excursion of the feet stands in.
    h = p[..., up_axis]
    rng = np.percentile(h, 95, axis=0) - np.percentile(h, 5, axis=0)
    return max(0.5 * float(np.median(rng)), 1e-6)


def _fit_floor(h, hz, slow, threshold, iters=3):
    """Least squares floor with one shared slope and one intercept per point, for one clip
    (`_fit_floors` fits many at once in closed form; this is its reference, and its answer
    where the slope is not determined).

    The slope is fitted only along horizontal directions the feet actually cover (spread of
    the planted points > 10 thresholds); CMU capture floors tilt by ~1 unit over a walk.
    """
    T, F, P = h.shape
    cand = slow & (h <= np.percentile(h, 30, axis=0))
    intercepts = np.percentile(h, 2, axis=0)
    slope = np.zeros(2)
    for _ in range(iters):
        if cand.sum() < F * P + 2:
            break
        pts = hz[cand]
        centre = pts.mean(0)
        cov = np.cov((pts - centre).T) if len(pts) > 2 else np.zeros((2, 2))
        evals, evecs = np.linalg.eigh(cov)
        dirs = [evecs[:, k] for k in range(2) if 4 * np.sqrt(max(evals[k], 0)) > 10 * threshold]
        _, fi, pi = np.nonzero(cand)
        used = np.zeros((F, P), bool)
        used[fi, pi] = True
        if not used.all():
            break
        # The rows of the candidates only: an intercept indicator per point, then the slopes.
        A = np.zeros((len(fi), F * P + len(dirs)))
        A[np.arange(len(fi)), fi * P + pi] = 1.0
        for k, d in enumerate(dirs):
            A[:, F * P + k] = ((hz - centre) @ d)[cand]
        sol = np.linalg.lstsq(A, h[cand], rcond=None)[0]
        slope = sum((sol[F * P + k] * d for k, d in enumerate(dirs)), np.zeros(2))
        intercepts = sol[: F * P].reshape(F, P) - centre @ slope
        resid = h - intercepts - hz @ slope
        cand = slow & (resid < threshold)
    return intercepts, slope


def _percentile_rows(s: np.ndarray, starts: np.ndarray, q: float) -> np.ndarray:
    """`np.percentile(x[a:b], q, axis=0)` of every clip ``[a, b)`` of ``starts [B + 1]``, bit for
    bit (numpy's "linear" method: the same index, weight and interpolation): ``s [N, ...]``
    sorted within each clip."""
    n = np.diff(starts)
    v = (n - 1) * (q / 100)
    lo = np.floor(v)
    gamma = (v - lo).reshape((-1,) + (1,) * (s.ndim - 1))
    lo = np.minimum(lo.astype(np.intp), n - 1)
    a, b = s[starts[:-1] + lo], s[starts[:-1] + np.minimum(lo + 1, n - 1)]
    diff = b - a
    # numpy's _lerp: from the far end when the weight is ≥ 1/2 (exact at both ends).
    return np.where(gamma >= 0.5, b - diff * (1 - gamma), a + diff * gamma)


def _sorted_within(x: np.ndarray, seg: np.ndarray) -> np.ndarray:
    """Each column of ``x [N, ...]`` sorted within each clip (``seg [N]``, ascending: each
    clip's rows together).

    The clips side by side, ``[B, longest, columns]`` padded with +inf, sorted along the frames
    in one call, read back without the padding: the same values as a lexsort by clip and value
    per column (128 Bandai-1 clips, 6 columns: 19 -> 1.4 ms). NaNs, which sort after the
    padding, take the lexsort."""
    flat = x.reshape(len(x), -1)
    if len(x) == 0 or np.isnan(flat).any():
        out = np.empty_like(flat)
        for c in range(flat.shape[1]):
            out[:, c] = flat[np.lexsort((flat[:, c], seg)), c]
        return out.reshape(x.shape)
    n = np.bincount(seg)
    row = np.arange(len(x)) - (np.cumsum(n) - n)[seg]
    side = np.full((len(n), int(n.max()), flat.shape[1]), np.inf, flat.dtype)
    side[seg, row] = flat
    side.sort(axis=1)
    return side[seg, row].reshape(x.shape)


def _fit_floors(h, hz, slow, starts, threshold, iters=3):
    """`_fit_floor` of B clips at once, in closed form: ``h [N, F, P]`` heights, ``hz
    [N, F, P, 2]`` horizontal positions and ``slow`` of all clips' frames end to end, clip ``b``
    at ``[starts[b], starts[b + 1])``, ``threshold [B]``. Returns intercepts ``[B, F, P]`` and
    slopes ``[B, 2]``.

    One intercept per point and a shared slope make the least squares separable: the slope
    solves the 2 × 2 normal equations of the positions centred per point, each intercept is its
    point's mean height less the slope times its mean position (equal to `_fit_floor`'s
    `lstsq` to rounding). All of it comes from each point's weighted moments, one reduction
    per iteration. A clip whose centred positions leave a chosen direction (near) empty, where
    `lstsq` would return its minimum-norm answer, is fitted by `_fit_floor` itself.
    """
    N, F, P = h.shape
    B, M = len(starts) - 1, F * P
    seg = np.repeat(np.arange(B), np.diff(starts))
    s = _sorted_within(h, seg)
    cand = slow & (h <= _percentile_rows(s, starts, 30)[seg])
    intercepts = _percentile_rows(s, starts, 2)
    slope = np.zeros((B, 2))
    # Moments about each point's first frame in its clip: the centred sums cancel little.
    h0, z0 = h.reshape(N, M)[starts[:-1]], hz.reshape(N, M, 2)[starts[:-1]]
    dh, dz = h.reshape(N, M) - h0[seg], hz.reshape(N, M, 2) - z0[seg]
    prods = np.concatenate([np.ones((N, M, 1)), dz, (dz[..., :, None] * dz[..., None, :]).reshape(N, M, 4),
                            dh[..., None], dh[..., None] * dz], axis=-1)
    going = np.ones(B, bool)
    odd = np.zeros(B, bool)
    for _ in range(iters):
        mom = np.add.reduceat(cand.reshape(N, M, 1) * prods, starts[:-1], axis=0)  # [B, M, 10]
        n = mom[..., 0]
        count = n.sum(1)
        going &= (count >= M + 2) & (n > 0).all(1)
        if not going.any():
            break
        k = np.maximum(n, 1)
        mu, hbar = mom[..., 1:3] / k[..., None], mom[..., 7] / k
        scatter = (mom[..., 3:7].reshape(B, M, 2, 2) - n[..., None, None] * mu[..., :, None] * mu[..., None, :]).sum(1)
        cross = (mom[..., 8:10] - (n * hbar)[..., None] * mu).sum(1)
        pos = z0 + mu  # each point's mean position
        centre = (n[..., None] * pos).sum(1) / np.maximum(count, 1)[:, None]
        e = pos - centre[:, None]
        cov = scatter + (n[..., None, None] * e[..., :, None] * e[..., None, :]).sum(1)
        evals, evecs = np.linalg.eigh(cov / np.maximum(count - 1, 1)[:, None, None])
        use = 4 * np.sqrt(np.maximum(evals, 0)) > 10 * threshold[:, None]
        V = evecs * use[:, None, :]  # the chosen directions, 0 for the others
        S = np.swapaxes(V, 1, 2) @ scatter @ V
        r = (np.swapaxes(V, 1, 2) @ cross[..., None])[..., 0]
        trace = np.where(use.any(1), np.trace(S, axis1=1, axis2=2), 1.0)
        S = S + np.eye(2) * np.where(use, 0, trace[:, None])[:, None]
        ev = np.linalg.eigvalsh(S)
        bad = going & use.any(1) & (ev[:, 0] <= 1e-9 * ev[:, 1])
        odd |= bad
        S[bad] = np.eye(2)
        new_slope = (V @ np.linalg.solve(S, r[..., None]))[..., 0]
        new_icpt = h0 + hbar - (pos * new_slope[:, None]).sum(-1)
        intercepts = np.where(going[:, None, None], new_icpt.reshape(B, F, P), intercepts)
        slope = np.where(going[:, None], new_slope, slope)
        resid = h - intercepts[seg] - (hz * slope[seg, None, None]).sum(-1)
        cand = np.where(going[seg, None, None], slow & (resid < threshold[seg, None, None]), cand)
    for b in np.flatnonzero(odd):
        a, e = starts[b], starts[b + 1]
        intercepts[b], slope[b] = _fit_floor(h[a:e], hz[a:e], slow[a:e], threshold[b], iters)
    return intercepts, slope


def _axis(up_axis) -> int:
    if isinstance(up_axis, bool) or not isinstance(up_axis, int | np.integer) or not (
        0 <= up_axis <= 2
    ):
        raise UserError(f"up_axis: must be the integer 0, 1 or 2, got {up_axis!r}")
    return int(up_axis)


def _runs(mask: np.ndarray):
    """(start, stop) of each run of True in a 1-D bool array."""
    d = np.diff(np.concatenate([[0], mask.astype(np.int8), [0]]))
    return np.nonzero(d == 1)[0], np.nonzero(d == -1)[0]


def estimate_ground(
    foot_positions: Float[ArrayLike, "T F *P 3"],
    frame_time_s: float,
    *,
    up_axis: int = 1,
    ground_height: float | None = None,
    height_threshold: float | None = None,
    speed_threshold: float | None = None,
) -> GroundEstimate:
    """Estimate the floor under each foot point and the contact thresholds (NumPy).

    With `ground_height` given the floor is level at that height and each point's clearance
    is its 2nd-percentile height above it (0 if the point goes lower).

    Arguments:
        foot_positions, frame_time_s, up_axis, ground_height, height_threshold,
            speed_threshold: as `foot_contacts` (which documents the defaults).

    Returns:
        A `GroundEstimate`.
    """
    return _grounds([_as_points(foot_positions)], [frame_time_s], up_axis, ground_height,
                    height_threshold, speed_threshold)[0][0]


def _grounds(ps, frame_times_s, up_axis, ground_height, height_threshold, speed_threshold):
    """`estimate_ground` of every clip of ``ps`` (each from `_as_points`), the floors fitted
    together (`_fit_floors`). Returns the grounds and, for all clips' frames end to end
    (``[N, F, P]``), each point's height above its floor and its speed, with each clip's first
    frame there (``starts [B + 1]``)."""
    dts = [number(dt, "frame_time_s:", positive=True) for dt in frame_times_s]
    up = _axis(up_axis)
    if height_threshold is not None:
        height_threshold = number(height_threshold, "height_threshold:", positive=True)
    if speed_threshold is not None:
        speed_threshold = number(speed_threshold, "speed_threshold:", positive=True)
    if ground_height is not None:
        ground_height = number(ground_height, "ground_height:")
    starts = np.cumsum([0] + [len(p) for p in ps])
    pts = np.concatenate(ps)
    speed = np.concatenate([_speeds(p, dt) for p, dt in zip(ps, dts, strict=True)])
    scale = np.array([_scale(p, up) for p in ps])
    B = len(ps)
    th = 0.25 * scale if height_threshold is None else np.full(B, height_threshold)
    tv = 6.0 * scale if speed_threshold is None else np.full(B, speed_threshold)
    h, hz = pts[..., up], np.delete(pts, up, axis=-1)
    seg = np.repeat(np.arange(B), np.diff(starts))
    if ground_height is None:
        intercepts, slope = _fit_floors(h, hz, speed < tv[seg, None, None], starts, th)
    else:
        lowest = _percentile_rows(_sorted_within(h, seg), starts, 2)
        intercepts, slope = np.maximum(lowest, ground_height), np.zeros((B, 2))
    above = h - intercepts[seg] - (hz * slope[seg, None, None]).sum(-1)
    grounds = [GroundEstimate(intercepts[b], slope[b], float(th[b]), float(tv[b])) for b in range(B)]
    return grounds, above, speed, starts


def foot_contacts(
    foot_positions: Float[ArrayLike, "T F *P 3"],
    frame_time_s: float,
    *,
    up_axis: int = 1,
    ground_height: float | None = None,
    height_threshold: float | None = None,
    speed_threshold: float | None = None,
    min_contact_s: float = 0.04,
    max_gap_s: float = 0.025,
) -> Bool[np.ndarray, "T F"]:
    """Detect foot contacts: a point is in contact when it is low AND slow (NumPy, edge code).

    A point is *low* when its height above its floor is below `height_threshold`, *slow* when
    its 3-D speed is below `speed_threshold`. The floor of each point is fitted (a plane with
    one slope shared by all points, so tilted capture floors work, and one intercept per point,
    so the ankle's clearance above the ground is learned). A foot given by several points
    (`[T, F, P, 3]`) is in contact when any of its points is: the heel lands first, the toes
    leave last. Hysteresis (a contact holds until 1.5× either threshold), then gaps of at most
    `max_gap_s` are closed and contacts shorter than `min_contact_s` are dropped.

    Defaults are relative to the clip's scale, the foot length ℓ (median ankle → toe-tip
    distance, or half the median vertical excursion with one point per foot):
    `height_threshold = 0.25 ℓ` (CMU: ~0.8 units ≈ 4.5 cm) and `speed_threshold = 6 ℓ/s`
    (CMU: ~19 units/s ≈ 1.1 m/s).

    Arguments:
        foot_positions: `[T, F, 3]` one point per foot, or `[T, F, P, 3]` (e.g. from
            `gather_foot_positions`), file units.
        frame_time_s: seconds per frame.
        up_axis: index of the vertical axis (1: Y up).
        ground_height: a level floor height; `None` fits the floor (see above).
        height_threshold: overrides the relative default (file units).
        speed_threshold: overrides the relative default (file units / s).
        min_contact_s: contacts shorter than this are dropped (seconds).
        max_gap_s: gaps inside a contact up to this long are closed (seconds).

    Returns:
        `bool [T, F]`. Raises `UserError` naming the argument for a non-finite or
    non-positive `frame_time_s` or threshold, a non-finite `ground_height`, negative or
    non-finite durations, or an `up_axis` other than the integer 0, 1 or 2.
    """
    return foot_contacts_many([foot_positions], [frame_time_s], up_axis=up_axis,
                              ground_height=ground_height, height_threshold=height_threshold,
                              speed_threshold=speed_threshold, min_contact_s=min_contact_s,
                              max_gap_s=max_gap_s)[0]


def foot_contacts_many(
    foot_positions: list,
    frame_times_s: list,
    *,
    up_axis: int = 1,
    ground_height: float | None = None,
    height_threshold: float | None = None,
    speed_threshold: float | None = None,
    min_contact_s: float = 0.04,
    max_gap_s: float = 0.025,
) -> list:
    """`foot_contacts` of many clips at once: the floor is fitted per clip, the thresholds,
    hysteresis and cleanup run as array ops over all clips (padded to the longest).

    Arguments:
        foot_positions: one `[T_i, F, 3]` or `[T_i, F, P, 3]` array per clip (the same F, P).
        frame_times_s: seconds per frame of each clip.
        up_axis, ground_height, height_threshold, speed_threshold, min_contact_s, max_gap_s:
            as `foot_contacts`, for every clip.

    Returns:
        One `bool [T_i, F]` per clip, equal to `foot_contacts` of each.
    """
    min_contact_s = number(min_contact_s, "min_contact_s:", nonnegative=True)
    max_gap_s = number(max_gap_s, "max_gap_s:", nonnegative=True)
    ps = [_as_points(p) for p in foot_positions]
    if not ps:
        return []
    grounds, above, speed, starts = _grounds(ps, frame_times_s, up_axis, ground_height,
                                             height_threshold, speed_threshold)
    seg = np.repeat(np.arange(len(ps)), np.diff(starts))
    th = np.array([g.height_threshold for g in grounds])[seg, None, None]
    tv = np.array([g.speed_threshold for g in grounds])[seg, None, None]
    # Padded to the longest clip, time first: [T, B, F, P] (frames after a clip's end: off).
    at = (np.arange(len(seg)) - starts[seg], seg)
    enter = np.zeros((max(len(p) for p in ps), len(ps)) + above.shape[1:], bool)
    stay = np.zeros_like(enter)
    enter[at] = (above < th) & (speed < tv)
    stay[at] = (above < 1.5 * th) & (speed < 1.5 * tv)
    dts = np.array([float(dt) for dt in frame_times_s])
    min_len = np.maximum(1, np.round(min_contact_s / dts).astype(int))
    max_gap = np.round(max_gap_s / dts).astype(int)
    on = _hysteresis(enter, stay).any(axis=3)  # [T, B, F]: any point of the foot
    lengths = np.array([len(p) for p in ps])[:, None]
    out = np.zeros(on.shape, bool)
    for lo, gap in dict.fromkeys(zip(min_len, max_gap)):  # clips of one frame rate together
        rows = (min_len == lo) & (max_gap == gap)
        out[:, rows] = _cleanup(on[:, rows], lo, gap, lengths[rows])
    return [out[:len(p), i] for i, p in enumerate(ps)]


def step_events(contacts: Bool[ArrayLike, "T F"]) -> tuple[Integer[np.ndarray, " strikes"], ...]:
    """Heel strikes: the frames where each foot's contact begins.

    A contact already on at frame 0 is not a strike (its onset was not seen).

    Arguments:
        contacts: `bool [T, F]`.

    Returns:
        A tuple of F integer arrays of frame indices, ascending.
    """
    c = np.asarray(contacts, bool)
    if c.ndim != 2:
        raise UserError(f"contacts: expected shape [T, F], got {c.shape}")
    return tuple(np.nonzero(c[1:, f] & ~c[:-1, f])[0] + 1 for f in range(c.shape[1]))


def step_intervals(contacts: Bool[ArrayLike, "T F"]) -> Integer[np.ndarray, " steps"]:
    """Frames between consecutive heel strikes of different feet (one per step).

    Arguments:
        contacts: `bool [T, F]`.

    Returns:
        Integer frame counts, in time order.
    """
    ev = step_events(contacts)
    frames = np.concatenate(ev) if ev else np.zeros(0, int)
    feet = np.concatenate([np.full(len(e), f) for f, e in enumerate(ev)]) if ev else frames
    order = np.argsort(frames, kind="stable")
    frames, feet = frames[order], feet[order]
    alt = feet[1:] != feet[:-1]
    return np.diff(frames)[alt]


STEP_STATISTICS = ("mean", "median")


def step_period_s(contacts: Bool[ArrayLike, "T F"], frame_time_s: float, *, statistic: str = "mean",
                  loop: bool = False) -> float:
    """Step duration, heel strike to the other foot's heel strike (Tilmanne §2.2).

    The gait cycle is two steps: `omega = 2π / (2 · step_period_s)`. When each foot has at
    least two strikes the cycle is measured foot by foot (strike to strike of the same foot,
    robust to left/right asymmetry) and halved; otherwise the alternating strike intervals
    (`step_intervals`) are used. `statistic="median"` resists a spurious extra strike (a
    stumble, CMU 142_02), which would pull the mean down.

    A clip that is one closed loop (`loop=True`: its last frame repeats its first, as in
    Bandai's short loops) repeats every `T - 1` frames, so each strike recurs one loop later:
    the steps across the seam count too. A 24-frame run loop (Bandai run_normal_001) holds one
    strike per foot and one step of 11 frames; its other step, across the seam, is 12.

    Arguments:
        contacts: `bool [T, F]`.
        frame_time_s: seconds per frame.
        statistic: `"mean"` or `"median"` of the intervals.
        loop: the clip is a closed loop (see above).

    Returns:
        Seconds. Raises `UserError` when the clip holds fewer than two alternating
    heel strikes, for an unknown `statistic`, or a non-finite or non-positive `frame_time_s`.
    """
    if statistic not in STEP_STATISTICS:
        raise UserError(f"statistic: {statistic!r} is not one of {STEP_STATISTICS}")
    frame_time_s = number(frame_time_s, "frame_time_s:", positive=True)
    reduce = np.mean if statistic == "mean" else np.median
    if loop:
        c = np.asarray(contacts, bool)
        contacts = np.concatenate([c, c[1:]]) if len(c) > 2 else c  # frame T - 1 is frame 0
    ev = step_events(contacts)
    cycles = [np.diff(e) for e in ev if len(e) >= 2]
    if len(ev) >= 2 and len(cycles) == len(ev):
        return float(reduce(np.concatenate(cycles))) * frame_time_s / 2.0
    steps = step_intervals(contacts)
    if len(steps) == 0:
        raise UserError(
            "step_period_s: fewer than two alternating heel strikes in the clip; cannot "
            "measure a step"
        )
    return float(reduce(steps)) * frame_time_s


def mean_step_period_s(contacts: Bool[ArrayLike, "T F"], frame_time_s: float) -> float:
    """Mean step duration: `step_period_s(contacts, frame_time_s, statistic="mean")`.

    Arguments:
        contacts: `bool [T, F]`.
        frame_time_s: seconds per frame.

    Returns:
        Seconds.
    """
    return step_period_s(contacts, frame_time_s, statistic="mean")


def flight_fraction(contacts: Bool[ArrayLike, "T F"]) -> float:
    """Fraction of frames with no foot in contact.

    Arguments:
        contacts: `bool [T, F]`.

    Returns:
        A fraction in [0, 1].
    """
    c = np.asarray(contacts, bool)
    return float(np.mean(~c.any(axis=1)))


def double_support_fraction(contacts: Bool[ArrayLike, "T F"]) -> float:
    """Fraction of frames with every foot in contact.

    Arguments:
        contacts: `bool [T, F]`.

    Returns:
        A fraction in [0, 1].
    """
    c = np.asarray(contacts, bool)
    return float(np.mean(c.all(axis=1)))


def contact_timeline(contacts: Bool[ArrayLike, "T F"], labels: tuple[str, ...] = ("L", "R")) -> str:
    """One text line per foot, `#` in contact, `.` in the air (for logs and the CLI).

    Arguments:
        contacts: `bool [T, F]`.
        labels: the name printed before each foot's line (its index when missing).

    Returns:
        F lines joined by newlines.
    """
    c = np.asarray(contacts, bool)
    return "\n".join(
        f"{labels[f] if f < len(labels) else f} " + "".join("#" if x else "." for x in c[:, f])
        for f in range(c.shape[1])
    )
