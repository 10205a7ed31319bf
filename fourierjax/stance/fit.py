"""Fit torso shape classes and amplitudes to a target pose by least squares (Neff & Fiume sec. 5.2)."""

import itertools

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import optimistix as optx
from jaxtyping import Array, Float

from fourierjax._jit import filter_jit
from fourierjax.errors import UserError
from fourierjax.stance import _util as u
from fourierjax.stance.skeleton48 import SHOULDER, Body
from fourierjax.stance.torso import COLLAR_STATES, SHAPE_CLASSES, class_weights, collar_quats, spine_quats

#: Segments compared: abdomen, chest, neck, head (their +Y), right and left collar bones.
SEGMENTS = ("abdomen", "chest", "neck", "head", "r_collar", "l_collar")
#: Every (sagittal class, coronal class, collar Y state, collar Z state) combination.
COMBINATIONS = tuple(itertools.product(SHAPE_CLASSES, SHAPE_CLASSES, tuple(COLLAR_STATES),
                                       tuple(COLLAR_STATES)))  # fmt: skip
_EY = jnp.array([0.0, 1.0, 0.0])


def torso_directions(body: Body, amplitudes, sagittal_weights, coronal_weights, collar_signs):
    """Unit directions `[6, 3]` of the `SEGMENTS` in the pelvis frame for torso amplitudes
    (sagittal, coronal, transverse, collar_y, collar_z, abdomen_x; the solver's order)."""
    a = amplitudes
    spine = spine_quats(a[0], a[1], a[2], a[5], sagittal_weights, coronal_weights)
    R = [spine[0]]
    for k in range(1, 4):
        R.append(u.mm(R[-1], spine[k]))
    collars = collar_quats(a[3], a[4], collar_signs)
    dirs = [u.mv(r, _EY) for r in R]
    for k in range(2):
        off = body.offsets[SHOULDER[k]]
        dirs.append(u.mv(u.mm(R[1], collars[k]), off / u.safe_norm(off)))
    return jnp.stack(dirs)


def _combo_arrays():
    sag = jnp.stack([class_weights("sagittal", c[0]) for c in COMBINATIONS])
    cor = jnp.stack([class_weights("coronal", c[1]) for c in COMBINATIONS])
    sig = jnp.array([[COLLAR_STATES[c[2]], COLLAR_STATES[c[3]]] for c in COMBINATIONS])
    return sag, cor, sig


class TorsoFit(eqx.Module):
    """Result of `fit_torso`: the best combination and the residual of every one."""

    amplitudes: Float[Array, "6"]  # sagittal, coronal, transverse, collar_y, collar_z, abdomen_x
    best: int
    residuals: Float[Array, " combos"]

    def describe(self) -> dict:
        c = COMBINATIONS[int(self.best)]
        names = ("sagittal", "coronal", "transverse", "collar_y", "collar_z", "abdomen_x")
        return {
            "sagittal_class": c[0], "coronal_class": c[1], "collar_y": c[2], "collar_z": c[3],
            "amplitudes": dict(zip(names, np.asarray(self.amplitudes).tolist())),
            "rms_direction_error": float(self.residuals[int(self.best)]),
        }  # fmt: skip


def fit_torso(body: Body, target_dirs: Float[Array, "6 3"]) -> TorsoFit:
    """Which spine classes, collar states and amplitudes explain a target torso best.

    For every combination in `COMBINATIONS` the six torso amplitudes are fitted by
    Levenberg-Marquardt to the target segment directions (pelvis frame, `SEGMENTS` order);
    the combinations run one after another (`lax.map`, no batched LAPACK; STYLE.md).

    Arguments:
        body: the character.
        target_dirs: `[6, 3]` unit directions of the segments in the pelvis frame.

    Returns:
        `TorsoFit` (`describe()` names the winning classes).

    Raises:
        UserError: `target_dirs` is not `[6, 3]` numbers or (when its values are known, i.e.
            not traced) holds NaN, infinity or directions that are not unit vectors.
    """
    dirs = target_dirs
    if not isinstance(dirs, jax.Array):  # checked as numpy: under an outer jit jnp would trace it
        try:
            dirs = np.asarray(dirs, np.float64)
        except (TypeError, ValueError) as err:
            raise UserError(f"fit_torso: target_dirs must be numbers, got {target_dirs!r} ({err})") from None
    if dirs.shape != (len(SEGMENTS), 3):
        raise UserError(f"fit_torso: target_dirs must have shape ({len(SEGMENTS)}, 3), one direction "
                        f"per segment {SEGMENTS}, got shape {dirs.shape}")  # fmt: skip
    if not isinstance(dirs, jax.core.Tracer):
        d = np.asarray(dirs, np.float64)
        bad = [SEGMENTS[k] for k in range(len(SEGMENTS)) if not np.isfinite(d[k]).all()]
        if bad:
            raise UserError(f"fit_torso: target_dirs holds NaN or infinite values for {bad}")
        norms = np.linalg.norm(d, axis=-1)
        bad = [f"{SEGMENTS[k]} ({norms[k]:.4g})" for k in range(len(SEGMENTS)) if abs(norms[k] - 1.0) > 1e-3]
        if bad:
            raise UserError(f"fit_torso: target_dirs must be unit directions; normalise them. Not "
                            f"unit: {', '.join(bad)}")  # fmt: skip
    dirs = jnp.asarray(dirs)
    if not jnp.issubdtype(dirs.dtype, jnp.floating):
        dirs = dirs.astype(float)
    return _fit_torso(body, dirs)


@filter_jit
def _fit_torso(body: Body, target_dirs: Float[Array, "6 3"]) -> TorsoFit:
    """`fit_torso` on checked input."""
    sag, cor, sig = _combo_arrays()

    def residual(y, args):
        s, c, g = args
        d = torso_directions(body, y, s, c, g)
        return (d - target_dirs).reshape(-1)

    def one(args):
        sol = optx.least_squares(
            residual, optx.LevenbergMarquardt(rtol=1e-8, atol=1e-8), jnp.zeros(6), args,
            max_steps=200, throw=False,
        )  # fmt: skip
        r = residual(sol.value, args)
        return sol.value, jnp.sqrt(jnp.mean(r * r))

    ys, res = jax.lax.map(one, (sag, cor, sig))
    # Prefer the simplest explanation among near-ties (straight classes come last in the
    # table, so break ties toward fewer nonzero amplitudes via a tiny penalty).
    best = jnp.argmin(res + 1e-6 * jnp.sum(jnp.abs(ys), axis=-1))
    return TorsoFit(amplitudes=ys[best], best=best, residuals=res)


def target_directions_from_positions(positions: dict[str, np.ndarray]) -> np.ndarray:
    """Segment directions `[6, 3]` in the pelvis frame from world joint positions.

    `positions` maps: "r_hip", "l_hip", "abdomen", "chest", "neck", "head", "head_top",
    "r_collar", "r_shoulder", "l_collar", "l_shoulder" to `[3]` points. The pelvis frame:
    X from the right to the left hip, Y the part of pelvis->chest perpendicular to it.
    """
    p = {k: np.asarray(v, np.float64) for k, v in positions.items()}
    ex = p["l_hip"] - p["r_hip"]
    ex /= np.linalg.norm(ex)
    up = p["chest"] - 0.5 * (p["l_hip"] + p["r_hip"])
    ey = up - (up @ ex) * ex
    ey /= np.linalg.norm(ey)
    R = np.stack([ex, ey, np.cross(ex, ey)], axis=1)
    segs = [("abdomen", "chest"), ("chest", "neck"), ("neck", "head"), ("head", "head_top"),
            ("r_collar", "r_shoulder"), ("l_collar", "l_shoulder")]  # fmt: skip
    out = []
    for a, b in segs:
        d = R.T @ (p[b] - p[a])
        out.append(d / np.linalg.norm(d))
    return np.stack(out)


def torso_points(body_map, topology) -> dict[str, tuple[int, ...]]:
    """The joints of a real skeleton that stand for `target_directions_from_positions`' points.

    From the body map: hips, the first two spine joints (abdomen, chest; one joint serves both
    when the spine has one), the neck, the joint between neck and head (or their midpoint),
    the head, and each arm's collar (or the shoulder's parent) and shoulder. A point given as
    several joints is their mean. On CMU rigs: LeftUpLeg, LowerBack, Spine, Neck, Neck1, Head,
    Left/RightShoulder, Left/RightArm.

    Raises:
        UserError: the map has no spine, neck or head, or no arms.
    """
    if not body_map.spine or body_map.neck < 0 or body_map.head < 0:
        raise UserError("stance fit: the body map has no spine, neck or head; give them in a body map file")
    if body_map.left_arm is None or body_map.right_arm is None:
        raise UserError("stance fit: the body map has no arms; give them in a body map file")
    parents = topology.parents
    spine = body_map.spine
    between, j = [], parents[body_map.head]
    while j >= 0 and j != body_map.neck:
        between.append(j)
        j = parents[j]
    head = (between[-1],) if between and j == body_map.neck else (body_map.neck, body_map.head)

    def collar(arm):
        return arm.collar if arm.collar >= 0 else parents[arm.shoulder]

    return {
        "r_hip": (body_map.right.hip,), "l_hip": (body_map.left.hip,), "abdomen": (spine[0],),
        "chest": (spine[1] if len(spine) > 1 else spine[0],), "neck": (body_map.neck,), "head": head,
        "head_top": (body_map.head,), "r_collar": (collar(body_map.right_arm),),
        "r_shoulder": (body_map.right_arm.shoulder,), "l_collar": (collar(body_map.left_arm),),
        "l_shoulder": (body_map.left_arm.shoulder,),
    }  # fmt: skip


def cmu_torso_directions(body: Body, motion, frame: int, rest_frame: int = 0, *, body_map=None) -> np.ndarray:
    """Target directions for `fit_torso` from a clip frame of any rig (joint-direction mapping).

    Each segment's rotation away from the clip's rest frame (the smallest rotation taking
    its rest direction to its direction at `frame`, in the pelvis frame) is applied to our
    skeleton's rest direction of the same segment: abdomen = first -> second spine joint,
    chest = second spine joint -> neck, neck = neck -> the joint below the head, head = that
    joint -> head, collars -> shoulders (`torso_points`; on CMU: LowerBack->Spine,
    Spine->Neck, Neck->Neck1, Neck1->Head, Left/RightShoulder->Left/RightArm). So differences
    of skeleton proportions and rest curvature do not bias the fit.

    Arguments:
        body: our `Body`; motion: a `Motion`; frame, rest_frame: frame indices.
        body_map: the clip's `body.BodyMap`; default `body.infer_body_map(motion)`.

    Returns:
        `[6, 3]` target directions.
    """
    import jax.numpy as jnp

    from fourierjax.kinematics import fk_from_channels

    sk = motion.skeleton()
    if body_map is None:
        from fourierjax.body import infer_body_map

        body_map = infer_body_map(motion)
    points = torso_points(body_map, motion.topology)

    def frame_dirs(f):
        pos = np.asarray(fk_from_channels(sk, jnp.asarray(motion.channels[f])).positions)
        return target_directions_from_positions({k: pos[list(js)].mean(0) for k, js in points.items()})

    d0, d1 = frame_dirs(rest_frame), frame_dirs(frame)
    # Our rest directions: the spine straight up, the collars along their bones.
    ours = np.asarray(torso_directions(body, jnp.zeros(6), jnp.zeros(4), jnp.zeros(4),
                                       jnp.ones(2)), np.float64)  # fmt: skip
    out = []
    for a, b, o in zip(d0, d1, ours):
        v = np.cross(a, b)
        s, c = np.linalg.norm(v), a @ b
        if s < 1e-12:
            out.append(o)
            continue
        k = v / s
        ang = np.arctan2(s, c)
        o_rot = o * np.cos(ang) + np.cross(k, o) * np.sin(ang) + k * (k @ o) * (1 - np.cos(ang))
        out.append(o_rot)
    return np.stack(out)

