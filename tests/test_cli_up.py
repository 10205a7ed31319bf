"""Issue #20: BVH written from a Z-up source keeps Z up (Blender exports), unless `--out-up` says
otherwise; every command reads a Z-up clip as `fit` does (turned Y-up, with a notice)."""

import json

import numpy as np
import pytest

import fourierjax.data
from fourierjax.body import infer_body_map
from fourierjax.cli import main
from fourierjax.cli._inputs import source_up
from fourierjax.io.axes import up_rotation
from fourierjax.io.bvh import read_bvh, write_bvh
from fourierjax.motion import motion_joint_positions
from tests.conventions import convert


@pytest.fixture(scope="module")
def zup(tmp_path_factory):
    """A Z-up walk and run (the CMU clips rewritten as Blender writes them), their models."""
    d = tmp_path_factory.mktemp("zup")
    for name, clip in (("walk", "02_01"), ("run", "02_03")):
        write_bvh(convert(read_bvh(fourierjax.data.path(clip))[:260], "zup"), d / f"{name}.bvh")
    rc = main(["fit", str(d / "walk.bvh"), str(d / "run.bvh"), "--harmonics", "3", "--out", str(d / "m") + "/"])
    assert rc == 0
    return d


def _up(path):
    bm = infer_body_map(read_bvh(path))
    return (bm.up_axis, bm.up_sign)


def _positions(path):
    m = read_bvh(path)
    return np.asarray(motion_joint_positions(m, np.arange(m.num_frames)), np.float64)


def test_fit_records_the_files_up_axis(zup, capsys):
    assert main(["fit", str(zup / "walk.bvh"), "--harmonics", "3", "--json"]) == 0
    out = capsys.readouterr()
    assert json.loads(out.out)[0]["up"] == "z"
    assert "z is up; turned Y-up on reading" in out.err
    assert source_up({}) == "y" and source_up({"up": "-Z"}) == "-z" and source_up({"up": "up"}) == "y"


def test_synth_writes_z_up_like_its_source(zup, capsys):
    model = str(zup / "m" / "walk.npz")
    assert main(["synth", model, "--seconds", "1", "--out", str(zup / "s.bvh")]) == 0
    assert "written z-up like its source" in capsys.readouterr().err
    assert main(["synth", model, "--seconds", "1", "--out", str(zup / "sy.bvh"), "--out-up", "y"]) == 0
    assert _up(zup / "s.bvh") == (2, 1) and _up(zup / "sy.bvh") == (1, 1)
    # The same motion, turned: Z-up positions are the Y-up ones rotated back (BVH's 6 decimals).
    zp, yp = _positions(zup / "s.bvh"), _positions(zup / "sy.bvh")
    np.testing.assert_allclose(zp, yp @ up_rotation("z"), atol=2e-3)
    assert abs(zp[..., 2].min()) < 1.0 < np.median(zp[:, 0, 2])  # feet on the floor z = 0, hips above


@pytest.mark.parametrize("command", ["transition", "interpolate"])
def test_two_gait_commands_read_and_write_z_up(zup, command, capsys):
    """`transition` and `interpolate` refused a Z-up BVH argument ("convert it first with
    to_y_up") where `fit` turned it; now they read it as `fit` does and write Z-up."""
    out = zup / f"{command}.bvh"
    extra = ["--start", "0.5", "--duration", "0.5"] if command == "transition" else ["--s", "0.5"]
    rc = main([command, str(zup / "walk.bvh"), str(zup / "run.bvh"), "--harmonics", "3",
               "--seconds", "1.5", *extra, "--out", str(out)])
    err = capsys.readouterr().err
    assert rc == 0, err
    assert "turned Y-up on reading" in err and "written z-up" in err
    assert _up(out) == (2, 1)
    p = _positions(out)
    assert p[..., 2].min() > -1.0  # on the floor, along Z


def test_interpolated_model_keeps_the_up_axis(zup, capsys):
    m = zup / "m"
    assert main(["interpolate", str(m / "walk.npz"), str(m / "run.npz"), "--s", "0.5", "--out",
                 str(zup / "i.npz")]) == 0
    assert main(["synth", str(zup / "i.npz"), "--seconds", "1", "--out", str(zup / "si.bvh")]) == 0
    assert _up(zup / "si.bvh") == (2, 1)


def test_out_up_is_checked(zup, capsys):
    with pytest.raises(SystemExit) as e:
        main(["synth", str(zup / "m" / "walk.npz"), "--seconds", "1", "--out", str(zup / "x.bvh"),
              "--out-up", "w"])
    assert e.value.code == 2
    assert "--out-up" in capsys.readouterr().err
