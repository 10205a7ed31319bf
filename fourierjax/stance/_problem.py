"""A stance problem: the shape vector, states and constraints of one pose (sec. 5), checked."""

import functools

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Bool, Float

from fourierjax import rotations
from fourierjax.errors import UserError
from fourierjax.stance import _util as u
from fourierjax.stance.balance import balance_point, inside_polygon_margin, monitor_points_world, support_polygon
from fourierjax.stance.ik import Feet, make_feet, pelvis_frame_desired
from fourierjax.stance.penalties import HermitePenalty, check_penalty, quadratic_penalty, reach_penalty
from fourierjax.stance.skeleton48 import ELBOW, LEFT, RIGHT, WRIST, Body
from fourierjax.stance.torso import class_weights, collar_sign

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


def substitute_invalid(problem: StanceProblem) -> tuple[StanceProblem, Bool[Array, ""]]:
    """`(problem, invalid)`: `make_problem`'s value checks, which its traced path cannot make,
    as a flag for the solvers' `result`.

    Invalid: a knee or elbow bend outside [`BEND_MIN_RAD`, `BEND_MAX_RAD`], a NaN or infinity
    in any array, foot quaternions that are not unit, `amplitude_scale <= 0` or
    `reach_weight < 0` (crossed feet are only refused when concrete). Where invalid, the
    shape vector becomes the neutral one (zeros) and the targets and gaze point their finite
    parts (NaN and infinity become 0), so that a bad shape vector or target (a 722-degree knee
    bend gave an all-NaN gradient with converged=True) solves to a finite pose with zero
    derivatives. Not replaced (a whole neutral problem made the first call seconds slower):
    NaN in the body or the feet still gives NaN values, flagged.

    Arguments:
        problem: one `StanceProblem` (no batch axis).

    Returns:
        `(problem', invalid)`: `problem'` is `problem` where `invalid` is False.
    """
    s = problem.shape
    bends = jnp.stack([s[P[name]] for name, _ in _BENDS])
    checks = [
        jnp.all((bends >= BEND_MIN_RAD - 1e-6) & (bends <= BEND_MAX_RAD + 1e-6)),
        jnp.all(jnp.abs(jnp.sum(problem.feet.quats**2, axis=-1) - 1.0) <= 2e-3),
        jnp.all(problem.amplitude_penalty.widths > 0.0),
        jnp.all(problem.reach_weights >= 0.0),
    ]
    checks += [jnp.all(jnp.isfinite(x)) for x in jax.tree.leaves(eqx.filter(problem, eqx.is_inexact_array))]
    invalid = ~functools.reduce(jnp.logical_and, checks)
    keep = ~invalid
    problem = eqx.tree_at(
        lambda p: (p.shape, p.targets, p.gaze_point),
        problem,
        (
            u.where(invalid, 0.0, s),
            u.where(jnp.isfinite(problem.targets) & keep, problem.targets, 0.0),
            u.where(jnp.isfinite(problem.gaze_point) & keep, problem.gaze_point, 0.0),
        ),
    )
    return problem, invalid

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


def arm_lengths(body: Body) -> Float[Array, "2"]:
    """Shoulder-to-wrist length of the right and left arm (m)."""
    off = body.offsets
    return jnp.stack(
        [u.safe_norm(off[ELBOW[s]]) + u.safe_norm(off[WRIST[s]]) for s in (RIGHT, LEFT)]
    )



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


def desired_balance_point(problem: StanceProblem) -> Float[Array, "2"]:
    """The (X, Z) point where the COM must project (`balance.balance_point`)."""
    s = problem.shape
    return balance_point(problem.body, problem.feet, s[P["weight_shift"]], s[P["forward_shift"]])
