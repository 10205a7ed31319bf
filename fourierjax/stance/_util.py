"""Small NaN-safe geometry helpers shared by the stance modules (elementary rotations, norms)."""


import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float

from fourierjax import rotations
from fourierjax._legik import safe_norm, safe_normalize  # noqa: F401  (one copy, shared with the foot lock)

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


def rsqrt_where(sq, small):
    """1/sqrt(sq) where not `small`, else 0 (one rsqrt instead of a sqrt and a divide)."""
    return where(small, 0.0, jax.lax.rsqrt(where(small, 1.0, sq)))




def where(cond, x, y):
    """`jnp.where` for the traced stance code: a bare `select_n`, without `jnp.where`'s nested
    jit (about 120 of them were traced into the stance solver's loop); same broadcasting."""
    cond, x, y = jnp.asarray(cond), jnp.asarray(x), jnp.asarray(y)
    dtype = jnp.result_type(x, y)
    shape = jnp.broadcast_shapes(cond.shape, x.shape, y.shape)

    def full(v, dt):
        v = v if v.dtype == dt else v.astype(dt)
        return v if v.shape == shape else jnp.broadcast_to(v, shape)

    return jax.lax.select(full(cond, cond.dtype), full(x, dtype), full(y, dtype))


def clip(x, lo, hi):
    """`jnp.clip` without its nested jit."""
    return jnp.minimum(jnp.maximum(x, lo), hi)


def _split3(x):
    """The three components along the last axis, each keeping a length-1 axis (one `split`)."""
    return jnp.split(x, 3, axis=-1)


def cross(a, b):
    (a0, a1, a2), (b0, b1, b2) = _split3(a), _split3(b)
    return jnp.concatenate([a1 * b2 - a2 * b1, a2 * b0 - a0 * b2, a0 * b1 - a1 * b0], axis=-1)


def dot(a, b):
    return _sum3(a * b)


def _sum3(x):
    """Sum over the last axis; for length 3 as two adds, which XLA fuses into the consumers
    (a reduction is a kernel of its own: 27 fewer kernels in the compiled solver)."""
    if x.shape[-1] != 3:
        return jnp.sum(x, axis=-1)
    a, b, c = _split3(x)
    return jax.lax.squeeze(a + b + c, (x.ndim - 1,))


def quat_from_columns(ex, ey, ez) -> Float[Array, "... 4"]:
    """Quaternion of the rotation matrix with columns ex, ey, ez (orthonormal, right-handed)."""
    R = jnp.stack([ex, ey, ez], axis=-1)
    return rotations.quat_from_matrix(R)


# ------------------------------------------------------------------ rotation matrices
# The stance pipeline works on 3x3 matrices: a product is 3 XLA ops (broadcast, multiply,
# sum; the formulation STYLE.md prescribes against the CPU nested-vmap bug) against ~45 for
# a quaternion product, and compile time of the solver grows with the op count.


_ROT_PARTS = {}  # axis -> (fixed, cos part, sin part) as numpy 3x3
for _axis in range(3):
    _i, _j = (_axis + 1) % 3, (_axis + 2) % 3
    _fixed, _c, _s = (np.zeros((3, 3)) for _ in range(3))
    _fixed[_axis, _axis] = 1.0
    _c[_i, _i] = _c[_j, _j] = 1.0
    _s[_j, _i], _s[_i, _j] = 1.0, -1.0
    _ROT_PARTS[_axis] = (_fixed, _c, _s)


def rot(axis: int, angle) -> Float[Array, "... 3 3"]:
    """Rotation matrix by `angle` (rad) about world axis 0 (X), 1 (Y) or 2 (Z).

    Built as fixed + cos(angle) C + sin(angle) S with constant C, S: a handful of
    element-wise ops that fuse, instead of stacking nine scalars.
    """
    angle = jnp.asarray(angle)
    return rot_cs(axis, jnp.cos(angle), jnp.sin(angle))


def rot_cs(axis: int, cos, sin) -> Float[Array, "... 3 3"]:
    """`rot(axis, angle)` from the angle's cosine and sine (no trigonometry)."""
    cos, sin = jnp.asarray(cos), jnp.asarray(sin)
    lead = (1,) * cos.ndim  # explicit ranks (the tests raise on rank promotion)
    fixed, c, s = (jnp.asarray(m.reshape(lead + (3, 3)), cos.dtype) for m in _ROT_PARTS[axis])
    return fixed + cos[..., None, None] * c + sin[..., None, None] * s


def mm(a, b):
    """Matrix product a @ b by broadcasting (`fourierjax.rotations.matrix_multiply`)."""
    return jnp.sum(a[..., :, :, None] * b[..., None, :, :], axis=-2)


def mv(a, v):
    """Matrix-vector product a @ v by broadcasting."""
    return _sum3(a * v[..., None, :])


def tr(a):
    """Transpose of (a batch of) matrices: the inverse of a rotation."""
    return jnp.swapaxes(a, -1, -2)


def euler_zxy(z, x, y):
    """R = Rz(z) Rx(x) Ry(y) (the skeleton's BVH order)."""
    return mm(mm(rot(2, z), rot(0, x)), rot(1, y))


def columns(ex, ey, ez):
    """The matrix with columns ex, ey, ez."""
    return jnp.stack([ex, ey, ez], axis=-1)


def zero_tangent(tree):
    """Zero tangents for a pytree: zeros for inexact leaves, float0 for the others."""

    def zero(x):
        x = jnp.asarray(x)
        if jnp.issubdtype(x.dtype, jnp.inexact):
            return jnp.zeros_like(x)
        return np.zeros(x.shape, jax.dtypes.float0)

    return jax.tree.map(zero, tree)
