"""Up-axis conversion at the edge: a Z-up (or any-up) `Motion` re-expressed Y-up exactly, and back."""

from __future__ import annotations

import dataclasses
from typing import TYPE_CHECKING

import numpy as np

from fourierjax.errors import UserError
from fourierjax.io.bvh import Motion

if TYPE_CHECKING:
    from jaxtyping import Float

__all__ = ["from_y_up", "rotate_root", "to_y_up", "up_name", "up_rotation"]

_AXES = "XYZ"


def up_rotation(up: str) -> Float[np.ndarray, "3 3"]:
    """The proper rotation that takes the signed axis `up` ("z", "-z", "x", "-x", "y", "-y") to +Y.

    Arguments:
        up: the file's up axis, optionally signed.

    Returns:
        `[3, 3]` float64; "z" gives `(x, y, z) -> (x, z, -y)` (Blender's Z-up to Y-up).
    """
    key = str(up).strip().lower().lstrip("+")
    table = {
        "y": np.eye(3),
        "-y": np.diag([1.0, -1.0, -1.0]),
        "z": np.array([[1.0, 0, 0], [0, 0, 1], [0, -1, 0]]),
        "-z": np.array([[1.0, 0, 0], [0, 0, -1], [0, 1, 0]]),
        "x": np.array([[0.0, -1, 0], [1, 0, 0], [0, 0, 1]]),
        "-x": np.array([[0.0, 1, 0], [-1, 0, 0], [0, 0, 1]]),
    }
    if key not in table:
        raise UserError(f"up_rotation: `up` must be one of x, y, z, -x, -y, -z; got {up!r}")
    return table[key]


def up_name(axis: int, sign: int) -> str:
    """The signed axis name `up_rotation` takes ("z", "-z", ...) of an up axis index and sign
    (`BodyMap.up_axis`, `BodyMap.up_sign`)."""
    return ("-" if sign < 0 else "") + "xyz"[axis]


def to_y_up(motion: Motion, up: str = "z") -> Motion:
    """`motion` (whose up axis is `up`) with its root turned so that up is +Y; other joints unchanged.

    World positions of every joint become `up_rotation(up) @ p` exactly (to round-off).
    """
    return rotate_root(motion, up_rotation(up))


def from_y_up(motion: Motion, up: str = "z") -> Motion:
    """The inverse of `to_y_up`: a Y-up `motion` written back with `up` as its up axis."""
    return rotate_root(motion, up_rotation(up).T)


def rotate_root(motion: Motion, rotation: Float[np.ndarray, "3 3"]) -> Motion:
    """Re-express `motion` in axes turned by `rotation` (world positions become `rotation @ p`).

    Only the roots change: each root's OFFSET, its position channels and its rotation channels
    (kept in the root's own Euler order). The other joints are local to their parents and stay
    as they are.

    Arguments:
        motion: the clip.
        rotation: `[3, 3]` proper rotation matrix.

    Returns:
        A new `Motion` with the same topology.

    Raises:
        UserError: `rotation` is not a rotation, or a root has one or two position channels (they
            would need the OFFSET's other components to vary) or fewer than three rotation
            channels while `rotation` is not the identity.
    """
    R = np.asarray(rotation, np.float64)
    if R.shape != (3, 3) or not np.allclose(R @ R.T, np.eye(3), atol=1e-9) or np.linalg.det(R) < 0:
        raise UserError(f"rotate_root: `rotation` must be a proper 3x3 rotation matrix, got {R.tolist()}")
    topo = motion.topology
    offsets = np.array(motion.offsets)
    channels = np.array(motion.channels)
    identity = np.allclose(R, np.eye(3), atol=0.0)
    for j, (parent, chans) in enumerate(zip(topo.parents, topo.channels)):
        if parent >= 0:
            continue
        offsets[j] = R @ offsets[j]
        first = topo.channel_offsets[j]
        pos = [first + k for k, c in enumerate(chans) if c.endswith("position")]
        rot = [first + k for k, c in enumerate(chans) if c.endswith("rotation")]
        if pos:
            if len(pos) != 3:
                raise UserError(f"rotate_root: root {topo.names[j]!r} has {len(pos)} position channel(s); "
                                "re-expressing it needs all three or none")
            axes = [_AXES.index(chans[k - first][0]) for k in pos]
            t = np.zeros((len(channels), 3))
            t[:, axes] = channels[:, pos]
            channels[:, pos] = (t @ R.T)[:, axes]
        if identity:
            continue
        order = "".join(chans[k - first][0] for k in rot)
        if len(order) != 3 or len(set(order)) != 3:
            raise UserError(f"rotate_root: root {topo.names[j]!r} has rotation channels {order or 'none'}; "
                            "re-expressing it needs three (a Tait-Bryan order)")
        M = _matrix_from_euler(np.deg2rad(channels[:, rot]), order)
        channels[:, rot] = np.rad2deg(_euler_from_matrix(R @ M, order))
    return dataclasses.replace(motion, offsets=offsets, channels=channels)


def _elementary(axis: int, angle: np.ndarray) -> np.ndarray:
    c, s = np.cos(angle), np.sin(angle)
    m = np.zeros(angle.shape + (3, 3))
    i, k = (axis + 1) % 3, (axis + 2) % 3
    m[..., axis, axis] = 1.0
    m[..., i, i], m[..., i, k], m[..., k, i], m[..., k, k] = c, -s, s, c
    return m


def _matrix_from_euler(angles: np.ndarray, order: str) -> np.ndarray:
    """`R = R_order[0](a0) @ R_order[1](a1) @ R_order[2](a2)` (BVH, intrinsic), float64."""
    out = np.broadcast_to(np.eye(3), angles.shape[:-1] + (3, 3))
    for n, axis in enumerate(order):
        out = out @ _elementary(_AXES.index(axis), angles[..., n])
    return out


def _euler_from_matrix(m: np.ndarray, order: str) -> np.ndarray:
    """Angles of a Tait-Bryan `order` for rotation matrices `m` (inverse of `_matrix_from_euler`)."""
    i, j, k = (_AXES.index(a) for a in order)
    s = 1.0 if (j - i) % 3 == 1 else -1.0  # cyclic orders (XYZ, YZX, ZXY) have sign +1
    b = np.arcsin(np.clip(s * m[..., i, k], -1.0, 1.0))
    a = np.arctan2(-s * m[..., j, k], m[..., k, k])
    c = np.arctan2(-s * m[..., i, j], m[..., i, i])
    return np.stack([a, b, c], axis=-1)
