"""Forward kinematics: BVH channels to local poses, local poses to world joint positions."""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float

from fourierjax import _jit, rotations
from fourierjax._sincos import sincos as _sincos
from fourierjax.errors import UserError
from fourierjax.skeleton import Skeleton, Topology

_AXIS_INDEX = {"X": 0, "Y": 1, "Z": 2}


class FKResult(eqx.Module):
    """World-space pose of one frame.

    - `rotations`: `[J, 4]` world orientation of every joint (unit quaternion, wxyz).
    - `positions`: `[J, 3]` world position of every joint.
    - `end_site_positions`: `[E, 3]` world position of every End Site (its orientation is its
      parent's).
    """

    rotations: Float[Array, "joints 4"]
    positions: Float[Array, "joints 3"]
    end_site_positions: Float[Array, "end_sites 3"]


def _elementary_quat(axis: str, angle: Float[Array, ...]) -> Float[Array, "... 4"]:
    half = 0.5 * angle
    c, s = jnp.cos(half), jnp.sin(half)
    zero = jnp.zeros_like(half)
    xyz = [zero, zero, zero]
    xyz[_AXIS_INDEX[axis]] = s
    return jnp.stack([c, *xyz], axis=-1)


def _channel_layout(topology: Topology):
    """Static index tables (numpy) for gathering channels into translations and rotations."""
    offsets = topology.channel_offsets
    # Position channels: (joint, axis, channel index).
    pos_joint, pos_axis, pos_chan = [], [], []
    # Rotation channels grouped by order: order -> (joints, [J_g, len(order)] channel indices).
    groups: dict[str, tuple[list[int], list[list[int]]]] = {}
    for j, chans in enumerate(topology.channels):
        rot_idx = []
        for k, c in enumerate(chans):
            if c.endswith("position"):
                pos_joint.append(j)
                pos_axis.append(_AXIS_INDEX[c[0]])
                pos_chan.append(offsets[j] + k)
            else:
                rot_idx.append(offsets[j] + k)
        order = topology.rotation_orders[j]
        if order is not None:
            joints, idx = groups.setdefault(order, ([], []))
            joints.append(j)
            idx.append(rot_idx)
    return (
        (np.array(pos_joint, dtype=np.int32), np.array(pos_axis, dtype=np.int32),
         np.array(pos_chan, dtype=np.int32)),
        {o: (np.array(js, dtype=np.int32), np.array(ix, dtype=np.int32)) for o, (js, ix) in groups.items()},
    )


def pose_from_channels(
    skeleton: Skeleton, channels: Float[Array, " channels"]
) -> tuple[Float[Array, "joints 3"], Float[Array, "joints 4"]]:
    """Local translations and rotations of one frame from its BVH channel values.

    Position channels replace the OFFSET components they name (they are the joint's local
    translation; adding them would double every bone in files that repeat the offsets).
    Rotation channels are degrees, applied in the listed order (BVH, intrinsic).

    Arguments:
        skeleton: the skeleton the channels belong to.
        channels: `[C]` one frame of channel values as stored in the file.

    Returns:
        `(translations [J, 3], quats [J, 4])`, local to each joint's parent.
    """
    topology = skeleton.topology
    channels = jnp.asarray(channels)
    if channels.shape != (topology.num_channels,):
        raise UserError(
            f"pose_from_channels: `channels` has shape {channels.shape}, expected "
            f"({topology.num_channels},) for one frame of this skeleton"
        )
    (pos_joint, pos_axis, pos_chan), groups = _channel_layout(topology)
    translations = skeleton.offsets.astype(channels.dtype)
    if pos_joint.size:
        translations = translations.at[pos_joint, pos_axis].set(channels[pos_chan])
    identity = jnp.zeros((topology.num_joints, 4), channels.dtype).at[:, 0].set(1.0)
    quats = identity
    for order, (joints, idx) in groups.items():
        angles = jnp.deg2rad(channels[idx])  # [J_g, len(order)]
        if len(order) == 3:
            q = rotations.quat_from_euler(angles, order)
        else:
            q = _elementary_quat(order[0], angles[:, 0])
            for k in range(1, len(order)):
                q = rotations.quat_multiply(q, _elementary_quat(order[k], angles[:, k]))
        quats = quats.at[joints].set(q)
    return translations, quats


def forward_kinematics(
    skeleton: Skeleton,
    translations: Float[Array, "joints 3"],
    quats: Float[Array, "joints 4"],
) -> FKResult:
    """World rotations and positions of every joint and End Site for one frame.

    Joints are posed level by level (all joints of one depth at once), composing rotations as
    quaternion products, which stays clear of the XLA CPU bug with batched 3x3 matmuls under
    nested vmap (see STYLE.md). Batch over frames and characters with `jax.vmap`.

    Arguments:
        skeleton: supplies the topology and the End Site offsets.
        translations: `[J, 3]` local translation of each joint (the root's is its world position).
        quats: `[J, 4]` local rotation of each joint (wxyz).

    Returns:
        an `FKResult`.
    """
    topology = skeleton.topology
    j = topology.num_joints
    if translations.shape != (j, 3) or quats.shape != (j, 4):
        raise UserError(
            f"forward_kinematics: expected translations ({j}, 3) and quats ({j}, 4), got "
            f"{translations.shape} and {quats.shape}"
        )
    parents = np.array(topology.parents)
    world_q = quats
    world_p = translations
    for level in topology.levels[1:]:
        idx = np.array(level)
        par = parents[idx]
        pq = world_q[par]
        world_q = world_q.at[idx].set(rotations.quat_multiply(pq, quats[idx]))
        world_p = world_p.at[idx].set(world_p[par] + rotations.quat_apply(pq, translations[idx]))
    if topology.num_end_sites:
        ep = np.array(topology.end_site_parents)
        end_sites = world_p[ep] + rotations.quat_apply(
            world_q[ep], skeleton.end_site_offsets.astype(world_p.dtype)
        )
    else:
        end_sites = jnp.zeros((0, 3), world_p.dtype)
    return FKResult(rotations=world_q, positions=world_p, end_site_positions=end_sites)


def fk_from_channels(skeleton: Skeleton, channels: Float[Array, " channels"]) -> FKResult:
    """`forward_kinematics` of one frame of BVH channel values (see `pose_from_channels`).

    Arguments:
        skeleton: the skeleton the channels belong to.
        channels: `[C]` one frame of channel values as stored in the file (degrees).

    Returns:
        The frame's `FKResult`.
    """
    return forward_kinematics(skeleton, *pose_from_channels(skeleton, channels))


# -------------------------------------------------------------------- batched fast path
#
# `fk_frames` / `joint_positions` pose many frames at once. Instead of vmapping the one-frame
# code (whose gathers and scatters run on `[frames, joints, 4]` with the frame axis outermost),
# they work on a joint-major, frame-minor layout (`[J, 4, M]`, M = all frames): every quaternion
# component is a contiguous vector over frames, so each step is a plain vectorised loop. The
# hierarchy is a `lax.scan` over joints (one small compiled body: compile time stays flat in
# the number of joints; unrolled elementwise graphs took minutes to compile here), and sines
# and cosines come from one shared range reduction (`_sincos`), because XLA's CPU `sin` is
# several times slower than the rest of FK put together.

def _qmul_sparse(a: list, b: list) -> list:
    """Hamilton product of component lists whose entries may be the Python int 0 (skipped)."""

    def term(u, v):
        return None if isinstance(u, int) or isinstance(v, int) else u * v

    def total(*signed):
        out = None
        for sign, t in signed:
            if t is None:
                continue
            out = (t if sign > 0 else -t) if out is None else (out + t if sign > 0 else out - t)
        return 0 if out is None else out

    w1, x1, y1, z1 = a
    w2, x2, y2, z2 = b
    return [
        total((1, term(w1, w2)), (-1, term(x1, x2)), (-1, term(y1, y2)), (-1, term(z1, z2))),
        total((1, term(w1, x2)), (1, term(x1, w2)), (1, term(y1, z2)), (-1, term(z1, y2))),
        total((1, term(w1, y2)), (-1, term(x1, z2)), (1, term(y1, w2)), (1, term(z1, x2))),
        total((1, term(w1, z2)), (1, term(x1, y2)), (-1, term(y1, x2)), (1, term(z1, w2))),
    ]


def _qapply_soa(q, v):
    """Rotate `v` (3 components) by unit quaternion `q` (4 components); components broadcast."""
    w, x, y, z = q
    vx, vy, vz = v
    tx, ty, tz = 2 * (y * vz - z * vy), 2 * (z * vx - x * vz), 2 * (x * vy - y * vx)
    return [vx + w * tx + (y * tz - z * ty), vy + w * ty + (z * tx - x * tz), vz + w * tz + (x * ty - y * tx)]


def _local_pose_soa(skeleton: Skeleton, x: Float[Array, "channels M"]):
    """Local rotations `[J, 4, M]` and translations `[J, 3, M]` of M frames of channels `[C, M]`."""
    topology = skeleton.topology
    num_joints, m, dtype = topology.num_joints, x.shape[1], x.dtype
    (pos_joint, pos_axis, pos_chan), groups = _channel_layout(topology)
    parts, part_joints = [], []
    for order, (joints, idx) in groups.items():
        half = x[idx.T] * np.asarray(np.pi / 360, dtype)  # [len(order), J_g, M] half-angles
        s, c = _sincos(half)
        q = None
        for k, axis in enumerate(order):
            e = [c[k], 0, 0, 0]
            e[1 + _AXIS_INDEX[axis]] = s[k]
            q = e if q is None else _qmul_sparse(q, e)
        zero = jnp.zeros((len(joints), m), dtype)
        parts.append(jnp.stack([zero if isinstance(t, int) else t for t in q], axis=1))
        part_joints.extend(joints.tolist())
    rest = [j for j, o in enumerate(topology.rotation_orders) if o is None]
    if rest:
        identity = jnp.asarray([1.0, 0.0, 0.0, 0.0], dtype)[None, :, None]
        parts.append(jnp.broadcast_to(identity, (len(rest), 4, m)))
        part_joints.extend(rest)
    quats = jnp.concatenate(parts, axis=0)
    perm = np.argsort(np.asarray(part_joints))
    if not np.array_equal(perm, np.arange(num_joints)):
        quats = quats[perm]
    translations = jnp.broadcast_to(skeleton.offsets.astype(dtype)[:, :, None], (num_joints, 3, m))
    if pos_joint.size:
        translations = translations.at[pos_joint, pos_axis].set(x[pos_chan])
    return quats, translations


def _fk_batch(skeleton: Skeleton, channels: Float[Array, "... channels"]) -> FKResult:
    """`FKResult` with leading dims `...` for channels `[..., C]` (one skeleton for all)."""
    topology = skeleton.topology
    channels = jnp.asarray(channels)
    if channels.ndim < 1 or channels.shape[-1] != topology.num_channels:
        raise UserError(
            f"fk_frames: `channels` has shape {channels.shape}, expected (..., "
            f"{topology.num_channels}) for this skeleton"
        )
    if skeleton.offsets.ndim != 2:
        raise UserError(
            f"fk_frames: the skeleton's offsets have shape {skeleton.offsets.shape}; for a batch "
            "of skeletons vmap `fk_from_channels` instead"
        )
    if not jnp.issubdtype(channels.dtype, jnp.floating):
        channels = channels.astype(skeleton.offsets.dtype)
    batch = channels.shape[:-1]
    flat = channels.reshape(-1, topology.num_channels)
    m = flat.shape[0]
    if m <= 2 * _FK_CHUNK:
        quats, positions, ends = _fk_flat(skeleton, flat)
    else:
        # Chunks of frames keep the working set ([J, 7, chunk]) in cache: one pass over a
        # [J, 7, M] buffer per joint is memory-bound once M is large (4x slower per joint at
        # 1024 x 240 frames than at 1000).
        n = -(-m // _FK_CHUNK)
        pad = n * _FK_CHUNK - m
        if pad:
            flat = jnp.concatenate([flat, jnp.zeros((pad, flat.shape[1]), flat.dtype)])
        out = jax.lax.map(lambda c: _fk_flat(skeleton, c), flat.reshape(n, _FK_CHUNK, -1))
        quats, positions, ends = (a.reshape(n * _FK_CHUNK, *a.shape[2:])[:m] for a in out)

    def back(a):  # [M, K, D] -> [..., K, D]
        return a.reshape(*batch, *a.shape[1:])

    return FKResult(rotations=back(quats), positions=back(positions), end_site_positions=back(ends))


_FK_CHUNK = 4096


def _fk_flat(skeleton: Skeleton, flat: Float[Array, "M channels"]):
    """`(rotations [M, J, 4], positions [M, J, 3], end sites [M, E, 3])` of M frames."""
    topology = skeleton.topology
    x = flat.T  # [C, M]: frames contiguous
    quats, translations = _local_pose_soa(skeleton, x)
    parents = np.asarray(topology.parents)
    children = np.nonzero(parents >= 0)[0]

    def pose_joint(world, jp):
        # `world` [J, 7, M] (quaternion then position) starts as the local pose: row j still
        # holds joint j's local transform until it is posed, and its parent (posed earlier:
        # parents[j] < j) already holds its world transform. One buffer, one in-place update.
        j, p = jp
        parent, local = world[p], world[j]
        pq = list(parent[:4])
        q = _qmul_sparse(pq, list(local[:4]))
        pos = _qapply_soa(pq, list(local[4:]))
        row = jnp.stack(q + [parent[4 + k] + pos[k] for k in range(3)])
        return jax.lax.dynamic_update_index_in_dim(world, row, j, 0), None

    if children.size:
        xs = (jnp.asarray(children, jnp.int32), jnp.asarray(parents[children], jnp.int32))
        world, _ = jax.lax.scan(pose_joint, jnp.concatenate([quats, translations], axis=1), xs)
        quats, translations = world[:, :4], world[:, 4:]
    if topology.num_end_sites:
        ep = np.asarray(topology.end_site_parents)
        pq = quats[ep]  # [E, 4, M]
        off = skeleton.end_site_offsets.astype(x.dtype)[:, :, None]  # [E, 3, 1]
        ends = translations[ep] + jnp.stack(_qapply_soa(list(jnp.moveaxis(pq, 1, 0)),
                                                        list(jnp.moveaxis(off, 1, 0))), axis=1)
    else:
        ends = jnp.zeros((0, 3, x.shape[1]), x.dtype)

    return tuple(jnp.transpose(a, (2, 0, 1)) for a in (quats, translations, ends))



# `_jit.jit` (the one wrapper's mechanism over `jax.jit`), not `filter_jit`: equinox's argument
# filtering cost ~150 us more per call on small batches (2-core machine, jax 0.10.2), which FK
# is called with per frame. XLA's default CPU emitters (`{}`), as before the wrapper.
@_jit.jit(cpu_compiler_options={})
def joint_positions(skeleton: Skeleton, channels: Float[Array, "... channels"]):
    """World positions of every joint for every frame (jitted entry point).

    Arguments:
        skeleton: the skeleton (unbatched offsets).
        channels: `[..., C]` BVH channel values (degrees, file units), e.g. `[F, C]` for one
            clip or `[B, F, C]` for a batch of clips of this skeleton.

    Returns:
        `[..., J, 3]` joint positions in file units, joints in file order.
    """
    return _fk_batch(skeleton, channels).positions


@_jit.jit(cpu_compiler_options={})
def fk_frames(skeleton: Skeleton, channels: Float[Array, "... channels"]) -> FKResult:
    """`FKResult` for every frame of `[..., C]` BVH channels (jitted entry point).

    Same values as `jax.vmap(fk_from_channels)`, computed in a frame-minor layout (see the
    notes above this function).

    Arguments:
        skeleton: the skeleton (unbatched offsets).
        channels: `[..., C]` BVH channel values (degrees, file units).

    Returns:
        An `FKResult` whose leaves get the leading dims `...` of `channels`.
    """
    return _fk_batch(skeleton, channels)
