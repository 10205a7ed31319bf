"""Vectorised NumPy forward kinematics: the baseline the JAX FK is measured against."""

from __future__ import annotations

import numpy as np

_AXIS = {"X": 0, "Y": 1, "Z": 2}


def _axis_matrices(axis: int, angle: np.ndarray) -> np.ndarray:
    c, s = np.cos(angle), np.sin(angle)
    m = np.zeros(angle.shape + (3, 3), angle.dtype)
    i, j = [k for k in range(3) if k != axis]
    m[..., axis, axis] = 1.0
    m[..., i, i] = c
    m[..., j, j] = c
    # Right-handed rotation about `axis`: (i, j) cyclic after axis.
    sign = 1.0 if (j - i) % 3 == 1 and (i - axis) % 3 == 1 else -1.0
    m[..., i, j] = -sign * s
    m[..., j, i] = sign * s
    return m


def numpy_fk(topology, offsets: np.ndarray, channels: np.ndarray):
    """World rotation matrices and positions of every joint, vectorised over frames.

    Arguments:
        topology: a `fourierjax.skeleton.Topology`.
        offsets: `[J, 3]` bone offsets.
        channels: `[..., C]` BVH channel values (degrees; position channels replace offsets).

    Returns:
        `(R [..., J, 3, 3], p [..., J, 3])` in the channels' dtype. Local matrices of all joints
        of one rotation order are built at once; the hierarchy is a loop over joints.
    """
    channels = np.asarray(channels)
    dtype = channels.dtype
    batch = channels.shape[:-1]
    J = topology.num_joints
    co = topology.channel_offsets
    rad = np.deg2rad(channels)
    local_R = np.broadcast_to(np.eye(3, dtype=dtype), batch + (J, 3, 3)).copy()
    groups: dict[str, tuple[list[int], list[list[int]]]] = {}
    for j, order in enumerate(topology.rotation_orders):
        if order is None:
            continue
        rot = [co[j] + k for k, c in enumerate(topology.channels[j]) if c.endswith("rotation")]
        js, idx = groups.setdefault(order, ([], []))
        js.append(j)
        idx.append(rot)
    for order, (js, idx) in groups.items():
        ang = rad[..., np.asarray(idx)]  # [..., Jg, k]
        R = None
        for k, a in enumerate(order):
            E = _axis_matrices(_AXIS[a], ang[..., k])
            R = E if R is None else np.matmul(R, E)
        local_R[..., js, :, :] = R
    t = np.broadcast_to(np.asarray(offsets, dtype), batch + (J, 3)).copy()
    for j, chans in enumerate(topology.channels):
        for k, c in enumerate(chans):
            if c.endswith("position"):
                t[..., j, _AXIS[c[0]]] = channels[..., co[j] + k]
    world_R = np.empty_like(local_R)
    world_p = np.empty_like(t)
    for j, p in enumerate(topology.parents):
        if p < 0:
            world_R[..., j, :, :] = local_R[..., j, :, :]
            world_p[..., j, :] = t[..., j, :]
        else:
            world_R[..., j, :, :] = np.matmul(world_R[..., p, :, :], local_R[..., j, :, :])
            world_p[..., j, :] = world_p[..., p, :] + np.matmul(
                world_R[..., p, :, :], t[..., j, :, None])[..., 0]
    return world_R, world_p
