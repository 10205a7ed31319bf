"""The one forward-kinematics formulation: joints by depth level, batch axes minor, quaternions."""

from __future__ import annotations

import functools
import operator
from typing import NamedTuple

import jax.numpy as jnp
import numpy as np
from jax import lax

from fourierjax._sincos import half_angle_sincos_degrees, sincos_degrees
from fourierjax.skeleton import Topology

# Arrays here are "components": one array per quaternion or vector component, joints first and
# the batch axes (frames or characters) after them, `[n, *S]`. Every step of the hierarchy is
# then an elementwise loop over `[n, *S]` (vector lanes over the batch), with the joints of one
# depth level in one block: a graph of one set of ops per level, not per joint, which keeps
# compile time small (fully unrolled per-joint graphs took 6-17 s to compile on 2 cores). A
# component may also be the Python int 0 or 1 (a known zero or one, skipped by the products).


class _Rot(NamedTuple):
    """Joints `[start, stop)` of a level rotated by `order`; slot `s` of joint `start + i` is
    rotation row `row + s * (stop - start) + i`."""

    order: str
    start: int
    stop: int
    row: int


class _Seg(NamedTuple):
    """Joints `[start, stop)` of a level whose translation component comes from position rows
    `row, row + 1, ...` (`row` -1: from the OFFSETs)."""

    start: int
    stop: int
    row: int


class _Level(NamedTuple):
    joints: tuple[int, ...]  # file indices: joints with a needed world rotation first
    num_rotated: int  # joints [0, num_rotated) carry a world rotation forward
    parents: tuple[tuple[int, int, int], ...]  # runs (start, count, step) into the previous level
    rots: tuple[_Rot, ...]
    pos: tuple[tuple[_Seg, ...], ...]  # per axis


class Plan(NamedTuple):
    """Static FK plan of a topology: levels, and the channel of each input row (`rows`: first
    the rotation rows, `num_rot` of them, then the position rows)."""

    levels: tuple[_Level, ...]
    rows: tuple[int, ...]
    num_rot: int
    order: tuple[int, ...]  # file index of each joint in level order
    inverse: tuple[int, ...]  # level-order position of each file joint


@functools.cache
def plan(topology: Topology, all_rotations: bool = True) -> Plan:
    """The static plan of `topology` (cached: the topology is hashable).

    Arguments:
        topology: the skeleton's static structure.
        all_rotations: also compose the world rotation of joints without children (needed for
            rotation outputs and End Sites); with False only rotations that move a joint are
            read and composed (the crowd, `joint_positions`).

    Returns:
        the `Plan`.
    """
    parents = topology.parents
    has_child = [False] * topology.num_joints
    for p in parents:
        if p >= 0:
            has_child[p] = True
    for p in topology.end_site_parents if all_rotations else ():
        has_child[p] = True
    offsets = topology.channel_offsets
    rot_ch = [[offsets[j] + k for k, c in enumerate(ch) if c.endswith("rotation")]
              for j, ch in enumerate(topology.channels)]
    pos_ch = [{"XYZ".index(c[0]): offsets[j] + k for k, c in enumerate(ch) if c.endswith("position")}
              for j, ch in enumerate(topology.channels)]
    rotated = [has_child[j] or all_rotations for j in range(topology.num_joints)]
    where: dict[int, int] = {}  # joint -> index within its level
    raw = []
    for level in topology.levels:
        def key(j):
            order = topology.rotation_orders[j] if rotated[j] else None
            return (not rotated[j], order or "", tuple(sorted(pos_ch[j])), where.get(parents[j], -1), j)

        joints = tuple(sorted(level, key=key))
        for i, j in enumerate(joints):
            where[j] = i
        raw.append(joints)
    rot_rows: list[int] = []
    pos_rows: list[int] = []
    levels = []
    for joints in raw:
        num_rotated = sum(rotated[j] for j in joints)
        rots = []
        i = 0
        while i < num_rotated:
            order = topology.rotation_orders[joints[i]]
            k = i
            while k < num_rotated and topology.rotation_orders[joints[k]] == order:
                k += 1
            if order:
                rots.append(_Rot(order, i, k, len(rot_rows)))
                for slot in range(len(order)):
                    rot_rows.extend(rot_ch[j][slot] for j in joints[i:k])
            i = k
        pos = []
        for axis in range(3):
            segs = []
            i = 0
            while i < len(joints):
                has = axis in pos_ch[joints[i]]
                k = i
                while k < len(joints) and (axis in pos_ch[joints[k]]) == has:
                    k += 1
                segs.append(_Seg(i, k, len(pos_rows) if has else -1))
                if has:
                    pos_rows.extend(pos_ch[j][axis] for j in joints[i:k])
                i = k
            pos.append(tuple(segs))
        levels.append(_Level(joints, num_rotated, _runs([where.get(parents[j], -1) for j in joints]),
                             tuple(rots), tuple(pos)))
    order = tuple(j for joints in raw for j in joints)
    inverse = tuple(int(i) for i in np.argsort(order))
    num_rot = len(rot_rows)
    return Plan(tuple(levels), tuple(rot_rows + pos_rows), num_rot, order, inverse)


def _runs(src: list[int]) -> tuple[tuple[int, int, int], ...]:
    """`src` as runs `(start, count, step)`, step 1 (consecutive) or 0 (one row repeated)."""
    runs: list[list[int]] = []
    for s in src:
        if runs:
            start, count, step = runs[-1]
            if count == 1 and s in (start, start + 1):
                runs[-1] = [start, 2, s - start]
                continue
            if s == start + count * step and step == 1 or (step == 0 and s == start):
                runs[-1][1] += 1
                continue
        runs.append([s, 1, 1])
    return tuple(tuple(r) for r in runs)


def store(x):
    """`x / (1 + 0 x)`: the value of `x`, computed once and stored (a `keep` for `world`).

    A division is too expensive for XLA to duplicate into each consumer, and `1 + 0 x` is not
    folded for floats (`0 x` is nan for infinite `x`). Speed only: finite values are unchanged.
    """
    return lax.div(x, lax.add(1.0, lax.mul(0.0, x)))  # lax: see `_same`


def _is(x, value: int) -> bool:
    return isinstance(x, int) and x == value


# The products and sums below bind lax primitives (the program is the one `*`, `+` and `-` would
# make, operands broadcast as jnp does): each jnp ufunc traces through a `jit` of its own, which
# cost 2-3x the op itself (a 1,200-op FK traced in 78 against 48 ms on 2 cores).
def _binary(name: str, u, v):
    lax_op, jnp_op, py_op = _OPS[name]
    u_num, v_num = isinstance(u, (int, float)), isinstance(v, (int, float))
    if (u_num or isinstance(u, np.ndarray)) and (v_num or isinstance(v, np.ndarray)):
        return py_op(u, v)  # constants stay Python or NumPy (folded into the program)
    if u_num or v_num:
        array = v if u_num else u
        if not jnp.issubdtype(array.dtype, jnp.floating):
            return jnp_op(u, v)
        return lax_op(float(u), v) if u_num else lax_op(u, float(v))
    if u.ndim != v.ndim or u.dtype != v.dtype:  # anything else as jnp does it
        return jnp_op(u, v)
    return lax_op(u, v)  # lax broadcasts axes of size 1 between operands of one rank, as jnp


_OPS = {
    "add": (lax.add, jnp.add, operator.add),
    "sub": (lax.sub, jnp.subtract, operator.sub),
    "mul": (lax.mul, jnp.multiply, operator.mul),
}


def _add(u, v):
    return _binary("add", u, v)


def _sub(u, v):
    return _binary("sub", u, v)


def _mul(u, v):
    if _is(u, 0) or _is(v, 0):
        return 0
    if _is(u, 1):
        return v
    if _is(v, 1):
        return u
    return _binary("mul", u, v)


def _sum(*signed):
    out = 0
    for sign, t in signed:
        if _is(t, 0):
            continue
        if _is(out, 0):
            out = t if sign > 0 else (-t if isinstance(t, (int, np.ndarray)) else lax.neg(t))
        else:
            out = _add(out, t) if sign > 0 else _sub(out, t)
    return out


def _rows(a, start: int, stop: int):
    """`a[start:stop]` (rows of the leading axis) as one `slice`, without jnp's indexing."""
    if start == 0 and stop == a.shape[0]:
        return a
    if isinstance(a, np.ndarray):  # a constant stays NumPy (folded into the program)
        return a[start:stop]
    return lax.slice(a, (start, *(0,) * (a.ndim - 1)), (stop, *a.shape[1:]))


def qmul(a, b):
    """Hamilton product of component lists (wxyz); known zeros and ones are skipped."""
    w1, x1, y1, z1 = a
    w2, x2, y2, z2 = b
    return [
        _sum((1, _mul(w1, w2)), (-1, _mul(x1, x2)), (-1, _mul(y1, y2)), (-1, _mul(z1, z2))),
        _sum((1, _mul(w1, x2)), (1, _mul(x1, w2)), (1, _mul(y1, z2)), (-1, _mul(z1, y2))),
        _sum((1, _mul(w1, y2)), (-1, _mul(x1, z2)), (1, _mul(y1, w2)), (1, _mul(z1, x2))),
        _sum((1, _mul(w1, z2)), (1, _mul(x1, y2)), (-1, _mul(y1, x2)), (1, _mul(z1, w2))),
    ]


def qapply(q, v):
    """`v` (3 components) rotated by the unit quaternion `q` (4): `v + 2w (u x v) + 2u x (u x v)`."""
    w, x, y, z = q
    if all(_is(c, 0) for c in (x, y, z)):
        return list(v)
    vx, vy, vz = v
    tx = _mul(2, _sum((1, _mul(y, vz)), (-1, _mul(z, vy))))
    ty = _mul(2, _sum((1, _mul(z, vx)), (-1, _mul(x, vz))))
    tz = _mul(2, _sum((1, _mul(x, vy)), (-1, _mul(y, vx))))
    return [
        _sum((1, vx), (1, _mul(w, tx)), (1, _mul(y, tz)), (-1, _mul(z, ty))),
        _sum((1, vy), (1, _mul(w, ty)), (1, _mul(z, tx)), (-1, _mul(x, tz))),
        _sum((1, vz), (1, _mul(w, tz)), (1, _mul(x, ty)), (-1, _mul(y, tx))),
    ]


def _broadcast(x, shape):
    """`jnp.broadcast_to(x, shape)` for `x` of the same rank, as one lax op."""
    if x.shape == shape:
        return x
    if isinstance(x, np.ndarray) or x.ndim != len(shape):
        return jnp.broadcast_to(x, shape)
    return lax.broadcast_in_dim(x, shape, tuple(range(x.ndim)))


def _concat(parts):
    """`jnp.concatenate(parts, axis=0)`, as one lax op for jax arrays of one dtype."""
    if any(isinstance(p, np.ndarray) or p.dtype != parts[0].dtype for p in parts):
        return jnp.concatenate(parts, axis=0)
    return lax.concatenate(parts, 0)


def _column(a, start: int, stop: int, axis: int, dtype, ones):
    """`a[start:stop, axis].astype(dtype).reshape(-1, *ones)` in lax ops (the same program)."""
    if isinstance(a, np.ndarray):
        return a[start:stop, axis].astype(dtype).reshape(-1, *ones)
    column = lax.squeeze(lax.slice(a, (start, axis), (stop, axis + 1)), (1,))
    return lax.reshape(column.astype(dtype), (stop - start, *ones))


def _take(a, runs):
    """Rows of `a` `[n, *S]` by static runs (slices and broadcasts, no gather)."""
    if isinstance(a, int):
        return a
    parts = []
    for start, count, step in runs:
        if step == 1:
            parts.append(_rows(a, start, start + count))
        else:
            parts.append(_broadcast(_rows(a, start, start + 1), (count, *a.shape[1:])))
    return parts[0] if len(parts) == 1 else _concat(parts)


def _cat(parts, shape, dtype):
    """Concatenate `(n_i, component)` pieces into `[sum n_i, *S]` (a Python int when all
    pieces are that same int)."""
    values = [c for _, c in parts]
    if all(isinstance(c, int) for c in values) and len(set(values)) == 1:
        return values[0]
    if len(parts) == 1:
        return values[0]
    return jnp.concatenate([jnp.broadcast_to(jnp.asarray(c, dtype), (n, *shape)) for n, c in parts], axis=0)


def local_quats(level: _Level, sin, cos, shape, dtype):
    """Local rotations (4 components `[num_rotated, *S]`) of a level from half-angle sin/cos rows."""
    n = level.num_rotated
    if n == 0:
        return [1, 0, 0, 0]
    pieces: list[tuple[int, list]] = []
    at = 0
    for r in level.rots:
        if r.start > at:
            pieces.append((r.start - at, [1, 0, 0, 0]))
        m = r.stop - r.start
        q = [1, 0, 0, 0]
        for slot, axis in enumerate(r.order):
            row = r.row + slot * m
            e = [_rows(cos, row, row + m), 0, 0, 0]
            e[1 + "XYZ".index(axis)] = _rows(sin, row, row + m)
            q = qmul(q, e)
        pieces.append((m, q))
        at = r.stop
    if at < n:
        pieces.append((n - at, [1, 0, 0, 0]))
    return [_cat([(m, q[k]) for m, q in pieces], shape, dtype) for k in range(4)]


def local_translations(level: _Level, pos, bone_offsets, shape, dtype):
    """Local translations (3 components `[n, *S]` or `[n, 1...]`) of a level; `bone_offsets`
    `[n, 3]` are the level's OFFSETs."""
    ones = (1,) * len(shape)
    out = []
    for axis in range(3):
        segs = level.pos[axis]
        parts = []
        for s in segs:
            if s.row < 0:
                parts.append(_column(bone_offsets, s.start, s.stop, axis, dtype, ones))
            else:
                parts.append(_rows(pos, s.row, s.row + s.stop - s.start))
        if len(parts) == 1:
            out.append(parts[0])
        else:
            out.append(_concat([_broadcast(p, (p.shape[0], *shape)) for p in parts]))
    return out


def world(the_plan: Plan, local_q, local_t, *, keep=None):
    """World rotations and positions, level by level, from per-level local poses.

    Arguments:
        the_plan: from `plan`.
        local_q: per level, 4 components `[num_rotated, *S]` (local rotations, wxyz).
        local_t: per level, 3 components `[n, *S]` (local translations; may broadcast).
        keep: when given, applied to each component of each level's world pose, which the
            next level reads: a function that marks a value to compute once and store (XLA
            duplicates cheap producers into every consumer, which recomputes an unrolled
            hierarchy from the root for every level; see `store`).

    Returns:
        `(q, p)`: per level, the world rotations (4 components `[num_rotated, *S]`) and
        positions (3 components `[n, *S]`).
    """
    out_q, out_p = [], []
    prev_q = prev_p = None
    for d, level in enumerate(the_plan.levels):
        lq, lt = local_q[d], local_t[d]
        if prev_q is None:
            q, p = lq, list(lt)
        else:
            pq = [_take(c, level.parents) for c in prev_q]
            pp = [_take(c, level.parents) for c in prev_p]
            pq_rot = [c if isinstance(c, int) else _rows(c, 0, level.num_rotated) for c in pq]
            q = qmul(pq_rot, lq) if level.num_rotated else [1, 0, 0, 0]
            p = [_add(a, b) for a, b in zip(pp, qapply(pq, lt))]
        if keep is not None:
            q = [c if isinstance(c, int) else keep(c) for c in q]
            p = [keep(c) for c in p]
        out_q.append(q)
        out_p.append(p)
        prev_q, prev_p = q, p
    return out_q, out_p


def pose_rows(the_plan: Plan, x, bone_offsets, *, keep=None, sincos=None, signed=True):
    """World pose of input rows `x` `[R, *S]` (rows as `the_plan.rows`, rotations in degrees).

    Arguments:
        the_plan: from `plan`.
        x: `[R, *S]` channel values in plan row order (degrees; positions in file units).
        bone_offsets: `[J, 3]` OFFSETs.
        keep: see `world`.
        sincos: `(sin, cos)` of the half-angles of the rotation rows; default from `x`.
        signed: with False, the default `sincos` may be both negated per angle
            (`half_angle_sincos_degrees`: no quadrant fix-up): each world rotation is then
            `q` or `-q`, the same rotation, and the positions are unchanged.

    Returns:
        `(q, p)` per level, as `world`.
    """
    shape, dtype = x.shape[1:], x.dtype
    if sincos is None:
        rows = _rows(x, 0, the_plan.num_rot)
        sincos = sincos_degrees(0.5 * rows) if signed else half_angle_sincos_degrees(rows)
    sin, cos = sincos
    if keep is not None:
        # One stored block: both come from one range reduction. Behind an optimization
        # barrier, not `keep`: `store`'s division made XLA:CPU write the block and then read it
        # again to divide it, a second pass over the largest array of the pose (a barrier is a
        # no-op at run time that fusion cannot cross). The pose ran 23-25% faster (CMU 07_01,
        # 2048 and 8192 frames, 31 interleaved rounds at load 7.6 on 2 cores: 754 -> 584 us and
        # 2697 -> 2019 us), with identical values.
        both = lax.optimization_barrier(_concat([sin, cos]))
        sin, cos = _rows(both, 0, the_plan.num_rot), _rows(both, the_plan.num_rot, both.shape[0])
    pos = _rows(x, the_plan.num_rot, x.shape[0])
    lq = [local_quats(lv, sin, cos, shape, dtype) for lv in the_plan.levels]
    offsets = bone_offsets[np.asarray(the_plan.order)]  # [J, 3] in level order: one gather
    lt, at = [], 0
    for lv in the_plan.levels:
        lt.append(local_translations(lv, pos, offsets[at:at + len(lv.joints)], shape, dtype))
        at += len(lv.joints)
    return world(the_plan, lq, lt, keep=keep)


def positions(the_plan: Plan, x, bone_offsets, *, sincos=None):
    """World joint positions `[J, 3, *S]` (file order) of input rows `x` `[R, *S]`.

    The FK of every batched entry point: `kinematics.joint_positions`, `fk_frames` (positions
    of a plan without leaf rotations), `joint_positions_frames_last` and the crowd. Batch axes
    minor, each level's world pose computed once and stored (`store`).

    Arguments:
        the_plan: from `plan` (`all_rotations=False` reads only the rotations that move a joint).
        x: `[R, *S]` channel values in plan row order, as `pose_rows`.
        bone_offsets: `[J, 3]` OFFSETs.
        sincos: as `pose_rows`.

    Returns:
        `[J, 3, *S]` positions in file units, joints in file order.
    """
    # Positions need each rotation only up to the sign of its quaternion.
    _, p = pose_rows(the_plan, x, bone_offsets, keep=store, sincos=sincos, signed=False)
    return gather_levels(the_plan, p, 3, False, x.shape[1:], x.dtype)


def gather_levels(the_plan: Plan, per_level, num_components: int, rotated_only: bool, shape, dtype):
    """Per-level components back to file order: `[J, num_components, *S]`."""
    comps = []
    for k in range(num_components):
        parts = []
        for level, c in zip(the_plan.levels, per_level):
            n = level.num_rotated if rotated_only else len(level.joints)
            if n:
                parts.append(jnp.broadcast_to(jnp.asarray(c[k], dtype), (n, *shape)))
        comps.append(jnp.concatenate(parts, axis=0) if len(parts) > 1 else parts[0])
    inverse = np.asarray(the_plan.inverse)
    if not np.array_equal(inverse, np.arange(inverse.size)):
        comps = [c[inverse] for c in comps]
    return jnp.stack(comps, axis=1)
