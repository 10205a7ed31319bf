"""`fourierjax plot` run as a user would (subprocess): every kind, BVH and model inputs, mistakes."""

import subprocess
import sys

import numpy as np
import pytest
from PIL import Image

from fourierjax import data
from fourierjax.cli import main
from tests.helpers import cli_env


def fj(*args, cwd=None):
    return subprocess.run([sys.executable, "-m", "fourierjax", *map(str, args)], capture_output=True,
                          text=True, cwd=cwd, timeout=600, env=cli_env())


@pytest.fixture(scope="module")
def model_file(tmp_path_factory):
    """A model file (N = 2) on the skeleton of the bundled walk: small random gait around the
    clip's mean pose (a fitted model is exercised by the demo test)."""
    from fourierjax import fourier, model_io
    from fourierjax.motion import channel_names_for, features_from_motion

    motion = data.load("07_01")[:32]
    x, names = features_from_motion(motion, "euler")
    rng = np.random.default_rng(0)
    C = len(names)
    model = fourier.FourierModel(x.mean(0), np.abs(rng.normal(0, 0.1, (C, 2))),
                                 rng.uniform(-3, 3, (C, 2)), np.float64(5.8), "euler", names)
    assert names == channel_names_for(motion.topology, "euler")
    out = tmp_path_factory.mktemp("m") / "walk.npz"
    model_io.save_model(out, model, motion=motion)
    return out


def _png(path):
    with Image.open(path) as im:
        assert im.format == "PNG" and min(im.size) > 100


def test_plot_kinds_from_a_bvh_file(tmp_path):
    bvh = data.path("09_01")
    for kind in ("spectrum", "stick"):
        r = fj("plot", kind, bvh, "--out", tmp_path / f"{kind}.png", "--frame", "5")
        assert r.returncode == 0, r.stderr
        assert "wrote" in r.stdout
        _png(tmp_path / f"{kind}.png")
    r = fj("plot", "gif", "09_01", "--out", tmp_path / "a.gif", "--seconds", "0.5",
           "--max-frames", "6")
    assert r.returncode == 0, r.stderr
    with Image.open(tmp_path / "a.gif") as im:
        assert im.n_frames == 6


def test_plot_kinds_from_a_model_file(tmp_path, model_file):
    for kind in ("spectrum", "decomposition", "stick"):
        r = fj("plot", kind, model_file, "--out", tmp_path / f"{kind}.png", "--phase", "1.5")
        assert r.returncode == 0, r.stderr
        assert "Traceback" not in r.stderr and "Warning" not in r.stderr
        _png(tmp_path / f"{kind}.png")
    r = fj("plot", "gif", model_file, "--out", tmp_path / "m.gif", "--seconds", "1",
           "--max-frames", "5")
    assert r.returncode == 0, r.stderr
    with Image.open(tmp_path / "m.gif") as im:
        assert im.n_frames == 5


MISTAKES = [
    (["bogus", "07_01", "--out", "x.png"], "unknown plot kind 'bogus'"),
    (["stick", "missing.bvh", "--out", "x.png"], "missing.bvh: no such file"),
    (["stick", "07_01", "--frame", "1e", "--out", "x.png"], "--frame: '1e' is not an integer"),
    (["stick", "07_01", "--frame", "99999", "--out", "x.png"], "--frame: 99999 is outside"),
    (["spectrum", "07_01", "--out", "x.gif"], "--out: x.gif: expected a .png"),
    (["gif", "07_01", "--out", "nodir/x.gif"], "nodir: no such directory"),
    (["gif", "07_01", "--seconds", "nan", "--out", "x.gif"], "--seconds: must be finite"),
]


@pytest.mark.parametrize("args, message", MISTAKES[:3])
def test_plot_user_mistakes_print_one_line(tmp_path, args, message):
    r = fj("plot", *args, cwd=tmp_path)
    assert r.returncode == 2
    lines = r.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("fourierjax: error: "), r.stderr
    assert message in lines[0]


@pytest.mark.parametrize("args, message", MISTAKES[3:])
def test_plot_user_mistakes_in_process(tmp_path, monkeypatch, capsys, args, message):
    monkeypatch.chdir(tmp_path)
    assert main(["plot", *args]) == 2
    lines = capsys.readouterr().err.strip().splitlines()
    assert len(lines) == 1 and message in lines[0]


def test_plot_decomposition_unknown_joint_names_the_joints(tmp_path, model_file):
    r = fj("plot", "decomposition", model_file, "--joint", "Tail", "--out", tmp_path / "d.png")
    assert r.returncode == 2 and "no rotation channels for 'Tail'" in r.stderr
    assert "LeftLeg" in r.stderr and "Traceback" not in r.stderr


def test_help_lists_plot_and_demo():
    r = fj("--help")
    assert r.returncode == 0
    for cmd in ("plot", "demo", "fit", "synth", "info"):
        assert f"    {cmd} " in r.stdout
