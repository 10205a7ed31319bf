"""Body maps: which joints of any skeleton are the legs, feet, trunk and arms, its up axis, facing and units."""

from __future__ import annotations

import functools
from collections.abc import Sequence

import numpy as np
from jaxtyping import Float

from fourierjax._body._infer import from_names as _from_names
from fourierjax._body._infer import from_stored as _from_stored
from fourierjax._body._infer import infer as _infer
from fourierjax._body._map import (
    BODY_MAP_VERSION,
    UNITS,
    Arm,
    BodyMap,
    BodyMapError,
    Leg,
    parse_overrides,
)
from fourierjax.skeleton import Topology

__all__ = ["BODY_MAP_VERSION", "UNITS", "Arm", "BodyMap", "BodyMapError", "Leg", "body_map_from_dict",
           "body_map_from_names", "body_map_from_toml", "infer_body_map", "infer_body_map_from_positions"]

#: Frames of a clip that inference poses (evenly spaced): enough for a mean pose and its travel.
MAX_FRAMES = 240


def infer_body_map(motion, *, up=None, overrides=None, max_frames: int = MAX_FRAMES) -> BodyMap:
    """The body map of a clip: from joint names first, from the geometry of its motion where they do not decide.

    Legs come from a table of the common naming conventions (CMU, Mixamo, Daz, 3ds Max, Bandai,
    SMPL, LAFAN; any case, prefix, namespace and side spelling), else from the mean pose: the two
    branches of the pelvis that reach lowest, left and right from where the toes point
    (left = up × forward). The up axis is the one from the feet to the pelvis; the trajectory
    joint is joint 0 when its position channels move, else the first joint whose do.

    Arguments:
        motion: a `fourierjax.io.bvh.Motion` (anything with `topology`, `channels` and `skeleton()`).
        up: the up axis ("y", "z", "-z", 0/1/2 or `(axis, sign)`); None to infer it.
        overrides: fields set by joint name: a dict, TOML text, or the path of a TOML file
            (the layout `BodyMap.to_toml` writes; any subset of its fields).
        max_frames: this many evenly spaced frames are posed (a short clip repeats some).

    Returns:
        A `BodyMap` for `motion.topology`.

    Raises:
        BodyMapError: no legs can be found (the message shows a minimal TOML map to write), or an
            override names a joint the skeleton does not have.
    """
    from fourierjax import kinematics

    channels = np.asarray(motion.channels)
    fk = kinematics.fk_frames(motion.skeleton(), channels[_sampled_frames(len(channels), max_frames)])
    return _infer_from_fk(motion, fk, up=up, overrides=overrides)


def _sampled_frames(num_frames: int, max_frames: int = MAX_FRAMES) -> np.ndarray:
    """The frames `infer_body_map` poses: always `max_frames` rows, evenly spaced (short clips
    repeat frames), so that FK compiles once per skeleton."""
    return np.linspace(0, num_frames - 1, max_frames).round().astype(int)


@functools.lru_cache(maxsize=64)
def _position_channels(topo: Topology) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The flat indices of ``topo``'s position channels (joint by joint, in file order), where
    each joint's run of them starts in that list, and those joints."""
    offsets = topo.channel_offsets
    idx, firsts, joints = [], [], []
    for j, chans in enumerate(topo.channels):
        mine = [offsets[j] + k for k, c in enumerate(chans) if c.endswith("position")]
        if mine:
            firsts.append(len(idx))
            joints.append(j)
            idx += mine
    return np.array(idx, np.intp), np.array(firsts, np.intp), np.array(joints, np.intp)


def _infer_from_fk(motion, fk, *, up=None, overrides=None, pre=None) -> BodyMap:
    """`infer_body_map` of `motion` given `fk`, the FK of its `_sampled_frames` (anything with
    `positions`, `end_site_positions` and `rotations`): for a caller that poses many clips at
    once (`fourierjax._motion._batch`; ``pre``: `_body._infer.infer`'s, from `moments_many`)."""
    return _infer(motion.topology, np.asarray(fk.positions, np.float64),
                  np.asarray(fk.end_site_positions, np.float64), np.asarray(fk.rotations, np.float64),
                  _moving(motion), up=up, overrides=overrides, pre=pre)


def _moving(motion) -> list[int]:
    """The joints of ``motion`` whose position channels move (`infer`'s ``moving``): their
    largest span over the clip passes a millionth of its largest channel value."""
    channels = np.asarray(motion.channels)
    scale = 1e-6 * (1.0 + float(np.abs(channels).max(initial=0.0)))
    idx, firsts, joints = _position_channels(motion.topology)
    if not len(idx):
        return []
    # The span of the position channels only: the same values as of every channel, picked
    span = np.ptp(channels[:, idx], axis=0) if len(channels) else np.zeros(len(idx))
    return joints[np.maximum.reduceat(span, firsts) > scale].tolist()


def infer_body_map_from_positions(
    topology: Topology,
    positions: Float[np.ndarray, "frames joints 3"],
    end_site_positions: Float[np.ndarray, "frames end_sites 3"] | None = None,
    rotations: Float[np.ndarray, "frames joints 4"] | None = None,
    *,
    up=None,
    overrides=None,
    moving: Sequence[int] | None = None,
) -> BodyMap:
    """`infer_body_map` from world joint positions (e.g. a motion converted from another format).

    Arguments:
        topology: the skeleton's `Topology`.
        positions: `[F, J, 3]` world joint positions, file units.
        end_site_positions: `[F, E, 3]`, or None (then no End Site becomes a foot point).
        rotations: `[F, J, 4]` world joint orientations (wxyz), or None; with them the mean pose
            is taken in the pelvis's frame, which a clip that turns around needs.
        up, overrides: as for `infer_body_map`.
        moving: the joints whose position channels move, in file order; None to judge from
            `positions`. `()` says that none does (a model's cycle, root at the origin: then the
            trajectory is the pelvis, or its nearest ancestor with position channels).

    Returns:
        A `BodyMap`; the trajectory is joint 0 when it moves, else the first joint that does,
        else the pelvis (or its nearest ancestor with position channels).
    """
    positions = np.asarray(positions, np.float64)
    if positions.ndim != 3 or positions.shape[1:] != (topology.num_joints, 3):
        raise BodyMapError(f"infer_body_map_from_positions: positions has shape {positions.shape}, expected "
                           f"(frames, {topology.num_joints}, 3)")
    if end_site_positions is None:
        topology = Topology(topology.names, topology.parents, topology.channels, ())
        ends = np.zeros((len(positions), 0, 3))
    else:
        ends = np.asarray(end_site_positions, np.float64)
    rots = None if rotations is None else np.asarray(rotations, np.float64)
    moving = None if moving is None else [int(j) for j in moving]
    return _infer(topology, positions, ends, rots, moving, up=up, overrides=overrides)


def body_map_from_dict(d: dict, topology: Topology) -> BodyMap:
    """The map stored by `BodyMap.to_dict` (a model file's header), checked against `topology`.

    Every joint is looked up by name, so the map fits any topology with those joints.

    Raises:
        BodyMapError: a version this fourierjax does not read, a missing field, or a joint the
            skeleton does not have.
    """
    return _from_stored(parse_overrides(dict(d)), topology, "stored")


def body_map_from_toml(text_or_path, topology: Topology) -> BodyMap:
    """The map a complete TOML file (as written by `BodyMap.to_toml`) describes, for `topology`."""
    return _from_stored(parse_overrides(text_or_path), topology, "file")


def body_map_from_names(topology: Topology, *, up=None) -> BodyMap:
    """The body map that joint names alone decide: for a bare topology, which has no poses.

    Legs, arms, pelvis, spine, neck and head come from the same name table as
    `infer_body_map` (CMU, Mixamo, Daz, 3ds Max, Bandai, SMPL, LAFAN, ...), so on a named rig the
    joints equal those of the clip's inferred map. The geometric fields cannot be known without
    poses: they are placeholders, marked `"default"` in `sources` (up +Y unless `up` is given,
    forward and facing along the next axis, leg length and height 0, units `"custom"`).

    Arguments:
        topology: the skeleton's `Topology` (names, parents, channels, End Sites).
        up: the up axis, as for `infer_body_map`; None for +Y.

    Returns:
        A `BodyMap` whose joint fields come from the names.

    Raises:
        BodyMapError: names do not decide the legs (infer the map of a clip instead).
    """
    return _from_names(topology, up)
