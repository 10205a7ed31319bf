"""Forward kinematics: BVH channels to local poses, local poses to world joint positions."""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

import jax
import jax.numpy as jnp
import numpy as np

from fourierjax import _fk, _jit, _saved, rotations
from fourierjax._fourier._buckets import length_bucket as _bucket
from fourierjax._pytree import Record
from fourierjax.errors import UserError
from fourierjax.skeleton import Skeleton, Topology

if TYPE_CHECKING:
    from jaxtyping import Array, Float

_AXIS_INDEX = {"X": 0, "Y": 1, "Z": 2}


class FKResult(Record):
    """World-space pose of one frame (a pytree of three arrays; leading axes for batches).

    - `rotations`: `[J, 4]` world orientation of every joint (unit quaternion, wxyz).
    - `positions`: `[J, 3]` world position of every joint.
    - `end_site_positions`: `[E, 3]` world position of every End Site (its orientation is its
      parent's).
    """

    __leaves__ = ("rotations", "positions", "end_site_positions")
    rotations: Float[Array, "joints 4"]
    positions: Float[Array, "joints 3"]
    end_site_positions: Float[Array, "end_sites 3"]

    def __init__(self, rotations, positions, end_site_positions):
        self._set("rotations", rotations)
        self._set("positions", positions)
        self._set("end_site_positions", end_site_positions)


def _elementary_quat(axis: str, angle: Float[Array, ...]) -> Float[Array, "... 4"]:
    half = 0.5 * angle
    c, s = jnp.cos(half), jnp.sin(half)
    zero = jnp.zeros_like(half)
    xyz = [zero, zero, zero]
    xyz[_AXIS_INDEX[axis]] = s
    return jnp.stack([c, *xyz], axis=-1)


def _channel_layout(topology: Topology):
    """Static index tables (numpy) for gathering channels into translations and rotations."""
    offsets = topology.channel_offsets
    # Position channels: (joint, axis, channel index).
    pos_joint, pos_axis, pos_chan = [], [], []
    # Rotation channels grouped by order: order -> (joints, [J_g, len(order)] channel indices).
    groups: dict[str, tuple[list[int], list[list[int]]]] = {}
    for j, chans in enumerate(topology.channels):
        rot_idx = []
        for k, c in enumerate(chans):
            if c.endswith("position"):
                pos_joint.append(j)
                pos_axis.append(_AXIS_INDEX[c[0]])
                pos_chan.append(offsets[j] + k)
            else:
                rot_idx.append(offsets[j] + k)
        order = topology.rotation_orders[j]
        if order is not None:
            joints, idx = groups.setdefault(order, ([], []))
            joints.append(j)
            idx.append(rot_idx)
    return (
        (np.array(pos_joint, dtype=np.int32), np.array(pos_axis, dtype=np.int32),
         np.array(pos_chan, dtype=np.int32)),
        {o: (np.array(js, dtype=np.int32), np.array(ix, dtype=np.int32)) for o, (js, ix) in groups.items()},
    )


def pose_from_channels(
    skeleton: Skeleton, channels: Float[Array, " channels"]
) -> tuple[Float[Array, "joints 3"], Float[Array, "joints 4"]]:
    """Local translations and rotations of one frame from its BVH channel values.

    Position channels replace the OFFSET components they name (they are the joint's local
    translation; adding them would double every bone in files that repeat the offsets).
    Rotation channels are degrees, applied in the listed order (BVH, intrinsic).

    Arguments:
        skeleton: the skeleton the channels belong to.
        channels: `[C]` one frame of channel values as stored in the file.

    Returns:
        `(translations [J, 3], quats [J, 4])`, local to each joint's parent.
    """
    topology = skeleton.topology
    channels = jnp.asarray(channels)
    if channels.shape != (topology.num_channels,):
        raise UserError(
            f"pose_from_channels: `channels` has shape {channels.shape}, expected "
            f"({topology.num_channels},) for one frame of this skeleton"
        )
    (pos_joint, pos_axis, pos_chan), groups = _channel_layout(topology)
    translations = skeleton.offsets.astype(channels.dtype)
    if pos_joint.size:
        translations = translations.at[pos_joint, pos_axis].set(channels[pos_chan])
    identity = jnp.zeros((topology.num_joints, 4), channels.dtype).at[:, 0].set(1.0)
    quats = identity
    for order, (joints, idx) in groups.items():
        angles = jnp.deg2rad(channels[idx])  # [J_g, len(order)]
        if len(order) == 3:
            q = rotations.quat_from_euler(angles, order)
        else:
            q = _elementary_quat(order[0], angles[:, 0])
            for k in range(1, len(order)):
                q = rotations.quat_multiply(q, _elementary_quat(order[k], angles[:, k]))
        quats = quats.at[joints].set(q)
    return translations, quats


def forward_kinematics(
    skeleton: Skeleton,
    translations: Float[Array, "joints 3"],
    quats: Float[Array, "joints 4"],
) -> FKResult:
    """World rotations and positions of every joint and End Site for one frame.

    The one FK formulation (`fourierjax._fk`): joints posed depth level by depth level,
    rotations composed as quaternion products (clear of the XLA CPU bug with batched 3x3
    matmuls under nested vmap, see STYLE.md). Batch over frames and characters with `jax.vmap`.

    Arguments:
        skeleton: supplies the topology and the End Site offsets.
        translations: `[J, 3]` local translation of each joint (the root's is its world position).
        quats: `[J, 4]` local rotation of each joint (wxyz).

    Returns:
        an `FKResult`.
    """
    topology = skeleton.topology
    j = topology.num_joints
    if translations.shape != (j, 3) or quats.shape != (j, 4):
        raise UserError(
            f"forward_kinematics: expected translations ({j}, 3) and quats ({j}, 4), got "
            f"{translations.shape} and {quats.shape}"
        )
    the_plan = _fk.plan(topology)
    dtype = jnp.result_type(translations.dtype, quats.dtype)
    lq, lt = [], []
    for level in the_plan.levels:
        idx = np.asarray(level.joints)
        lq.append(list(jnp.moveaxis(quats[idx].astype(dtype), 1, 0)))
        lt.append(list(jnp.moveaxis(translations[idx].astype(dtype), 1, 0)))
    q, p = _fk.world(the_plan, lq, lt)
    world_q = _fk.gather_levels(the_plan, q, 4, True, (), dtype)
    world_p = _fk.gather_levels(the_plan, p, 3, False, (), dtype)
    ends = _end_sites(skeleton, world_q, world_p, (), dtype)
    return FKResult(rotations=world_q, positions=world_p, end_site_positions=ends)


def _end_sites(skeleton: Skeleton, world_q, world_p, shape, dtype):
    """`[E, 3, *S]` End Site positions from world poses `[J, 4, *S]`, `[J, 3, *S]`."""
    topology = skeleton.topology
    if not topology.num_end_sites:
        return jnp.zeros((0, 3, *shape), dtype)
    ep = np.asarray(topology.end_site_parents)
    pq, pp = world_q[ep], world_p[ep]
    off = skeleton.end_site_offsets.astype(dtype).reshape(-1, 3, *(1,) * len(shape))
    moved = _fk.qapply([pq[:, k] for k in range(4)], [off[:, k] for k in range(3)])
    return jnp.stack([pp[:, k] + moved[k] for k in range(3)], axis=1)


def fk_from_channels(skeleton: Skeleton, channels: Float[Array, " channels"]) -> FKResult:
    """`forward_kinematics` of one frame of BVH channel values (see `pose_from_channels`).

    Arguments:
        skeleton: the skeleton the channels belong to.
        channels: `[C]` one frame of channel values as stored in the file (degrees).

    Returns:
        The frame's `FKResult`.
    """
    topology = skeleton.topology
    channels = jnp.asarray(channels)
    if channels.shape != (topology.num_channels,):
        raise UserError(
            f"fk_from_channels: `channels` has shape {channels.shape}, expected "
            f"({topology.num_channels},) for one frame of this skeleton"
        )
    if not jnp.issubdtype(channels.dtype, jnp.floating):
        channels = channels.astype(skeleton.offsets.dtype)
    the_plan = _fk.plan(topology)
    dtype = channels.dtype
    q, p = _fk.pose_rows(the_plan, channels[np.asarray(the_plan.rows, np.int32)], skeleton.offsets)
    world_q = _fk.gather_levels(the_plan, q, 4, True, (), dtype)
    world_p = _fk.gather_levels(the_plan, p, 3, False, (), dtype)
    ends = _end_sites(skeleton, world_q, world_p, (), dtype)
    return FKResult(rotations=world_q, positions=world_p, end_site_positions=ends)


# -------------------------------------------------------------------- batched entry points


def _check_batch(skeleton: Skeleton, channels, name: str, frames_last: bool = False):
    """`channels` as an array: a jax array or Tracer as it is, anything else as NumPy (the jitted
    call moves it to the device; `jnp.asarray` would compile a `stage` program per shape).
    `[..., C]`, or `[C, M]` with `frames_last`."""
    topology = skeleton.topology
    if not isinstance(channels, jax.Array):
        channels = np.asarray(channels)
        channels = channels.astype(jax.dtypes.canonicalize_dtype(channels.dtype), copy=False)
    if frames_last and (channels.ndim != 2 or channels.shape[0] != topology.num_channels):
        raise UserError(
            f"{name}: `channels` has shape {channels.shape}, expected ({topology.num_channels}, M): "
            "channels first, frames last"
        )
    if not frames_last and (channels.ndim < 1 or channels.shape[-1] != topology.num_channels):
        raise UserError(
            f"{name}: `channels` has shape {channels.shape}, expected (..., "
            f"{topology.num_channels}) for this skeleton"
        )
    if skeleton.offsets.ndim != 2:
        raise UserError(
            f"{name}: the skeleton's offsets have shape {skeleton.offsets.shape}; for a batch "
            "of skeletons vmap `fk_from_channels` instead"
        )
    if not jnp.issubdtype(channels.dtype, jnp.floating):
        channels = channels.astype(skeleton.offsets.dtype)
    return channels


def _unaliased_frames(m: int) -> int:
    """Frames (>= `m`) of the frames-minor arrays of `_fk_chunk`.

    A row stride that is a multiple of 1 KiB puts the strided reads and writes of the transposes
    between `[M, C]` and `[K, M]` into a few cache sets (4K aliasing): with XLA:CPU's classic
    emitters a `[124, M]` transpose took 314 us at M = 1024 against 67 us at 1040, and 583
    against 105 us at 2048 and 2064 (2 cores, load 6.5). Such counts (length buckets, the
    2048-frame chunks) get 16 frames of padding.
    """
    return m + 16 if m >= 256 and m % 256 == 0 else m


def _fk_chunk(skeleton: Skeleton, flat, all_rotations: bool):
    """`(rotations [M, J, 4] or None, positions [M, J, 3], end sites [M, E, 3] or None)`."""
    topology = skeleton.topology
    the_plan = _fk.plan(topology, all_rotations)
    m, dtype = flat.shape[0], flat.dtype
    mp = _unaliased_frames(m)
    if mp > m:  # zero channels: a valid pose, cut off below
        flat = jnp.concatenate([flat, jnp.zeros((mp - m, flat.shape[1]), dtype)])
    x = flat[:, np.asarray(the_plan.rows, np.int32)].T  # [R, Mp]: frames minor, plan row order

    def frames_major(a):  # [J, K, Mp] -> [M, J, K]: one 2-D transpose
        flat_t = a.reshape(a.shape[0] * a.shape[1], mp).T
        return (flat_t if mp == m else flat_t[:m]).reshape(m, a.shape[0], a.shape[1])

    if not all_rotations:  # the FK of `joint_positions_frames_last` and the crowd
        return None, frames_major(_fk.positions(the_plan, x, skeleton.offsets)), None
    q, p = _fk.pose_rows(the_plan, x, skeleton.offsets, keep=_fk.store)
    world_p = _fk.gather_levels(the_plan, p, 3, False, (mp,), dtype)
    world_q = _fk.gather_levels(the_plan, q, 4, True, (mp,), dtype)
    ends = _end_sites(skeleton, world_q, world_p, (mp,), dtype)
    return frames_major(world_q), frames_major(world_p), frames_major(ends)


# Frames per chunk of a large batch: 2048 ran 5-15% faster than 4096 in CPU time (1024 x 240
# frames of CMU 07_01, two interleaved runs on the shared 2-core machine at load ~22-25;
# `joint_positions` 288 against 309 ms and 290 against 318 ms, `fk_frames` 530 against 581 and
# 521 against 564 ms). 1024 was no faster than 2048. CPU time, not wall time: under that load a
# wall clock measures the other processes.
_FK_CHUNK = 2048

#: Joint-frames per chunk on an accelerator. A chunk's temporaries are about 13 values per joint
#: and frame (`fk_frames` on CPU, `Compiled.memory_analysis`: 12.6, and 7.9 for
#: `joint_positions`), so 2^25 joint-frames hold under 2 GB in float32; a GPU kernel over a chunk
#: that size is far past its launch overhead. With the CPU's 2048-frame chunks an H200 was
#: launch-bound: 24 kernels per chunk at about 7 us each, 0.73 G joint transforms/s at every
#: batch size from 1024 x 240 to 65536 x 240 frames (`experiments.benchmarks.gpu`).
_ACCELERATOR_JOINT_FRAMES = 1 << 25


def _chunk_frames(num_joints: int, backend: str | None = None) -> int:
    """Frames per chunk of a large FK batch on `backend` (default: JAX's default backend).

    The CPU keeps a chunk's working set in cache (`_FK_CHUNK`); an accelerator takes chunks as
    large as `_ACCELERATOR_JOINT_FRAMES` allows for this many joints (at least `_FK_CHUNK`), so
    that its kernels are not launch-bound.
    """
    backend = jax.default_backend() if backend is None else backend
    if backend == "cpu":
        return _FK_CHUNK
    return max(_FK_CHUNK, _ACCELERATOR_JOINT_FRAMES // max(1, num_joints))


def _in_chunks(fn, x, size: int, in_axis: int, out_axis: int):
    """``fn`` over chunks of ``size`` frames of ``x`` (frames along ``in_axis``) in one loop, its
    outputs (a pytree, None leaves allowed) written along ``out_axis``. The last chunk is clamped
    to end at the last frame (it recomputes a few frames), so nothing is padded and nothing is
    copied afterwards."""
    m = x.shape[in_axis]
    shapes = jax.eval_shape(fn, jax.lax.slice_in_dim(x, 0, size, axis=in_axis))
    init = jax.tree.map(
        lambda s: jnp.zeros((*s.shape[:out_axis], m, *s.shape[out_axis + 1:]), s.dtype), shapes)

    def body(i, acc):
        start = jnp.minimum(i * size, m - size)
        res = fn(jax.lax.dynamic_slice_in_dim(x, start, size, in_axis))
        return jax.tree.map(
            lambda a, r: jax.lax.dynamic_update_slice_in_dim(a, r, start, out_axis), acc, res)

    return jax.lax.fori_loop(0, -(-m // size), body, init)


def _fk_batch(skeleton: Skeleton, channels, all_rotations: bool):
    """`_fk_chunk` of `[..., C]` channels, in chunks of frames when there are many."""
    topology = skeleton.topology
    batch = channels.shape[:-1]
    m = int(np.prod(batch))
    flat = channels.reshape(m, topology.num_channels)  # not -1: a skeleton may have no channels
    size = _chunk_frames(topology.num_joints)
    if m <= 2 * size:
        out = _fk_chunk(skeleton, flat, all_rotations)
    else:
        # Chunks of frames keep the working set in cache (one pass over [J, 7, M] per level is
        # memory-bound once M is large).
        out = _in_chunks(lambda f: _fk_chunk(skeleton, f, all_rotations), flat, size, 0, 0)

    def back(a):  # [M, K, D] -> [..., K, D]
        return None if a is None else a.reshape(*batch, *a.shape[1:])

    return tuple(back(a) for a in out)


#: Batches of up to this many frames (all leading axes together) are padded to
#: `_fourier._buckets.length_bucket` frames, so clips of new lengths reuse the compiled FK of
#: their bucket; larger batches compile for their own shape (their run time dwarfs a compile,
#: and padding them would cost up to 2x the work).
PAD_LIMIT = 1 << 16


def _padded_frames(m: int) -> int:
    """Frames of the compiled FK program that serves a concrete batch of `m` frames: the length
    bucket, with `_unaliased_frames`' padding, so the program pads nothing inside and cuts
    nothing before its outputs (one program per bucket, as before)."""
    return _unaliased_frames(_bucket(m))


def _to_device(x: np.ndarray, sharding, committed: bool):
    """NumPy `x` as a JAX array on the one device of `sharding`, as `jax.device_put` makes it
    (on CPU an aligned `x` is aliased, not copied), for less Python.

    `jax.device_put` costs 17-25 us of Python per array (2 cores, jax 0.10.2); its last step,
    jaxlib's `batched_device_put`, 4-9 us. `fk_frames` cuts three outputs per call, against
    ~310 us of FK for 1,000 frames: with this and `_padded_frames`, `fk_frames` of 1 x 1,000
    frames took 600 against 780 us a call (`joint_positions` 453 against 527; medians of 3,000
    calls alternated with the previous entry point, load 7.7). Falls back to `jax.device_put`
    where that private function is missing or refuses the call (another jaxlib).
    """
    if _batched_device_put is not None:
        try:
            device = next(iter(sharding.device_set))
            return _batched_device_put(_ShapedArray(x.shape, x.dtype), sharding, [x], [device], committed)
        except (TypeError, AttributeError, ValueError):
            pass
    return jax.device_put(x, sharding) if committed else jax.device_put(x)


try:  # private: `_to_device`'s fast path (jax 0.10.2), looked up once here
    from jax._src.core import ShapedArray as _ShapedArray
    from jax._src.lib import xla_client as _xla_client

    _batched_device_put = _xla_client.batched_device_put
except (ImportError, AttributeError):  # pragma: no cover - another jax
    _batched_device_put = None


def _bucketed(jitted, skeleton: Skeleton, channels):
    """`jitted(skeleton, channels)` with the frames of a concrete `[..., C]` batch flattened and
    padded to `_padded_frames`, and the outputs cut back to `[..., ...]`.

    Frames are independent, so padding is exact. On CPU the padding and the cut are a NumPy
    copy and views (`_to_device`), not XLA programs, so a new length compiles nothing at all;
    elsewhere they are two small eager ops. Traced channels or skeletons (inside jit, vmap or
    grad) are passed through: the caller's program has one shape anyway.
    """
    batch = channels.shape[:-1]
    m = math.prod(batch)
    rows = _padded_frames(m)
    # A traced skeleton (FK vmapped over skeletons with concrete channels) is traced too: the
    # outputs are tracers, which the host-side cut below cannot read.
    traced = isinstance(channels, jax.core.Tracer) or any(
        isinstance(a, jax.core.Tracer) for a in jax.tree.leaves(skeleton))
    if traced or m > PAD_LIMIT or (rows == m and len(batch) == 1):
        return jitted(skeleton, channels)
    width = channels.shape[-1]
    if isinstance(channels, np.ndarray) or jax.default_backend() == "cpu":
        padded = np.zeros((rows, width), channels.dtype)
        padded[:m] = np.asarray(channels).reshape(m, width)
        out = jitted(skeleton, padded)  # the jitted call copies it to the device

        def cut(a):
            if a is None:
                return None
            # A view of the padded output, put back on its device without a copy (as before).
            return _to_device(np.asarray(a)[:m].reshape(*batch, *a.shape[1:]), a.sharding, a.committed)
    else:
        out = jitted(skeleton, jnp.pad(channels.reshape(m, width), ((0, rows - m), (0, 0))))

        def cut(a):
            return None if a is None else a[:m].reshape(*batch, *a.shape[1:])

    return jax.tree.map(cut, out, is_leaf=lambda a: a is None)


# `_jit.jit` (the one wrapper's mechanism over `jax.jit`), not `filter_jit`: equinox's argument
# filtering cost ~150 us more per call on small batches (2-core machine, jax 0.10.2; 0.94 ms
# against 13 us under a load of 13), which FK is called with per frame. The classic CPU
# emitters (`_jit.CPU_COMPILER_OPTIONS`) compile the unrolled levels 2-2.5x faster than the new
# fusion emitters (3.2 vs 6.9 s under a load of 12 on 2 cores) at a run time equal within the
# noise of the shared machine.
# A fresh process with the compile cache on loads both as saved executables (`_saved`).
@_saved.saved_executable
@_jit.jit
def _joint_positions_jit(skeleton: Skeleton, channels):
    return _fk_batch(skeleton, channels, False)[1]


@_saved.saved_executable
@_jit.jit
def _fk_frames_jit(skeleton: Skeleton, channels):
    rot, pos, ends = _fk_batch(skeleton, channels, True)
    return FKResult(rotations=rot, positions=pos, end_site_positions=ends)


def joint_positions(skeleton: Skeleton, channels: Float[Array, "... channels"]) -> Float[Array, "... joints 3"]:
    """World positions of every joint for every frame (jitted entry point).

    Concrete batches of up to `PAD_LIMIT` frames are padded to their length bucket
    (`fourierjax._fourier._buckets.length_bucket`), so clips of different lengths in one bucket
    share one compiled program.

    Arguments:
        skeleton: the skeleton (unbatched offsets).
        channels: `[..., C]` BVH channel values (degrees, file units), e.g. `[F, C]` for one
            clip or `[B, F, C]` for a batch of clips of this skeleton.

    Returns:
        `[..., J, 3]` joint positions in file units, joints in file order.
    """
    channels = _check_batch(skeleton, channels, "joint_positions")
    return _bucketed(_joint_positions_jit, skeleton, channels)


def fk_frames(skeleton: Skeleton, channels: Float[Array, "... channels"]) -> FKResult:
    """`FKResult` for every frame of `[..., C]` BVH channels (jitted entry point).

    Same values as `jax.vmap(fk_from_channels)`, computed in a frame-minor layout; concrete
    batches are padded to their length bucket as in `joint_positions`.

    Arguments:
        skeleton: the skeleton (unbatched offsets).
        channels: `[..., C]` BVH channel values (degrees, file units).

    Returns:
        An `FKResult` whose leaves get the leading dims `...` of `channels`.
    """
    channels = _check_batch(skeleton, channels, "fk_frames")
    return _bucketed(_fk_frames_jit, skeleton, channels)


#: Frames per chunk of `joint_positions_frames_last` on CPU, as `_FK_CHUNK`. Unchunked, 245,760
#: frames (1024 x 240) ran 2.5x slower than in chunks: each level's stored pose, `[n, M]` per
#: component, leaves the cache. Chunk sizes at 1024 x 240 frames, interleaved rounds on the
#: shared 2-core machine (median wall / CPU ms): 2048 frames 108 / 104 and 142 / 102, 4096 131 /
#: 106, 8192 142 / 119 and 165 / 116, 16384 124 / 108, 32768 145 / 120, 1024 160 / 111 (loads
#: 2.8 and 3.8; 9 rounds each).
_FRAMES_LAST_CHUNK = 2048


def _frames_last_chunk(num_joints: int, backend: str | None = None) -> int:
    """Frames per chunk of `joint_positions_frames_last` on `backend` (as `_chunk_frames`)."""
    backend = jax.default_backend() if backend is None else backend
    if backend == "cpu":
        return _FRAMES_LAST_CHUNK
    return max(_FRAMES_LAST_CHUNK, _ACCELERATOR_JOINT_FRAMES // max(1, num_joints))


def _positions_frames_last(skeleton: Skeleton, channels):
    """`[J, 3, M]` positions of `[C, M]` channels: FK's own layout, no transposes.

    Large batches in chunks of frames (`_frames_last_chunk`, `_in_chunks`).
    """
    the_plan = _fk.plan(skeleton.topology, all_rotations=False)
    rows = np.asarray(the_plan.rows, np.int32)
    m = channels.shape[1]
    size = _frames_last_chunk(skeleton.topology.num_joints)
    def fk(chunk):
        return _fk.positions(the_plan, chunk[rows], skeleton.offsets)

    return fk(channels) if m <= 2 * size else _in_chunks(fk, channels, size, 1, 2)


_joint_positions_frames_last_jit = _jit.jit(_positions_frames_last)


def _bucketed_frames_last(skeleton: Skeleton, channels):
    """`_joint_positions_frames_last_jit` with concrete frames padded to their length bucket and
    the output cut back (as `_bucketed`, along the last axis)."""
    jitted = _joint_positions_frames_last_jit
    width, m = channels.shape
    rows = _bucket(m)
    traced = any(isinstance(a, jax.core.Tracer) for a in (channels, *jax.tree.leaves(skeleton)))
    if traced or m > PAD_LIMIT or rows == m:
        return jitted(skeleton, channels)
    if isinstance(channels, np.ndarray) or jax.default_backend() == "cpu":
        padded = np.zeros((width, rows), channels.dtype)
        padded[:, :m] = np.asarray(channels)
        out = jitted(skeleton, padded)
        return _to_device(np.ascontiguousarray(np.asarray(out)[..., :m]), out.sharding, out.committed)
    return jitted(skeleton, jnp.pad(channels, ((0, 0), (0, rows - m))))[..., :m]


def joint_positions_frames_last(skeleton: Skeleton, channels: Float[Array, "channels frames"]
                                ) -> Float[Array, "joints 3 frames"]:
    """World positions of every joint for every frame, frames last (jitted entry point).

    FK's own layout (the crowd's): one row per channel in, one row per joint coordinate out,
    frames along each row, so no transpose is made on the way in or out. Same values as
    `jnp.moveaxis(joint_positions(skeleton, channels.T), 0, -1)`; faster where the caller can
    take this layout. Concrete batches of up to `PAD_LIMIT` frames are padded to their length
    bucket, as in `joint_positions`.

    Arguments:
        skeleton: the skeleton (unbatched offsets).
        channels: `[C, M]` BVH channel values (degrees, file units), one column per frame.

    Returns:
        `[J, 3, M]` joint positions in file units, joints in file order.

    Raises:
        `UserError` naming `channels` or the skeleton's offsets when the shapes do not fit.
    """
    channels = _check_batch(skeleton, channels, "joint_positions_frames_last", frames_last=True)
    return _bucketed_frames_last(skeleton, channels)


# The retrace guard of the tests counts the compiled programs behind each entry point.
joint_positions.num_traces = _joint_positions_jit.num_traces  # type: ignore[attr-defined]
fk_frames.num_traces = _fk_frames_jit.num_traces  # type: ignore[attr-defined]
joint_positions_frames_last.num_traces = _joint_positions_frames_last_jit.num_traces  # type: ignore[attr-defined]
