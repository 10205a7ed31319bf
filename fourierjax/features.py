"""The Fourier feature layout: channel names, Motion <-> features, and poses from features.

Features are one column per channel: ``ROOT_CHANNELS`` (heading-frame root velocity and height)
first, then every joint's rotation in radians, as Euler angles in the file's order
(``"<joint>.<Z|Y|X>rotation"``) or a continuous exponential map (``"<joint>.expmap0..2"``; for
``"tangent"`` models ``"<joint>.expmap_tangent0..2"``, also expmaps as features: only the model's
coefficients are tangent coordinates about the clip means, `fourierjax._fourier._tangent`).
"""

from __future__ import annotations

import dataclasses
from typing import TYPE_CHECKING

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, ArrayLike, Bool, Float

from fourierjax import _eulerscan, rotations
from fourierjax._checks import number
from fourierjax._fourier._layout import (
    ancestors as _ancestors,
)
from fourierjax._fourier._layout import (
    as_f64 as _np,
)
from fourierjax._fourier._layout import (
    local_transform as _local_transform,
)
from fourierjax._fourier._layout import (
    place_root,
    root_joints,
)
from fourierjax._fourier._layout import (
    rot as _rot,
)
from fourierjax._fourier._layout import (
    rotation_joints as _rotation_joints,
)
from fourierjax._fourier._layout import (
    world_pose as _world_pose,
)
from fourierjax._fourier._layout import (
    yaw_quat as _yaw_quat,
)
from fourierjax.errors import UserError
from fourierjax.skeleton import Skeleton, Topology

if TYPE_CHECKING:  # imported where used at run time: `fourierjax._fourier` imports this module
    from fourierjax._fourier._model import FourierModel

#: Feature representations of joint rotations.
REPRESENTATIONS = ("euler", "expmap", "tangent")
#: The root channels that start every feature layout: heading-frame velocity (file units/s) and
#: root height (file units). Root position is integrated from the velocities when written back.
ROOT_CHANNELS = ("root.vx", "root.vz", "root.y")
#: Channel name stems of the expmap-valued feature layouts.
_EXPMAP_SUFFIX = {"expmap": "expmap", "tangent": "expmap_tangent"}

__all__ = [
    "REPRESENTATIONS",
    "ROOT_CHANNELS",
    "angle_channel_mask",
    "channel_names_for",
    "heading_of",
    "features_from_motion",
    "motion_from_features",
    "place_root",
    "channel_model",
    "make_euler_continuous",
    "local_pose_from_features",
    "root_relative_positions",
    "joint_expmaps",
]


def angle_channel_mask(channel_names: tuple[str, ...]) -> tuple[bool, ...]:
    """True for rotation channels, False for the root translation channels ``root.*``.

    Arguments:
        channel_names: feature channel names.

    Returns:
        One bool per channel.
    """
    return tuple(not name.startswith("root.") for name in channel_names)


def channel_names_for(topology: Topology, representation: str) -> tuple[str, ...]:
    """Feature channel names for a skeleton: ``ROOT_CHANNELS`` then each joint's rotation."""
    if representation not in REPRESENTATIONS:
        raise UserError(f"representation: {representation!r} is not one of {REPRESENTATIONS}")
    names = list(ROOT_CHANNELS)
    for j, order, _ in _rotation_joints(topology):
        joint = topology.names[j]
        if representation == "euler":
            names += [f"{joint}.{axis}rotation" for axis in order]
        else:
            names += [f"{joint}.{_EXPMAP_SUFFIX[representation]}{k}" for k in range(3)]
    return tuple(names)


def heading_of(motion, *, body_map=None) -> float:
    """Circular mean (radians) of the body's facing yaw, from the pelvis's world orientation.

    The facing is the pelvis-frame direction ``(left hip - right hip) x up`` of the body map
    averaged over the clip (within a few degrees of CMU's local +Z, but not snapped to it, so that
    every rig's joint frames give the same heading), turned to world axes each frame and
    projected on the floor;
    ``psi = atan2(f_x, f_z)``, so a rotation by ``psi`` about +Y takes +Z to the facing.

    Arguments:
        motion: a Motion (Y up).
        body_map: the clip's `fourierjax.body.BodyMap`; None infers it.

    Returns:
        The heading in radians.
    """
    rj = root_joints(motion, body_map)
    _, q = _world_pose(motion, rj.pelvis)
    f = _rot("quat_apply", q, np.tile(np.array(rj.facing_local), (len(q), 1)))
    s, c = f[:, 0].sum(), f[:, 2].sum()
    if np.hypot(s, c) < 1e-9 * len(f):
        return 0.0
    return float(np.arctan2(s, c))


def check_static_above(motion, rj) -> None:
    """Joints above the trajectory joint are written back at the template's values: refuse a
    clip where they move."""
    topo = motion.topology
    for j in _ancestors(topo, rj.trajectory):
        base = topo.channel_offsets[j]
        n = len(topo.channels[j])
        if n and motion.num_frames > 1:
            span = float(np.ptp(motion.channels[:, base:base + n], axis=0).max())
            if span > 1e-6 * (1.0 + float(np.abs(motion.channels[:, base:base + n]).max())):
                raise UserError(
                    f"{motion.source or 'motion'}: joint {topo.names[j]!r}, above the trajectory joint "
                    f"{topo.names[rj.trajectory]!r}, moves (its channels span {span:.4g}); the root "
                    "features cannot be written back. Name the moving joint as `trajectory` in a body map")


def make_euler_continuous(
    angles: Float[ArrayLike, "F *joints 3"], order: str,
    valid: Bool[ArrayLike, " F"] | Bool[ArrayLike, " F *joints"] | None = None
) -> Float[np.ndarray, "F *joints 3"]:
    """Continuous Euler angles over time (radians): unwrap 2 pi jumps AND repair gimbal flips.

    Every rotation has two Euler triples (Tait-Bryan ``(a, b, c) ~ (a + pi, pi - b, c + pi)``;
    proper Euler ``(a, b, c) ~ (a + pi, -b, c + pi)``), each up to 2 pi per angle. ``np.unwrap``
    only removes the 2 pi jumps; near gimbal lock a clip can switch triples, which looks like a
    jump of ~pi in two angles. Each frame takes, of the two triples (each unwrapped towards the
    previous frame), the one closest to the previous frame. The first frame is kept.

    Frames with ``valid`` False (capture glitches) are repaired too but never serve as the
    reference: the next valid frame follows the last valid one, so a glitch that passes near
    gimbal lock cannot leave the rest of the clip on the other triple, 2 pi away.

    Arguments:
        angles: ``[F, ..., 3]`` radians; order: the 3-letter order of the angles;
        valid: optional ``bool [F]``, or ``bool [F, ...]`` per joint (a glitch of one joint).
    Returns:
        ``[F, ..., 3]`` the same rotations, continuous over the first axis.
    Raises:
        UserError: ``order`` not one of ``rotations.EULER_ORDERS``, or ``angles`` not
        ``[F, ..., 3]``.
    """
    if not isinstance(order, str) or order not in rotations.EULER_ORDERS:
        raise UserError(f"make_euler_continuous: `order` must be one of "
                        f"{', '.join(rotations.EULER_ORDERS)}, got {order!r}")
    a = np.array(angles, dtype=np.float64, copy=True)
    if a.ndim < 2 or a.shape[-1] != 3:
        raise UserError(f"make_euler_continuous: `angles` must have shape [F, ..., 3], got "
                        f"{a.shape}")
    if a.shape[0] < 2:
        return a
    F = a.shape[0]
    flat = a.reshape(F, -1, 3)
    ok = np.ones(flat.shape[:2], bool) if valid is None else np.broadcast_to(
        np.asarray(valid, bool).reshape(F, -1), flat.shape[:2])
    # Of the raw frames, all at once; then a parallel prefix over frames (no frame loop).
    a = _eulerscan.continuous(flat, rotations.euler_twin(flat.copy(), order), ok).reshape(a.shape)
    return a


def features_from_motion(
    motion, representation: str = "euler", heading_rad: float | None = None,
    valid: Bool[ArrayLike, " F"] | None = None, *, body_map=None,
) -> tuple[Float[np.ndarray, "F C"], tuple[str, ...]]:
    """Fitting features of a clip: heading-frame root velocity and height, joint rotations.

    The root features come from the world pose of the body map's pelvis (through FK of its
    ancestors): its ground-plane velocity and height, and its orientation relative to the
    heading, which replaces the pelvis's own rotation channels. On CMU the pelvis is joint 0.

    Arguments:
        motion: a ``fourierjax.io.bvh.Motion`` (at least 2 frames).
        representation: ``"euler"`` (file Euler angles, made continuous with
            :func:`make_euler_continuous`) or ``"expmap"`` (exponential maps made continuous,
            Tilmanne & Dutoit §2.1).
        heading_rad: yaw of the heading frame; default :func:`heading_of` the clip.
        valid: optional ``bool [F]``, or ``bool [F, J]`` per joint (file order), False at
            capture glitches (Euler continuity skips them).
        body_map: the clip's `fourierjax.body.BodyMap`; None infers it.
    Returns:
        ``(features [F, C] float64, channel_names)``: ``root.vx, root.vz`` (file units/s, by
        central differences), ``root.y`` (file units), then rotations in radians.
    """
    names = channel_names_for(motion.topology, representation)
    if motion.num_frames < 2:
        raise UserError(f"features_from_motion: need at least 2 frames, got {motion.num_frames}")
    rj = root_joints(motion, body_map)
    check_static_above(motion, rj)
    psi = (heading_of(motion, body_map=body_map) if heading_rad is None
           else number(heading_rad, "features_from_motion: `heading_rad`"))
    pos, q_root = _world_pose(motion, rj.pelvis)
    c, s = np.cos(psi), np.sin(psi)
    # World -> heading frame: rotate by -psi about +Y.
    x_h = c * pos[:, 0] - s * pos[:, 2]
    z_h = s * pos[:, 0] + c * pos[:, 2]
    dt = motion.frame_time_s
    vx, vz = np.gradient(x_h, dt), np.gradient(z_h, dt)
    q_rel = _rot("quat_multiply", np.tile(_yaw_quat(-psi), (len(q_root), 1)), q_root)
    cols = [vx, vz, pos[:, 1]]
    joints = _rotation_joints(motion.topology)
    blocks = _joint_rotations(motion, joints, representation, root_quat=q_rel, root_joint=rj.pelvis,
                              valid=valid)
    for j, _, _ in joints:
        cols += [blocks[j][:, 0], blocks[j][:, 1], blocks[j][:, 2]]
    return np.stack(cols, axis=1), names


def _joint_rotations(motion, joints, representation: str, *, root_quat=None, root_joint: int = 0,
                     valid=None) -> dict[int, np.ndarray]:
    """Rotation of each of ``joints`` (from :func:`_rotation_joints`) over the clip, ``{joint:
    [F, 3]}`` radians: continuous Euler angles in the file's order, or continuous exponential
    maps. ``root_quat [F, 4]`` replaces the rotation of ``root_joint`` (the pelvis) when given."""
    blocks: dict[int, np.ndarray] = {}
    # Joints sharing a rotation order are converted together: [F, J_g, 3].
    for order in dict.fromkeys(o for _, o, _ in joints):
        group = [(j, idx) for j, o, idx in joints if o == order]
        e = np.radians(motion.channels[:, np.array([idx for _, idx in group])])
        members = [j for j, _ in group]
        root = root_quat is not None and root_joint in members
        r = members.index(root_joint) if root else 0
        if root:  # the pelvis: e.g. its orientation relative to the heading frame
            e[:, r] = _rot("euler_from_quat", root_quat, order=order)
        if representation == "euler":
            v = valid
            if v is not None and np.ndim(v) == 2:  # per joint
                v = np.asarray(v, bool)[:, members]
            ang = make_euler_continuous(e, order, v)
        else:
            q = _rot("quat_from_euler", e, order=order)
            if root:
                q[:, r] = root_quat
            ang = _rot("make_expmap_continuous", _rot("expmap_from_quat", q))
        for k, (j, _) in enumerate(group):
            blocks[j] = ang[:, k]
    return blocks


def joint_expmaps(motion) -> tuple[Float[np.ndarray, "F K3"], tuple[str, ...]]:
    """Continuous exponential maps of every non-root joint of a clip (Tilmanne & Dutoit §2.1).

    The root is left out (its rotation includes the walking direction); so are joints without
    three rotation channels. Each joint's map is made continuous over time
    (``rotations.make_expmap_continuous``), so that spectra and fits see no 2π jumps.

    Arguments:
        motion: a ``fourierjax.io.bvh.Motion``.
    Returns:
        ``(x [F, 3K] float64 radians, names)`` with names ``"<joint>.expmap0..2"`` (the
        expmap layout of :func:`channel_names_for`, without the root channels).
    """
    joints = [jt for jt in _rotation_joints(motion.topology, strict=False) if jt[0] != 0]
    names = tuple(f"{motion.topology.names[j]}.expmap{k}" for j, _, _ in joints
                  for k in range(3))
    if not joints:
        return np.zeros((motion.num_frames, 0)), names
    blocks = _joint_rotations(motion, joints, "expmap")
    return np.concatenate([blocks[j] for j, _, _ in joints], axis=1), names


def _check_names(topology, channel_names, where: str) -> str:
    names = tuple(channel_names)
    for rep in REPRESENTATIONS:
        if names == channel_names_for(topology, rep):
            return rep
    raise UserError(
        f"{where}: channel names do not match this skeleton (expected the layout of "
        f"channel_names_for(topology, 'euler' | 'expmap'), got {names[:5]}...)"
    )


def motion_from_features(
    template,
    features: Float[ArrayLike, "F C"],
    channel_names: tuple[str, ...],
    frame_time_s: float,
    *,
    heading_rad: float = 0.0,
    start_xz: tuple[float, float] = (0.0, 0.0),
    body_map=None,
):
    """A writeable Motion from features (e.g. ``synthesize`` output) on a template's skeleton.

    The root position is integrated from ``root.vx, root.vz`` (trapezoid rule, starting at
    ``start_xz``) in the heading frame rotated by ``heading_rad`` about +Y (0: walking along +Z);
    its height is ``root.y``. This is the world pose of the body map's pelvis: the travel goes
    into the trajectory joint's position channels (in its parent's frame) and the orientation
    into the pelvis's rotation channels, with the joints above the pelvis at the template's
    first-frame values (CMU: both are joint 0). Rotations are converted back to the file's
    Euler orders in degrees. Other position channels keep the template's first-frame values.

    Arguments:
        template: Motion supplying topology, offsets and channel layout.
        features: ``[F, C]``; channel_names: their names (the layout of :func:`channel_names_for`).
        frame_time_s: seconds per frame of the new motion.
        body_map: the template's `fourierjax.body.BodyMap`; None infers it.
    Returns:
        Motion with ``F`` frames.
    Raises:
        UserError: channel names or feature shape that do not fit the template, NaN or
        infinite features, a non-finite ``heading_rad`` or ``start_xz``, or a non-finite or
        non-positive ``frame_time_s``.
    """
    where = "motion_from_features"
    topo = template.topology
    rep = _check_names(topo, channel_names, where)
    x = _np(features)
    if x.ndim != 2 or x.shape[1] != len(channel_names):
        raise UserError(
            f"motion_from_features: features shape {x.shape}, expected [F, {len(channel_names)}]"
        )
    bad = ~np.isfinite(x)
    if bad.any():
        f, c = np.argwhere(bad)[0]
        raise UserError(f"{where}: `features` holds NaN or infinite values (first at frame {f}, "
                        f"channel {channel_names[c]!r})")
    frame_time_s = number(frame_time_s, f"{where}: `frame_time_s`")
    if frame_time_s <= 0:
        raise UserError(f"{where}: `frame_time_s` must be positive, got {frame_time_s}")
    heading_rad = number(heading_rad, f"{where}: `heading_rad`")
    if np.shape(start_xz) != (2,):
        raise UserError(f"{where}: `start_xz` must be two numbers (x, z), got {start_xz!r}")
    start_xz = tuple(number(v, f"{where}: `start_xz`") for v in start_xz)
    F = x.shape[0]
    out = np.empty((F, topo.num_channels), np.float64)
    out[:] = template.channels[:1] if template.num_frames else 0.0
    vx, vz, y = x[:, 0], x[:, 1], x[:, 2]
    px = np.concatenate([[0.0], np.cumsum(0.5 * (vx[1:] + vx[:-1]) * frame_time_s)])
    pz = np.concatenate([[0.0], np.cumsum(0.5 * (vz[1:] + vz[:-1]) * frame_time_s)])
    c, s = np.cos(heading_rad), np.sin(heading_rad)
    world = {"X": start_xz[0] + c * px + s * pz, "Y": y, "Z": start_xz[1] - s * px + c * pz}
    rj = root_joints(template, body_map)
    pelvis, traj = rj.pelvis, rj.trajectory
    # The pelvis's world pose is written back through the trajectory joint's position channels
    # and the pelvis's rotation channels; the joints above the pelvis keep the template's values.
    general = not (pelvis == traj == 0)
    above = set(_ancestors(topo, pelvis))
    if general:
        first = template if template.num_frames else None
        tq = {j: _local_transform(first, j, np.array([0])) if first is not None else
              (np.asarray(template.offsets[j], np.float64)[None], np.array([[1.0, 0, 0, 0]]))
              for j in [*_ancestors(topo, pelvis), pelvis]}
        pre_t, pre_q = np.zeros((1, 3)), np.array([[1.0, 0.0, 0.0, 0.0]])  # world of traj's parent
        for j in _ancestors(topo, traj):
            pre_t = pre_t + _rot("quat_apply", pre_q, tq[j][0])
            pre_q = _rot("quat_multiply", pre_q, tq[j][1])
        chain = [*[j for j in _ancestors(topo, pelvis) if j not in _ancestors(topo, traj)], pelvis]
        # Pelvis in the trajectory joint's parent frame: t_0 + q_0 (t_1 + q_1 (... + t_pelvis)),
        # chain = (trajectory, ..., pelvis); all but t_0 at the template's values.
        tail = np.zeros((1, 3))
        if len(chain) > 1:
            tail = tq[pelvis][0]
            for j in chain[-2:0:-1]:
                tail = tq[j][0] + _rot("quat_apply", tq[j][1], tail)
            tail = _rot("quat_apply", tq[traj][1], tail)
        rot_above = pre_q
        for j in chain[:-1]:
            rot_above = _rot("quat_multiply", rot_above, tq[j][1])
        conj = pre_q * np.array([1.0, -1.0, -1.0, -1.0])
        p_world = np.stack([world["X"], world["Y"], world["Z"]], axis=1)
        t_traj = _rot("quat_apply", np.tile(conj, (F, 1)), p_world - pre_t) - tail
        world = {"X": t_traj[:, 0], "Y": t_traj[:, 1], "Z": t_traj[:, 2]}
        rot_above_inv = np.tile(rot_above * np.array([1.0, -1.0, -1.0, -1.0]), (F, 1))
    col = 3
    for j, order, idx in _rotation_joints(topo):
        ang = x[:, col : col + 3]
        col += 3
        if j in above:
            continue  # the template's values
        if j == pelvis or rep != "euler":
            q = (_rot("quat_from_euler", ang, order=order) if rep == "euler"
                 else _rot("quat_from_expmap", ang))
            if j == pelvis:
                q = _rot("quat_multiply", np.tile(_yaw_quat(heading_rad), (F, 1)), q)
                if general:
                    q = _rot("quat_multiply", rot_above_inv, q)
            ang = make_euler_continuous(_rot("euler_from_quat", q, order=order), order)
        out[:, idx] = np.degrees(ang)
    base = topo.channel_offsets[traj]
    for k, ch in enumerate(topo.channels[traj]):
        if ch.endswith("position"):
            out[:, base + k] = world[ch[0]]
    return dataclasses.replace(template, channels=out, frame_time_s=float(frame_time_s),
                               source=None)


def channel_model(
    template, model: FourierModel, root_xz: Float[ArrayLike, "*batch 2"] = (0.0, 0.0)
) -> FourierModel:
    """A Fourier model of the template's BVH channels from a gait model: a walker in place.

    ``motion_from_features`` in the frequency domain, for models of ``"euler"`` features (e.g.
    ``fit_motions(..., "euler")``, ``style.interpolate`` of such fits): the result animates
    every BVH channel of ``template`` in file order and units, which is what
    ``crowd.make_crowd`` and ``kinematics.joint_positions`` of its synthesis take. Per channel:

    - joint rotations: the features in degrees (offset and amplitudes times 180/pi, phases
      unchanged; the root's is relative to the heading frame, so every walker faces +Z);
    - root X / Z position: the integral of ``root.vx`` / ``root.vz`` without their mean (a
      treadmill: amplitude A_n / (n omega), phase phi_n - pi/2), swaying about ``root_xz``;
    - root Y position: ``root.y``; other channels (non-root positions, rotations of joints
      the features leave out): the template's first frame, constant.

    Exact: the synthesis of the result equals ``motion_from_features`` of the model's synthesis
    up to that function's trapezoid integration and the dropped drift (tested). Pure ``jnp``:
    leading batch axes of ``model`` (``fourier.stack_models``) and of ``root_xz`` broadcast, and
    it runs under ``jit``, ``vmap`` and ``grad``.

    Arguments:
        template: the Motion whose skeleton and channel layout the result animates (the
            features' skeleton: ``model.channel_names`` must be its ``channel_names_for``).
        model: a ``FourierModel`` of ``"euler"`` features, optionally batched ``[..., C, N]``.
        root_xz: ``[..., 2]`` centre of each walker's root on the ground (file units).
    Returns:
        A ``FourierModel`` with ``channel_names = template.topology.flat_channel_names``.
    Raises:
        UserError naming ``model`` for expmap features, channel names of another skeleton or a
        non-positive omega, and ``root_xz`` for a last axis other than 2.
    """
    from fourierjax._fourier._model import FourierModel
    from fourierjax._math import wrap_angle

    topo = template.topology
    if not isinstance(model, FourierModel):
        raise UserError(f"channel_model: `model` must be a FourierModel, got {type(model).__name__}")
    rep = _check_names(topo, model.channel_names, "channel_model: `model`")
    if rep != "euler":
        raise UserError(
            f"channel_model: `model` has {rep} features; BVH channels are Euler angles, which "
            "are not linear in exponential maps (fit with representation='euler')"
        )
    omega = model.omega
    if isinstance(omega, jax.core.Tracer):  # refused at run time (a value check that holds under jit)
        omega = eqx.error_if(omega, ~jnp.all(omega > 0), "channel_model: `model` omega must be > 0 (rad/s)")
    elif not bool(np.all(np.asarray(omega) > 0)):
        raise UserError(f"channel_model: `model` omega must be > 0 (rad/s), got {np.asarray(omega)}")
    root_xz = jnp.asarray(root_xz, model.offset.dtype)
    if root_xz.ndim == 0 or root_xz.shape[-1] != 2:
        raise UserError(f"channel_model: `root_xz` must be [..., 2] (X, Z), got shape {root_xz.shape}")
    feature = {n: i for i, n in enumerate(model.channel_names)}
    root = topo.names[_channel_model_root(template)]
    position = {f"{root}.Xposition": "root.vx", f"{root}.Yposition": "root.y",
                f"{root}.Zposition": "root.vz"}  # fmt: skip
    names = topo.flat_channel_names
    # Per BVH channel: its feature (or -1 for a constant), scale, and whether it is integrated.
    src = np.array([feature.get(position.get(n, n), -1) for n in names])
    scale = np.array([180.0 / np.pi if n.endswith("rotation") else 1.0 for n in names])
    integrated = np.array([n in (f"{root}.Xposition", f"{root}.Zposition") for n in names])
    constant = src < 0
    first = template.channels[0] if template.num_frames else np.zeros(len(names))
    dtype = model.offset.dtype
    lead = jnp.broadcast_shapes(model.offset.shape[:-1], root_xz.shape[:-1])
    C, N = len(names), model.amplitude.shape[-1]

    def full(x, shape):  # a constant table at the rank of `shape` (rank promotion is explicit)
        x = jnp.asarray(x)
        return jnp.broadcast_to(x.reshape((1,) * (len(shape) - x.ndim) + x.shape), shape)

    per_channel, per_term = lead + (C,), lead + (C, N)
    take = np.maximum(src, 0)
    n_omega = full(jnp.arange(1, N + 1, dtype=dtype), per_term) * full(omega[..., None, None], per_term)
    amp = full(model.amplitude[..., take, :], per_term) * full(jnp.asarray(scale[:, None], dtype), per_term)
    amp = jnp.where(full(integrated[:, None], per_term), amp / n_omega, amp)
    phase = full(model.phase[..., take, :], per_term)
    phase = jnp.where(full(integrated[:, None], per_term), wrap_angle(phase - 0.5 * jnp.pi), phase)
    offset = full(model.offset[..., take], per_channel) * full(jnp.asarray(scale, dtype), per_channel)
    for c, n in enumerate(names):
        axis = {f"{root}.Xposition": 0, f"{root}.Zposition": 1}.get(n)
        if axis is not None:  # the integral's constant: the walker's spot
            offset = offset.at[..., c].set(jnp.broadcast_to(root_xz[..., axis], lead))
    offset = jnp.where(full(constant, per_channel), full(jnp.asarray(first, dtype), per_channel), offset)
    amp = jnp.where(full(constant[:, None], per_term), 0.0, amp)
    phase = jnp.where(full(constant[:, None], per_term), 0.0, phase)
    omega = jnp.broadcast_to(omega, lead)
    return FourierModel(offset, amp, phase, omega, "euler", names)


def _channel_model_root(template) -> int:
    """The joint whose position channels take the travel in `channel_model`: the body map's
    pelvis, which must carry it (the trajectory joint) below joints at rest (Bandai: `Hips` under a
    `joint_Root` at the origin; CMU: joint 0)."""
    rj = root_joints(template)
    topo = template.topology
    if rj.pelvis != rj.trajectory:
        raise UserError(
            f"channel_model: the travel is on {topo.names[rj.trajectory]!r}, above the pelvis "
            f"{topo.names[rj.pelvis]!r}: a linear model of the BVH channels needs it on the pelvis")
    frame = np.array([0]) if template.num_frames else None
    for j in _ancestors(topo, rj.pelvis):
        with jax.ensure_compile_time_eval():  # the template is concrete, also under a trace
            t, q = ((np.asarray(template.offsets[j], np.float64)[None], np.array([[1.0, 0, 0, 0]]))
                    if frame is None else _local_transform(template, j, frame))
        if np.abs(t).max() > 1e-9 or np.abs(np.abs(q[0, 0]) - 1.0) > 1e-9:
            raise UserError(f"channel_model: joint {topo.names[j]!r} above the pelvis is not at the "
                            "origin with no rotation in the template")
    return rj.pelvis


def _layout_tables(topology, representation):
    """Static gather tables: per order, (joints, feature column triples)."""
    groups: dict[str, tuple[list[int], list[list[int]]]] = {}
    col = len(ROOT_CHANNELS)
    for j, order, _ in _rotation_joints(topology):
        key = order if representation == "euler" else "expmap"
        js, cols = groups.setdefault(key, ([], []))
        js.append(j)
        cols.append([col, col + 1, col + 2])
        col += 3
    return {k: (np.asarray(js), np.asarray(cs)) for k, (js, cs) in groups.items()}


def local_pose_from_features(
    skeleton: Skeleton, features: Float[ArrayLike, " C"], representation: str, pelvis: int = 0
) -> tuple[Float[Array, "J 3"], Float[Array, "J 4"]]:
    """Local translations [J, 3] and rotations [J, 4] of one feature frame (pure JAX).

    The pelvis sits at the origin (root-relative) with its heading-frame orientation (its
    features are its world orientation): the joints above it collapse onto the origin with the
    identity rotation. Joints without rotation channels keep the identity.

    Arguments:
        skeleton: ``fourierjax.skeleton.Skeleton``; features: ``[C]`` one frame;
        representation: the features' representation;
        pelvis: the body map's pelvis (``BodyMap.pelvis``; CMU: joint 0), a static int.
    Returns:
        ``(translations [J, 3], quats [J, 4])`` for ``kinematics.forward_kinematics``.
    """
    topo = skeleton.topology
    features = jnp.asarray(features)
    J = topo.num_joints
    quats = jnp.zeros((J, 4), features.dtype).at[:, 0].set(1.0)
    for key, (js, cols) in _layout_tables(topo, representation).items():
        ang = features[cols]
        q = rotations.quat_from_expmap(ang) if key == "expmap" else rotations.quat_from_euler(
            ang, key)
        quats = quats.at[js].set(q)
    translations = jnp.asarray(skeleton.offsets, features.dtype).at[pelvis].set(0.0)
    above = _ancestors(topo, pelvis)
    if above:
        translations = translations.at[jnp.asarray(above)].set(0.0)
        quats = quats.at[jnp.asarray(above)].set(jnp.asarray([1.0, 0.0, 0.0, 0.0], features.dtype))
    return translations, quats


def root_relative_positions(
    skeleton: Skeleton, features: Float[ArrayLike, "T C"], representation: str, pelvis: int = 0
) -> Float[Array, "T J 3"]:
    """Joint positions [T, J, 3] with the pelvis at the origin (heading frame), through FK.

    Arguments:
        skeleton: the clip's Skeleton; features: ``[T, C]``; representation: of the features;
        pelvis: the body map's pelvis (static int; CMU: joint 0).
    Returns:
        ``[T, J, 3]`` file units.
    """
    from fourierjax.kinematics import forward_kinematics

    def one(f):
        return forward_kinematics(skeleton, *local_pose_from_features(skeleton, f, representation,
                                                                      pelvis)).positions

    return jax.vmap(one)(jnp.asarray(features))
