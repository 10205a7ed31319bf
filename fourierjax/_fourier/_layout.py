"""Helpers of the feature layout shared by `fourierjax.features` and `fourierjax.motion`."""

from __future__ import annotations

import functools

import numpy as np

from fourierjax import _jit, rotations
from fourierjax.errors import UserError

_AXES = "XYZ"


def rotation_joints(topology, *, strict: bool = True) -> list[tuple[int, str, list[int]]]:
    """(joint, order, rotation channel indices) for joints with 3 rotation channels.

    A joint with some but not 3 rotation channels raises (``strict``) or is left out.
    """
    out = []
    for j, chans in enumerate(topology.channels):
        rot = [topology.channel_offsets[j] + k for k, c in enumerate(chans)
               if c.endswith("rotation")]
        if not rot:
            continue
        order = topology.rotation_orders[j]
        if order is None or len(order) != 3 or len(rot) != 3:
            if not strict:
                continue
            raise UserError(
                f"joint {topology.names[j]!r}: Fourier features need 3 rotation channels per "
                f"joint, got {list(chans)}"
            )
        out.append((j, order, rot))
    return out


def as_f64(x) -> np.ndarray:
    return np.asarray(x, dtype=np.float64)


def bucket(n: int) -> int:
    """Pad lengths to a few sizes so jitted code compiles once per bucket, not per clip."""
    return max(64, int(2 ** np.ceil(np.log2(max(n, 1)))))


_JITTED: dict = {}


def rot(name: str, *arrays, **static) -> np.ndarray:
    """``rotations.<name>(*arrays)`` on NumPy arrays whose first axis is time: padded to a
    length bucket and run through one cached jit per function (eager JAX ops would compile
    again for every clip length)."""
    F = arrays[0].shape[0]
    Fp = bucket(F)
    padded = [np.concatenate([a, np.repeat(a[-1:], Fp - F, axis=0)]) for a in arrays]
    key = (name, tuple(sorted(static.items())))
    fn = _JITTED.get(key)
    if fn is None:
        fn = _JITTED[key] = _jit.filter_jit(functools.partial(getattr(rotations, name), **static))
    return as_f64(fn(*padded))[:F]


def yaw_quat(psi: np.ndarray) -> np.ndarray:
    psi = np.asarray(psi, np.float64)
    z = np.zeros_like(psi)
    return np.stack([np.cos(psi / 2), z, np.sin(psi / 2), z], axis=-1)


def root_pose(motion) -> tuple[np.ndarray, np.ndarray]:
    """Root world position [F, 3] and orientation [F, 4] (wxyz) of every frame."""
    topo = motion.topology
    chans = topo.channels[0]
    base = topo.channel_offsets[0]
    pos = np.broadcast_to(np.asarray(motion.offsets[0], np.float64),
                          (motion.num_frames, 3)).copy()
    for k, c in enumerate(chans):
        if c.endswith("position"):
            pos[:, _AXES.index(c[0])] = motion.channels[:, base + k]
    idx = [base + k for k, c in enumerate(chans) if c.endswith("rotation")]
    order = topo.rotation_orders[0]
    if order is None or len(order) != 3:
        raise UserError(f"root joint {topo.names[0]!r} needs 3 rotation channels, got {chans}")
    q = rot("quat_from_euler", np.radians(motion.channels[:, idx]), order=order)
    return pos, q
