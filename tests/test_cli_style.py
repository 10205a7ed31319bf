"""Command-line tests of `characteristic`, `interpolate` and `transition` (subprocesses)."""

import subprocess
import sys

import jax.numpy as jnp
import numpy as np
import pytest

from fourierjax import data, model_io, style
from fourierjax import motion as fmotion
from fourierjax.fourier import FourierModel
from fourierjax.io.bvh import read_bvh
from tests.helpers import cli_env


def run_cli(*args, cwd):
    return subprocess.run(
        [sys.executable, "-m", "fourierjax", *map(str, args)], cwd=cwd, capture_output=True, text=True, timeout=600,
        env=cli_env(),
    )


def assert_user_error(proc, *fragments):
    """Exit 2, exactly one line on stderr, no traceback, naming what is wrong."""
    assert proc.returncode == 2, proc.stderr
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1, proc.stderr
    assert lines[0].startswith("fourierjax: error: ")
    assert "Traceback" not in proc.stderr
    for f in fragments:
        assert f in lines[0], lines[0]


def _model(seed, names, representation="euler", omega=6.0, speed=20.0):
    rng = np.random.default_rng(seed)
    c = len(names)
    offset = rng.normal(scale=0.1, size=c)
    offset[:3] = (0.0, speed, 17.0)  # root.vx, root.vz (units/s), root.y
    return FourierModel(
        jnp.asarray(offset),
        jnp.asarray(rng.uniform(0.0, 0.2, size=(c, 3))),
        jnp.asarray(rng.uniform(-np.pi, np.pi, size=(c, 3))),
        jnp.asarray(omega),
        representation,
        names,
    )


@pytest.fixture(scope="module")
def files(tmp_path_factory):
    """Two compatible model files (with a skeleton) and an incompatible (expmap) one."""
    d = tmp_path_factory.mktemp("models")
    template = data.load("02_01")[:2]
    euler = fmotion.channel_names_for(template.topology, "euler")
    expmap = fmotion.channel_names_for(template.topology, "expmap")
    models = {
        "a": _model(0, euler),
        "b": _model(1, euler, omega=8.0, speed=40.0),
        "x": _model(2, expmap, representation="expmap"),
    }
    for k, m in models.items():
        model_io.save_model(d / f"{k}.npz", m, motion=template, alignment="left_heel_strike")
    return d, models


def test_interpolate_writes_the_model_and_a_motion(files):
    d, models = files
    proc = run_cli("interpolate", "a.npz", "b.npz", "--s", "1.25", "--out", "ab.npz", cwd=d)
    assert proc.returncode == 0, proc.stderr
    got = model_io.load_model(d / "ab.npz")
    ref = style.interpolate(models["a"], models["b"], 1.25)
    np.testing.assert_allclose(got.model.amplitude, ref.amplitude, atol=1e-5)
    np.testing.assert_allclose(np.cos(got.model.phase - ref.phase), 1.0, atol=1e-5)
    assert float(got.model.omega) == pytest.approx(6.0**-0.25 * 8.0**1.25, rel=1e-5)
    assert got.topology == models_topology()

    proc = run_cli(
        "interpolate",
        "a.npz",
        "b.npz",
        "--s",
        "0.5",
        "--out",
        "ab.bvh",
        "--seconds",
        "2",
        "--fps",
        "60",
        "--method",
        "phasor",
        "--no-root-motion",  # the model's own root channels (grounded by default: the hip rule)
        cwd=d,
    )
    assert proc.returncode == 0, proc.stderr
    motion = read_bvh(d / "ab.bvh")
    assert motion.num_frames == 120 and motion.frame_time_s == pytest.approx(1 / 60)
    # the root walks along +Z at the interpolated speed (0.5 (20 + 40) units/s)
    assert motion.channels[-1, 2] - motion.channels[0, 2] == pytest.approx(30.0 * 119 / 60, rel=0.05)


def models_topology():
    return data.load("02_01").topology


def test_interpolate_bad_number_is_one_line(files):
    d, _ = files
    assert_user_error(
        run_cli("interpolate", "a.npz", "b.npz", "--s", "half", "--out", "o.npz", cwd=d),
        "--s",
        "'half' is not a number",
    )


def test_transition_writes_a_bvh(files):
    d, models = files
    proc = run_cli(
        "transition", "a.npz", "b.npz", "--seconds", "3", "--start", "1", "--duration", "1", "--out", "t.bvh",
        "--no-foot-lock",  # the transition's own angles (foot locking, on by default, changes the legs')
        cwd=d,
    )
    assert proc.returncode == 0, proc.stderr
    motion = read_bvh(d / "t.bvh")
    assert motion.num_frames == 360
    feats, names = fmotion.features_from_motion(motion, "euler", heading_rad=0.0)
    t = np.arange(360) / 120
    ref = np.asarray(style.transition(models["a"], models["b"], jnp.asarray(t), 1.0, 1.0))
    rot = [i for i, n in enumerate(names) if not n.startswith("root.")]
    # the written angles are the transition's (mod 2π, through Euler round trips and 6 digits)
    err = np.angle(np.exp(1j * (feats[:, rot] - ref[:, rot])))
    assert np.abs(err).max() < 1e-3


def test_transition_incompatible_models_is_one_line(files):
    d, _ = files
    assert_user_error(
        run_cli(
            "transition", "a.npz", "x.npz", "--seconds", "3", "--start", "1", "--duration", "1", "--out", "t.bvh", cwd=d
        ),
        "incompatible models",
        "B (x.npz): representation 'expmap'",
    )


def test_characteristic_missing_file_is_one_line(files):
    d, _ = files
    assert_user_error(
        run_cli("characteristic", "a.npz", "nope.bvh", "--out", "c.npz", cwd=d), "B: nope.bvh: no such file"
    )


def test_characteristic_fits_bvh_clips_on_the_fly(tmp_path):
    # run - walk of subject 02: the run is faster in cadence and in speed.
    proc = run_cli(
        "characteristic",
        data.path("02_03"),
        data.path("02_01"),
        "--harmonics",
        "3",
        "--out",
        "runness.npz",
        cwd=tmp_path,
    )
    assert proc.returncode == 0, proc.stderr
    char, header = model_io.load_characteristic(tmp_path / "runness.npz")
    assert header["a"].endswith("02_03.bvh") and header["alignment"] == "left_heel_strike"
    assert char.amplitude.shape == (96, 3)
    # ω ratio 1.30 Hz / 0.907 Hz (the fitted fundamentals of the two clips)
    assert float(np.exp(char.log_omega)) == pytest.approx(1.300 / 0.907, rel=0.02)
    vz = char.channel_names.index("root.vz")
    assert 15.0 < float(char.offset[vz]) < 35.0  # ≈ 46 − 21 units/s


def test_model_file_inputs_are_not_fitted_again(files, monkeypatch, capsys):
    # Model files are used as they are: interpolate, transition and characteristic never fit
    # (issue 25: transition re-fitted both clips on every call).
    from fourierjax import _compile_cache
    from fourierjax.cli import main

    d, models = files

    def no_fit(*args, **kwargs):
        raise AssertionError("fit_motions called for model-file inputs")

    monkeypatch.setattr(fmotion, "fit_motions", no_fit)
    monkeypatch.setattr(_compile_cache, "enable_compile_cache", lambda: False)
    monkeypatch.chdir(d)
    assert main(["characteristic", "a.npz", "b.npz", "--out", "c.npz"]) == 0
    char, _ = model_io.load_characteristic(d / "c.npz")
    np.testing.assert_allclose(char.offset, np.asarray(models["a"].offset - models["b"].offset), atol=1e-6)
    assert main(["interpolate", "a.npz", "b.npz", "--s", "0.5", "--out", "m.bvh", "--seconds", "1"]) == 0
    assert read_bvh(d / "m.bvh").num_frames == 120
    assert main(["transition", "a.npz", "b.npz", "--seconds", "1", "--start", "0.2", "--duration", "0.5",
                 "--out", "t2.bvh"]) == 0
    assert read_bvh(d / "t2.bvh").num_frames == 120
    assert "wrote t2.bvh" in capsys.readouterr().out


def test_interpolate_reexports_the_input_helpers():
    from fourierjax.cli import _inputs, interpolate

    for name in ("Gait", "add_gait_arguments", "fit_bvhs", "load_gait_pair", "load_gaits"):
        assert getattr(interpolate, name) is getattr(_inputs, name)


def _leg_and_other_channels(motion):
    """(leg columns, other rotation columns) of a Motion's BVH channels: the body map's hips,
    knees and ankles (what foot locking may change) and every other joint's rotations."""
    from fourierjax import body

    bm = body.infer_body_map(motion)
    legs = {j for leg in (bm.left, bm.right) for j in (leg.hip, leg.knee, leg.ankle)}
    cols, other = [], []
    topo = motion.topology
    for j, (start, names) in enumerate(zip(topo.channel_offsets, topo.channels)):
        for k, n in enumerate(names):
            if n.endswith("rotation"):
                (cols if j in legs else other).append(start + k)
    return np.asarray(cols), np.asarray(other), bm


@pytest.mark.parametrize("command", ["transition", "interpolate"])
def test_foot_lock_flags(files, command, monkeypatch):
    """`--foot-lock` plants the feet: only the leg joints' angles change against `--no-foot-lock`;
    the flag reaches both commands (issue 21). On by default in both."""
    from fourierjax import _compile_cache
    from fourierjax.cli import main

    d, _ = files
    monkeypatch.setattr(_compile_cache, "enable_compile_cache", lambda: False)
    monkeypatch.chdir(d)
    args = (["transition", "a.npz", "b.npz", "--seconds", "1", "--start", "0.2", "--duration", "0.5"]
            if command == "transition" else ["interpolate", "a.npz", "b.npz", "--s", "0.5", "--seconds", "1"])
    out = {}
    for flag in (None, "--foot-lock", "--no-foot-lock"):
        name = f"{command}{flag or ''}.bvh"
        assert main([*args, "--out", name, *([flag] if flag else [])]) == 0
        out[flag] = read_bvh(d / name)
    np.testing.assert_array_equal(out[None].channels, out["--foot-lock"].channels)
    legs, other, _ = _leg_and_other_channels(out[None])
    on, off = out["--foot-lock"].channels, out["--no-foot-lock"].channels
    np.testing.assert_allclose(on[:, other], off[:, other], atol=1e-3)
    assert np.abs(on[:, legs] - off[:, legs]).max() > 0.5  # degrees: the lock moved the legs
