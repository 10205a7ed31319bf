"""Sharding the character axis over 4 forced CPU devices gives the same results as one device."""

import os
import subprocess
import sys
import textwrap

import jax
import numpy as np
import pytest

from fourierjax import parallel

# XLA_FLAGS must be set before JAX initialises its backends, so the multi-device check runs in a
# fresh interpreter.
_SCRIPT = textwrap.dedent(
    """
    import jax, jax.numpy as jnp, numpy as np
    from fourierjax import data, fourier, kinematics, parallel
    assert jax.device_count() == 4, jax.devices()
    mesh = parallel.data_mesh()
    assert mesh.shape == {"data": 4}

    # 6 clips (not a multiple of 4: exercises padding), band-limited with known omega.
    rng = np.random.default_rng(0)
    B, T, C, N = 6, 120, 5, 2
    dt = 1 / 60
    t = np.arange(T) * dt
    omega = rng.uniform(5.0, 8.0, size=B)
    x = np.zeros((B, T, C))
    for n in range(1, N + 1):
        a = rng.normal(size=(B, 1, C)); b = rng.normal(size=(B, 1, C))
        x += a * np.sin(n * omega[:, None, None] * t[None, :, None])
        x += b * np.cos(n * omega[:, None, None] * t[None, :, None])
    x = jnp.asarray(x, jnp.float32)
    kw = dict(grid_points=9, golden_iterations=12)
    one = fourier.fit_batch(x, dt, N, **kw)
    many = parallel.fit_batch_sharded(x, dt, N, mesh=mesh, **kw)
    assert many.omega_fit.shape == (B,)
    for a, b in zip(jax.tree.leaves(one), jax.tree.leaves(many)):
        np.testing.assert_allclose(np.asarray(a), np.asarray(b), rtol=2e-5, atol=2e-5)
    np.testing.assert_allclose(np.asarray(many.omega_fit), omega, rtol=1e-3)

    # Synthesis: padded 6 -> 8 over 4 devices; output sharded along the character axis.
    ts = jnp.linspace(0.0, 2.0, 50)
    ref = jax.vmap(fourier.synthesize, in_axes=(0, None))(one.model, ts)
    out = parallel.synthesize_sharded(one.model, ts, mesh=mesh)
    np.testing.assert_allclose(np.asarray(out), np.asarray(ref), rtol=1e-5, atol=1e-5)
    full = parallel.synthesize_sharded(fourier.stack_models([jax.tree.map(lambda v: v[0], one.model)] * 8), ts)
    assert len(full.sharding.device_set) == 4
    # Each device synthesizes its own characters: the compiled program has no collectives.
    eight = parallel.shard_batch(fourier.stack_models([jax.tree.map(lambda v: v[0], one.model)] * 8), mesh)
    hlo = jax.jit(fourier.synthesize_batch).lower(eight, jax.device_put(ts, parallel.replicated(mesh)))
    hlo = hlo.compile().as_text()
    assert not any(op in hlo for op in ("all-reduce", "all-gather", "collective-permute", "all-to-all"))
    rows = parallel.synthesize_sharded(one.model, jnp.stack([ts] * 6), mesh=mesh)  # times [B, T]
    np.testing.assert_allclose(np.asarray(rows), np.asarray(ref), rtol=1e-5, atol=1e-5)

    # Crowd pose: FK of 10 characters split over the devices.
    m = data.load("07_01")
    skel = m.skeleton()
    ch = jnp.asarray(m.channels[:10], jnp.float32)
    pos = parallel.crowd_positions_sharded(skel, ch, mesh=mesh)
    np.testing.assert_allclose(np.asarray(pos), np.asarray(kinematics.joint_positions(skel, ch)),
                               atol=1e-4)

    # A Crowd (synthesis + FK per device): 10 characters padded to 12 over 4 devices.
    from fourierjax import crowd
    rngc = np.random.default_rng(1)
    C = skel.topology.num_channels
    off = np.broadcast_to(m.channels.mean(0), (10, C)).astype(np.float32)
    amp = rngc.uniform(1.0, 10.0, size=(10, C, 2)).astype(np.float32)
    ph = rngc.uniform(-3.0, 3.0, size=(10, C, 2)).astype(np.float32)
    om = rngc.uniform(4.0, 8.0, size=10).astype(np.float32)
    models = fourier.FourierModel(jnp.asarray(off), jnp.asarray(amp), jnp.asarray(ph), jnp.asarray(om))
    cr = crowd.make_crowd(skel, models)
    many = parallel.crowd_positions_sharded(cr, 0.7, mesh=mesh)
    assert many.shape == (10, skel.topology.num_joints, 3)
    np.testing.assert_allclose(np.asarray(many), np.asarray(crowd.crowd_positions(cr, 0.7)), atol=1e-3)
    print("OK")
    """
)


@pytest.mark.timeout(240)
def test_sharded_equals_one_device_on_4_cpu_devices():
    env = dict(os.environ)
    env["XLA_FLAGS"] = (env.get("XLA_FLAGS", "") + " --xla_force_host_platform_device_count=4").strip()
    env["JAX_PLATFORMS"] = "cpu"
    proc = subprocess.run([sys.executable, "-c", _SCRIPT], env=env, capture_output=True, text=True,
                          timeout=230)
    assert proc.returncode == 0, proc.stderr[-4000:]
    assert proc.stdout.strip().endswith("OK")


def test_mesh_and_sharding_helpers():
    mesh = parallel.data_mesh()
    assert mesh.axis_names == ("data",)
    assert mesh.axis_types == (jax.sharding.AxisType.Auto,)
    s = parallel.batch_sharding(mesh, 3)
    assert s.spec == jax.sharding.PartitionSpec("data", None, None)
    placed = parallel.shard_batch({"a": np.zeros((4, 2)), "b": np.ones((4,))}, mesh)
    np.testing.assert_array_equal(placed["b"], np.ones(4))


def test_shard_batch_errors_name_the_problem():
    mesh = parallel.data_mesh()
    with pytest.raises(ValueError, match="common leading axis"):
        parallel.shard_batch({"a": np.zeros((4, 2)), "b": np.ones((3,))}, mesh)
    with pytest.raises(ValueError, match="no axis"):
        parallel.fit_batch_sharded(np.zeros((2, 10, 3)), 0.1, 1, mesh=mesh, axis_name="model")
    with pytest.raises(ValueError, match="ndim"):
        parallel.batch_sharding(mesh, 0)
