"""The benchmark suite runs end to end at a tiny size and writes well-formed results (no timings asserted)."""

import json
import math
import os
import subprocess
import sys

import pytest

from experiments.benchmarks.__main__ import HEADLINE

REQUIRED = ("name", "ours", "baseline", "unit", "ratio", "target", "met")


@pytest.mark.timeout(300)
def test_suite_runs_small_and_writes_results(tmp_path):
    root = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
    env = dict(os.environ, JAX_PLATFORMS="cpu")
    proc = subprocess.run(
        [sys.executable, "-m", "experiments.benchmarks", "--out", str(tmp_path), "--small"],
        cwd=root, env=env, capture_output=True, text=True, timeout=290,
    )
    assert proc.returncode == 0, proc.stderr[-4000:]
    records = json.loads((tmp_path / "results.json").read_text())
    meta = json.loads((tmp_path / "metadata.json").read_text())
    assert isinstance(records, list)
    names = [r["name"] for r in records]
    for h in HEADLINE:
        assert h in names, f"missing headline record {h}: {names}"
    for r in records:
        for k in REQUIRED:
            assert k in r, (r["name"], k)
        assert r["met"] in (True, False, None)
        if r["ours"] is None:
            # Only allowed with a stated reason.
            assert any(n.startswith("not measured") for n in r["notes"]), r
            continue
        assert math.isfinite(r["ours"]) and r["ours"] > 0, r
        if r["baseline"] is not None:
            assert r["ratio"] is not None and math.isfinite(r["ratio"]) and r["ratio"] > 0, r
        assert r["meta"]["cpu_count"] >= 1
    # Everything except stance (another module, may be unfinished) must really be measured.
    for h in ("bvh_parse", "fk_1x1000", "fk_1024x240", "synthesis_1024", "fit_256", "crowd_10k",
              "compile_max_s"):
        rec = next(r for r in records if r["name"] == h)
        assert rec["ours"] is not None, rec
        if rec["target"] is not None:
            assert rec["met"] is not None, rec
    fit = next(r for r in records if r["name"] == "fit_256")
    assert fit["details"]["residual_sse_scipy_on_subset"] > 0
    for k in ("jax", "numpy", "cpu_count", "load_average_start", "load_average_end", "devices"):
        assert k in meta
    table = (tmp_path / "results.txt").read_text()
    assert "fk_1024x240" in table and "ratio" in table


def test_a_benchmark_that_raises_still_writes_its_headline_records(tmp_path, monkeypatch, capsys):
    """results.json keeps every headline name: a failing benchmark's records say why they are
    missing (the module's name alone used to stand in for e.g. synthesis_1024)."""
    from experiments.benchmarks import __main__ as suite
    from experiments.benchmarks import fk

    def broken(size):
        raise RuntimeError("no such compile option")

    monkeypatch.setattr(fk, "run", broken)
    assert suite.main(["--out", str(tmp_path), "--small", "--only", "fk"]) == 0
    records = json.loads((tmp_path / "results.json").read_text())
    assert [r["name"] for r in records] == ["fk_1x1000", "fk_1024x240"]
    for r in records:
        assert r["ours"] is None and r["met"] is None
        assert any("fk raised RuntimeError: no such compile option" in n for n in r["notes"]), r
    assert "no such compile option" in capsys.readouterr().err


def test_a_run_stopped_part_way_keeps_the_records_it_made(tmp_path, monkeypatch):
    """Each benchmark's records are written as it ends (results.partial.json), so a run stopped
    by a timeout keeps them; a finished run leaves only results.json."""
    from experiments.benchmarks import __main__ as suite
    from experiments.benchmarks import bvh_parse, fk

    def broken(size):
        raise RuntimeError("no such compile option")

    def stopped(size):
        raise KeyboardInterrupt

    monkeypatch.setattr(fk, "run", broken)
    monkeypatch.setattr(bvh_parse, "run", stopped)
    with pytest.raises(KeyboardInterrupt):
        suite.main(["--out", str(tmp_path), "--small", "--only", "fk,bvh_parse"])
    partial = json.loads((tmp_path / "results.partial.json").read_text())
    assert [r["name"] for r in partial] == ["fk_1x1000", "fk_1024x240"]
    assert not (tmp_path / "results.json").exists()
    assert suite.main(["--out", str(tmp_path), "--small", "--only", "fk"]) == 0
    assert (tmp_path / "results.json").exists() and not (tmp_path / "results.partial.json").exists()


@pytest.mark.timeout(300)
def test_gpu_script_runs_small_on_cpu_and_checks_positions(tmp_path):
    # `experiments.benchmarks.gpu` is what a lent GPU runs (issue 26); its tiny form runs here on
    # the CPU, so it cannot rot between lends. No timings asserted: the positions must equal the
    # NumPy reference and every stage must be measured.
    root = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
    env = dict(os.environ, JAX_PLATFORMS="cpu")
    proc = subprocess.run(
        [sys.executable, "-m", "experiments.benchmarks.gpu", "--out", str(tmp_path), "--small",
         "--only", "fk,fkparts,crowd"],
        cwd=root, env=env, capture_output=True, text=True, timeout=290,
    )
    assert proc.returncode == 0, proc.stderr[-4000:]
    out = json.loads((tmp_path / "gpu.json").read_text())
    assert out["meta"]["ceilings"]["copy_bytes_per_s"] > 0
    names = [r["name"] for r in out["records"]]
    assert any(n.startswith("gpu_fk_parts_") for n in names), names
    for r in out["records"]:
        assert r["ours"] is not None and r["ours"] > 0, r
        if "max_abs_position_diff_vs_numpy" in r["details"]:
            assert r["details"]["max_abs_position_diff_vs_numpy"] < 1e-3, r
        kernels = r["details"].get("joint_positions_kernels") or r["details"].get("kernels")
        if kernels is not None:
            assert "error" not in kernels and kernels["entry_kernels"] >= 1, kernels


def test_kernel_count_reads_loops_and_their_bodies():
    from experiments.benchmarks.gpu import kernel_count

    hlo = """HloModule m

%body.1 (p: (s32[], f32[8])) -> (s32[], f32[8]) {
  %a = f32[8] fusion(%x), kind=kLoop, calls=%f1
  %b = f32[8] custom-call(%a), custom_call_target="x"
}

ENTRY %main (x: f32[8]) -> f32[8] {
  %c = f32[8] fusion(%x), kind=kLoop, calls=%f2
  %w = (s32[], f32[8]) while(%t), condition=%cond.1, body=%body.1
}
"""
    assert kernel_count(hlo) == {"entry_kernels": 1, "loops": 1, "loop_body_kernels": 2}


def test_fk_benchmark_measures_frames_last_and_checks_its_positions():
    from experiments.benchmarks import fk

    records = {r.name: r for r in fk.run("small")}
    for name in ("fk_1x1000", "fk_1024x240"):
        details = records[name].details
        assert details["joint_positions_frames_last_rate"] > 0
        assert details["joint_positions_frames_last_max_abs_diff"] < 1e-3
