"""Argument checks and pose helpers shared by the gait modules."""

from __future__ import annotations

from typing import TYPE_CHECKING

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, ArrayLike, Float

from fourierjax._checks import concrete
from fourierjax.errors import UserError

if TYPE_CHECKING:
    from fourierjax.contacts import FootPoints
    from fourierjax.skeleton import Skeleton, Topology

RULES = ("unuma1995", "continuous", "smooth")
CMU_GROINS = ("LeftUpLeg", "RightUpLeg")


def check_finite(where: str, name: str, value: ArrayLike) -> None:
    """UserError for a concrete non-finite `value` (traced values: see `traced_checks`)."""
    v = concrete(value)
    if v is not None and not np.all(np.isfinite(v)):
        raise UserError(f"{where}: `{name}` must be finite, got {v if v.ndim == 0 else 'non-finite entries'}")


def check_jump(where: str, jump: ArrayLike) -> None:
    """UserError for a concrete `jump` that is negative or not finite."""
    # Eq. 5 lifts the hip by jump·√(Lmax − L) in flight: the flight height, so jump ≥ 0 (the
    # lift is ≥ 0 by construction). A negative jump would push the stance foot into the ground.
    check_finite(where, "jump", jump)
    v = concrete(jump)
    if v is not None and np.any(v < 0):
        raise UserError(f"{where}: `jump` must be >= 0 (the flight height of eq. 5), got {v}")


def check_rule(rule: str) -> str:
    """`rule` itself, or UserError when it is not one of `RULES`."""
    if rule not in RULES:
        raise UserError(f"hip rule {rule!r} is not one of {RULES}")
    return rule


def check_positive(where: str, name: str, value: ArrayLike, what: str) -> None:
    """UserError for a concrete `value` that is not finite and > 0."""
    v = concrete(value)
    if v is not None and not (np.all(np.isfinite(v)) and np.all(v > 0)):
        raise UserError(f"{where}: `{name}` ({what}) must be finite and > 0, got {v}")


def _traced(*values) -> bool:
    return any(isinstance(v, jax.core.Tracer) for v in values)


def smooth_parameter_checks(where: str, x: Array, width: ArrayLike, temperature: ArrayLike | None) -> Array:
    """`x`, carrying checks that `width` and `temperature` (when given) are finite and > 0.

    Concrete values raise `UserError` here; traced ones (under jit, vmap or grad) go through
    `eqx.error_if` and fail when the program runs: a value refused eagerly is refused traced.
    """
    check_positive(where, "width", width, "the sigmoid width of the smooth rule, in units of N")
    if temperature is not None:
        check_positive(where, "temperature", temperature, "the log-sum-exp temperature, file units")
    if not _traced(width, temperature):
        return x
    w = jnp.asarray(width)
    bad = jnp.any(~(jnp.isfinite(w) & (w > 0)))
    if temperature is not None:
        t = jnp.asarray(temperature)
        bad = bad | jnp.any(~(jnp.isfinite(t) & (t > 0)))
    return eqx.error_if(x, bad, f"{where}: `width` and `temperature` must be finite and > 0")


def traced_jump_checks(where: str, x: Array, gait: ArrayLike, jump: ArrayLike) -> Array:
    """`x`, carrying `eqx.error_if` checks of a traced `gait` (finite) and `jump` (finite, >= 0);
    concrete values are checked by `check_finite` and `check_jump`."""
    if not _traced(gait, jump):
        return x
    g, j = jnp.asarray(gait), jnp.asarray(jump)
    bad = jnp.any(~jnp.isfinite(g)) | jnp.any(~jnp.isfinite(j) | (j < 0))
    return eqx.error_if(x, bad, f"{where}: `gait` must be finite and `jump` finite and >= 0")


def groin_joints(topology: Topology, names: tuple[str, str] = CMU_GROINS) -> tuple[int, int]:
    """Indices of the left and right groin (hip) joints; CMU names by default.

    Arguments:
        topology: a `Topology` (anything with `names`).
        names: `(left, right)` joint names.

    Returns:
        `(left, right)` joint indices. Raises `UserError` naming the skeleton's joints when a
        name is missing.
    """
    joints = tuple(topology.names)
    missing = [n for n in names if n not in joints]
    if missing:
        raise UserError(
            f"groin_joints: the skeleton has no joint(s) {missing}; its joints are {list(joints)}."
            " Pass names=(left, right) for a skeleton that does not use the CMU names"
        )
    return joints.index(names[0]), joints.index(names[1])


def _is_index(i, n: int) -> bool:
    return isinstance(i, int | np.integer) and not isinstance(i, bool) and -n <= i < n


def check_indices(where: str, skeleton: Skeleton, feet: FootPoints, groins: tuple[int, int]) -> tuple[int, int]:
    """The groin joint indices as non-negative Python ints; UserError for an index outside the
    skeleton (JAX would clamp it: a wrong joint and a wrong leg length, silently)."""
    num_joints = skeleton.topology.num_joints
    groins = tuple(groins)
    if len(groins) != 2 or not all(_is_index(g, num_joints) for g in groins):
        raise UserError(
            f"{where}: `groins`={groins!r}; expected (left, right) joint indices of the skeleton's "
            f"{num_joints} joints (see `groin_joints`)"
        )
    num_points = num_joints + skeleton.topology.num_end_sites
    for side in ("left", "right"):
        points = tuple(getattr(feet, side))
        if not all(_is_index(i, num_points) for i in points):
            raise UserError(
                f"{where}: `feet.{side}`={points!r}; expected point indices below {num_points} "
                f"({num_joints} joints, then End Sites; see `contacts.foot_points`)"
            )
    return tuple(int(g) % num_joints for g in groins)


def pose_points(
    skeleton: Skeleton, representation: str, idx: Array, groins: tuple[int, int], feat: Float[Array, " C"]
) -> tuple[Float[Array, "2 P 3"], Float[Array, "2 3"]]:
    """Foot points `[2, P, 3]` and groins `[2, 3]` of one feature frame, pelvis at the origin."""
    from fourierjax.kinematics import forward_kinematics
    from fourierjax.motion import local_pose_from_features

    fk = forward_kinematics(skeleton, *local_pose_from_features(skeleton, feat, representation))
    allp = jnp.concatenate([fk.positions, fk.end_site_positions], axis=0)
    return allp[idx], fk.positions[jnp.asarray(groins)]
