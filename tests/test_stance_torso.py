"""Spine shape classes (paper appendix tables), collars, penalties, arms, gaze."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from fourierjax.errors import UserError
from fourierjax.stance import _util as u
from fourierjax.stance.arms import arm_to_target, elbow_flexion
from fourierjax.stance.gaze import gaze_rotation
from fourierjax.stance.penalties import (
    HermitePenalty,
    hermite_penalty,
    quadratic_penalty,
    reach_penalty,
)
from fourierjax.stance.torso import (
    CORONAL_WEIGHTS,
    SAGITTAL_WEIGHTS,
    class_weights,
    collar_quats,
    spine_quats,
)

# Neff & Fiume 2004, appendix "Shape Class Weights", typed in from the paper's tables.
PAPER_SAGITTAL = """
Large S .15 -.1 -.12 -.1
Large C .15 .15 .15 .1
Small S .15 -.2 .06 -.1
Small C -.15 .3 .15 .1
Straight 0 0 0 0
"""
PAPER_CORONAL = """
Large S .08 -.1 -.12 -.06
Large C .15 .15 .12 .06
Small S .15 -.2 .12 .06
Small C -.15 .3 .12 .06
Straight 0 0 0 0
"""


def _parse(table):
    out = {}
    for line in table.strip().splitlines():
        parts = line.split()
        name = "_".join(parts[:-4]).lower() if parts[0] != "Straight" else "straight"
        out[name] = tuple(float(x) for x in parts[-4:])
    return out


def test_weight_tables_are_the_papers():
    assert dict(SAGITTAL_WEIGHTS) == _parse(PAPER_SAGITTAL)
    assert dict(CORONAL_WEIGHTS) == _parse(PAPER_CORONAL)


def test_spine_dofs_are_amplitude_times_weight():
    sag_w, cor_w = class_weights("sagittal", "small_c"), class_weights("coronal", "large_s")
    R = spine_quats(0.7, -0.4, 0.8, 0.05, sag_w, cor_w)
    zxy = Rotation.from_matrix(np.asarray(R, np.float64)).as_euler("ZXY")
    np.testing.assert_allclose(zxy[:, 1], 0.7 * np.array(SAGITTAL_WEIGHTS["small_c"]) + [0.05, 0, 0, 0], atol=1e-6)
    np.testing.assert_allclose(zxy[:, 0], -0.4 * np.array(CORONAL_WEIGHTS["large_s"]), atol=1e-6)
    np.testing.assert_allclose(zxy[:, 2], 0.2, atol=1e-6)  # transverse spread evenly over 4


def test_unknown_class_names_the_choices():
    with pytest.raises(UserError, match="large_s"):
        class_weights("sagittal", "huge_s")


def test_collars_aligned_and_opposed():
    def ends(y, z, signs):
        R = np.asarray(collar_quats(y, z, jnp.array(signs)))
        return R[0] @ [-1.0, 0, 0], R[1] @ [1.0, 0, 0]  # right collar points -X, left +X

    r, le = ends(0.0, 0.3, [1.0, 1.0])  # aligned Z: a shrug, both shoulders up
    assert r[1] > 0.2 and le[1] > 0.2
    r, le = ends(0.0, 0.3, [1.0, -1.0])  # opposed Z: left up, right down
    assert le[1] > 0.2 and r[1] < -0.2
    r, le = ends(0.3, 0.0, [1.0, 1.0])  # aligned Y: both shoulders forward
    assert r[2] > 0.2 and le[2] > 0.2
    r, le = ends(0.3, 0.0, [-1.0, 1.0])  # opposed Y: right forward, left back (a twist)
    assert r[2] > 0.2 and le[2] < -0.2


# ----------------------------------------------------------------------------- penalties


def test_quadratic_penalty_is_exact_parabola_then_linear():
    p = quadratic_penalty(0.3, 0.2)
    x = jnp.linspace(0.3 - 0.5, 0.3 + 0.5, 101)
    np.testing.assert_allclose(hermite_penalty(p, x), ((x - 0.3) / 0.2) ** 2, rtol=1e-5, atol=1e-6)
    far = hermite_penalty(p, jnp.array([0.3 + 1.0, 0.3 + 2.0]))
    np.testing.assert_allclose(far[1] - far[0], 2 * 2.5 / 0.2, rtol=1e-5)  # slope kept


def test_penalty_is_c1_with_flat_basin_and_asymmetry():
    p = HermitePenalty(
        desired=jnp.asarray(0.0),
        widths=jnp.array([[0.5, 0.2], [0.1, 0.1]]),
        values=jnp.array([[0.01, 1.0], [2.0, 50.0]]),
        slopes=jnp.array([[0.05, 20.0], [30.0, 600.0]]),
    )
    f = lambda x: hermite_penalty(p, x)  # noqa: E731
    g = jax.vmap(jax.grad(f))
    knots = jnp.array([-0.7, -0.5, 0.0, 0.1, 0.2])
    eps = 1e-9
    with jax.enable_x64(True):
        k = knots.astype(jnp.float64)
        np.testing.assert_allclose(g(k - eps), g(k + eps), atol=1e-4)  # slope continuous
        np.testing.assert_allclose(jax.vmap(f)(k - 1e-9), jax.vmap(f)(k + 1e-9), atol=1e-6)
    assert float(f(-0.4)) < 0.02  # flat basin on the left
    assert float(f(0.15)) > 10.0  # steep wall on the right
    np.testing.assert_allclose([f(-0.5), f(0.1), f(0.2)], [0.01, 2.0, 50.0], rtol=1e-6)


def test_reach_penalty_walls_beyond_the_arm():
    p = reach_penalty(0.55)
    assert abs(float(p(0.8 * 0.55))) < 1e-6
    assert float(p(0.5 * 0.55)) < 0.5
    assert float(p(1.0 * 0.55)) > 5.0
    np.testing.assert_allclose(float(p(1.07 * 0.55)), 60.0, rtol=1e-4)


# ---------------------------------------------------------------------------------- arms


def test_elbow_flexion_law_of_cosines(x64):
    a, b = 0.3, 0.27
    for d in (0.1, 0.35, 0.5, 0.569):
        flex, alpha = elbow_flexion(a, b, d)
        interior = np.pi - float(flex)
        np.testing.assert_allclose(a * a + b * b - 2 * a * b * np.cos(interior), d * d, rtol=1e-6)


def test_arm_reaches_target_and_points_at_unreachable(x64):
    shoulder = jnp.array([-0.19, 1.42, 0.0])
    Rp = jnp.eye(3)
    for target, reach in (([-0.3, 1.2, 0.35], True), ([-0.5, 1.6, 1.5], False)):
        t = jnp.array(target)
        R_sh, R_el, gap = arm_to_target(shoulder, Rp, 0.28, 0.27, t, 0.3, jnp.array([-1.0, 0, 0]))
        for R in (R_sh, R_el):  # proper rotations (the upper arm's X axis is built, not crossed)
            np.testing.assert_allclose(R @ R.T, np.eye(3), atol=1e-12)
            np.testing.assert_allclose(np.linalg.det(R), 1.0, atol=1e-12)
        elbow = shoulder + R_sh @ jnp.array([0, -0.28, 0])
        wrist = elbow + (R_sh @ R_el) @ jnp.array([0, -0.27, 0])
        assert np.isfinite(np.asarray(wrist)).all()
        if reach:
            assert float(gap) == 0.0
            np.testing.assert_allclose(wrist, t, atol=1e-9)
        else:
            assert float(gap) > 0.5
            d = (wrist - shoulder) / jnp.linalg.norm(wrist - shoulder)
            c = (t - shoulder) / jnp.linalg.norm(t - shoulder)
            assert float(d @ c) > 1 - 1e-6  # straight arm pointing at the target


def test_gaze_weight_blends_rest_to_full_alignment(x64):
    R0 = jnp.eye(3)
    head = jnp.array([0.0, 1.6, 0.0])
    point = jnp.array([1.0, 1.6, 1.0])
    full = gaze_rotation(R0, jnp.eye(3), head, point, 1.0)
    np.testing.assert_allclose(full @ jnp.array([0, 0, 1.0]), u.safe_normalize(point - head, head), atol=1e-9)
    np.testing.assert_allclose(gaze_rotation(R0, jnp.eye(3), head, point, 0.0), R0, atol=1e-9)
    half = Rotation.from_matrix(np.asarray(gaze_rotation(R0, jnp.eye(3), head, point, 0.5)))
    np.testing.assert_allclose(half.magnitude(), np.pi / 8, atol=1e-9)  # half of 45 deg yaw


def test_gaze_is_a_slerp_toward_the_look_at_frame_at_any_angle(x64):
    """Against scipy: R_a (R_a^T R_b)^w for random shape poses and parent frames, weights in and
    beyond [0, 1], and relative rotations up to a hair below 180 degrees."""
    rng = np.random.default_rng(3)
    for i in range(40):
        R_parent = Rotation.random(random_state=rng).as_matrix()
        head = rng.normal(size=3)
        point = head + rng.normal(size=3)
        fwd = (point - head) / np.linalg.norm(point - head)
        side = np.cross([0.0, 1.0, 0.0], fwd)
        side /= np.linalg.norm(side)
        R_b = R_parent.T @ np.stack([side, np.cross(fwd, side), fwd], axis=-1)
        if i % 4 == 0:  # the shape pose turned almost 180 degrees away from the look-at frame
            axis = rng.normal(size=3)
            turn = np.pi - 10.0 ** -rng.uniform(1, 6)
            R_a = R_b @ Rotation.from_rotvec(axis / np.linalg.norm(axis) * turn).as_matrix()
        else:
            R_a = Rotation.random(random_state=rng).as_matrix()
        w = rng.uniform(-0.5, 1.5)
        delta = Rotation.from_matrix(R_a.T @ R_b).as_rotvec()
        expected = R_a @ Rotation.from_rotvec(w * delta).as_matrix()
        got = gaze_rotation(jnp.asarray(R_a), jnp.asarray(R_parent), jnp.asarray(head), jnp.asarray(point), w)
        np.testing.assert_allclose(np.asarray(got), expected, atol=1e-9)
