"""Arm IK (Neff & Fiume 2004, sec. 5.3): elbow from shoulder-wrist distance, swivel about the reach axis."""


import jax.numpy as jnp
from jaxtyping import Array, Float

from fourierjax._math import safe_sqrt
from fourierjax.stance import _util as u

_EY = jnp.array([0.0, 1.0, 0.0])


def _arm_cosines(
    upper: Float[Array, ""], fore: Float[Array, ""], distance: Float[Array, ""]
) -> tuple[Float[Array, ""], Float[Array, ""]]:
    """Cosines of the elbow's interior angle and of the shoulder angle (`elbow_flexion`).

    The distance is clamped to `[|upper - fore|, upper + fore]` and the cosines a hair
    inside [-1, 1] (the sine `sqrt(1 - c^2)` and arccos have infinite slopes at +-1).
    """
    dmax = upper + fore
    dmin = jnp.abs(upper - fore) + 1e-6
    d = u.clip(distance, dmin, dmax)
    cos_elbow = (upper * upper + fore * fore - d * d) / (2.0 * upper * fore)
    cos_shoulder = (upper * upper + d * d - fore * fore) / (2.0 * upper * d)
    lim = 1.0 - 1e-7
    return u.clip(cos_elbow, -lim, lim), u.clip(cos_shoulder, -lim, lim)


def elbow_flexion(
    upper: Float[Array, ""], fore: Float[Array, ""], distance: Float[Array, ""]
) -> tuple[Float[Array, ""], Float[Array, ""]]:
    """Elbow flexion (rad, 0 = straight) that puts the wrist `distance` from the shoulder.

    Law of cosines on the arm triangle; a distance outside `[|upper - fore|, upper + fore]`
    is clamped (straight arm, or fully folded).

    Returns:
        `(flexion, shoulder_angle)`: the shoulder angle is between the upper arm and the
        shoulder->wrist axis.
    """
    cos_elbow, cos_shoulder = _arm_cosines(upper, fore, distance)
    return jnp.pi - jnp.arccos(cos_elbow), jnp.arccos(cos_shoulder)


def arm_to_target(
    shoulder: Float[Array, "3"],
    R_parent_world: Float[Array, "3 3"],
    upper: Float[Array, ""],
    fore: Float[Array, ""],
    target: Float[Array, "3"],
    swivel: Float[Array, ""],
    outward: Float[Array, "3"],
) -> tuple[Float[Array, "3 3"], Float[Array, "3 3"], Float[Array, ""]]:
    """Shoulder and elbow rotations that put the wrist on `target` (sec. 5.3).

    The elbow angle comes from the shoulder-wrist distance; the arm triangle is then turned
    about the shoulder->target axis by `swivel` (rad) from a reference where the elbow points
    down and slightly out (`outward`: the arm's side, a world unit vector); positive swivel
    takes the elbow away from the body. An unreachable target gives a straight arm pointing
    at it.

    The triangle's angles enter only through their cosines and sines (law of cosines, no
    arccos): fewer transcendental operations in the stance solver's compiled loop.

    Arguments:
        shoulder: `[3]` world shoulder joint.
        R_parent_world: `[3, 3]` world rotation of the collar (the shoulder's parent).
        upper, fore: upper-arm and forearm lengths (m).
        target: `[3]` world wrist target.
        swivel: rotation of the arm triangle about the reach axis (rad).
        outward: `[3]` unit vector to the arm's side (world).

    Returns:
        `(R_shoulder_local, R_elbow_local, reach_gap)` (matrices), reach_gap = distance beyond reach (m).
    """
    axis = target - shoulder
    dist = u.safe_norm(axis)
    c = u.safe_normalize(axis, -_EY)
    cos_elbow, cos_a = _arm_cosines(upper, fore, dist)
    sin_elbow, sin_a = safe_sqrt(1.0 - cos_elbow * cos_elbow), safe_sqrt(1.0 - cos_a * cos_a)
    ref = -_EY + 0.25 * outward
    ref = ref - u.dot(ref, c) * c
    e0 = u.safe_normalize(ref, u.safe_normalize(u.cross(c, _EY), outward))
    side = u.cross(c, e0)
    # Orient the swivel so that a positive angle moves the elbow toward `outward`.
    s = u.where(u.dot(side, outward) >= 0.0, 1.0, -1.0)
    cos_sw, sin_sw = jnp.cos(swivel), s * jnp.sin(swivel)
    e = cos_sw * e0 + sin_sw * side
    # Upper-arm frame: -Y along the upper arm, +Z toward the forearm's bend, X = Y x Z, which
    # is c x e (c, e orthonormal) = cos(swivel) side - sin(swivel) e0.
    ez = sin_a * c - cos_a * e
    ey = -(cos_a * c + sin_a * e)
    ex = cos_sw * side - sin_sw * e0
    R_local = u.mm(u.tr(R_parent_world), u.columns(ex, ey, ez))
    # Forearm bends toward the upper arm's +Z: Rx(-flex) maps -Y to (0, -cos, sin), with
    # flex = pi - interior: cos(-flex) = -cos(interior), sin(-flex) = -sin(interior).
    R_elbow = u.rot_cs(0, -cos_elbow, -sin_elbow)
    return R_local, R_elbow, jnp.maximum(dist - (upper + fore), 0.0)


def arm_free(
    elbow: Float[Array, ""], arm_out: Float[Array, ""], side_sign: float
) -> tuple[Float[Array, "3 3"], Float[Array, "3 3"]]:
    """Arm without a wrist target: elbow flexion and the arm rotated out from the body (rad).

    `side_sign` is -1 for the right arm (its outside is -X), +1 for the left.

    Returns:
        `(R_shoulder_local, R_elbow_local)` (matrices).
    """
    # A hanging arm (-Y) rotated about Z by +t swings toward +X: the left arm's outside.
    return u.rot(2, side_sign * arm_out), u.rot(0, -elbow)
