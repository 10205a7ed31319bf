"""Test configuration: strict rank promotion, x64 on demand, bundled-data paths."""

import os
import shutil
import tempfile

import jax
import pytest

jax.config.update("jax_numpy_rank_promotion", "raise")
# The command line turns on the persistent compile cache (in ~/.cache/fourierjax); tests that
# call it in-process or as a subprocess must neither write the user's cache nor load programs
# compiled by another test process. tests/test_cli_cache.py gives its subprocesses their own
# cache folder and clears this variable.
os.environ.setdefault("FOURIERJAX_NO_CACHE", "1")

#: One compile-cache folder for the whole run, shared by the xdist workers and by the command-line
#: subprocesses started through `tests.helpers.cli_env` (a fresh folder: nothing from an earlier
#: run or from the user's cache is read). In-process calls keep the cache off (above).
RUN_CACHE_ENV = "FOURIERJAX_TEST_RUN_CACHE"


def pytest_configure(config):
    if not hasattr(config, "workerinput") and RUN_CACHE_ENV not in os.environ:
        os.environ[RUN_CACHE_ENV] = tempfile.mkdtemp(prefix="fourierjax-test-cache-")
        config._fourierjax_run_cache = os.environ[RUN_CACHE_ENV]


def pytest_unconfigure(config):
    path = getattr(config, "_fourierjax_run_cache", None)
    if path:
        shutil.rmtree(path, ignore_errors=True)
        os.environ.pop(RUN_CACHE_ENV, None)


@pytest.fixture
def x64():
    """Run a test body in float64 (reference checks to tight tolerances)."""
    with jax.enable_x64(True):
        yield


@pytest.fixture(scope="module", autouse=True)
def _free_compiled_programs():
    """Drop JAX's in-memory compiled programs after each test file. A worker that ran half the
    suite held 9.3 GB (resident) of them, and a second worker crashed inside an XLA compile on
    the 24 GiB machine; the programs a file compiles are mostly its own."""
    yield
    if os.environ.get("FOURIERJAX_TEST_KEEP_PROGRAMS") != "1":
        import gc

        jax.clear_caches()
        gc.collect()
