"""A stance problem (shape vector, states, constraints) and the pose it builds (sec. 5)."""


import functools

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float

from fourierjax import rotations
from fourierjax._linalg import PRECISION, matmul
from fourierjax.errors import UserError
from fourierjax.stance import _util as u
from fourierjax.stance.arms import arm_free, arm_to_target
from fourierjax.stance.balance import (
    balance_point,
    inside_polygon_margin,
    inverse_2x2,
    monitor_points_world,
    newton_2d_with_tangents,
    support_polygon,
)
from fourierjax.stance.gaze import gaze_rotation
from fourierjax.stance.ik import Feet, lower_body_ik, make_feet, pelvis_frame_desired
from fourierjax.stance.penalties import (
    HermitePenalty,
    check_penalty,
    quadratic_penalty,
    reach_penalty,
)
from fourierjax.stance.skeleton48 import (
    ANKLE,
    COLLAR,
    ELBOW,
    HIP,
    JOINT_NAMES,
    KNEE,
    LEFT,
    RIGHT,
    SHOULDER,
    SPINE,
    WRIST,
    Body,
    J,
    StancePose,
    center_of_mass_matrices,
)
from fourierjax.stance.torso import class_weights, collar_quats, collar_sign, spine_quats

#: The numeric shape vector (Neff & Fiume sec. 6): all zeros is the neutral pose. The first
#: six are the torso amplitudes the solver optimises (their values here are the desired
#: points of their penalties); the rest are set directly. Radians, except the two balance
#: shifts (fractions in [-1, 1], see `balance_point`) and the gaze weight (0..1).
SHAPE_PARAMS: tuple[str, ...] = (
    "sagittal", "coronal", "transverse", "collar_y", "collar_z", "abdomen_x",
    "knee_right", "knee_left", "pelvis_x", "pelvis_y", "pelvis_z",
    "weight_shift", "forward_shift",
    "elbow_right", "elbow_left", "arm_out_right", "arm_out_left",
    "swivel_right", "swivel_left",
    "gaze_weight",
)  # fmt: skip
P = {name: i for i, name in enumerate(SHAPE_PARAMS)}
NUM_AMPLITUDES = 6
AMPLITUDES = SHAPE_PARAMS[:NUM_AMPLITUDES]
HANDS = ("right", "left")


class StanceProblem(eqx.Module):
    """Everything that defines one pose to solve; all arrays, so problems batch with vmap.

    - `body`, `feet`: the character and where its feet are planted.
    - `shape`: `[20]` shape vector (`SHAPE_PARAMS`).
    - `sagittal_weights`, `coronal_weights`: `[4]` shape-class weights (`torso`).
    - `collar_signs`: `[2]` Y and Z collar states (+1 aligned, -1 opposed).
    - `free`: `[6]` 1 where the solver may move a torso amplitude, 0 to hold it.
    - `amplitude_penalty`: `HermitePenalty` with `[6]` leaves, in offsets from the desired
      point (its `desired` is 0); `amplitude_weights` `[6]`: the w_i of eq. 5.
    - `targets`: `[2, 3]` wrist targets (right, left); `target_active` `[2]` 0/1.
    - `reach`: `HermitePenalty` with `[2]` leaves on the shoulder-target distance;
      `reach_weights` `[2]`.
    - `gaze_point`: `[3]` world point the head turns to (with the `gaze_weight` parameter).
    - `dominant`: "right" or "left" (static): the foot that carries balance.
    """

    body: Body
    feet: Feet
    shape: Float[Array, "20"]
    sagittal_weights: Float[Array, "4"]
    coronal_weights: Float[Array, "4"]
    collar_signs: Float[Array, "2"]
    free: Float[Array, "6"]
    amplitude_penalty: HermitePenalty
    amplitude_weights: Float[Array, "6"]
    targets: Float[Array, "2 3"]
    target_active: Float[Array, "2"]
    reach: HermitePenalty
    reach_weights: Float[Array, "2"]
    gaze_point: Float[Array, "3"]
    dominant: str = eqx.field(static=True, default="right")


def as_finite(x, name: str, dtype=None) -> Array:
    """`x` as an array, or a `UserError` naming `name` if it is not numbers or (when its values
    are known, i.e. not traced) holds NaN or infinity."""
    try:
        a = jnp.asarray(x, dtype)
    except (TypeError, ValueError) as err:
        raise UserError(f"{name} must be numbers, got {x!r} ({err})") from None
    if not isinstance(a, jax.core.Tracer) and not np.isfinite(np.asarray(a)).all():
        raise UserError(f"{name} holds NaN or infinite values: {np.asarray(a).tolist()}")
    return a


def make_problem(
    body: Body,
    shape=None,
    *,
    feet: Feet | None = None,
    sagittal_class: str = "straight",
    coronal_class: str = "straight",
    collar_y: str = "aligned",
    collar_z: str = "aligned",
    abdomen_offset: bool = False,
    target_right=None,
    target_left=None,
    gaze_point=None,
    amplitude_scale: float = 0.25,
    reach_weight: float = 10.0,
    dominant: str = "right",
) -> StanceProblem:
    """Build a `StanceProblem` from names (the low-level interface of sec. 3).

    Arguments:
        body: the character (`make_body`).
        shape: `[20]` shape vector, or a dict {name: value} over `SHAPE_PARAMS` (missing
            names are 0). Default: neutral.
        feet: planted feet (default `make_feet(body)`).
        sagittal_class, coronal_class: spine shape classes (`torso.SHAPE_CLASSES`).
        collar_y, collar_z: "aligned" or "opposed".
        abdomen_offset: let the solver move the abdomen X offset.
        target_right, target_left: `[3]` world wrist targets (m) or None.
        gaze_point: `[3]` world point to look at (default: 2 m ahead at eye height).
        amplitude_scale: rad, > 0; the amplitude penalties are ((a - desired)/scale)^2 near
            the desired point.
        reach_weight: weight of each reach penalty in eq. 5, >= 0 (0: the torso does not
            help the arms reach; the arm IK still aims at the targets).
        dominant: "right" or "left".

    Returns:
        A `StanceProblem`.

    Raises:
        UserError: a bad argument. Values are checked when they are known (not traced): NaN
            or infinity anywhere, `amplitude_scale <= 0`, `reach_weight < 0`, foot quaternions
            that are not unit, crossed feet: the right foot not to the right of the left one
            for the direction the toes point (the pelvis would face away from the toes), or a
            knee or elbow bend outside [`BEND_MIN_RAD`, `BEND_MAX_RAD`] (-6 to 149 degrees).
    """
    if dominant not in ("right", "left"):
        raise UserError(f"dominant must be 'right' or 'left', got {dominant!r}")
    dtype = body.offsets.dtype
    amplitude_scale = _positive_scalar(amplitude_scale, "amplitude_scale", dtype, allow_zero=False)
    reach_weight = _positive_scalar(reach_weight, "reach_weight", dtype, allow_zero=True)
    if shape is None:
        vec = jnp.zeros(len(SHAPE_PARAMS), dtype)
    elif isinstance(shape, dict):
        unknown = sorted(set(shape) - set(SHAPE_PARAMS))
        if unknown:
            raise UserError(f"unknown shape parameter(s) {unknown}; known: {list(SHAPE_PARAMS)}")
        values = [as_finite(shape.get(n, 0.0), f"shape[{n!r}]", dtype) for n in SHAPE_PARAMS]
        bad = [n for n, v in zip(SHAPE_PARAMS, values) if v.shape != ()]
        if bad:
            raise UserError(f"shape values must be single numbers; not {bad}")
        vec = jnp.stack(values)
    else:
        vec = as_finite(shape, "shape", dtype)
        if vec.shape != (len(SHAPE_PARAMS),):
            raise UserError(f"shape must have {len(SHAPE_PARAMS)} values, got shape {vec.shape}")
    check_bends(vec, "make_problem: shape")
    if feet is None:
        feet = make_feet(body)
    else:
        _check_feet(feet)
    targets, active = [], []
    for hand, t in (("right", target_right), ("left", target_left)):
        if t is None:
            targets.append(jnp.zeros(3, dtype))
            active.append(0.0)
        else:
            t = as_finite(t, f"target_{hand}", dtype)
            if t.shape != (3,):
                raise UserError(f"target_{hand} must be 3 coordinates, got shape {t.shape}")
            targets.append(t)
            active.append(1.0)
    if gaze_point is None:
        gaze_point = jnp.array([0.0, 0.94 * body.height_m, 2.0], dtype)
    gaze_point = as_finite(gaze_point, "gaze_point", dtype)
    if gaze_point.shape != (3,):
        raise UserError(f"gaze_point must be 3 coordinates, got shape {gaze_point.shape}")
    arm = arm_lengths(body)
    free = jnp.array([1.0] * 5 + [1.0 if abdomen_offset else 0.0], dtype)
    amplitude_penalty = quadratic_penalty(jnp.zeros(NUM_AMPLITUDES), amplitude_scale)
    if not isinstance(amplitude_scale, jax.core.Tracer):
        # A tiny scale passes the check above but its slopes (2 / scale) overflow. Evaluated
        # eagerly: under an outer jit the penalty built above is traced even for a known scale.
        with jax.ensure_compile_time_eval():
            check_penalty(quadratic_penalty(jnp.zeros(NUM_AMPLITUDES), amplitude_scale),
                          f"make_problem: amplitude_scale={float(amplitude_scale):.6g}")
    reach = reach_penalty(arm[0])
    reach = HermitePenalty(*(jnp.stack([x, x]) for x in (reach.desired, reach.widths,
                                                          reach.values, reach.slopes)))  # fmt: skip
    return StanceProblem(
        body=body,
        feet=feet,
        shape=vec,
        sagittal_weights=class_weights("sagittal", sagittal_class),
        coronal_weights=class_weights("coronal", coronal_class),
        collar_signs=jnp.array([collar_sign(collar_y), collar_sign(collar_z)], dtype),
        free=free,
        amplitude_penalty=amplitude_penalty,
        amplitude_weights=jnp.ones(NUM_AMPLITUDES, dtype),
        targets=jnp.stack(targets),
        target_active=jnp.array(active, dtype),
        reach=reach,
        reach_weights=jnp.full(2, reach_weight, dtype),
        gaze_point=gaze_point,
        dominant=dominant,
    )


#: Range of the knee and elbow bends (rad) a problem may ask for. Past the top (~149 degrees)
#: the thigh folds onto and then through the shin (the posture set at intensity 1.8 asked
#: for 180 degrees, at 2.0 for 246, which the IK turned into a knee bent backwards); below
#: the bottom (-6 degrees) the joint bends backwards (a knee bend of -0.3 was solved as a knee
#: bent 17 degrees the wrong way, an elbow as a 17-degree hyperextension), all with
#: converged=True.
BEND_MIN_RAD = -0.1
BEND_MAX_RAD = 2.6
_BENDS = (("knee_right", "knee"), ("knee_left", "knee"), ("elbow_right", "elbow"), ("elbow_left", "elbow"))

#: Shape parameters that are sizes, not directions: the joint bends and the gaze blend.
#: `negate_directions` (a wind-up; the negative side of a shape set without a [negative]
#: table) keeps their sign: a recoil's wind-up leans towards the object with the elbows
#: still bent and the eyes still on it, where negating every value hyperextended the elbows
#: (34 degrees at strong_recoil -1) and turned the head away.
MAGNITUDE_PARAMS: tuple[str, ...] = ("knee_right", "knee_left", "elbow_right", "elbow_left", "gaze_weight")
_DIRECTION_SIGNS = np.array([1.0 if n in MAGNITUDE_PARAMS else -1.0 for n in SHAPE_PARAMS], np.float32)


def negate_directions(shape: Float[Array, "20"]) -> Float[Array, "20"]:
    """The shape vector pointing the other way: directions (leans, twists, shifts, arm
    directions) negated, `MAGNITUDE_PARAMS` kept."""
    return jnp.asarray(_DIRECTION_SIGNS, jnp.result_type(shape)) * shape


def check_bends(shape, where: str) -> None:
    """Refuse a concrete shape vector whose knee or elbow bends leave [`BEND_MIN_RAD`,
    `BEND_MAX_RAD`] (traced: no check)."""
    if isinstance(shape, jax.core.Tracer):
        return
    v = np.asarray(shape, np.float64)
    for name, joint in _BENDS:
        bend = float(v[P[name]])
        if not BEND_MIN_RAD - 1e-6 <= bend <= BEND_MAX_RAD + 1e-6:  # the bounds in float32 pass
            why = ("the joint would bend backwards" if bend < BEND_MIN_RAD else
                   "the limb would fold onto itself")
            article = "an" if joint == "elbow" else "a"
            raise UserError(
                f"{where}: {name} = {bend:.3f} rad ({np.degrees(bend):.0f} degrees) is past "
                f"{article} {joint}'s range ({BEND_MIN_RAD} to {BEND_MAX_RAD} rad, "
                f"{np.degrees(BEND_MIN_RAD):.0f} to {np.degrees(BEND_MAX_RAD):.0f} degrees): {why}"
            )


def _positive_scalar(x, name: str, dtype, allow_zero: bool) -> Array:
    """`make_problem`'s argument `name` as a scalar, checked finite and > 0 (>= 0 with
    `allow_zero`) when its value is known."""
    a = as_finite(x, f"make_problem: {name}", dtype)
    if a.shape != ():
        raise UserError(f"make_problem: {name} must be a single number, got shape {a.shape}")
    if not isinstance(a, jax.core.Tracer):
        v = float(a)
        if v < 0.0 or (v == 0.0 and not allow_zero):
            raise UserError(f"make_problem: {name} must be {'>= 0' if allow_zero else '> 0'}, got {v:.6g}")
    return a


def _check_feet(feet: Feet, name: str = "make_problem: feet") -> None:
    """Raise a `UserError` naming `name` if `feet` is not a `Feet` of `[2, 3]` positions and
    `[2, 4]` quaternions or, when its values are known (not traced), holds NaN or infinity,
    quaternions that are not unit, or crossed feet.

    Crossed means the pelvis would face away from the toes. The lower-body IK turns the pelvis
    square to the right->left ankle line (`pelvis_frame_desired`: facing +Z for a right foot
    at -X, and +Z when the ankles coincide), so when the right foot is not on the right of the
    left foot, relative to where the feet point, the body stands turned around on its feet
    (hips twisted by 180 degrees) and the solve still converges. The direction the feet point
    is the sum of their toe directions, so feet turned together by any yaw are fine; each
    foot turned out by more than 90 degrees points behind the body and counts as crossed (it
    is the same pose as crossed feet, turned by 180 degrees).
    """
    if not isinstance(feet, Feet):
        raise UserError(f"{name} must be a Feet (make_feet), got {type(feet).__name__}")
    arrays = []
    for field, shape in (("positions", (2, 3)), ("quats", (2, 4))):
        a = as_finite(getattr(feet, field), f"{name}.{field}")
        if a.shape != shape:
            raise UserError(f"{name}.{field} must have shape {shape}, got {a.shape}")
        arrays.append(a)
    positions, quats = arrays
    if isinstance(positions, jax.core.Tracer) or isinstance(quats, jax.core.Tracer):
        return
    # Eagerly: under an outer jit, operations on known feet would be traced.
    with jax.ensure_compile_time_eval():
        toes = np.asarray(rotations.matrix_from_quat(quats), np.float64)[:, :, 2]
        pelvis = pelvis_frame_desired(Feet(positions, quats), jnp.zeros(3, positions.dtype))
    positions = np.asarray(positions, np.float64)
    norms = np.linalg.norm(np.asarray(quats, np.float64), axis=-1)
    if np.abs(norms - 1.0).max() > 1e-3:
        raise UserError(f"{name}.quats must be unit quaternions (wxyz), got norms {norms.tolist()}")
    toes = toes.sum(axis=0) * np.array([1.0, 0.0, 1.0])  # horizontal; ~0 when pointing sideways
    facing = np.asarray(pelvis, np.float64)[:, 2]
    if facing @ toes < -1e-6:  # the tolerance lets toes turned out by exactly 90 degrees pass

        def show(v, digits=3):
            return (np.round(np.asarray(v, np.float64), digits) + 0.0).tolist()  # no "-0.0"

        raise UserError(
            f"{name} are crossed: the right foot (positions[0] = {show(positions[0], 4)}) "
            f"must be to the right of the left foot ({show(positions[1], 4)}) for the "
            f"direction the toes point ({show(toes / np.linalg.norm(toes))}); the pelvis turns "
            "square to the right->left ankle line (+Z when the ankles coincide) and would face "
            f"{show(facing)}, so the body would stand turned around on its feet. For feet facing "
            "+Z the right foot is at -X. Uncross the feet, or turn each foot out by less than "
            "90 degrees"
        )


def _pair(x, joints: tuple[int, int]):
    """`x[joints]` for a (right, left) pair of joint indices, stacked."""
    return jnp.stack([x[joints[RIGHT]], x[joints[LEFT]]])


def arm_lengths(body: Body) -> Float[Array, "2"]:
    """Shoulder-to-wrist length of the right and left arm (m)."""
    off = body.offsets
    return jnp.stack(
        [u.safe_norm(off[ELBOW[s]]) + u.safe_norm(off[WRIST[s]]) for s in (RIGHT, LEFT)]
    )


class PoseInfo(eqx.Module):
    """What `build_pose` measures on the way (all world, metres)."""

    com: Float[Array, "3"]
    shoulders: Float[Array, "2 3"]
    wrists: Float[Array, "2 3"]
    reach_gaps: Float[Array, "2"]
    free_foot_gap: Float[Array, ""]


def build_rotations(
    problem: StanceProblem, amplitudes: Float[Array, "6"], balance_xz: Float[Array, "2"]
) -> tuple[Float[Array, "3"], Float[Array, "joints 3 3"], PoseInfo]:
    """`build_pose` on rotation matrices: `(root_position, local rotations [J, 3, 3], info)`."""
    body, s = problem.body, problem.shape
    sag, cor, trans, cy, cz, abx = (amplitudes[i] for i in range(NUM_AMPLITUDES))
    lb = lower_body_ik(
        body,
        problem.feet,
        jnp.stack([s[P["knee_right"]], s[P["knee_left"]]]),
        balance_xz,
        jnp.stack([s[P["pelvis_x"]], s[P["pelvis_y"]], s[P["pelvis_z"]]]),
        problem.dominant,
    )
    off = body.offsets
    L = [None] * len(JOINT_NAMES)
    L[0] = lb.pelvis
    for k in (RIGHT, LEFT):
        L[HIP[k]], L[KNEE[k]], L[ANKLE[k]] = lb.hips[k], lb.knees[k], lb.ankles[k]
    spine = spine_quats(sag, cor, trans, abx, problem.sagittal_weights, problem.coronal_weights)
    for i, j in enumerate(SPINE):
        L[j] = spine[i]
    collars = collar_quats(cy, cz, problem.collar_signs)
    # World frames are built along the way (the arm IK and gaze need some of them), so the
    # pose needs no separate forward kinematics: fewer XLA kernels in the solver's loop.
    Rw, Pw = [lb.pelvis], [lb.root_position]  # pelvis, abdomen, chest, neck, head
    for j in SPINE[:3]:  # abdomen, chest, neck
        Rw.append(u.mm(Rw[-1], L[j]))
        Pw.append(Pw[-1] + u.mv(Rw[-2], off[j]))
    R_chest, p_chest, R_neck = Rw[2], Pw[2], Rw[3]
    p_head = Pw[3] + u.mv(R_neck, off[J["head"]])
    # Legs: world frames from the IK (the feet keep their planted orientation); the ankles
    # by forward kinematics, as a free foot the leg cannot reach is not on its mark.
    R_thigh, R_shin, R_foot = lb.thighs, lb.shins, lb.feet
    p_hip = lb.hip_positions
    p_knee = p_hip + u.mv(R_thigh, _pair(off, KNEE))
    p_ankle = p_knee + u.mv(R_shin, _pair(off, ANKLE))
    # Both arms at once (a leading axis of 2: right, left): one copy of the arm IK in the graph.
    L[COLLAR[RIGHT]], L[COLLAR[LEFT]] = collars[RIGHT], collars[LEFT]
    R_collars = u.mm(R_chest[None], collars)
    arm_off = {name: _pair(off, idx) for name, idx in (("collar", COLLAR), ("shoulder", SHOULDER),
                                                        ("elbow", ELBOW), ("wrist", WRIST))}  # fmt: skip
    p_collars = p_chest[None] + u.mv(R_chest[None], arm_off["collar"])
    shoulders = p_collars + u.mv(R_collars, arm_off["shoulder"])
    sides = jnp.array([-1.0, 1.0], off.dtype)  # the arm's outside is -X (right), +X (left)

    def arm_params(*names):
        return jnp.stack([s[P[n]] for n in names])

    R_sh_t, R_el_t, gap = jax.vmap(arm_to_target)(
        shoulders,
        R_collars,
        u.safe_norm(arm_off["elbow"]),
        u.safe_norm(arm_off["wrist"]),
        problem.targets,
        arm_params("swivel_right", "swivel_left"),
        lb.pelvis[None, :, 0] * sides[:, None],
    )
    R_sh_f, R_el_f = jax.vmap(arm_free)(
        arm_params("elbow_right", "elbow_left"), arm_params("arm_out_right", "arm_out_left"), sides
    )
    on = problem.target_active > 0.5
    R_sh = u.where(on[:, None, None], R_sh_t, R_sh_f)
    R_el = u.where(on[:, None, None], R_el_t, R_el_f)
    R_upper = u.mm(R_collars, R_sh)
    R_fore = u.mm(R_upper, R_el)
    p_elbow = shoulders + u.mv(R_upper, arm_off["elbow"])
    wrists = p_elbow + u.mv(R_fore, arm_off["wrist"])
    for k in (RIGHT, LEFT):
        L[SHOULDER[k]], L[ELBOW[k]] = R_sh[k], R_el[k]
        L[WRIST[k]] = jnp.eye(3, dtype=off.dtype)
    L[J["head"]] = gaze_rotation(
        spine[3], R_neck, p_head, problem.gaze_point, s[P["gaze_weight"]]
    )
    Rw.append(u.mm(R_neck, L[J["head"]]))
    Pw.append(p_head)
    local = jnp.stack(L)
    # The COM by blocks of joints that are contiguous in the skeleton, each block one batched
    # product (`center_of_mass_matrices` with `first`): world frames [side, joint] of the arms
    # (collar, shoulder, elbow, wrist) and legs (hip, knee, ankle), and pelvis..head. Neither
    # the 19 frames stacked into one array (40 more XLA kernels in the solver's loop) nor
    # summed one by one (~250 traced operations).
    stack = functools.partial(jnp.stack, axis=1)
    blocks = (
        (jnp.stack(Rw), jnp.stack(Pw), J["pelvis"]),
        (stack([R_collars, R_upper, R_fore, R_fore]), stack([p_collars, shoulders, p_elbow, wrists]), COLLAR[RIGHT]),
        (stack([R_thigh, R_shin, R_foot]), stack([p_hip, p_knee, p_ankle]), HIP[RIGHT]),
    )
    info = PoseInfo(
        com=sum(center_of_mass_matrices(body, R, pos, first) for R, pos, first in blocks),
        shoulders=shoulders,
        wrists=wrists,
        reach_gaps=u.where(on, gap, 0.0),
        free_foot_gap=lb.free_foot_gap_m,
    )
    return lb.root_position, local, info


# `build_rotations` sums the COM by blocks of joints that must be contiguous, row-major.
assert [J[n] for n in ("pelvis", "abdomen", "chest", "neck", "head")] == list(range(5))
assert [c + i for c in (COLLAR[RIGHT], COLLAR[LEFT]) for i in range(4)] == [
    idx[k] for k in (RIGHT, LEFT) for idx in (COLLAR, SHOULDER, ELBOW, WRIST)
] == list(range(COLLAR[RIGHT], COLLAR[RIGHT] + 8))
assert [idx[k] for k in (RIGHT, LEFT) for idx in (HIP, KNEE, ANKLE)] == list(range(HIP[RIGHT], HIP[RIGHT] + 6))


def balance_margin_m(problem: StanceProblem) -> np.ndarray:
    """How far (m) the desired COM point lies inside the support polygon; < 0: outside.

    The signed distance of `desired_balance_point` from the nearest edge of the convex hull of
    the feet's monitor points (`balance.support_polygon`). Negative where `weight_shift` or
    `forward_shift` beyond +-1 (directly or from a shape set past intensity 1) put the point off
    the feet: such a pose is solved, and its COM placed there, but it is not statically
    balanced (the paper leaves such poses to the animator). NumPy at the edge, for concrete
    problems: one problem gives a 0-d array, a stacked batch one value per problem.
    """
    batch = problem.shape.shape[:-1]
    arrays, static = eqx.partition(problem, eqx.is_array)

    def points(a):
        p = eqx.combine(a, static)
        return monitor_points_world(p.body, p.feet), desired_balance_point(p)

    flat = jax.tree.map(lambda x: x.reshape((-1,) + x.shape[len(batch):]), arrays)
    mon, goal = (np.asarray(x, np.float64) for x in jax.vmap(points)(flat))
    out = [inside_polygon_margin(support_polygon(m[..., [0, 2]]), g) for m, g in zip(mon, goal, strict=True)]
    return np.asarray(out).reshape(batch)


def build_pose(
    problem: StanceProblem, amplitudes: Float[Array, "6"], balance_xz: Float[Array, "2"]
) -> tuple[StancePose, PoseInfo]:
    """The pose for given torso amplitudes and dominant-ankle balance offsets (sec. 5).

    Lower body by the analytic IK (`ik`), spine and collars from the shape classes
    (`torso`), arms by the analytic arm IK or elbow angle and arm-out without a target
    (`arms`), head by gaze (`gaze`).

    Returns:
        `(pose, info)`.
    """
    root, local, info = build_rotations(problem, amplitudes, balance_xz)
    return StancePose(root, rotations.quat_from_matrix(local)), info


def desired_balance_point(problem: StanceProblem) -> Float[Array, "2"]:
    """The (X, Z) point where the COM must project (`balance.balance_point`)."""
    s = problem.shape
    return balance_point(problem.body, problem.feet, s[P["weight_shift"]], s[P["forward_shift"]])


class BalancedBuild(eqx.Module):
    """A pose built with its balance solved (`balanced_rotations`), on rotation matrices.

    - `balance_xz`: `[2]` dominant-ankle X/Z offsets (rad).
    - `root_position`: `[3]`; `local`: `[J, 3, 3]` local rotations; `info`: `PoseInfo`.
    """

    balance_xz: Float[Array, "2"]
    root_position: Float[Array, "3"]
    local: Float[Array, "joints 3 3"]
    info: PoseInfo

    def pose(self) -> StancePose:
        """The `StancePose` (quaternions)."""
        return StancePose(self.root_position, rotations.quat_from_matrix(self.local))


def _build_with_residual(problem: StanceProblem, amplitudes, balance_xz):
    """`(com_xz - goal, (root, local, info))` for given amplitudes and balance offsets.

    The builder is traced with jit disabled: most `jax.numpy` functions (the array operators
    included) are small jitted functions, and inside the solver's loop each one would be traced,
    differentiated and batched as a nested program before being inlined. Traced as bare
    primitives the program is the same (identical optimised HLO) and its trace ~15% shorter
    (stance benchmark: 0.98 -> 0.83 s of the single solve's first call). The builder holds no
    `lax` loop, which disabled jit would unroll (guarded by a test in tests/test_stance_ik.py).
    """
    with jax.disable_jit():
        root, local, info = build_rotations(problem, amplitudes, balance_xz)
    r = jnp.stack([info.com[0], info.com[2]]) - desired_balance_point(problem)
    return r, (root, local, info)


def _build_output_like(dtype):
    """Zeros shaped like `_build_with_residual`'s output (saves tracing the builder for it)."""
    def z(*shape):
        return jnp.zeros(shape, dtype)

    info = PoseInfo(com=z(3), shoulders=z(2, 3), wrists=z(2, 3), reach_gaps=z(2), free_foot_gap=z())
    return z(2), (z(3), z(len(JOINT_NAMES), 3, 3), info)


#: Most Newton evaluations of the balance solve (`balance.newton_2d_with_tangents`, which
#: stops earlier at float32 round-off).
BALANCE_EVALUATIONS = 12


def balanced_rotations_with_tangents(
    problem: StanceProblem, amplitudes: Float[Array, "6"], directions: Float[Array, "m 6"]
) -> tuple[BalancedBuild, BalancedBuild]:
    """`balanced_rotations` and its derivatives along `m` directions in the amplitudes.

    One traced copy of the pose builder serves the balance solve and the derivatives (see
    `balance.newton_2d_with_tangents`): the solver's objective gets its gradient from this
    in forward mode with `directions` = the 6x6 identity. The tangents follow the implicit
    function theorem: along a direction da the balance offsets move by db = -J_b^-1 dr and
    the pose by its partial derivative plus J_pose,b db.

    Returns:
        `(built, d_built)`: `d_built` has a leading `m` axis on every leaf.
    """
    m = directions.shape[0]
    b0 = jnp.zeros(2, amplitudes.dtype)
    b, (_, out), (dr, dout) = newton_2d_with_tangents(
        lambda a, x: _build_with_residual(problem, a, x),
        amplitudes, b0, directions, BALANCE_EVALUATIONS,
        out_like=_build_output_like(amplitudes.dtype),
    )
    db = -matmul(inverse_2x2(dr[m:].T), dr[:m].T).T  # [m, 2]
    dout = jax.tree.map(lambda t: t[:m] + jnp.tensordot(db, t[m:], axes=1, precision=PRECISION), dout)
    return BalancedBuild(b, *out), BalancedBuild(db, *dout)


def _zero_tangent(tree):
    def zero(x):
        x = jnp.asarray(x)
        if jnp.issubdtype(x.dtype, jnp.inexact):
            return jnp.zeros_like(x)
        return np.zeros(x.shape, jax.dtypes.float0)

    return jax.tree.map(zero, tree)


@jax.custom_jvp
def balanced_rotations(problem: StanceProblem, amplitudes: Float[Array, "6"]) -> BalancedBuild:
    """The pose (`build_rotations`) with the balance offsets solved (sec. 4).

    For a static pose the paper searches for the dominant-ankle offsets; we solve
    `com_xz(offsets) = goal` by Newton's method from zero offsets, with the exact 2x2
    Jacobian from forward-mode derivatives (`balance.newton_2d_with_tangents`). Derivatives
    come from the implicit function theorem in a custom JVP: one linearisation of the pose
    at the solution gives both the exact 2x2 Jacobian J_b of the residual in the offsets
    and the tangents of the pose, d offsets = -J_b^-1 dr, so no derivative runs through the
    iterations. Reverse mode and higher orders work.
    """
    none = jnp.zeros((0, NUM_AMPLITUDES), amplitudes.dtype)
    return balanced_rotations_with_tangents(problem, amplitudes, none)[0]


@balanced_rotations.defjvp
def _balanced_rotations_jvp(primals, tangents):
    problem, amplitudes = primals
    dp, da = tangents
    # Through the custom JVP itself, so that a second derivative (the implicit adjoint of
    # the solver) uses this rule again instead of differentiating Newton's iterations.
    b = balanced_rotations(problem, amplitudes).balance_xz
    (_, out), lin = jax.linearize(_build_with_residual, problem, amplitudes, b)
    zp, za = _zero_tangent(problem), _zero_tangent(amplitudes)
    dr_b, dout_b = jax.vmap(lambda e: lin(zp, za, e))(jnp.eye(2, dtype=b.dtype))
    dr, dout = lin(dp, da, jnp.zeros_like(b))
    db = -matmul(inverse_2x2(dr_b.T), dr)
    dout = jax.tree.map(lambda t, tb: t + jnp.tensordot(db, tb, axes=1, precision=PRECISION), dout, dout_b)
    return BalancedBuild(b, *out), BalancedBuild(db, *dout)


def balance_offsets(problem: StanceProblem, amplitudes: Float[Array, "6"]) -> Float[Array, "2"]:
    """Dominant-ankle X/Z offsets (rad) that put the COM projection on the desired point."""
    return balanced_rotations(problem, amplitudes).balance_xz


def balanced_pose(
    problem: StanceProblem, amplitudes: Float[Array, "6"]
) -> tuple[StancePose, PoseInfo, Float[Array, "2"]]:
    """`build_pose` with the balance offsets solved (`balanced_rotations`).

    Returns:
        `(pose, info, balance_xz)`.
    """
    built = balanced_rotations(problem, amplitudes)
    return built.pose(), built.info, built.balance_xz
