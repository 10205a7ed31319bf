"""Test configuration: strict rank promotion, x64 on demand, bundled-data paths."""

import os

import jax
import pytest

jax.config.update("jax_numpy_rank_promotion", "raise")
# The command line turns on the persistent compile cache (in ~/.cache/fourierjax); tests that
# call it in-process or as a subprocess must neither write the user's cache nor load programs
# compiled by another test process. tests/test_cli_cache.py gives its subprocesses their own
# cache folder and clears this variable.
os.environ.setdefault("FOURIERJAX_NO_CACHE", "1")


@pytest.fixture
def x64():
    """Run a test body in float64 (reference checks to tight tolerances)."""
    with jax.enable_x64(True):
        yield
