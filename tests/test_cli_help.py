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
