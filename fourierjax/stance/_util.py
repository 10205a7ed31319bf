"""Small NaN-safe geometry helpers shared by the stance modules (elementary rotations, norms)."""


import jax.numpy as jnp
from jaxtyping import Array, Float

from fourierjax import rotations

_EPS = 1e-12


def quat_axis(axis: int, angle: Float[Array, "..."]) -> Float[Array, "... 4"]:
    """Rotation by `angle` (rad) about world axis 0 (X), 1 (Y) or 2 (Z), wxyz."""
    angle = jnp.asarray(angle)
    half = 0.5 * angle
    zero = jnp.zeros_like(half)
    xyz = [zero, zero, zero]
    xyz[axis] = jnp.sin(half)
    return jnp.stack([jnp.cos(half), *xyz], axis=-1)


def quat_euler_zxy(z, x, y) -> Float[Array, "... 4"]:
    """R = Rz(z) Rx(x) Ry(y) (the stance skeleton's BVH order) as a quaternion."""
    q = rotations.quat_multiply(quat_axis(2, z), quat_axis(0, x))
    return rotations.quat_multiply(q, quat_axis(1, y))


def safe_norm(v: Float[Array, "... n"]) -> Float[Array, "..."]:
    """|v| with a zero (not NaN) gradient at v = 0 (double-where shim)."""
    sq = jnp.sum(v * v, axis=-1)
    small = sq < _EPS * _EPS
    return jnp.where(small, 0.0, jnp.sqrt(jnp.where(small, 1.0, sq)))


def safe_normalize(v: Float[Array, "... n"], fallback: Float[Array, "... n"]) -> Float[Array, "... n"]:
    """v / |v|, or `fallback` (assumed unit) where |v| is ~0; finite gradients everywhere."""
    sq = jnp.sum(v * v, axis=-1, keepdims=True)
    small = sq < 1e-20
    inv = jnp.where(small, 0.0, 1.0 / jnp.sqrt(jnp.where(small, 1.0, sq)))
    return jnp.where(small, fallback, v * inv)


def safe_sqrt(x: Float[Array, "..."], floor: float = 0.0) -> Float[Array, "..."]:
    """sqrt(max(x, floor)) with a zero gradient where x <= floor (and at 0)."""
    lo = x <= max(floor, 1e-30)
    return jnp.where(lo, jnp.sqrt(max(floor, 0.0)), jnp.sqrt(jnp.where(lo, 1.0, x)))


def cross(a, b):
    return jnp.stack(
        [
            a[..., 1] * b[..., 2] - a[..., 2] * b[..., 1],
            a[..., 2] * b[..., 0] - a[..., 0] * b[..., 2],
            a[..., 0] * b[..., 1] - a[..., 1] * b[..., 0],
        ],
        axis=-1,
    )


def dot(a, b):
    return jnp.sum(a * b, axis=-1)


def quat_from_columns(ex, ey, ez) -> Float[Array, "... 4"]:
    """Quaternion of the rotation matrix with columns ex, ey, ez (orthonormal, right-handed)."""
    R = jnp.stack([ex, ey, ez], axis=-1)
    return rotations.quat_from_matrix(R)


# ------------------------------------------------------------------ rotation matrices
# The stance pipeline works on 3x3 matrices: a product is 3 XLA ops (broadcast, multiply,
# sum; the formulation STYLE.md prescribes against the CPU nested-vmap bug) against ~45 for
# a quaternion product, and compile time of the solver grows with the op count.


def rot(axis: int, angle) -> Float[Array, "... 3 3"]:
    """Rotation matrix by `angle` (rad) about world axis 0 (X), 1 (Y) or 2 (Z)."""
    angle = jnp.asarray(angle)
    c, s = jnp.cos(angle), jnp.sin(angle)
    one, zero = jnp.ones_like(c), jnp.zeros_like(c)
    if axis == 0:
        rows = ((one, zero, zero), (zero, c, -s), (zero, s, c))
    elif axis == 1:
        rows = ((c, zero, s), (zero, one, zero), (-s, zero, c))
    else:
        rows = ((c, -s, zero), (s, c, zero), (zero, zero, one))
    return jnp.stack([jnp.stack(r, axis=-1) for r in rows], axis=-2)


def mm(a, b):
    """Matrix product a @ b by broadcasting (`fourierjax.rotations.matrix_multiply`)."""
    return jnp.sum(a[..., :, :, None] * b[..., None, :, :], axis=-2)


def mv(a, v):
    """Matrix-vector product a @ v by broadcasting."""
    return jnp.sum(a * v[..., None, :], axis=-1)


def tr(a):
    """Transpose of (a batch of) matrices: the inverse of a rotation."""
    return jnp.swapaxes(a, -1, -2)


def euler_zxy(z, x, y):
    """R = Rz(z) Rx(x) Ry(y) (the skeleton's BVH order)."""
    return mm(mm(rot(2, z), rot(0, x)), rot(1, y))


def columns(ex, ey, ez):
    """The matrix with columns ex, ey, ez."""
    return jnp.stack([ex, ey, ez], axis=-1)
