"""`fourierjax info`, run as a user runs it (a subprocess), plus in-process checks."""

import json
import subprocess
import sys

import pytest

from fourierjax import data
from fourierjax.cli import main
from fourierjax.io.bvh import read_bvh
from tests.helpers import cli_env

SIX_CHANNELS = """HIERARCHY
ROOT Hips
{
\tOFFSET 0 0 0
\tCHANNELS 6 Xposition Yposition Zposition Zrotation Xrotation Yrotation
\tJOINT Leg
\t{
\t\tOFFSET 0 -5 0
\t\tCHANNELS 6 Xposition Yposition Zposition Yrotation Xrotation Zrotation
\t\tEnd Site
\t\t{
\t\t\tOFFSET 0 -5 0
\t\t}
\t}
\tJOINT Chest
\t{
\t\tOFFSET 0 5 0
\t\tCHANNELS 3 Zrotation Xrotation Yrotation
\t}
}
MOTION
Frames: 2
Frame Time: 0.04
1 2 3 4 5 6 7 8 9 10 11 12 13 14 15
1 2 3 4 5 6 7 8 9 10 11 12 13 14 15
"""


def _run(*args):
    return subprocess.run(
        [sys.executable, "-m", "fourierjax", "info", *map(str, args)],
        capture_output=True, text=True, timeout=120, env=cli_env(),
    )  # fmt: skip


def test_info_json_on_a_bundled_clip():
    path = data.path("07_12")
    r = _run(path, "--json")
    assert r.returncode == 0, r.stderr
    info = json.loads(r.stdout)
    assert info["file"] == str(path)
    assert (info["joints"], info["end_sites"], info["channels"]) == (31, 7, 96)
    assert info["frames"] == 264 and info["frame_time_s"] == 0.0083333
    assert info["duration_s"] == pytest.approx(264 * 0.0083333)
    assert info["rotation_orders"] == {"ZYX": 31}
    assert info["leading_rest_frames"] == 2


def test_info_table_on_a_six_channel_mixed_order_file(tmp_path):
    f = tmp_path / "six.bvh"
    f.write_text(SIX_CHANNELS)
    r = _run(f)
    assert r.returncode == 0, r.stderr
    lines = dict(line.split(":", 1) for line in r.stdout.splitlines())
    assert lines["joints"].split()[0] == "3"
    assert lines["end sites"].strip() == "1"
    assert lines["channels"].split()[0] == "15"
    assert lines["frames"].strip() == "2"
    assert lines["frame time"].strip() == "0.04 s"
    assert lines["duration"].strip() == "0.080 s"
    assert lines["fps"].strip() == "25.0000"
    assert lines["rotation orders"].strip() == "ZXY x2, YXZ x1"
    assert "2 joint" in lines["position channels"]
    assert "rest frames" not in lines


@pytest.mark.parametrize("kind", ["missing", "malformed"])
def test_user_mistakes_print_one_line_and_exit_nonzero(kind, tmp_path):
    f = tmp_path / "walk.bvh"
    if kind == "malformed":
        f.write_text(SIX_CHANNELS.replace("Frames: 2", "Frames: 3"))
    r = _run(f, "--json")
    assert r.returncode == 2
    assert r.stdout == ""
    assert "Traceback" not in r.stderr
    assert len(r.stderr.strip().splitlines()) == 1
    if kind == "missing":
        assert r.stderr.startswith(f"fourierjax: error: {f}") and "no such file" in r.stderr
    else:  # names the file and the line of the frame count
        assert r.stderr.startswith(f"fourierjax: error: {f}:22: 'Frames: 3'")


def test_bundled_clip_names_work_as_in_the_other_commands(capsys):
    # `fit`, `plot` and `info` take a bundled clip's name for its file (info used to refuse it).
    assert main(["info", "07_01", "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["file"] == str(data.path("07_01")) and out["frames"] == read_bvh(data.path("07_01")).num_frames
    assert main(["info", "07_99"]) == 2
    assert "07_99: no such file (bundled clips: " in capsys.readouterr().err


def test_in_process_matches_subprocess_keys(capsys):
    assert main(["info", str(data.path("142_02")), "--json"]) == 0
    info = json.loads(capsys.readouterr().out)
    assert {"joints", "channels", "frames", "frame_time_s", "duration_s", "rotation_orders",
            "end_sites", "file"} <= set(info)  # fmt: skip
    assert info["frames"] == 1882 and info["leading_rest_frames"] == 0


def test_info_prints_the_body_map_and_units(capsys):
    assert main(["info", "07_01", "--json"]) == 0
    info = json.loads(capsys.readouterr().out)
    assert info["body_map"]["legs"]["left"]["hip"] == "LeftUpLeg"
    assert info["body_map"]["trajectory"] == "Hips" and info["units"] == "cmu"
    assert info["metres_per_unit"] == pytest.approx(0.0564)
    assert main(["info", "07_01"]) == 0
    out = capsys.readouterr().out
    assert "units:" in out and "legs (names): left LeftUpLeg > LeftLeg > LeftFoot > LeftToeBase" in out


def test_info_says_why_there_is_no_body_map(tmp_path, capsys):
    path = tmp_path / "six.bvh"
    path.write_text(SIX_CHANNELS)
    assert main(["info", str(path), "--json"]) == 0
    info = json.loads(capsys.readouterr().out)
    assert info["body_map"] is None and "legs" in info["body_map_error"]
