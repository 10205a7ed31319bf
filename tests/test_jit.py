"""fourierjax._jit: compiler options on top-level calls, plain jit inside transformations."""

import jax
import jax.numpy as jnp
import numpy as np

from fourierjax._jit import filter_jit, jit


def _f(x):
    return jnp.sin(x) * x


def test_wrapped_functions_work_at_top_level_and_under_transformations():
    for wrap in (filter_jit, jit):
        f = wrap(_f)
        x = jnp.linspace(0.0, 1.0, 4)
        np.testing.assert_allclose(f(x), _f(x), rtol=1e-6)
        # Compiler options are refused on nested jits: these must fall back to plain jit.
        np.testing.assert_allclose(jax.jit(f)(x), _f(x), rtol=1e-6)
        np.testing.assert_allclose(jax.vmap(f)(x), _f(x), rtol=1e-6)
        g = jax.grad(lambda v: f(v).sum())(x)
        np.testing.assert_allclose(g, jnp.cos(x) * x + jnp.sin(x), rtol=1e-5)
        assert f.lower(x).compile() is not None


def test_static_arguments_pass_through():
    f = jit(lambda x, n: x * n, static_argnums=1)
    assert float(f(jnp.float32(2.0), 3)) == 6.0
