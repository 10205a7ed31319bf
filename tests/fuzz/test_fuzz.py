"""The fuzz and fault suite, small (CI): typed errors only, no traceback, finite gradients.

`make fuzz` runs the same generators at >= 10,000 BVH files, 1,000 model files and 500 CLI
argument sets (`python -m tests.fuzz`).
"""

import time

import numpy as np
import pytest

from tests.fuzz import cases


def _assert_clean(rep, at_least):
    assert rep.cases >= at_least
    assert rep.untyped == 0, rep.examples


def test_mutated_bvh_files_raise_only_bvh_errors():
    rep = cases.run_bvh(400, seed=1)
    _assert_clean(rep, 400)
    assert rep.typed > 100 and rep.accepted > 0  # the mutations reach both outcomes


def test_mutated_model_files_raise_only_user_errors():
    rep = cases.run_models(150, seed=1)
    _assert_clean(rep, 150)
    assert rep.typed > 50 and rep.accepted > 0


def test_cli_argument_sets_print_no_traceback():
    rep = cases.run_cli(10, seed=0, case_seconds=120)  # seed 1: all 10 refused since --foot-lock
    _assert_clean(rep, 10)
    assert rep.typed > 0 and rep.accepted > 0


def test_gradients_are_finite_at_singular_points():
    rep = cases.run_gradients()
    _assert_clean(rep, 60)


def test_the_runners_count_an_escaping_exception(monkeypatch):
    """A runner that cannot see a failure is no test: an untyped exception is counted."""
    from fourierjax.io import bvh

    def broken(text, source="<string>"):
        raise KeyError("boom")

    monkeypatch.setattr(bvh, "parse_bvh", broken)
    rep = cases.run_bvh(5, seed=0, file_every=10**9)
    assert rep.untyped == 5 and "KeyError" in rep.examples[0][1]


def test_the_cli_runner_counts_a_traceback(monkeypatch):
    import fourierjax.cli.info as info

    def broken(args):
        raise ZeroDivisionError("boom")

    monkeypatch.setattr(info, "run", broken)
    monkeypatch.setattr(cases, "CLI_COMMANDS", ("info",))
    rep = cases.run_cli(3, seed=0)
    assert rep.untyped == 3 and "ZeroDivisionError" in rep.examples[0][1]


def test_a_command_that_needs_100_gb_is_refused_at_once(tmp_path, capsys):
    """The out-of-memory guard: noise harmonics whose model needs >= 100 GB are refused with
    one line and exit 2 before anything is allocated (the time is printed, not asserted)."""
    from fourierjax.cli import main

    raw = cases.model_file_bytes(str(tmp_path))
    model = tmp_path / "m.npz"
    model.write_bytes(raw)
    C = 96  # 07_01's Euler channels
    harmonics = 10**11 // (C * 4 * 8)  # >= 100 GB of float32 amplitude and phase arrays
    t0 = time.perf_counter()
    code = main(["synth", str(model), "--seconds", "2", "--noise", "1", "--noise-harmonics",
                 str(harmonics), "--out", str(tmp_path / "o.bvh")])
    seconds = time.perf_counter() - t0
    err = capsys.readouterr().err
    print(f"refused in {seconds:.2f} s")
    assert code == 2 and "Traceback" not in err
    assert "--noise-harmonics" in err or "harmonics" in err
    line = err.strip().splitlines()[-1]
    assert "GB" in line and "limit" in line and not (tmp_path / "o.bvh").exists()
    nbytes = float(line.split("would need ")[1].split(" ")[0])
    assert nbytes >= 100


@pytest.mark.parametrize("suite", ["bvh", "models"])
def test_fuzz_cases_are_reproducible(suite):
    run = cases.run_bvh if suite == "bvh" else cases.run_models
    a, b = run(30, seed=7), run(30, seed=7)
    assert (a.accepted, a.typed) == (b.accepted, b.typed)
    assert np.isfinite(a.seconds)
