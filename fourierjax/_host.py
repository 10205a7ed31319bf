"""Host-side conversions at the edges: NumPy arrays in JAX's default float dtype, without a program."""

from __future__ import annotations

import numpy as np


def default_float_dtype() -> np.dtype:
    """JAX's default float dtype: float32, or float64 when `jax_enable_x64` is on.

    Returns:
        The NumPy dtype.
    """
    import jax

    return np.dtype(jax.dtypes.canonicalize_dtype(np.float64))


def as_default_float(x):
    """`x` in JAX's default float dtype, converted on the host when it is not a JAX array.

    `jnp.asarray(x, float)` of a float64 NumPy array runs a conversion program on the device,
    one compiled program per shape (a command line call made tens of them); the conversion in
    NumPy rounds the same way (to nearest) and makes none.

    Arguments:
        x: a NumPy array, a nested sequence of numbers, a JAX array or a tracer.

    Returns:
        A JAX array of the default float dtype (NumPy input is converted on the host and put on
        the device; JAX input goes through `jnp.asarray`, traced or not).
    """
    import jax
    import jax.numpy as jnp

    if isinstance(x, jax.Array | jax.core.Tracer):
        return jnp.asarray(x, dtype=float)
    # `device_put`, not `jnp.asarray`: the latter is a program even when no conversion is needed.
    return jax.device_put(np.asarray(x, dtype=default_float_dtype()))
