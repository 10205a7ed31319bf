"""The README's quick tour runs as written (a user's first copy and paste)."""

import pathlib
import re

README = pathlib.Path(__file__).resolve().parents[1] / "README.md"


def _quick_tour() -> str:
    text = README.read_text()
    section = text[text.index("## Quick tour"):]
    match = re.search(r"```python\n(.*?)```", section, re.S)
    assert match, "README: no python block under 'Quick tour'"
    return match.group(1)


def test_quick_tour_runs():
    namespace: dict = {}
    exec(compile(_quick_tour(), str(README), "exec"), namespace)  # noqa: S102
    # What the comments promise.
    assert namespace["positions"].shape[1:] == (31, 3)
    assert namespace["x"].shape == (2, 240, namespace["normal"].num_channels)
    assert namespace["pos"].shape == (100, 31, 3)
    sol = namespace["sol"]
    assert bool(sol.converged) and float(sol.com_error_m) < 1e-3


def test_bandai_walkthrough_characteristic_is_style_minus_normal():
    """`characteristic A B` is A - B: the walkthrough's `old.npz`, added to the normal walk with
    weight 1, must be old - normal (it was normal - old, which extrapolates away from old)."""
    text = README.read_text()
    block = text[text.index("B=../shared/data/mocap/bandai1/data"):]
    line = next(ln for ln in block.splitlines() if ln.startswith("fourierjax characteristic"))
    args = line.split()
    out = args[args.index("--out") + 1]
    assert out == "old.npz" and "_old_" in args[2] and "_normal_" in args[3], line
    assert "--add old.npz=1" in block.split("```")[0] and "walk_normal_001.npz --seconds 4 --add" in block
