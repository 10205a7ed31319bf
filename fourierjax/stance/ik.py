"""Lower-body analytic IK (Neff & Fiume 2004, sec. 5.1 and appendix): planted feet to leg angles."""


import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float

from fourierjax import rotations
from fourierjax._legik import sphere_circle_point
from fourierjax._math import safe_sqrt
from fourierjax.errors import UserError
from fourierjax.stance import _util as u
from fourierjax.stance.skeleton48 import ANKLE, HIP, KNEE, LEFT, RIGHT, Body

_EX = jnp.array([1.0, 0.0, 0.0])
_EY = jnp.array([0.0, 1.0, 0.0])
_EZ = jnp.array([0.0, 0.0, 1.0])


class Feet(eqx.Module):
    """Where the feet are planted: ankle joint positions and foot orientations (world).

    - `positions`: `[2, 3]` ankle joints of the right (row 0) and left (row 1) foot (m).
    - `quats`: `[2, 4]` world orientation of each ankle joint frame (wxyz; identity = flat,
      toes along +Z).
    """

    positions: Float[Array, "2 3"]
    quats: Float[Array, "2 4"]


def make_feet(
    body: Body,
    stance_width_m: float | Float[Array, ""] | None = None,
    turn_out_rad: float | Float[Array, ""] = 0.0,
    stagger_m: float | Float[Array, ""] = 0.0,
) -> Feet:
    """Flat feet at the origin, facing +Z.

    Arguments:
        body: the character.
        stance_width_m: distance between the ankle joints, >= 0 (default: the hip-joint
            spread). The right foot is at -X, the character's right (a negative width would
            cross the feet, and the pelvis, square to the ankle line, would turn around).
        turn_out_rad: each foot's toes turned outward by this yaw (rad).
        stagger_m: the left foot this far ahead of the right along Z (m; split evenly).

    Returns:
        `Feet`.

    Raises:
        UserError: an argument is not a single finite number, or the width is negative
            (checked when the values are known, i.e. not traced).
    """
    off = body.offsets
    hip_spread = off[HIP[LEFT], 0] - off[HIP[RIGHT], 0]
    if stance_width_m is None:
        width = hip_spread
    else:
        width = _scalar(stance_width_m, "stance_width_m", off.dtype)
        if not isinstance(width, jax.core.Tracer) and float(width) < 0.0:
            raise UserError(
                f"make_feet: stance_width_m must be >= 0 (the distance between the ankles, the "
                f"right foot on the character's right), got {float(width):.6g}: crossed feet turn "
                "the body around (the pelvis faces square to the right->left ankle line)"
            )
    stagger = _scalar(stagger_m, "stagger_m", off.dtype)
    t = _scalar(turn_out_rad, "turn_out_rad", off.dtype)
    ankle_h = off[0, 1] + off[KNEE[RIGHT], 1] + off[ANKLE[RIGHT], 1]
    half = 0.5 * stagger
    pos = jnp.stack(
        [
            jnp.stack([-0.5 * width, ankle_h, -half]),
            jnp.stack([0.5 * width, ankle_h, half]),
        ]
    )
    # Turning the right foot's toes outward (toward -X) is a negative yaw about +Y.
    quats = jnp.stack([u.quat_axis(1, -t), u.quat_axis(1, t)])
    return Feet(positions=pos, quats=quats)


def _scalar(x, name: str, dtype) -> Float[Array, ""]:
    """`x` as a scalar array, or a `UserError` naming `make_feet`'s argument `name` if it is not
    one number or (when its value is known, i.e. not traced) not finite."""
    try:
        a = jnp.asarray(x, dtype)
    except (TypeError, ValueError) as err:
        raise UserError(f"make_feet: {name} must be a number, got {x!r} ({err})") from None
    if a.shape != ():
        raise UserError(f"make_feet: {name} must be a single number, got shape {a.shape}")
    if not isinstance(a, jax.core.Tracer) and not np.isfinite(np.asarray(a)):
        raise UserError(f"make_feet: {name} must be finite, got {float(a)}")
    return a


class LowerBody(eqx.Module):
    """Result of `lower_body_ik` (rotation matrices; `quats` gives quaternions).

    - `root_position`: `[3]` pelvis joint (m).
    - `pelvis`: `[3, 3]` world orientation of the pelvis.
    - `hips`, `knees`, `ankles`: `[2, 3, 3]` local rotations (right, left).
    - `hip_positions`: `[2, 3]` world hip joints.
    - `thighs`, `shins`, `feet`: `[2, 3, 3]` world frames of the hip, knee and ankle joints
      (the feet are the planted ones).
    - `free_foot_gap_m`: how far the free foot's leg cannot reach (0 when the circle of
      valid hip positions exists, i.e. the foot is planted exactly).
    """

    root_position: Float[Array, "3"]
    pelvis: Float[Array, "3 3"]
    hips: Float[Array, "2 3 3"]
    knees: Float[Array, "2 3 3"]
    ankles: Float[Array, "2 3 3"]
    hip_positions: Float[Array, "2 3"]
    free_foot_gap_m: Float[Array, ""]
    thighs: Float[Array, "2 3 3"]
    shins: Float[Array, "2 3 3"]
    feet: Float[Array, "2 3 3"]

    def quats(self) -> dict[str, Float[Array, "... 4"]]:
        """The rotations as wxyz quaternions: pelvis [4], hips/knees/ankles [2, 4]."""
        q = rotations.quat_from_matrix
        return {"pelvis": q(self.pelvis), "hips": q(self.hips), "knees": q(self.knees),
                "ankles": q(self.ankles)}  # fmt: skip


def _leg_vector(body: Body, side: int, knee: Float[Array, ""]) -> Float[Array, "3"]:
    """Ankle -> hip vector in the shin frame for a knee flexion `knee` (rad)."""
    o_knee = body.offsets[KNEE[side]]  # hip -> knee in the thigh frame
    o_ankle = body.offsets[ANKLE[side]]  # knee -> ankle in the shin frame
    # hip - ankle = R_shin (-o_ankle - R_knee^T o_knee), R_knee = Rx(knee).
    return -o_ankle - u.mv(u.rot(0, -knee), o_knee)


def _unit2(a, b):
    """(a, b) / |(a, b)|, or (1, 0) where it is ~0: the cosine and sine of the angle of (a, b)."""
    sq = a * a + b * b
    small = sq < 1e-20
    inv = u.rsqrt_where(sq, small)
    return u.where(small, 1.0, a * inv), b * inv


def _ankle_from_vector(w: Float[Array, "3"], v: Float[Array, "3"]) -> Float[Array, "3 3"]:
    """Ankle rotation R_a = Rz(z) Rx(x) with R_a^T w = v (|w| = |v|, w_x = 0).

    The angles enter only through their cosines and sines, from normalised 2-vectors (no
    atan2 and trigonometric round trip in the stance solver's loop).
    """
    (_, wy, wz), (vx, vy, vz) = (jnp.split(x, 3, axis=-1) for x in (w, v))
    # Rz(-z) w = (wy sin z, wy cos z, wz): its x must equal v_x.
    cz = safe_sqrt(wy * wy - vx * vx, floor=1e-12)  # = wy cos z  (>= 0: |z| <= pi/2)
    cos_z, sin_z = _unit2(cz, vx)
    # Rx(-x) rotates (wy cos z, wz) onto (v_y, v_z) in the YZ plane: x = angle(cz, wz) -
    # angle(vy, vz).
    (c1, s1), (c2, s2) = _unit2(cz, wz), _unit2(vy, vz)
    cos_x, sin_x = c1 * c2 + s1 * s2, s1 * c2 - c1 * s2
    return u.mm(u.rot_cs(2, cos_z[0], sin_z[0]), u.rot_cs(0, cos_x[0], sin_x[0]))


def pelvis_frame_desired(feet: Feet, pelvis_xyz: Float[Array, "3"]) -> Float[Array, "3 3"]:
    """Desired pelvis orientation (matrix): yaw of the ankle line, then Y, Z and X (rad).

    The pelvic Y rotation is relative to the line through the two ankles (sec. 5.1):
    `R = R_base Ry(y) Rz(z) Rx(x)`, where `R_base` turns +X onto the right->left ankle line.
    """
    d = feet.positions[LEFT] - feet.positions[RIGHT]
    yaw = jnp.arctan2(-d[2], jnp.where(jnp.abs(d[0]) + jnp.abs(d[2]) > 0, d[0], 1.0))
    R = u.mm(u.rot(1, yaw + pelvis_xyz[1]), u.rot(2, pelvis_xyz[2]))
    return u.mm(R, u.rot(0, pelvis_xyz[0]))


def free_hip_position(
    root_hip: Float[Array, "3"],
    free_ankle: Float[Array, "3"],
    hip_width: Float[Array, ""],
    free_leg_length: Float[Array, ""],
    hip_dir_desired: Float[Array, "3"],
) -> tuple[Float[Array, "3"], Float[Array, ""]]:
    """The free hip on the circle of valid positions, closest to the desired hip vector.

    The circle (appendix, Fig. 8) is where |h - root_hip| = hip_width (side B) and
    |h - free_ankle| = free_leg_length (side C) meet: it lies in a plane perpendicular to
    side A (root hip -> free ankle). The paper intersects the desired hip vector with that
    plane (or, when the vector lies in or near the plane, projects its end point onto it) and
    moves the point to the closest point of the circle. Both constructions give a point on
    the same ray from the circle's centre, the in-plane part of the desired hip vector, so
    the closest circle point is `centre + radius * normalize(in-plane part)`, which we use in
    both cases (it has no switch and stays differentiable): `_legik.sphere_circle_point`, the
    two-bone IK that the gait foot lock shares. `tests/test_stance_ik.py` checks it against a
    literal two-case implementation.

    Returns:
        `(free_hip [3], gap)` where `gap > 0` (m) when the circle does not exist (the foot
        cannot be reached; the closest point is returned).
    """
    return sphere_circle_point(root_hip, free_ankle, hip_width, free_leg_length, hip_dir_desired)


def lower_body_ik(
    body: Body,
    feet: Feet,
    knees: Float[Array, "2"],
    balance_xz: Float[Array, "2"],
    pelvis_xyz: Float[Array, "3"],
    dominant: str = "right",
) -> LowerBody:
    """Lower-body analytic IK (Neff & Fiume 2004, appendix "Lower Body IK Algorithm").

    The root (dominant) leg: its knee takes the desired angle; the ankle->hip vector, of the
    length the knee angle gives, is vertical in the foot frame and then turned by the balance
    offsets on the ankle's X and Z axes (`balance_xz`, rad: ankle joint rotations, so with
    the foot planted the leg turns by their inverse). The free hip is placed on the circle
    of valid positions (see `free_hip_position`) so that the free knee takes its desired
    angle exactly; the free ankle angles follow so the free foot stays planted; the pelvis
    frame is built from the actual hip vector with the up vector of the desired pelvis X
    rotation projected perpendicular to it (the appendix's "view matrix"). Hip rotations are
    R_hip = R_pelvis^T R_thigh (the appendix works with quaternions; `LowerBody.quats`).

    Arguments:
        body: the character.
        feet: planted ankle positions and foot orientations.
        knees: `[2]` desired knee flexions (rad, right then left; 0 = straight).
        balance_xz: `[2]` X and Z offsets (rad) on the dominant ankle (balance control).
        pelvis_xyz: `[3]` desired pelvis X (tilt), Y (relative to the ankle line) and Z
            (rad).
        dominant: "right" or "left" (static): the root leg.

    Returns:
        `LowerBody`.
    """
    if dominant not in ("right", "left"):
        raise UserError(f"lower_body_ik: dominant must be 'right' or 'left', got {dominant!r}")
    d = RIGHT if dominant == "right" else LEFT
    f = 1 - d
    off = body.offsets
    R_feet = rotations.matrix_from_quat(feet.quats)
    knees = jnp.asarray(knees)

    # Root leg: ankle -> hip.
    w_d = _leg_vector(body, d, knees[d])
    beta = jnp.arctan2(-w_d[2], w_d[1])  # lean of w off the shin axis (thigh behind)
    R_ankle_d = u.mm(u.rot(2, balance_xz[1]), u.rot(0, balance_xz[0] - beta))
    R_shin_d = u.mm(R_feet[d], u.tr(R_ankle_d))
    hip_d = feet.positions[d] + u.mv(R_shin_d, w_d)

    # Free hip on the circle of valid positions.
    off_d, off_f = off[HIP[d]], off[HIP[f]]
    R_des = pelvis_frame_desired(feet, pelvis_xyz)
    hip_vec_local = off_f - off_d
    W = u.safe_norm(hip_vec_local)
    b_des = u.mv(R_des, hip_vec_local) / W
    w_f = _leg_vector(body, f, knees[f])
    leg_f = u.safe_norm(w_f)
    hip_f, gap = free_hip_position(hip_d, feet.positions[f], W, leg_f, b_des)

    # Free ankle: its angles put the free hip where it must be. The plant->hip vector is
    # scaled to the leg's length (a no-op up to round-off when the plant is reachable): with
    # a plant the leg cannot reach (gap > 0) the leg then points at the hip and the free foot
    # misses its plant by the reported gap (unscaled, the leg turned ~20 degrees off: 441 mm
    # off the plant for a 294 mm gap).
    v_f = u.mv(u.tr(R_feet[f]), hip_f - feet.positions[f])
    sq = u.dot(v_f, v_f)
    v_f = v_f * (leg_f * u.rsqrt_where(sq, sq < 1e-12))
    R_ankle_f = _ankle_from_vector(w_f, v_f)
    R_shin_f = u.mm(R_feet[f], u.tr(R_ankle_f))

    # Pelvis frame: X along the actual hip vector, Y the projected desired up vector.
    sign = jnp.sign(hip_vec_local[0])  # +1 when the free hip is the left one
    ex = sign * (hip_f - hip_d) / W
    up = R_des[:, 1]
    ey = u.safe_normalize(up - u.dot(up, ex) * ex, _EY)
    R_p = u.columns(ex, ey, u.cross(ex, ey))
    root = hip_d - u.mv(R_p, off_d)

    R_knees = u.rot(0, knees)
    shins = [None, None]
    shins[d], shins[f] = R_shin_d, R_shin_f
    shins = jnp.stack(shins)
    ankles = [None, None]
    ankles[d], ankles[f] = R_ankle_d, R_ankle_f
    thighs = u.mm(shins, u.tr(R_knees))  # world: shin = thigh knee
    hip_pos = [None, None]
    hip_pos[d], hip_pos[f] = hip_d, hip_f
    return LowerBody(
        root_position=root,
        pelvis=R_p,
        hips=u.mm(u.tr(R_p)[None], thighs),
        knees=R_knees,
        ankles=jnp.stack(ankles),
        hip_positions=jnp.stack(hip_pos),
        free_foot_gap_m=gap,
        thighs=thighs,
        shins=shins,
        feet=R_feet,
    )
