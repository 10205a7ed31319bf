"""One floor for every grounded synthesis (issue #21): `synthesize_gait` (hence `synth` and
`interpolate`) and `grounded_transition` stand the lowest foot point on the model's captured floor
(`captured_floor`), not on the file's height 0."""

import functools
import pathlib

import jax.numpy as jnp
import numpy as np
import pytest

from fourierjax import data, gait, style
from fourierjax import motion as M
from fourierjax.data import detect_rest_frames
from fourierjax.io.bvh import read_bvh
from fourierjax.io.gait_bvh import gait_motion

BANDAI = pathlib.Path(__file__).resolve().parents[1] / ".." / "shared" / "data" / "mocap" / "bandai1" / "data"
BANDAI_WALK = BANDAI / "dataset-1_walk_normal_001.bvh"


def _load(name):
    if str(name).endswith(".bvh"):
        if not pathlib.Path(name).is_file():
            pytest.skip(f"Bandai-Namco data set not present at {BANDAI}")
        m = read_bvh(name)
    else:
        m = data.load(name)
    return m[detect_rest_frames(m):]


@functools.cache
def _fit(name):
    mot = _load(name)
    return mot, M.fit_motions([mot], 3, "euler", throw=True)[0]


def _stance_lowest(positions, clearance, up):
    """`[T]` the lower foot's lowest point (clearance off) of each frame: in a walk, the stance foot's."""
    return (np.asarray(positions)[..., up] - np.asarray(clearance)[None]).min(axis=(1, 2))


@pytest.mark.parametrize("name", ["02_01", str(BANDAI_WALK)], ids=["cmu_02_01", "bandai_walk_normal"])
def test_synthesized_stance_stands_where_the_capture_stood(name):
    """The locked synthesis's stance foot, through an independent FK of the written motion, stands
    at the capture's height (median over frames, both with the synthesis's sole clearances).
    Before the shared floor it stood on the file's y = 0: 3.95 cm lower than 02_01's capture,
    4.11 cm lower than Bandai-1 walk_normal's (N = 3); now 0.59 and 0.24 cm lower."""
    mot, fit = _fit(name)
    bm, dt = fit.body_map, mot.frame_time_s
    r = gait.synthesize_gait(fit.model, mot.skeleton(), int(round(4.0 / dt)), dt, body_map=bm)
    out = gait_motion(mot, r, fit.model.channel_names, dt, body_map=bm)
    syn = _stance_lowest(M.foot_positions_of(out, body_map=bm), r.clearance, bm.up_axis)
    cap = _stance_lowest(M.foot_positions_of(mot[fit.frame_start:fit.frame_stop], body_map=bm), r.clearance,
                         bm.up_axis)
    cm = 100.0 * bm.metres_per_unit
    print(f"\n{pathlib.Path(name).stem}: stance foot {np.median(syn) * cm:.2f} cm, captured "
          f"{np.median(cap) * cm:.2f} cm, floor {float(r.floor) * cm:.2f} cm")
    assert abs(np.median(syn) - np.median(cap)) * cm <= 1.0
    # `lowest` is over that floor: the hip rule's lowest point stands on it.
    assert float(np.median(np.asarray(r.lowest).min(-1))) * cm == pytest.approx(0.0, abs=0.2)


def test_synthesis_and_transition_share_the_floor():
    """`grounded_transition` keeps A's captured floor; `synthesize_gait` of A stands on the same one
    (one rule, `captured_floor`). They differed by 2.5 cm on CMU before."""
    mot, fit = _fit("02_01")
    _, fit_b = _fit("02_03")
    bm, dt = fit.body_map, mot.frame_time_s
    a, b = fit.model, fit_b.model
    r = gait.synthesize_gait(a, mot.skeleton(), 32, dt, body_map=bm, foot_lock=False)
    t = style.grounded_transition(a, b, mot.skeleton(), 32, dt, 0.1, 0.1, body_map=bm, clearance=r.clearance,
                                  foot_lock=False, contact_intervals=(jnp.asarray([[0.0, 3.0], [3.2, 6.2]]),) * 2)
    assert float(r.floor) == pytest.approx(float(t.floor), abs=1e-4)
