"""The 48-DOF stance skeleton (Neff & Fiume 2004, sec. 3): topology, de Leva proportions, COM."""


import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float

from fourierjax import rotations
from fourierjax._host import as_default_float
from fourierjax._jit import filter_jit
from fourierjax.errors import UserError
from fourierjax.kinematics import FKResult, forward_kinematics
from fourierjax.skeleton import Skeleton, Topology

# --------------------------------------------------------------------------------- topology
#
# Y up, Z forward, right-handed, metres. The character faces +Z, so its LEFT side is +X and
# its right hand hangs on the -X side. Every joint frame is aligned with the world at rest
# (BVH convention), the rest pose is standing with the arms hanging at the sides.
#
# Rotation order of every joint: BVH "ZXY" (R = Rz @ Rx @ Ry). X is the sagittal axis
# (positive X bends the spine forward, flexes the knee, tips a hanging segment's end
# backward), Z the coronal axis (positive Z tips the spine toward the character's right),
# Y the transverse (twist) axis.
#
# The paper's Fig. 3 is missing from the text; only "6 root + 42 rotational" survives. Our
# choice (documented in DOFS below):
#   root (pelvis)      6  (position X Y Z, rotation Z X Y)
#   abdomen, chest     3 + 3   sagittal/coronal shape classes act on X/Z, transverse on Y
#   neck, head         3 + 3   the shape tables have NeckX/Z and HeadX/Z; gaze needs Y
#   collars            2 x 2   Y and Z only (the paper: "collar bones consist of Y and Z
#                               rotations")
#   shoulders          3 x 2   ball joints
#   elbows             2 x 2   flexion X + forearm twist Y (pronation lives here, not in
#                               the wrist, anatomically at the radio-ulnar joints)
#   wrists             2 x 2   X (flexion) and Z (radial/ulnar deviation)
#   hips               3 x 2   "the 3-DOF hips" of the lower-body IK appendix
#   knees              1 x 2   hinge (X)
#   ankles             2 x 2   X and Z: balance "is fed back into the Z and X axes of the
#                               ankle", and with a 2-DOF ankle the appendix's IK is exactly
#                               determined (hip 3 + knee 1 + ankle 2 = 6 = a planted foot).
#   total              6 + 12 + 4 + 6 + 4 + 4 + 6 + 2 + 4 = 48
#
# In BVH files every joint still gets three rotation channels (Z X Y) so that every importer
# reads them; the channels that are not DOFs stay at zero.

JOINT_NAMES: tuple[str, ...] = (
    "pelvis", "abdomen", "chest", "neck", "head",
    "r_collar", "r_shoulder", "r_elbow", "r_wrist",
    "l_collar", "l_shoulder", "l_elbow", "l_wrist",
    "r_hip", "r_knee", "r_ankle",
    "l_hip", "l_knee", "l_ankle",
)  # fmt: skip
PARENTS: tuple[int, ...] = (-1, 0, 1, 2, 3, 2, 5, 6, 7, 2, 9, 10, 11, 0, 13, 14, 0, 16, 17)
END_SITE_NAMES: tuple[str, ...] = ("head_top", "r_hand", "l_hand", "r_toe", "l_toe")
END_SITE_PARENTS: tuple[int, ...] = (4, 8, 12, 15, 18)

ROTATION_ORDER = "ZXY"

#: Rotational DOFs of each joint, as axis letters (the root's 3 translations come on top).
DOFS: dict[str, str] = {
    "pelvis": "ZXY",
    "abdomen": "ZXY", "chest": "ZXY", "neck": "ZXY", "head": "ZXY",
    "r_collar": "ZY", "l_collar": "ZY",
    "r_shoulder": "ZXY", "l_shoulder": "ZXY",
    "r_elbow": "XY", "l_elbow": "XY",
    "r_wrist": "ZX", "l_wrist": "ZX",
    "r_hip": "ZXY", "l_hip": "ZXY",
    "r_knee": "X", "l_knee": "X",
    "r_ankle": "ZX", "l_ankle": "ZX",
}  # fmt: skip

#: Names of the 48 DOFs in the order of `dof_vector`.
DOF_NAMES: tuple[str, ...] = ("pelvis.Xposition", "pelvis.Yposition", "pelvis.Zposition") + tuple(
    f"{j}.{a}rotation" for j in JOINT_NAMES for a in DOFS[j]
)
assert len(DOF_NAMES) == 48

J = {name: i for i, name in enumerate(JOINT_NAMES)}
RIGHT, LEFT = 0, 1
HIP = (J["r_hip"], J["l_hip"])
KNEE = (J["r_knee"], J["l_knee"])
ANKLE = (J["r_ankle"], J["l_ankle"])
SHOULDER = (J["r_shoulder"], J["l_shoulder"])
ELBOW = (J["r_elbow"], J["l_elbow"])
WRIST = (J["r_wrist"], J["l_wrist"])
COLLAR = (J["r_collar"], J["l_collar"])
SPINE = (J["abdomen"], J["chest"], J["neck"], J["head"])

TOPOLOGY = Topology(
    names=JOINT_NAMES,
    parents=PARENTS,
    channels=tuple(
        (("Xposition", "Yposition", "Zposition") if p < 0 else ())
        + ("Zrotation", "Xrotation", "Yrotation")
        for p in PARENTS
    ),
    end_site_parents=END_SITE_PARENTS,
)

# ---------------------------------------------------------------------------- anthropometry
#
# de Leva, P. (1996), J. Biomech. 29(9) 1223-1230, Table 4, male column: segment lengths (mm,
# for the mean stature 1741 mm), mass (% body mass) and centre of mass (% of the length from
# the proximal end). The trunk uses the paper's three sub-segments (upper: cervicale->
# xiphoid, middle: xiphoid->omphalion, lower: omphalion->mid-hip), which map onto our chest,
# abdomen and pelvis links. Values not in de Leva (hip-joint spread, shoulder breadth, ankle
# height, foot width) are typical adult values, scaled with the height like everything else.
DE_LEVA_STATURE_M = 1.741
_L = {  # metres at the de Leva stature
    "head_neck": 0.2033,  # cervicale -> vertex
    "upper_trunk": 0.2421,
    "middle_trunk": 0.2155,
    "lower_trunk": 0.1457,
    "upper_arm": 0.2817,
    "forearm": 0.2689,
    "hand": 0.0862,  # wrist -> 3rd metacarpale
    "thigh": 0.4222,
    "shank": 0.4340,
    "foot": 0.2581,  # heel -> toe tip
}
_MASS = {  # fraction of body mass
    "head_neck": 0.0694, "upper_trunk": 0.1596, "middle_trunk": 0.1633, "lower_trunk": 0.1117,
    "upper_arm": 0.0271, "forearm": 0.0162, "hand": 0.0061,
    "thigh": 0.1416, "shank": 0.0433, "foot": 0.0137,
}  # fmt: skip
_COM = {  # from the proximal end (trunk sub-segments: from the upper end, as in de Leva)
    "head_neck": 0.5002,  # from the vertex
    "upper_trunk": 0.5066, "middle_trunk": 0.4502, "lower_trunk": 0.6115,
    "upper_arm": 0.5772, "forearm": 0.4574, "hand": 0.7900,
    "thigh": 0.4095, "shank": 0.4459, "foot": 0.4415,  # foot: from the heel
}  # fmt: skip
_HIP_HALF_SPREAD = 0.087  # hip joint centres are ~0.1 x stature apart
_ANKLE_HEIGHT = 0.068  # lateral malleolus above the floor
_NECK_FRACTION = 0.35  # head joint (atlas) sits this far up the cervicale->vertex segment
_HEEL_BEHIND_ANKLE = 0.25  # of the foot length
_FOOT_WIDTH = 0.10
_COLLAR_OFFSET = (0.02, 0.15, 0.03)  # sternoclavicular joint from the xiphoid joint (|x|)
_SHOULDER_FROM_COLLAR = (0.17, 0.0, -0.035)  # acromion from the sternoclavicular joint (|x|)


def _rest_geometry() -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Offsets, End Site offsets, segment masses, COM offsets and foot monitor points (1.741 m)."""
    hip_h = _ANKLE_HEIGHT + _L["shank"] + _L["thigh"]
    neck_len = _NECK_FRACTION * _L["head_neck"]
    toe_fwd = (1.0 - _HEEL_BEHIND_ANKLE) * _L["foot"]
    heel_back = _HEEL_BEHIND_ANKLE * _L["foot"]
    off = np.zeros((len(JOINT_NAMES), 3))
    off[J["pelvis"]] = (0.0, hip_h, 0.0)
    off[J["abdomen"]] = (0.0, _L["lower_trunk"], 0.0)
    off[J["chest"]] = (0.0, _L["middle_trunk"], 0.0)
    off[J["neck"]] = (0.0, _L["upper_trunk"], 0.0)
    off[J["head"]] = (0.0, neck_len, 0.0)
    for side, sx in (("r", -1.0), ("l", 1.0)):
        cx, cy, cz = _COLLAR_OFFSET
        off[J[f"{side}_collar"]] = (sx * cx, cy, cz)
        sx_, sy_, sz_ = _SHOULDER_FROM_COLLAR
        off[J[f"{side}_shoulder"]] = (sx * sx_, sy_, sz_)
        off[J[f"{side}_elbow"]] = (0.0, -_L["upper_arm"], 0.0)
        off[J[f"{side}_wrist"]] = (0.0, -_L["forearm"], 0.0)
        off[J[f"{side}_hip"]] = (sx * _HIP_HALF_SPREAD, 0.0, 0.0)
        off[J[f"{side}_knee"]] = (0.0, -_L["thigh"], 0.0)
        off[J[f"{side}_ankle"]] = (0.0, -_L["shank"], 0.0)
    ends = np.array(
        [
            (0.0, _L["head_neck"] - neck_len, 0.0),
            (0.0, -_L["hand"], 0.0),
            (0.0, -_L["hand"], 0.0),
            (0.0, -_ANKLE_HEIGHT, toe_fwd),
            (0.0, -_ANKLE_HEIGHT, toe_fwd),
        ]
    )
    mass = np.zeros(len(JOINT_NAMES))
    com = np.zeros((len(JOINT_NAMES), 3))
    # Each segment's mass hangs off the joint that moves it, at a fixed point of its frame.
    mass[J["pelvis"]] = _MASS["lower_trunk"]
    com[J["pelvis"]] = (0.0, (1.0 - _COM["lower_trunk"]) * _L["lower_trunk"], 0.0)
    mass[J["abdomen"]] = _MASS["middle_trunk"]
    com[J["abdomen"]] = (0.0, (1.0 - _COM["middle_trunk"]) * _L["middle_trunk"], 0.0)
    mass[J["chest"]] = _MASS["upper_trunk"]
    com[J["chest"]] = (0.0, (1.0 - _COM["upper_trunk"]) * _L["upper_trunk"], 0.0)
    mass[J["head"]] = _MASS["head_neck"]
    com[J["head"]] = (0.0, (1.0 - _COM["head_neck"]) * _L["head_neck"] - neck_len, 0.0)
    for side in ("r", "l"):
        for joint, seg in (("shoulder", "upper_arm"), ("elbow", "forearm"), ("wrist", "hand"),
                           ("hip", "thigh"), ("knee", "shank")):  # fmt: skip
            mass[J[f"{side}_{joint}"]] = _MASS[seg]
            com[J[f"{side}_{joint}"]] = (0.0, -_COM[seg] * _L[seg], 0.0)
        mass[J[f"{side}_ankle"]] = _MASS["foot"]
        com[J[f"{side}_ankle"]] = (0.0, -0.5 * _ANKLE_HEIGHT, _COM["foot"] * _L["foot"] - heel_back)
    # Foot monitor points (ankle frame): heel inner/outer, toe inner/outer, on the floor.
    # Index [side, point]; inner = toward the body's midline.
    mon = np.zeros((2, 4, 3))
    for s, sx in ((RIGHT, -1.0), (LEFT, 1.0)):
        hw = 0.5 * _FOOT_WIDTH
        mon[s] = [
            (-sx * 0.6 * hw, -_ANKLE_HEIGHT, -0.8 * heel_back),
            (sx * 0.6 * hw, -_ANKLE_HEIGHT, -0.8 * heel_back),
            (-sx * 0.9 * hw, -_ANKLE_HEIGHT, 0.85 * toe_fwd),
            (sx * 0.9 * hw, -_ANKLE_HEIGHT, 0.85 * toe_fwd),
        ]
    return off, ends, mass, com, mon


class Body(eqx.Module):
    """A 48-DOF character: skeleton geometry, segment masses and foot monitor points.

    All fields are arrays (batch characters with `jax.vmap`); build one with `make_body`.

    - `skeleton`: `fourierjax.skeleton.Skeleton` on `TOPOLOGY` (offsets in metres).
    - `mass_fractions`: `[J]` de Leva mass fraction of the segment each joint moves.
    - `com_offsets`: `[J, 3]` that segment's centre of mass in the joint's frame (m).
    - `monitor_points`: `[2, 4, 3]` heel/toe monitor points of the right and left foot in the
      ankle frame (m); the support polygon is their convex hull (Neff & Fiume, sec. 4).
    - `height_m`, `mass_kg`: scalars.
    """

    skeleton: Skeleton
    mass_fractions: Float[Array, " joints"]
    com_offsets: Float[Array, "joints 3"]
    monitor_points: Float[Array, "2 4 3"]
    height_m: Float[Array, ""]
    mass_kg: Float[Array, ""]

    @property
    def offsets(self) -> Float[Array, "joints 3"]:
        return self.skeleton.offsets


def make_body(height_m: float = 1.75, mass_kg: float = 75.0) -> Body:
    """The default character scaled to `height_m` (de Leva 1996 proportions and masses).

    Arguments:
        height_m: stature in metres (> 0).
        mass_kg: body mass (only scales reported masses; the COM does not depend on it).

    Returns:
        A `Body`.
    """
    h = float(height_m)
    if not (np.isfinite(h) and 0.3 <= h <= 3.0):
        raise UserError(f"make_body: height_m must be between 0.3 and 3 m, got {height_m!r}")
    m = float(mass_kg)
    if not (np.isfinite(m) and m > 0):
        raise UserError(f"make_body: mass_kg must be positive, got {mass_kg!r}")
    s = h / DE_LEVA_STATURE_M
    off, ends, mass, com, mon = _rest_geometry()
    return Body(
        # Converted on the host (`as_default_float`): eager `jnp.asarray` of float64 NumPy
        # arrays made one conversion program per array.
        skeleton=Skeleton(TOPOLOGY, off * s, ends * s),
        mass_fractions=as_default_float(mass / mass.sum()),
        com_offsets=as_default_float(com * s),
        monitor_points=as_default_float(mon * s),
        height_m=jax.device_put(h),  # weakly typed, as jnp.asarray(h), without its program
        mass_kg=jax.device_put(m),
    )


# ----------------------------------------------------------------------------------- poses


class StancePose(eqx.Module):
    """One pose of the 48-DOF skeleton: root position and local joint rotations.

    - `root_position`: `[3]` world position of the pelvis joint (m).
    - `quats`: `[J, 4]` local rotation of every joint (wxyz; the pelvis's is its world one).
    """

    root_position: Float[Array, "3"]
    quats: Float[Array, "joints 4"]


def rest_pose(body: Body) -> StancePose:
    """The rest pose: standing straight, arms at the sides, feet under the hips."""
    dtype = body.offsets.dtype
    quats = jnp.zeros((len(JOINT_NAMES), 4), dtype).at[:, 0].set(1.0)
    return StancePose(root_position=body.offsets[0], quats=quats)


def pose_fk(body: Body, pose: StancePose) -> FKResult:
    """World rotations and positions of every joint and End Site (metres)."""
    translations = body.offsets.at[0].set(pose.root_position.astype(body.offsets.dtype))
    return forward_kinematics(body.skeleton, translations, pose.quats.astype(translations.dtype))


def center_of_mass(body: Body, fk: FKResult) -> Float[Array, "3"]:
    """Whole-body centre of mass of a posed character (m): sum of de Leva segment COMs.

    Arguments:
        body: the character.
        fk: its `pose_fk` result.

    Returns:
        `[3]` world position of the centre of mass.
    """
    seg = fk.positions + rotations.quat_apply(fk.rotations, body.com_offsets)
    w = body.mass_fractions / jnp.sum(body.mass_fractions)
    return jnp.sum(w[:, None] * seg, axis=0)


#: `[J, 3]` 1 where a ZXY Euler component is not one of the joint's DOFs.
_NON_DOF = np.array([[a not in DOFS[name] for a in ROTATION_ORDER] for name in JOINT_NAMES], np.float32)


def _dof_euler(quats: Float[Array, "joints 4"]) -> Float[Array, "joints 3"]:
    """ZXY Euler angles of each joint, of its two triples (z, x, y) and (z + pi, pi - x, y + pi)
    the one whose non-DOF components are smaller (then the smaller angles): a knee or elbow
    flexed past 90 degrees is (0, x, 0), not (pi, pi - x, pi) with the flexion read as pi - x."""
    eul = rotations.euler_from_quat(quats, ROTATION_ORDER)
    twin = rotations.euler_twin(eul, ROTATION_ORDER)
    twin = jnp.arctan2(jnp.sin(twin), jnp.cos(twin))
    weight = jnp.broadcast_to(jnp.asarray(_NON_DOF, eul.dtype) + 1e-3, eul.shape)

    def cost(e):
        return jnp.sum(jnp.abs(e) * weight, axis=-1, keepdims=True)

    return jnp.where(cost(twin) < cost(eul), twin, eul)


#: `_dof_euler` over frames, compiled once (for the BVH export).
dof_euler_frames = filter_jit(jax.vmap(_dof_euler))


def dof_vector(pose: StancePose) -> Float[Array, "48"]:
    """The 48 DOF values of a pose (metres, radians), named by `DOF_NAMES`.

    Each joint's quaternion is read as BVH "ZXY" Euler angles (of the two triples, the one
    with the smaller non-DOF components) and its DOF axes are kept; for a pose built by the
    stance solver the dropped components are zero.
    """
    eul = _dof_euler(pose.quats)  # [J, 3] as (z, x, y)
    parts = [pose.root_position]
    for j, name in enumerate(JOINT_NAMES):
        parts.append(jnp.stack([eul[j, ROTATION_ORDER.index(a)] for a in DOFS[name]]))
    return jnp.concatenate(parts)


def non_dof_components(pose: StancePose) -> Float[Array, " n"]:
    """The ZXY Euler components that are not DOFs (should be ~0): for tests and reports."""
    eul = _dof_euler(pose.quats)
    out = []
    for j, name in enumerate(JOINT_NAMES):
        for a in ROTATION_ORDER:
            if a not in DOFS[name]:
                out.append(eul[j, ROTATION_ORDER.index(a)])
    return jnp.stack(out)


def fk_matrices(
    body: Body, root_position: Float[Array, "3"], local: Float[Array, "joints 3 3"]
) -> tuple[Float[Array, "joints 3 3"], Float[Array, "joints 3"]]:
    """Forward kinematics on rotation matrices for this fixed topology (inner loops).

    Same result as `pose_fk` (tested against `fourierjax.kinematics.forward_kinematics`),
    written joint by joint with broadcast matrix products (a handful of XLA ops each, ~5x
    fewer than a quaternion FK). The solver itself does not call it: `problem.build_rotations`
    builds the world frames along the way.

    Returns:
        `(world rotations [J, 3, 3], world positions [J, 3])`.
    """
    from fourierjax.stance._util import mm, mv

    off = body.offsets
    R = [local[0]]
    P = [root_position]
    for j in range(1, len(PARENTS)):
        p = PARENTS[j]
        R.append(mm(R[p], local[j]))
        P.append(P[p] + mv(R[p], off[j]))
    return jnp.stack(R), jnp.stack(P)


def center_of_mass_matrices(
    body: Body,
    world_rotations: Float[Array, "... 3 3"],
    positions: Float[Array, "... 3"],
    first: int = 0,
) -> Float[Array, "3"]:
    """`center_of_mass` from `fk_matrices` output (m).

    With `first`, the frames may cover a block of contiguous joints `first, first + 1, ...`,
    in the row-major order of their leading axes (e.g. `[side, joint]`), and the result is
    that block's share of the whole-body COM: the stance pose builder sums its blocks of
    world frames this way, one batched product per block.
    """
    from fourierjax.stance._util import mv

    lead = positions.shape[:-1]
    n = int(np.prod(lead))
    w = body.mass_fractions / jnp.sum(body.mass_fractions)
    w = w[first : first + n].reshape(lead)
    c = body.com_offsets[first : first + n].reshape(lead + (3,))
    seg = w[..., None] * (positions + mv(world_rotations, c))
    return jnp.sum(seg.reshape(n, 3), axis=0)
