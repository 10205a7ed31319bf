"""Walking along a path: a synthesized straight gait bent onto a ground-plane polyline or circle."""

from __future__ import annotations

from collections.abc import Sequence

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, ArrayLike, Float

from fourierjax import rotations
from fourierjax._jit import filter_jit
from fourierjax._math import safe_sqrt
from fourierjax.errors import UserError


class GroundPath(eqx.Module):
    """A path in the ground plane: a polyline `[K, 2]` (file units, ground axes in file order,
    e.g. (x, z) for Y up), open or closed (a closed path is walked round and round)."""

    points: Float[Array, "K 2"]
    closed: bool = eqx.field(static=True, default=False)

    def __check_init__(self):
        if jnp.ndim(self.points) != 2 or jnp.shape(self.points)[-1] != 2 or jnp.shape(self.points)[0] < 2:
            raise UserError(f"GroundPath: `points` must be [K >= 2, 2] ground-plane points, got shape "
                            f"{jnp.shape(self.points)}")


def circle_path(radius: Float[ArrayLike, ""], num_points: int = 256, *, left: bool = True) -> GroundPath:
    """A closed circle through the origin, leaving it along the forward axis (+Z for Y up).

    Arguments:
        radius: in file units (> 0; convert metres with the body map's `metres_per_unit`).
        num_points: polyline vertices (the chord error is `R (1 − cos(π/K))`: 0.2 mm for
            R = 3 m, K = 256).
        left: turn left (counter-clockwise seen from above) or right.

    Returns:
        A closed `GroundPath`.
    """
    r = float(radius)
    if not (np.isfinite(r) and r > 0):
        raise UserError(f"circle_path: `radius` must be finite and > 0 (file units), got {radius}")
    th = np.linspace(0.0, 2 * np.pi, int(num_points), endpoint=False)
    side = 1.0 if left else -1.0
    # Ground axes (x, z), Y up: leave the origin along +Z; +X is the walker's left (Y × Z).
    pts = np.stack([side * r * (1 - np.cos(th)), r * np.sin(th)], axis=1)
    return GroundPath(jnp.asarray(pts), closed=True)


def polyline_path(points: Sequence[Sequence[float]], *, closed: bool = False) -> GroundPath:
    """A `GroundPath` through `points` `[K, 2]` (file units), repeated vertices removed.

    Arguments:
        points: `[K ≥ 2, 2]` ground-plane points.
        closed: walk round and round (the last point joins the first).

    Returns:
        A `GroundPath`.
    """
    p = np.asarray(points, np.float64)
    if p.ndim != 2 or p.shape[1] != 2 or not np.all(np.isfinite(p)):
        raise UserError(f"polyline_path: `points` must be finite [K, 2] ground-plane points, got shape {p.shape}")
    keep = np.concatenate([[True], np.linalg.norm(np.diff(p, axis=0), axis=1) > 1e-9])
    p = p[keep]
    if len(p) < 2:
        raise UserError("polyline_path: the path needs at least two distinct points")
    return GroundPath(jnp.asarray(p), closed=closed)


def _segments(points, closed):
    """`(start points [S, 2], segments [S, 2], lengths [S])` of a path (a closed one's last
    segment joins its last point to its first)."""
    if closed:
        points = jnp.concatenate([points, points[:1]], axis=0)
    seg = points[1:] - points[:-1]
    return points[:-1], seg, safe_sqrt(jnp.sum(seg * seg, axis=-1), floor=1e-24)


def _resolve(points, closed, s):
    """Position `[N, 2]` at arc lengths `s` `[N]` (linear beyond the ends of an open path)."""
    points, seg, length = _segments(points, closed)
    cum = jnp.concatenate([jnp.zeros((1,), length.dtype), jnp.cumsum(length)])
    if closed:
        s = jnp.mod(s, cum[-1])
    i = jnp.clip(jnp.searchsorted(cum, s, side="right") - 1, 0, len(length) - 1)
    u = (s - cum[i]) / length[i]
    return points[i] + u[:, None] * seg[i]


def _yaw_quat(psi, up_axis):
    q = jnp.zeros(psi.shape + (4,), psi.dtype).at[..., 0].set(jnp.cos(0.5 * psi))
    return q.at[..., 1 + up_axis].set(jnp.sin(0.5 * psi))


#: Points of the arc-length window that `follow_path` averages the path over.
_WINDOW_SAMPLES = 17


@filter_jit
def _follow(features, root, path, smoothing, sway, frame_time_s, start, *, columns, order, up_axis):
    horiz = [k for k in range(3) if k != up_axis]
    origin = jax.lax.dynamic_slice_in_dim(root[:, horiz], start, 1)  # [1, 2]
    ground = root[:, horiz] - origin
    travel = ground[-1] - ground[0]
    norm = safe_sqrt(jnp.sum(travel * travel), floor=1e-24)
    d = jnp.where(norm > 1e-9, travel / norm, jnp.asarray([0.0, 1.0], travel.dtype))
    n = jnp.stack([d[1], -d[0]])  # the ground-plane normal of d (a, b) -> (b, -a)
    s, lateral = ground @ d, ground @ n
    # The root walks the path averaged over a window of +-smoothing of arc length (corners rounded),
    # and the heading is that average's direction: the chord from s - smoothing to s + smoothing.
    # Walked as drawn, a polyline's corner turned the root's travel at once while the body turned
    # over the chord: 02_01 (Euler N = 4, smoothing 23 cm) along a 90-degree corner skated 0.635x
    # its capture and stepped its knee 5.31 deg (the capture's 3.49); averaged, 0.176x and 2.92
    # deg. The chord was also at least the mean vertex spacing (against a 256-gon's steps), so a
    # 2-segment polyline's body turned over metres before its corner while its root walked
    # straight; the default smoothing (a quarter of the leg) is three times a 3 m circle's
    # spacing. A chord of zero length has no direction: at least 1e-3 of the shortest segment.
    pts = path.points - path.points[:1]
    length = _segments(pts, path.closed)[2]
    if smoothing is None:  # `follow_path`'s default
        smoothing = jnp.mean(length)
    smoothing = jnp.maximum(smoothing, 1e-3 * jnp.min(length))
    # Trapezoids on _WINDOW_SAMPLES points of the window (the path is piecewise linear).
    u = jnp.linspace(-1.0, 1.0, _WINDOW_SAMPLES, dtype=s.dtype)
    w = jnp.ones(_WINDOW_SAMPLES, s.dtype).at[0].set(0.5).at[-1].set(0.5)
    def averaged(arc):
        window = jax.vmap(lambda ui: _resolve(pts, path.closed, arc + ui * smoothing))(u)  # [W, N, 2]
        return jnp.tensordot(w / jnp.sum(w), window, axes=1)

    # From the start frame's place: the averaged path need not pass through the first point (a
    # circle's average runs R (L/R)^2 / 6 inside it).
    p = averaged(s) - averaged(jnp.zeros((1,), s.dtype))
    ahead = _resolve(pts, path.closed, s + smoothing) - _resolve(pts, path.closed, s - smoothing)
    t_len = safe_sqrt(jnp.sum(ahead * ahead, axis=-1), floor=1e-24)
    tangent = ahead / t_len[:, None]
    normal = jnp.stack([tangent[:, 1], -tangent[:, 0]], axis=-1)
    new_ground = origin + p + (sway * lateral)[:, None] * normal
    # Yaw about +up that turns d into the tangent; heading angle atan2(a, b) for Y up (x, z).
    def heading(v):
        return jnp.arctan2(v[..., 0], v[..., 1])

    psi = heading(tangent) - heading(d)
    psi = jnp.concatenate([psi[:1], psi[0] + jnp.cumsum(jnp.mod(jnp.diff(psi) + jnp.pi, 2 * jnp.pi) - jnp.pi)])
    out_root = root.at[:, horiz[0]].set(new_ground[:, 0]).at[:, horiz[1]].set(new_ground[:, 1])
    cols = jnp.asarray(columns)
    ang = features[:, cols]
    q = rotations.quat_from_expmap(ang) if order == "expmap" else rotations.quat_from_euler(ang, order)
    q = rotations.quat_multiply(_yaw_quat(psi, up_axis), q)
    ang = rotations.expmap_from_quat(q) if order == "expmap" else rotations.euler_from_quat(q, order)
    vel = jnp.gradient(out_root, axis=0) / frame_time_s
    feats = features.at[:, cols].set(ang).at[:, 0].set(vel[:, horiz[0]]).at[:, 1].set(vel[:, horiz[1]])
    return feats, out_root, psi


def follow_path(
    features: Float[ArrayLike, "T C"],
    root_position: Float[ArrayLike, "T 3"],
    path: GroundPath,
    channel_names: Sequence[str],
    pelvis_name: str,
    frame_time_s: float,
    *,
    up_axis: int = 1,
    smoothing: Float[ArrayLike, ""] | None = None,
    sway: Float[ArrayLike, ""] = 0.0,
    start_frame: int = 0,
) -> tuple[Float[Array, "T C"], Float[Array, "T 3"], Float[Array, " T"]]:
    """Bend a straight synthesized gait onto a path: heading and root follow it at the gait's speed.

    The root's travel along its mean direction becomes arc length on the path (so the speed is
    the gait's); the root walks the path averaged over `+-smoothing` of arc length (its corners
    rounded), a fraction `sway` of its sideways deviation is kept about the path's normal, and
    the pelvis (with the whole body) turns about the up axis with the averaged path's direction.
    Pure JAX: vmap it over characters, each with its own path of the same vertex count.

    Arguments:
        features: `[T, C]` frames of one character (`synthesize_gait(...).features`).
        root_position: `[T, 3]` its world pelvis path (`GaitResult.root_position`).
        path: a `GroundPath` in file units, starting where the root starts (its first point
            is placed at the root's position at `start_frame`).
        channel_names: the features' names; pelvis_name: the body map's pelvis joint name.
        frame_time_s: seconds per frame.
        up_axis: the up axis (Y, 1).
        smoothing: half-width L (file units) of the arc-length window the path is averaged
            over (at least 1e-3 of its shortest segment); default the mean segment length (a
            polygon's vertices turn the heading smoothly; `synthesize_gait` and `synth --path`
            pass a quarter of the leg). Longer rounds corners more: the root passes a
            right-angled corner 0.35 L inside it, and walks a circle of radius R about
            R (L/R)^2/6 inside it (3 mm for L = 23 cm, R = 3 m).
        sway: the fraction of the root's sideways deviation from its mean line that is kept
            (0: the root stays on the path; 1: the gait's own sway, on CMU 07_01 4.7 cm peak
            to peak per cycle plus 2.5 cm of slow drift, so up to 3.7 cm off the path).
        start_frame: the frame (in `[0, T)`) that stands at the path's first point; the frames
            before it walk up to it (an open path's first segment extended backwards, a closed
            one's end): `synthesize_gait`'s lock pre-roll.

    Returns:
        `(features [T, C]` with the pelvis rotation turned and `root.vx, root.vz` the world
        velocity, `root_position [T, 3]`, `yaw [T]` radians about up).
    """
    names = tuple(channel_names)
    cols = [i for i, n in enumerate(names) if n.startswith(f"{pelvis_name}.")]
    if len(cols) != 3:
        raise UserError(f"follow_path: the features have no three rotation channels of the pelvis {pelvis_name!r}")
    kinds = [names[i].split(".", 1)[1] for i in cols]
    order = "expmap" if kinds[0].startswith("expmap") else "".join(k[0] for k in kinds)
    if up_axis != 1:
        raise UserError(f"follow_path: the library works Y up (io.axes converts on reading), got up_axis={up_axis}")
    features = jnp.asarray(features)
    root = jnp.asarray(root_position, features.dtype)
    if root.shape != (features.shape[0], 3):
        raise UserError(f"follow_path: `root_position` must be [T={features.shape[0]}, 3], got {root.shape}")
    path = GroundPath(jnp.asarray(path.points, features.dtype), closed=path.closed)
    if isinstance(start_frame, bool) or not isinstance(start_frame, (int, np.integer)) or not (
            0 <= start_frame < features.shape[0]):
        raise UserError(f"follow_path: `start_frame` must be a frame index in [0, {features.shape[0]}), "
                        f"got {start_frame!r}")
    f = features.dtype
    smoothing = None if smoothing is None else jnp.asarray(smoothing, f)
    return _follow(features, root, path, smoothing, jnp.asarray(sway, f),
                   jnp.asarray(frame_time_s, f), jnp.asarray(start_frame, jnp.int32), columns=tuple(cols),
                   order=order, up_axis=up_axis)
