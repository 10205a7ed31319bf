"""Walks that turn (issue 21 item 4): heading over time, straight passes, one fit of every pass."""

import dataclasses
import pathlib

import numpy as np
import pytest

from fourierjax import _passes as P
from fourierjax import data
from fourierjax import motion as M
from fourierjax.body import infer_body_map
from fourierjax.errors import UserError


@pytest.fixture(scope="module")
def clips():
    return {n: data.load(n) for n in ("142_02", "142_08", "07_01")}


def _facing_deg(a, b):
    return abs((np.degrees(a - b) + 180) % 360 - 180)


def test_heading_over_time_follows_each_pass(clips):
    m = clips["142_08"]
    assert M.heading_over_time is P.heading_over_time and M.straight_passes is P.straight_passes
    psi = M.heading_over_time(m)
    passes = M.straight_passes(m)
    assert len(passes) == 4
    means = []
    for a, b in passes:
        assert np.degrees(np.ptp(psi[a:b])) < 25
        means.append(np.mean(psi[a:b]))
    for a, b in zip(means[:-1], means[1:]):  # back and forth
        assert 160 < _facing_deg(a, b) <= 180
    # The heading over time follows the travel of the pelvis on each pass.
    pos = M.motion_joint_positions(m)[:, infer_body_map(m).pelvis]
    for a, b in passes:
        d = pos[b - 1] - pos[a]
        assert _facing_deg(np.arctan2(d[0], d[2]), np.mean(psi[a:b])) < 10


def test_heading_over_time_is_robust_to_standing_still(clips):
    """A walker that stops for 2 s, turns on the spot and walks back: while it stands the heading
    moves smoothly and monotonically from the old direction to the new (no jump, no NaN); on
    each pass it is the pass's direction."""
    m = clips["142_08"]
    (a, b), (a2, b2) = P.straight_passes(m)[:2]
    topo = m.topology
    xz = [topo.channel_offsets[0] + k for k, c in enumerate(topo.channels[0]) if c in ("Xposition", "Zposition")]
    back = m.channels[a2:b2].copy()
    back[:, xz] += m.channels[b - 1, xz] - back[0, xz]  # walk back from where it stopped
    still = np.repeat(m.channels[b - 1:b], 240, axis=0)
    clip = dataclasses.replace(m, channels=np.concatenate([m.channels[a:b], still, back]))
    psi = P.heading_over_time(clip)
    assert np.all(np.isfinite(psi))
    assert np.degrees(np.max(np.abs(np.diff(psi)))) < 2
    n = b - a
    d = np.diff(psi[n:n + 240])
    assert np.degrees(np.abs(d).sum() - abs(d.sum())) < 10  # no back and forth
    assert 160 < _facing_deg(np.mean(psi[:n]), np.mean(psi[n + 240:])) <= 180
    assert np.degrees(np.ptp(psi[n + 240 + 130:])) < 25
    # A clip that never moves gets the facing of features.heading_of.
    frozen = dataclasses.replace(m, channels=np.repeat(m.channels[a:a + 1], 50, axis=0))
    np.testing.assert_allclose(P.heading_over_time(frozen), M.heading_of(frozen), atol=1e-9)


def test_straight_passes(clips):
    for name, count in (("142_02", 3), ("142_08", 4)):
        m = clips[name]
        passes = P.straight_passes(m)
        assert len(passes) == count, (name, passes)
        assert all((b - a) * m.frame_time_s > 1.5 for a, b in passes)
        assert all(b0 < a1 for (_, b0), (a1, _) in zip(passes[:-1], passes[1:]))
        # The longest pass is the steady segment of fit_motions(passes="longest").
        a, b = M.steady_segment(m)
        assert max(passes, key=lambda p: p[1] - p[0]) == (a, b) or \
            any(abs(p[0] - a) < 10 and abs(p[1] - b) < 10 for p in passes)
    # A straight walk is one pass.
    m = clips["07_01"]
    assert len(P.straight_passes(m)) == 1


def test_cycle_period_frames_resists_a_stumble():
    T = 93.0
    left = np.array([10.0, 103.0, 196.0, 289.0])
    right = left + 46
    stumble = np.sort(np.append(left, 135.0))  # an extra strike a third of a cycle in
    got = P.cycle_period_frames([(stumble.astype(int), right.astype(int)),
                                 ((left[:2] + 7).astype(int), (right[:2] + 7).astype(int))])
    assert abs(got - T) < 0.5
    assert np.isnan(P.cycle_period_frames([(np.array([3]), np.array([40]))]))


def test_layout_puts_every_pass_strike_at_one_phase():
    passes = [(100, 330), (700, 960), (1300, 1520)]
    T = 93.4
    left = [np.array([12, 105, 199]), np.array([61, 154]), np.array([30, 124])]
    lay = P.layout_passes(passes, left, T)
    assert lay.offsets[0] == 0
    ends = [o + b - a for o, (a, b) in zip(lay.offsets, passes)]
    for k in range(1, 3):
        assert ends[k - 1] <= lay.offsets[k] < ends[k - 1] + T + 1
    ph = [(2 * np.pi * (o + lft) / T) for o, lft in zip(lay.offsets, left)]
    ref = np.angle(np.exp(1j * ph[0]).mean())
    for p in ph:
        assert np.all(np.abs(np.angle(np.exp(1j * (p - ref)))) < 2 * np.pi * 0.6 / T)
    mask = P.pass_mask(lay)
    assert mask.sum() == sum(b - a for a, b in passes)
    with pytest.raises(UserError, match="period_frames"):
        P.layout_passes(passes, left, float("nan"))


def test_passes_share_one_branch(clips):
    """Rotation channels continue across the cut-out turns: no 2 pi jump between passes."""
    m = clips["142_08"]
    got = P.prepare_passes(m, 0, "euler", infer_body_map(m))
    layout, a, b, sub, x, names, left, right, omega, keep = got
    assert (a, b) == (layout.passes[0][0], layout.passes[-1][1])
    for o in layout.offsets[1:]:
        assert np.max(np.abs(x[o, 3:] - x[o - 1, 3:])) < 1.5
    assert np.isclose(omega / (2 * np.pi), 0.90, rtol=0.03)
    assert keep.sum() == P.pass_mask(layout).sum()  # no glitches in 142_08: only the gaps
    assert all(keep[left]) and all(keep[right])


def test_fit_every_pass_of_142_08(clips):
    """Acceptance (issue 21): every straight pass used, position VE >= 0.9 with N = 4 (the longest
    pass alone: 2.2 s of the 25 s clip)."""
    m = clips["142_08"]
    auto, longest = M.fit_motions([m], 4, passes="auto")[0], M.fit_motions([m], 4)[0]
    passes = P.straight_passes(m)
    assert (auto.frame_start, auto.frame_stop) == (passes[0][0], passes[-1][1])
    assert longest.frame_stop - longest.frame_start < 0.4 * (auto.frame_stop - auto.frame_start)
    assert auto.successful and auto.alignment == "left_heel_strike"
    assert auto.variance_explained_positions >= 0.9, auto.summary()
    assert abs(auto.omega_fit / auto.omega_steps - 1) < 0.02
    assert len(auto.left_heel_strikes) >= 7  # the strikes of every pass


def test_runs_of_passes_share_one_euler_branch():
    """A run of kept rows that continuity carried onto a joint's twin branch (across a gimbal lock
    in a masked glitch) is moved back, as a whole: the same rotations, next to the other runs."""
    from scipy.spatial.transform import Rotation

    rng = np.random.default_rng(0)
    t = np.arange(300)
    base = np.stack([0.3 * np.sin(0.1 * t), 0.2 + 0.3 * np.cos(0.1 * t), 0.5 * np.sin(0.1 * t + 1)], -1)
    block = base[:, None, :].repeat(2, 1) + 0.01 * rng.standard_normal((300, 2, 3))
    keep = np.ones(300, bool)
    keep[100:120] = keep[200:210] = False
    moved = block.copy()
    twin = np.stack([moved[120:, 0, 0] + np.pi, np.pi - moved[120:, 0, 1], moved[120:, 0, 2] + np.pi], -1)
    moved[120:, 0] = twin  # joint 0 on its twin after the first glitch
    moved[210:, 1] += 2 * np.pi  # joint 1 a turn off after the second
    got = P._runs_on_one_branch(moved, "ZYX", keep)
    np.testing.assert_allclose(got[keep], block[keep], atol=1e-9)
    same = Rotation.from_euler("ZYX", got[120:, 0]).inv() * Rotation.from_euler("ZYX", moved[120:, 0])
    assert np.degrees(same.magnitude()).max() < 1e-6  # the same rotations
    np.testing.assert_array_equal(P._runs_on_one_branch(block, "ZYX", np.ones(300, bool)), block)


def test_fit_every_pass_of_142_02(clips):
    """Every pass used, and the left arm on one Euler branch: continuity crossed its gimbal lock in
    a masked glitch of the second pass, and one model through two branches gave position VE
    -0.80 (N = 4). The 0.9 bound is the clip's, not the fit's (see the xfail below)."""
    m = clips["142_02"]
    auto = M.fit_motions([m], 4, passes="auto")[0]
    assert (auto.frame_start, auto.frame_stop) == (P.straight_passes(m)[0][0], P.straight_passes(m)[-1][1])
    assert auto.variance_explained_positions > 0.0, auto.summary()  # -0.80 on one branch per pass
    got = P.prepare_passes(m, 0, "euler", infer_body_map(m))
    layout, _, _, _, x, names, _, _, _, keep = got
    col = names.index("LeftArm.Zrotation")
    means = [x[o:o + b - a][keep[o:o + b - a], col:col + 3].mean(0) for (a, b), o in zip(layout.passes, layout.offsets)]
    assert max(np.abs(u - v).max() for u in means for v in means) < 1.0, means  # was 3.2 rad (the twin)
    if auto.variance_explained_positions < 0.9:
        pytest.xfail(f"142_02 (clumsy) position VE {auto.variance_explained_positions:.2f} at N = 4: its strides "
                     "last 67-102 frames (a stumble of 32), and each pass fitted alone explains 0.20 / 0.09 / "
                     "0.34 of its positions; 72% of the variance is the arms'")


def test_straight_walks_fit_as_before(clips):
    m = clips["07_01"]
    auto, longest = M.fit_motions([m], 3, passes="auto")[0], M.fit_motions([m], 3)[0]
    assert (auto.frame_start, auto.frame_stop) == (longest.frame_start, longest.frame_stop)
    np.testing.assert_array_equal(np.asarray(auto.model.amplitude), np.asarray(longest.model.amplitude))
    assert auto.variance_explained_positions == longest.variance_explained_positions
    with pytest.raises(UserError, match="passes"):
        M.fit_motions([m], 3, passes="every")


BANDAI = pathlib.Path(__file__).resolve().parents[1] / ".." / "shared" / "data" / "mocap" / "bandai1" / "data"


@pytest.mark.skipif(not BANDAI.is_dir(), reason=f"Bandai-Namco data not found at {BANDAI}")
def test_bandai_straight_walks_are_not_split():
    """Bandai locomotion walks one way: a heading wobble or a slow step can cut one into 2-4
    straight runs (8 of 120 clips), which are not passes of a walk that turns: fit_motions(passes=
    "auto") fits them as before."""
    from fourierjax.io.bvh import read_bvh

    kinds = ("walk", "run", "dash", "walk-back", "walk-left", "walk-right")
    split = 0
    for path in sorted(BANDAI.glob("dataset-1_*.bvh")):
        if path.stem.split("_")[1] not in kinds:
            continue
        m = read_bvh(path)
        bm = infer_body_map(m)
        split += len(P.straight_passes(m, body_map=bm)) > 1
        assert P.prepare_passes(m, 0, "euler", bm) is None, path.name
    assert split >= 1  # the rule above is exercised
