"""Rotation conversions against scipy's Rotation, finite differences and closed forms."""

import functools
import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from scipy.spatial.transform import Rotation, Slerp

from fourierjax import rotations as rot
from fourierjax.errors import UserError
from tests.helpers import random_angles

ORDERS = rot.EULER_ORDERS
TAIT_BRYAN = [o for o in ORDERS if o[0] != o[2]]
PROPER = [o for o in ORDERS if o[0] == o[2]]
KINDS = ["uniform", "near_zero", "gimbal"]
# One batch size everywhere: eager calls then reuse the primitives compiled by earlier tests.
N = 64


def _sample_angles(seed: int, n: int, kind: str, order: str) -> np.ndarray:
    """random_angles, with the gimbal kind moved to the lock of proper orders (middle 0 or pi)."""
    a = random_angles(np.random.default_rng(seed), n, kind)
    if kind == "gimbal" and order[0] == order[2]:
        a[:, 1] = np.abs(a[:, 1] - np.pi / 2)  # ~0
        a[::2, 1] = np.pi - a[::2, 1]  # ~pi
    return a


def _wxyz(q_xyzw: np.ndarray) -> np.ndarray:
    return q_xyzw[..., [3, 0, 1, 2]]


def _xyzw(q_wxyz: np.ndarray) -> np.ndarray:
    return np.asarray(q_wxyz)[..., [1, 2, 3, 0]]


def _assert_same_quat(q, ref, atol):
    """Equal as rotations: q == ref or q == -ref, row by row."""
    q, ref = np.asarray(q, np.float64), np.asarray(ref, np.float64)
    err = np.minimum(np.abs(q - ref).max(-1), np.abs(q + ref).max(-1))
    assert err.max() <= atol, err.max()


def _wrapped(d):
    return (np.asarray(d) + np.pi) % (2 * np.pi) - np.pi


def _exact_lock_matrices(order: str) -> np.ndarray:
    """Matrices exactly at gimbal lock (entries 0 / +-1) for `order`."""
    middles = [np.pi / 2, -np.pi / 2] if order[0] != order[2] else [0.0, np.pi]
    angles = [(a, m, c) for m in middles for a in (0.0, np.pi / 2) for c in (0.0, -np.pi / 2)]
    mats = Rotation.from_euler(order, np.array(angles)).as_matrix()
    return np.round(mats)


# ------------------------------------------------------------------------------ constants


def test_euler_orders():
    assert rot.EULER_ORDERS == (
        "XYZ", "XZY", "YXZ", "YZX", "ZXY", "ZYX",
        "XYX", "XZX", "YXY", "YZY", "ZXZ", "ZYZ",
    )  # fmt: skip


def test_bvh_semantics_zyx():
    """Order "ZYX", angles (a, b, c) -> Rz(a) @ Ry(b) @ Rx(c) (closed form, not scipy)."""
    a, b, c = 0.3, -0.7, 1.1
    rz = np.array([[np.cos(a), -np.sin(a), 0], [np.sin(a), np.cos(a), 0], [0, 0, 1]])
    ry = np.array([[np.cos(b), 0, np.sin(b)], [0, 1, 0], [-np.sin(b), 0, np.cos(b)]])
    rx = np.array([[1, 0, 0], [0, np.cos(c), -np.sin(c)], [0, np.sin(c), np.cos(c)]])
    got = rot.matrix_from_euler(jnp.array([a, b, c]), "ZYX")
    np.testing.assert_allclose(got, rz @ ry @ rx, atol=1e-6)


# ------------------------------------------------------------------- Euler vs scipy (x64)


@pytest.mark.parametrize("kind", KINDS)
@pytest.mark.parametrize("order", ORDERS)
def test_euler_conversions_vs_scipy(x64, order, kind):
    angles = _sample_angles(ORDERS.index(order) * 10 + KINDS.index(kind), N, kind, order)
    ref = Rotation.from_euler(order, angles)
    R = rot.matrix_from_euler(jnp.asarray(angles), order)
    assert R.dtype == jnp.float64
    np.testing.assert_allclose(R, ref.as_matrix(), rtol=0, atol=1e-12)
    q = rot.quat_from_euler(jnp.asarray(angles), order)
    _assert_same_quat(q, _wxyz(ref.as_quat()), atol=1e-12)
    np.testing.assert_allclose(jnp.linalg.norm(q, axis=-1), 1.0, atol=1e-12)

    for back in (rot.euler_from_matrix(R, order), rot.euler_from_quat(q, order)):
        back = np.asarray(back)
        # Canonical ranges.
        mid = back[:, 1]
        if order[0] != order[2]:
            assert np.all(np.abs(mid) <= np.pi / 2)
        else:
            assert np.all((mid >= 0) & (mid <= np.pi))
        assert np.all((back[:, [0, 2]] > -np.pi) & (back[:, [0, 2]] <= np.pi))
        # Round trip reconstructs the rotation, in every regime.
        np.testing.assert_allclose(Rotation.from_euler(order, back).as_matrix(), ref.as_matrix(), atol=1e-10)
        if kind == "uniform":  # away from gimbal lock the angles themselves match scipy's
            np.testing.assert_allclose(_wrapped(back - ref.as_euler(order)), 0.0, atol=1e-9)


@pytest.mark.parametrize("order", ORDERS)
def test_euler_float32(order):
    angles = _sample_angles(7, N, "uniform", order).astype(np.float32)
    ref = Rotation.from_euler(order, angles.astype(np.float64))
    R = rot.matrix_from_euler(angles, order)
    assert R.dtype == jnp.float32
    np.testing.assert_allclose(R, ref.as_matrix(), atol=2e-6)
    back = rot.euler_from_matrix(R, order)
    assert back.dtype == jnp.float32
    # Euler angles are ill-conditioned near gimbal lock: compare where comfortably away from it.
    mid = ref.as_euler(order)[:, 1]
    lock_distance = np.cos(mid) if order[0] != order[2] else np.sin(mid)
    ok = np.abs(lock_distance) > 0.05
    np.testing.assert_allclose(_wrapped(back - ref.as_euler(order))[ok], 0.0, atol=5e-5)
    np.testing.assert_allclose(rot.matrix_from_euler(back, order), ref.as_matrix(), atol=1e-5)
    for kind in ("near_zero", "gimbal"):
        angles = _sample_angles(8, N, kind, order).astype(np.float32)
        R = rot.matrix_from_euler(angles, order)
        for back in (
            rot.euler_from_matrix(R, order),
            rot.euler_from_quat(rot.quat_from_matrix(R), order),
        ):
            assert np.all(np.isfinite(back))
            np.testing.assert_allclose(rot.matrix_from_euler(back, order), R, atol=1e-5)


@pytest.mark.parametrize("dtype", ["float32", "float64"])
@pytest.mark.parametrize("order", ORDERS)
def test_euler_exact_gimbal_lock(x64, order, dtype):
    """Exactly at the lock: any split of first/last angle is fine if it reconstructs R."""
    mats = jnp.asarray(np.resize(_exact_lock_matrices(order), (N, 3, 3)), dtype=dtype)
    for back in (
        rot.euler_from_matrix(mats, order),
        rot.euler_from_quat(rot.quat_from_matrix(mats), order),
    ):
        assert back.dtype == dtype
        np.testing.assert_allclose(rot.matrix_from_euler(back, order), mats, atol=1e-6)


# -------------------------------------------------------------- quaternion / matrix / expmap


def _random_rotations(n: int, seed: int) -> Rotation:
    r = Rotation.random(n, rng=seed)
    # Add the special cases: identity, near identity, 180 degrees about each axis and about a
    # diagonal, and rotations just short of 180 degrees.
    special = np.concatenate(
        [
            np.zeros((1, 3)),
            1e-9 * np.eye(3),
            np.pi * np.eye(3),
            np.pi / np.sqrt(3) * np.ones((1, 3)),
            (np.pi - 1e-7) * np.eye(3),
        ]
    )
    return Rotation.concatenate([r, Rotation.from_rotvec(special)])


def test_quat_matrix_expmap_vs_scipy(x64):
    ref = _random_rotations(N - 9, 0)  # 9 special cases: N rows
    M, q_ref, v_ref = ref.as_matrix(), _wxyz(ref.as_quat(canonical=True)), ref.as_rotvec()

    q = rot.quat_from_matrix(jnp.asarray(M))
    np.testing.assert_allclose(q, q_ref, atol=1e-12)  # canonical sign, as scipy's canonical
    assert np.all(np.asarray(q)[:, 0] >= 0)
    np.testing.assert_allclose(rot.matrix_from_quat(jnp.asarray(q_ref)), M, atol=1e-12)

    # as_rotvec's sign is ambiguous only at exactly pi: compare those as rotations.
    angle = np.linalg.norm(v_ref, axis=-1)
    unambiguous = angle < np.pi - 1e-12
    for v in (rot.expmap_from_matrix(jnp.asarray(M)), rot.expmap_from_quat(jnp.asarray(q_ref))):
        v = np.asarray(v)
        np.testing.assert_allclose(v[unambiguous], v_ref[unambiguous], atol=1e-10)
        assert np.all(np.linalg.norm(v, axis=-1) <= np.pi + 1e-12)
        np.testing.assert_allclose(Rotation.from_rotvec(np.array(v)).as_matrix(), M, atol=1e-10)
    # q and -q give the same expmap.
    np.testing.assert_allclose(rot.expmap_from_quat(-jnp.asarray(q_ref))[unambiguous], v_ref[unambiguous], atol=1e-10)

    # Forward maps for any angle (beyond pi too).
    v_big = np.random.default_rng(1).normal(size=(N, 3)) * 2.5
    for v_all in (v_ref, v_big, 1e-8 * v_big):
        ref_all = Rotation.from_rotvec(v_all)
        np.testing.assert_allclose(rot.matrix_from_expmap(jnp.asarray(v_all)), ref_all.as_matrix(), atol=1e-12)
        q = rot.quat_from_expmap(jnp.asarray(v_all))
        _assert_same_quat(q, _wxyz(ref_all.as_quat()), atol=1e-12)
        np.testing.assert_allclose(jnp.linalg.norm(q, axis=-1), 1.0, atol=1e-14)


def test_expmap_near_zero_is_exact(x64):
    """The Taylor branches agree with the closed forms at and around their threshold."""
    theta = np.geomspace(1e-12, 1e-1, N)
    axis = np.array([2.0, -1.0, 0.5]) / np.linalg.norm([2.0, -1.0, 0.5])
    v = theta[:, None] * axis
    exact_q = np.concatenate([np.cos(theta / 2)[:, None], np.sin(theta / 2)[:, None] * axis], -1)
    np.testing.assert_allclose(rot.quat_from_expmap(jnp.asarray(v)), exact_q, rtol=1e-15, atol=1e-16)
    np.testing.assert_allclose(rot.expmap_from_quat(jnp.asarray(exact_q)), v, rtol=1e-14, atol=0)
    v32 = jnp.asarray(v, jnp.float32)
    np.testing.assert_allclose(rot.quat_from_expmap(v32), exact_q, rtol=1e-6, atol=1e-7)
    np.testing.assert_allclose(rot.expmap_from_quat(jnp.asarray(exact_q, jnp.float32)), v, rtol=1e-6)


def test_quat_algebra_vs_scipy(x64):
    r1, r2 = Rotation.random(N, rng=2), Rotation.random(N, rng=3)
    q1, q2 = jnp.asarray(_wxyz(r1.as_quat())), jnp.asarray(_wxyz(r2.as_quat()))
    prod = rot.quat_multiply(q1, q2)
    _assert_same_quat(prod, _wxyz((r1 * r2).as_quat()), atol=1e-12)
    np.testing.assert_allclose(
        rot.matrix_from_quat(prod),
        rot.matrix_multiply(rot.matrix_from_quat(q1), rot.matrix_from_quat(q2)),
        atol=1e-12,
    )
    np.testing.assert_allclose(
        rot.matrix_multiply(rot.matrix_from_quat(q1), rot.matrix_from_quat(q2)),
        r1.as_matrix() @ r2.as_matrix(),
        atol=1e-12,
    )
    # Inverse.
    inv = rot.quat_conjugate(q1)
    _assert_same_quat(inv, _wxyz(r1.inv().as_quat()), atol=1e-12)
    ident = np.zeros((N, 4))
    ident[:, 0] = 1
    np.testing.assert_allclose(rot.quat_multiply(q1, inv), ident, atol=1e-12)
    np.testing.assert_allclose(rot.matrix_from_quat(inv), np.swapaxes(r1.as_matrix(), -1, -2), atol=1e-12)
    # Apply.
    v = np.random.default_rng(4).normal(size=(N, 3))
    np.testing.assert_allclose(rot.quat_apply(q1, jnp.asarray(v)), r1.apply(v), atol=1e-12)
    # Broadcasting of leading dims: one rotation, many vectors.
    np.testing.assert_allclose(rot.quat_apply(q1[0], jnp.asarray(v)), r1[0].apply(v), atol=1e-12)
    np.testing.assert_allclose(rot.quat_multiply(q1[0], q2), rot.quat_multiply(jnp.broadcast_to(q1[0], (N, 4)), q2))


def test_quat_normalize(x64):
    q = np.random.default_rng(5).normal(size=(N, 4)) * 3
    out = rot.quat_normalize(jnp.asarray(q))
    np.testing.assert_allclose(out, q / np.linalg.norm(q, axis=-1, keepdims=True), atol=1e-15)
    np.testing.assert_array_equal(rot.quat_normalize(jnp.zeros(4)), [1.0, 0.0, 0.0, 0.0])


def test_axis_angle_and_slerp(x64):
    rng = np.random.default_rng(6)
    axis, angle = rng.normal(size=(N, 3)) * 2, rng.uniform(-4, 4, size=N)
    ref = Rotation.from_rotvec(axis / np.linalg.norm(axis, axis=-1, keepdims=True) * angle[:, None])
    q = rot.quat_from_axis_angle(jnp.asarray(axis), jnp.asarray(angle))
    _assert_same_quat(q, _wxyz(ref.as_quat()), atol=1e-12)
    np.testing.assert_array_equal(rot.quat_from_axis_angle(jnp.zeros(3), 1.0), [1, 0, 0, 0])

    r0, r1 = Rotation.random(N, rng=7), Rotation.random(N, rng=8)
    q0, q1 = jnp.asarray(_wxyz(r0.as_quat())), jnp.asarray(_wxyz(r1.as_quat()))
    t = rng.uniform(0, 1, size=N)
    expected = [Slerp([0.0, 1.0], Rotation.concatenate([r0[i], r1[i]]))(t[i]) for i in range(N)]
    expected = np.stack([_wxyz(e.as_quat()) for e in expected])
    got = rot.quat_slerp(q0, q1, jnp.asarray(t))
    _assert_same_quat(got, expected, atol=1e-12)
    _assert_same_quat(rot.quat_slerp(q0, -q1, jnp.asarray(t)), expected, atol=1e-12)  # shortest
    np.testing.assert_allclose(rot.quat_slerp(q0, q1, 0.0), q0, atol=1e-14)
    _assert_same_quat(rot.quat_slerp(q0, q1, 1.0), q1, atol=1e-12)
    # One pair, a time axis of t.
    ts = jnp.linspace(0.0, 1.0, 5)
    assert rot.quat_slerp(q0[0], q1[0], ts).shape == (5, 4)
    # The power on its own: scipy's rotation vector scaled (shortest arc), any norm of q.
    tp = rng.uniform(-0.5, 1.5, size=N)
    expected = np.stack([_wxyz(Rotation.from_rotvec(r0[i].as_rotvec() * tp[i]).as_quat()) for i in range(N)])
    _assert_same_quat(rot.quat_power(3.0 * q0, jnp.asarray(tp)), expected, atol=1e-12)
    _assert_same_quat(rot.quat_power(-q0, jnp.asarray(tp)), expected, atol=1e-12)


def test_power_and_slerp_at_and_near_the_identity():
    # The small-angle branch of quat_power: exact at the identity (any norm, any exponent),
    # continuous into the general formula (scipy's scaled rotation vector), zero slope in t.
    ident = jnp.array([1.0, 0.0, 0.0, 0.0])
    for t in (-0.7, 0.0, 0.5, 1.0, 2.0):
        np.testing.assert_allclose(rot.quat_power(ident, t), ident, atol=1e-15)
        np.testing.assert_allclose(rot.quat_power(2.5 * ident, t), ident, atol=1e-15)
    for angle in (1e-9, 1e-7, 1e-5, 1e-3):  # on both sides of the branch (|xyz| <= 1e-6 w)
        r = Rotation.from_rotvec([angle, -2 * angle, 0.5 * angle])
        q = jnp.asarray(_wxyz(r.as_quat()))
        for t in (0.5, 2.0):
            ref = _wxyz(Rotation.from_rotvec(r.as_rotvec() * t).as_quat())
            np.testing.assert_allclose(rot.quat_power(q, t), ref, rtol=1e-6, atol=1e-12)  # float32
    assert float(jax.grad(lambda t: rot.quat_power(ident, t)[0])(0.5)) == 0.0
    # slerp between equal rotations is that rotation at every t.
    q = rot.quat_from_axis_angle(jnp.array([0.0, 0.0, 1.0]), 0.7)
    for t in (0.0, 0.5, 1.0, 1.5):
        np.testing.assert_allclose(rot.quat_slerp(q, q, t), q, atol=1e-15)


# --------------------------------------------------------------------------- continuity


def test_make_quat_continuous():
    rng = np.random.default_rng(9)
    T, J = 60, 4
    t = np.linspace(0, 1, T)[:, None, None]
    v = rng.normal(size=(1, J, 3)) + t * rng.normal(size=(1, J, 3)) * 6  # angles well beyond pi
    q_smooth = np.asarray(rot.quat_from_expmap(jnp.asarray(v, jnp.float32)))  # smooth in time
    flips = rng.choice([-1.0, 1.0], size=(T, J, 1)).astype(np.float32)
    noisy = q_smooth * flips
    out = np.asarray(jax.jit(rot.make_quat_continuous)(jnp.asarray(noisy)))
    assert np.all(np.sum(out[1:] * out[:-1], -1) >= 0)
    sign0 = np.sign(np.sum(out[0] * q_smooth[0], -1))
    np.testing.assert_allclose(out, q_smooth * sign0[None, :, None], atol=1e-6)
    # Time along another axis.
    out1 = rot.make_quat_continuous(jnp.asarray(np.swapaxes(noisy, 0, 1)), axis=1)
    np.testing.assert_allclose(np.swapaxes(out1, 0, 1), out, atol=0)
    with pytest.raises(UserError, match="axis"):
        rot.make_quat_continuous(jnp.asarray(noisy), axis=-1)


def test_make_expmap_continuous_crossing_pi(x64):
    T = 200
    t = np.linspace(0.0, 1.0, T)
    angle = 0.5 * np.pi + 3.0 * np.pi * t  # 0.5 pi .. 3.5 pi: crosses pi, 2 pi and 3 pi
    axis = np.stack([np.cos(0.4 * t), np.sin(0.4 * t), 0.3 + 0 * t], -1)
    axis /= np.linalg.norm(axis, axis=-1, keepdims=True)
    v_true = angle[:, None] * axis
    wrapped = Rotation.from_rotvec(v_true).as_rotvec()  # angle <= pi: jumps at pi, 3 pi
    assert np.max(np.linalg.norm(np.diff(wrapped, axis=0), axis=-1)) > 5.0
    out = np.array(rot.make_expmap_continuous(jnp.asarray(wrapped)))
    np.testing.assert_allclose(out, v_true, atol=1e-9)
    np.testing.assert_allclose(
        Rotation.from_rotvec(out).as_matrix(), Rotation.from_rotvec(v_true).as_matrix(), atol=1e-9
    )

    # Injected 2 pi jumps and antipodal flips on a batch of small-angle tracks, time on axis 1.
    rng = np.random.default_rng(10)
    v = 0.3 * rng.normal(size=(3, 50, 3)).cumsum(1) / 5 + rng.normal(size=(3, 1, 3))
    n = v / np.linalg.norm(v, axis=-1, keepdims=True)
    k = rng.choice([-1, 0, 0, 1], size=(3, 50, 1))
    k[:, 0] = 0
    noisy = v + 2 * np.pi * k * n
    out = rot.make_expmap_continuous(jnp.asarray(noisy), axis=1)
    np.testing.assert_allclose(out, v, atol=1e-9)

    # float32 keeps float32 and still works.
    out32 = rot.make_expmap_continuous(jnp.asarray(wrapped, jnp.float32))
    assert out32.dtype == jnp.float32
    np.testing.assert_allclose(out32, v_true, atol=2e-5)


# ----------------------------------------------------------------------------- gradients


# Every jit below is a compile (0.1 to 1 s of CPU each): the tests group work into few of them.
# Eager jax.grad is far slower still (op-by-op dispatch of the backward pass).

# LLVM -O0 halves compile time; used only where a test checks values, not compiled code paths.
_FAST_COMPILE = {"xla_backend_optimization_level": 0}

_ORDERS_BY_PARITY = ("ZYX", "XYZ", "ZXZ", "ZYZ")  # both parities, Tait-Bryan and proper


def _special_matrices(orders) -> np.ndarray:
    """Identity, exact and near gimbal lock for `orders`, and 180 degree rotations."""
    mats = [np.eye(3)[None], Rotation.from_rotvec(np.pi * np.eye(3)).as_matrix()]
    for order in orders:
        mats.append(_exact_lock_matrices(order))
        mats.append(Rotation.from_euler(order, _sample_angles(11, 4, "gimbal", order)).as_matrix())
    return np.concatenate(mats)


def _from_matrix_all(R, orders=_ORDERS_BY_PARITY):
    """All conversions out of a matrix; they share one quat_from_matrix inside the jit."""
    outs = [rot.euler_from_matrix(R, order) for order in orders]
    return jnp.concatenate([*outs, rot.expmap_from_matrix(R), rot.quat_from_matrix(R)], axis=-1)


def _from_quat_all(q):
    outs = [rot.quat_normalize(q), rot.quat_slerp(q, q, 0.3), rot.euler_from_quat(q, "XZY")]
    return jnp.concatenate(outs, axis=-1)


def _from_vector_all(v):  # v as an expmap and as Euler angles
    outs = [rot.matrix_from_expmap(v).reshape(*v.shape[:-1], 9), rot.quat_from_euler(v, "YZY")]
    return jnp.concatenate(outs, axis=-1)


def _grads(f, x):
    """Per-row gradient of sum(f(x) * w) for a fixed random w, jitted."""
    w = jnp.asarray(np.random.default_rng(12).normal(size=jax.eval_shape(f, x).shape), x.dtype)
    return jax.jit(jax.grad(lambda x: jnp.sum(f(x) * w)))(x)


@pytest.mark.parametrize("dtype", ["float32", "float64"])
def test_gradients_finite_at_zero_and_gimbal_lock(x64, dtype):
    mats = jnp.asarray(_special_matrices(_ORDERS_BY_PARITY), dtype)
    quats = rot.quat_from_matrix(mats)
    quats = jnp.concatenate([quats, -quats, jnp.zeros((1, 4), dtype)])  # zero: quat_normalize
    vecs = jnp.asarray([[0.0, 0, 0], [1e-20, 0, 0], [1e-4, -1e-4, 2e-4], [0, 0, np.pi], [0.3, np.pi / 2, 0]], dtype)
    groups = [(_from_matrix_all, mats), (_from_quat_all, quats), (_from_vector_all, vecs)]
    if dtype == "float64":  # the dtype-dependent thresholds matter most at gimbal lock
        groups = [(functools.partial(_from_matrix_all, orders=("ZYX", "ZYZ")), mats)]
    for f, x in groups:
        g = _grads(f, x)
        assert g.dtype == dtype
        bad = ~np.all(np.isfinite(np.asarray(g).reshape(len(x), -1)), axis=-1)
        assert not bad.any(), (f, np.asarray(x)[bad])


def test_gradients_match_finite_differences(x64):
    """Reverse-mode gradients of composite conversions against central differences."""
    rng = np.random.default_rng(14)
    angles = random_angles(rng, 5)
    v = rng.normal(size=(5, 3))
    x0 = jnp.asarray(np.concatenate([angles, v, 1e-5 * v]))  # small ones: in the Taylor branches
    w = jnp.asarray(rng.normal(size=(15, 3)))

    def parts(x):  # four scalars, each exercising a different chain
        a, e, s = x[:5], x[5:10], x[10:]
        return jnp.stack(
            [
                jnp.sum(w[:5] * rot.euler_from_quat(rot.quat_from_euler(a, "XZY"), "XZY")),
                jnp.sum(w[5:10] * rot.euler_from_matrix(rot.matrix_from_expmap(e), "ZXZ")),
                jnp.sum(w[:5] * rot.expmap_from_matrix(rot.matrix_from_euler(a, "YXZ"))),
                jnp.sum(w[10:] * rot.expmap_from_quat(rot.quat_from_expmap(s))),
            ]
        )

    jac = jax.jit(jax.jacrev(parts), compiler_options=_FAST_COMPILE)(x0)  # [4, 15, 3]
    f = jax.jit(parts, compiler_options=_FAST_COMPILE)
    scale = jnp.asarray([1.0] * 10 + [1e-5] * 5)[:, None]  # step relative to the input's size
    for d in rng.normal(size=(3, 15, 3)):
        d = jnp.asarray(d) * scale
        h = 1e-6
        fd = (f(x0 + h * d) - f(x0 - h * d)) / (2 * h)
        np.testing.assert_allclose(jnp.sum(jac * d[None], axis=(1, 2)), fd, rtol=1e-6, atol=1e-9)


def test_jacobians_closed_form(x64):
    """d exp(v)/dv at 0 is the hat of the basis; log o exp has identity Jacobian (angle < pi)."""
    hat = np.array(
        [
            [[0, 0, 0], [0, 0, -1], [0, 1, 0]],
            [[0, 0, 1], [0, 0, 0], [-1, 0, 0]],
            [[0, -1, 0], [1, 0, 0], [0, 0, 0]],
        ],
        dtype=np.float64,
    )
    points = np.array([[0.0, 0.0, 0.0], [1e-4, -2e-4, 3e-5], [1.0, -2.0, 0.5]])

    def jacobians(v):
        return (
            jax.jacobian(rot.matrix_from_expmap)(v),
            jax.jacobian(lambda v: rot.expmap_from_matrix(rot.matrix_from_expmap(v)))(v),
        )

    for dtype, atol in ((jnp.float32, 2e-5), (jnp.float64, 1e-12)):
        exp_jac, log_exp_jac = jax.jit(jax.vmap(jacobians), compiler_options=_FAST_COMPILE)(jnp.asarray(points, dtype))
        np.testing.assert_allclose(np.moveaxis(exp_jac[0], -1, 0), hat, atol=atol)
        np.testing.assert_allclose(log_exp_jac, np.broadcast_to(np.eye(3), (3, 3, 3)), atol=atol)


# ---------------------------------------------------------------------- jit, vmap, dtypes


def _all_functions():
    order = "YXZ"
    return [
        (lambda x: rot.matrix_from_euler(x, order), (3,)),
        (lambda x: rot.quat_from_euler(x, order), (3,)),
        (lambda x: rot.euler_from_matrix(x, order), (3, 3)),
        (lambda x: rot.euler_from_quat(x, "ZYZ"), (4,)),
        (rot.quat_from_matrix, (3, 3)),
        (rot.matrix_from_quat, (4,)),
        (rot.quat_from_expmap, (3,)),
        (rot.expmap_from_quat, (4,)),
        (rot.matrix_from_expmap, (3,)),
        (rot.expmap_from_matrix, (3, 3)),
        (rot.quat_conjugate, (4,)),
        (rot.quat_normalize, (4,)),
        (lambda q: rot.quat_multiply(q, q[::-1]), (4,)),
        (lambda q: rot.quat_apply(q, q[1:]), (4,)),
        (lambda m: rot.matrix_multiply(m, m.T), (3, 3)),
        (lambda v: rot.quat_from_axis_angle(v, v[0]), (3,)),
        (lambda q: rot.quat_slerp(q, q[::-1], 0.3), (4,)),
        (lambda x: rot.make_quat_continuous(jnp.stack([x, -x])), (4,)),
        (lambda x: rot.make_expmap_continuous(jnp.stack([x, x * (1 - 2 * math.pi)])), (3,)),
    ]


def test_jit_and_vmap():
    """jit(vmap(f))(x)[i] == f(x[i]) (eager), in one compile, for the functions with structure
    beyond elementwise arithmetic (gathers, argmax, scans, explicit broadcasting, static orders)."""
    rng = np.random.default_rng(15)
    fns = [_all_functions()[i] for i in (2, 3, 4, 7, 13, 14, 15, 16, 17, 18)]
    xs = [jnp.asarray(rng.normal(size=(4, *shape)), jnp.float32) for _, shape in fns]
    batched = jax.jit(lambda xs: [jax.vmap(f)(x) for (f, _), x in zip(fns, xs)])(xs)
    for (f, _), x, out in zip(fns, xs, batched):
        assert out.dtype == jnp.float32
        for i in (0, 3):
            np.testing.assert_allclose(out[i], f(x[i]), rtol=1e-5, atol=1e-6)


def test_dtypes_preserved(x64):
    """float32 in, float32 out (even under x64); float64 in, float64 out (traced, not run)."""
    for f, shape in _all_functions():
        for dtype in (jnp.float32, jnp.float64):
            assert jax.eval_shape(f, jax.ShapeDtypeStruct(shape, dtype)).dtype == dtype


def test_integer_input_becomes_float():
    assert rot.matrix_from_euler(jnp.array([0, 1, 2]), "XYZ").dtype == jnp.float32


def test_matrix_multiply_under_nested_vmap():
    """The XLA CPU bug pattern (STYLE.md): a parent-chain product under jit(vmap(vmap))."""
    rng = np.random.default_rng(17)
    mats = Rotation.random(4 * 3 * 5, rng=17).as_matrix().reshape(4, 3, 5, 3, 3)
    parents = (-1, 0, 1, 1, 3)

    def chain(R):  # [J, 3, 3] local -> world, one character, one frame
        for j, p in enumerate(parents):
            if p >= 0:
                R = R.at[j].set(rot.matrix_multiply(R[p], R[j]))
        return R

    got = jax.jit(jax.vmap(jax.vmap(chain)))(jnp.asarray(mats, jnp.float32))
    want = mats.copy()
    for j, p in enumerate(parents):
        if p >= 0:
            want[:, :, j] = want[:, :, p] @ want[:, :, j]
    np.testing.assert_allclose(got, want, atol=1e-5)
    a, b = rng.normal(size=(2, 7, 3, 3))
    a32, b32 = jnp.asarray(a, jnp.float32), jnp.asarray(b, jnp.float32)
    np.testing.assert_allclose(rot.matrix_multiply(a32, b32), a @ b, atol=1e-5)
    np.testing.assert_allclose(rot.matrix_multiply(a32[0], b32), a[0] @ b, atol=1e-5)


# -------------------------------------------------------------------------------- errors


@pytest.mark.parametrize("bad", ["zyx", "XYZW", "XXY", "", 3, None])
def test_bad_order_raises(bad):
    with pytest.raises(UserError, match="order"):
        rot.matrix_from_euler(jnp.zeros(3), bad)
    with pytest.raises(UserError, match="order"):
        rot.euler_from_quat(jnp.array([1.0, 0, 0, 0]), bad)


def test_lower_case_order_hint():
    with pytest.raises(UserError, match="extrinsic"):
        rot.quat_from_euler(jnp.zeros(3), "zyx")


@pytest.mark.parametrize(
    "call, name",
    [
        (lambda: rot.matrix_from_euler(jnp.zeros(4), "XYZ"), "angles"),
        (lambda: rot.euler_from_matrix(jnp.zeros((3, 4)), "XYZ"), "R"),
        (lambda: rot.quat_from_matrix(jnp.zeros(9)), "R"),
        (lambda: rot.matrix_from_quat(jnp.zeros(3)), "q"),
        (lambda: rot.quat_multiply(jnp.zeros(4), jnp.zeros(3)), "q2"),
        (lambda: rot.quat_apply(jnp.zeros(4), jnp.zeros(4)), "v"),
        (lambda: rot.quat_from_expmap(jnp.zeros(())), "v"),
        (lambda: rot.matrix_multiply(jnp.zeros((3, 3)), jnp.zeros((2, 3))), "a"),
        (lambda: rot.quat_from_euler(jnp.zeros(3, jnp.complex64), "XYZ"), "angles"),
    ],
)
def test_bad_shapes_raise(call, name):
    with pytest.raises(UserError, match=rf"\b{name}\b"):
        call()


def test_euler_twin_is_the_same_rotation():
    """The other triple of every order gives the same rotation (checked with scipy), NumPy in
    NumPy out, JAX in JAX out."""
    rng = np.random.default_rng(7)
    a = rng.uniform(-1.2, 1.2, (5, 3))
    for order in rot.EULER_ORDERS:
        twin = rot.euler_twin(a, order)
        assert isinstance(twin, np.ndarray)
        np.testing.assert_allclose(Rotation.from_euler(order, twin).as_matrix(),
                                   Rotation.from_euler(order, a).as_matrix(), atol=1e-12)
        assert isinstance(rot.euler_twin(jnp.asarray(a, jnp.float32), order), jax.Array)


# ----------------------------------------------------------- tiny quaternions (issue 24)

_TINY_FUNCTIONS = {
    "quat_normalize": rot.quat_normalize,
    "expmap_from_quat": rot.expmap_from_quat,
    "quat_power": lambda q: rot.quat_power(q, jnp.asarray(0.3, q.dtype)),
    "quat_from_axis_angle": lambda q: rot.quat_from_axis_angle(q[1:], q[0] + jnp.asarray(0.7, q.dtype)),
}


def _tiny_quats(dtype: str, lowest: int) -> jnp.ndarray:
    """Quaternions of norm 10**e for e from `lowest` to 0, in four directions, plus the norms
    just above and below `zero_norm_threshold`."""
    dirs = np.array([[1, 0, 0, 0], [0.6, 0.8, 0, 0], [0.1, 0.2, -0.3, 0.9], [-0.5, 0.5, -0.5, 0.5]], float)
    dirs /= np.linalg.norm(dirs, axis=1, keepdims=True)
    thr = rot.zero_norm_threshold(dtype)
    norms = np.concatenate([10.0 ** np.linspace(lowest, 0, 4 * abs(lowest) // 5 + 1), [thr * 0.99, thr * 1.01]])
    return jnp.asarray((norms[:, None, None] * dirs[None]).reshape(-1, 4), dtype)


@pytest.mark.parametrize("name", sorted(_TINY_FUNCTIONS))
@pytest.mark.parametrize("dtype, lowest", [("float32", -30), ("float64", -300)])
def test_tiny_quaternions_have_finite_values_and_gradients(x64, name, dtype, lowest):
    f = _TINY_FUNCTIONS[name]
    q = _tiny_quats(dtype, lowest)
    value = jax.vmap(f)(q)
    rev = jax.vmap(jax.jacrev(f))(q)
    fwd = jax.vmap(jax.jacfwd(f))(q)
    for what, x in (("value", value), ("jacrev", rev), ("jacfwd", fwd)):
        bad = ~np.isfinite(np.asarray(x)).reshape(len(q), -1).all(axis=1)
        assert not bad.any(), (name, what, np.linalg.norm(np.asarray(q, float)[bad], axis=1))


@pytest.mark.parametrize("dtype", ["float32", "float64"])
def test_tiny_quaternions_below_the_threshold_are_the_identity(x64, dtype):
    thr = rot.zero_norm_threshold(dtype)
    assert thr == pytest.approx(float(jnp.finfo(dtype).tiny) ** 0.25)
    below = jnp.asarray([1e-20 if dtype == "float32" else 1e-200, 0, 0, 0], dtype)
    np.testing.assert_array_equal(rot.expmap_from_quat(below), np.zeros(3))  # NaN before issue 24
    np.testing.assert_array_equal(rot.quat_normalize(below * 0.5), [1, 0, 0, 0])
    np.testing.assert_array_equal(rot.quat_power(below, 0.5), [1, 0, 0, 0])
    # Just above it, the rotation of a scaled quaternion is the rotation of the unit one.
    q = jnp.asarray([0.1, 0.2, -0.3, 0.9], dtype) / np.linalg.norm([0.1, 0.2, -0.3, 0.9])
    rtol = 1e-5 if dtype == "float32" else 1e-12
    np.testing.assert_allclose(rot.expmap_from_quat(q * thr * 4), rot.expmap_from_quat(q), rtol=rtol)
    np.testing.assert_allclose(rot.quat_power(q * thr * 4, 0.3), rot.quat_power(q, 0.3), rtol=rtol, atol=1e-7)
    np.testing.assert_allclose(rot.quat_normalize(q * thr * 4), q, rtol=rtol)
