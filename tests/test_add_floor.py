"""`synth --add` stands an edited model on its fitted model's ground (issue #21): a walk plus a
run-minus-walk characteristic put its lowest foot point 1.9 cm under the captured floor (its own
root height and stance, read from the edited cycle, no longer matched its legs)."""

from __future__ import annotations

import numpy as np
import pytest

from fourierjax import data
from fourierjax.body import infer_body_map
from fourierjax.cli import main
from fourierjax.io.bvh import read_bvh
from tests.rigs import world

WALK = "fourierjax/data/cmu_mb/02_01.bvh"
RUN = "fourierjax/data/cmu_mb/02_03.bvh"


@pytest.fixture(scope="module")
def files(tmp_path_factory):
    d = tmp_path_factory.mktemp("add_floor")
    assert main(["fit", WALK, "--out", f"{d}/walk.npz"]) == 0
    assert main(["fit", RUN, "--out", f"{d}/run.npz"]) == 0
    assert main(["characteristic", f"{d}/run.npz", f"{d}/walk.npz", "--out", f"{d}/runness.npz"]) == 0
    assert main(["synth", f"{d}/walk.npz", "--seconds", "4", "--out", f"{d}/plain.bvh"]) == 0
    return d


def _lowest(motion, bm):
    """`[F]` the lowest foot point's height per frame (numpy FK of the file, not the library's)."""
    P, E, _ = world(motion)
    pts = np.concatenate([P, E], axis=1)
    feet = list(bm.feet[0]) + list(bm.feet[1])
    return pts[:, feet, bm.up_axis].min(axis=1) * bm.up_sign


@pytest.mark.parametrize("weight, flags", [("0.5", []), ("1.5", ["--no-speed-limit"])])
def test_synth_add_keeps_the_feet_on_the_captured_floor(files, weight, flags):
    src = data.load("02_01")
    bm = infer_body_map(src)
    cm = 100.0 * bm.metres_per_unit
    floor = np.percentile(_lowest(src, bm), 2)  # the capture's floor: its lowest foot point's
    out = files / f"add{weight}.bvh"
    assert main(["synth", f"{files}/walk.npz", "--seconds", "4", "--add", f"{files}/runness.npz={weight}",
                 *flags, "--out", str(out)]) == 0
    low = _lowest(read_bvh(out), bm)
    assert (low.min() - floor) * cm >= -0.5  # was -1.9 cm at 0.5, -2.7 cm at 1.5
    # on the walk's ground, not over it: the edited walk's feet meet the floor as the walk's do
    plain = _lowest(read_bvh(files / "plain.bvh"), bm)
    assert (np.median(low) - np.median(plain)) * cm <= 1.5


def test_model_ground_is_the_default_ground_and_synthesize_gait_uses_a_given_one(files):
    from fourierjax import gait, model_io

    mf = model_io.load_model(files / "walk.npz")
    sk = mf.template_motion().skeleton()
    floor, clearance = gait.model_ground(mf.model, sk, body_map=mf.body_map)
    r = gait.synthesize_gait(mf.model, sk, 40, mf.frame_time_s, body_map=mf.body_map, foot_lock=False)
    np.testing.assert_allclose(float(floor), float(r.floor), atol=1e-6)
    np.testing.assert_allclose(np.asarray(clearance), np.asarray(r.clearance), atol=1e-6)
    up = gait.synthesize_gait(mf.model, sk, 40, mf.frame_time_s, body_map=mf.body_map, foot_lock=False,
                              floor=floor + 1.0, clearance=clearance)
    assert float(up.floor) == pytest.approx(float(floor) + 1.0)
    np.testing.assert_allclose(np.asarray(up.root_position)[:, 1], np.asarray(r.root_position)[:, 1] + 1.0, atol=1e-4)
    with pytest.raises(Exception, match="floor"):
        gait.synthesize_gait(mf.model, sk, 40, mf.frame_time_s, body_map=mf.body_map, floor=float("nan"))
