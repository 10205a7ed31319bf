"""`fourierjax stance` as a user runs it: subprocesses, including user mistakes."""

import json
import os
import subprocess
import sys

import pytest

from tests.helpers import cli_env

ENV = cli_env(JAX_PLATFORMS="cpu")


def _run(*args, env=None, cwd=None):
    return subprocess.run(
        [sys.executable, "-m", "fourierjax", "stance", *args],
        capture_output=True,
        text=True,
        timeout=1200,
        env=env or ENV,
        cwd=cwd,
    )


def test_list_names_first_one_per_line():
    r = _run("--list")
    assert r.returncode == 0, r.stderr
    names = [line.split("\t")[0] for line in r.stdout.strip().splitlines()]
    assert {"posture", "strong_recoil", "weak_recoil", "interest", "beauty_line"} <= set(names)


@pytest.mark.parametrize(
    "args, message",
    [
        (["--shape-set", "nope", "--out", "x.bvh"], "unknown shape set 'nope'"),
        (["--shape-set", "posture", "--target", "1,2", "--out", "x.bvh"], "three coordinates"),
        (["--shape-set", "posture", "--intensity", "nan", "--out", "x.bvh"], "must be finite"),
        (["--shape-set", "posture", "--target", "a,b,c", "--out", "x.bvh"], "expected a number"),
        (["--shape-set", "strong_recoil", "--out", "x.bvh"], "needs --object"),
        (["--shape-set", "posture"], "--out"),
        (["--shape-set", "posture", "--out", "/no/such/dir/x.bvh"], "does not exist"),
        (["--shape-set", "missing.toml", "--out", "x.bvh"], "missing.toml"),
        (["--shape-set", "posture", "--out", "pose.txt"], "expected a .bvh file"),
    ],
)
def test_user_mistakes_give_one_line_and_exit_2(args, message, tmp_path):
    r = _run(*args)
    assert r.returncode == 2
    assert "Traceback" not in r.stderr
    lines = r.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("fourierjax: error:")
    assert message in lines[0]


@pytest.mark.parametrize("name", ["m.npz", "m.toml", "ABSOLUTE"])
def test_binary_shape_set_file_gives_one_line_and_exit_2(name, tmp_path):
    """A binary file (here a NumPy array) given as a shape set: a UnicodeDecodeError traceback
    before; now one line naming the file. A bare name that is an existing file counts as a path."""
    import numpy as np

    path = tmp_path / ("abs.npz" if name == "ABSOLUTE" else name)
    with open(path, "wb") as f:
        np.save(f, np.arange(5.0))  # starts with b"\x93NUMPY": not UTF-8
    arg = str(path) if name == "ABSOLUTE" else name
    repo = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
    env = {**ENV, "PYTHONPATH": os.pathsep.join([repo, ENV.get("PYTHONPATH", "")])}
    r = _run("--shape-set", arg, "--out", str(tmp_path / "x.bvh"), env=env, cwd=tmp_path)
    assert r.returncode == 2, r.stderr
    assert "Traceback" not in r.stderr
    lines = r.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("fourierjax: error:"), r.stderr
    assert path.name in lines[0] and "not UTF-8" in lines[0]


@pytest.mark.slow
def test_solve_writes_bvh_and_json(tmp_path):
    out = tmp_path / "pose.bvh"
    env = {**ENV, "FOURIERJAX_CACHE_DIR": str(tmp_path / "cache")}
    r = _run("--shape-set", "strong_recoil", "--intensity", "0.8", "--object", "0.3,1.2,0.6",
             "--target=-0.3,1.1,0.45", "--out", str(out), "--json", env=env)  # fmt: skip
    assert r.returncode == 0, r.stderr
    result = json.loads(r.stdout)
    for key in ("converged", "iterations", "objective", "reach_error_m", "com_error_m"):
        assert key in result
    assert result["converged"] and result["reach_error_m"] < 1e-3 and result["com_error_m"] < 1e-3
    from fourierjax.io.bvh import read_bvh

    m = read_bvh(out)
    assert m.num_frames == 1 and m.topology.names[0] == "pelvis"
