"""The MJX baseline of the FK benchmark: the MJCF model of a BVH skeleton poses like fourierjax."""

import numpy as np
import pytest

from experiments.benchmarks import mjx
from fourierjax import data


def test_mjcf_has_one_body_per_joint_and_one_joint_per_channel():
    motion = data.load("07_01", raw=True)
    xml = mjx.mjcf(motion.topology, motion.offsets)
    assert xml.count("<body ") == motion.topology.num_joints
    assert xml.count("<joint ") == motion.topology.num_channels
    assert xml.count('type="slide"') == sum(c.endswith("position") for c in motion.topology.flat_channel_names)


def test_mjx_positions_equal_fourierjax():
    reason = mjx.available()
    if reason is not None:
        pytest.skip(reason)
    import jax.numpy as jnp

    from fourierjax import kinematics

    motion = data.load("07_01", raw=True)
    skel = motion.skeleton()
    ch = np.asarray(motion.channels[:16], np.float32)
    fn, qpos_of = mjx.mjx_positions_fn(motion.topology, np.asarray(motion.offsets))
    got = np.asarray(fn(qpos_of(ch)))
    ref = np.asarray(kinematics.joint_positions(skel, jnp.asarray(ch)))
    np.testing.assert_allclose(got, ref, atol=1e-3)
    assert np.abs(ref).max() > 1.0
