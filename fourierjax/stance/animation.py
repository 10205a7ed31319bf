"""Eased transitions between stance poses (Neff & Fiume 2004, sec. 7)."""

import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, ArrayLike, Float

from fourierjax import rotations
from fourierjax.errors import UserError
from fourierjax.stance.skeleton48 import StancePose


def ease_in_out(t: Float[ArrayLike, "*shape"]) -> Float[Array, "*shape"]:
    """The ease-in, ease-out curve used for all transitions (Neff & Fiume, sec. 7): 3t^2 - 2t^3.

    Arguments:
        t: times in [0, 1] (clipped there), any shape.

    Returns:
        The eased times, same shape.
    """
    t = jnp.clip(jnp.asarray(t), 0.0, 1.0)
    return t * t * (3.0 - 2.0 * t)


def animate(poses: list[StancePose], frames_per_transition: int = 30) -> StancePose:
    """Frames easing from each pose to the next (root lerp, joint slerp on the eased time).

    Arguments:
        poses: two or more poses to pass through (e.g. anticipation, then the action).
        frames_per_transition: frames from one pose to the next (>= 1).

    Returns:
        A `StancePose` with a leading frame axis (`root_position [F, 3]`, `quats [F, J, 4]`).
    """
    if len(poses) < 2:
        raise UserError("animate: give at least two poses")
    n = frames_per_transition
    if isinstance(n, bool) or not isinstance(n, int | np.integer) or n < 1:
        raise UserError(f"animate: frames_per_transition must be a whole number >= 1, got {n!r}")
    t = ease_in_out(jnp.arange(frames_per_transition) / frames_per_transition)
    roots, quats = [], []
    for a, b in zip(poses[:-1], poses[1:]):
        roots.append(a.root_position[None] + t[:, None] * (b.root_position - a.root_position)[None])
        quats.append(rotations.quat_slerp(a.quats[None], b.quats[None], t[:, None]))
    roots.append(poses[-1].root_position[None])
    quats.append(poses[-1].quats[None])
    return StancePose(jnp.concatenate(roots), jnp.concatenate(quats))
