"""`fourierjax demo` end to end (subprocess, reduced length) and its skip-with-notice behaviour."""

import json
import subprocess
import sys

import numpy as np
import pytest
from PIL import Image

from fourierjax import demo
from tests.helpers import cli_env

CLIPS = "07_01,07_04,07_12,02_01,02_03,09_01"

BVH = ["walk_normal", "walk_brisk_extrapolated", "walk_tired", "run_brisk_superposed",
       "walk_to_run", "run_to_walk", "walk_long_steps", "walk_short_steps",
       "walk_slowing_to_stop", "run_flight", "run_high_jump", "run_flight_continuous_rule",
       "walk_shivering"]
PLOTS = ["spectrum_07_01", "decomposition_07_01_left_knee", "interpolation_strip",
         "style_space_pca", "hip_rule_variants", "crowd"]
STANCE = ["posture_-1.00", "posture_-0.50", "posture_+0.00", "posture_+0.50", "posture_+1.00",
          "strong_recoil_+0.25", "strong_recoil_+1.00", "beauty_line_-1.00", "beauty_line_+1.00"]
GIFS = ["walk_styles", "run_brisk_superposed", "walk_to_run", "run_flight", "walk_shivering"]


@pytest.fixture(scope="module")
def demo_run(tmp_path_factory):
    out = tmp_path_factory.mktemp("demo")
    r = subprocess.run([sys.executable, "-m", "fourierjax", "demo", "--out", str(out), "--clips",
                        CLIPS, "--seconds", "1.5"], capture_output=True, text=True, timeout=900,
                       env=cli_env())
    assert r.returncode == 0, r.stderr[-3000:]
    return out, r


def test_demo_writes_every_part(demo_run):
    from fourierjax.io import model_io
    from fourierjax.io.bvh import read_bvh

    out, r = demo_run
    assert "Traceback" not in r.stderr
    assert "fourierjax demo" in r.stderr  # the tqdm progress bar
    for c in CLIPS.split(","):
        mf = model_io.load_model(out / "models" / f"{c}.npz")
        assert mf.model.num_harmonics == 3 and mf.topology is not None
    for name in BVH:
        m = read_bvh(out / "bvh" / f"{name}.bvh")
        frames = 360 if name in ("walk_to_run", "run_to_walk") else 180  # twice as long
        assert m.num_frames == frames and np.all(np.isfinite(m.channels)), name
    for name in PLOTS:
        with Image.open(out / "plots" / f"{name}.png") as im:
            assert im.format == "PNG" and min(im.size) > 200, name
    for name in STANCE:
        m = read_bvh(out / "stance" / f"{name}.bvh")
        assert m.num_frames == 1 and np.all(np.isfinite(m.channels)), name
    for name in ("stance_posture", "stance_strong_recoil", "stance_beauty_line"):
        with Image.open(out / "plots" / f"{name}.png") as im:
            assert min(im.size) > 200, name
    for name in GIFS:
        path = out / "gifs" / f"{name}.gif"
        with Image.open(path) as im:
            assert im.n_frames == 40, name
        assert path.stat().st_size < 400_000, name


def test_demo_summary_has_fit_metrics(demo_run):
    out, r = demo_run
    s = json.loads((out / "summary.json").read_text())
    assert set(s["fits"]) == set(CLIPS.split(","))
    for c, f in s["fits"].items():
        # Issue 3 acceptance on cmu_mb clips, N = 3: positions >= 97 %, a few degrees RMS.
        assert f["variance_explained_positions"] >= 0.97, c
        assert 0.5 < f["rms_deg"] < 4.0, c
        assert 0.5 < f["fundamental_hz"] < 2.0, c
    # Walks are slower than runs.
    assert s["fits"]["07_04"]["fundamental_hz"] < s["fits"]["07_01"]["fundamental_hz"] \
        < s["fits"]["07_12"]["fundamental_hz"] < s["fits"]["09_01"]["fundamental_hz"]
    assert s["synthesis"]["walk_normal"]["flight_fraction"] == 0.0
    assert s["synthesis"]["run_flight"]["flight_fraction"] > 0.05
    assert s["skipped"] == []
    assert len(s["stance"]) == 11 and all(x["converged"] for x in s["stance"])
    assert max(x["com_error_m"] for x in s["stance"]) < 1e-3  # balanced (issue 5)
    assert s["crowd"]["characters"] == 10_000 and s["crowd"]["frames_per_s"] > 0
    assert "07_01" in r.stdout and "summary.json" in r.stdout


def test_demo_user_mistakes_print_one_line(tmp_path):
    for args, message in ((["--clips", "99_99"], "--clips: unknown clip(s) ['99_99']"),
                          (["--seconds", "x"], "--seconds: 'x' is not a number")):
        out = tmp_path / "never_made"
        r = subprocess.run([sys.executable, "-m", "fourierjax", "demo", "--out", str(out),
                            "--quiet", *args], capture_output=True, text=True, timeout=300)
        assert r.returncode == 2
        lines = r.stderr.strip().splitlines()
        assert len(lines) == 1 and message in lines[0], r.stderr
        assert not out.exists()  # a typo leaves no empty output folder behind


def test_a_failing_part_is_skipped_with_a_notice(tmp_path, monkeypatch):
    ran = []

    def missing(st):
        demo._import("fourierjax.not_landed_yet")

    def ok(st):
        ran.append(True)

    monkeypatch.setattr(demo, "STEPS", (("needs a module", missing), ("works", ok)))
    notices = []
    s = demo.run_demo(tmp_path, progress=False, log=notices.append)
    assert ran == [True]
    assert s["skipped"][0]["part"] == "needs a module"
    assert "fourierjax.not_landed_yet is not available" in notices[0]
    assert json.loads((tmp_path / "summary.json").read_text())["skipped"] == s["skipped"]
