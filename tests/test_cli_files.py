"""Output files and inputs of the command line: failed writes, whole-or-nothing files, folders,
bundled names, and the one-line errors (audit of user workflows, session 9)."""

import os
import subprocess
import sys

import numpy as np
import pytest

from fourierjax import data
from fourierjax.cli import main
from fourierjax.io.atomic import write_bytes_atomic


def _one_error_line(capsys, *fragments):
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("fourierjax: error: "), err
    for f in fragments:
        assert f in err[0], err[0]


def test_an_output_that_cannot_be_written_is_one_line_and_exit_2(tmp_path, capsys):
    # A directory where the .npy goes raised IsADirectoryError with a traceback (exit 1).
    (tmp_path / "p.npy").mkdir()
    assert main(["positions", str(data.path("07_01")), "--out", str(tmp_path / "p.npy")]) == 2
    _one_error_line(capsys, str(tmp_path / "p.npy"), "Is a directory")
    assert [p.name for p in tmp_path.iterdir()] == ["p.npy"]  # no temporary file left behind


def test_writes_are_whole_or_nothing(tmp_path, monkeypatch):
    target = tmp_path / "clip.bvh"
    target.write_bytes(b"old")
    write_bytes_atomic(target, b"new contents")
    assert target.read_bytes() == b"new contents"
    assert oct(target.stat().st_mode & 0o777) == oct(0o666 & ~_umask())

    def fail(*_):  # the disk fills up at the very end
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(os, "replace", fail)
    with pytest.raises(OSError, match="No space left") as info:
        write_bytes_atomic(target, b"newer")
    assert info.value.filename == str(target)  # names the file asked for, not the temporary one
    assert target.read_bytes() == b"new contents"  # untouched
    assert [p.name for p in tmp_path.iterdir()] == ["clip.bvh"]


def _umask():
    mask = os.umask(0)
    os.umask(mask)
    return mask


def test_fit_out_with_a_slash_is_a_folder_and_duplicate_names_are_refused(tmp_path, capsys):
    # "--out newmodels/" wrote a model FILE called newmodels; two walk.bvh overwrote each other.
    assert main(["fit", "07_01", "--harmonics", "2", "--out", f"{tmp_path / 'models'}/"]) == 0
    assert (tmp_path / "models" / "07_01.npz").is_file()
    capsys.readouterr()
    for sub in ("a", "b"):
        (tmp_path / sub).mkdir()
        (tmp_path / sub / "walk.bvh").write_bytes(data.path("07_01").read_bytes())
    args = ["fit", str(tmp_path / "a" / "walk.bvh"), str(tmp_path / "b" / "walk.bvh"), "--harmonics", "2",
            "--out", str(tmp_path / "dup")]
    assert main(args) == 2
    _one_error_line(capsys, "would both be written to", "walk.npz")
    assert not (tmp_path / "dup").exists()


def test_fit_warns_about_a_poor_fit(capsys):
    # 142_02's arm channels pass near gimbal lock: 41% of the angle variance, no word said
    # (17% before the steady segment watched the heading over +-1 s and those joints left the
    # omega search). The Euler fit: the tangent default has no winding joints, and explains 38%.
    assert main(["fit", "142_02", "--harmonics", "3", "--representation", "euler", "--json"]) == 0
    err = capsys.readouterr().err
    assert "fourierjax: warning: 142_02: the fit looks poor (it explains 41% of the angle variance" in err
    assert main(["fit", "142_02", "--harmonics", "3", "--json"]) == 0
    assert "fourierjax: warning: 142_02: the fit looks poor (it explains 38% of the angle variance" in (
        capsys.readouterr().err)


def test_transition_window_after_the_motion_is_refused(tmp_path, capsys):
    # "--seconds 4 --start 10" wrote 4 s of gait A and reported "transition 10s to 12s".
    a, b = str(data.path("07_01")), str(data.path("07_12"))
    args = ["transition", a, b, "--seconds", "4", "--start", "10", "--duration", "2", "--out",
            str(tmp_path / "t.bvh")]
    assert main(args) == 2
    _one_error_line(capsys, "--start: the transition starts at 10 s, at or after the end of the 4 s motion")
    assert not (tmp_path / "t.bvh").exists()


def test_a_bvh_given_as_a_model_says_so(tmp_path, capsys):
    args = ["synth", str(data.path("07_01")), "--seconds", "1", "--out", str(tmp_path / "s.bvh")]
    assert main(args) == 2
    _one_error_line(capsys, "it is a BVH motion file; fit a model to it first")


def test_a_closed_pipe_is_not_an_error():
    # `fourierjax info clip.bvh | head -1` ended in a BrokenPipeError traceback (exit 1).
    code = (
        "import os, sys\n"
        "r, w = os.pipe(); os.close(r); os.dup2(w, 1)\n"
        "from fourierjax.cli import main\n"
        f"sys.exit(main(['info', {str(data.path('07_01'))!r}]))\n"
    )
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr
    assert "Traceback" not in proc.stderr


def test_plot_frame_numbers_are_the_files(tmp_path, capsys):
    # A bundled name plotted data.load's clip (rest frame dropped): --frame 316 was "outside"
    # the 317-frame file.
    frames = data.load("07_01", raw=True).num_frames
    assert main(["plot", "stick", "07_01", "--frame", str(frames - 1), "--out", str(tmp_path / "f.png")]) == 0
    assert (tmp_path / "f.png").stat().st_size > 0
    assert np.isfinite(frames)


def test_absurd_lengths_and_extrapolations_are_one_line_errors(tmp_path, capsys):
    # synth --seconds 1e6 asked XLA for 46 GB (a RESOURCE_EXHAUSTED traceback); interpolate
    # --s 1e30 failed later with a message about NaN features that did not name --s.
    a, b = tmp_path / "a.npz", tmp_path / "b.npz"
    assert main(["fit", "07_01", "09_01", "--harmonics", "2", "--out", f"{tmp_path}/"]) == 0
    (tmp_path / "07_01.npz").rename(a)
    (tmp_path / "09_01.npz").rename(b)
    capsys.readouterr()
    assert main(["synth", str(a), "--seconds", "1000000", "--out", str(tmp_path / "s.bvh")]) == 2
    _one_error_line(capsys, "--seconds: 1e+06 s at 120 fps is", "more than the 1000000 a command writes")
    assert main(["interpolate", str(a), str(b), "--s", "1e30", "--out", str(tmp_path / "i.bvh")]) == 2
    _one_error_line(capsys, "--s: 1e+30 extrapolates so far that the model overflows")
    assert not (tmp_path / "s.bvh").exists() and not (tmp_path / "i.bvh").exists()


_ISSUE_24_SCRIPT = r"""
import sys, traceback
import numpy as np
from fourierjax import data
from fourierjax.cli import main
from fourierjax.fourier import FourierModel
from fourierjax.io import model_io
from fourierjax.motion import channel_names_for

out = sys.argv[1]
clip = data.load("07_01")[:10]
names = channel_names_for(clip.topology, "euler")
amp = np.random.default_rng(0).uniform(0, 0.1, (len(names), 2))
model = FourierModel(np.zeros(len(names)), amp, np.zeros_like(amp), np.asarray(6.0), "euler", names)
m = f"{out}/m.npz"
model_io.save_model(m, model, motion=clip)
cases = [
    ["synth", m, "--seconds", "1e308", "--out", f"{out}/s.bvh"],
    ["synth", m, "--seconds", "2", "--fps", "1e308", "--out", f"{out}/s.bvh"],
    ["interpolate", m, m, "--s", "0.5", "--seconds", "1e308", "--out", f"{out}/i.bvh"],
    ["interpolate", m, m, "--s", "0.5", "--fps", "1e308", "--out", f"{out}/i.bvh"],
    ["transition", m, m, "--seconds", "1e308", "--start", "1", "--duration", "1", "--out", f"{out}/t.bvh"],
    ["transition", m, m, "--seconds", "4", "--fps", "1e308", "--start", "1", "--duration", "1",
     "--out", f"{out}/t.bvh"],
    ["plot", "stick", m, "--phase", "1e308", "--out", f"{out}/p.png"],
    ["info", ""],
    ["demo", "--clips", "", "--out", f"{out}/demo", "--quiet"],
    ["synth", f"{out}/deep.npz", "--seconds", "2", "--out", f"{out}/s.bvh"],
]
np.savez(f"{out}/deep.npz", header=np.array("[" * 100_000 + "]" * 100_000))
for argv in cases:
    try:
        rc = main(argv)
    except BaseException:
        traceback.print_exc()
        rc = "raised"
    print(f"CASE {argv[0]} {argv[-1] if argv[0] == 'info' else ' '.join(argv[3:5])!r} rc={rc}", flush=True)
"""


def test_issue_24_command_line_cases_are_one_line_errors(tmp_path):
    """OverflowError for --seconds/--fps 1e308 (int(round(inf))), matplotlib's ValueError for
    plot --phase 1e308, `info ''` reading the current folder, `demo --clips ''` running the
    whole demo, a model file whose header nests 100,000 brackets (RecursionError): each must be
    a one-line error with exit 2 and no traceback."""
    env = dict(os.environ, PYTHONPATH=_ROOT)
    r = subprocess.run([sys.executable, "-c", _ISSUE_24_SCRIPT, str(tmp_path)], capture_output=True,
                       text=True, timeout=600, env=env)
    text = r.stdout + r.stderr
    assert r.returncode == 0 and "Traceback" not in text, text
    results = [line for line in r.stdout.splitlines() if line.startswith("CASE ")]
    assert len(results) == 10 and all(line.endswith("rc=2") for line in results), results
    errors = [line for line in r.stderr.splitlines() if line.startswith("fourierjax: error: ")]
    assert len(errors) == 10, r.stderr
    for fragment in ("--seconds: 1e+308 s at 120 fps is too many frames",
                     "--seconds: 2 s at 1e+308 fps", "--phase: 1e+308 is outside",
                     "an empty name, expected a BVH file", "--clips: '' names no clip",
                     "deep.npz: header is not valid JSON: nested too deeply"):
        assert any(fragment in e for e in errors), (fragment, errors)
    assert not any((tmp_path / n).exists() for n in ("s.bvh", "i.bvh", "t.bvh", "p.png", "demo"))


_ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))  # this tree, for subprocesses
