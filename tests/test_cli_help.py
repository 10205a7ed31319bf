"""`fourierjax --help` and every subcommand's `--help` answer without importing JAX (issue 25)."""

import subprocess
import sys

from fourierjax.cli import COMMANDS

_PROBE = """
import sys
from fourierjax.cli import main
for argv in [["--help"]] + [[c, "--help"] for c in sys.argv[1:]]:
    try:
        main(argv)
    except SystemExit as e:
        assert e.code == 0, (argv, e.code)
heavy = sorted(m for m in ("jax", "jaxlib", "equinox", "optimistix", "matplotlib") if m in sys.modules)
print("HEAVY", heavy)
"""


def test_help_imports_no_jax():
    proc = subprocess.run([sys.executable, "-c", _PROBE, *COMMANDS], capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr
    assert "HEAVY []" in proc.stdout, proc.stdout[-500:]
    assert proc.stdout.count("usage: fourierjax") == len(COMMANDS) + 1


def test_import_fourierjax_imports_no_jax():
    code = "import sys, fourierjax; print(sorted(m for m in ('jax', 'equinox') if m in sys.modules))"
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300)
    assert proc.stdout.strip() == "[]", proc.stdout + proc.stderr


_CONSOLE = """
import atexit, sys
atexit.register(lambda: print("ATEXIT", file=sys.stderr, flush=True))
sys.argv = ["fourierjax", *sys.argv[1:]]
from fourierjax.cli import console
console()
"""


def test_console_flushes_and_skips_the_backend_teardown(tmp_path):
    """The script leaves by `os._exit` once JAX has run (no atexit), with its piped output whole and
    its exit status kept; a usage error and `--help` exit the normal way."""
    import json
    import os

    env = {k: v for k, v in os.environ.items() if k != "PYTHONUNBUFFERED"}  # `make` sets it
    proc = subprocess.run([sys.executable, "-c", _CONSOLE, "info", "07_01", "--json"],
                          capture_output=True, text=True, timeout=300, env=env)
    assert proc.returncode == 0, proc.stderr
    assert "ATEXIT" not in proc.stderr
    assert json.loads(proc.stdout)  # block-buffered through a pipe: flushed before the exit
    bad = subprocess.run([sys.executable, "-c", _CONSOLE, "info", str(tmp_path / "missing.bvh")],
                         capture_output=True, text=True, timeout=300)
    assert bad.returncode == 2 and "no such file" in bad.stderr
    usage = subprocess.run([sys.executable, "-c", _CONSOLE, "--help"], capture_output=True, text=True, timeout=300)
    assert usage.returncode == 0 and "ATEXIT" in usage.stderr
