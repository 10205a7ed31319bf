"""Motion <-> Fourier fitting features (Euler / continuous expmap + heading-frame root motion).

The feature layout (one column per channel, radians for rotations) is documented in
``fourierjax.fourier``: three root channels ``root.vx, root.vz, root.y`` first, then every joint's
rotation as Euler angles in the file's order (``"<joint>.<Z|Y|X>rotation"``) or as a continuous
exponential map (``"<joint>.expmap0..2"``). The root's rotation is taken relative to the heading
frame (a yaw about +Y by the circular mean of the root's facing direction over the clip), so a
straight walk in any direction gives the same features, and root velocity is expressed in that
frame. ``motion_from_features`` inverts the conversion (root position integrated from velocity).
"""

from __future__ import annotations

import dataclasses

import jax
import jax.numpy as jnp
import numpy as np

from fourierjax import rotations
from fourierjax._checks import number
from fourierjax.errors import UserError
from fourierjax.fourier import REPRESENTATIONS, ROOT_CHANNELS

__all__ = [
    "channel_names_for",
    "heading_of",
    "features_from_motion",
    "motion_from_features",
    "channel_model",
    "make_euler_continuous",
    "local_pose_from_features",
    "root_relative_positions",
    "joint_expmaps",
    "motion_joint_positions",
    "model_joint_positions",
    "foot_positions_of",
    "foot_contacts_of",
]

_AXES = "XYZ"


def _rotation_joints(topology, *, strict: bool = True) -> list[tuple[int, str, list[int]]]:
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


def channel_names_for(topology, representation: str) -> tuple[str, ...]:
    """Feature channel names for a skeleton: ``ROOT_CHANNELS`` then each joint's rotation."""
    if representation not in REPRESENTATIONS:
        raise UserError(f"representation: {representation!r} is not one of {REPRESENTATIONS}")
    names = list(ROOT_CHANNELS)
    for j, order, _ in _rotation_joints(topology):
        joint = topology.names[j]
        if representation == "euler":
            names += [f"{joint}.{axis}rotation" for axis in order]
        else:
            names += [f"{joint}.expmap{k}" for k in range(3)]
    return tuple(names)


def _np(x) -> np.ndarray:
    return np.asarray(x, dtype=np.float64)


def _bucket(n: int) -> int:
    """Pad lengths to a few sizes so jitted code compiles once per bucket, not per clip."""
    return max(64, int(2 ** np.ceil(np.log2(max(n, 1)))))


_JITTED: dict = {}


def _rot(name: str, *arrays, **static) -> np.ndarray:
    """``rotations.<name>(*arrays)`` on NumPy arrays whose first axis is time: padded to a
    length bucket and run through one cached jit per function (eager JAX ops would compile
    again for every clip length)."""
    F = arrays[0].shape[0]
    Fp = _bucket(F)
    padded = [np.concatenate([a, np.repeat(a[-1:], Fp - F, axis=0)]) for a in arrays]
    key = (name, tuple(sorted(static.items())))
    fn = _JITTED.get(key)
    if fn is None:
        import functools

        fn = _JITTED[key] = jax.jit(functools.partial(getattr(rotations, name), **static))
    return _np(fn(*padded))[:F]


def _yaw_quat(psi: np.ndarray) -> np.ndarray:
    psi = np.asarray(psi, np.float64)
    z = np.zeros_like(psi)
    return np.stack([np.cos(psi / 2), z, np.sin(psi / 2), z], axis=-1)


def _root_pose(motion) -> tuple[np.ndarray, np.ndarray]:
    """Root world position [F, 3] and orientation [F, 4] (wxyz) of every frame."""
    topo = motion.topology
    chans = topo.channels[0]
    base = topo.channel_offsets[0]
    pos = np.broadcast_to(np.asarray(motion.offsets[0], np.float64),
                          (motion.num_frames, 3)).copy()
    for k, c in enumerate(chans):
        if c.endswith("position"):
            pos[:, _AXES.index(c[0])] = motion.channels[:, base + k]
    rot = [base + k for k, c in enumerate(chans) if c.endswith("rotation")]
    order = topo.rotation_orders[0]
    if order is None or len(order) != 3:
        raise UserError(f"root joint {topo.names[0]!r} needs 3 rotation channels, got {chans}")
    q = _rot("quat_from_euler", np.radians(motion.channels[:, rot]), order=order)
    return pos, q


def heading_of(motion) -> float:
    """Circular mean (radians) of the root's facing yaw: its local +Z projected on the floor.

    ``psi = atan2(f_x, f_z)``; a rotation by ``psi`` about +Y takes +Z to the facing direction.
    """
    _, q = _root_pose(motion)
    f = _rot("quat_apply", q, np.tile([0.0, 0.0, 1.0], (len(q), 1)))
    s, c = f[:, 0].sum(), f[:, 2].sum()
    if np.hypot(s, c) < 1e-9 * len(f):
        return 0.0
    return float(np.arctan2(s, c))


def make_euler_continuous(angles: np.ndarray, order: str, valid=None) -> np.ndarray:
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
        valid: optional ``bool [F]``.
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
    two_pi = 2 * np.pi
    ok = np.ones(a.shape[0], bool) if valid is None else np.asarray(valid, bool)
    ref = 0
    for t in range(1, a.shape[0]):
        prev = a[ref] if ok[t] else a[t - 1]
        cur = a[t]
        alt = rotations.euler_twin(cur, order)
        best = None
        best_d = None
        for cand in (cur, alt):
            cand = cand + two_pi * np.round((prev - cand) / two_pi)
            d = np.sum((cand - prev) ** 2, axis=-1)
            if best is None:
                best, best_d = cand, d
            else:
                take = d < best_d - 1e-12
                best = np.where(take[..., None], cand, best)
                best_d = np.minimum(d, best_d)
        a[t] = best
        if ok[t] or not ok[ref]:
            ref = t
    return a


def features_from_motion(
    motion, representation: str = "euler", heading_rad: float | None = None, valid=None
) -> tuple[np.ndarray, tuple[str, ...]]:
    """Fitting features of a clip: heading-frame root velocity and height, joint rotations.

    Arguments:
        motion: a ``fourierjax.io.bvh.Motion`` (at least 2 frames).
        representation: ``"euler"`` (file Euler angles, made continuous with
            :func:`make_euler_continuous`) or ``"expmap"`` (exponential maps made continuous,
            Tilmanne & Dutoit §2.1).
        heading_rad: yaw of the heading frame; default :func:`heading_of` the clip.
        valid: optional ``bool [F]``, False at capture glitches (Euler continuity skips them).
    Returns:
        ``(features [F, C] float64, channel_names)``: ``root.vx, root.vz`` (file units/s, by
        central differences), ``root.y`` (file units), then rotations in radians.
    """
    names = channel_names_for(motion.topology, representation)
    if motion.num_frames < 2:
        raise UserError(f"features_from_motion: need at least 2 frames, got {motion.num_frames}")
    psi = (heading_of(motion) if heading_rad is None
           else number(heading_rad, "features_from_motion: `heading_rad`"))
    pos, q_root = _root_pose(motion)
    c, s = np.cos(psi), np.sin(psi)
    # World -> heading frame: rotate by -psi about +Y.
    x_h = c * pos[:, 0] - s * pos[:, 2]
    z_h = s * pos[:, 0] + c * pos[:, 2]
    dt = motion.frame_time_s
    vx, vz = np.gradient(x_h, dt), np.gradient(z_h, dt)
    q_rel = _rot("quat_multiply", np.tile(_yaw_quat(-psi), (len(q_root), 1)), q_root)
    cols = [vx, vz, pos[:, 1]]
    joints = _rotation_joints(motion.topology)
    blocks = _joint_rotations(motion, joints, representation, root_quat=q_rel, valid=valid)
    for j, _, _ in joints:
        cols += [blocks[j][:, 0], blocks[j][:, 1], blocks[j][:, 2]]
    return np.stack(cols, axis=1), names


def _joint_rotations(motion, joints, representation: str, *, root_quat=None,
                     valid=None) -> dict[int, np.ndarray]:
    """Rotation of each of ``joints`` (from :func:`_rotation_joints`) over the clip, ``{joint:
    [F, 3]}`` radians: continuous Euler angles in the file's order, or continuous exponential
    maps. ``root_quat [F, 4]`` replaces the root's (joint 0) rotation when given."""
    blocks: dict[int, np.ndarray] = {}
    # Joints sharing a rotation order are converted together: [F, J_g, 3].
    for order in dict.fromkeys(o for _, o, _ in joints):
        group = [(j, idx) for j, o, idx in joints if o == order]
        e = np.radians(motion.channels[:, np.array([idx for _, idx in group])])
        root = group[0][0] == 0 and root_quat is not None
        if root:  # the root: e.g. its orientation relative to the heading frame
            e[:, 0] = _rot("euler_from_quat", root_quat, order=order)
        if representation == "euler":
            ang = make_euler_continuous(e, order, valid)
        else:
            q = _rot("quat_from_euler", e, order=order)
            if root:
                q[:, 0] = root_quat
            ang = _rot("make_expmap_continuous", _rot("expmap_from_quat", q))
        for k, (j, _) in enumerate(group):
            blocks[j] = ang[:, k]
    return blocks


def joint_expmaps(motion) -> tuple[np.ndarray, tuple[str, ...]]:
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
    features,
    channel_names,
    frame_time_s: float,
    *,
    heading_rad: float = 0.0,
    start_xz: tuple[float, float] = (0.0, 0.0),
):
    """A writeable Motion from features (e.g. ``synthesize`` output) on a template's skeleton.

    The root position is integrated from ``root.vx, root.vz`` (trapezoid rule, starting at
    ``start_xz``) in the heading frame rotated by ``heading_rad`` about +Y (0: walking along +Z);
    its height is ``root.y``. Rotations are converted back to the file's Euler orders in degrees.
    Position channels of non-root joints keep the template's first-frame values.

    Arguments:
        template: Motion supplying topology, offsets and channel layout.
        features: ``[F, C]``; channel_names: their names (the layout of :func:`channel_names_for`).
        frame_time_s: seconds per frame of the new motion.
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
    col = 3
    for j, order, idx in _rotation_joints(topo):
        ang = x[:, col : col + 3]
        col += 3
        if j == 0 or rep == "expmap":
            q = (_rot("quat_from_euler", ang, order=order) if rep == "euler"
                 else _rot("quat_from_expmap", ang))
            if j == 0:
                q = _rot("quat_multiply", np.tile(_yaw_quat(heading_rad), (F, 1)), q)
            ang = make_euler_continuous(_rot("euler_from_quat", q, order=order), order)
        out[:, idx] = np.degrees(ang)
    base = topo.channel_offsets[0]
    for k, ch in enumerate(topo.channels[0]):
        if ch.endswith("position"):
            out[:, base + k] = world[ch[0]]
    return dataclasses.replace(template, channels=out, frame_time_s=float(frame_time_s),
                               source=None)


def channel_model(template, model, root_xz=(0.0, 0.0)):
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
    from fourierjax.fourier import FourierModel, wrap_angle

    topo = template.topology
    if not isinstance(model, FourierModel):
        raise UserError(f"channel_model: `model` must be a FourierModel, got {type(model).__name__}")
    rep = _check_names(topo, model.channel_names, "channel_model: `model`")
    if rep != "euler":
        raise UserError(
            "channel_model: `model` has expmap features; BVH channels are Euler angles, which "
            "are not linear in exponential maps (fit with representation='euler')"
        )
    omega = model.omega
    if not isinstance(omega, jax.core.Tracer) and not bool(np.all(np.asarray(omega) > 0)):
        raise UserError(f"channel_model: `model` omega must be > 0 (rad/s), got {np.asarray(omega)}")
    root_xz = jnp.asarray(root_xz, model.offset.dtype)
    if root_xz.ndim == 0 or root_xz.shape[-1] != 2:
        raise UserError(f"channel_model: `root_xz` must be [..., 2] (X, Z), got shape {root_xz.shape}")
    feature = {n: i for i, n in enumerate(model.channel_names)}
    root = topo.names[0]
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


def local_pose_from_features(skeleton, features, representation: str):
    """Local translations [J, 3] and rotations [J, 4] of one feature frame (pure JAX).

    The root sits at the origin (root-relative) with its heading-frame orientation; joints
    without rotation channels keep the identity.

    Arguments:
        skeleton: ``fourierjax.skeleton.Skeleton``; features: ``[C]`` one frame;
        representation: the features' representation.
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
    translations = jnp.asarray(skeleton.offsets, features.dtype).at[0].set(0.0)
    return translations, quats


def root_relative_positions(skeleton, features, representation: str):
    """Joint positions [T, J, 3] with the root at the origin (heading frame), through FK.

    Arguments:
        skeleton: the clip's Skeleton; features: ``[T, C]``; representation: of the features.
    Returns:
        ``[T, J, 3]`` file units.
    """
    from fourierjax.kinematics import forward_kinematics

    def one(f):
        return forward_kinematics(skeleton, *local_pose_from_features(skeleton, f,
                                                                      representation)).positions

    return jax.vmap(one)(jnp.asarray(features))


def motion_joint_positions(motion, frames=None) -> np.ndarray:
    """World joint positions of a clip through forward kinematics of its BVH channels.

    Arguments:
        motion: a Motion; frames: optional frame indices (default: every frame).
    Returns:
        ``[F, J, 3]`` file units (JAX's default float dtype), joints in file order.
    """
    from fourierjax.kinematics import joint_positions

    ch = motion.channels if frames is None else motion.channels[np.asarray(frames)]
    return np.asarray(joint_positions(motion.skeleton(), jnp.asarray(ch)))


_root_relative_positions_jit = jax.jit(root_relative_positions, static_argnums=2)


def model_joint_positions(model, skeleton, phases) -> np.ndarray:
    """Joint positions of a Fourier gait model's pose at cycle phases (Unuma 1995 eq. 1).

    The pose is ``fourier.synthesize_phase(model, phases)`` through forward kinematics; the
    root stands above the origin of the heading frame (facing +Z) at the model's ``root.y``
    height, so poses of different models line up for side-by-side plots.

    Arguments:
        model: a ``FourierModel`` with the gait channel layout (:func:`channel_names_for`);
        skeleton: the Skeleton the model was fitted on; phases: ``[K]`` radians of the cycle.
    Returns:
        ``[K, J, 3]`` file units.
    """
    from fourierjax import fourier

    feats = fourier.synthesize_phase(model, jnp.asarray(phases, float))
    p = np.asarray(_root_relative_positions_jit(skeleton, feats, model.representation))
    height = np.asarray(feats[:, ROOT_CHANNELS.index("root.y")])
    return p + height[:, None, None] * np.array([0.0, 1.0, 0.0])


def _hip_flexion_phase(model, motion, channel: int):
    """Phase of the left hip's peak flexion: the extreme of the hip channel's fundamental at
    which the left knee is further forward (+Z in the heading frame) than at the other.

    The channel's peak alone (``fourier.channel_event_phase``) is not enough: whether flexion is
    its maximum or its minimum depends on the skeleton's axes (on CMU skeletons flexion is
    negative ``LeftUpLeg.Xrotation``, and the peak is full extension, half a cycle off).
    """
    from fourierjax import fourier as fr

    peak = float(fr.channel_event_phase(model, channel))
    topo = motion.topology
    hip = topo.index("LeftUpLeg")
    knees = topo.children(hip)
    if not knees:
        return jnp.asarray(peak)
    p = model_joint_positions(model, motion.skeleton(), np.array([peak, peak + np.pi]))
    ahead = p[:, knees[0], 2] - p[:, hip, 2]
    return jnp.asarray(peak if ahead[0] >= ahead[1] else peak + np.pi)


def glitch_frames(motion, max_joint_speed_deg_s: float = 5000.0, pad_s: float = 0.1):
    """Capture glitches: ``bool [F]``, True within ``pad_s`` of a frame where some joint turns
    faster than ``max_joint_speed_deg_s`` (CMU 142_02's left arm jumps 60 degrees in one frame
    at frame 1140; captured motion stays under ~3200 deg/s, even at toes and fingers).

    ``fit_motions`` masks these frames out of the fit (time stays continuous around them).
    """
    F = motion.num_frames
    glitch = np.zeros(F, bool)
    joints = _rotation_joints(motion.topology)
    for order in dict.fromkeys(o for _, o, _ in joints):
        idx = np.array([i for _, o, i in joints if o == order])
        q = _rot("quat_from_euler", np.radians(motion.channels[:, idx]), order=order)
        dot = np.clip(np.abs(np.sum(q[1:] * q[:-1], axis=-1)), 0.0, 1.0)  # [F-1, J_g]
        fast = np.degrees(2 * np.arccos(dot)) / motion.frame_time_s > max_joint_speed_deg_s
        glitch[1:] |= fast.any(axis=1)
    out = glitch.copy()
    pad = max(1, int(round(pad_s / motion.frame_time_s)))
    for i in np.nonzero(glitch)[0]:
        out[max(0, i - pad) : i + pad + 1] = True
    return out


def steady_segment(
    motion,
    *,
    window_s: float = 0.5,
    min_speed_fraction: float = 0.75,
    max_turn_deg_s: float = 30.0,
    min_duration_s: float = 0.5,
) -> tuple[int, int]:
    """The longest steady, straight stretch of a clip: frames ``[start, stop)``.

    The root's horizontal velocity is smoothed over ``+-window_s`` (which averages out the
    in-step sway); a frame is steady when its smoothed speed is at least
    ``min_speed_fraction`` of the clip's 90th-percentile speed and its heading turns slower than
    ``max_turn_deg_s``. Clips that start from standing, stop, or walk back and forth (CMU
    142_02, 142_08) keep their longest steady run; if no run lasts ``min_duration_s`` the whole
    clip is returned. (Capture glitches inside it are masked by ``fit_motions``, see
    :func:`glitch_frames`.)

    Arguments:
        motion: a Motion. Returns: ``(start, stop)`` frame indices into ``motion``.
    """
    F = motion.num_frames
    pos, _ = _root_pose(motion)
    p = pos[:, [0, 2]]
    w = max(1, int(round(window_s / motion.frame_time_s)))
    idx = np.arange(F)
    hi, lo = np.minimum(idx + w, F - 1), np.maximum(idx - w, 0)
    span = np.maximum(hi - lo, 1) * motion.frame_time_s
    v = (p[hi] - p[lo]) / span[:, None]
    speed = np.hypot(v[:, 0], v[:, 1])
    heading = np.unwrap(np.arctan2(v[:, 0], v[:, 1]))
    turn = np.abs(np.gradient(heading, motion.frame_time_s)) if F > 1 else np.zeros(F)
    ref = np.percentile(speed, 90)
    if ref <= 0:
        return 0, F
    steady = (speed >= min_speed_fraction * ref) & (np.degrees(turn) <= max_turn_deg_s)
    best = (0, 0)
    start = None
    for i, s in enumerate(np.append(steady, False)):
        if s and start is None:
            start = i
        elif not s and start is not None:
            if i - start > best[1] - best[0]:
                best = (start, i)
            start = None
    if (best[1] - best[0]) * motion.frame_time_s < min_duration_s:
        return 0, F
    return best


# ----------------------------------------------------------------------------- clip fitting


@dataclasses.dataclass(frozen=True)
class ClipFit:
    """A fitted clip: the phase-aligned model plus what was used and how well it fits.

    Frames ``[frame_start, frame_stop)`` index the Motion given to :func:`fit_motions`. ω per
    method in rad/s (``omega_steps`` is NaN without step events). ``alignment`` names the event
    at phase 0 (``"left_heel_strike"``, the fallback ``"left_hip_flexion"`` or ``"none"``) and
    ``phase_shift`` the shift applied (a clip time t has aligned phase ``omega t - phase_shift``).
    Metrics are over the fitted frames: ``rms`` per channel (radians or file units),
    ``rms_deg`` and ``variance_explained_angles`` over rotation channels,
    ``variance_explained_positions`` over root-relative joint positions (through FK).
    ``masked_frames`` counts capture-glitch frames left out of the fit (:func:`glitch_frames`).
    """

    source: str | None
    frame_start: int
    frame_stop: int
    frame_time_s: float
    model: object
    raw_model: object
    alignment: str
    phase_shift: float
    omega_spectral: float
    omega_steps: float
    omega_fit: float
    rms: np.ndarray
    rms_deg: float
    variance_explained_angles: float
    variance_explained_positions: float
    left_heel_strikes: tuple[int, ...]
    right_heel_strikes: tuple[int, ...]
    masked_frames: int = 0

    @property
    def fundamental_hz(self) -> float:
        return self.omega_fit / (2 * np.pi)

    def summary(self) -> dict:
        """JSON-able summary (frequencies in Hz, metrics as floats)."""
        hz = 1 / (2 * np.pi)

        def f(v):
            return None if not np.isfinite(v) else float(v)

        return {
            "source": self.source,
            "frame_start": self.frame_start,
            "frame_stop": self.frame_stop,
            "num_frames": self.frame_stop - self.frame_start,
            "frame_time_s": self.frame_time_s,
            "num_harmonics": int(self.model.num_harmonics),
            "representation": self.model.representation,
            "fundamental_hz": f(self.omega_fit * hz),
            "fundamental_hz_spectral": f(self.omega_spectral * hz),
            "fundamental_hz_steps": f(self.omega_steps * hz),
            "fundamental_hz_fit": f(self.omega_fit * hz),
            "omega_rad_s": {"spectral": f(self.omega_spectral), "steps": f(self.omega_steps),
                            "fit": f(self.omega_fit)},
            "rms_deg": float(self.rms_deg),
            "variance_explained_angles": float(self.variance_explained_angles),
            "variance_explained_positions": float(self.variance_explained_positions),
            "alignment": self.alignment,
            "phase_shift_rad": float(self.phase_shift),
            "left_heel_strikes": list(self.left_heel_strikes),
            "right_heel_strikes": list(self.right_heel_strikes),
            "masked_glitch_frames": self.masked_frames,
        }


def foot_positions_of(motion, points=None) -> np.ndarray:
    """World positions of the foot points of every frame of a clip, through FK.

    Frames are padded to a few length buckets, so clips of similar lengths share one compiled
    FK.

    Arguments:
        motion: a Motion; points: ``contacts.FootPoints`` (default:
        ``contacts.foot_points(motion.topology)``, the CMU feet: ankle, toe, toe tip).
    Returns:
        ``[F, 2, P, 3]`` (left, right) file units, ready for ``contacts.foot_contacts`` and
        ``contacts.estimate_ground``.
    """
    from fourierjax import contacts
    from fourierjax.kinematics import fk_frames

    points = contacts.foot_points(motion.topology) if points is None else points
    F = motion.num_frames
    ch = np.concatenate([motion.channels, np.repeat(motion.channels[-1:], _bucket(F) - F, 0)])
    fk = fk_frames(motion.skeleton(), jnp.asarray(ch))
    return np.asarray(contacts.gather_foot_positions(fk.positions, fk.end_site_positions,
                                                     points))[:F]


def foot_contacts_of(motion) -> np.ndarray | None:
    """Foot contacts ``bool [F, 2]`` (left, right) of a clip: ``fourierjax.contacts`` on FK foot
    points (ankle, toe, toe tip). None when the skeleton has no CMU-named feet."""
    from fourierjax import contacts

    try:
        points = contacts.foot_points(motion.topology)
    except UserError:
        return None
    return contacts.foot_contacts(foot_positions_of(motion, points), motion.frame_time_s)


def _steps(contacts_lr, frame_time_s):
    """(left strikes, right strikes, omega from steps or NaN): Tilmanne §2.2, cycle = 2 steps.

    The step period is the MEDIAN interval (``contacts.step_period_s``), so that a spurious
    extra strike (stumbling, CMU 142_02) does not halve the cycle.
    """
    from fourierjax import contacts

    if contacts_lr is None:
        return np.zeros(0, int), np.zeros(0, int), float("nan")
    left, right = contacts.step_events(contacts_lr)
    try:
        step = contacts.step_period_s(contacts_lr, frame_time_s, statistic="median")
    except UserError:  # fewer than two alternating heel strikes
        return left, right, float("nan")
    # Both feet striking together (two-footed hops) can give a zero median: no step frequency.
    return left, right, float(2 * np.pi / (2 * step)) if step > 0 else float("nan")


def _position_ve(skeleton, representation, x, xhat, mask):
    return _position_ve_jit(skeleton, x, xhat, mask, representation)


def _position_ve_impl(skeleton, x, xhat, mask, representation):
    from fourierjax.fourier import variance_explained

    p = root_relative_positions(skeleton, x, representation)
    ph = root_relative_positions(skeleton, xhat, representation)
    return variance_explained(p, ph, mask)


_position_ve_jit = jax.jit(_position_ve_impl, static_argnames=("representation",))


def fit_motions(
    motions,
    num_harmonics: int = 3,
    representation: str = "euler",
    *,
    segment: bool = True,
    use_contacts: bool = True,
    dtype=None,
    **fit_kwargs,
) -> list[ClipFit]:
    """Fit Fourier models to clips: segment, convert, find ω three ways, fit, align, score.

    Per clip: the steady straight stretch (:func:`steady_segment`, unless ``segment=False``)
    with capture glitches masked out (:func:`glitch_frames`),
    its features (:func:`features_from_motion`), heel strikes from FK foot contacts
    (``fourierjax.contacts``; ω from steps, Tilmanne §2.2), then ONE batched
    :func:`fourierjax.fourier.fit_batch` call for all clips that share a channel layout (padding
    and masks), phase alignment to the left heel strike (fallback: the peak of the left hip
    flexion fundamental, ``LeftUpLeg.Xrotation`` / ``LeftUpLeg.expmap0``), and the metrics.

    Arguments:
        motions: a sequence of Motions (e.g. after dropping a rest frame).
        num_harmonics: N; representation: "euler" | "expmap".
        fit_kwargs: passed on to ``fit_batch`` (search band, grid...).
    Returns:
        One :class:`ClipFit` per motion, in order.
    """
    from fourierjax import fourier as fr

    motions = list(motions)
    if not motions:
        raise UserError("fit_motions: no motions given")
    dtype = dtype or jnp.zeros(()).dtype
    prepared = []
    for m in motions:
        a, b = steady_segment(m) if segment else (0, m.num_frames)
        sub = m[a:b]
        keep = ~glitch_frames(sub)
        x, names = features_from_motion(sub, representation, valid=keep)
        c = foot_contacts_of(sub) if use_contacts else None
        left, right, om = _steps(c, sub.frame_time_s)
        prepared.append((m, a, b, sub, x, names, left, right, om, keep))
    groups: dict[tuple[str, ...], list[int]] = {}
    for i, p in enumerate(prepared):
        groups.setdefault(p[5], []).append(i)
    results: list[ClipFit | None] = [None] * len(prepared)
    for names, idx in groups.items():
        T = _bucket(max(prepared[i][4].shape[0] for i in idx))
        C = len(names)
        feats = np.zeros((len(idx), T, C))
        mask = np.zeros((len(idx), T), bool)
        for k, i in enumerate(idx):
            x = prepared[i][4]
            feats[k, : len(x)] = x
            feats[k, len(x):] = x[-1]
            mask[k, : len(x)] = prepared[i][9]
        dts = np.array([prepared[i][3].frame_time_s for i in idx])
        om_steps = np.array([prepared[i][8] for i in idx])
        res = fr.fit_batch(jnp.asarray(feats, dtype), jnp.asarray(dts, dtype), num_harmonics,
                           mask=jnp.asarray(mask), omega_steps=jnp.asarray(om_steps, dtype),
                           representation=representation, channel_names=names, **fit_kwargs)
        for k, i in enumerate(idx):
            m, a, b, sub, x, _, left, right, _, keep = prepared[i]
            raw = jax.tree.map(lambda v: v[k], res.model)
            dt = sub.frame_time_s
            if len(left):
                # Circular mean of the strikes' phases (fourier.align_to_events, in NumPy so
                # that clips with different strike counts share compiled code).
                th = float(raw.omega) * np.asarray(left) * dt
                delta = float(np.arctan2(np.sin(th).sum(), np.cos(th).sum()))
                model = fr.shift_phase(raw, delta)
                alignment = "left_heel_strike"
            else:
                hip = [c for c in ("LeftUpLeg.Xrotation", "LeftUpLeg.expmap0") if c in names]
                if hip:
                    delta = _hip_flexion_phase(raw, sub, names.index(hip[0]))
                    model = fr.shift_phase(raw, delta)
                    alignment = "left_hip_flexion"
                else:
                    model, delta, alignment = raw, jnp.zeros(()), "none"
            t = jnp.arange(T, dtype=dtype) * dt
            xhat = fr.synthesize(raw, t)
            pve = _position_ve(sub.skeleton(), representation, jnp.asarray(feats[k], dtype),
                               xhat, jnp.asarray(mask[k]))
            results[i] = ClipFit(
                source=m.source, frame_start=int(a), frame_stop=int(b), frame_time_s=float(dt),
                model=model, raw_model=raw, alignment=alignment, phase_shift=float(delta),
                omega_spectral=float(res.omega_spectral[k]), omega_steps=float(om_steps[k]),
                omega_fit=float(res.omega_fit[k]), rms=np.asarray(res.rms[k]),
                rms_deg=float(res.rms_deg[k]),
                variance_explained_angles=float(res.variance_explained_angles[k]),
                variance_explained_positions=float(pve),
                left_heel_strikes=tuple(int(v) for v in left),
                right_heel_strikes=tuple(int(v) for v in right),
                masked_frames=int(np.sum(~keep)),
            )
    return results  # type: ignore[return-value]
