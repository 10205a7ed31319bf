"""Joint and foot positions of clips and models through FK, and the position metric."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import ArrayLike, Bool, Float, Int

from fourierjax import _jit
from fourierjax._fourier._buckets import length_bucket as _bucket
from fourierjax._fourier._model import FourierModel
from fourierjax.features import ROOT_CHANNELS, root_relative_positions
from fourierjax.skeleton import Skeleton


def motion_joint_positions(
    motion, frames: Int[ArrayLike, " K"] | None = None
) -> Float[np.ndarray, "K J 3"]:
    """World joint positions of a clip through forward kinematics of its BVH channels.

    The frames are padded to their length bucket (`length_bucket`) in NumPy and cut back, so
    clips of different lengths in one bucket share one compiled FK and compile nothing else.

    Arguments:
        motion: a Motion; frames: optional frame indices (default: every frame).
    Returns:
        ``[F, J, 3]`` file units (JAX's default float dtype), joints in file order.
    """
    from fourierjax.kinematics import PAD_LIMIT, joint_positions

    ch = motion.channels if frames is None else motion.channels[np.asarray(frames)]
    ch = np.asarray(ch, jax.dtypes.canonicalize_dtype(ch.dtype))  # JAX's default float
    num_frames = ch.shape[0]
    if num_frames > PAD_LIMIT:
        return np.asarray(joint_positions(motion.skeleton(), ch))
    padded = np.zeros((_bucket(num_frames), ch.shape[1]), ch.dtype)
    padded[:num_frames] = ch
    return np.asarray(joint_positions(motion.skeleton(), padded))[:num_frames]


_root_relative_positions_jit = _jit.filter_jit(root_relative_positions)


def model_joint_positions(
    model: FourierModel, skeleton: Skeleton, phases: Float[ArrayLike, " K"], pelvis: int = 0
) -> Float[np.ndarray, "K J 3"]:
    """Joint positions of a Fourier gait model's pose at cycle phases (Unuma 1995 eq. 1).

    The pose is ``fourier.synthesize_phase(model, phases)`` through forward kinematics; the
    root stands above the origin of the heading frame (facing +Z) at the model's ``root.y``
    height, so poses of different models line up for side-by-side plots.

    Arguments:
        model: a ``FourierModel`` with the gait channel layout (:func:`channel_names_for`);
        skeleton: the Skeleton the model was fitted on; phases: ``[K]`` radians of the cycle;
        pelvis: the body map's pelvis (``BodyMap.pelvis``; CMU: joint 0).
    Returns:
        ``[K, J, 3]`` file units.
    """
    from fourierjax import fourier

    feats = fourier.synthesize_phase(model, jnp.asarray(phases, float))
    p = np.asarray(_root_relative_positions_jit(skeleton, feats, model.representation, pelvis))
    height = np.asarray(feats[:, ROOT_CHANNELS.index("root.y")])
    return p + height[:, None, None] * np.array([0.0, 1.0, 0.0])


def foot_positions_of(motion, points=None, *, body_map=None) -> Float[np.ndarray, "F P 3"]:
    """World positions of the foot points of every frame of a clip, through FK.

    Frames are padded to a few length buckets, so clips of similar lengths share one compiled
    FK.

    Arguments:
        motion: a Motion; points: ``contacts.FootPoints`` (default: the body map's feet,
        ``contacts.foot_points(motion.topology, body_map)``: ankle, toe, toe tip);
        body_map: the clip's `fourierjax.body.BodyMap` (None: inferred when ``points`` is None).
    Returns:
        ``[F, 2, P, 3]`` (left, right) file units, ready for ``contacts.foot_contacts`` and
        ``contacts.estimate_ground``.
    """
    from fourierjax import contacts
    from fourierjax._host import as_default_float
    from fourierjax.body import infer_body_map
    from fourierjax.kinematics import fk_frames

    if points is None:
        points = contacts.foot_points(motion.topology, body_map or infer_body_map(motion))
    F = motion.num_frames
    ch = np.concatenate([motion.channels, np.repeat(motion.channels[-1:], _bucket(F) - F, 0)])
    fk = fk_frames(motion.skeleton(), as_default_float(ch))
    # The gather on the host: eager JAX ops would compile a program for every new clip length.
    allp = np.concatenate([np.asarray(fk.positions), np.asarray(fk.end_site_positions)], -2)[:F]
    return allp[:, np.asarray([points.left, points.right])]


def foot_contacts_of(motion, *, body_map=None) -> Bool[np.ndarray, "F 2"] | None:
    """Foot contacts ``bool [F, 2]`` (left, right) of a clip: ``fourierjax.contacts`` on FK of
    the body map's foot points (ankle, toe, toe tip), about its up axis. None when the skeleton
    has no body map (no legs can be found).

    Arguments:
        motion: a Motion; body_map: its `fourierjax.body.BodyMap` (None: inferred).
    Returns:
        ``bool [F, 2]`` or None.
    """
    from fourierjax import contacts
    from fourierjax.body import BodyMapError, infer_body_map

    if body_map is None:
        try:
            body_map = infer_body_map(motion)
        except BodyMapError:
            return None
    points = contacts.foot_points(motion.topology, body_map)
    return contacts.foot_contacts(foot_positions_of(motion, points), motion.frame_time_s,
                                  up_axis=body_map.up_axis)


def _position_ve(skeleton, representation, x, xhat, mask, pelvis=0):
    return _position_ve_jit(skeleton, x, xhat, mask, representation, pelvis)


def _position_ve_impl(skeleton, x, xhat, mask, representation, pelvis):
    from fourierjax.fourier import variance_explained

    p = root_relative_positions(skeleton, x, representation, pelvis)
    ph = root_relative_positions(skeleton, xhat, representation, pelvis)
    return variance_explained(p, ph, mask)


_position_ve_jit = _jit.filter_jit(_position_ve_impl)
