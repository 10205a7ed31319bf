"""Solved stance poses (or an eased animation between them) as a BVH `Motion` for Blender."""

import os

import numpy as np

from fourierjax._host import as_default_float
from fourierjax.errors import UserError
from fourierjax.io.bvh import Motion, write_bvh
from fourierjax.motion import make_euler_continuous
from fourierjax.stance.animation import animate, ease_in_out
from fourierjax.stance.skeleton48 import ROTATION_ORDER, TOPOLOGY, Body, StancePose, dof_euler_frames

__all__ = ["animate", "ease_in_out", "pose_to_motion", "write_stance_bvh"]


def pose_to_motion(body: Body, poses: StancePose, frame_time_s: float = 1.0 / 30.0) -> Motion:
    """A BVH `Motion` of one pose (leaves `[3]`, `[J, 4]`) or of frames (`[F, 3]`, `[F, J, 4]`).

    Every joint gets Z X Y rotation channels in degrees (the 48 DOFs plus zeros on the
    non-DOF axes), the root also X Y Z positions; offsets in metres, Y up, facing +Z.

    Each rotation has two Euler triples, (z, x, y) and (z + 180, 180 - x, y + 180). The first
    frame takes, per joint, the one with the smaller non-DOF angles (`skeleton48._dof_euler`),
    so an elbow bent past 90 degrees is (0, -102, 0), not (180, -78, 180); later frames follow it
    continuously (`motion.make_euler_continuous`), so an animation never jumps by 180 degrees
    on two axes (which Blender would interpolate as a spin).

    Arguments:
        body: the character (`make_body`).
        poses: a `StancePose`, one pose or frames (`animate`).
        frame_time_s: seconds per frame.

    Returns:
        A `Motion` (numpy, degrees).
    """
    root = np.asarray(poses.root_position, np.float64)
    quats = np.asarray(poses.quats, np.float64)
    if root.ndim == 1:
        root, quats = root[None], quats[None]
    eul = np.asarray(dof_euler_frames(as_default_float(quats)), np.float64)  # no conversion program
    eul = np.degrees(make_euler_continuous(eul, ROTATION_ORDER))
    frames = root.shape[0]
    channels = np.concatenate([root, eul.reshape(frames, -1)], axis=1)
    return Motion(
        topology=TOPOLOGY,
        offsets=np.asarray(body.offsets, np.float64),
        end_site_offsets=np.asarray(body.skeleton.end_site_offsets, np.float64),
        channels=channels,
        frame_time_s=frame_time_s,
        source=None,
    )


def write_stance_bvh(path, body: Body, poses: StancePose, frame_time_s: float = 1.0 / 30.0):
    """Write a pose or an animation (see `pose_to_motion`) to a BVH file that opens in Blender.

    Arguments:
        path: the BVH file to write.
        body, poses, frame_time_s: as for `pose_to_motion`.

    Raises:
        UserError: the pose holds NaN, or the file cannot be written (e.g. its directory does
            not exist: it is not created, as with `io.bvh.write_bvh`).
    """
    if not np.isfinite(np.asarray(poses.quats)).all():
        raise UserError("write_stance_bvh: the pose holds NaN values")
    motion = pose_to_motion(body, poses, frame_time_s)
    try:
        write_bvh(motion, path)
    except OSError as err:
        raise UserError(f"write_stance_bvh: cannot write {os.fspath(path)}: {err.strerror or err}") from None
