"""Tests of fourierjax.contacts on real CMU clips and on synthetic feet with known contacts."""

from __future__ import annotations

import functools
import pathlib

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from fourierjax import contacts as C
from fourierjax.errors import UserError
from tests.helpers import CMU_BUNDLED, NamesTopology, fk_oracle, read_bvh_oracle


@functools.cache
def clip_feet(name: str):
    """Foot points [T, 2, 3, 3] of a bundled clip (T-pose frame dropped) and its frame time."""
    b = read_bvh_oracle(CMU_BUNDLED / f"{name}.bvh")
    start = 2 if name == "07_12" else 1
    pos, es = fk_oracle(b, b["frames"][start:])
    pts = C.foot_points(NamesTopology(b["names"], b["es_par"]))
    return np.asarray(C.gather_foot_positions(pos, es, pts)), b["frame_time"]


WALKS = ["07_01", "02_01", "07_04", "07_12"]
RUNS = ["09_01", "02_03", "09_02"]


# -- foot_points -----------------------------------------------------------------------------
def test_foot_points_cmu():
    b = read_bvh_oracle(CMU_BUNDLED / "07_01.bvh")
    topo = NamesTopology(b["names"], b["es_par"])
    fp = C.foot_points(topo)
    n = b["names"]
    J = len(n)
    assert fp.left[:2] == (n.index("LeftFoot"), n.index("LeftToeBase"))
    assert fp.right[:2] == (n.index("RightFoot"), n.index("RightToeBase"))
    # The toe End Site, found through its parent.
    assert b["es_par"][fp.left[2] - J] == n.index("LeftToeBase")
    assert b["es_par"][fp.right[2] - J] == n.index("RightToeBase")
    assert fp.names[0] == ("LeftFoot", "LeftToeBase", "LeftToeBase/End Site")
    assert len(C.foot_points(topo, end_sites=False).left) == 2


def test_foot_points_unknown_skeleton():
    topo = NamesTopology(("pelvis", "l_ankle", "r_ankle"), ())
    with pytest.raises(UserError, match="LeftFoot.*pelvis"):
        C.foot_points(topo)
    fp = C.foot_points(topo, feet=(("l_ankle",), ("r_ankle",)))
    assert fp.left == (1,) and fp.right == (2,)


# -- real clips -------------------------------------------------------------------------------
def _alternates(contacts):
    ev = C.step_events(contacts)
    strikes = sorted([(int(f), side) for side, e in enumerate(ev) for f in e])
    sides = [s for _, s in strikes]
    return len(sides) >= 2 and all(a != b for a, b in zip(sides, sides[1:]))


@pytest.mark.parametrize("name", WALKS)
def test_walks_alternate_with_double_support(name):
    feet, ft = clip_feet(name)
    c = C.foot_contacts(feet, ft)
    assert _alternates(c), C.contact_timeline(c)
    assert C.double_support_fraction(c) > 0.08, C.contact_timeline(c)
    # A walk never leaves the ground (07_12's glitch frame is dropped above).
    assert C.flight_fraction(c) == 0.0, C.contact_timeline(c)
    # Each foot is on the ground for more than half of the clip (stance ~60% of a cycle).
    assert np.all(c.mean(0) > 0.45)
    period = C.mean_step_period_s(c, ft)
    assert 0.4 < period < 0.8, period


@pytest.mark.parametrize("name", RUNS)
def test_runs_have_flight_phases(name):
    feet, ft = clip_feet(name)
    c = C.foot_contacts(feet, ft)
    assert _alternates(c), C.contact_timeline(c)
    assert C.double_support_fraction(c) == 0.0, C.contact_timeline(c)
    assert C.flight_fraction(c) > 0.2, C.contact_timeline(c)
    # Flight phases: runs of frames with no foot down between the two feet's stances.
    airborne = ~c.any(1)
    starts = np.nonzero(airborne[1:] & ~airborne[:-1])[0]
    assert len(starts) >= 2
    period = C.mean_step_period_s(c, ft)
    assert 0.3 < period < 0.45, period


def test_run_steps_are_shorter_than_walk_steps_same_subject():
    walk, ft = clip_feet("02_01")
    run, _ = clip_feet("02_03")
    p_walk = C.mean_step_period_s(C.foot_contacts(walk, ft), ft)
    p_run = C.mean_step_period_s(C.foot_contacts(run, ft), ft)
    assert p_run < 0.85 * p_walk


def test_tilted_capture_floor_is_fitted():
    # CMU floors rise ~1 unit along a walk; the fitted slope follows the walking direction (+Z).
    feet, ft = clip_feet("07_01")
    g = C.estimate_ground(feet, ft)
    assert 0.005 < g.slope[1] < 0.03
    # The toe tip's floor is near the world ground, the ankle's clearance ~1 unit above it.
    assert np.all(np.abs(g.intercepts[:, 2] - g.intercepts[:, 2].mean()) < 0.5)
    assert np.all(g.intercepts[:, 0] - g.intercepts[:, 2] > 0.5)


# -- synthetic feet with known contacts ----------------------------------------------------
def _synthetic_walk(T=480, ft=1 / 120, cycle=120, stance=72, tilt=0.02, flight=False):
    """Two feet (ankle, toe) on a floor y = tilt * z; known contact masks."""
    t = np.arange(T)
    feet = np.zeros((T, 2, 2, 3))
    truth = np.zeros((T, 2), bool)
    stride = 30.0
    for f, shift in enumerate((0, cycle // 2)):
        ph = (t + shift) % cycle
        k = (t + shift) // cycle
        down = ph < stance
        s = np.clip((ph - stance) / (cycle - stance), 0, 1)
        z = stride * (k + np.where(down, 0.0, 0.5 - 0.5 * np.cos(np.pi * s)))
        lift = np.where(down, 0.0, 3.0 * np.sin(np.pi * s))
        x = 3.0 if f == 0 else -3.0
        for p, (dz, dy) in enumerate(((0.0, 1.0), (3.0, 0.0))):
            feet[:, f, p] = np.stack([np.full(T, x), tilt * (z + dz) + dy + lift, z + dz], -1)
        truth[:, f] = down
    return feet, ft, truth


def test_synthetic_contacts_match_truth_on_tilted_floor():
    feet, ft, truth = _synthetic_walk()
    c = C.foot_contacts(feet, ft)
    # Equal except within a couple of frames of each touch-down / lift-off.
    diff = c != truth
    edges = np.zeros_like(truth)
    for f in range(2):
        on = np.nonzero(np.diff(truth[:, f].astype(int)))[0]
        for e in on:
            edges[max(e - 3, 0) : e + 4, f] = True
    assert not np.any(diff & ~edges)
    assert C.mean_step_period_s(c, ft) == pytest.approx(0.5, abs=1 / 120)


def test_ground_height_given_is_level():
    feet, ft, truth = _synthetic_walk(tilt=0.0)
    c = C.foot_contacts(feet, ft, ground_height=0.0)
    assert (c == truth).mean() > 0.95
    g = C.estimate_ground(feet, ft, ground_height=0.0)
    np.testing.assert_allclose(g.slope, 0.0)
    np.testing.assert_allclose(g.intercepts[:, 1], 0.0, atol=1e-9)


def test_one_point_per_foot_and_explicit_thresholds():
    feet, ft, truth = _synthetic_walk(tilt=0.0)
    toes = feet[:, :, 1]
    c = C.foot_contacts(toes, ft, height_threshold=0.5, speed_threshold=10.0)
    assert (c == truth).mean() > 0.95


def test_bad_input_raises():
    with pytest.raises(UserError, match="foot_positions"):
        C.foot_contacts(np.zeros((10, 2)), 0.01)
    with pytest.raises(UserError, match="frame_time_s"):
        C.foot_contacts(np.zeros((10, 2, 3)), 0.0)
    with pytest.raises(UserError, match="NaN"):
        C.foot_contacts(np.full((10, 2, 3), np.nan), 0.01)
    with pytest.raises(UserError, match="contacts"):
        C.step_events(np.zeros(5, bool))
    with pytest.raises(UserError, match="fewer than two"):
        C.mean_step_period_s(np.zeros((10, 2), bool), 0.01)


def test_step_events_and_fractions_by_hand():
    c = np.array([[1, 0], [1, 0], [0, 0], [0, 1], [0, 1], [1, 1], [1, 0]], bool)
    ev = C.step_events(c)
    assert ev[0].tolist() == [5] and ev[1].tolist() == [3]
    assert C.step_intervals(c).tolist() == [2]
    assert C.mean_step_period_s(c, 0.5) == 1.0
    assert C.flight_fraction(c) == pytest.approx(1 / 7)
    assert C.double_support_fraction(c) == pytest.approx(1 / 7)
    assert C.contact_timeline(c).splitlines()[0] == "L ##...##"


def test_cleanup_closes_gaps_and_drops_blips():
    c = np.array([1, 1, 1, 1, 0, 1, 1, 1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 0], bool)
    out = C._cleanup(c, min_len=3, max_gap=1)
    assert out.tolist() == [True] * 8 + [False] * 10


# -- differentiable parts ----------------------------------------------------------------------
def test_soft_weights_and_speed_gradients_are_finite():
    p = jnp.zeros((5, 2, 3))  # a planted, motionless foot: speed exactly 0
    g = jax.grad(lambda q: C.point_speeds(q, 0.01).sum())(p)
    assert jnp.all(jnp.isfinite(g))
    w = C.soft_contact_weights(jnp.array([0.0, 1.0, 10.0]), jnp.array([0.0, 2.0, 0.0]), 1.0, 2.0)
    np.testing.assert_allclose(w[1], 0.25, rtol=1e-6)
    assert w[0] > 0.95 and w[2] < 1e-6
    dw = jax.grad(lambda h: C.soft_contact_weights(h, 0.0, 1.0, 2.0))(0.5)
    assert jnp.isfinite(dw) and dw < 0


def test_point_speeds_match_numpy_gradient():
    rng = np.random.default_rng(0)
    p = rng.normal(size=(20, 2, 3))
    ref = np.linalg.norm(np.gradient(p, 0.1, axis=0), axis=-1)
    np.testing.assert_allclose(C.point_speeds(p, 0.1), ref, rtol=1e-5)
    ref_h = np.linalg.norm(np.gradient(p[..., [0, 2]], 0.1, axis=0), axis=-1)
    np.testing.assert_allclose(C.point_speeds(p, 0.1, up_axis=1), ref_h, rtol=1e-5)


def _contacts_from_intervals(T, left, right):
    c = np.zeros((T, 2), bool)
    for f, runs in enumerate((left, right)):
        for a, b in runs:
            c[a:b, f] = True
    return c


def test_step_period_median_resists_a_spurious_strike():
    # Left strikes at 10, 130, 135 (the contact breaks for 3 frames: a stumble), 250;
    # right strikes at 70, 190. Cycles (same foot): 120, 5, 115 and 120 frames.
    c = _contacts_from_intervals(300, [(10, 60), (130, 132), (135, 180), (250, 290)],
                                 [(70, 120), (190, 240)])
    assert [e.tolist() for e in C.step_events(c)] == [[10, 130, 135, 250], [70, 190]]
    ft = 0.01
    assert C.step_period_s(c, ft) == pytest.approx((120 + 5 + 115 + 120) / 4 / 2 * ft)
    assert C.step_period_s(c, ft, statistic="median") == pytest.approx(117.5 / 2 * ft)
    assert C.mean_step_period_s(c, ft) == C.step_period_s(c, ft, statistic="mean")
    # One strike per foot: the alternating interval (70 - 10 frames) is the step.
    one = _contacts_from_intervals(100, [(10, 60)], [(70, 95)])
    for stat in C.STEP_STATISTICS:
        assert C.step_period_s(one, ft, statistic=stat) == pytest.approx(60 * ft)
    with pytest.raises(UserError, match="statistic"):
        C.step_period_s(c, ft, statistic="mode")
    with pytest.raises(UserError, match="fewer than two"):
        C.step_period_s(np.zeros((10, 2), bool), ft, statistic="median")


# -- non-finite and mistyped parameters (audit item 11) ----------------------------------------
NAN, INF = float("nan"), float("inf")
BAD_CONTACT_ARGS = [
    ({"frame_time_s": NAN}, "frame_time_s: must be finite"),
    ({"frame_time_s": INF}, "frame_time_s: must be finite"),
    ({"frame_time_s": -0.01}, "frame_time_s: must be positive"),
    ({"frame_time_s": "0.01x"}, "frame_time_s: must be a number"),
    ({"height_threshold": NAN}, "height_threshold: must be finite"),
    ({"height_threshold": 0.0}, "height_threshold: must be positive"),
    ({"speed_threshold": NAN}, "speed_threshold: must be finite"),
    ({"speed_threshold": -1.0}, "speed_threshold: must be positive"),
    ({"ground_height": NAN}, "ground_height: must be finite"),
    ({"ground_height": -INF}, "ground_height: must be finite"),
    ({"min_contact_s": NAN}, "min_contact_s: must be finite"),
    ({"min_contact_s": -0.1}, "min_contact_s: must be >= 0"),
    ({"max_gap_s": NAN}, "max_gap_s: must be finite"),
    ({"up_axis": 1.0}, "up_axis: must be the integer 0, 1 or 2, got 1.0"),
    ({"up_axis": True}, "up_axis: must be the integer"),
    ({"up_axis": 3}, "up_axis: must be the integer"),
]


@pytest.mark.parametrize("kwargs, message", BAD_CONTACT_ARGS,
                         ids=[f"{next(iter(k))}={next(iter(k.values()))}" for k, _ in BAD_CONTACT_ARGS])
def test_foot_contacts_rejects_bad_parameters_by_name(kwargs, message):
    feet, ft, _ = _synthetic_walk(tilt=0.0)
    kwargs = {"frame_time_s": ft, **kwargs}
    with pytest.raises(UserError, match=message.replace("(", r"\(")):
        C.foot_contacts(feet, **kwargs)
    if "min_contact_s" not in kwargs and "max_gap_s" not in kwargs:
        with pytest.raises(UserError, match=message.replace("(", r"\(")):
            C.estimate_ground(feet, **kwargs)


def test_foot_contacts_accepts_numpy_scalar_parameters():
    feet, ft, truth = _synthetic_walk(tilt=0.0)
    c = C.foot_contacts(feet, np.float32(ft), up_axis=np.int64(1), min_contact_s=np.float64(0.04))
    np.testing.assert_array_equal(c, C.foot_contacts(feet, ft))
    assert (c == truth).mean() > 0.95


@pytest.mark.parametrize("frame_time_s", [-1.0, 0.0, NAN, INF])
def test_step_period_rejects_bad_frame_time(frame_time_s):
    c = _contacts_from_intervals(100, [(10, 60)], [(70, 95)])
    with pytest.raises(UserError, match="frame_time_s: must be"):
        C.step_period_s(c, frame_time_s)
    with pytest.raises(UserError, match="frame_time_s: must be"):
        C.mean_step_period_s(c, frame_time_s)


# -- vectorised detection (issue 25, item 3) against the per-frame loops it replaced -----------
def _hysteresis_loop(enter, stay):
    out = np.zeros_like(enter)
    on = False
    for t in range(len(enter)):
        on = bool(enter[t]) or (on and bool(stay[t]))
        out[t] = on
    return out


def _cleanup_loop(c, min_len, max_gap):
    c = c.copy()
    starts, stops = C._runs(~c)
    for a, b in zip(starts, stops, strict=True):
        if a > 0 and b < len(c) and b - a <= max_gap:
            c[a:b] = True
    starts, stops = C._runs(c)
    for a, b in zip(starts, stops, strict=True):
        if b - a < min_len:
            c[a:b] = False
    return c


def test_vectorised_hysteresis_and_cleanup_equal_the_loops():
    rng = np.random.default_rng(3)
    for trial in range(40):
        T, K = int(rng.integers(1, 60)), int(rng.integers(1, 5))
        enter = rng.random((T, K)) < rng.uniform(0.05, 0.6)
        stay = enter | (rng.random((T, K)) < 0.6)
        if trial % 2:
            stay = rng.random((T, K)) < 0.5  # enter need not imply stay
        got = C._hysteresis(enter, stay)
        for k in range(K):
            assert got[:, k].tolist() == _hysteresis_loop(enter[:, k], stay[:, k]).tolist()
        lengths = rng.integers(1, T + 1, K)
        min_len, max_gap = int(rng.integers(1, 5)), int(rng.integers(0, 4))
        out = C._cleanup(got, min_len, max_gap, lengths)
        for k in range(K):
            n = lengths[k]
            assert out[:n, k].tolist() == _cleanup_loop(got[:n, k], min_len, max_gap).tolist()
            assert not out[n:, k].any()


def _foot_contacts_loop(p, dt):
    """The detection as it was: eager `point_speeds`, per-point hysteresis and cleanup loops."""
    p = C._as_points(p)
    g = _ground_per_clip(p, dt)
    above = p[..., 1] - g.intercepts - np.delete(p, 1, axis=-1) @ g.slope
    speed = np.asarray(C.point_speeds(p, dt))
    enter = (above < g.height_threshold) & (speed < g.speed_threshold)
    stay = (above < 1.5 * g.height_threshold) & (speed < 1.5 * g.speed_threshold)
    min_len, max_gap = max(1, int(round(0.04 / dt))), int(round(0.025 / dt))
    out = np.zeros(p.shape[:2], bool)
    for f in range(p.shape[1]):
        pts = [_hysteresis_loop(enter[:, f, k], stay[:, f, k]) for k in range(p.shape[2])]
        out[:, f] = _cleanup_loop(np.any(pts, axis=0), min_len, max_gap)
    return out


def test_foot_contacts_many_equals_the_per_clip_loop_on_bundled_clips():
    clips = [clip_feet(n) for n in ("07_01", "09_01", "07_12")]  # three lengths, walk and run
    many = C.foot_contacts_many([p for p, _ in clips], [dt for _, dt in clips])
    for (p, dt), got in zip(clips, many, strict=True):
        ref = _foot_contacts_loop(p, dt)
        assert got.shape == ref.shape and np.array_equal(got, ref)
        assert np.array_equal(C.foot_contacts(p, dt), ref)
        assert 0.2 < got.mean() < 0.9  # not a degenerate all-off or all-on detection


# -- the batched floor fit against the per-clip least squares ---------------------------------
BANDAI = pathlib.Path(__file__).resolve().parents[1] / ".." / "shared" / "data" / "mocap" / "bandai1" / "data"


def _ground_per_clip(p, dt):
    """`estimate_ground` as it was: one clip, the floor by `_fit_floor`'s `lstsq` iterations."""
    p = C._as_points(p)
    scale = C._scale(p, 1)
    th, tv = 0.25 * scale, 6.0 * scale
    speed = C._speeds(p, dt)
    intercepts, slope = C._fit_floor(p[..., 1], np.delete(p, 1, axis=-1), speed < tv, th)
    return C.GroundEstimate(intercepts, slope, th, tv)


@functools.cache
def _bandai_feet():
    """Foot points and frame times of Bandai-1's clips (every 4th), when ``../shared`` has them."""
    from fourierjax._motion._poses import foot_positions_of
    from fourierjax.body import infer_body_map
    from fourierjax.io.bvh import read_bvh

    out = []
    for path in sorted(BANDAI.glob("*.bvh"))[::4] if BANDAI.is_dir() else []:
        m = read_bvh(path)
        out.append((np.asarray(foot_positions_of(m, body_map=infer_body_map(m)), float), m.frame_time_s))
    return out


def _real_feet(source):
    if source == "cmu":
        return [clip_feet(n) for n in WALKS + RUNS]
    if not BANDAI.is_dir():
        pytest.skip(f"Bandai-Namco data not found at {BANDAI}")
    return _bandai_feet()


@pytest.mark.parametrize("source", ["cmu", "bandai"])
def test_batched_floors_and_contacts_equal_the_per_clip_path(source):
    clips = _real_feet(source)
    feet, dts = [p for p, _ in clips], [dt for _, dt in clips]
    grounds = C._grounds([C._as_points(p) for p in feet], dts, 1, None, None, None)[0]
    for (p, dt), g in zip(clips, grounds, strict=True):
        ref = _ground_per_clip(p, dt)
        assert (g.height_threshold, g.speed_threshold) == (ref.height_threshold, ref.speed_threshold)
        # Floors to rounding (the closed form against lstsq), in float64 whatever the input:
        # within 1e-10 of the height threshold (all 175 Bandai-1 clips: 1e-11 units at most,
        # while the closest height to a threshold is 1.7e-5 away, so no contact frame flips).
        np.testing.assert_allclose(C.floor_heights(g, p), C.floor_heights(ref, p), rtol=0,
                                   atol=1e-10 * ref.height_threshold)
        np.testing.assert_allclose(g.intercepts, ref.intercepts, rtol=0, atol=1e-10 * ref.height_threshold)
        np.testing.assert_allclose(g.slope, ref.slope, rtol=0, atol=1e-12)
        one = C.estimate_ground(p, dt)
        np.testing.assert_allclose(one.intercepts, g.intercepts, rtol=0, atol=1e-12 * ref.height_threshold)
    # Contact masks identical, frame for frame, to the per-clip loop on the per-clip floor.
    for got, (p, dt) in zip(C.foot_contacts_many(feet, dts), clips, strict=True):
        assert np.array_equal(got, _foot_contacts_loop(p, dt))


def test_percentile_rows_are_numpy_percentiles_bit_for_bit():
    rng = np.random.default_rng(0)
    n = np.array([1, 2, 3, 7, 50, 51, 101])
    starts = np.concatenate([[0], np.cumsum(n)])
    x = rng.normal(size=(starts[-1], 2, 3))
    seg = np.repeat(np.arange(len(n)), n)
    s = C._sorted_within(x, seg)
    for q in (0, 2, 30, 50, 97.5, 100):
        got = C._percentile_rows(s, starts, q)
        for b in range(len(n)):
            assert np.array_equal(got[b], np.percentile(x[starts[b]:starts[b + 1]], q, axis=0))


def test_batched_floor_falls_back_on_a_degenerate_clip():
    # Each foot planted on one spot, the two spots 100 units apart: the slope's direction is
    # chosen (the spread) but each point's centred positions are 0 along it, so the slope is not
    # determined and lstsq's minimum-norm answer is the floor (the clip goes through `_fit_floor`).
    T = 20
    p = np.zeros((T, 2, 1, 3))
    p[:, 1, 0, 2] = 100.0
    p[:, 1, 0, 1] = 1.0
    p[::2, :, 0, 1] += 0.01  # not a constant height
    h, hz = p[..., 1], np.delete(p, 1, axis=-1)
    slow = np.ones(h.shape, bool)
    got = C._fit_floors(h, hz, slow, np.array([0, T]), np.array([0.5]))
    ref = C._fit_floor(h, hz, slow, 0.5)
    assert np.abs(ref[1]).max() > 1e-6  # lstsq spread the step over the slope
    np.testing.assert_allclose(got[0][0], ref[0], rtol=0, atol=1e-12)
    np.testing.assert_allclose(got[1][0], ref[1], rtol=0, atol=1e-14)
