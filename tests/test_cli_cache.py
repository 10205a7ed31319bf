"""Every command uses the persistent compile cache; `--no-cache` turns it off (issue 25)."""

import os
import subprocess
import sys
import time

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
    # Every file, saved programs and executables (``exported/``) included.
    return sorted(str(f.relative_to(tmp_path / cache)) for f in (tmp_path / cache).rglob("*") if f.is_file())


def test_a_command_fills_the_cache_and_a_second_call_compiles_nothing_new(tmp_path):
    out = str(tmp_path / "p.npy")
    first = _positions(tmp_path, "positions", "07_01", "--out", out)
    # FK's program is saved whole, compiled afresh rather than read back from the compile cache
    # (`_saved._compile_cache_bypassed`).
    assert any("joint_positions" in name and name.endswith(".xlaexe") for name in first), first
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


def _fill(folder, ages_s, size=1000, now=1.0e9):
    """Files of ``size`` bytes last used ``ages_s`` seconds before ``now``; returns their paths."""
    folder.mkdir(parents=True, exist_ok=True)
    paths = []
    for k, age in enumerate(ages_s):
        p = folder / f"f{k}-cache"
        p.write_bytes(b"x" * size)
        os.utime(p, (now - age, now - age))
        paths.append(p)
    return paths


def test_prune_removes_the_least_recently_used_files_down_to_080_of_the_budget(tmp_path):
    now = 1.0e9
    # Ten 1000-byte files, the oldest first in age; one saved program among them.
    paths = _fill(tmp_path / "c", [10_000 - 900 * k for k in range(9)], now=now)
    paths += _fill(tmp_path / "c" / "exported", [20_000], now=now)
    assert _compile_cache.cache_usage(str(tmp_path / "c")) == (10, 10_000)
    removed = _compile_cache.prune_cache(6000, str(tmp_path / "c"), now=now)
    assert removed == (6, 6000)  # down to 4000 <= 0.8 x 6000: the saved program and f0..f4
    left = sorted(p.name for p in (tmp_path / "c").rglob("*") if p.is_file())
    assert left == [f"f{k}-cache" for k in range(5, 9)]
    # Within budget: nothing happens.
    assert _compile_cache.prune_cache(6000, str(tmp_path / "c"), now=now) == (0, 0)


def test_prune_keeps_files_used_in_the_last_minutes(tmp_path):
    now = 1.0e9
    _fill(tmp_path / "c", [5.0, 10.0, 3600.0], now=now)  # two in use, one an hour old
    assert _compile_cache.prune_cache(1000, str(tmp_path / "c"), now=now) == (1, 1000)
    assert _compile_cache.cache_usage(str(tmp_path / "c")) == (2, 2000)  # over budget until they age


def _cache_cli(tmp_path, *args, **env_extra):
    env = {k: v for k, v in os.environ.items() if k not in (_compile_cache.NO_CACHE_ENV,
                                                             _compile_cache.CACHE_MAX_MB_ENV)}
    env.update({_compile_cache.CACHE_DIR_ENV: str(tmp_path / "c"), **env_extra})
    return subprocess.run([sys.executable, "-m", "fourierjax", "cache", *args],
                          capture_output=True, text=True, timeout=120, env=env)


def test_the_cache_command_reports_prunes_on_start_and_clears(tmp_path):
    import json

    _fill(tmp_path / "c", [7200.0 + k for k in range(4)], size=2**19, now=time.time())  # 4 x 0.5 MiB
    _fill(tmp_path / "c" / "exported", [60.0], size=2**19, now=time.time())  # in use: kept
    proc = _cache_cli(tmp_path, "--json")
    assert proc.returncode == 0, proc.stderr
    assert json.loads(proc.stdout) == {"folder": str(tmp_path / "c"), "files": 5, "bytes": 5 * 2**19,
                                       "budget_bytes": 2048 * 2**20, "on": True}
    # A 2 MiB budget: the command's start removes the two oldest (2.5 -> 1.5 MiB <= 1.6).
    proc = _cache_cli(tmp_path, "--json", FOURIERJAX_CACHE_MAX_MB="2")
    assert json.loads(proc.stdout)["files"] == 3
    assert sorted(p.name for p in (tmp_path / "c").glob("f*")) == ["f0-cache", "f1-cache"]
    proc = _cache_cli(tmp_path, "--clear")
    assert proc.returncode == 0, proc.stderr
    assert "removed    3 files, 1.5 MiB" in proc.stdout and "holds      0 files" in proc.stdout
    assert not [p for p in (tmp_path / "c").rglob("*") if p.is_file()]
    assert "jax" not in proc.stderr


@pytest.mark.parametrize("budget", ["x", "0", "-5", "inf", "nan"])
def test_a_malformed_budget_is_one_error_line(tmp_path, budget):
    proc = _cache_cli(tmp_path, FOURIERJAX_CACHE_MAX_MB=budget)
    assert proc.returncode == 2
    assert proc.stderr.strip().splitlines() == [
        f"fourierjax: error: $FOURIERJAX_CACHE_MAX_MB must be a positive number of MiB, got {budget!r}"]
