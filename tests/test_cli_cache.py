"""Every command uses the persistent compile cache; `--no-cache` turns it off (issue 25)."""

import os
import subprocess
import sys

import pytest

from fourierjax import _compile_cache
from fourierjax.cli import COMMANDS, _build_parser


def _positions(tmp_path, *flags, cache="cache"):
    env = {k: v for k, v in os.environ.items() if k != _compile_cache.NO_CACHE_ENV
           and not k.startswith("JAX_")}
    env[_compile_cache.CACHE_DIR_ENV] = str(tmp_path / cache)
    proc = subprocess.run([sys.executable, "-m", "fourierjax", *flags],
                          capture_output=True, text=True, timeout=300, env=env)
    assert proc.returncode == 0, proc.stderr
    return sorted(os.listdir(tmp_path / cache)) if (tmp_path / cache).exists() else []


def test_a_command_fills_the_cache_and_a_second_call_compiles_nothing_new(tmp_path):
    out = str(tmp_path / "p.npy")
    first = _positions(tmp_path, "positions", "07_01", "--out", out)
    assert any("joint_positions" in name for name in first), first
    # The second call finds every program it needs: nothing new is written.
    assert _positions(tmp_path, "positions", "07_01", "--out", out) == first


@pytest.mark.parametrize("where", ["before", "after"])
def test_no_cache_leaves_the_cache_folder_empty(tmp_path, where):
    args = ["positions", "07_01", "--out", str(tmp_path / "p.npy")]
    args = ["--no-cache", *args] if where == "before" else [*args, "--no-cache"]
    assert _positions(tmp_path, *args) == []


def test_every_subcommand_takes_no_cache():
    parser = _build_parser()
    sub = next(a for a in parser._actions if a.dest == "command")
    assert set(sub.choices) == set(COMMANDS)
    for name, p in sub.choices.items():
        assert "--no-cache" in p._option_string_actions, name
    assert parser.parse_args(["--no-cache", "info", "x.bvh"]).no_cache is True
    assert parser.parse_args(["info", "x.bvh", "--no-cache"]).no_cache is True
    assert parser.parse_args(["info", "x.bvh"]).no_cache is False


def test_no_cache_environment_wins_over_enable(monkeypatch, tmp_path):
    monkeypatch.setenv(_compile_cache.CACHE_DIR_ENV, str(tmp_path / "c"))
    monkeypatch.setenv(_compile_cache.NO_CACHE_ENV, "1")
    import jax

    before = jax.config.jax_enable_compilation_cache
    try:
        assert _compile_cache.enable_compile_cache() is False
        assert not (tmp_path / "c").exists()
        assert jax.config.jax_enable_compilation_cache is False
    finally:
        jax.config.update("jax_enable_compilation_cache", before)
    assert _compile_cache.cache_dir() == str(tmp_path / "c")


def test_a_second_stance_call_reads_its_saved_programs_instead_of_tracing(tmp_path):
    """The first call saves the stance build and solve (`fourierjax._saved`); the second reads
    them: neither function is traced again, and nothing is exported."""
    import json

    from tests.helpers import cli_env

    env = cli_env(JAX_PLATFORMS="cpu")
    # This run's shared folder (the first call may find the programs another test saved).
    env.setdefault(_compile_cache.CACHE_DIR_ENV, str(tmp_path / "cache"))
    env.pop(_compile_cache.NO_CACHE_ENV, None)
    counts = []
    for k in range(2):
        log = tmp_path / f"programs{k}.json"
        proc = subprocess.run([sys.executable, "-m", "fourierjax", "stance", "--shape-set", "posture",
                               "--out", str(tmp_path / "p.bvh")], capture_output=True, text=True,
                              timeout=600, env={**env, "FOURIERJAX_PROGRAM_LOG": str(log)})
        assert proc.returncode == 0, proc.stderr
        counts.append(json.loads(log.read_text()))
    # Traced by name: the saved functions themselves, or `flat` (an export) on a first call.
    assert not set(counts[1]["by_name"]) & {"solve_stance", "build", "flat"}, counts[1]["by_name"]
    assert counts[1]["traces"] <= counts[0]["traces"]
    folder = os.path.join(env[_compile_cache.CACHE_DIR_ENV], "exported")
    names = {n.split("-")[0] for n in os.listdir(folder)}
    assert {"build", "solve_stance"} <= names, names
