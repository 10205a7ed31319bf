"""The flat public face of `fourierjax`: one `__all__`, cheap to import, lazy heavy modules."""

import subprocess
import sys
import types

import fourierjax


def test_every_name_in_all_resolves():
    assert len(set(fourierjax.__all__)) == len(fourierjax.__all__)
    for name in fourierjax.__all__:
        assert getattr(fourierjax, name) is not None, name
    modules = [n for n in fourierjax.__all__ if isinstance(getattr(fourierjax, n), types.ModuleType)]
    assert {"rotations", "kinematics", "fourier", "stance", "io", "data", "crowd"} <= set(modules)
    assert fourierjax.stance.__name__ == "fourierjax.stance"
    assert fourierjax.read_bvh is fourierjax.io.bvh.read_bvh
    assert "stance" in dir(fourierjax)


def test_unknown_attribute_raises():
    import pytest

    with pytest.raises(AttributeError, match="no_such_name"):
        fourierjax.no_such_name  # noqa: B018


def test_import_is_cheap():
    """`import fourierjax` loads neither matplotlib nor the solver stack; the lazy modules load
    on first use."""
    code = (
        "import sys, fourierjax; "
        "print(sorted(m for m in ('matplotlib', 'optimistix', 'jaxopt', 'fourierjax.stance') if m in sys.modules)); "
        "fourierjax.stance; print('fourierjax.stance' in sys.modules)"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True, cwd=".")
    assert out.stdout.split("\n")[:2] == ["[]", "True"], out.stdout + out.stderr


def test_reading_and_posing_a_clip_imports_neither_equinox_nor_jaxtyping():
    """Parse + FK in a fresh process (issue 25's first call) stays on jax and numpy: `Skeleton`
    and `FKResult` are `_pytree.Record`s, annotations are not evaluated, and `_jit` imports
    equinox only for a filtered entry point's first call (about 0.1 s of a fresh process)."""
    code = (
        "import sys\n"
        "from fourierjax import data\n"
        "from fourierjax.io.bvh import read_bvh\n"
        "from fourierjax.kinematics import fk_frames, joint_positions\n"
        "m = read_bvh(data.path('07_01'))\n"
        "p = joint_positions(m.skeleton(), m.channels[:50])\n"
        "r = fk_frames(m.skeleton(), m.channels[:50])\n"
        "print(sorted(k for k in ('equinox', 'jaxtyping', 'optimistix', 'scipy') if k in sys.modules))\n"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True, cwd=".")
    assert out.stdout.strip().splitlines()[-1] == "[]", out.stdout + out.stderr


def test_records_behave_as_the_equinox_modules_they_replace():
    import dataclasses

    import equinox as eqx
    import jax
    import jax.numpy as jnp
    import numpy as np
    import pytest

    from fourierjax import data
    from fourierjax.kinematics import FKResult, fk_frames

    skel = data.load("07_01").skeleton()
    # Leaves are the arrays; the topology is static (in the tree structure).
    leaves, tree = jax.tree.flatten(skel)
    assert [a.shape for a in leaves] == [skel.offsets.shape, skel.end_site_offsets.shape]
    assert jax.tree.unflatten(tree, leaves) == skel
    # Frozen; edited with tree_at.
    with pytest.raises(dataclasses.FrozenInstanceError):
        skel.offsets = skel.offsets * 2
    longer = eqx.tree_at(lambda s: s.offsets, skel, skel.offsets * 2)
    assert longer != skel and longer.topology is skel.topology
    np.testing.assert_array_equal(longer.offsets, 2 * np.asarray(skel.offsets))
    # Batched over skeletons under vmap, differentiable through jit.
    batch = jax.tree.map(lambda a: jnp.stack([a, 2 * a]), skel)
    pos = jax.vmap(lambda s: fk_frames(s, jnp.zeros((1, skel.topology.num_channels))).positions)(batch)
    np.testing.assert_allclose(pos[1], 2 * pos[0], rtol=1e-5, atol=1e-5)
    grad = jax.grad(lambda s: fk_frames(s, jnp.zeros((1, skel.topology.num_channels))).positions.sum())(skel)
    assert isinstance(grad, type(skel)) and np.isfinite(np.asarray(grad.offsets)).all()
    # Equality under jit is a traced bool, as equinox.tree_equal.
    assert bool(jax.jit(lambda a, b: a == b)(skel, skel))
    res = fk_frames(skel, jnp.zeros((2, skel.topology.num_channels)))
    assert isinstance(res, FKResult) and "positions=f32[2,31,3]" in repr(res)
