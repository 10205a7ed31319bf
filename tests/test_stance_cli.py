"""`fourierjax stance` as a user runs it: subprocesses, including user mistakes."""

import functools
import json
import os
import subprocess
import sys

import pytest

from tests.helpers import cli_env

ENV = cli_env(JAX_PLATFORMS="cpu")

#: See `test_solve_writes_bvh_and_json`.
STANCE_PROGRAMS_MAX = 8


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
    log = tmp_path / "programs.json"
    env = {**ENV, "FOURIERJAX_CACHE_DIR": str(tmp_path / "cache"), "FOURIERJAX_PROGRAM_LOG": str(log)}
    r = _run("--shape-set", "strong_recoil", "--intensity", "0.8", "--object", "0.3,1.2,0.6",
             "--target=-0.3,1.1,0.45", "--out", str(out), "--json", env=env)  # fmt: skip
    assert r.returncode == 0, r.stderr
    # Programs of the command (a second call on a warm cache traces and lowers each): the
    # problem build, the solve, the BVH's Euler angles and two of the core's. 96 when the
    # problem was built eagerly, one program per small op (issue 25).
    count = json.loads(log.read_text())
    assert 0 < count["programs"] <= STANCE_PROGRAMS_MAX, count["where"]
    result = json.loads(r.stdout)
    for key in ("converged", "iterations", "objective", "reach_error_m", "com_error_m"):
        assert key in result
    assert result["converged"] and result["reach_error_m"] < 1e-3 and result["com_error_m"] < 1e-3
    from fourierjax.io.bvh import read_bvh

    m = read_bvh(out)
    assert m.num_frames == 1 and m.topology.names[0] == "pelvis"


@pytest.mark.parametrize("name, obj", [("weak_recoil", [0.5, 1.2, 0.6]), ("beauty_line", None)])
def test_objective_zero_in_two_steps_is_the_start_meeting_every_target(name, obj):
    """`weak_recoil` and `beauty_line` at intensity 1 report "objective 0, 2 iterations". That is
    right: eq. 5's terms are the amplitude penalties, in offsets from the shape set's desired
    amplitudes (the solver starts at offset 0), and the reach penalties, inactive without
    --target; balance, IK and gaze are solved inside the pose, not penalised. So the start
    pose meets every term, and BFGS stops after its two steps (a zero step, then the check).
    The bugs it could have hidden: a penalty zero by construction, or a mask dropping every
    term; then an offset would cost nothing too."""
    import equinox as eqx
    import numpy as np

    from fourierjax.cli.stance import _build_problem
    from fourierjax.stance.shape_sets import get_shape_set
    from fourierjax.stance.skeleton48 import make_body

    body = make_body(1.75)
    dt = body.offsets.dtype
    p = _build_problem()(get_shape_set(name), body, np.asarray(1.0, dt),
                         None if obj is None else np.asarray(obj, dt), None, "right")
    assert np.asarray(p.target_active).tolist() == [0.0, 0.0]
    free = np.asarray(p.free)
    assert free[:5].tolist() == [1.0] * 5
    shoulders = np.zeros((2, 3), dt)
    ys = np.concatenate([np.zeros((1, 6)), 0.1 * np.eye(6)]).astype(dt)
    f = _objectives()
    values = np.asarray(f(ys, p, shoulders))
    assert values[0] == 0.0
    # Every free amplitude's offset costs ((0.1 / 0.25)^2 = 0.16), a held one 0.5 y^2.
    np.testing.assert_allclose(values[1:], np.where(free > 0, 0.16, 0.005), rtol=1e-5)
    # A reach target adds a term the start pose does not meet: the shoulders 2 m from it.
    reach = eqx.tree_at(lambda q: (q.target_active, q.targets), p,
                        (np.array([1.0, 0.0], dt), np.array([[0.0, 0.0, 2.0], [0.0, 0.0, 0.0]], dt)))
    assert np.asarray(f(ys[:1], reach, shoulders))[0] > 1.0


@functools.cache
def _objectives():
    """Eq. 5 at a batch of offsets, one compiled program for every test that uses it."""
    import jax

    from fourierjax.stance._objective import objective_given_shoulders

    return jax.jit(jax.vmap(objective_given_shoulders, (0, None, None)))
