"""FK compiles once per clip-length bucket (issue 26): the frames of a concrete batch are padded
to `length_bucket` and cut back. Counted with the entry points' trace counters and JAX's compile
events, never with a clock."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from jax import monitoring

from fourierjax import data, kinematics
from fourierjax._fourier._buckets import length_bucket
from fourierjax.motion import motion_joint_positions
from tests.helpers import reference_fk

# Ten clip lengths, all in the 128-frame bucket.
LENGTHS = (65, 70, 77, 83, 90, 99, 104, 111, 120, 127)


@pytest.fixture(scope="module")
def walk():
    m = data.load("07_01", raw=True)
    return m, m.skeleton()


class _Compiles:
    """Counts XLA backend compilations (every program, eager ops included) inside a `with`."""

    def __enter__(self):
        self.events = []
        self._listener = lambda event, duration_secs, **_: self.events.append(event)
        monitoring.register_event_duration_secs_listener(self._listener)
        return self

    def __exit__(self, *exc):
        monitoring.unregister_event_duration_listener(self._listener)

    @property
    def count(self):
        return self.events.count("/jax/core/compile/backend_compile_duration")


def test_ten_clip_lengths_in_one_bucket_compile_fk_once(walk):
    m, skel = walk
    assert {length_bucket(n) for n in LENGTHS} == {128}
    ch = np.asarray(m.channels, np.float32)
    before = (kinematics.joint_positions.num_traces(), kinematics.fk_frames.num_traces())

    def run(n):
        return (kinematics.joint_positions(skel, ch[:n]),
                kinematics.fk_frames(skel, jax.device_put(ch[5:5 + n])),
                motion_joint_positions(m[10:10 + n]))

    first = run(LENGTHS[0])  # compiles the bucket (unless an earlier test did) and the eager ops
    with _Compiles() as c:
        rest = [run(n) for n in LENGTHS[1:]]
    after = (kinematics.joint_positions.num_traces(), kinematics.fk_frames.num_traces())
    out, fk, clips = (dict(zip(LENGTHS, r)) for r in zip(first, *rest))
    # At most one trace of each entry point for the ten lengths, and on CPU no program at all
    # for the nine after the first: the padding and the cut are NumPy copies.
    assert after[0] - before[0] <= 1 and after[1] - before[1] <= 1
    if jax.default_backend() == "cpu":
        assert c.count == 0, c.events
    # Padding is exact: every length equals the independent reference.
    ref, ends = reference_fk(m.topology, m.offsets, m.end_site_offsets, ch[:140])
    for n in LENGTHS:
        assert out[n].shape == (n, 31, 3) and isinstance(out[n], jax.Array)
        np.testing.assert_allclose(out[n], ref[:n], atol=1e-4)
        assert fk[n].positions.shape == (n, 31, 3) and fk[n].rotations.shape == (n, 31, 4)
        np.testing.assert_allclose(fk[n].positions, ref[5:5 + n], atol=1e-4)
        np.testing.assert_allclose(clips[n], ref[10:10 + n], atol=1e-4)
    np.testing.assert_allclose(fk[70].end_site_positions, ends[5:75], atol=1e-4)


def test_batch_axes_are_flattened_into_one_bucket(walk):
    # [2, 50, C], [100, C] and [4, 25, C] all pad to 128 frames: one program for all three.
    m, skel = walk
    ch = np.asarray(m.channels[:100], np.float32)
    kinematics.joint_positions(skel, ch)
    before = kinematics.joint_positions.num_traces()
    a = kinematics.joint_positions(skel, ch.reshape(2, 50, -1))
    b = kinematics.joint_positions(skel, jax.device_put(ch.reshape(4, 25, -1)))
    assert kinematics.joint_positions.num_traces() == before
    assert a.shape == (2, 50, 31, 3) and b.shape == (4, 25, 31, 3)
    full = np.asarray(kinematics.joint_positions(skel, ch))
    np.testing.assert_array_equal(np.asarray(a).reshape(100, 31, 3), full)
    np.testing.assert_array_equal(np.asarray(b).reshape(100, 31, 3), full)


def test_traced_batches_are_not_padded(walk):
    m, skel = walk
    ch = jnp.asarray(m.channels[:37], jnp.float32)
    # Inside jit, vmap or grad the caller's program has one shape: the FK is staged into it
    # unpadded (traced only: compiling it again here would cost minutes of CI).
    jaxpr = jax.make_jaxpr(lambda c: kinematics.joint_positions(skel, c))(ch)
    shapes = {tuple(v.aval.shape) for eqn in jaxpr.eqns for v in eqn.outvars}
    assert (37, 31, 3) in shapes and not any(s[:1] == (64,) for s in shapes)


def test_batches_above_the_limit_keep_their_shape(walk, monkeypatch):
    # Above PAD_LIMIT frames a batch compiles for its own shape (padding would double the work).
    m, skel = walk
    seen = []

    def spy(skeleton, channels):
        seen.append(channels.shape)
        return jax.device_put(np.zeros((*channels.shape[:-1], 31, 3), np.float32))

    monkeypatch.setattr(kinematics, "_joint_positions_jit", spy)
    ch = np.asarray(m.channels[:37], np.float32)
    assert kinematics.joint_positions(skel, ch).shape == (37, 31, 3)
    monkeypatch.setattr(kinematics, "PAD_LIMIT", 32)
    assert kinematics.joint_positions(skel, ch).shape == (37, 31, 3)
    assert seen == [(64, 96), (37, 96)]


def test_frames_last_lengths_in_one_bucket_compile_once(walk):
    m, skel = walk
    before = kinematics.joint_positions_frames_last.num_traces()
    for n in LENGTHS[:4]:
        ch = np.asarray(m.channels[:n], np.float32)
        got = kinematics.joint_positions_frames_last(skel, jnp.asarray(ch.T))
        assert got.shape == (m.topology.num_joints, 3, n)
        np.testing.assert_allclose(np.moveaxis(np.asarray(got), -1, 0), kinematics.joint_positions(skel, ch),
                                   atol=1e-4)
    assert kinematics.joint_positions_frames_last.num_traces() - before <= 1


def test_the_cut_puts_arrays_as_device_put_does(walk, monkeypatch):
    # `_to_device` (jaxlib's `batched_device_put`, less Python than `jax.device_put`) makes the
    # same arrays: uncommitted, on the default device, equal values; and without that private
    # function (another jaxlib) the cut falls back to `jax.device_put`.
    m, skel = walk
    ch = np.asarray(m.channels[:90], np.float32)
    fast = kinematics.fk_frames(skel, ch)
    ref = jax.device_put(np.zeros(3))
    for a in jax.tree.leaves(fast):
        assert isinstance(a, jax.Array) and a.shape[0] == 90
        assert a.committed == ref.committed and a.sharding == ref.sharding
    monkeypatch.setattr(kinematics, "_batched_device_put", None)
    slow = kinematics.fk_frames(skel, ch)

    def refuses(*args, **kwargs):
        raise TypeError("batched_device_put(): incompatible function arguments")

    monkeypatch.setattr(kinematics, "_batched_device_put", refuses)
    refused = kinematics.fk_frames(skel, ch)
    for a, b, c in zip(jax.tree.leaves(fast), jax.tree.leaves(slow), jax.tree.leaves(refused)):
        np.testing.assert_array_equal(a, b)
        np.testing.assert_array_equal(a, c)
        assert b.committed == c.committed == a.committed
