"""Torso shape classes and collar bones (Neff & Fiume 2004, sec. 5.2, eqs. 1-4, appendix)."""


from types import MappingProxyType

import jax.numpy as jnp
from jaxtyping import Array, Float

from fourierjax.errors import UserError
from fourierjax.stance import _util as u

#: Shape class names (config spelling) in table order.
SHAPE_CLASSES: tuple[str, ...] = ("large_s", "large_c", "small_s", "small_c", "straight")

#: Appendix "Shape Class Weights", sagittal table: weights of (AbX, ChestX, NeckX, HeadX).
SAGITTAL_WEIGHTS = MappingProxyType(
    {
        "large_s": (0.15, -0.10, -0.12, -0.10),
        "large_c": (0.15, 0.15, 0.15, 0.10),
        "small_s": (0.15, -0.20, 0.06, -0.10),
        "small_c": (-0.15, 0.30, 0.15, 0.10),
        "straight": (0.0, 0.0, 0.0, 0.0),
    }
)

#: Appendix, coronal table: weights of (AbZ, ChestZ, NeckZ, HeadZ).
CORONAL_WEIGHTS = MappingProxyType(
    {
        "large_s": (0.08, -0.10, -0.12, -0.06),
        "large_c": (0.15, 0.15, 0.12, 0.06),
        "small_s": (0.15, -0.20, 0.12, 0.06),
        "small_c": (-0.15, 0.30, 0.12, 0.06),
        "straight": (0.0, 0.0, 0.0, 0.0),
    }
)

#: Collar state spellings and their sign (aligned: both shoulders move the same way).
COLLAR_STATES = MappingProxyType({"aligned": 1.0, "opposed": -1.0})


def class_weights(plane: str, name: str) -> Float[Array, "4"]:
    """The 4 weights of shape class `name` in `plane` ("sagittal" or "coronal")."""
    table = {"sagittal": SAGITTAL_WEIGHTS, "coronal": CORONAL_WEIGHTS}.get(plane)
    if table is None:
        raise UserError(f"class_weights: plane must be 'sagittal' or 'coronal', got {plane!r}")
    if name not in table:
        raise UserError(
            f"unknown {plane} shape class {name!r}; choose one of {', '.join(SHAPE_CLASSES)}"
        )
    return jnp.asarray(table[name])


def collar_sign(name: str) -> float:
    """+1 for "aligned", -1 for "opposed" (a UserError otherwise)."""
    if name not in COLLAR_STATES:
        raise UserError(f"unknown collar state {name!r}; choose 'aligned' or 'opposed'")
    return COLLAR_STATES[name]


def spine_quats(
    sagittal: Float[Array, ""],
    coronal: Float[Array, ""],
    transverse: Float[Array, ""],
    abdomen_x: Float[Array, ""],
    sagittal_weights: Float[Array, "4"],
    coronal_weights: Float[Array, "4"],
) -> Float[Array, "4 3 3"]:
    """Local rotations of abdomen, chest, neck and head from the spine amplitudes (rad).

    DOF = amplitude x class weight (eqs. 1-4) in the sagittal (X) and coronal (Z) planes; the
    transverse amplitude is spread evenly over the four joints (Y); `abdomen_x` is the
    optional abdomen X offset, added to AbX.

    Returns:
        `[4, 3, 3]` rotation matrices, R = Rz Rx Ry (BVH order Z X Y).
    """
    x = sagittal * sagittal_weights + jnp.array([1.0, 0.0, 0.0, 0.0]) * abdomen_x
    z = coronal * coronal_weights
    y = jnp.broadcast_to(transverse / 4.0, (4,))
    return u.euler_zxy(z, x, y)


def collar_quats(
    collar_y: Float[Array, ""],
    collar_z: Float[Array, ""],
    signs_yz: Float[Array, "2"],
) -> Float[Array, "2 3 3"]:
    """Local rotations of the right and left collar bones.

    Aligned (sign +1): positive `collar_z` raises both shoulders (a shrug), positive
    `collar_y` moves both shoulders forward (closing the chest). Opposed (sign -1): the
    collars act as one rigid unit: positive `collar_z` raises the left and lowers the right
    shoulder, positive `collar_y` brings the right shoulder forward and the left back (the
    same sense as a positive transverse twist of the spine).

    Returns:
        `[2, 3, 3]` (right, left) rotation matrices, R = Rz Ry.
    """
    sy, sz = signs_yz[0], signs_yz[1]
    # Right collar points to -X: +Z rotation lowers its end, +Y rotation brings it forward.
    right = u.mm(u.rot(2, -sz * collar_z), u.rot(1, collar_y))
    left = u.mm(u.rot(2, collar_z), u.rot(1, -sy * collar_y))
    return jnp.stack([right, left])
