"""Helpers of the feature layout shared by `fourierjax.features` and `fourierjax.motion`."""

from __future__ import annotations

import dataclasses
import functools

import jax
import numpy as np
from jaxtyping import ArrayLike, Float

from fourierjax import _jit, rotations
from fourierjax.errors import UserError

_AXES = "XYZ"


def rotation_joints(topology, *, strict: bool = True) -> list[tuple[int, str, list[int]]]:
    """(joint, order, rotation channel indices) for joints with 3 rotation channels.

    A joint with some but not 3 rotation channels raises (``strict``) or is left out.
    """
    return [(j, order, list(rot)) for j, order, rot in _rotation_joints(topology, strict)]


# Per topology (hashable), once: the pipeline asks for each chunk's layout several times, and
# `Topology.channel_offsets` / `.rotation_orders` are derived anew on every read (read per
# joint, 8 ms a call on Bandai-1's 22 joints under a profiler, 96 calls per 500 clips).
@functools.lru_cache(maxsize=256)
def _rotation_joints(topology, strict: bool) -> tuple[tuple[int, str, tuple[int, ...]], ...]:
    out = []
    offsets, orders = topology.channel_offsets, topology.rotation_orders
    for j, chans in enumerate(topology.channels):
        rot = [offsets[j] + k for k, c in enumerate(chans) if c.endswith("rotation")]
        if not rot:
            continue
        order = orders[j]
        if order is None or len(order) != 3 or len(rot) != 3:
            if not strict:
                continue
            raise UserError(
                f"joint {topology.names[j]!r}: Fourier features need 3 rotation channels per "
                f"joint, got {list(chans)}"
            )
        out.append((j, order, tuple(rot)))
    return tuple(out)


def as_f64(x) -> np.ndarray:
    return np.asarray(x, dtype=np.float64)


def bucket(n: int) -> int:
    """Pad lengths to a few sizes so jitted code compiles once per bucket, not per clip."""
    return max(64, int(2 ** np.ceil(np.log2(max(n, 1)))))


_JITTED: dict = {}

#: `rot` runs more rows than this in blocks of this many, so its programs stop at this size:
#: a batch's concatenated frames (`_motion._batch`) reuse one program whatever the batch size.
ROW_BLOCK = 4096


#: `rotations` functions that run along the time axis (each frame continues the previous one).
_ALONG_TIME = frozenset({"make_expmap_continuous", "make_quat_continuous"})


def rot(name: str, *arrays, **static) -> np.ndarray:
    """``rotations.<name>(*arrays)`` on NumPy arrays whose first axis is time: padded to a
    length bucket (blocks of `ROW_BLOCK` rows beyond it) and run through one cached jit per
    function (eager JAX ops would compile again for every clip length)."""
    return rot_blocks(name, arrays, static, whole_blocks=False)


def rot_blocks(name: str, arrays, static: dict, *, whole_blocks: bool) -> np.ndarray:
    """`rot`; with ``whole_blocks``, every block of rows (the last one too) is padded to
    `ROW_BLOCK` rows, so that any number of rows runs the one program of that size."""
    F = arrays[0].shape[0]
    key = (name, tuple(sorted(static.items())))
    fn = _JITTED.get(key)
    if fn is None:
        fn = _JITTED[key] = _jit.filter_jit(functools.partial(getattr(rotations, name), **static))
    # A continuity pass runs along time: each block after the first starts from the previous
    # block's last output row (kept as given, then dropped), so that blocks continue one path.
    carry = name in _ALONG_TIME
    out = None
    s = 0
    while s < max(F, 1):
        block = [a[s:s + ROW_BLOCK - (carry and s > 0)] for a in arrays]
        if carry and s > 0:
            block = [np.concatenate([out[s - 1:s].astype(block[0].dtype), block[0]])]
        n = block[0].shape[0]
        Fp = ROW_BLOCK if whole_blocks else bucket(n)
        # Only a short block is padded (a whole one goes as it is: no copy of the rows).
        padded = block if n == Fp else [np.concatenate([a, np.repeat(a[-1:], Fp - n, axis=0)])
                                        for a in block]
        r = np.asarray(fn(*padded))
        if out is None:
            out = np.empty((F, *r.shape[1:]), np.float64)
        # Copied into a float64 array of our own, writable: under x64 `np.asarray` of a float64
        # JAX array is a read-only view (callers write into the result, e.g. the pelvis's rows
        # of `quat_from_euler`); sliced in NumPy (slicing the JAX array is one more eager op).
        if carry and s > 0:
            out[s:s + n - 1] = r[1:n]
            s += n - 1
        else:
            out[s:s + n] = r[:n]
            s += max(n, 1)  # no rows: one pass, as for any other length
    return out


def yaw_quat(psi: np.ndarray) -> np.ndarray:
    psi = np.asarray(psi, np.float64)
    z = np.zeros_like(psi)
    return np.stack([np.cos(psi / 2), z, np.sin(psi / 2), z], axis=-1)


def root_pose(motion) -> tuple[np.ndarray, np.ndarray]:
    """Joint 0's world position [F, 3] and orientation [F, 4] (wxyz) of every frame."""
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


def local_transform(motion, joint: int, frames=None) -> tuple[np.ndarray, np.ndarray]:
    """A joint's local translation [F, 3] (OFFSET, position channels replacing what they name)
    and rotation [F, 4] (wxyz; identity without rotation channels) of every frame, or of
    ``frames``."""
    topo = motion.topology
    ch = motion.channels if frames is None else motion.channels[frames]
    chans = topo.channels[joint]
    base = topo.channel_offsets[joint]
    F = ch.shape[0]
    pos = np.broadcast_to(np.asarray(motion.offsets[joint], np.float64), (F, 3)).copy()
    for k, c in enumerate(chans):
        if c.endswith("position"):
            pos[:, _AXES.index(c[0])] = ch[:, base + k]
    idx = [base + k for k, c in enumerate(chans) if c.endswith("rotation")]
    order = topo.rotation_orders[joint]
    if not idx:
        q = np.zeros((F, 4))
        q[:, 0] = 1.0
    elif order is None or len(order) != 3:
        raise UserError(f"joint {topo.names[joint]!r} needs 3 rotation channels or none, got {chans}")
    else:
        q = rot("quat_from_euler", np.radians(ch[:, idx]), order=order)
    return pos, q


def ancestors(topology, joint: int) -> list[int]:
    """The joints above ``joint``, root first (``joint`` excluded)."""
    out = []
    j = topology.parents[joint]
    while j >= 0:
        out.append(j)
        j = topology.parents[j]
    return out[::-1]


def world_pose(motion, joint: int, frames=None) -> tuple[np.ndarray, np.ndarray]:
    """World position [F, 3] and orientation [F, 4] (wxyz) of ``joint`` through FK of its
    ancestors' channels. Joint 0 (a root) takes :func:`root_pose`'s exact path."""
    if joint == 0 and frames is None:
        return root_pose(motion)
    pos = quat = None
    for j in [*ancestors(motion.topology, joint), joint]:
        t, q = local_transform(motion, j, frames)
        if pos is None:
            pos, quat = t, q
        else:
            pos = pos + rot("quat_apply", quat, t)
            quat = rot("quat_multiply", quat, q)
    return pos, quat


@dataclasses.dataclass(frozen=True)
class RootJoints:
    """The joints that carry the root features: ``pelvis`` (whose world pose gives heading,
    velocity, height and orientation), ``trajectory`` (an ancestor of, or the pelvis, whose
    position channels take the travel back) and the pelvis-frame facing (a unit 3-vector)."""

    trajectory: int
    pelvis: int
    facing_local: tuple[float, float, float] = (0.0, 0.0, 1.0)


def root_joints(motion, body_map=None) -> RootJoints:
    """The root joints of a clip from its body map (inferred when None).

    A skeleton whose body map cannot be inferred (no legs: test rigs, props) keeps joint 0 and
    its local +Z, the layout of older releases. The map's up axis must be +Y (convert Z-up
    clips at the edge with ``fourierjax.io.axes.to_y_up``).
    """
    from fourierjax.body import BodyMapError, infer_body_map

    if body_map is None:
        try:  # the motion is concrete: infer eagerly even when called under a trace
            with jax.ensure_compile_time_eval():
                body_map = infer_body_map(motion)
        except BodyMapError:
            return RootJoints(0, 0)
    bm = body_map
    if (bm.up_axis, bm.up_sign) != (1, 1):
        raise UserError(
            f"{motion.source or 'motion'}: its up axis is {'-' if bm.up_sign < 0 else '+'}{'xyz'[bm.up_axis]}; "
            "the Fourier features are Y-up: convert it first with fourierjax.io.axes.to_y_up(motion, up)"
            + ("" if motion.num_frames > 1 else
               " (read from a one-frame template: a rest pose that is not a T-pose may mislead it; pass "
               "body_map=, e.g. ModelFile.body_map or gait.model_body_map(model, skeleton))")
        )
    topo = motion.topology
    pelvis, traj = bm.pelvis, bm.trajectory
    if traj != pelvis and traj not in ancestors(topo, pelvis):
        # A map inferred from posed positions (a model's cycle, walking in place) cannot tell
        # which joint's channels carry the travel: the pelvis, or the nearest of its ancestors
        # with position channels, does.
        traj = next((j for j in [pelvis, *reversed(ancestors(topo, pelvis))]
                     if {c[0] for c in topo.channels[j] if c.endswith("position")} == set("XYZ")), None)
        if traj is None:
            raise UserError(f"body map: the trajectory joint {topo.names[bm.trajectory]!r} is neither the "
                            f"pelvis {topo.names[pelvis]!r} nor one of its ancestors, and none of those has "
                            "X, Y and Z position channels")
    with jax.ensure_compile_time_eval():
        return RootJoints(traj, pelvis, _facing_local(motion, bm))


def relative_position(motion, base: int, joint: int) -> np.ndarray:
    """Position [F, 3] of ``joint`` in the frame of its ancestor ``base``."""
    chain = []
    j = joint
    while j != base:
        chain.append(j)
        j = motion.topology.parents[j]
    pos = quat = None
    for j in chain[::-1]:
        t, q = local_transform(motion, j)
        if pos is None:
            pos, quat = t, q
        else:
            pos = pos + rot("quat_apply", quat, t)
            quat = rot("quat_multiply", quat, q)
    return pos


def _facing_local(motion, bm) -> tuple[float, float, float]:
    """Where the body faces in the pelvis's frame: ``(left hip - right hip) x up``, averaged over
    frames. Not snapped to a local axis: a change of the pelvis's joint frame ``C`` maps it to
    ``C^T f``, so the world facing, and the heading, are the same on every rig (snapped, CMU's
    was its local +Z, 0.21 degrees from the hips' on 07_01, while a rewrite's was not)."""
    _, q = world_pose(motion, bm.pelvis)
    lat = relative_position(motion, bm.pelvis, bm.left.hip) - relative_position(motion, bm.pelvis, bm.right.hip)
    conj = q * np.array([1.0, -1.0, -1.0, -1.0])
    up = rot("quat_apply", conj, np.tile([0.0, 1.0, 0.0], (len(q), 1)))
    f = np.cross(lat, up).mean(axis=0)
    n = np.linalg.norm(f)
    if not np.isfinite(n) or n < 1e-12:
        return (0.0, 0.0, 1.0)
    f = f / n
    return tuple(float(v) for v in f)  # type: ignore[return-value]


def place_root(motion, root_position: Float[ArrayLike, "F 3"], *, body_map=None):
    """The motion with its pelvis's world position moved to `root_position` exactly.

    The move goes into the trajectory joint's position channels (in its parent's frame), as
    `motion_from_features` writes the travel; rotations are unchanged. On CMU both are joint 0,
    whose position channels are set to `root_position`.

    Arguments:
        motion: a Motion (e.g. from `motion_from_features`).
        root_position: `[F, 3]` world positions of the pelvis, file units.
        body_map: the skeleton's `fourierjax.body.BodyMap`; None infers it from `motion`.

    Returns:
        A Motion with the same frames.
    """
    rj = root_joints(motion, body_map)
    target = as_f64(root_position)
    if target.shape != (motion.num_frames, 3):
        raise UserError(f"place_root: root_position has shape {target.shape}, expected ({motion.num_frames}, 3)")
    topo = motion.topology
    traj, parent = rj.trajectory, topo.parents[rj.trajectory]
    axes = {c[0]: k for k, c in enumerate(topo.channels[traj]) if c.endswith("position")}
    if set(axes) != set("XYZ"):
        raise UserError(f"place_root: the trajectory joint {topo.names[traj]!r} has no X, Y and Z position channels")
    ch = np.array(motion.channels, np.float64)
    base = topo.channel_offsets[traj]
    if traj == rj.pelvis and parent < 0:  # position channels replace the offset: set them exactly
        for a, k in axes.items():
            ch[:, base + k] = target[:, "XYZ".index(a)]
    else:
        pos, _ = world_pose(motion, rj.pelvis)
        delta = target - pos
        if parent >= 0:
            _, q_parent = world_pose(motion, parent)
            delta = rot("quat_apply", rot("quat_conjugate", q_parent), delta)
        for a, k in axes.items():
            ch[:, base + k] += delta[:, "XYZ".index(a)]
    return dataclasses.replace(motion, channels=ch)
