"""Forward kinematics: BVH channels to local poses, local poses to world joint positions."""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float

from fourierjax import rotations
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

    **Arguments:**

    - `skeleton`: the skeleton the channels belong to.
    - `channels`: `[C]` one frame of channel values as stored in the file.

    **Returns:** `(translations [J, 3], quats [J, 4])`, local to each joint's parent.
    """
    topology = skeleton.topology
    channels = jnp.asarray(channels)
    if channels.shape != (topology.num_channels,):
        raise ValueError(
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

    **Arguments:**

    - `skeleton`: supplies the topology and the End Site offsets.
    - `translations`: `[J, 3]` local translation of each joint (the root's is its world position).
    - `quats`: `[J, 4]` local rotation of each joint (wxyz).

    **Returns:** an `FKResult`.
    """
    topology = skeleton.topology
    j = topology.num_joints
    if translations.shape != (j, 3) or quats.shape != (j, 4):
        raise ValueError(
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
    """`forward_kinematics` of one frame of BVH channel values (see `pose_from_channels`)."""
    return forward_kinematics(skeleton, *pose_from_channels(skeleton, channels))


@jax.jit
def joint_positions(skeleton: Skeleton, channels: Float[Array, "frames channels"]):
    """World positions of every joint for every frame (jitted entry point).

    **Arguments:**

    - `skeleton`: the skeleton.
    - `channels`: `[F, C]` BVH channel values (degrees, file units).

    **Returns:** `[F, J, 3]` joint positions in file units, joints in file order.
    """
    return jax.vmap(lambda c: fk_from_channels(skeleton, c).positions)(channels)


@jax.jit
def fk_frames(skeleton: Skeleton, channels: Float[Array, "frames channels"]) -> FKResult:
    """`FKResult` for every frame of `[F, C]` BVH channels (jitted entry point)."""
    return jax.vmap(lambda c: fk_from_channels(skeleton, c))(channels)
