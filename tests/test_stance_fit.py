"""Fitting shape classes and amplitudes to a target pose (synthetic oracle and a CMU frame)."""

import jax.numpy as jnp
import numpy as np
import pytest

from fourierjax.stance.fit import (
    COMBINATIONS,
    cmu_torso_directions,
    fit_torso,
    torso_directions,
)
from fourierjax.stance.skeleton48 import make_body
from fourierjax.stance.torso import class_weights

BODY = make_body(1.75)


@pytest.fixture(scope="module")
def synthetic():
    amps = jnp.array([0.8, -0.5, 0.3, 0.2, -0.15, 0.0])
    dirs = torso_directions(BODY, amps, class_weights("sagittal", "small_c"),
                            class_weights("coronal", "large_s"), jnp.array([1.0, -1.0]))  # fmt: skip
    return amps, fit_torso(BODY, dirs)


def test_fit_recovers_classes_and_amplitudes(synthetic):
    amps, fit = synthetic
    d = fit.describe()
    assert (d["sagittal_class"], d["coronal_class"]) == ("small_c", "large_s")
    assert (d["collar_y"], d["collar_z"]) == ("aligned", "opposed")
    np.testing.assert_allclose(fit.amplitudes[:5], amps[:5], atol=1e-3)
    assert d["rms_direction_error"] < 1e-4
    assert len(fit.residuals) == len(COMBINATIONS) == 100


def test_fit_a_cmu_frame():
    from fourierjax.data import load

    motion = load("07_01")
    dirs = cmu_torso_directions(BODY, motion, frame=150)
    assert np.allclose(np.linalg.norm(dirs, axis=-1), 1.0)
    fit = fit_torso(BODY, jnp.asarray(dirs, jnp.float32))
    d = fit.describe()
    assert np.isfinite(d["rms_direction_error"]) and d["rms_direction_error"] < 0.2
    # The fit explains the frame better than the neutral pose does.
    neutral = np.asarray(torso_directions(BODY, jnp.zeros(6), jnp.zeros(4), jnp.zeros(4), jnp.ones(2)))
    assert d["rms_direction_error"] <= np.sqrt(np.mean((neutral - dirs) ** 2)) + 1e-6


def test_torso_points_from_the_body_map():
    """The map's joints are the CMU joints this fit read by name before (CMU results unchanged)."""
    from fourierjax.body import infer_body_map
    from fourierjax.data import load
    from fourierjax.stance.fit import torso_points

    motion = load("07_01")
    names = motion.topology.names
    pts = torso_points(infer_body_map(motion), motion.topology)
    got = {k: tuple(names[j] for j in v) for k, v in pts.items()}
    assert got == {
        "r_hip": ("RightUpLeg",), "l_hip": ("LeftUpLeg",), "abdomen": ("LowerBack",), "chest": ("Spine",),
        "neck": ("Neck",), "head": ("Neck1",), "head_top": ("Head",), "r_collar": ("RightShoulder",),
        "r_shoulder": ("RightArm",), "l_collar": ("LeftShoulder",), "l_shoulder": ("LeftArm",),
    }  # fmt: skip


def test_torso_directions_of_a_renamed_rig_equal_cmu():
    from fourierjax.data import load
    from tests.conventions import convert

    motion = load("07_01")
    ref = cmu_torso_directions(BODY, motion, frame=150)
    for convention in ("mixamo", "daz"):
        got = cmu_torso_directions(BODY, convert(motion, convention), frame=150)
        np.testing.assert_allclose(got, ref, atol=1e-6)
