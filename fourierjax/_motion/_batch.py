"""The stages before the fit for a whole chunk of clips at once: one concatenated pass per skeleton."""

from __future__ import annotations

import dataclasses
import os

import numpy as np

from fourierjax._fourier._layout import (
    ROW_BLOCK,
    ancestors,
    relative_position,
    rot,
    rot_blocks,
    rotation_joints,
    world_pose,
    yaw_quat,
)
from fourierjax._motion._segment import feature_mask, steady_from_positions
from fourierjax.features import ROOT_CHANNELS, channel_names_for, check_static_above


@dataclasses.dataclass
class _Item:
    """A clip of the chunk on its way: frames ``[lo, hi)`` of ``motion`` (``clip``), the steady
    segment ``[a, b)`` of ``clip`` once found."""

    index: int
    motion: object
    lo: int
    clip: object
    body_map: object
    a: int = 0
    b: int = 0


def prepare_chunk(entries, *, representation, segment, use_contacts, start_frame, stop_frame,
                  timings, passes="longest") -> list:
    """`_pipeline._prepare` of every ``(index, motion or path, body map or None)`` of
    ``entries``, with the same results: clips that share a skeleton (topology and offsets) go
    through the steady segment, glitch masks, features and contacts together, as array ops
    over their concatenated frames (one call per rotation function and one FK per chunk, not
    per clip). Clips the batched path does not cover (no body map, not Y up, a trajectory joint
    off the pelvis's chain, ``passes="auto"``, under 3 frames) take the per-clip path."""
    from fourierjax._motion._clip import _frame_range
    from fourierjax._motion._pipeline import _Clock, _prepare
    from fourierjax.io.bvh import read_bvh

    clock = _Clock(timings)
    opts = dict(representation=representation, segment=segment, use_contacts=use_contacts,
                start_frame=start_frame, stop_frame=stop_frame, timings=timings, passes=passes)
    done: dict[int, object] = {}
    groups: dict[tuple, list[_Item]] = {}
    read = []
    for index, m, bm in entries:
        if isinstance(m, (str, os.PathLike)):
            m = read_bvh(m)
            clock("read")
        lo, hi = _frame_range(m, start_frame, stop_frame)
        read.append((index, m, lo, m[lo:hi], bm))
    inferred = iter(infer_body_maps([clip for _, _, _, clip, bm in read if bm is None]))
    clock("body_map")
    for index, m, lo, clip, bm in read:
        given = bm
        if bm is None:
            bm = next(inferred)
        if not _batchable(clip, bm, representation, passes, segment):
            done[index] = _prepare(index, m, bm if bm is not None else given, **opts)
            clock = _Clock(timings)
            continue
        key = (clip.topology, clip.offsets.tobytes(), clip.end_site_offsets.tobytes(), bm.pelvis)
        groups.setdefault(key, []).append(_Item(index, m, lo, clip, bm))
    for items in groups.values():
        for c in _prepare_group(items, representation=representation, segment=segment,
                                use_contacts=use_contacts, timings=timings):
            done[c.index] = c
    return [done[index] for index, _, _ in entries]


def infer_body_maps(clips) -> list:
    """`fourierjax.body.infer_body_map` of each clip of ``clips`` (None where it raises a
    `BodyMapError`: no legs), with the same maps: the frames it poses of all the clips that
    share a skeleton (topology and offsets) go through FK together, in blocks of `ROW_BLOCK`
    rows, straight to NumPy (one FK call per clip cost more in its dispatch and the copies of
    its outputs than in the FK); each clip's map is then inferred from its own poses."""
    import jax

    from fourierjax._body._infer import infer_named_many
    from fourierjax.body import BodyMapError, _infer_from_fk, _moving, _sampled_frames
    from fourierjax.kinematics import _fk_frames_jit

    out: list = [None] * len(clips)
    groups: dict[tuple, list[int]] = {}
    for k, c in enumerate(clips):
        groups.setdefault((c.topology, c.offsets.tobytes(), c.end_site_offsets.tobytes()),
                          []).append(k)
    for ks in groups.values():
        frames = [_sampled_frames(clips[k].num_frames) for k in ks]
        # A clip shorter than the posed rows repeats frames (Bandai-1: 38% of the rows): FK of
        # each clip's distinct frames, then one gather of the rows in order.
        distinct = [np.unique(f, return_inverse=True) for f in frames]
        rows = np.concatenate([np.asarray(clips[k].channels)[u]
                               for k, (u, _) in zip(ks, distinct, strict=True)])
        first = np.cumsum([0] + [len(u) for u, _ in distinct])
        order = np.concatenate([first[i] + inv for i, (_, inv) in enumerate(distinct)])
        ch = np.zeros((-(-len(rows) // ROW_BLOCK) * ROW_BLOCK, rows.shape[1]),
                      jax.dtypes.canonicalize_dtype(rows.dtype))  # FK's dtype, as fk_frames
        ch[:len(rows)] = rows
        skeleton = clips[ks[0]].skeleton()
        blocks = [jax.tree.map(np.asarray, _fk_frames_jit(skeleton, ch[s:s + ROW_BLOCK]))
                  for s in range(0, len(ch), ROW_BLOCK)]
        # float64 once for the group, as `_infer_from_fk` converts each clip's rows
        fk = jax.tree.map(lambda *a: np.concatenate(a)[order].astype(np.float64), *blocks)
        topo, B, F = clips[ks[0]].topology, len(ks), len(frames[0])
        pres = _moments(topo, fk, B, F)
        # The maps of clips whose names decide the legs and head, all at once; the others (and
        # a clip whose geometry `infer` refuses) one by one, with the same `pre` rows.
        maps = infer_named_many(topo, fk.positions.reshape(B, F, *fk.positions.shape[1:]),
                                fk.rotations.reshape(B, F, *fk.rotations.shape[1:]),
                                [_moving(clips[k]) for k in ks], pres)
        for i, k in enumerate(ks):
            if maps[i] is not None:
                out[k] = maps[i]
                continue
            s = slice(i * F, (i + 1) * F)
            try:
                out[k] = _infer_from_fk(clips[k], jax.tree.map(lambda a, s=s: a[s], fk),
                                        pre={p: tuple(v[i] for v in r) for p, r in pres.items()})
            except BodyMapError:
                out[k] = None  # no legs: joint 0 carries the root, no contacts, no alignment
    return out


def _moments(topology, fk, num_clips: int, num_frames: int) -> dict:
    """`_body._infer.moments_arrays` of a skeleton's clips (``num_frames`` posed rows each, FK
    ``fk`` of them in order) about each pelvis that names decide: ``{pelvis: arrays}``."""
    from fourierjax._body._infer import moments_arrays, named_pelvises

    pelvises = named_pelvises(topology)
    if not pelvises:
        return {}
    B, F = num_clips, num_frames
    points = np.concatenate([fk.positions, fk.end_site_positions], axis=1)
    points = points.reshape(B, F, *points.shape[1:])
    rotations = fk.rotations.reshape(B, F, *fk.rotations.shape[1:])
    return {p: moments_arrays(points, rotations, p) for p in pelvises}


def _batchable(clip, bm, representation, passes, segment) -> bool:
    if bm is None or (segment and passes == "auto"):
        return False
    if (bm.up_axis, bm.up_sign) != (1, 1) or clip.num_frames < 3:
        return False
    return bm.trajectory == bm.pelvis or bm.trajectory in ancestors(clip.topology, bm.pelvis)


def _with_channels(motion, channels: np.ndarray):
    """``motion.with_channels(channels)`` for a float64 array made here and held nowhere else:
    frozen in place, not copied (a chunk's frames are copied once, not once per Motion)."""
    from fourierjax.io._bvh_motion import _owned_arrays

    with _owned_arrays():
        return motion.with_channels(channels)


def _concat(motions):
    """One Motion of all the frames of ``motions`` (one skeleton) and each one's first frame."""
    starts = np.cumsum([0] + [m.num_frames for m in motions])
    cat = _with_channels(motions[0], np.concatenate([m.channels for m in motions]))
    return cat, starts


# The concatenation's rows are padded to whole blocks of `ROW_BLOCK` for every JAX program (the
# rotation functions and FK) and cut back, so a chunk of any size, and one clip alone, run the
# same programs: an eager op on the concatenation's own length would compile again for every
# batch size (issue 25: a sweep of 8 to 500 clips compiled 21 programs).
def _blocked(a: np.ndarray) -> np.ndarray:
    """``a`` with its last row repeated up to a whole number of `ROW_BLOCK` rows."""
    rows = max(1, -(-len(a) // ROW_BLOCK)) * ROW_BLOCK
    return np.concatenate([a, np.repeat(a[-1:], rows - len(a), axis=0)])


def _rot(name: str, *arrays, **static) -> np.ndarray:
    """`rot` of the rows of ``arrays``, run in whole blocks (only the last one padded)."""
    return rot_blocks(name, arrays, static, whole_blocks=True)



def _blocked_motion(cat):
    """``cat`` with its frames padded like `_blocked` (pose functions of it: cut to
    ``cat.num_frames``)."""
    return _with_channels(cat, _blocked(cat.channels))


def _world_pose(cat, joint):
    pos, q = world_pose(_blocked_motion(cat), joint)
    return pos[:cat.num_frames], q[:cat.num_frames]


def _prepare_group(items: list[_Item], *, representation, segment, use_contacts, timings) -> list:
    from fourierjax._motion._clip import _steps
    from fourierjax._motion._pipeline import _Clip, _Clock

    clock = _Clock(timings)
    topo = items[0].clip.topology
    pelvis = items[0].body_map.pelvis
    dts = np.array([it.clip.frame_time_s for it in items])
    # -- steady segment: the pelvis's world track of every clip from one pass
    pose = None
    if segment:
        cat, starts = _concat([it.clip for it in items])
        pos, q = _world_pose(cat, pelvis)
        for k, it in enumerate(items):
            it.a, it.b = steady_from_positions(pos[starts[k]:starts[k + 1]][:, [0, 2]], dts[k])
        # The segments' rows of it, for the features (each frame's pose is its own: the
        # same values as the pose of the segments' concatenation, one FK pass fewer)
        rows = np.concatenate([np.arange(starts[k] + it.a, starts[k] + it.b)
                               for k, it in enumerate(items)])
        pose = pos[rows], q[rows]
    else:
        for it in items:
            it.a, it.b = 0, it.clip.num_frames
    subs = [it.clip[it.a:it.b] for it in items]
    clock("segment")
    cat, starts = _concat(subs)
    n = np.diff(starts)
    dt_f = np.repeat(dts, n)  # per frame
    glitch, quats = _glitch_joints(cat, starts, dt_f, dts)
    clock("glitch")
    x = _features(cat, starts, dt_f, items, subs, glitch, pelvis, representation, pose, quats)
    mask = feature_mask(glitch, topo, pelvis)
    names = channel_names_for(topo, representation)
    clock("features")
    contacts = _contacts(cat, starts, dts, items) if use_contacts else [None] * len(items)
    loops = _closed_loops(cat, starts) if use_contacts else [False] * len(items)
    out = []
    for k, it in enumerate(items):
        left, right, om = _steps(contacts[k], dts[k], loops[k])  # as _prepare
        s = slice(starts[k], starts[k + 1])
        out.append(_Clip(it.index, it.motion, it.a + it.lo, it.b + it.lo, subs[k], x[s],
                         names, mask[s], left, right, om, it.body_map))
    clock("contacts")
    return out


def _closed_loops(cat, starts) -> list[bool]:
    """`_clip.closed_loop` of every clip of the concatenation ``cat`` (its rotation channels'
    frame steps from one pass, each clip's median over its own)."""
    from fourierjax._motion._clip import _LOOP_SEAM

    rot = [k for k, c in enumerate(cat.topology.flat_channel_names) if c.endswith("rotation")]
    if not rot:
        return [False] * (len(starts) - 1)
    a = np.asarray(cat.channels)[:, rot]

    def rms(d):
        # `(d + 180) % 360` is `d + 180` itself where that lies in [0, 360) (nearly every
        # step): the float remainder only where it does not, the same values (a quarter of
        # the contacts stage went to `%` over every rotation channel of the chunk).
        r = d + 180.0
        out = (r < 0.0) | (r >= 360.0)
        if out.any():
            r[out] %= 360.0
        return np.sqrt(np.mean((r - 180.0) ** 2, axis=-1))

    steps = rms(np.diff(a, axis=0))  # row t: frame t + 1 minus frame t (across clips: unused)
    first, last = starts[:-1], starts[1:] - 1
    seams = rms(a[last] - a[first])
    out = []
    for k in range(len(first)):
        if last[k] - first[k] + 1 < 3:
            out.append(False)
            continue
        typical = float(np.median(steps[first[k]:last[k]]))
        out.append(typical > 0 and float(seams[k]) < _LOOP_SEAM * typical)
    return out


def _dilate(flags, starts, pad):
    """`_segment._dilate` of each clip's rows of ``flags [N, J]`` (clip k: rows
    ``[starts[k], starts[k + 1])``, ``pad`` frames per row), in one pass."""
    N = flags.shape[0]
    c = np.concatenate([np.zeros((1, flags.shape[1]), np.int64), np.cumsum(flags, axis=0)])
    t = np.arange(N)
    clip = np.searchsorted(starts, t, side="right") - 1
    hi = np.minimum(t + pad + 1, starts[clip + 1])
    lo = np.maximum(t - pad, starts[clip])
    return (c[hi] - c[lo]) > 0


def _glitch_joints(cat, starts, dt_f, dts, max_joint_speed_deg_s=5000.0, pad_s=0.1):
    """`_segment.glitch_joints` of every clip of the concatenation ``cat``, and the joints'
    quaternions it compares, ``{order: [N, J_order, 4]}`` (the expmap features start from
    the same ones)."""
    N, J = cat.num_frames, len(cat.topology.names)
    fast = np.zeros((N, J), bool)
    joints = rotation_joints(cat.topology)
    first = np.zeros(N, bool)
    first[starts[:-1]] = True  # no speed across two clips
    quats = {}
    for order in dict.fromkeys(o for _, o, _ in joints):
        group = [(j, i) for j, o, i in joints if o == order]
        q = _rot("quat_from_euler", np.radians(cat.channels[:, np.array([i for _, i in group])]),
                 order=order)
        quats[order] = q
        dot = np.clip(np.abs(np.sum(q[1:] * q[:-1], axis=-1)), 0.0, 1.0)
        f = np.degrees(2 * np.arccos(dot)) / dt_f[1:, None] > max_joint_speed_deg_s
        fast[1:, [j for j, _ in group]] = f & ~first[1:, None]
    pad = np.repeat(np.maximum(1, np.round(pad_s / dts).astype(int)), np.diff(starts))
    return _dilate(fast, starts, pad), quats


def _segment_sums(v, starts):
    return np.stack([v[starts[k]:starts[k + 1]].sum(axis=0) for k in range(len(starts) - 1)])


def _facing_locals(cat, starts, q, items) -> np.ndarray:
    """`RootJoints.facing_local` of each clip (`_fourier._layout.root_joints`): ``(left hip -
    right hip) x up`` in the pelvis's frame averaged over the clip's frames; ``[B, 3]``."""
    pelvis = items[0].body_map.pelvis
    hips = {(it.body_map.left.hip, it.body_map.right.hip) for it in items}
    lat = np.zeros((cat.num_frames, 3))
    blocked = _blocked_motion(cat)
    for lh, rh in hips:
        rows = np.concatenate([np.arange(starts[k], starts[k + 1]) for k, it in enumerate(items)
                               if (it.body_map.left.hip, it.body_map.right.hip) == (lh, rh)])
        d = relative_position(blocked, pelvis, lh) - relative_position(blocked, pelvis, rh)
        lat[rows] = d[rows]
    conj = q * np.array([1.0, -1.0, -1.0, -1.0])
    up = _rot("quat_apply", conj, np.tile([0.0, 1.0, 0.0], (len(q), 1)))
    cross = np.cross(lat, up)
    out = np.zeros((len(items), 3))
    for k in range(len(items)):
        f = cross[starts[k]:starts[k + 1]].mean(axis=0)
        nrm = np.linalg.norm(f)
        if not np.isfinite(nrm) or nrm < 1e-12:
            out[k] = (0.0, 0.0, 1.0)
            continue
        out[k] = f / nrm
    return out


def _gradient(v, starts, dt_f):
    """`np.gradient(v_k, dt_k)` of each clip's rows of ``v [N]`` (at least 2 per clip)."""
    g = np.empty_like(v)
    g[1:-1] = (v[2:] - v[:-2]) / (2.0 * dt_f[1:-1])
    first, last = starts[:-1], starts[1:] - 1
    g[first] = (v[first + 1] - v[first]) / dt_f[first]
    g[last] = (v[last] - v[last - 1]) / dt_f[last]
    return g


def _features(cat, starts, dt_f, items, subs, glitch, pelvis, representation,
              pose=None, quats=None) -> np.ndarray:
    """`features_from_motion(sub, representation, valid=~glitch, body_map=bm)` of every clip,
    rows concatenated ``[N, C]`` (expmap-valued layouts ignore ``valid``, as it does);
    ``pose``: the pelvis's world pose of ``cat``'s frames when known; ``quats``: the joints'
    quaternions of ``cat``'s frames by rotation order when known (`_glitch_joints`'), taken
    over (their pelvis column is overwritten)."""
    topo = cat.topology
    B = len(items)
    pos, q_root = _world_pose(cat, pelvis) if pose is None else pose
    facing = _facing_locals(cat, starts, q_root, items)
    for it, sub in zip(items, subs, strict=True):
        check_static_above(sub, _RJ(it.body_map.trajectory))
    n = np.diff(starts)
    f = _rot("quat_apply", q_root, np.repeat(facing, n, axis=0))
    s, c = _segment_sums(f[:, 0], starts), _segment_sums(f[:, 2], starts)
    psi = np.array([0.0 if np.hypot(s[k], c[k]) < 1e-9 * n[k] else float(np.arctan2(s[k], c[k]))
                    for k in range(B)])
    cf, sf = np.repeat(np.cos(psi), n), np.repeat(np.sin(psi), n)
    x_h = cf * pos[:, 0] - sf * pos[:, 2]
    z_h = sf * pos[:, 0] + cf * pos[:, 2]
    q_rel = _rot("quat_multiply", yaw_quat(np.repeat(-psi, n)), q_root)
    cols = [_gradient(x_h, starts, dt_f), _gradient(z_h, starts, dt_f), pos[:, 1]]
    joints = rotation_joints(topo)
    blocks = {}
    # Clips of similar lengths side by side (`_length_groups`): each column's continuity is its
    # own, so grouping changes no value, only the padding the array ops carry.
    layouts = []
    for g in _length_groups(n):
        rows = np.arange(int(n[g].max()))[:, None]
        index = np.minimum(rows, n[g][None, :] - 1) + starts[g][None, :]  # [T, G]: padded with the last
        layouts.append((index, rows < n[g][None, :]))
    for order in dict.fromkeys(o for _, o, _ in joints):
        group = [(j, idx) for j, o, idx in joints if o == order]
        members = [j for j, _ in group]
        e = np.radians(cat.channels[:, np.array([idx for _, idx in group])])
        if representation == "euler":
            if pelvis in members:
                e[:, members.index(pelvis)] = _rot("euler_from_quat", q_rel, order=order)
            flat = _euler_continuous(e, order, ~glitch[:, members], layouts)
        else:
            # The glitch masks' quaternions of the same angles when given: the same values,
            # one conversion of the chunk's frames fewer.
            q = quats[order] if quats is not None else _rot("quat_from_euler", e, order=order)
            if pelvis in members:
                q[:, members.index(pelvis)] = q_rel
            flat = _expmap_continuous(_rot("expmap_from_quat", q), layouts)
        for k, (j, _) in enumerate(group):
            blocks[j] = flat[:, k]
    for j, _, _ in joints:
        cols += [blocks[j][:, 0], blocks[j][:, 1], blocks[j][:, 2]]
    assert len(cols) == len(ROOT_CHANNELS) + 3 * len(joints)
    return np.stack(cols, axis=1)


def _euler_continuous(e, order, ok_all, layouts) -> np.ndarray:
    """`features.make_euler_continuous` of each clip's rows of ``e [N, J_g, 3]`` (``ok_all [N,
    J_g]``: valid), the clips of each layout side by side."""
    from fourierjax import rotations
    from fourierjax._eulerscan import continuous

    flat = np.empty_like(e)
    for index, valid in layouts:
        # [T, G * J_g, 3]: the group's clips' frames side by side; frames after a clip's end
        # repeat its last and come after it, so they never serve as a reference.
        T = len(index)
        padded = e[index].reshape(T, -1, 3)
        ok = ok_all[index].reshape(T, -1)
        ang = continuous(padded, rotations.euler_twin(padded.copy(), order), ok)
        flat[index[valid]] = ang.reshape(T, index.shape[1], e.shape[1], 3)[valid]
    return flat


#: Columns per call of the expmap continuity (`_expmap_continuous`): a fixed width, so that its
#: scan compiles once per length bucket, whatever the number of clips and joints.
EXPMAP_COLUMNS = 256


def _expmap_continuous(v, layouts) -> np.ndarray:
    """`rotations.make_expmap_continuous` of each clip's rows of ``v [N, J_g, 3]`` (as
    `features._joint_rotations` runs it, through `rot`), the clips of each layout side by side
    in blocks of `EXPMAP_COLUMNS` columns (each column's scan is its own: the blocks change no
    value)."""
    flat = np.empty_like(v)
    W = EXPMAP_COLUMNS
    for index, valid in layouts:
        T = len(index)
        padded = v[index].reshape(T, -1, 3)
        K = padded.shape[1]
        cols = np.minimum(np.arange(-(-K // W) * W), K - 1)  # padded with the last column
        # Not `_rot`: the scan runs over time, padded only to the group's length bucket.
        ang = np.concatenate([rot("make_expmap_continuous", padded[:, cols[s:s + W]])
                              for s in range(0, len(cols), W)], axis=1)[:, :K]
        flat[index[valid]] = ang.reshape(T, index.shape[1], v.shape[1], 3)[valid]
    return flat


def _length_groups(n, *, slack=1.25, pad=16) -> list[np.ndarray]:
    """The clips of lengths ``n [B]`` in groups of similar lengths (indices, ascending by
    length): a group's longest is at most ``slack`` times its shortest plus ``pad`` frames, so
    padding each group to its longest wastes little (one group for all of them padded 20 frames
    to 401 of Bandai's gaits: 2.8x the frames)."""
    order = np.argsort(n, kind="stable")
    groups, first = [], 0
    for k in range(1, len(order) + 1):
        if k == len(order) or n[order[k]] > slack * n[order[first]] + pad:
            groups.append(order[first:k])
            first = k
    return groups


@dataclasses.dataclass(frozen=True)
class _RJ:
    """The part of `RootJoints` that `features.check_static_above` reads."""

    trajectory: int


def _contacts(cat, starts, dts, items) -> list:
    """`foot_contacts_of(sub, body_map=bm)` of every clip: FK of all the frames (in blocks of
    `ROW_BLOCK`), then `contacts.foot_contacts_many`."""
    import jax.numpy as jnp

    from fourierjax import contacts
    from fourierjax.kinematics import fk_frames

    N, ch, skeleton = cat.num_frames, _blocked(cat.channels), cat.skeleton()
    blocks = [fk_frames(skeleton, jnp.asarray(ch[s:s + ROW_BLOCK])) for s in range(0, len(ch), ROW_BLOCK)]
    allp = np.concatenate([np.concatenate([np.asarray(fk.positions), np.asarray(fk.end_site_positions)], 1)
                           for fk in blocks])[:N]
    ps = []
    for k, it in enumerate(items):
        pts = contacts.foot_points(cat.topology, it.body_map)
        ps.append(allp[starts[k]:starts[k + 1]][:, np.asarray([pts.left, pts.right])])
    ups = {it.body_map.up_axis for it in items}
    assert len(ups) == 1  # Y up: checked by `_batchable`
    return contacts.foot_contacts_many(ps, list(dts), up_axis=ups.pop())
