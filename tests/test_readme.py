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
