"""Every experiment runs at its small setting (subprocess) and writes its tables and figures;
experiment configs are validated with messages that name the key."""

import json
import pathlib
import subprocess
import sys

import pytest

from fourierjax.config import ConfigError, load_experiment_config

ROOT = pathlib.Path(__file__).resolve().parent.parent
CONFIGS = sorted((ROOT / "configs" / "experiments").glob("*.toml"))

OUTPUTS = {
    "fit_quality": ["fit_quality.csv", "fit_quality.md", "troje_comparison.md",
                    "variance_vs_harmonics.png"],
    "style": ["interpolation.csv", "superposition.md", "checks.json", "style_metrics.png",
              "interpolation_strip.png"],
    "hip_rule": ["hip_rule_sweep.csv", "step_sweep.md", "hip_rule_sweep.png"],
    "stance": ["stance.csv", "solver_summary.json", "posture_range_posture.png"],
}


@pytest.mark.parametrize("name", list(OUTPUTS))
def test_experiment_runs_small(name, tmp_path):
    r = subprocess.run([sys.executable, "-m", f"experiments.{name}", "--small", "--out",
                        str(tmp_path)], cwd=ROOT, capture_output=True, text=True, timeout=900)
    assert r.returncode == 0, r.stderr[-3000:]
    for f in OUTPUTS[name]:
        assert (tmp_path / name / f).stat().st_size > 0, f
    if name == "fit_quality":
        rows = json.loads((tmp_path / name / "fit_quality.json").read_text())
        for clip in ("07_01", "09_01"):
            ve = {r["harmonics"]: r["variance_explained_positions"] for r in rows
                  if r["clip"] == clip}
            assert ve[1] < ve[2] < ve[3] and ve[2] > 0.97  # more harmonics, better fit
    if name == "style":
        checks = json.loads((tmp_path / name / "checks.json").read_text())
        assert checks["interpolate_s0_equals_normal_max_abs"] < 1e-5
        assert checks["brisk_walk_as_normal_plus_w_tired"] < 0  # brisk = extrapolated s < 0
    if name == "stance":
        s = json.loads((tmp_path / name / "solver_summary.json").read_text())
        assert s["all_converged"]


@pytest.mark.parametrize("path", CONFIGS, ids=lambda p: p.stem)
def test_shipped_configs_are_valid(path):
    for small in (False, True):
        cfg = load_experiment_config(path, small=small)
        assert cfg["experiment"] == path.stem and cfg["small"] is small


@pytest.mark.parametrize("text, message", [
    ('experiment = "fit_quality"\nclips = ["07_01"]\nharmonics = [1]\nbogus = 1\n',
     "unknown key 'bogus'"),
    ('experiment = "fit_quality"\nclips = ["07_01"]\nharmonics = ["a"]\n', "key 'harmonics'"),
    ('experiment = "fit_quality"\nclips = ["99_99"]\nharmonics = [1]\n',
     "key 'clips': unknown clip '99_99'"),
    ('experiment = "fit_quality"\nharmonics = [1]\n', "missing required key 'clips'"),
    ('experiment = "nope"\n', "key 'experiment'"),
    ('experiment = "style"\nnormal = "07_01"\ntired = "07_04"\nbrisk = "07_12"\nrun = "09_01"\n'
     's_values = [0.0]\nweights = [1.0]\nseconds = -1\n', "key 'seconds'"),
    ('experiment = "fit_quality"\nclips = ["07_01"]\nharmonics = [1]\n[small]\nharmonic = [1]\n',
     "[small]: unknown key 'harmonic'"),
    ('experiment = "fit_quality"\nclips = ["07_01"]\nharmonics = [1]\n[small]\nharmonics = [0]\n',
     "[small]: key 'harmonics'"),
    ("experiment = \n", "not valid TOML"),
])
def test_bad_configs_name_the_key(tmp_path, text, message):
    p = tmp_path / "c.toml"
    p.write_text(text)
    with pytest.raises(ConfigError) as e:
        load_experiment_config(p)
    assert message in str(e.value) and str(p) in str(e.value)


def test_bad_config_on_the_command_line_is_one_line(tmp_path):
    p = tmp_path / "c.toml"
    p.write_text('experiment = "fit_quality"\nclips = ["07_01"]\nharmonics = 2\n')
    r = subprocess.run([sys.executable, "-m", "experiments.fit_quality", "--config", str(p),
                        "--out", str(tmp_path)], cwd=ROOT, capture_output=True, text=True,
                       timeout=300)
    assert r.returncode == 2
    lines = r.stderr.strip().splitlines()
    assert len(lines) == 1 and "key 'harmonics'" in lines[0]
    with pytest.raises(ConfigError, match="this script runs 'style'"):
        load_experiment_config(CONFIGS[0], experiment="style")


BANDAI = ROOT / ".." / "shared" / "data" / "mocap" / "bandai1" / "data"


@pytest.mark.skipif(not BANDAI.is_dir(), reason="Bandai-1 not found at ../shared/data/mocap/bandai1")
def test_style_space_runs_small(tmp_path):
    cfg = (ROOT / "configs" / "experiments" / "style_space.toml").read_text()
    cfg = cfg.replace('cache = "/tmp/fourierjax_style_space_cache"', f'cache = "{tmp_path / "cache"}"')
    assert str(tmp_path) in cfg
    (tmp_path / "c.toml").write_text(cfg)
    from experiments.style_space import main

    # in-process (the experiment's own CLI entry point): no second interpreter and JAX import
    assert main(["--small", "--config", str(tmp_path / "c.toml"), "--out", str(tmp_path)]) == 0
    out = tmp_path / "style_space"
    for f in ("recognition.md", "recognition_pca.csv", "recognition_contents.csv", "transfer.csv",
              "transfer_summary.md", "flips.csv", "confusion_walk.png", "pca_accuracy.png", "transfer_ratios.png",
              "transfer_weights.csv", "recognition_representations.md", "recognition_ceiling.csv",
              "transfer_feature_targets.csv"):
        assert (out / f).stat().st_size > 0, f
    assert list((tmp_path / "cache").glob("fits_euler_3_*.npz"))  # the fits are cached
    s = json.loads((out / "summary.json").read_text())
    assert len(s["styles"]) == 5 and not s["failed"]
    assert max(r["accuracy"] for r in s["recognition"]) >= 0.6  # 5 styles: chance 0.2
    assert {r["classifier"] for r in s["recognition"]} == {"ncm", "lda", "logreg", "knn"}
    rows = {r["method"]: r for r in s["transfer"]}
    assert rows["baseline"]["median_ratio"] == pytest.approx(1.0)
    assert set(rows) >= {"eq8", "content_mean", "content_mean_w", "ridge_map", "ls_weights", "harmonic_weights",
                         "group_weights"}
    assert rows["content_mean_w"]["median_ratio"] < rows["baseline"]["median_ratio"]
    assert {"content_mean_gains", "content_mean_gains_cv", "content_mean_cadence_cv"} <= set(rows)
    # the saturated form is the same transfer at its weight (<= 1); beyond 1 its swings saturate
    sat, plain = rows["content_mean_cadence_cv_sat"], rows["content_mean_cadence_cv"]
    assert sat["median_ratio"] == pytest.approx(plain["median_ratio"], rel=1e-5)
    by_w = {(r["method"], r["weight"]): r for r in s["flips_by_weight"]}
    assert set(by_w) == {(m, w) for m in ("eq8", "content_mean_cadence_cv", "content_mean_cadence_cv_sat")
                         for w in (0.0, 1.5)}
    assert by_w[("content_mean_cadence_cv_sat", 0.0)]["phase_ratio"] == pytest.approx(
        by_w[("content_mean_cadence_cv", 0.0)]["phase_ratio"])
    assert by_w[("content_mean_cadence_cv_sat", 1.5)]["phase_ratio"] <= by_w[("content_mean_cadence_cv", 1.5)][
        "phase_ratio"] + 1e-9
    # the oracle (the real target's fit, featurised as the transfers are) is a point of the
    # scorer's training set: anything below 1 would mean the two sides take different paths
    assert all(rows["oracle"][f"recognised_{c}"] == 1.0 for c in ("ncm", "lda", "logreg", "knn"))
    assert rows["oracle"]["median_ratio"] == pytest.approx(0.0, abs=1e-6) and "oracle_take_noise" in rows
    assert "content_mean_rec_cv" in rows and s["recognition_weight"]["euler"]["values"]
    span = s["span_bound"][0]
    assert 0 <= span["span_energy_share"] <= 1 and span["recognised_out_of_span"] >= span["recognised_in_span"]
    assert rows["oracle"]["scorer_to_target"] == pytest.approx(0.0, abs=1e-6)
    assert {r["map"] for r in s["feature_targets"]} >= {"identity", "spread", "slope"}
    # every method with the speed limit (`style.superpose(speed_limit=)`) stays strictly within
    # the clips it reads, per frame and per radian; eq. 8 plain does not without it
    limited = [r for r in s["transfer"] if r.get("limited_max_jump_ratio") is not None]
    assert {r["method"] for r in limited} >= {"eq8", "content_mean_cadence_cv", "content_mean_cadence_cv_sat"}
    assert all(r["limited_max_jump_ratio"] <= 1 + 1e-5 and r["limited_max_frame_jump_ratio"] <= 1 + 1e-5
               for r in limited)
    assert rows["eq8"]["max_frame_jump_ratio"] > 1.0
    sweep = {(r["method"], r["weight"]) for r in s["transfer_weights"]}
    assert sweep == {(m, w) for m in ("content_mean", "content_mean_gains") for w in (1.5, 2.0)}
    reps = {r["features"] for r in s["recognition_representations"]}
    assert {"angles (euler)", "quat", "sixd", "quat+positions", "sixd+positions"} <= reps
    assert 0 <= s["gain_log_omega"]["euler"]["min"] <= s["gain_log_omega"]["euler"]["max"] <= 2
