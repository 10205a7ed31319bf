"""The flat public face of `fourierjax`: one `__all__`, cheap to import, lazy heavy modules."""

import subprocess
import sys
import types

import fourierjax


def test_every_name_in_all_resolves():
    assert len(set(fourierjax.__all__)) == len(fourierjax.__all__)
    for name in fourierjax.__all__:
        assert getattr(fourierjax, name) is not None, name
    modules = [n for n in fourierjax.__all__ if isinstance(getattr(fourierjax, n), types.ModuleType)]
    assert {"rotations", "kinematics", "fourier", "stance", "io", "data", "crowd"} <= set(modules)
    assert fourierjax.stance.__name__ == "fourierjax.stance"
    assert fourierjax.read_bvh is fourierjax.io.bvh.read_bvh
    assert "stance" in dir(fourierjax)


def test_unknown_attribute_raises():
    import pytest

    with pytest.raises(AttributeError, match="no_such_name"):
        fourierjax.no_such_name  # noqa: B018


def test_import_is_cheap():
    """`import fourierjax` loads neither matplotlib nor the solver stack; the lazy modules load
    on first use."""
    code = (
        "import sys, fourierjax; "
        "print(sorted(m for m in ('matplotlib', 'optimistix', 'jaxopt', 'fourierjax.stance') if m in sys.modules)); "
        "fourierjax.stance; print('fourierjax.stance' in sys.modules)"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True, cwd=".")
    assert out.stdout.split("\n")[:2] == ["[]", "True"], out.stdout + out.stderr
