"""Joint and foot positions of clips and models through FK, and the position metric."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import ArrayLike, Bool, Float, Int

from fourierjax import _fk, _jit
from fourierjax._fourier._buckets import length_bucket as _bucket
from fourierjax._fourier._model import FourierModel
from fourierjax.features import ROOT_CHANNELS, channel_names_for, root_relative_positions
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


def _feature_quats(topology, x, representation, pelvis, expmap_quats=None):
    """Local rotations of every joint from feature rows ``x`` ``[C, *S]``, as
    `features.local_pose_from_features` makes them (the same formulas, batch axes minor): 4
    components ``[J, *S]``, identity for joints without rotation features and at and above
    the pelvis's ancestors (the pelvis keeps its own). ``expmap_quats``: the expmap-valued
    joints' quaternions ``[4, n, *S]`` when known (their features are then not read)."""
    from fourierjax._fourier._layout import ancestors
    from fourierjax._sincos import sincos
    from fourierjax.features import _layout_tables
    from fourierjax.rotations import quat_from_expmap

    shape, dtype = x.shape[1:], x.dtype
    parts, rows = [], {}
    at = 0
    for key, (js, cols) in _layout_tables(topology, representation).items():
        a = [x[np.asarray(cols[:, k])] for k in range(3)]  # [n, *S] each
        if key == "expmap" and expmap_quats is not None:
            q = expmap_quats
        elif key == "expmap":  # the library's exponential map (Taylor branch near zero)
            q = jnp.moveaxis(quat_from_expmap(jnp.stack(a, axis=-1)), -1, 0)  # [4, n, *S]
        else:  # rotations.quat_from_euler: the product of the three axis quaternions
            q = [1, 0, 0, 0]
            for ax, ang in zip(key, a, strict=True):
                sin, cos = sincos(0.5 * ang)
                e = [cos, 0, 0, 0]
                e[1 + "XYZ".index(ax)] = sin
                q = _fk.qmul(q, e)
        parts.append((len(js), q))
        for i, j in enumerate(js):
            rows[int(j)] = at + i
        at += len(js)
    ident = at  # one identity row after the groups' rows
    for j in ancestors(topology, pelvis):
        rows.pop(j, None)
    src = np.asarray([rows.get(j, ident) for j in range(topology.num_joints)])
    one = jnp.ones((1, *shape), dtype)
    zero = jnp.zeros((1, *shape), dtype)
    comps = []
    for k in range(4):
        col = [jnp.broadcast_to(jnp.asarray(q[k], dtype), (n, *shape)) for n, q in parts]
        comps.append(jnp.concatenate([*col, one if k == 0 else zero], axis=0)[src])
    return comps


def root_relative_positions_frames_last(topology, offsets, x, representation, pelvis):
    """`features.root_relative_positions` of feature rows ``x`` ``[C, *S]`` (batch axes minor,
    as `_fk`: one elementwise loop over the batch per depth level); ``offsets`` ``[J, 3, ...]``
    broadcastable against ``[J, 3, *S]`` (per-clip bones: a clip axis of size B, 1 elsewhere).

    Returns ``[J, 3, *S]`` file units (the pelvis at the origin of the heading frame)."""

    return _positions_from_quats(topology, offsets, _feature_quats(topology, x, representation, pelvis),
                                 pelvis, x.shape[1:], x.dtype)


def _positions_from_quats(topology, offsets, q_all, pelvis, shape, dtype):
    """`root_relative_positions_frames_last` from the joints' local rotations ``q_all`` (4
    components ``[J, *S]``, `_feature_quats`)."""
    from fourierjax._fourier._layout import ancestors

    plan = _fk.plan(topology, all_rotations=False)
    zeroed = np.ones(topology.num_joints, bool)
    zeroed[[pelvis, *ancestors(topology, pelvis)]] = False
    offsets = jnp.where(jnp.asarray(zeroed).reshape(-1, *(1,) * (offsets.ndim - 1)),
                        offsets.astype(dtype), 0.0)
    lq, lt = [], []
    for lv in plan.levels:
        idx = np.asarray(lv.joints)
        lq.append([c[idx[:lv.num_rotated]] for c in q_all] if lv.num_rotated else [1, 0, 0, 0])
        lt.append([offsets[idx, k] for k in range(3)])
    _, p = _fk.world(plan, lq, lt, keep=_fk.store)
    return _fk.gather_levels(plan, p, 3, False, shape, dtype)


def position_ve_batch(skeleton, x, xhat, frames, representation, pelvis, means=None):
    """The position variance explained (`_position_ve_impl`) of a batch of clips that share a
    topology and pelvis: ``skeleton`` with offsets ``[B, J, 3]``, ``x``, ``xhat`` ``[B, T, C]``,
    ``frames`` ``bool [B, T]``: ``[B]``. One FK of data and model together, batch axes minor
    (`root_relative_positions_frames_last`), then the masked sums of `variance_explained`.

    ``means``: for a "tangent" model, its frames ``[B, K, 4]`` (`FourierModel.frames`); ``xhat``
    is then its synthesis before `_tangent.from_tangent` (the tangent coordinates ``d``), and
    the model's joint rotations ``M exp(d)`` go to FK as they are: the positions of its
    features ``log(M exp(d))`` to float32 round-off, without the log, the branch choice and
    the exp back (500 Bandai-1 clips: a quarter of the tangent fit's CPU went to them)."""
    topo = skeleton.topology
    offsets = jnp.moveaxis(skeleton.offsets, 0, -1)[:, :, None, :, None]  # [J, 3, 1, B, 1]
    if means is None:
        both = jnp.moveaxis(jnp.stack([x, xhat]), -1, 0)  # [C, 2, B, T]
        p = root_relative_positions_frames_last(topo, offsets, both, representation,
                                                pelvis)  # [J, 3, 2, B, T]
    else:
        from fourierjax import rotations
        from fourierjax._fourier._tangent import triples
        from fourierjax.features import _layout_tables

        cols = _layout_tables(topo, representation)["expmap"][1]
        if not np.array_equal(cols, triples(channel_names_for(topo, representation), x.shape[-1])):
            raise AssertionError("position_ve_batch: the tangent triples are not the features' joints")
        m = jnp.asarray(means, x.dtype)[:, None, :, :]  # [B, 1, K, 4], as `_tangent.from_tangent`
        q = rotations.quat_multiply(m, rotations.quat_from_expmap(xhat[..., cols]))  # [B, T, K, 4]
        data = _feature_quats(topo, jnp.moveaxis(x, -1, 0), representation, pelvis)
        model = _feature_quats(topo, jnp.moveaxis(xhat, -1, 0), representation, pelvis,
                               expmap_quats=jnp.moveaxis(q, (-1, -2), (0, 1)))  # [4, K, B, T]
        q_all = [jnp.stack([a, b], axis=1) for a, b in zip(data, model, strict=True)]
        p = _positions_from_quats(topo, offsets, q_all, pelvis, (2, *x.shape[:-1]), x.dtype)
    target, approx = p[:, :, 0], p[:, :, 1]
    w = frames.astype(x.dtype)[None, None]  # [1, 1, B, T]
    mean = jnp.sum(w * target, axis=-1, keepdims=True) / jnp.maximum(
        jnp.sum(w, axis=-1, keepdims=True), 1.0)
    sse = jnp.sum(w * (target - approx) ** 2, axis=(0, 1, 3))
    sst = jnp.sum(w * (target - mean) ** 2, axis=(0, 1, 3))
    return 1.0 - sse / jnp.maximum(sst, 1e-30)
