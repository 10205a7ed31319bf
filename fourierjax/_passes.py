"""Walks that turn: the heading over time, the straight passes, and one fit of all passes."""

from __future__ import annotations

import dataclasses

import numpy as np
from jaxtyping import Bool, Float, Int

from fourierjax import _jit, rotations
from fourierjax._fourier._layout import as_f64, bucket, root_joints, rot, rotation_joints, world_pose
from fourierjax.errors import UserError

#: How `fit_motions` uses a clip that turns: every straight pass, or the longest one only.
PASS_MODES = ("auto", "longest")


def heading_over_time(
    motion, *, body_map=None, window_s: float = 1.0, min_speed_fraction: float = 0.2
) -> Float[np.ndarray, " F"]:
    """The walker's heading (yaw, radians) at every frame: the direction it travels, smoothed.

    The travel is the body map's pelvis's ground-plane position (world, through FK of its
    ancestors: the trajectory joint's travel; CMU: joint 0), differenced over ``+-window_s``
    (which averages out the in-step sway). ``psi = atan2(v_x, v_z)``, unwrapped. Where the
    walker stands (smoothed speed under ``min_speed_fraction`` of the clip's 90th-percentile
    speed) the travel has no direction: the heading is interpolated between the moving frames
    around (held at the clip's ends), so standing still and turning on the spot give no jumps.
    A clip that never moves has the facing of `features.heading_of` throughout. (The facing
    itself is no heading over time: a stylized walker's pelvis yaws 40 degrees either way of
    where it goes, CMU 142_02.)

    Arguments:
        motion: a Motion (Y up).
        body_map: its `fourierjax.body.BodyMap`; None infers it.
        window_s: half-width of the velocity's window, seconds.
        min_speed_fraction: under this fraction of the 90th-percentile speed a frame stands.

    Returns:
        ``[F]`` radians, continuous (a walk that turns twice by 180 degrees ends near 2 pi).
    """
    from fourierjax.features import heading_of

    F = motion.num_frames
    rj = root_joints(motion, body_map)
    pos, _ = world_pose(motion, rj.pelvis)
    p = pos[:, [0, 2]]
    w = max(1, int(round(window_s / motion.frame_time_s)))
    idx = np.arange(F)
    v = p[np.minimum(idx + w, F - 1)] - p[np.maximum(idx - w, 0)]
    span = (np.minimum(idx + w, F - 1) - np.maximum(idx - w, 0)) * motion.frame_time_s
    speed = np.hypot(v[:, 0], v[:, 1]) / np.maximum(span, 1e-12)
    ref = np.percentile(speed, 90) if F else 0.0
    moving = speed > max(min_speed_fraction * ref, 1e-12)
    if not moving.any():
        return np.full(F, heading_of(motion, body_map=body_map))
    good = np.nonzero(moving)[0]
    psi = np.unwrap(np.arctan2(v[good, 0], v[good, 1]))
    return np.interp(idx, good, psi)


def straight_passes(
    motion,
    *,
    body_map=None,
    window_s: float = 0.5,
    heading_window_s: float = 1.0,
    min_speed_fraction: float = 0.75,
    max_turn_deg_s: float = 30.0,
    min_duration_s: float = 1.0,
    trim_fraction: float = 0.9,
) -> list[tuple[int, int]]:
    """Every steady, straight stretch of a clip: frames ``[start, stop)`` in time order.

    A frame belongs to a pass when the pelvis's horizontal speed (its world position through
    FK, smoothed over ``+-window_s``) is at least ``min_speed_fraction`` of the clip's
    90th-percentile speed, and the heading (`heading_over_time`) turns slower than
    ``max_turn_deg_s``. Each run of such frames is trimmed at both ends while its speed is
    under ``trim_fraction`` of the run's median (the slowing into a turn and the speeding up
    out of it), and kept when it lasts ``min_duration_s``. This is
    `motion.steady_segment`'s rule, keeping every run instead of the longest.

    Arguments:
        motion: a Motion (Y up).
        body_map: its `fourierjax.body.BodyMap`; None infers it.
        window_s, heading_window_s: smoothing of the speed and of the heading, seconds.
        min_speed_fraction, max_turn_deg_s, min_duration_s, trim_fraction: as above.

    Returns:
        A list of ``(start, stop)`` frame pairs (empty when the walker never goes straight
        for ``min_duration_s``).
    """
    F = motion.num_frames
    dt = motion.frame_time_s
    if F < 3:
        return []
    rj = root_joints(motion, body_map)
    pos, _ = world_pose(motion, rj.pelvis)
    p = pos[:, [0, 2]]
    w = max(1, int(round(window_s / dt)))
    idx = np.arange(F)
    hi, lo = np.minimum(idx + w, F - 1), np.maximum(idx - w, 0)
    v = (p[hi] - p[lo]) / (np.maximum(hi - lo, 1) * dt)[:, None]
    speed = np.hypot(v[:, 0], v[:, 1])
    ref = np.percentile(speed, 90)
    if not ref > 0:
        return []
    psi = heading_over_time(motion, body_map=body_map, window_s=heading_window_s)
    turn = np.degrees(np.abs(np.gradient(psi, dt)))
    ok = np.append((speed >= min_speed_fraction * ref) & (turn <= max_turn_deg_s), False)
    out = []
    start = None
    for i, s in enumerate(ok):
        if s and start is None:
            start = i
        elif not s and start is not None:
            a, b = start, i
            start = None
            med = np.median(speed[a:b])
            while a < b - 1 and speed[a] < trim_fraction * med:
                a += 1
            while b - 1 > a and speed[b - 1] < trim_fraction * med:
                b -= 1
            if (b - a) * dt >= min_duration_s:
                out.append((a, b))
    return out


def cycle_period_frames(
    strikes: list[tuple[Int[np.ndarray, " L"], Int[np.ndarray, " R"]]],
) -> float:
    """Gait cycle (frames) shared by several passes: heel strikes ``t = t0(pass, foot) + j T``.

    One line per pass and foot with a common slope ``T`` (least squares, pooled within the
    groups); each strike's cycle index ``j`` is its time from the group's first strike over the
    median same-foot interval, rounded. Strikes more than a quarter cycle off their line (a
    stumble: CMU 142_02) are dropped and ``T`` is fitted again.

    Arguments:
        strikes: per pass, ``(left, right)`` heel-strike frames.

    Returns:
        ``T`` in frames, or NaN when no foot strikes twice in one pass.
    """
    groups = [np.asarray(g, float) for pair in strikes for g in pair if len(g) >= 2]
    if not groups:
        return float("nan")
    T = float(np.median(np.concatenate([np.diff(g) for g in groups])))
    if not T > 0:
        return float("nan")
    for _ in range(3):
        num = den = 0.0
        keep_groups = []
        for g in groups:
            j = np.round((g - g[0]) / T)
            j, first = np.unique(j, return_index=True)  # one strike per cycle
            t = g[first]
            r = t - T * j
            good = np.abs(r - np.median(r)) <= 0.25 * T
            j, t = j[good], t[good]
            if len(j) >= 2:
                keep_groups.append(g)
                num += float(np.sum((j - j.mean()) * (t - t.mean())))
                den += float(np.sum((j - j.mean()) ** 2))
        if den <= 0:  # no foot kept two strikes on its line: keep the median
            return T
        T = num / den
        groups = keep_groups
    return float(T)


def _pass_phase(left: np.ndarray, T: float) -> float:
    """Circular mean phase (radians) of the left strikes of one pass, ``2 pi t / T``."""
    th = 2 * np.pi * np.asarray(left, float) / T
    return float(np.arctan2(np.sin(th).sum(), np.cos(th).sum()))


def _join_branches(x: np.ndarray, topology, representation: str, keep) -> np.ndarray:
    """Rotation channels of passes laid end to end put on one branch: each pass's Euler triples
    (or expmaps) continue the previous pass's, across the turn that was cut out."""
    joints = rotation_joints(topology)
    x = x.copy()
    for order in dict.fromkeys(o for _, o, _ in joints):
        cols = np.array([[3 + 3 * k + i for i in range(3)]
                         for k, (_, o, _) in enumerate(joints) if o == order])
        block = x[:, cols]  # [T, J_g, 3]
        if representation == "euler":
            x[:, cols] = _runs_on_one_branch(_euler_continuous(block, order, keep), order, keep)
        else:
            x[:, cols] = rot("make_expmap_continuous", block)
    return x


def _runs_on_one_branch(block: np.ndarray, order: str, keep: np.ndarray) -> np.ndarray:
    """Each run of kept rows (a pass, or a stretch between capture glitches) of ``block``
    ``[T, J, 3]`` moved, per joint, to the Euler triple (itself or its twin, each angle shifted
    by whole turns) whose mean lies nearest the runs already placed (longest first).

    Frame-to-frame continuity alone can cross a joint's gimbal lock and carry the rest of the
    clip onto the twin branch: CMU 142_02's left arm passes within 4 degrees of it in a masked
    glitch of its second pass, so its last pass and a half sat on the twin (Y near -3.3 against
    +0.15 rad, the same rotations): one Fourier model through both branches explained
    nothing of the arm (position VE -0.80 at N = 4; the longest pass alone -0.07)."""
    from fourierjax.rotations import euler_twin

    k = np.asarray(keep, bool)
    edges = np.flatnonzero(np.diff(np.concatenate([[0], k.astype(np.int8), [0]])))
    runs = sorted(zip(edges[::2], edges[1::2]), key=lambda r: r[0] - r[1])  # longest first
    if len(runs) < 2:
        return block
    out = block.copy()
    total = np.zeros(block.shape[1:])
    count = 0
    for a, b in runs:
        seg = out[a:b]
        if count:
            ref = total / count
            best = None
            for cand in (seg, euler_twin(seg, order)):
                shift = 2 * np.pi * np.round((ref - cand.mean(0)) / (2 * np.pi))  # [J, 3]
                cost = np.sum((cand.mean(0) + shift - ref) ** 2, axis=-1)  # [J]
                best = (cand + shift, cost) if best is None else (
                    np.where((cost < best[1])[None, :, None], cand + shift, best[0]),
                    np.minimum(cost, best[1]))
            seg = best[0]
            out[a:b] = seg
        total += seg.sum(0)
        count += b - a
    return out


_EULER_JIT = _jit.filter_jit(rotations.make_euler_continuous)


def _euler_continuous(block: np.ndarray, order: str, keep: np.ndarray) -> np.ndarray:
    """`rotations.make_euler_continuous` on a NumPy block, padded to a length bucket (one
    compiled program per bucket and order, not per clip)."""
    T = len(block)
    Tp = bucket(T)
    pad = np.concatenate([block, np.repeat(block[-1:], Tp - T, axis=0)])
    ok = np.concatenate([keep, np.zeros(Tp - T, bool)])
    return as_f64(_EULER_JIT(pad, order, ok))[:T]


@dataclasses.dataclass(frozen=True)
class PassLayout:
    """Where each straight pass sits on the fitting time axis.

    ``passes`` are ``(start, stop)`` frames of the clip; pass ``k`` occupies rows
    ``offsets[k] : offsets[k] + stop - start`` of the features, and the rows between passes are
    masked. The gaps are chosen so that every pass's left heel strikes fall at one phase of the
    cycle ``period_frames`` (`cycle_period_frames`), to within half a frame.
    """

    passes: tuple[tuple[int, int], ...]
    offsets: tuple[int, ...]
    headings_rad: tuple[float, ...]
    period_frames: float


def layout_passes(passes, left_strikes, period_frames: float, headings=None, lengths=None) -> PassLayout:
    """Place passes on one time axis so that their left heel strikes share a phase.

    Arguments:
        passes: ``(start, stop)`` frames per pass.
        left_strikes: per pass, left heel-strike frames relative to the pass's start.
        period_frames: the gait cycle in frames.
        headings: per pass, its heading (radians), stored in the layout.
        lengths: per pass, its rows on the time axis (default ``stop - start``).

    Returns:
        A `PassLayout`.
    """
    T = float(period_frames)
    if not (np.isfinite(T) and T > 0):
        raise UserError(f"layout_passes: period_frames must be a positive number, got {period_frames!r}")
    if len(passes) != len(left_strikes):
        raise UserError(f"layout_passes: {len(passes)} passes but {len(left_strikes)} strike lists")
    lengths = [b - a for a, b in passes] if lengths is None else [int(n) for n in lengths]
    phi0 = _pass_phase(left_strikes[0], T)
    offsets = [0]
    end = lengths[0]
    for n, left in zip(lengths[1:], left_strikes[1:]):
        # Offset o with 2 pi o / T + phi_k = phi_0 (mod 2 pi), o >= end.
        o0 = (phi0 - _pass_phase(left, T)) / (2 * np.pi) * T
        o = int(round(o0 + np.ceil((end - o0) / T) * T))
        if o < end:
            o += int(round(T))
        offsets.append(o)
        end = o + n
    heads = tuple(float(h) for h in headings) if headings is not None else (0.0,) * len(passes)
    return PassLayout(tuple((int(a), int(b)) for a, b in passes), tuple(offsets), heads, T)


def prepare_passes(clip, lo: int, representation: str, body_map, use_contacts: bool = True,
                   min_turn_deg: float = 45.0, **pass_kwargs):
    """The fitting input of a clip that walks back and forth, for `motion.fit_motions`.

    Every straight pass (`straight_passes`) in its own heading frame (the pass's circular mean
    of `heading_over_time`), its rotations put on one branch with the other passes', laid on
    one time axis (`layout_passes`) so that the passes' left heel strikes share a phase; the
    turns and the gaps between passes are masked out, and so are capture glitches.

    Arguments:
        clip: the Motion (frames ``[lo, ...)`` of the one given to ``fit_motions``).
        lo: the clip's first frame in that Motion.
        representation: ``"euler"`` or ``"expmap"``.
        body_map: the clip's `fourierjax.body.BodyMap` (None: no passes).
        use_contacts: False fits the longest pass only (no heel strikes to align passes by).
        min_turn_deg: passes whose directions all lie within this angle are one straight walk
            (interrupted by a wobble of the heading or a pause), fitted as before.
        pass_kwargs: passed on to `straight_passes`.

    Returns:
        None when the clip has fewer than two passes, they do not turn, or no cycle can be
        measured from heel strikes (``fit_motions`` then fits its steady segment); else ``(layout, a, b, sub, x,
        names, left, right, omega_steps, keep)``: frames ``[a, b)`` of the given Motion span the
        passes (``sub`` is that slice), ``x [T, C]`` the features, ``left`` / ``right`` heel
        strikes as rows of ``x``, ``omega_steps`` rad/s, ``keep [T]`` the rows fitted.
    """
    from fourierjax import motion as M
    from fourierjax.features import features_from_motion, heading_of

    if body_map is None or not use_contacts:
        return None
    passes = straight_passes(clip, body_map=body_map, **pass_kwargs)
    if len(passes) < 2:
        return None
    psi = heading_over_time(clip, body_map=body_map)
    ways = [np.arctan2(np.sin(psi[a:b]).sum(), np.cos(psi[a:b]).sum()) for a, b in passes]
    turn = max(abs(float(np.angle(np.exp(1j * (u - v))))) for u in ways for v in ways)
    if np.degrees(turn) < min_turn_deg:  # one straight walk with a wobble or a pause in it
        return None
    contacts = M.foot_contacts_of(clip, body_map=body_map)
    if contacts is None:
        return None
    from fourierjax.contacts import step_events

    strikes = []
    for a, b in passes:
        ev = step_events(contacts[a:b])
        strikes.append((ev[0], ev[1]))
    usable = [k for k, (lft, _) in enumerate(strikes) if len(lft) >= 1]
    if len(usable) < 2:
        return None
    passes = [passes[k] for k in usable]
    strikes = [strikes[k] for k in usable]
    T = cycle_period_frames(strikes)
    if not (np.isfinite(T) and T > 0):
        return None
    # Each pass's heading frame is where the body faces on it (`features.heading_of`, as for a
    # straight clip), so that the root channels keep their sign convention (walking backwards
    # has root.vz < 0).
    heads = [heading_of(clip[a:b], body_map=body_map) for a, b in passes]
    blocks = []
    names = None
    for (a, b), h, (lft, rgt) in zip(passes, heads, strikes):
        sub = clip[a:b]
        ok = ~M.glitch_frames(sub)
        xk, names = features_from_motion(sub, representation, heading_rad=h, valid=ok, body_map=body_map)
        blocks.append((xk, ok, np.asarray(lft, int), np.asarray(rgt, int)))
    layout = layout_passes(passes, [bl[2] for bl in blocks], T, heads, lengths=[len(bl[0]) for bl in blocks])
    rows = layout.offsets[-1] + len(blocks[-1][0])
    x = np.zeros((rows, blocks[0][0].shape[1]))
    keep = np.zeros(rows, bool)
    filled = np.zeros(rows, bool)
    left, right = [], []
    for (xk, ok, lft, rgt), o in zip(blocks, layout.offsets):
        x[o:o + len(xk)] = xk
        keep[o:o + len(xk)] = ok
        filled[o:o + len(xk)] = True
        left += list(o + lft)
        right += list(o + rgt)
    # Masked rows between passes hold the previous pass's last frame.
    last = np.maximum.accumulate(np.where(filled, np.arange(rows), 0))
    x = x[last]
    x = _join_branches(x, clip.topology, representation, keep)
    a0, b0 = lo + passes[0][0], lo + passes[-1][1]
    omega = 2 * np.pi / (T * clip.frame_time_s)
    return (layout, a0, b0, clip[passes[0][0]:passes[-1][1]], x, names, np.asarray(left, int),
            np.asarray(right, int), float(omega), keep)


def pass_mask(layout: PassLayout) -> Bool[np.ndarray, " T"]:
    """``bool [T]``: True on the rows of the fitting time axis that hold a pass."""
    rows = layout.offsets[-1] + layout.passes[-1][1] - layout.passes[-1][0]
    out = np.zeros(rows, bool)
    for (a, b), o in zip(layout.passes, layout.offsets):
        out[o:o + b - a] = True
    return out


def check_mode(passes) -> None:
    """Refuse a ``passes`` argument of `motion.fit_motions` that is not one of `PASS_MODES`."""
    if passes not in PASS_MODES:
        raise UserError(f"fit_motions: passes={passes!r} is not one of {PASS_MODES}")

