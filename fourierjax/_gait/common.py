"""Argument checks and pose helpers shared by the gait modules."""

from __future__ import annotations

from typing import TYPE_CHECKING

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, ArrayLike, Float

from fourierjax._checks import concrete
from fourierjax._jit import filter_jit
from fourierjax._saved import saved
from fourierjax.errors import UserError
from fourierjax.skeleton import common_ancestor

if TYPE_CHECKING:
    from fourierjax.body import BodyMap
    from fourierjax.contacts import FootPoints
    from fourierjax.fourier import FourierModel
    from fourierjax.skeleton import Skeleton

RULES = ("unuma1995", "continuous", "smooth")
#: The CMU groin names, the old default of a bare topology (now its names' body map): deprecated.
_CMU_GROINS = ("LeftUpLeg", "RightUpLeg")


def deprecated_cmu_groins(module: str) -> tuple[str, str]:
    """`CMU_GROINS`, with its DeprecationWarning (for the module `__getattr__`s)."""
    import warnings

    warnings.warn(f"{module}.CMU_GROINS is deprecated: groins come from the body map "
                  "(`groin_joints(topology)` reads the names of any rig, `body_map.groins`); it will be "
                  "removed in the next release", DeprecationWarning, stacklevel=3)
    return _CMU_GROINS


def __getattr__(name: str):
    if name == "CMU_GROINS":
        return deprecated_cmu_groins(__name__)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


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


def groin_joints(
    topology, names: tuple[str, str] | None = None, *, body_map: BodyMap | None = None
) -> tuple[int, int]:
    """Indices of the left and right groin (hip) joints, from the body map.

    Arguments:
        topology: a `Topology`, or a `Motion` (then its body map is inferred,
            `body.infer_body_map`).
        names: `(left, right)` joint names; given, they win.
        body_map: a `body.BodyMap`; its `groins` win over the defaults.

    Returns:
        `(left, right)` joint indices. With neither `names` nor `body_map`: the map of a
        `Motion`, or of a bare topology's joint names (`body.body_map_from_names`: CMU, Mixamo,
        Daz, 3ds Max, Bandai, SMPL and LAFAN names). Raises `UserError` naming the skeleton's
        joints when a name is missing or names do not decide the legs.
    """
    if names is None and body_map is not None:
        return tuple(int(g) for g in body_map.groins)
    if names is None and hasattr(topology, "channels") and hasattr(topology, "topology"):
        from fourierjax.body import infer_body_map

        return tuple(int(g) for g in infer_body_map(topology).groins)
    topology = getattr(topology, "topology", topology)
    joints = tuple(topology.names)
    if names is None:
        from fourierjax.body import BodyMapError, body_map_from_names

        try:
            if not hasattr(topology, "parents"):
                raise BodyMapError("no parents")
            return tuple(int(g) for g in body_map_from_names(topology).groins)
        except BodyMapError:
            raise UserError(
                f"groin_joints: the joint names of this skeleton do not decide its legs (no left and right "
                f"hip, knee and ankle named as a known rig names them, e.g. CMU's LeftUpLeg / RightUpLeg, "
                f"LeftLeg / RightLeg, LeftFoot / RightFoot); its joints are {list(joints)}. Pass the clip "
                "itself, body_map=fourierjax.body.infer_body_map(motion) or names=(left, right)"
            ) from None
    missing = [n for n in names if n not in joints]
    if missing:
        raise UserError(
            f"groin_joints: the skeleton has no joint(s) {missing}; its joints are {list(joints)}."
            " Pass names=(left, right) that it has, or body_map="
        )
    return joints.index(names[0]), joints.index(names[1])


def feet_of(body_map: BodyMap) -> FootPoints:
    """The `contacts.FootPoints` of a body map (ankle first, toe tip last)."""
    from fourierjax.contacts import FootPoints

    return FootPoints(tuple(body_map.left.foot_points), tuple(body_map.right.foot_points),
                      (tuple(body_map.left.foot_point_names), tuple(body_map.right.foot_point_names)))


@saved
@filter_jit
def _cycle_fk(model, skeleton, num_samples):
    from fourierjax.fourier import synthesize_phase
    from fourierjax.kinematics import forward_kinematics
    from fourierjax.motion import local_pose_from_features

    grid = jnp.linspace(0.0, 2 * jnp.pi, num_samples, endpoint=False, dtype=model.offset.dtype)
    def pose(f):
        return forward_kinematics(skeleton, *local_pose_from_features(skeleton, f, model.representation))

    return jax.vmap(pose)(synthesize_phase(model, grid))


def model_body_map(model: FourierModel, skeleton: Skeleton, num_samples: int = 64, *, overrides=None) -> BodyMap:
    """The body map of a model's own cycle (`num_samples` poses, root at the origin).

    Nothing travels in these poses, so the trajectory joint is the pelvis (or its nearest
    ancestor with position channels), never a joint that sways about the origin.

    `overrides` (a dict, TOML text or path; `body.infer_body_map`) set fields by joint name.

    A model file's template is the rest pose, which on rigs with joint orients (Bandai: bones
    along local X) lies along another axis than the body stands: the model's poses show how it
    stands. Needs a concrete model (NumPy inference); under a transformation pass `body_map=`.
    """
    from fourierjax.body import infer_body_map_from_positions

    if isinstance(model.offset, jax.core.Tracer):
        raise UserError("the body map is inferred from a concrete model: under jit, vmap or grad pass "
                        "`body_map=` (or `feet=` and `groins=`)")
    model = jax.tree_util.tree_map(jnp.asarray, model)  # NumPy float64 leaves as JAX holds them
    fk = _cycle_fk(model, skeleton, num_samples)
    return infer_body_map_from_positions(skeleton.topology, np.asarray(fk.positions, np.float64),
                                         np.asarray(fk.end_site_positions, np.float64),
                                         np.asarray(fk.rotations, np.float64), overrides=overrides,
                                         moving=())  # the root sits at the origin: nothing travels


def resolve_body(
    where: str, model: FourierModel, skeleton: Skeleton, feet: FootPoints | None,
    groins: tuple[int, int] | None, body_map: BodyMap | None, up_axis: int | None,
) -> tuple[FootPoints, tuple[int, int], int, int]:
    """`(feet, groins, pelvis, up_axis)` of a synthesis: given arguments win, then `body_map`,
    then the map of the model's own cycle (`model_body_map`); up is Y (1) without a map."""
    if body_map is None and (feet is None or groins is None):
        body_map = model_body_map(model, skeleton)
    if body_map is not None and tuple(body_map.joint_names) != tuple(skeleton.topology.names):
        raise UserError(f"{where}: `body_map` was made for another skeleton (joints "
                        f"{list(body_map.joint_names)[:4]}..., the model's are {list(skeleton.topology.names)[:4]}...)")
    if feet is None:
        feet = feet_of(body_map)
    if groins is None:
        groins = body_map.groins
    if up_axis is None:
        up_axis = 1 if body_map is None else int(body_map.up_axis)
    if up_axis not in (0, 1, 2):
        raise UserError(f"{where}: `up_axis` must be 0, 1 or 2, got {up_axis!r}")
    groins = check_indices(where, skeleton, feet, groins)
    if body_map is not None and tuple(sorted(groins)) == tuple(sorted(body_map.groins)):
        pelvis = int(body_map.pelvis)
    else:
        pelvis = common_ancestor(tuple(skeleton.topology.parents), *groins)
    if pelvis < 0:
        raise UserError(f"{where}: the groins {groins} have no common ancestor (pelvis) in the skeleton")
    return feet, groins, pelvis, up_axis


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
    skeleton: Skeleton, representation: str, idx: Array, joints: tuple[int, ...], feat: Float[Array, " C"],
    pelvis: int = 0,
) -> tuple[Float[Array, "2 P 3"], Float[Array, "K 3"]]:
    """Foot points `[2, P, 3]` and `joints` `[K, 3]` (the groins, then e.g. the pelvis) of one
    feature frame, the pelvis (the joint whose world pose the root features are) at the origin."""
    from fourierjax.features import local_pose_from_features
    from fourierjax.kinematics import forward_kinematics

    fk = forward_kinematics(skeleton, *local_pose_from_features(skeleton, feat, representation, pelvis))
    allp = jnp.concatenate([fk.positions, fk.end_site_positions], axis=0)
    return allp[idx], fk.positions[jnp.asarray(joints)]
