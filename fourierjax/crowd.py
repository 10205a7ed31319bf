"""A crowd: many Fourier-animated characters of one skeleton, synthesized and posed per frame."""

from __future__ import annotations

from typing import TYPE_CHECKING

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float

from fourierjax import _fk, _jit
from fourierjax._sincos import sincos as _sincos
from fourierjax.errors import UserError
from fourierjax.fourier import FourierModel
from fourierjax.skeleton import Skeleton, Topology

if TYPE_CHECKING:
    from fourierjax.body import BodyMap

__all__ = ["Crowd", "make_crowd", "crowd_positions"]

# Layout (measured on 2 CPU cores, 10,000 characters, CMU 07_01: 31 joints; see
# experiments/benchmarks/crowd.py): characters are the last (minor) axis of every array, so
# synthesis and FK are elementwise loops over characters. Synthesis is fused with FK in one
# program: coefficients `[P, K, B]` become the `[K, B]` channel values of one time and then
# positions, with no `[B, T, C]` angles in between. The FK is `fourierjax._fk`, the same as
# `kinematics.joint_positions` (joints by depth level, half-angle sincos to quaternions); only
# the channels that move a joint are kept (a leaf joint's rotation moves nothing but its End
# Site).


class Crowd(eqx.Module):
    """Many characters of one skeleton, each a Fourier model, laid out for posing per frame.

    Build it once with `make_crowd`; pose it every frame with `crowd_positions`. Arrays put the
    character axis last (`B`). Only the channels that move joints are kept (`channel_index`).

    - `coefficients`: `[2N + 1, K, B]` linear Fourier coefficients of the kept channels, in the
      channels' units (degrees for rotations, file units for positions): row 0 the offset
      `A0`, rows `1..N` the sine and rows `N+1..2N` the cosine coefficients
      (`x = A0 + sum_n a_n sin(n theta) + b_n cos(n theta)`, Unuma 1995 eq. 1 in linear form).
    - `omega`: `[B]` fundamental of each character (rad/s); `theta = omega * t`.
    - `bone_offsets`: `[J, 3]` the skeleton's OFFSETs (file units).
    - `topology`: the static `Topology`.
    - `channel_index`: static; the model channel of each kept row, in the row order of the FK
      plan (`fourierjax._fk.plan(topology, all_rotations=False).rows`): first the rotation
      channels of joints with children, level by level, then every position channel.
    """

    coefficients: Float[Array, "P K B"]
    omega: Float[Array, " B"]
    bone_offsets: Float[Array, "J 3"]
    topology: Topology = eqx.field(static=True)
    channel_index: tuple[int, ...] = eqx.field(static=True)

    @property
    def num_characters(self) -> int:
        return self.omega.shape[-1]

    @property
    def num_harmonics(self) -> int:
        return (self.coefficients.shape[0] - 1) // 2

    def __check_init__(self):
        p, k = self.coefficients.shape[:2] if self.coefficients.ndim == 3 else (None, None)
        if self.coefficients.ndim != 3 or p % 2 != 1 or k != len(self.channel_index):
            raise UserError(
                f"Crowd: `coefficients` has shape {self.coefficients.shape}, expected "
                f"(2N + 1, {len(self.channel_index)}, B)"
            )
        if self.omega.shape != self.coefficients.shape[2:]:
            raise UserError(
                f"Crowd: `omega` has shape {self.omega.shape}, expected "
                f"({self.coefficients.shape[2]},) (one per character)"
            )
        if self.bone_offsets.shape != (self.topology.num_joints, 3):
            raise UserError(
                f"Crowd: `bone_offsets` has shape {self.bone_offsets.shape}, expected "
                f"({self.topology.num_joints}, 3)"
            )


def make_crowd(skeleton: Skeleton, models: FourierModel) -> Crowd:
    """Lay out a batch of Fourier models of one skeleton's BVH channels as a `Crowd`.

    Each model animates every BVH channel of `skeleton` in file order and units (degrees for
    rotations, file units for positions), so that one frame of a character is
    `fourier.synthesize(model, t[None])[0]`, a valid `kinematics.joint_positions` input. The
    linear coefficients (`FourierModel.sin_cos`) are computed here once, not per frame.

    Arguments:
        skeleton: the skeleton every character shares (unbatched offsets `[J, 3]`).
        models: a `FourierModel` with a leading character axis (`fourier.stack_models`):
            offset `[B, C]`, amplitude and phase `[B, C, N]`, omega `[B]`, with `C` the skeleton's
            channel count. Gait fits (`motion.fit_motions`, models of features) become such models
            with `motion.channel_model`.

    Returns:
        a `Crowd` of `B` characters (arrays in the models' floating dtype).

    Raises:
        `UserError` naming `skeleton` or `models` when the shapes do not fit.
    """
    if not isinstance(skeleton, Skeleton):
        raise UserError(f"make_crowd: `skeleton` must be a Skeleton, got {type(skeleton).__name__}")
    if not isinstance(models, FourierModel):
        raise UserError(f"make_crowd: `models` must be a FourierModel, got {type(models).__name__}")
    topology = skeleton.topology
    if skeleton.offsets.shape != (topology.num_joints, 3):
        raise UserError(
            f"make_crowd: `skeleton` offsets have shape {skeleton.offsets.shape}; the crowd shares "
            f"one skeleton, expected ({topology.num_joints}, 3)"
        )
    if models.offset.ndim != 2:
        raise UserError(
            f"make_crowd: `models` need one leading character axis (fourier.stack_models); "
            f"offset has shape {models.offset.shape}"
        )
    num_chars, num_channels = models.offset.shape
    if num_channels != topology.num_channels:
        raise UserError(
            f"make_crowd: `models` have {num_channels} channels, the skeleton has "
            f"{topology.num_channels} BVH channels ({topology.num_joints} joints)"
        )
    if models.channel_names and tuple(models.channel_names) != topology.flat_channel_names:
        raise UserError(
            "make_crowd: `models` channel_names are not the skeleton's BVH channels "
            f"({topology.flat_channel_names[:3]}...); crowd models animate BVH channel values"
        )
    if num_chars == 0:
        raise UserError("make_crowd: `models` hold no characters")
    from fourierjax import _memory

    _memory.check_bytes(f"make_crowd: {num_chars} characters", _memory.crowd_bytes(num_chars, topology.num_joints),
                        hint="make a smaller crowd")
    dtype = jnp.result_type(models.offset.dtype, jnp.float32)
    index = _fk.plan(topology, all_rotations=False).rows
    a, b = models.sin_cos()  # [B, C, N]
    rows = np.asarray(index, np.int32)
    coef = jnp.concatenate([models.offset[:, None, :], jnp.swapaxes(a, 1, 2),
                            jnp.swapaxes(b, 1, 2)], axis=1)  # [B, 2N + 1, C]
    coef = jnp.transpose(coef[:, :, rows], (1, 2, 0)).astype(dtype)  # [2N + 1, K, B]
    return Crowd(
        coefficients=coef,
        omega=jnp.asarray(models.omega, dtype),
        bone_offsets=jnp.asarray(skeleton.offsets, dtype),
        topology=topology,
        channel_index=index,
    )


def _channels(crowd: Crowd, t: Array, keep) -> Array:
    """Kept channels `[K, B]` at time `t` (Unuma 1995 eq. 1 in linear form)."""
    coef = crowd.coefficients
    num_harmonics = crowd.num_harmonics
    # Phase basis per character: one sin/cos, then the angle-addition recurrence.
    theta = crowd.omega * t
    s1, c1 = (keep(v) for v in _sincos(theta))
    sines, cosines = [s1], [c1]
    for _ in range(1, num_harmonics):
        s, c = sines[-1], cosines[-1]
        sines.append(keep(s * c1 + c * s1))
        cosines.append(keep(c * c1 - s * s1))
    x = coef[0]
    for n in range(num_harmonics):
        x = x + coef[1 + n] * sines[n][None] + coef[1 + num_harmonics + n] * cosines[n][None]  # [K, B]
    return x


def _pose(crowd: Crowd, t: Float[Array, ""]) -> Float[Array, "J 3 B"]:
    """World joint positions `[J, 3, B]` (characters last) at time `t` (seconds)."""
    topology = crowd.topology
    dtype = crowd.coefficients.dtype
    t = jnp.asarray(t, dtype)
    the_plan = _fk.plan(topology, all_rotations=False)
    # The channels stored once: fused into the sin/cos block, each of its two halves would
    # synthesize them again (a second read of every coefficient).
    return _fk.positions(the_plan, _fk.store(_channels(crowd, t, _fk.store)), crowd.bone_offsets)


def crowd_positions(
    crowd: Crowd,
    t: Float[Array, ""],
    foot_lock: bool = False,
    *,
    body_map: BodyMap | None = None,
    intervals: Float[Array, "B 2 2"] | None = None,
    state: tuple[Array, Array] | None = None,
    floor: Float[Array, " B"] | None = None,
    clearance: Float[Array, "2 P"] | None = None,
) -> Float[Array, "B J 3"] | tuple[Float[Array, "B J 3"], tuple[Array, Array]]:
    """World positions of every joint of every character at time `t` (jitted entry point).

    Per character: the channels of Unuma 1995 eq. 1 at `theta = omega t` (linear form, harmonics
    by recurrence from one sin/cos), then forward kinematics (BVH intrinsic Euler order per
    joint, position channels replacing OFFSET components). Equal to
    `kinematics.joint_positions(skeleton, jax.vmap(lambda m: fourier.synthesize(m, t[None])[0])(models))`
    for the skeleton and models the crowd was made from. Differentiable in `t` and in the
    crowd's arrays. With `foot_lock=True` the feet are then locked as by `gait.lock_crowd`
    (held foot points and two-bone leg IK; frames are posed in order, carrying `state`), in the
    same jitted program.

    Arguments:
        crowd: from `make_crowd`.
        t: scalar time in seconds (traced: a new time does not recompile).
        foot_lock: lock the feet of every character in stance (`gait.lock_crowd`).
        body_map: the skeleton's `BodyMap` (feet, legs, up axis); needed with `foot_lock`.
        intervals: `[B, 2, 2]` contact intervals per character (`gait.contact_intervals` of each
            model); needed with `foot_lock`.
        state: the previous frame's lock state (None on the first frame).
        floor: `[B]` floor heights (default 0); clearance: `[2, P]` sole clearances (default 0).

    Returns:
        `[B, J, 3]` joint positions in file units, joints in file order; with `foot_lock`,
        `(positions, state)`, the state to pass with the next frame.

    Raises:
        `UserError` naming the argument when the crowd, `t`, or the foot-lock inputs do not fit.
    """
    if not isinstance(crowd, Crowd):
        raise UserError(f"crowd_positions: `crowd` must be a Crowd (make_crowd), got {type(crowd).__name__}")
    dtype = crowd.coefficients.dtype
    # Called once per frame: `jnp.asarray` of an array already of the dtype cost ~10 us, and
    # of a NumPy scalar ~35 us (jit's own dispatch takes a NumPy scalar for less).
    if not (isinstance(t, (jax.Array, np.ndarray, np.generic)) and t.dtype == dtype):
        t = jnp.asarray(t, dtype)
    if t.shape != ():
        raise UserError(f"crowd_positions: `t` must be a scalar time in seconds, got shape {t.shape}")
    if not foot_lock:
        return _positions_jit(crowd, t)
    if body_map is None or intervals is None:
        raise UserError("crowd_positions: foot_lock=True needs `body_map` (the skeleton's BodyMap) and "
                        "`intervals` ([B, 2, 2] contact intervals, gait.contact_intervals per model)")
    from fourierjax._gait import crowdlock

    topology = crowd.topology
    plan = crowdlock.lock_plan(body_map, topology.parents, topology.num_joints, "crowd_positions")
    _, iv, state, floor, clearance = crowdlock.check_inputs(
        "crowd_positions", plan, crowd.num_characters, t.dtype, None, intervals, state, floor, clearance)
    return _positions_locked_jit(crowd, t, iv, state, floor, clearance, plan=plan)


def _characters_first(pose: Array) -> Array:
    """`[J, 3, B]` -> `[B, J, 3]`."""
    num_joints = pose.shape[0]
    # Store the [J * 3, B] block, then one 2-D transpose: XLA emits a tiled transpose for it
    # (0.4 ms at 10,000 characters) instead of fusing the concatenation into a strided
    # [B, J, 3] loop (6 ms).
    flat = _fk.store(pose.reshape(num_joints * 3, -1))
    return flat.T.reshape(-1, num_joints, 3)


def _positions(crowd: Crowd, t: Array) -> Array:
    return _characters_first(_pose(crowd, t))


def _positions_locked(crowd: Crowd, t: Array, intervals, state, floor, clearance, plan):
    # The lock on the pose as FK leaves it (characters last), before the one transpose.
    from fourierjax._gait import crowdlock

    pose, state = crowdlock.lock_pose(_fk.store(_pose(crowd, t)), crowd.omega * t, intervals, state, floor,
                                      clearance, plan)
    return _characters_first(pose), state


# `_jit.jit` (the one wrapper's mechanism over `jax.jit`; the crowd is all arrays): called once per
# frame, where `filter_jit`'s argument filtering cost ~150 us a call. XLA's default CPU fusion
# emitters (`cpu_compiler_options={}`) run this graph faster than the classic ones of
# `CPU_COMPILER_OPTIONS` (5.8 vs 8.1 ms per frame at 10,000 characters) but compile it slower
# (3.0 vs 1.5 s; shared 2-core machine, load ~5): a crowd is compiled once and posed every frame.
# 512-bit vectors where the CPU has them (AVX-512; elsewhere LLVM keeps the widest it has): CPU
# per frame 5-10% less than with XLA's default preference for 256 bits (10,000 characters, 5
# interleaved runs of 11 rounds at load ~8: 2.97/2.81/2.62/2.70/2.99 against 3.14/3.07/2.68/
# 3.01/3.25 ms), at the same compile time (3 fresh processes each: 2.95/4.25/3.19 against
# 3.03/4.28/3.27 s at load 8).
_CPU_OPTIONS = {"xla_cpu_prefer_vector_width": 512}
_positions_jit = _jit.jit(_positions, cpu_compiler_options=_CPU_OPTIONS)
# The crowd and its foot lock in one program: one dispatch a frame, the lock on `[3, B]` rows.
_positions_locked_jit = _jit.jit(_positions_locked, static_argnames=("plan",), cpu_compiler_options=_CPU_OPTIONS)
