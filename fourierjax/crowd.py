"""A crowd: many Fourier-animated characters of one skeleton, synthesized and posed per frame."""

from __future__ import annotations

from typing import NamedTuple

import equinox as eqx
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float

from fourierjax import _jit
from fourierjax._sincos import sincos_degrees as _sincos_degrees
from fourierjax.errors import UserError
from fourierjax.fourier import FourierModel
from fourierjax.skeleton import Skeleton, Topology

__all__ = ["Crowd", "make_crowd", "crowd_positions"]

# Layout and why (measured on 2 CPU cores, 10,000 characters, CMU 07_01: 31 joints, 96
# channels; see experiments/benchmarks/crowd.py):
#
# * Characters are the last (minor) axis of every array, so each step of synthesis and FK is one
#   elementwise loop over characters (AVX lanes), with joints and channels unrolled over the
#   static topology: no scatters, no 3x3 dot_generals, and one static gather (the output rows
#   back to file order).
# * Only the channels that move a joint are synthesized: rotations of joints with children and
#   position channels (a leaf joint's rotation moves nothing but its End Site).
# * Per character and frame: one sin/cos of the phase, harmonics by the angle-addition
#   recurrence, one shared range reduction (in degrees) per Euler angle; rotations are built from
#   the elementary matrices of each joint's own channel order and composed entry by entry.
# * Joints are posed level by level: the joints of one depth that share a rotation order (and
#   position channels) are one block of `[n, B]` arrays, so the graph has one set of entry
#   computations per block, not per joint (same speed, fewer ops to compile).
# * XLA fuses every cheap producer into each of its consumers, so an unrolled hierarchy gets
#   recomputed from the root for every output entry (68 ms per frame instead of about 6 ms),
#   and the phase basis (`jnp.sin`, slow on CPU) gets recomputed for every channel. `keep`
#   (from `_keeper`) stops that: a division is "expensive" to XLA, which then never duplicates
#   it into several consumers, so each kept value is computed once and stored. The divisor is a
#   runtime 1 (`1 + 0 * t`: XLA does not fold `0 * t` for floats), so the division survives
#   algebraic simplification; it only changes speed, never values.
# * The output is stored as one `[J * 3, B]` block and transposed once to `[B, J, 3]`.


class Crowd(eqx.Module):
    """Many characters of one skeleton, each a Fourier model, laid out for posing per frame.

    Build it once with `make_crowd`; pose it every frame with `crowd_positions`. Arrays put the
    character axis last (`B`). Only the channels that move joints are kept (`channel_index`).

    - `coefficients`: `[2N + 1, K, B]` linear Fourier coefficients of the kept channels, in the
      channels' units (degrees for rotations, file units for positions): row 0 the offset
      `A0`, rows `1..N` the sine and rows `N+1..2N` the cosine coefficients
      (`x = A0 + sum_n a_n sin(n theta) + b_n cos(n theta)`, Unuma 1995 eq. 1 in linear form).
    - `omega`: `[B]` fundamental of each character (rad/s); `theta = omega * t`.
    - `bone_offsets`: `[J, 3]` the skeleton's OFFSETs (file units).
    - `topology`: the static `Topology`.
    - `channel_index`: static; the model channel of each kept row: first the rotation channels
      of joints with children, grouped by hierarchy level and rotation order (each rotation
      slot of a group is a contiguous block of rows), then every position channel.
    """

    coefficients: Float[Array, "P K B"]
    omega: Float[Array, " B"]
    bone_offsets: Float[Array, "J 3"]
    topology: Topology = eqx.field(static=True)
    channel_index: tuple[int, ...] = eqx.field(static=True)

    @property
    def num_characters(self) -> int:
        return self.omega.shape[-1]

    @property
    def num_harmonics(self) -> int:
        return (self.coefficients.shape[0] - 1) // 2

    def __check_init__(self):
        p, k = self.coefficients.shape[:2] if self.coefficients.ndim == 3 else (None, None)
        if self.coefficients.ndim != 3 or p % 2 != 1 or k != len(self.channel_index):
            raise UserError(
                f"Crowd: `coefficients` has shape {self.coefficients.shape}, expected "
                f"(2N + 1, {len(self.channel_index)}, B)"
            )
        if self.omega.shape != self.coefficients.shape[2:]:
            raise UserError(
                f"Crowd: `omega` has shape {self.omega.shape}, expected "
                f"({self.coefficients.shape[2]},) (one per character)"
            )
        if self.bone_offsets.shape != (self.topology.num_joints, 3):
            raise UserError(
                f"Crowd: `bone_offsets` has shape {self.bone_offsets.shape}, expected "
                f"({self.topology.num_joints}, 3)"
            )


class _Group(NamedTuple):
    """Joints of one hierarchy level posed together (same rotation order and position axes)."""

    joints: tuple[int, ...]
    parents: tuple[int, ...]
    order: str  # rotation order applied ("" when none is needed)
    rot_row: int  # first row of slot 0; slot s of joint i is row rot_row + s * len(joints) + i
    pos_rows: tuple[tuple[int, int], ...]  # (axis, first row): axis of joint i is row + i
    has_child: bool


def _layout(topology: Topology) -> tuple[tuple[_Group, ...], tuple[int, ...], int]:
    """Static plan: `(groups, channel_index, num_rotation_rows)`, groups in level order.

    Only channels that move a joint are kept: rotations of joints with children (a leaf's
    rotation moves nothing but its End Site) and every position channel. Rows are ordered so
    that each group's rotation slot and position axis is one contiguous block of rows.
    """
    has_child = _has_child(topology)
    offsets = topology.channel_offsets
    keyed = []  # (joints, order, rotation channels per joint, position channel per axis)
    for level in topology.levels:
        groups: dict = {}
        for j in level:
            chans = topology.channels[j]
            rot = [offsets[j] + k for k, c in enumerate(chans) if c.endswith("rotation")]
            order = (topology.rotation_orders[j] or "") if has_child[j] else ""
            pos = {"XYZ".index(c[0]): offsets[j] + k for k, c in enumerate(chans) if c.endswith("position")}
            key = (order, tuple(sorted(pos)), has_child[j])
            groups.setdefault(key, []).append((j, rot if order else [], pos))
        keyed.extend((key, items) for key, items in groups.items())
    rows: list[int] = []
    rot_start = []
    for (order, _, _), items in keyed:
        rot_start.append(len(rows))
        for slot in range(len(order)):
            rows.extend(rot[slot] for _, rot, _ in items)
    num_rot = len(rows)
    out = []
    for ((order, axes, child), items), r0 in zip(keyed, rot_start):
        pos_rows = []
        for axis in axes:
            pos_rows.append((axis, len(rows)))
            rows.extend(pos[axis] for _, _, pos in items)
        joints = tuple(j for j, _, _ in items)
        out.append(_Group(joints, tuple(topology.parents[j] for j in joints), order, r0,
                          tuple(pos_rows), child))
    return tuple(out), tuple(rows), num_rot


def _has_child(topology: Topology) -> list[bool]:
    out = [False] * topology.num_joints
    for p in topology.parents:
        if p >= 0:
            out[p] = True
    return out


def make_crowd(skeleton: Skeleton, models: FourierModel) -> Crowd:
    """Lay out a batch of Fourier models of one skeleton's BVH channels as a `Crowd`.

    Each model animates every BVH channel of `skeleton` in file order and units (degrees for
    rotations, file units for positions), so that one frame of a character is
    `fourier.synthesize(model, t[None])[0]`, a valid `kinematics.joint_positions` input. The
    linear coefficients (`FourierModel.sin_cos`) are computed here once, not per frame.

    Arguments:
        skeleton: the skeleton every character shares (unbatched offsets `[J, 3]`).
        models: a `FourierModel` with a leading character axis (`fourier.stack_models`):
            offset `[B, C]`, amplitude and phase `[B, C, N]`, omega `[B]`, with `C` the skeleton's
            channel count. Gait fits (`motion.fit_motions`, models of features) become such models
            with `motion.channel_model`.

    Returns:
        a `Crowd` of `B` characters (arrays in the models' floating dtype).

    Raises:
        `UserError` naming `skeleton` or `models` when the shapes do not fit.
    """
    if not isinstance(skeleton, Skeleton):
        raise UserError(f"make_crowd: `skeleton` must be a Skeleton, got {type(skeleton).__name__}")
    if not isinstance(models, FourierModel):
        raise UserError(f"make_crowd: `models` must be a FourierModel, got {type(models).__name__}")
    topology = skeleton.topology
    if skeleton.offsets.shape != (topology.num_joints, 3):
        raise UserError(
            f"make_crowd: `skeleton` offsets have shape {skeleton.offsets.shape}; the crowd shares "
            f"one skeleton, expected ({topology.num_joints}, 3)"
        )
    if models.offset.ndim != 2:
        raise UserError(
            f"make_crowd: `models` need one leading character axis (fourier.stack_models); "
            f"offset has shape {models.offset.shape}"
        )
    num_chars, num_channels = models.offset.shape
    if num_channels != topology.num_channels:
        raise UserError(
            f"make_crowd: `models` have {num_channels} channels, the skeleton has "
            f"{topology.num_channels} BVH channels ({topology.num_joints} joints)"
        )
    if models.channel_names and tuple(models.channel_names) != topology.flat_channel_names:
        raise UserError(
            "make_crowd: `models` channel_names are not the skeleton's BVH channels "
            f"({topology.flat_channel_names[:3]}...); crowd models animate BVH channel values"
        )
    if num_chars == 0:
        raise UserError("make_crowd: `models` hold no characters")
    from fourierjax import _memory

    _memory.check_bytes(f"make_crowd: {num_chars} characters", _memory.crowd_bytes(num_chars, topology.num_joints),
                        hint="make a smaller crowd")
    dtype = jnp.result_type(models.offset.dtype, jnp.float32)
    _, index, _ = _layout(topology)
    a, b = models.sin_cos()  # [B, C, N]
    rows = np.asarray(index, np.int32)
    coef = jnp.concatenate([models.offset[:, None, :], jnp.swapaxes(a, 1, 2),
                            jnp.swapaxes(b, 1, 2)], axis=1)  # [B, 2N + 1, C]
    coef = jnp.transpose(coef[:, :, rows], (1, 2, 0)).astype(dtype)  # [2N + 1, K, B]
    return Crowd(
        coefficients=coef,
        omega=jnp.asarray(models.omega, dtype),
        bone_offsets=jnp.asarray(skeleton.offsets, dtype),
        topology=topology,
        channel_index=index,
    )


# Symbolic 3x3 matrices: nested lists whose entries are arrays or the Python ints 0 and 1, so
# that products with elementary rotations skip the known zeros and ones.
_IDENTITY = ((1, 0, 0), (0, 1, 0), (0, 0, 1))


def _elementary(axis: str, s, c):
    """Rotation about `axis` ("X", "Y" or "Z") by the angle with sine `s`, cosine `c`."""
    i = "XYZ".index(axis)
    m = [list(r) for r in _IDENTITY]
    u, v = (i + 1) % 3, (i + 2) % 3  # (u, v) cyclic after the axis: Rx acts on (y, z), ...
    m[u][u], m[v][v] = c, c
    m[u][v], m[v][u] = -s, s
    return m


def _matmul(a, b):
    out = [[0] * 3 for _ in range(3)]
    for i in range(3):
        for k in range(3):
            acc = 0
            for j in range(3):
                x, y = a[i][j], b[j][k]
                if _is(x, 0) or _is(y, 0):
                    continue
                term = y if _is(x, 1) else x if _is(y, 1) else x * y
                acc = term if _is(acc, 0) else acc + term
            out[i][k] = acc
    return out


def _is(x, value: int) -> bool:
    return isinstance(x, int) and x == value


def _channels(crowd: Crowd, t: Array, keep) -> tuple[Array, Array, Array]:
    """Kept channels at time `t`: `(x [K, B], sin, cos [R, B])`, sin/cos of the R rotation rows."""
    coef = crowd.coefficients
    num_harmonics = crowd.num_harmonics
    # Phase basis per character: one sin/cos, then the angle-addition recurrence.
    theta = crowd.omega * t
    s1, c1 = jnp.sin(theta), jnp.cos(theta)
    sines, cosines = [keep(s1)], [keep(c1)]
    for _ in range(1, num_harmonics):
        s, c = sines[-1], cosines[-1]
        sines.append(keep(s * c1 + c * s1))
        cosines.append(keep(c * c1 - s * s1))
    x = coef[0]
    for n in range(num_harmonics):
        x = x + coef[1 + n] * sines[n][None] + coef[1 + num_harmonics + n] * cosines[n][None]  # [K, B]
    num_rot = _layout(crowd.topology)[2]
    sin, cos = (keep(v) for v in _sincos_degrees(keep(x[:num_rot])))
    return x, sin, cos


def _keeper(t: Array):
    # A runtime 1: dividing by it marks a value to compute once and store (see the notes above).
    one = 1.0 + 0.0 * t

    def keep(x):
        return x if isinstance(x, int) else x / one

    return keep


def _pose(crowd: Crowd, t: Float[Array, ""]) -> Float[Array, "J 3 B"]:
    """World joint positions `[J, 3, B]` (characters last) at time `t` (seconds)."""
    topology = crowd.topology
    dtype = crowd.coefficients.dtype
    t = jnp.asarray(t, dtype)
    keep = _keeper(t)
    x, sin, cos = _channels(crowd, t, keep)
    groups = _layout(topology)[0]
    # One gather of the bone offsets into group order, then a slice per group.
    bone = crowd.bone_offsets[np.asarray([j for grp in groups for j in grp.joints])]
    first = np.cumsum([0] + [len(grp.joints) for grp in groups])
    where: dict[int, tuple[int, int]] = {}  # joint -> (group, index in group)
    world_r: list = []  # per group: 3x3 of [n, B] arrays (or 0/1)
    world_p: list = []  # per group: 3 of [n, B] arrays
    for g, grp in enumerate(groups):
        n = len(grp.joints)
        for i, j in enumerate(grp.joints):
            where[j] = (g, i)
        local_t: list = [bone[first[g]:first[g] + n, k:k + 1] for k in range(3)]
        for axis, row in grp.pos_rows:
            local_t[axis] = x[row:row + n]  # position channels replace the OFFSET component
        local_r = _IDENTITY
        for slot, axis in enumerate(grp.order):
            r0 = grp.rot_row + slot * n
            local_r = _matmul(local_r, _elementary(axis, sin[r0:r0 + n], cos[r0:r0 + n]))
        if grp.parents[0] < 0:  # a level-0 group: roots
            pos = local_t
            rot = local_r
        else:
            pr = [[_rows(world_r, where, grp.parents, i, k) for k in range(3)] for i in range(3)]
            pp = [_rows(world_p, where, grp.parents, i) for i in range(3)]
            pos = [pp[i] + _dot(pr[i], local_t) for i in range(3)]
            rot = pr if local_r is _IDENTITY else _matmul(pr, local_r)
        if grp.has_child:
            pos = [keep(v) for v in pos]
            rot = [[jnp.full((n, 1), float(e), dtype) if isinstance(e, int) else keep(e) for e in r]
                   for r in rot]
        world_r.append(rot if grp.has_child else None)
        world_p.append(pos)
    # Back to file order: one [J, 3, B] block in group order, then one static row permutation
    # (compiles faster than a concatenation of per-joint slices, at the same speed).
    num_chars = crowd.num_characters
    block = jnp.concatenate(
        [jnp.stack([jnp.broadcast_to(v, (len(grp.joints), num_chars)) for v in p], axis=1)
         for grp, p in zip(groups, world_p)], axis=0)
    order = np.asarray([j for grp in groups for j in grp.joints])
    return block if np.array_equal(order, np.arange(order.size)) else block[np.argsort(order)]


def _rows(world, where, parents, i, k=None):
    """Entry `(i, k)` (or component `i`) of each parent's world transform, stacked `[n, B]`."""
    src = [where[p] for p in parents]

    def entry(g):
        return world[g][i] if k is None else world[g][i][k]

    if all(s == src[0] for s in src):  # one parent for the whole group: broadcast its row
        g, idx = src[0]
        e = entry(g)
        return e if isinstance(e, int) else e[idx:idx + 1]
    pieces, run = [], None
    for g, idx in src:
        if run is not None and run[0] == g and run[2] == idx:
            run = (g, run[1], idx + 1)
            continue
        if run is not None:
            pieces.append(run)
        run = (g, idx, idx + 1)
    pieces.append(run)
    parts = [entry(g)[a:b] for g, a, b in pieces]
    return jnp.concatenate(parts, axis=0) if len(parts) > 1 else parts[0]


def _dot(row, vec):
    """`sum_k row[k] * vec[k]` skipping the symbolic zeros and ones of `row`."""
    acc = 0
    for a, v in zip(row, vec):
        if _is(a, 0):
            continue
        term = v if _is(a, 1) else a * v
        acc = term if _is(acc, 0) else acc + term
    return acc


def crowd_positions(crowd: Crowd, t: Float[Array, ""]) -> Float[Array, "B J 3"]:
    """World positions of every joint of every character at time `t` (jitted entry point).

    Per character: the channels of Unuma 1995 eq. 1 at `theta = omega t` (linear form, harmonics
    by recurrence from one sin/cos), then forward kinematics (BVH intrinsic Euler order per
    joint, position channels replacing OFFSET components). Equal to
    `kinematics.joint_positions(skeleton, jax.vmap(lambda m: fourier.synthesize(m, t[None])[0])(models))`
    for the skeleton and models the crowd was made from. Differentiable in `t` and in the
    crowd's arrays.

    Arguments:
        crowd: from `make_crowd`.
        t: scalar time in seconds (traced: a new time does not recompile).

    Returns:
        `[B, J, 3]` joint positions in file units, joints in file order.
    """
    if not isinstance(crowd, Crowd):
        raise UserError(f"crowd_positions: `crowd` must be a Crowd (make_crowd), got {type(crowd).__name__}")
    t = jnp.asarray(t, crowd.coefficients.dtype)
    if t.shape != ():
        raise UserError(f"crowd_positions: `t` must be a scalar time in seconds, got shape {t.shape}")
    return _positions_jit(crowd, t)


def _positions(crowd: Crowd, t: Array) -> Array:
    pose = _pose(crowd, t)
    num_joints = pose.shape[0]
    # Store the [J * 3, B] block, then one 2-D transpose: XLA emits a tiled transpose for it
    # (0.4 ms at 10,000 characters) instead of fusing the concatenation into a strided
    # [B, J, 3] loop (6 ms).
    flat = _keeper(t)(pose.reshape(num_joints * 3, -1))
    return flat.T.reshape(-1, num_joints, 3)


# `_jit.jit` (the one wrapper's mechanism over `jax.jit`; the crowd is all arrays): called once per
# frame, where `filter_jit`'s argument filtering cost ~150 us a call. XLA's default CPU fusion
# emitters (`cpu_compiler_options={}`) run this graph faster (8.5 vs 12 ms per frame at 10,000
# characters) and compile it faster (5.8 vs 7.2 s) than the classic ones of
# `CPU_COMPILER_OPTIONS` (measured on the shared 2-core machine).
_positions_jit = _jit.jit(_positions, cpu_compiler_options={})
