"""Rotation conversions: Euler angles (12 BVH orders), wxyz quaternions, expmaps, matrices.

Quaternions and axes whose norm is at or below `zero_norm_threshold(dtype)` (about 3.3e-10 in
float32, 1.2e-77 in float64) count as zero: values and gradients stay finite there.
"""

from __future__ import annotations

from fourierjax._rotations._common import (
    EULER_ORDERS,
    zero_norm_threshold,
)
from fourierjax._rotations._continuity import (
    make_euler_continuous,
    make_expmap_continuous,
    make_quat_continuous,
)
from fourierjax._rotations._euler import (
    euler_from_matrix,
    euler_from_quat,
    euler_twin,
    matrix_from_euler,
    quat_from_euler,
)
from fourierjax._rotations._quat import (
    expmap_from_matrix,
    expmap_from_quat,
    matrix_from_expmap,
    matrix_from_quat,
    matrix_multiply,
    quat_apply,
    quat_conjugate,
    quat_from_axis_angle,
    quat_from_expmap,
    quat_from_matrix,
    quat_multiply,
    quat_normalize,
    quat_power,
    quat_slerp,
)

__all__ = [
    "EULER_ORDERS",
    "euler_from_matrix",
    "euler_from_quat",
    "euler_twin",
    "expmap_from_matrix",
    "expmap_from_quat",
    "make_euler_continuous",
    "make_expmap_continuous",
    "make_quat_continuous",
    "matrix_from_euler",
    "matrix_from_expmap",
    "matrix_from_quat",
    "matrix_multiply",
    "quat_apply",
    "quat_conjugate",
    "quat_from_axis_angle",
    "quat_from_euler",
    "quat_from_expmap",
    "quat_from_matrix",
    "quat_multiply",
    "quat_normalize",
    "quat_power",
    "quat_slerp",
    "zero_norm_threshold",
]
