"""Gaze (Neff & Fiume 2004, sec. 5.4): the head turned toward a world point, weighted."""

import jax.numpy as jnp
from jaxtyping import Array, Float

from fourierjax import rotations
from fourierjax.stance import _util as u

_EY = jnp.array([0.0, 1.0, 0.0])
_EZ = jnp.array([0.0, 0.0, 1.0])
_NEAR_VERTICAL = 0.05  # sin of the angle from vertical below which the neck's side axis helps


def gaze_rotation(
    R_head_local: Float[Array, "3 3"],
    R_parent_world: Float[Array, "3 3"],
    head_position: Float[Array, "3"],
    point: Float[Array, "3"],
    weight: Float[Array, ""],
) -> Float[Array, "3 3"]:
    """Local head rotation blended from its shape pose toward looking at `point`.

    Full alignment (weight 1) turns the head's +Z (face) onto the direction to `point`
    with its +Y as close to world up as possible; weight 0 keeps `R_head_local`; in between
    is a slerp (the paper's gaze weight: how much of the gaze the head does, the eyes doing
    the rest).

    Arguments:
        R_head_local: `[3, 3]` the head's local rotation from the spine shape.
        R_parent_world: `[3, 3]` world rotation of the neck.
        head_position: `[3]` world head joint.
        point: `[3]` world point to look at.
        weight: blend in [0, 1] (values outside extrapolate).

    Returns:
        `[3, 3]` local head rotation.
    """
    fwd = u.safe_normalize(point - head_position, u.mv(R_parent_world, _EZ))
    # Side axis: world up x forward. Within ~3 degrees of straight up or down that cross
    # product turns ever faster with the direction (1 / sin of the angle from vertical), and
    # the head's twist with it: the neck's own X axis is blended in there (weight 1 at
    # vertical, 0 from sin = _NEAR_VERTICAL on), so the twist stays continuous and the balance
    # solve, which moves the head slightly, converges (measured before: COM 4.3 mm off goal).
    across = u.cross(_EY, fwd)
    blend = u.clip(1.0 - u.safe_norm(across) / _NEAR_VERTICAL, 0.0, 1.0)
    hint = R_parent_world[..., 0]  # the neck's X axis in the world
    hint = hint - u.dot(hint, fwd)[..., None] * fwd
    side = u.safe_normalize(across + blend[..., None] * hint, jnp.array([1.0, 0.0, 0.0]))
    up = u.cross(fwd, side)
    R_look = u.mm(u.tr(R_parent_world), u.columns(side, up, fwd))
    # slerp(R_a, R_b, w) = R_a (R_a^T R_b)^w, the power taken on the quaternion of R_a^T R_b.
    return u.mm(R_head_local, _matrix_power(u.mm(u.tr(R_head_local), R_look), weight))


def _matrix_power(M: Float[Array, "3 3"], weight: Float[Array, ""]) -> Float[Array, "3 3"]:
    """M^w for a rotation matrix, on its quaternion (`rotations.quat_power`; `quat_from_matrix`
    is exact at every angle, 180 degrees included)."""
    return rotations.matrix_from_quat(rotations.quat_power(rotations.quat_from_matrix(M), weight))
