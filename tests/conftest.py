"""Test configuration: strict rank promotion, x64 on demand, bundled-data paths."""

import jax
import pytest

jax.config.update("jax_numpy_rank_promotion", "raise")


@pytest.fixture
def x64():
    """Run a test body in float64 (reference checks to tight tolerances)."""
    with jax.enable_x64(True):
        yield
