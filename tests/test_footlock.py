"""Foot locking and the honest skating metric (issue 21, items 1 and 5)."""

import functools
import pathlib

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from fourierjax import gait
from fourierjax.errors import UserError

BANDAI = pathlib.Path(__file__).resolve().parents[1] / ".." / "shared" / "data" / "mocap" / "bandai1" / "data"
WALKS_AND_RUNS = ("02_01", "02_03", "07_01", "07_04", "07_12", "09_01", "09_02")
SECONDS = 5.0


# ---------------------------------------------------------------------------- weights, intervals


def test_contact_weights_are_one_inside_zero_outside_and_smooth():
    iv = jnp.asarray([[0.5, 3.0], [3.6, 0.2]])  # the right foot's interval wraps through 0
    phase = jnp.linspace(-2 * np.pi, 4 * np.pi, 3001)
    w = np.asarray(gait.contact_weights(phase, iv, blend=0.3))
    th = np.mod(np.asarray(phase), 2 * np.pi)
    inside_l = (th >= 0.5) & (th <= 3.0)
    inside_r = (th >= 3.6) | (th <= 0.2)
    assert np.all(w[inside_l, 0] == 1.0) and np.all(w[inside_r, 1] == 1.0)
    far_l = (th > 3.35) & (th < 0.5 + 2 * np.pi - 0.35)
    assert np.all(w[far_l, 0] == 0.0)
    assert w.min() >= 0.0 and w.max() <= 1.0
    assert np.abs(np.diff(w, axis=0)).max() < 0.05  # no jump: eased over 0.3 rad
    g = jax.grad(lambda p: gait.contact_weights(p[None], iv, blend=0.3)[0, 0])(jnp.float32(3.1))
    assert np.isfinite(float(g)) and float(g) < 0  # easing out after the end
    with pytest.raises(UserError, match=r"\[2, 2\]"):
        gait.contact_weights(phase, jnp.zeros((2,)))


def test_intervals_from_contacts_recover_the_phases():
    omega, dt = 2 * np.pi, 1 / 100  # 1 Hz, 100 frames a cycle
    k = np.arange(400)
    th = np.mod(omega * k * dt, 2 * np.pi)
    c = np.stack([(th > 0.3) & (th < 3.5), (th > 3.4) | (th < 0.4)], axis=1)
    iv = gait.intervals_from_contacts(c, omega, dt)
    np.testing.assert_allclose(iv, [[0.3, 3.5], [3.4, 0.4]], atol=0.07)
    # A phase shift (the fit's alignment) moves every phase back by it.
    iv2 = gait.intervals_from_contacts(c, omega, dt, phase_shift=0.5)
    np.testing.assert_allclose(np.mod(iv - iv2, 2 * np.pi), 0.5, atol=1e-6)
    assert gait.intervals_from_contacts(np.ones((50, 2), bool), omega, dt) is None


# -------------------------------------------------------------------------------- the metric


def test_contact_skating_counts_only_points_in_the_band():
    from types import SimpleNamespace

    bm = SimpleNamespace(up_axis=1, up_sign=1, height=50.0, left=None, right=None)
    T, dt = 100, 0.01
    p = np.zeros((T, 2, 2, 3))
    p[:, 0, :, 2] = 3.0 * np.arange(T)[:, None] * dt  # left foot slides at 3 units/s on the floor
    p[:, 1, :, 1] = 5.0  # right foot well above the 1-unit band (2% of 50) ...
    p[:5, 1, :, 1] = 0.0  # ... after 5 frames on the floor
    p[:, 1, :, 2] = 100.0 * np.arange(T)[:, None] * dt  # and fast
    s = gait.contact_skating(p, dt, body_map=bm, floor=0.0)
    # Left: 3 units/s on every frame; right: counted on its 5 floor frames only (100 units/s).
    expected = (200 * 3.0 + 10 * 100.0) / 210
    assert float(s.mean_speed) == pytest.approx(expected, rel=1e-4)
    still = gait.contact_skating(np.zeros((10, 2, 3, 3)), dt, body_map=bm)
    assert float(still.mean_speed) == 0.0 and float(still.contact_fraction) == 1.0


# ---------------------------------------------------------------------- bundled walks and runs


@functools.cache
def _fits():
    from fourierjax import data
    from fourierjax import motion as M

    motions = [data.load(n) for n in WALKS_AND_RUNS]
    return dict(zip(WALKS_AND_RUNS, zip(motions, M.fit_motions(motions, 4), strict=True), strict=True))


def measure(mot, fit, *, foot_lock=True, seconds=SECONDS):
    """(skating synthesized, skating captured, depth below the floor in m, knee step synthesized,
    knee step captured, straightest knee) of a clip and its locked synthesis, through an
    independent FK of the written motion (radians; `experiments.footlock_bounds.measure`)."""
    from experiments.footlock_bounds import measure as measure_bounds

    m = measure_bounds(mot, fit, foot_lock=foot_lock, seconds=seconds)
    return (m["skating_synth"], m["skating_capture"], m["depth_m"], np.radians(m["knee_step_synth_deg"]),
            np.radians(m["knee_step_capture_deg"]), np.radians(m["straightest_knee_deg"]))


# Not met yet (measured 2026-12-04, session 21, with each contact's hold led in by the easing's
# frames at 120 fps; 5 s at the clip's rate, N = 4; skating synthesized vs captured, largest
# frame-to-frame knee change synthesized vs captured; `python -m experiments.footlock_bounds`).
# Before the lead-in: 02_03 0.36x, 09_01 0.46x, 09_02 0.31x (knee 6.9 deg). Before the toe
# clearance: 0.37x, 0.47x, 0.32x; before the toe hold: 0.39x, 0.50x, 0.32x. What is left, by
# foot point and part of its run of contact frames (`--breakdown`), on 02_03: the ankle's heel-off
# (0.55 units/s: the foot rolls about its planted ball, and the synthesized ankle, higher over the
# ball than the capture's, moves 0.69 units forward per unit it rises against the capture's 0.42)
# and the toe tip's release (0.60). The lock already turns the foot about the held ball (the
# ball's release 0.12 units/s); the ankle leaves its floor only once the foot has turned 29 deg
# onto the ball (the capture 20 deg), as its floor stands 1.07 units over the ball's (the
# estimated sole clearances, `estimate_sole_clearance`) against the capture's 0.74: see there for
# a lower ankle clearance (02_03 0.28x, but 09_01 0.88x). Turning the foot flat at mid-stance in
# the lock (one turn about the ankle per stance, eased between; with that lower ankle clearance)
# did not help: 02_03 0.31x (the tip's release 0.60 -> 0.72 units/s), 09_01 0.89x, 02_01's knee
# step 4.3 deg against 3.5.
# Flight 20% on 02_03 against the capture's 16%, 25% against 24% on 09_01, 23% against 21% on 09_02
# (18%, 24%, 22% once a landing point is planted under twice the stillness threshold and the lift
# is judged after the hold: skating 02_03 0.306x -> 0.298x, 09_01 0.398x -> 0.378x, 09_02 0.261x
# -> 0.250x, knee steps 5.27, 7.59, 7.01 deg; 02_03's ankle landing 0.25 -> 0.20 units/s).
# With the horizontal shift not eased in contact (session ground7): skating 02_03 0.298x -> 0.270x,
# 09_01 0.378x -> 0.297x, 09_02 0.250x -> 0.212x, flight 16%, 22%, 21%, knee steps unchanged
# (02_01's 2.6 -> 2.9 deg against the capture's 3.5).
# With the roll-off (session ground8, `footlock._roll_off`: in a stance's second half a point
# risen over its stance's lowest by 0.25-0.5 bands more than the foot's least-risen point is let
# go horizontally, so the rising heel no longer drags the ball): 02_03 0.270x -> 0.251x, 09_01
# 0.297x -> 0.261x, 09_02 0.212x -> 0.191x; the walks 02_01 0.177x -> 0.179x, 07_01 0.096x ->
# 0.095x, 07_04 0.088x, 07_12 0.100x -> 0.098x; knee steps unchanged. Over the whole stance
# (landing and mid-stance too) the walks slid more (07_04 0.100x, 07_12 0.106x, 02_01 0.183x).
# With the heading hold (session ground9, `footlock._heading_hold`: while a point of a foot is
# down in stance the foot keeps the heading it landed with, so the ankle no longer slides against
# the planted ball as the model's foot yaws): 02_03 0.251x -> 0.234x and 09_01 0.261x -> 0.226x
# (both met), 09_02 0.191x -> 0.161x; 02_01 0.179x -> 0.132x, 07_01 0.095x -> 0.082x, 07_04
# 0.088x -> 0.071x, 07_12 0.098x -> 0.072x; knee steps and flight unchanged (02_03 5.25 deg).
# Holding the whole orientation (pitch too) helped the flat foot (Bandai walk_happy 0.303x ->
# 0.152x) but fights the model's heel-off: held flat while the heel rises, the whole foot lifted
# (walk_happy 8% flight, 09_01 0.568x); faded as the heel starts to rise (0.02-0.1 bands over
# the least-risen point) it kept 09_01 (0.262x) but lost most of the gain (walk_happy 0.274x,
# 02_03 0.264x); turned about the foot's low points instead of the ankle, it sank the foot
# (0.07-0.18 cm below the floor) and skated more (09_01 0.31x).
# 09_02's knee: the unlocked synthesis already steps 6.16 deg against the capture's 5.69 (the
# N = 4 model's own swing), so the lock cannot meet it by undoing its own excess. The lock's
# excess (7.01 deg, early swing, frame 43 of 600) comes from the toe hold: from the stance's end
# the held toe keeps the leg at the soft reach (knee 163.8 deg for 12 frames, where the model's
# goes to 171.4) and the swing starts 0.69 units behind the model's foot (the tip slides that far
# at toe-off), so the knee is 9-11 deg straighter in its fastest flexion, where a given change of
# hip-to-ankle distance turns it more. The swing's easing warp does not change it (LEAD_WARP 1.0:
# 7.19 deg, 2.2: 7.04, 3.0: 7.01); fading the toe hold where it stretches the leg (the 30 fps rule,
# `TOE_REACH_FADE`, at 120 fps) gave 6.52 deg but doubled 02_03's skating (0.498x).
# With the knee-speed cap (session ground10, `footlock._knee_speed_cap`: where the foot is free,
# the knee's angle changes no faster than the capture's largest knee speed, `gait.fit_knee_speed`,
# passed as `synthesize_gait(knee_speed_rad_s=)`): 09_02 7.03 -> 5.61 deg (met), 02_03 5.25 ->
# 4.98, 09_01 7.6 -> 6.6; skating and flight unchanged on all 7. Synthesized at 60 fps: 09_02
# 13.7 -> 11.3 deg against the capture's speed as a 60 fps step, 11.4; at 30 fps 24.8 -> 22.5
# against 22.7.
# Strict: a clip that starts meeting the bounds fails here until it is moved out of this table.
NOT_MET: dict[str, str] = {}


@pytest.mark.parametrize("name", [
    pytest.param(n, marks=pytest.mark.xfail(strict=True, reason=f"issue 21 bounds not met: {NOT_MET[n]}"))
    if n in NOT_MET else n for n in WALKS_AND_RUNS])
def test_locked_synthesis_meets_the_issue_bounds_on_bundled_clips(name):
    mot, fit = _fits()[name]
    s_syn, s_cap, depth_m, k_syn, k_cap, straightest = measure(mot, fit)
    print(f"\n{name}: skating {s_syn:.2f} vs captured {s_cap:.2f} units/s ({s_syn / s_cap:.3f}x), "
          f"{100 * depth_m:.3f} cm below the floor, knee step {np.degrees(k_syn):.1f} vs "
          f"{np.degrees(k_cap):.1f} deg, straightest knee {np.degrees(straightest):.1f} deg")
    assert straightest < np.radians(179.0)  # the knee never straightens fully, never hyperextends
    assert s_syn <= 0.25 * s_cap
    assert depth_m <= 0.005
    assert k_syn <= k_cap


@pytest.mark.slow
def test_the_toe_hold_at_30_fps_keeps_the_knee_within_the_capture():
    """At 30 fps (one frame of easing) the toe's end point is held at toe-off horizontally, faded
    out as it stretches the leg past the unheld foot's reach. Held fully, Bandai-1 run_normal's
    knee stepped 20.1 deg (the capture's largest 16.4; 16.2 without the hold) as the knee, frozen
    straight, caught up with the swing. Measured with the fade: knee 16.1 deg, skating 0.227x
    the capture's (0.231x without the hold); with each contact's hold led in by a frame, knee
    16.2 deg, skating 0.200x; with the band lift (`footlock._band_lift`), 16.2 deg and 0.147x."""
    if not BANDAI.is_dir():
        pytest.skip(f"Bandai-Namco data set not present at {BANDAI}")
    from fourierjax import motion as M
    from fourierjax.io.bvh import read_bvh

    mot = read_bvh(BANDAI / "dataset-1_run_normal_001.bvh")
    assert round(0.04 / mot.frame_time_s) == 1  # one frame of easing: the faded hold
    (fit,) = M.fit_motions([mot], 4)
    s_syn, s_cap, depth_m, k_syn, k_cap, _ = measure(mot, fit)
    print(f"\nrun_normal_001: skating {s_syn / s_cap:.3f}x, knee step {np.degrees(k_syn):.1f} vs "
          f"{np.degrees(k_cap):.1f} deg")
    assert k_syn <= k_cap
    assert s_syn <= 0.25 * s_cap and depth_m <= 0.005


BANDAI_CLIPS = tuple(f"{kind}_{style}" for kind in ("walk", "run") for style in (
    "active", "angry", "childish", "chimpira", "feminine", "giant", "happy", "masculinity", "musical", "normal",
    "not-confident", "old", "proud", "sad", "tired"))
# Bandai-1 walks and runs not met yet (measured 2026-12-05, session ground8, with the roll-off;
# `python -m experiments.footlock_bounds --bandai`; skating synthesized vs captured, knee step
# synthesized vs captured): 23/30 met (23/30 with the horizontal shift not eased in contact,
# ground7; 21/30 with it eased, ground6; 18/30 before the 30 fps band lift). What is left on the runs is
# mostly the ankle point (Bandai's first foot point is the ankle joint, 7-8 cm up) at heel-off and
# landing: it rolls about the planted ball, so it moves forward as it rises through the band
# (walk_happy's heel-off: 3.6 units forward for one band up, the pure pivot about the ball).
# walk_not-confident meets the knee bound by 0.4 deg (11.9 vs 12.3; 12.27 with the shift eased).
# With the heading hold (ground9) still 23/30: the walks skate 0-10% less (walk_musical 0.209x ->
# 0.196x, walk_sad 0.074x -> 0.067x; walk_chimpira 0.109x -> 0.111x), the runs either way
# (run_happy 0.283x -> 0.276x, run_chimpira 0.483x -> 0.505x, run_old 0.176x -> 0.184x): at 30 fps
# the hold takes and leaves the foot within a frame or two. run_childish's knee: the unlocked
# synthesis steps 19.50 deg against the capture's 19.42 (the model's own swing; the lock adds 0.2);
# with the knee-speed cap (ground10) 19.74 -> 19.2 deg (met), 24/30; the other 29 clips unchanged.
# Synthesized at 60 fps: 9.9 -> 9.6 deg against the capture's speed as a 60 fps step, 9.7; at
# 120 fps 5.0 deg against 4.9 either way: there the largest step is the lock's, in stance (the
# knee flexing after the landing, weight 1), which the cap leaves alone.
# Tried, not kept (ground10): holding the foot's roll with its heading (every change since the
# landing's first frame of full weight but the pitch about the foot's lateral axis, heights
# measured again after the turn): Bandai-1 25/30 (run_masculinity 0.257x -> 0.243x met,
# run_chimpira 0.505x -> 0.457x, run_active 0.404x -> 0.397x, run_happy 0.276x -> 0.267x,
# run_angry 0.260x -> 0.254x, walk_happy 0.299x -> 0.296x) but the CMU clips skated 3-17% more
# (07_12 0.072x -> 0.084x, 07_04 0.071x -> 0.082x, 02_01 0.132x -> 0.141x, 02_03 0.234x ->
# 0.237x, 09_01 0.226x -> 0.233x; their landing heel rolls flat after the reference frame) and
# two Bandai runs flew more (run_tired 19% -> 23%). The roll taken at mid-stance instead (about
# the foot's forward axis): CMU still mixed (07_01 0.082x -> 0.071x, 07_12 0.085x, 02_01
# 0.140x), Bandai run_active 0.431x. Keeping the heading hold on for 0.1 s after the phase's
# stance ends (the toe still in the band): run_active 0.404x -> 0.434x, run_chimpira 0.496x.
# Strict: a clip that starts meeting the bounds fails here until it is moved out of this table.
BANDAI_NOT_MET = {
    # Since session 30 the lock runs at 120 fps (`gait.lock_supersampling`: 4x at Bandai-1's 30
    # fps), after a pre-roll of a whole contact, and the frames are decimated; the ratio at 30 fps
    # (one frame of easing) follows in brackets. run_angry (0.254x) and run_happy (0.310x) now
    # meet (0.207x, 0.246x).
    "walk_childish": "skating 0.265x the capture's (0.279x at 120 fps without the pre-roll, 0.262x at 30 fps; "
                     "0.240x, met, with the taller body before cf7fe81)",
    "walk_happy": "skating 0.286x the capture's (0.296x at 30 fps, 0.364x before the roll-off)",
    "run_active": "skating 0.402x the capture's (0.438x at 30 fps): the heel-off pivot about the planted ball, "
                  "as in the unlocked model",
    "run_chimpira": "skating 0.579x the capture's (0.524x at 30 fps)",
    "run_masculinity": "skating 0.459x the capture's (0.366x at 120 fps without the pre-roll, 0.285x at 30 fps, "
                       "0.251x before the heading hold)",
}

# Within 0.5% of the bound: not strict, since another machine's float32 rounding could tip it
# either way; the printed ratio says where it stands. (None now: run_feminine, 0.2508x, is 0.222x.)
BANDAI_AT_THE_EDGE: set[str] = set()


@functools.cache
def _bandai_fits():
    from fourierjax import motion as M
    from fourierjax.io.bvh import read_bvh

    motions = [read_bvh(BANDAI / f"dataset-1_{n}_001.bvh") for n in BANDAI_CLIPS]
    return dict(zip(BANDAI_CLIPS, zip(motions, M.fit_motions(motions, 4), strict=True), strict=True))


@pytest.mark.slow
@pytest.mark.parametrize("name", [
    pytest.param(n, marks=pytest.mark.xfail(strict=n not in BANDAI_AT_THE_EDGE,
                                            reason=f"issue 21 bounds not met: {BANDAI_NOT_MET[n]}"))
    if n in BANDAI_NOT_MET else n for n in BANDAI_CLIPS])
def test_locked_synthesis_meets_the_issue_bounds_on_bandai_clips(name):
    if not BANDAI.is_dir():
        pytest.skip(f"Bandai-Namco data set not present at {BANDAI}")
    mot, fit = _bandai_fits()[name]
    s_syn, s_cap, depth_m, k_syn, k_cap, _ = measure(mot, fit)
    print(f"\n{name}: skating {s_syn / s_cap:.3f}x, {100 * depth_m:.3f} cm below the floor, knee step "
          f"{np.degrees(k_syn):.1f} vs {np.degrees(k_cap):.1f} deg")
    assert s_syn <= 0.25 * s_cap
    assert depth_m <= 0.005
    assert k_syn <= k_cap


def test_foot_lock_off_is_the_step_constraints_alone():
    mot, fit = _fits()["07_01"]
    sk, dt = mot.skeleton(), mot.frame_time_s
    off = gait.synthesize_gait(fit.model, sk, 240, dt, body_map=fit.body_map, foot_lock=False)
    on = gait.synthesize_gait(fit.model, sk, 240, dt, body_map=fit.body_map)
    # The locked synthesis starts a contact earlier (`_lock_preroll`) and is re-anchored there: its
    # root moves off the unlocked one's by float32 rounding and the pre-roll's share of the root
    # rule's means (02_01, 5 s: 0.0044 units at most, 0.03 mm).
    np.testing.assert_allclose(np.asarray(on.root_position), np.asarray(off.root_position), rtol=0, atol=0.01)
    # Only leg channels change.
    names = fit.model.channel_names
    leg = {sk.topology.names[j] for g in (fit.body_map.left, fit.body_map.right) for j in (g.hip, g.knee, g.ankle)}
    changed = np.any(np.abs(np.asarray(on.features) - np.asarray(off.features)) > 1e-3, axis=0)  # float32 shapes
    assert changed.any()
    # (The root channels follow the root above: velocities of a root within 0.01 units.)
    assert all(names[c].rpartition(".")[0] in leg for c in np.flatnonzero(changed) if not names[c].startswith("root."))


def test_lock_supersampling_nears_120_fps():
    assert [gait.lock_supersampling(1 / f) for f in (24, 25, 30, 50, 60, 100, 120, 240)] == [5, 5, 4, 2, 2, 1, 1, 1]
    assert gait.lock_supersampling(1.0) == 8  # at most MAX_SUPERSAMPLING
    for bad in (0.0, -1.0, float("nan"), float("inf"), "x", None):
        assert gait.lock_supersampling(bad) == 1  # the caller's own check names it


def test_a_locked_synthesis_at_30_fps_is_every_4th_frame_of_120_fps():
    """Under 100 fps the feet are locked on denser frames and every k-th is kept: at 30 fps the
    locked frames are those of the 120 fps synthesis (the phase at frame 4 i of 120 fps is frame
    i's at 30), under vmap too; unlocked, the frames are the clip rate's own."""
    mot, fit = _fits()["07_01"]
    sk, bm = mot.skeleton(), fit.body_map
    iv = gait.contact_intervals(fit.model, sk, body_map=bm)
    kw = dict(body_map=bm, contact_intervals=iv, knee_speed_rad_s=8.0)
    at30 = gait.synthesize_gait(fit.model, sk, 31, 1 / 30, **kw)
    at120 = gait.synthesize_gait(fit.model, sk, 121, 1 / 120, **kw)
    for a, b in ((at30.features, at120.features), (at30.root_position, at120.root_position),
                 (at30.foot_positions, at120.foot_positions), (at30.phase, at120.phase), (at30.hip.L, at120.hip.L)):
        assert a.shape[0] == 31
        np.testing.assert_allclose(np.asarray(a), np.asarray(b)[::4], rtol=0, atol=1e-4)
    off = gait.synthesize_gait(fit.model, sk, 31, 1 / 30, body_map=bm, foot_lock=False)
    assert not np.allclose(np.asarray(off.features), np.asarray(at30.features))
    many = jax.vmap(lambda st: gait.synthesize_gait(fit.model, sk, 31, 1 / 30, step=st, **kw).features)(
        jnp.asarray([1.0, 0.9]))
    # float32 under vmap (the root velocities, units/s, differ by up to 1.7e-4)
    np.testing.assert_allclose(np.asarray(many[0]), np.asarray(at30.features), rtol=1e-4, atol=2e-3)
    assert np.all(np.isfinite(np.asarray(many)))


def test_lock_feet_vmaps_over_characters_and_is_differentiable():
    mot, fit = _fits()["07_01"]
    sk, dt, bm = mot.skeleton(), mot.frame_time_s, fit.body_map
    iv = gait.contact_intervals(fit.model, sk, body_map=bm)
    r = gait.synthesize_gait(fit.model, sk, 60, dt, body_map=bm, foot_lock=False)
    w = gait.contact_weights(r.phase, iv)
    feats = jnp.stack([r.features, r.features.at[:, 3:].multiply(1.01)])
    roots = jnp.stack([r.root_position, r.root_position])

    def one(f, root, smooth_frames=0, knee_speed=None):
        return gait.lock_feet(f, sk, w, body_map=bm, representation="euler", root_position=root,
                              clearance=r.clearance, smooth_frames=smooth_frames, knee_speed_rad_s=knee_speed,
                              frame_time_s=dt)

    batched = jax.jit(jax.vmap(one))(feats, roots)
    for i in range(2):
        np.testing.assert_allclose(np.asarray(batched[i]), np.asarray(one(feats[i], roots[i])), atol=1e-4)
    g = jax.grad(lambda f: jnp.sum(one(f, roots[0])[:, 3:] ** 2))(feats[0])
    assert np.all(np.isfinite(np.asarray(g)))
    g = jax.grad(lambda root: jnp.sum(one(feats[0], root, 3)[:, 3:] ** 2))(roots[0])
    assert np.all(np.isfinite(np.asarray(g))) and np.abs(np.asarray(g)).max() > 0
    # One frame of easing (30 fps): the band lift (`footlock._band_lift`) is on the path.
    g = jax.grad(lambda f: jnp.sum(one(f, roots[0], 1)[:, 3:] ** 2))(feats[0])
    assert np.all(np.isfinite(np.asarray(g))) and np.abs(np.asarray(g)).max() > 0
    # The knee-speed cap, tight enough to act on the swing: under vmap and grad (in the cap too).
    cap = jnp.asarray([2.0, 2.5])  # rad/s; 07_01's swing knee reaches about 6
    capped = jax.jit(jax.vmap(lambda f, root: one(f, root, 3, cap)))(feats, roots)
    np.testing.assert_allclose(np.asarray(capped[1]), np.asarray(one(feats[1], roots[1], 3, cap)), atol=1e-4)
    assert np.abs(np.asarray(capped[0]) - np.asarray(one(feats[0], roots[0], 3))).max() > 1e-3
    g = jax.grad(lambda c: jnp.sum(one(feats[0], roots[0], 3, c)[:, 3:] ** 2))(cap)
    assert np.all(np.isfinite(np.asarray(g))) and np.abs(np.asarray(g)).max() > 0
    with pytest.raises(UserError, match="knee_speed_rad_s"):
        one(feats[0], roots[0], 3, jnp.zeros((3,)))


def test_foot_lock_under_vmap_needs_the_map_and_intervals():
    mot, fit = _fits()["07_01"]
    sk, dt = mot.skeleton(), mot.frame_time_s
    models = jax.tree.map(lambda x: jnp.stack([x, x]), fit.model)
    with pytest.raises(UserError, match="body_map"):
        jax.vmap(lambda m: gait.synthesize_gait(m, sk, 30, dt).features)(models)
    iv = gait.contact_intervals(fit.model, sk, body_map=fit.body_map)
    out = jax.vmap(lambda m: gait.synthesize_gait(m, sk, 30, dt, body_map=fit.body_map,
                                                  contact_intervals=iv).features)(models)
    one = gait.synthesize_gait(fit.model, sk, 30, dt, body_map=fit.body_map, contact_intervals=iv).features
    # float32: traced, the model gets the default 1 s pre-roll (`_lock_preroll`); root velocities
    # (~20 units/s) then differ by up to 1.1e-4.
    np.testing.assert_allclose(np.asarray(out[1]), np.asarray(one), rtol=1e-5, atol=1e-4)


def test_intervals_from_the_model_agree_with_the_clips():
    mot, fit = _fits()["07_01"]
    from fourierjax import motion as M

    sub = mot[fit.frame_start:fit.frame_stop]
    clip = np.asarray(gait.contact_intervals(fit.model, mot.skeleton(), body_map=fit.body_map,
                                             contacts=M.foot_contacts_of(sub, body_map=fit.body_map),
                                             frame_time_s=mot.frame_time_s, phase_shift=fit.phase_shift))
    est = np.asarray(gait.contact_intervals(fit.model, mot.skeleton(), body_map=fit.body_map))
    diff = np.abs(np.angle(np.exp(1j * (clip - est))))
    print(f"\n07_01 contact intervals: clip {np.round(clip, 2).tolist()}, model {np.round(est, 2).tolist()}")
    assert diff.max() < 0.2 * 2 * np.pi  # within a fifth of the cycle


def test_stance_free_hip_is_the_shared_leg_ik():
    from fourierjax._legik import sphere_circle_point
    from fourierjax.stance import ik

    rng = np.random.default_rng(1)
    for _ in range(5):
        a, b, pole = (jnp.asarray(rng.normal(size=3), jnp.float32) for _ in range(3))
        ra, rb = jnp.float32(1.0), jnp.float32(float(jnp.linalg.norm(b - a)) * 0.8)
        p1, g1 = ik.free_hip_position(a, b, ra, rb, pole)
        p2, g2 = sphere_circle_point(a, b, ra, rb, pole)
        np.testing.assert_array_equal(np.asarray(p1), np.asarray(p2))
        np.testing.assert_allclose(float(jnp.linalg.norm(p2 - a)), 1.0, rtol=1e-4)
        np.testing.assert_allclose(float(jnp.linalg.norm(p2 - b)), float(rb), rtol=1e-4)


def test_a_near_straight_leg_bends_its_knee_the_way_it_bent():
    """`_legik.knee_pole`: the lock's knee bends towards the pose knee's offset from its own
    hip-to-ankle line, not towards the thigh. Closed form: a pose leg 2 deg short of straight,
    knee forward (+z), and a goal 3 units forward and 2 units up: the thigh as the pole put the
    new knee behind the hip-to-goal line (a backward knee, and a swing of the knee about that line
    as the goal moves: Bandai-1 run_happy's knee moved 23.5 units in a frame, see `knee_pole`)."""
    from fourierjax._legik import knee_pole, sphere_circle_point

    l1 = l2 = 10.0
    half = np.radians(1.0)  # each bone 1 deg off the hip-to-ankle line: the knee at 178 deg
    H = jnp.zeros(3)
    K = jnp.asarray([0.0, -l1 * np.cos(half), l1 * np.sin(half)])
    A = jnp.asarray([0.0, -2 * l1 * np.cos(half), 0.0])
    G = A + jnp.asarray([0.0, 2.0, 3.0])
    axis = (G - H) / jnp.linalg.norm(G - H)
    # "Forward" of the new line: +z with its component along the line removed.
    fwd = jnp.asarray([0.0, 0.0, 1.0]) - axis[2] * axis
    new, _ = sphere_circle_point(H, G, l1, l2, knee_pole(H, K, A))
    old, _ = sphere_circle_point(H, G, l1, l2, K - H)
    np.testing.assert_allclose([float(jnp.linalg.norm(new - H)), float(jnp.linalg.norm(G - new))], [l1, l2], rtol=1e-5)
    assert float(jnp.dot(new - H, fwd)) > 0.5  # the knee in front of the hip-to-goal line
    assert float(jnp.dot(old - H, fwd)) < 0.0  # the thigh as the pole: behind it (what this replaced)
    # A straight pose leg (no bend to follow) falls back on the thigh, finite.
    assert np.all(np.isfinite(np.asarray(knee_pole(H, jnp.asarray([0.0, -l1, 0.0]), A))))


def test_lock_crowd_holds_a_sliding_planted_foot():
    from fourierjax import data
    from fourierjax.body import infer_body_map
    from fourierjax.motion import motion_joint_positions

    m = data.load("07_01")
    bm = infer_body_map(m)
    P0 = motion_joint_positions(m[:1])[0]  # [J, 3]
    parents = m.topology.parents
    below = [bm.left.ankle] + [j for j in range(bm.left.ankle + 1, len(parents))
                               if parents[j] >= bm.left.ankle and parents[j] in
                               {bm.left.ankle, *range(bm.left.ankle + 1, j)}]
    floor = float(P0[[bm.left.ankle, bm.right.ankle], 1].min())
    iv = jnp.asarray([[[0.0, 6.2], [0.0, 6.2]]] * 2, jnp.float32)  # always in stance
    state, ankle = None, []
    for k in range(20):
        p = np.repeat(P0[None], 2, 0).astype(np.float32)
        p[0, below, 2] += 0.05 * k  # character 0: the left foot slides forward 0.05 units a frame
        out, state = gait.lock_crowd(jnp.asarray(p), jnp.full((2,), 0.1 * k), iv, state, body_map=bm,
                                     parents=parents, floor=jnp.full((2,), floor))
        ankle.append(np.asarray(out[0, bm.left.ankle]))
        assert np.all(np.isfinite(np.asarray(out)))
    ankle = np.asarray(ankle)
    # Held to a fifth of the slide (0.05 a frame unlocked): the rest pose's nearly straight leg
    # reaches its limit as the foot is held behind.
    assert np.abs(np.diff(ankle[:, 2])).max() < 0.2 * 0.05


def test_a_sliding_foot_point_is_not_planted_and_the_smoothing_is_a_moving_average():
    from fourierjax._gait.footlock import _smooth, stillness

    T = 20
    root = np.zeros((T, 3), np.float32)
    root[:, 2] = np.arange(T)  # the root moves 1 unit a frame
    pts = np.zeros((T, 2, 1, 3), np.float32)
    pts[:, 1, 0, 2] = 0.9 * np.arange(T)  # the right foot slides at 0.9 units a frame
    pts[:, 0, 0, 2] = 0.01 * np.arange(T)  # the left one barely moves
    w = np.asarray(stillness(jnp.asarray(pts), jnp.asarray(root), horizontal=jnp.asarray([1.0, 0.0, 1.0])))
    assert np.all(w[:, 0] == 1.0) and np.all(w[:, 1] == 0.0)
    x = jnp.zeros((T, 2)).at[10:].set(1.0)  # a step: eased over 2 frames each side, edges held
    y = np.asarray(_smooth(x, 2))
    np.testing.assert_allclose(y[[0, 7, -1], 0], [0.0, 0.0, 1.0])
    assert np.all(np.diff(y[:, 0]) >= 0) and np.abs(np.diff(y[:, 0])).max() < 0.5
    np.testing.assert_allclose(y[9:11, 0], [1 / 3, 2 / 3], atol=1e-6)  # weights 1, 2, 3, 2, 1 (/9)


def test_a_foot_that_slides_through_its_stance_stays_on_the_floor():
    """A root that outruns the stride (issue 20's `synth A --add (A-B)=1`, an extrapolation) slides
    the stance foot, never still. It is planted and slides with the hip where the leg's reach
    runs out, on the floor; the sliding-point rule lifted it 1.2 contact bands (3.2 cm on Bandai)."""
    mot, fit = _fits()["07_01"]
    sk, dt, bm = mot.skeleton(), mot.frame_time_s, fit.body_map
    up = bm.up_axis
    iv = gait.contact_intervals(fit.model, sk, body_map=bm)
    r = gait.synthesize_gait(fit.model, sk, 120, dt, body_map=bm, foot_lock=False)
    horiz = [k for k in range(3) if k != up]
    root = r.root_position.at[:, jnp.asarray(horiz)].multiply(2.5)  # the root outruns the stride
    w = gait.contact_weights(r.phase, iv)
    _, feet = gait.lock_feet(r.features, sk, w, body_map=bm, representation="euler", root_position=root,
                             clearance=r.clearance, ground=r.floor, return_feet=True, smooth_frames=5)
    band = 0.02 * float(bm.height)
    lowest = np.asarray(feet[..., up] * bm.up_sign - r.clearance[None] - r.floor).min(-1)  # [T, 2]
    stance = np.asarray(w) >= 0.99
    unlocked = np.asarray(r.foot_positions) + np.asarray(root - r.root_position)[:, None, None]
    slide = np.linalg.norm(np.diff(unlocked[..., horiz], axis=0), axis=-1).min(-1)  # [T-1, 2]
    held = np.linalg.norm(np.diff(np.asarray(feet)[..., horiz], axis=0), axis=-1).min(-1)
    both = stance[1:] & stance[:-1]
    print(f"\nstance lowest point: median {np.median(lowest[stance]):.3f}, 90% {np.quantile(lowest[stance], 0.9):.3f} "
          f"(band {band:.2f}); slide per frame {held[both].mean():.3f} locked vs {slide[both].mean():.3f} unlocked")
    # Measured: median 0.0 bands, 90% 0.39 bands (lifted, the median was 1.2 bands).
    assert np.median(lowest[stance]) <= 0.05 * band and np.quantile(lowest[stance], 0.9) <= 0.75 * band
    assert lowest.min() >= -1e-3 * band  # never below the floor
    # At 2.5x the root's speed the reach holds nothing back: 0.297 against 0.292 units a frame
    # unlocked (measured); the plant slides with the hip, no faster than 5% over the unlocked foot.
    assert held[both].mean() <= 1.05 * slide[both].mean()


def test_toe_clearance_turns_the_foot_toes_up_about_its_ankle_outside_stance():
    """Closed form: a foot whose tip lies `d` ahead of and `v` under its ankle, turned by `a`
    toes up about the ankle (axis across the foot), has its tip `d sin a + v (1 - cos a)` higher
    and `v sin a` further forward; the angle asked for is the tip's height short of
    `LIFT_BANDS` bands over the ankle's reach `d`, none in stance, none where the tip is higher."""
    from fourierjax import rotations
    from fourierjax._gait.footlock import LIFT_BANDS, _toe_clearance

    d, v, band = 8.0, 3.0, 0.5
    heights = jnp.asarray([0.0, 0.2, 0.4, 0.2, 2.0])  # the tip's height over its floor
    contact = jnp.asarray([0.0, 0.0, 0.5, 1.0, 0.0])
    T = heights.shape[0]
    A = jnp.zeros((T, 3)).at[:, 1].set(v + heights)  # ankle over the tip (y up), foot along +z
    P = jnp.stack([A, A + jnp.asarray([[0.0, -v, 0.5 * d]]), A + jnp.asarray([[0.0, -v, d]])], 1)
    q, angle = _toe_clearance(P, A, A, contact, 0.0, band, 1, 1.0, 30.0, 0)
    need = np.maximum(LIFT_BANDS * band - np.asarray(heights), 0.0) * (1.0 - np.asarray(contact))
    np.testing.assert_allclose(np.asarray(angle), need / d, rtol=1e-6, atol=1e-7)
    assert float(angle[3]) == 0.0 and float(angle[4]) == 0.0  # stance; tip high
    a = np.asarray(angle)
    tip = np.asarray(rotations.quat_apply(q, P[:, -1] - A))
    np.testing.assert_allclose(tip[:, 1], -v + d * np.sin(a) + v * (1 - np.cos(a)), atol=1e-5)
    np.testing.assert_allclose(tip[:, 2], d * np.cos(a) + v * np.sin(a), atol=1e-5)
    np.testing.assert_allclose(tip[:, 0], 0.0, atol=1e-6)
    g = jax.grad(lambda h: _toe_clearance(P, A.at[:, 1].set(v + h), A.at[:, 1].set(v + h), contact, 0.0, band, 1,
                                          1.0, 30.0, 1)[1].sum())(heights)
    assert np.all(np.isfinite(np.asarray(g)))


def test_heading_hold_keeps_the_landing_heading_and_every_height():
    """A foot that yaws and pitches through a stance keeps, by the weight, the heading (turn about
    the up axis) of the stance's first frame of full weight; its pitch, and so every height of
    the points it turns about the ankle, is left as it is; the identity where the weight is 0."""
    from fourierjax import rotations
    from fourierjax._gait.footlock import _heading_hold

    T = 12
    yaw = jnp.linspace(0.0, 0.6, T)  # radians about y (up)
    pitch = jnp.linspace(-0.2, 0.3, T)  # about x
    q = rotations.quat_multiply(rotations.quat_from_expmap(yaw[:, None] * jnp.asarray([[0.0, 1.0, 0.0]])),
                                rotations.quat_from_expmap(pitch[:, None] * jnp.asarray([[1.0, 0.0, 0.0]])))
    w = jnp.asarray([0.0, 0.3, 0.7, 1.0, 1.0, 1.0, 1.0, 1.0, 0.6, 0.2, 0.0, 0.0])
    turn = _heading_hold(q, w, 1)
    held = rotations.quat_multiply(turn, q)
    fwd = np.asarray(rotations.quat_apply(held, jnp.broadcast_to(jnp.asarray([0.0, 0.0, 1.0]), (T, 3))))
    heading = np.arctan2(fwd[:, 0], fwd[:, 2])
    # Full weight from frame 2 (the first with w >= 0.5) on: the heading of frame 2.
    np.testing.assert_allclose(heading[3:8], float(yaw[2]), atol=1e-5)
    np.testing.assert_allclose(heading[[0, 10, 11]], np.asarray(yaw)[[0, 10, 11]], atol=1e-6)
    np.testing.assert_allclose(heading[8], float(yaw[8]) + 0.6 * float(yaw[2] - yaw[8]), atol=1e-5)
    # A turn about the up axis: heights are left as they are.
    pts = jnp.asarray([[0.0, -3.0, 8.0], [1.0, -7.0, -2.0]])
    pts = jnp.broadcast_to(pts[None], (T, 2, 3))
    before = np.asarray(rotations.quat_apply(jnp.broadcast_to(q[:, None], (T, 2, 4)), pts))
    after = np.asarray(rotations.quat_apply(jnp.broadcast_to(held[:, None], (T, 2, 4)), pts))
    np.testing.assert_allclose(after[..., 1], before[..., 1], atol=1e-5)
    g = jax.grad(lambda q: jnp.sum(_heading_hold(q, w, 1) ** 2 * jnp.arange(4.0)[None]))(q)
    assert np.all(np.isfinite(np.asarray(g)))


def test_knee_speed_cap_spreads_a_fast_knee_step_over_its_neighbours():
    """Where the knee already changes slower than the cap the goals stay; a faster change is
    replaced by the mean of its Lipschitz envelopes (no lag: symmetric in time), whose steps are
    within the cap; the stance (`free` 0) keeps its goals; gradients are finite."""
    from fourierjax._gait.footlock import _knee_speed_cap

    T, l1, l2 = 40, 4.0, 4.0
    k = jnp.arange(T, dtype=jnp.float32)
    theta = 2.0 + 0.4 * jnp.tanh((k - 20.0) / 1.5)  # a 0.8 rad flexion, 0.13 rad a frame at its fastest
    d = jnp.sqrt(l1 ** 2 + l2 ** 2 - 2 * l1 * l2 * jnp.cos(theta))
    H = jnp.zeros((T, 3))
    G = jnp.stack([0.3 * d, -jnp.sqrt(0.91) * d, jnp.zeros(T)], -1)
    ones, step = jnp.ones((T,)), 0.08

    def knee(g):
        dd = jnp.linalg.norm(g - H, axis=-1)
        return np.arccos(np.clip((l1 ** 2 + l2 ** 2 - np.asarray(dd) ** 2) / (2 * l1 * l2), -1, 1))

    G2, moved = _knee_speed_cap(H, G, jnp.full((T,), l1), jnp.full((T,), l2), step, ones, 6)
    th2 = knee(G2)
    assert np.abs(np.diff(knee(G))).max() > 0.12
    assert np.abs(np.diff(th2)).max() <= step + 1e-5
    np.testing.assert_allclose(th2[[0, 1, -2, -1]], np.asarray(theta)[[0, 1, -2, -1]], atol=1e-5)
    assert not bool(moved[0]) and bool(moved[18]) and bool(moved[22])
    np.testing.assert_allclose(th2[20], float(theta[20]), atol=1e-4)  # centred: the midpoint stays
    # The goals move along the hip-to-goal line only.
    u1 = np.asarray(G / jnp.linalg.norm(G, axis=-1, keepdims=True))
    u2 = np.asarray(G2 / jnp.linalg.norm(G2, axis=-1, keepdims=True))
    np.testing.assert_allclose(u1, u2, atol=1e-5)
    stance = ones.at[15:25].set(0.0)
    G3, moved3 = _knee_speed_cap(H, G, jnp.full((T,), l1), jnp.full((T,), l2), step, stance, 6)
    np.testing.assert_array_equal(np.asarray(G3[15:25]), np.asarray(G[15:25]))
    assert not bool(jnp.any(moved3[15:25]))
    g = jax.grad(lambda g: jnp.sum(_knee_speed_cap(H, g, jnp.full((T,), l1), jnp.full((T,), l2), step, ones,
                                                   6)[0] ** 2))(G)
    assert np.all(np.isfinite(np.asarray(g)))
    # A per-frame cap (a speed schedule): each step within its own frame's.
    steps = jnp.where(k < 20, 0.06, 0.1)
    G4, _ = _knee_speed_cap(H, G, jnp.full((T,), l1), jnp.full((T,), l2), steps, ones, 12)
    assert np.all(np.abs(np.diff(knee(G4))) <= np.asarray(steps)[:-1] + 1e-5)


def test_knee_speed_limit_is_the_largest_knee_step_per_second():
    from types import SimpleNamespace

    T, dt = 30, 1 / 60
    ang = np.linspace(0.0, 1.2, T) ** 2  # the left knee bends faster and faster
    leg_l = SimpleNamespace(hip=0, knee=1, ankle=2)
    leg_r = SimpleNamespace(hip=3, knee=4, ankle=5)
    bm = SimpleNamespace(left=leg_l, right=leg_r)
    p = np.zeros((T, 6, 3))
    p[:, 0] = [0.0, 1.0, 0.0]  # hip over the knee at the origin
    p[:, 2] = np.stack([np.sin(ang), -np.cos(ang), 0 * ang], -1)  # the shin turns by `ang` from straight
    p[:, 3:6] = p[:, 0:3] + [5.0, 0.0, 0.0]
    p[:, 5] = [5.0, -1.0, 0.0]  # the right leg stays straight
    limit = gait.knee_speed_limit(p, dt, bm)
    np.testing.assert_allclose(limit, [np.abs(np.diff(ang)).max() / dt, 0.0], atol=1e-6)
    np.testing.assert_allclose(gait.knee_angles(p, bm)[:, 0], np.pi - ang, atol=1e-6)
    with pytest.raises(UserError, match="positions"):
        gait.knee_speed_limit(p[:1], dt, bm)


def test_knee_speed_is_stored_with_the_model_and_old_files_have_none(tmp_path):
    from fourierjax import model_io

    mot, fit = _fits()["07_01"]
    limit = gait.fit_knee_speed(fit, mot)
    from fourierjax import motion as M

    sub = mot[fit.frame_start:fit.frame_stop]
    np.testing.assert_allclose(limit, gait.knee_speed_limit(M.motion_joint_positions(sub), mot.frame_time_s,
                                                            fit.body_map))
    assert limit.shape == (2,) and np.all(limit > 0)
    path = tmp_path / "m.npz"
    model_io.save_model(path, fit.model, motion=mot, body_map=fit.body_map, knee_speed_rad_s=limit)
    np.testing.assert_allclose(model_io.load_model(path).knee_speed_rad_s, limit)
    model_io.save_model(path, fit.model, motion=mot, body_map=fit.body_map)
    assert model_io.load_model(path).knee_speed_rad_s is None
    with pytest.raises(UserError, match="knee_speed_rad_s"):
        model_io.save_model(path, fit.model, motion=mot, knee_speed_rad_s=[1.0, -2.0])
