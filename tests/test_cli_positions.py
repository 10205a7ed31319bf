"""`fourierjax positions` run as a user would, against the scipy reference FK."""

import subprocess
import sys

import numpy as np

from fourierjax import data
from tests.helpers import cli_env, reference_fk


def _run(*args):
    return subprocess.run([sys.executable, "-m", "fourierjax", *args], capture_output=True, text=True, timeout=300,
                          env=cli_env())


def test_positions_writes_every_frame_in_file_order(tmp_path):
    out = tmp_path / "p.npy"
    proc = _run("positions", str(data.path("09_02")), "--out", str(out))
    assert proc.returncode == 0, proc.stderr
    pos = np.load(out)
    motion = data.load("09_02", raw=True)  # every frame stored in the file, T-pose included
    assert pos.shape == (motion.num_frames, motion.num_joints, 3)
    ref, _ = reference_fk(motion.topology, motion.offsets, motion.end_site_offsets, motion.channels)
    assert np.abs(pos - ref).max() < 1e-6


def test_positions_user_mistakes(tmp_path):
    proc = _run("positions", str(tmp_path / "missing.bvh"), "--out", str(tmp_path / "p.npy"))
    assert proc.returncode != 0
    assert "missing.bvh" in proc.stderr and "Traceback" not in proc.stderr
    assert len(proc.stderr.strip().splitlines()) == 1
    bad = tmp_path / "bad.bvh"
    bad.write_text("HIERARCHY\nROOT Hips\n{\n  OFFSET 0 0 0\n  CHANNELS 3 Xposition Yposition\n}\n")
    proc = _run("positions", str(bad), "--out", str(tmp_path / "p.npy"))
    assert proc.returncode != 0 and "bad.bvh:" in proc.stderr and "Traceback" not in proc.stderr
