"""Up-axis conversion at the edge (fourierjax.io.axes): exact, root-only, invertible."""

import dataclasses

import jax
import numpy as np
import pytest

import fourierjax.data
from fourierjax.errors import UserError
from fourierjax.io.axes import from_y_up, rotate_root, to_y_up, up_rotation
from fourierjax.kinematics import fk_frames
from fourierjax.skeleton import Topology

UPS = ("z", "-z", "x", "-x", "y", "-y")


def _fk(motion):
    with jax.enable_x64(True):
        fk = fk_frames(motion.skeleton(), motion.channels)
        return np.asarray(fk.positions), np.asarray(fk.end_site_positions)


@pytest.fixture(scope="module")
def clip():
    return fourierjax.data.load("07_01")[:60]


@pytest.mark.parametrize("up", UPS)
def test_up_rotation_takes_up_to_y(up):
    R = up_rotation(up)
    v = np.zeros(3)
    v["xyz".index(up[-1])] = -1.0 if up.startswith("-") else 1.0
    np.testing.assert_allclose(R @ v, [0.0, 1.0, 0.0], atol=0)
    np.testing.assert_allclose(R @ R.T, np.eye(3), atol=0)
    assert np.linalg.det(R) == pytest.approx(1.0)


@pytest.mark.parametrize("up", UPS)
def test_fk_of_converted_equals_rotated_original(clip, up):
    p0, e0 = _fk(clip)
    for convert, R in ((to_y_up, up_rotation(up)), (from_y_up, up_rotation(up).T)):
        p1, e1 = _fk(convert(clip, up))
        np.testing.assert_allclose(p1, p0 @ R.T, atol=1e-5)
        np.testing.assert_allclose(e1, e0 @ R.T, atol=1e-5)


def test_only_the_root_changes_and_back_is_identity(clip):
    z = from_y_up(clip, "z")
    first_child = clip.topology.channel_offsets[1]
    np.testing.assert_array_equal(z.channels[:, first_child:], clip.channels[:, first_child:])
    np.testing.assert_array_equal(z.offsets[1:], clip.offsets[1:])
    np.testing.assert_array_equal(z.end_site_offsets, clip.end_site_offsets)
    assert z.topology == clip.topology
    back = to_y_up(z, "z")
    np.testing.assert_allclose(_fk(back)[0], _fk(clip)[0], atol=1e-9)
    np.testing.assert_allclose(back.channels[:, :3], clip.channels[:, :3], atol=1e-9)


def test_z_up_clip_stands_along_z(clip):
    p, _ = _fk(from_y_up(clip, "z"))
    head, foot = clip.topology.index("Head"), clip.topology.index("LeftFoot")
    assert (p[:, head, 2] - p[:, foot, 2]).min() > 10.0  # head above the foot along +Z (CMU units)
    assert np.ptp(p[:, 0, 2]) < 0.2 * np.ptp(p[:, 0, 1])  # the root travels along -Y and bobs along Z


def test_refuses_what_it_cannot_reexpress(clip):
    with pytest.raises(UserError, match="proper 3x3 rotation"):
        rotate_root(clip, np.diag([1.0, 1.0, -1.0]))
    with pytest.raises(UserError, match="x, y, z"):
        up_rotation("w")
    t = clip.topology
    one_pos = Topology(t.names, t.parents, (("Yposition", "Zrotation", "Yrotation", "Xrotation"),) + t.channels[1:],
                       t.end_site_parents)
    m = dataclasses.replace(clip, topology=one_pos, channels=clip.channels[:, 2:])
    with pytest.raises(UserError, match="1 position channel"):
        to_y_up(m, "z")
    no_rot = Topology(t.names, t.parents, (("Xposition", "Yposition", "Zposition"),) + t.channels[1:],
                      t.end_site_parents)
    m = dataclasses.replace(clip, topology=no_rot, channels=np.delete(clip.channels, [3, 4, 5], axis=1))
    with pytest.raises(UserError, match="rotation channels"):
        to_y_up(m, "z")
    assert np.array_equal(to_y_up(m, "y").channels, m.channels)  # the identity needs no rotation channels
