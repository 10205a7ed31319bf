"""Data parallelism: shard the character / clip axis of batched fitting and synthesis over devices."""

from __future__ import annotations

from collections.abc import Sequence

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jax.sharding import Mesh, NamedSharding, PartitionSpec

from fourierjax import fourier, kinematics
from fourierjax.fourier import FitResult, FourierModel
from fourierjax.skeleton import Skeleton

__all__ = [
    "DATA_AXIS",
    "data_mesh",
    "batch_sharding",
    "replicated",
    "shard_batch",
    "fit_batch_sharded",
    "synthesize_sharded",
    "crowd_positions_sharded",
]

DATA_AXIS = "data"


def data_mesh(devices: Sequence[jax.Device] | None = None, axis_name: str = DATA_AXIS) -> Mesh:
    """A 1-D mesh over `devices` (default: every device of every process) with one data axis.

    The axis type is `Auto` (sharding propagated by the compiler): `jax.make_mesh` now defaults
    to explicit axes, which optimistix and jaxopt do not support (STYLE.md). Under
    `jax.distributed.initialize`, `jax.devices()` spans all hosts, so the same mesh scales out.

    Arguments:
        devices: the devices of the mesh (default `jax.devices()`).
        axis_name: the name of its data axis.

    Returns:
        A `Mesh` of shape `(len(devices),)`.
    """
    devices = jax.devices() if devices is None else list(devices)
    if not devices:
        raise ValueError("data_mesh: `devices` is empty")
    return Mesh(np.asarray(devices), (axis_name,), axis_types=(jax.sharding.AxisType.Auto,))


def batch_sharding(mesh: Mesh, ndim: int, axis_name: str = DATA_AXIS) -> NamedSharding:
    """`NamedSharding` splitting axis 0 of an `ndim`-dimensional array over `axis_name`.

    Arguments:
        mesh: the mesh (`data_mesh()`).
        ndim: the rank of the arrays (>= 1).
        axis_name: the mesh axis to split over.

    Returns:
        The sharding.
    """
    if ndim < 1:
        raise ValueError(f"batch_sharding: a batched array has ndim >= 1, got {ndim}")
    return NamedSharding(mesh, PartitionSpec(axis_name, *([None] * (ndim - 1))))


def replicated(mesh: Mesh) -> NamedSharding:
    """`NamedSharding` that keeps a full copy on every device of `mesh`.

    Arguments:
        mesh: the mesh.

    Returns:
        The sharding.
    """
    return NamedSharding(mesh, PartitionSpec())


def _num_shards(mesh: Mesh, axis_name: str) -> int:
    if axis_name not in mesh.shape:
        raise ValueError(f"mesh has no axis {axis_name!r}; its axes are {tuple(mesh.shape)}")
    return mesh.shape[axis_name]


def _pad_leading(x: jax.Array, size: int) -> jax.Array:
    # Pad by repeating the last element: padded rows are valid problems (no NaN, no empty
    # masks) whose results are dropped again.
    n = x.shape[0]
    if n == size:
        return x
    reps = jnp.broadcast_to(x[-1:], (size - n, *x.shape[1:]))
    return jnp.concatenate([x, reps], axis=0)


def shard_batch(tree, mesh: Mesh, axis_name: str = DATA_AXIS):
    """Place every array leaf of `tree` with its leading (batch) axis split over `axis_name`.

    The leading axes must all have the same length, a multiple of the number of devices on the
    axis (see `fit_batch_sharded` for padding). Non-array leaves are left alone.

    Arguments:
        tree: any pytree.
        mesh: the mesh (`data_mesh()`).
        axis_name: the mesh axis to split over.

    Returns:
        `(tree_on_devices)`: the same structure with sharded `jax.Array` leaves.
    """
    n = _num_shards(mesh, axis_name)
    leaves = [x for x in jax.tree.leaves(tree) if eqx.is_array(x)]
    sizes = {int(x.shape[0]) if x.ndim else None for x in leaves}
    if None in sizes or len(sizes) > 1:
        raise ValueError(f"shard_batch: array leaves need one common leading axis, got {sizes}")
    (size,) = sizes or {0}
    if size % n:
        raise ValueError(f"shard_batch: batch of {size} does not split over {n} devices; pad it first")
    return jax.tree.map(
        lambda x: jax.device_put(x, batch_sharding(mesh, x.ndim, axis_name)) if eqx.is_array(x) else x,
        tree,
    )


def fit_batch_sharded(
    features,
    frame_time_s,
    num_harmonics: int,
    *,
    mesh: Mesh | None = None,
    mask=None,
    omega_steps=None,
    axis_name: str = DATA_AXIS,
    **kwargs,
) -> FitResult:
    """`fourier.fit_batch` with the clip axis split over the devices of `mesh`.

    Each device fits its share of clips (variable projection with a small Gauss-Jordan elimination:
    plain jnp, so no batched LAPACK call, which hangs on small CPUs). The batch is padded to a
    multiple of the device count by repeating the last clip and the padding is dropped from the
    result, so any batch size works. Results equal an unsharded `fit_batch` to rounding.

    Arguments:
        As `fourier.fit_batch` (`features [B, T, C]`, `frame_time_s [B]` or scalar,
        `num_harmonics`, `mask [B, T]`, `omega_steps [B]`, keyword options), plus `mesh` (default
        `data_mesh()`) and the name of its data axis.

    Returns:
        a `FitResult` with a leading axis of `B`, sharded over the mesh.
    """
    mesh = data_mesh() if mesh is None else mesh
    n = _num_shards(mesh, axis_name)
    features = jnp.asarray(features)
    if features.ndim != 3:
        raise ValueError(f"fit_batch_sharded: features must be [B, T, C], got shape {features.shape}")
    B, T, _ = features.shape
    if B == 0:
        raise ValueError("fit_batch_sharded: empty batch")
    size = -(-B // n) * n
    dtype = features.dtype
    frame_time_s = jnp.broadcast_to(jnp.asarray(frame_time_s, dtype), (B,))
    mask = jnp.ones((B, T), dtype) if mask is None else jnp.asarray(mask, dtype)
    omega_steps = (jnp.full((B,), jnp.nan, dtype) if omega_steps is None
                   else jnp.broadcast_to(jnp.asarray(omega_steps, dtype), (B,)))
    batch = shard_batch(
        tuple(_pad_leading(x, size) for x in (features, frame_time_s, mask, omega_steps)),
        mesh, axis_name,
    )
    f, dt, m, om = batch
    res = fourier.fit_batch(f, dt, num_harmonics, mask=m, omega_steps=om, **kwargs)
    return res if size == B else jax.tree.map(lambda x: x[:B], res)


def _synthesize_batch(models: FourierModel, t_s):
    # `fourier.synthesize_batch` is jitted; given inputs sharded along B (and times replicated)
    # XLA partitions its one [B, T, C] loop along B with no communication.
    return fourier.synthesize_batch(models, t_s)


def synthesize_sharded(
    models: FourierModel, t_s, *, mesh: Mesh | None = None, axis_name: str = DATA_AXIS
) -> jax.Array:
    """Synthesize a batch of models (Unuma 1995 eq. 1) with the character axis over devices.

    Each device runs `fourier.synthesize_batch` on its share of the characters.

    Arguments:
        models: a `FourierModel` whose leaves have a leading character axis `[B, ...]`
            (`fourier.stack_models`).
        t_s: `[T]` times in seconds shared by all characters (replicated on every device), or
            `[B, T]` one row per character (split like the characters).
        mesh, axis_name: the mesh (default `data_mesh()`) and its data axis.

    Returns:
        `[B, T, C]` channel values, sharded over the mesh along `B`.
    """
    mesh = data_mesh() if mesh is None else mesh
    n = _num_shards(mesh, axis_name)
    if models.offset.ndim != 2:
        raise ValueError(f"synthesize_sharded: models need one leading batch axis, offset has "
                         f"shape {models.offset.shape}")
    B = models.offset.shape[0]
    size = -(-B // n) * n
    padded = jax.tree.map(lambda x: _pad_leading(x, size) if eqx.is_array(x) else x, models)
    sharded = shard_batch(padded, mesh, axis_name)
    t_s = jnp.asarray(t_s, models.offset.dtype)
    if t_s.ndim == 2 and t_s.shape[0] == B:  # one row of times per character: split like them
        t_s = shard_batch(_pad_leading(t_s, size), mesh, axis_name)
    else:  # shared times (other shapes are refused by fourier.synthesize_batch)
        t_s = jax.device_put(t_s, replicated(mesh))
    out = _synthesize_batch(sharded, t_s)
    return out if size == B else out[:B]


def crowd_positions_sharded(
    skeleton: Skeleton | eqx.Module, channels, *, mesh: Mesh | None = None, axis_name: str = DATA_AXIS
) -> jax.Array:
    """World joint positions of a crowd with the character axis split over devices.

    Two forms:

    - `crowd_positions_sharded(crowd, t)`: a `fourierjax.crowd.Crowd` synthesized and posed at
      time `t` (seconds) by `crowd.crowd_positions`, each device posing its share of the
      characters (the crowd's arrays keep characters last; they are split along that axis).
    - `crowd_positions_sharded(skeleton, channels)`: FK of given BVH channel values `[B, C]`
      (`kinematics.joint_positions`), split along `B`.

    The batch is padded to a multiple of the device count by repeating the last character and
    the padding is dropped again.

    Arguments:
        skeleton: a `Crowd`, or the `Skeleton` of the channels.
        channels: the time `t` (seconds, scalar) with a crowd, or `[B, C]` BVH channel values.
        mesh: the mesh (default `data_mesh()`).
        axis_name: its data axis.

    Returns:
        `[B, J, 3]` positions, sharded along `B`.
    """
    from fourierjax.crowd import Crowd, crowd_positions

    mesh = data_mesh() if mesh is None else mesh
    n = _num_shards(mesh, axis_name)
    if isinstance(skeleton, Crowd):
        crowd, t = skeleton, channels
        B = crowd.num_characters
        size = -(-B // n) * n

        def last_axis(x):  # pad (repeat the last character) and split the character axis
            if size != B:
                reps = jnp.broadcast_to(x[..., -1:], (*x.shape[:-1], size - B))
                x = jnp.concatenate([x, reps], axis=-1)
            spec = PartitionSpec(*([None] * (x.ndim - 1)), axis_name)
            return jax.device_put(x, NamedSharding(mesh, spec))

        crowd = eqx.tree_at(lambda c: (c.coefficients, c.omega), crowd,
                            (last_axis(crowd.coefficients), last_axis(crowd.omega)))
        crowd = eqx.tree_at(lambda c: c.bone_offsets, crowd,
                            jax.device_put(crowd.bone_offsets, replicated(mesh)))
        t = jax.device_put(jnp.asarray(t, crowd.coefficients.dtype), replicated(mesh))
        out = crowd_positions(crowd, t)
        return out if size == B else out[:B]
    channels = jnp.asarray(channels)
    B = channels.shape[0]
    size = -(-B // n) * n
    ch = shard_batch(_pad_leading(channels, size), mesh, axis_name)
    out = kinematics.joint_positions(skeleton, ch)
    return out if size == B else out[:B]
