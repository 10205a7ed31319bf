"""Grounded locomotion (issue #21 item 2, issue #20's root speeds): the captured speed, and
walk <-> run transitions that keep the hip rule and root motion."""

import functools
import pathlib

import jax.numpy as jnp
import numpy as np
import pytest

from fourierjax import data, gait, style
from fourierjax import motion as fmotion
from fourierjax.data import detect_rest_frames
from fourierjax.errors import UserError
from fourierjax.features import motion_from_features, place_root
from fourierjax.io.bvh import read_bvh
from fourierjax.kinematics import fk_frames

BANDAI = pathlib.Path(__file__).resolve().parents[1] / ".." / "shared" / "data" / "mocap" / "bandai1" / "data"
WALKS_AND_RUNS = ("02_01", "02_03", "07_01", "07_04", "07_12", "09_01", "09_02")


def _load(name):
    m = read_bvh(name) if str(name).endswith(".bvh") else data.load(name)
    return m[detect_rest_frames(m):]


@functools.cache
def _fits(names, harmonics=3):
    motions = [_load(n) for n in names]
    return motions, fmotion.fit_motions(motions, harmonics, "euler", throw=True)


def _captured_speeds(motions, fits):
    """Captured root speeds `[B]` (file units/s, ground plane): the trajectory joint's travel over
    each fitted segment. One FK call for every clip: only the segment's first and last frames
    are needed, so the batch is `[B, 2, C]` whatever the clip lengths (skeletons vmapped)."""
    import jax

    chans = jnp.asarray(np.stack([m.channels[[f.frame_start, f.frame_stop - 1]] for m, f in zip(motions, fits)]))
    sks = jax.tree_util.tree_map(lambda *xs: jnp.stack(xs), *[m.skeleton() for m in motions])
    P = np.asarray(jax.vmap(lambda sk, ch: fk_frames(sk, ch).positions)(sks, chans))  # [B, 2, J, 3]
    out = []
    for p, f in zip(P, fits):
        bm = f.body_map
        d = p[1, bm.trajectory] - p[0, bm.trajectory]
        d[bm.up_axis] = 0
        out.append(np.linalg.norm(d) / ((f.frame_stop - f.frame_start - 1) * f.frame_time_s))
    return np.asarray(out)


def _speed_ratios(motions, fits, cycles=4):
    """Synthesized / captured root speed of each clip. The synthesis (`synthesize_gait` with root
    motion) has one length for all clips, `cycles` cycles of the slowest, so it compiles once for
    models of one shape (it compiled per clip with a length per clip); each clip's speed is taken
    over the whole cycles that fit. Foot locking leaves the root path as it is: off here."""
    captured = _captured_speeds(motions, fits)
    dt = fits[0].frame_time_s
    assert all(f.frame_time_s == dt for f in fits)
    n = int(round(cycles * 2 * np.pi / min(float(f.model.omega) for f in fits) / dt)) + 1
    ratios = []
    for m, f, c in zip(motions, fits, captured):
        sk = m.skeleton()
        r = gait.synthesize_gait(f.model, sk, n, dt, body_map=gait.model_body_map(f.model, sk), foot_lock=False)
        period = 2 * np.pi / float(f.model.omega)
        k = min(int(round(np.floor((n - 1) * dt / period) * period / dt)), n - 1)
        dd = np.array(r.root_position[k] - r.root_position[0])
        dd[f.body_map.up_axis] = 0
        ratios.append(np.linalg.norm(dd) / (k * dt) / c)
    return np.asarray(ratios)


# ------------------------------------------------------------------------------ the right speed
def test_the_planted_point_carries_the_root_not_the_lowest():
    """A landing heel, lower than the planted foot but still swinging forward, carried the root
    backwards (0.72-0.90 of the captured speed on the bundled clips); the planted one is still
    in the model's own world (`flight_step + its move`) and carries it at the model's speed."""
    T, v = 40, 1.0
    k = np.arange(T, dtype=np.float32)
    feet = np.zeros((T, 2, 1, 3), np.float32)
    feet[:, 0, 0, 2] = -v * k  # planted: moves back under the pelvis at the root's speed
    feet[:, 1, 0, 2] = 0.5 * v * k  # swinging forward (world speed 1.5 v), and the lowest point
    feet[:, 0, 0, 1] = -10.0
    feet[:, 1, 0, 1] = -10.05
    height = np.full(T, 10.0, np.float32)
    flight = np.tile([[0.0, v]], (T - 1, 1)).astype(np.float32)
    root = np.asarray(gait.root_trajectory(jnp.asarray(feet), jnp.asarray(height), jnp.zeros(T), jnp.zeros((2, 1)),
                                           flight_step=jnp.asarray(flight)))
    np.testing.assert_allclose(root[-1, 2], v * (T - 1), rtol=1e-3)
    # Without the model's move (no flight step) the lowest point still carries it: backwards.
    alone = np.asarray(gait.root_trajectory(jnp.asarray(feet), jnp.asarray(height), jnp.linspace(0, 6, T),
                                            jnp.zeros((2, 1))))
    assert alone[-1, 2] < 0
    # In flight (frames 15-25: no point still in the model's world, both swing forward) the
    # model's own move carries it; the lowest point alone would carry it backwards there.
    sweep = np.where((k >= 15) & (k < 25), 0.5 * v, -v).astype(np.float32)
    feet[:, 0, 0, 2] = np.concatenate([[0.0], np.cumsum(sweep[1:])])
    root = np.asarray(gait.root_trajectory(jnp.asarray(feet), jnp.asarray(height), jnp.zeros(T), jnp.zeros((2, 1)),
                                           flight_step=jnp.asarray(flight)))
    np.testing.assert_allclose(root[-1, 2], v * (T - 1), rtol=0.05)


def test_root_speed_is_the_captured_on_every_bundled_walk_and_run():
    """Issue #21: within +-5% (was 0.72-0.96: 02_03 0.72, 09_02 0.72, 09_01 0.74, 07_01 0.85)."""
    motions, fits = _fits(WALKS_AND_RUNS)
    ratios = dict(zip(WALKS_AND_RUNS, _speed_ratios(motions, fits)))
    assert all(abs(r - 1) <= 0.05 for r in ratios.values()), ratios


BANDAI_KINDS = ("walk", "run", "dash", "walk-back")
STYLES = ("active", "angry", "childish", "chimpira", "feminine", "giant", "happy", "masculinity", "musical",
          "normal", "not-confident", "old", "proud", "sad", "tired")


@pytest.fixture(scope="module")
def bandai_speed_ratios():
    """Synthesized / captured root speed of all 60 Bandai-1 `_001` walks, runs, dashes and
    walk-backs: one batched `fit_motions` call, one FK call, one synthesis program."""
    if not BANDAI.is_dir():
        pytest.skip(f"Bandai-Namco data set not present at {BANDAI}")
    names = tuple(str(BANDAI / f"dataset-1_{k}_{s}_001.bvh") for k in BANDAI_KINDS for s in STYLES)
    motions = [_load(n) for n in names]
    fits = fmotion.fit_motions(motions, 3, "euler", throw=True)
    return dict(zip((pathlib.Path(n).stem for n in names), _speed_ratios(motions, fits, cycles=3)))


@pytest.mark.slow
@pytest.mark.parametrize("kind", BANDAI_KINDS)
def test_bandai_root_speed_within_10_percent(kind, bandai_speed_ratios):
    """Issue #20: every Bandai-1 walk, run, dash and walk-back within +-10% of the captured speed
    (measured 0.952-1.023 over the 60 clips; before, walks happy 0.81, not-confident 0.78, old
    0.88, tired 0.73)."""
    ratios = {k: r for k, r in bandai_speed_ratios.items() if k.startswith(f"dataset-1_{kind}_")}
    assert len(ratios) == len(STYLES)
    assert all(abs(r - 1) <= 0.10 for r in ratios.values()), ratios


# ------------------------------------------------------------------------ grounded transitions
def _foot_points(motion, bm):
    fk = fk_frames(motion.skeleton(), motion.channels)
    allp = np.concatenate([np.asarray(fk.positions), np.asarray(fk.end_site_positions)], axis=1)
    feet = allp[:, [*bm.left.foot_points, *bm.right.foot_points]].reshape(len(allp), 2, -1, 3)
    return feet, np.asarray(fk.positions)


def _flight_and_pop(motion, bm):
    """(flight fraction, largest per-frame joint position change) of a captured motion. Flight is
    `gait.contact_flight_fraction`: no foot point within 2% of the body height of its floor, the
    floor the clip's fitted ground plane (`contacts.estimate_ground`). CMU subject 02's floor
    rises 1.6% along z, 1.1 units (6 cm) over 02_03's steady run: against one level floor its
    late stance read as flight (53% of the frames, or 46% with the floor at the 20% quantile of
    the lowest point) where the plane gives 16%."""
    from fourierjax import contacts

    feet, P = _foot_points(motion, bm)
    ground = contacts.estimate_ground(feet, motion.frame_time_s, up_axis=bm.up_axis)
    floor = contacts.floor_heights(ground, feet, up_axis=bm.up_axis)
    flight = float(gait.contact_flight_fraction(feet, body_map=bm, floor=floor))
    return flight, float(np.linalg.norm(np.diff(P, axis=0), axis=-1).max())


def _check_transition(walk_name, run_name, harmonics=5, seconds=6.0, start=2.0, duration=1.5, foot_lock=True):
    """The issue's acceptance figures for walk -> run and run -> walk, as a dict per direction."""
    motions, fits = _fits((walk_name, run_name), harmonics)
    bm, dt = fits[0].body_map, fits[0].frame_time_s
    sk = motions[0].skeleton()
    walk, run = fits[0].model, fits[1].model
    out = {}
    for direction, (a, b) in (("walk->run", (walk, run)), ("run->walk", (run, walk))):
        T = int(round(seconds / dt))
        r = style.grounded_transition(a, b, sk, T, dt, start, duration, body_map=bm, foot_lock=foot_lock)
        low, s = np.asarray(r.lowest), np.asarray(r.s)
        walk_part = (s <= 0.0) if direction == "walk->run" else (s >= 1.0)
        run_part = ~walk_part & ((s >= 1.0) | (s <= 0.0))
        tol = 0.02 * bm.height
        mot = place_root(motion_from_features(motions[0], np.asarray(r.features), a.channel_names, dt, body_map=bm),
                         np.asarray(r.root_position, np.float64), body_map=bm)
        _, P = _foot_points(mot, bm)
        jumps = np.linalg.norm(np.diff(P, axis=0), axis=-1).max()
        fl_run, pop_run = _flight_and_pop(motions[1][fits[1].frame_start:fits[1].frame_stop], bm)
        _, pop_walk = _flight_and_pop(motions[0][fits[0].frame_start:fits[0].frame_stop], bm)
        own = style.grounded_transition(run, run, sk, T, dt, start, duration, body_map=bm, foot_lock=foot_lock)
        feet = np.asarray(r.foot_positions)
        floor = float(r.floor) + np.asarray(r.clearance)[None]  # each point's floor
        out[direction] = dict(
            on_floor=float(np.mean(low[walk_part].min(-1) <= tol)),
            flight=float(gait.contact_flight_fraction(feet[run_part], body_map=bm, floor=floor)),
            flight_captured=fl_run,
            flight_model=float(gait.contact_flight_fraction(np.asarray(own.foot_positions), body_map=bm,
                                                            floor=float(own.floor) + np.asarray(own.clearance)[None])),
            below_cm=float(-low.min() * bm.metres_per_unit * 100),
            pop=float(jumps), pop_sources=max(pop_run, pop_walk),
            speed=float(np.linalg.norm(np.diff(np.asarray(r.root_position)[:, [0, 2]], axis=0), axis=1).max()),
        )
    return out


def _assert_grounded(res):
    for direction, m in res.items():
        assert m["on_floor"] >= 0.95, (direction, m)
        assert m["below_cm"] <= 1.0, (direction, m)
        assert m["pop"] <= m["pop_sources"], (direction, m)
        # Flight only where the run has it: as much as the run model's own.
        assert abs(m["flight"] - m["flight_model"]) <= 0.10, (direction, m)
        assert m["flight"] > 0.05, (direction, m)


@pytest.fixture(scope="module")
def cmu_transition():
    return _check_transition("02_01", "02_03")


def test_cmu_walk_run_transitions_are_grounded(cmu_transition):
    """Feet locked (the default): a foot on the floor in every walk frame, none below it, no pop
    (measured 0.923 walk -> run and 0.899 run -> walk against the sources' 1.016; 1.049 before
    the feet's shifts were eased)."""
    _assert_grounded(cmu_transition)


def test_cmu_unlocked_run_flies_as_the_capture():
    """Flight by one definition (`gait.contact_flight_fraction`, the capture on its fitted floor
    plane): the unlocked run part flies 11-12% of its frames against the captured 16% (22-23%
    while the model's own root drift in stance counted as flight). (It read 46% against 28%
    when the capture's sloped floor was taken as level.)"""
    for direction, m in _check_transition("02_01", "02_03", foot_lock=False).items():
        assert abs(m["flight"] - m["flight_captured"]) <= 0.10, (direction, m)
        assert m["on_floor"] >= 0.95 and m["below_cm"] <= 1.0 and m["pop"] <= m["pop_sources"], (direction, m)


# Measured 2026-12-04 (N = 5, 6 s, run part s = 1, intervals estimated from the models' cycles as
# here): the run part flies 23.7% walk -> run and 24.5% run -> walk against the captured 16.2%
# (the run model's own 19.3%). It flew 29.3% / 31.1% while `lock_feet` lifted the landing heel
# to 1.2 contact bands as it decelerated into the band (6-12 frames a landing, 38 units/s one
# band up): it was not still by `stillness`, so not planted, and the lift was judged on the
# unlocked foot. Now a landing point is planted under twice the stillness threshold until a point
# of its foot is still, and the lift is judged after the hold (`_lock`); skating 02_01 0.208x ->
# 0.205x, 02_03 0.306x -> 0.298x, 09_01 0.398x -> 0.378x. Each alone: the earlier plant 29.3% /
# 31.1%, the lift after the hold 27.3% / 29.1%. Before: not lifting the heel in the plant's
# lead-in gave 27.0% / 27.0% at +0.012x skating on 02_03; the stored intervals (low and slow,
# `fit_contact_intervals`) read 27.7% / 29.5%.
def test_cmu_run_flight_matches_the_capture(cmu_transition):
    for direction, m in cmu_transition.items():
        assert abs(m["flight"] - m["flight_captured"]) <= 0.10, (direction, m)


def test_the_sources_knee_speeds_cap_the_transitions_knee():
    """Issue #21 item 1 (the knee never pops) in a transition, CMU 02_03 -> 02_01 (N = 4, 120 fps,
    blend from 2 s over 1 s), against the captures' largest knee step, 5.28 deg:
    - Inside the blend the stance feet carry the root (`_grounded`). The blend's own root speed
      let the walk's first stance foot slide 8.5 units, which the lock held and let go of at the
      blend's end: 8.02 deg with the intervals estimated from the models, 14.04 with the
      captures' (as `fourierjax fit` stores them; 9.44 capped). Carried: 5.24 and 5.36.
    - The sources' knee speeds (`gait.fit_knee_speed`, as `synth` passes its clip's) cap the
      lock's swing knee, blended by s: with the captures' intervals 5.36 -> 5.23."""
    motions, fits = _fits(("02_01", "02_03"), 4)
    bm, dt = fits[0].body_map, fits[0].frame_time_s
    sk = motions[0].skeleton()
    knees = [gait.fit_knee_speed(f, m) for f, m in zip(fits, motions)]
    stored = [gait.contact_intervals(f.model, sk, body_map=bm, frame_time_s=m.frame_time_s, phase_shift=f.phase_shift,
                                     contacts=fmotion.foot_contacts_of(m[f.frame_start:f.frame_stop], body_map=bm))
              for m, f in zip(motions, fits)]

    def largest_step(motion):
        P = fmotion.motion_joint_positions(motion)
        return float(np.degrees(np.abs(np.diff(gait.knee_angles(P, bm), axis=0)).max()))

    captured = max(largest_step(m[f.frame_start:f.frame_stop]) for m, f in zip(motions, fits))
    T = int(round(5.0 / dt))
    steps = {}
    ivs = {"contact_intervals": (stored[1], stored[0])}
    capped = {**ivs, "knee_speed_rad_s": (knees[1], knees[0])}
    for label, kw in (("estimated", {}), ("stored", ivs), ("capped", capped)):
        r = style.grounded_transition(fits[1].model, fits[0].model, sk, T, dt, 2.0, 1.0, body_map=bm, **kw)
        mot = place_root(motion_from_features(motions[0], np.asarray(r.features), fits[1].model.channel_names, dt,
                                              body_map=bm), np.asarray(r.root_position, np.float64), body_map=bm)
        steps[label] = largest_step(mot)
        assert float(np.asarray(r.lowest).min()) >= -1e-3, label
    assert steps["estimated"] <= captured, (steps, captured)
    assert steps["stored"] > captured, steps  # the step the cap removes (else the cap's check shows nothing)
    assert steps["capped"] <= captured, (steps, captured)
    for bad, match in (((1.0,), r"\(A's, B's\)"), ((knees[0], np.ones(3)), "scalar or \\[2\\]"),
                       ((knees[0], -1.0), "finite and > 0"), ((np.nan, knees[1]), "finite and > 0")):
        with pytest.raises(UserError, match=match):
            style.grounded_transition(fits[1].model, fits[0].model, sk, 8, dt, 0.0, 0.1, body_map=bm,
                                      knee_speed_rad_s=bad)


def test_grounded_transition_keeps_the_pose_and_travels_at_the_blend_speed():
    """Without locking only the root channels change; the root travels as fast as the blend's
    own root velocity. Foot locking (the default) changes the legs' angles only, keeps the root
    path, and needs contact intervals under a trace."""
    motions, fits = _fits(("02_01", "02_03"), 5)
    bm, dt = fits[0].body_map, fits[0].frame_time_s
    T = int(round(4.0 / dt))
    sk = motions[0].skeleton()
    g = style.grounded_transition(fits[0].model, fits[1].model, sk, T, dt, 1.0, 1.5, body_map=bm, foot_lock=False)
    x = style.transition(fits[0].model, fits[1].model, jnp.arange(T) * dt, 1.0, 1.5)
    np.testing.assert_allclose(np.asarray(g.features[:, 3:]), np.asarray(x[:, 3:]), atol=1e-5)  # same pose
    # Grounded: the root travels at the blend's own speed.
    travel = np.linalg.norm(np.asarray(g.root_position[-1] - g.root_position[0])[[0, 2]])
    own = np.linalg.norm(np.asarray(x[:, :2]).sum(0) * dt)
    assert abs(travel / own - 1) < 0.05
    locked = style.grounded_transition(fits[0].model, fits[1].model, sk, T, dt, 1.0, 1.5, body_map=bm,
                                       foot_lock=True)
    np.testing.assert_array_equal(np.asarray(locked.root_position), np.asarray(g.root_position))
    names = fits[0].model.channel_names
    legs = {sk.topology.names[j] for leg in (bm.left, bm.right) for j in (leg.hip, leg.knee, leg.ankle)}
    leg_cols = np.asarray([i for i, n in enumerate(names) if n.partition(".")[0] in legs])
    other = np.asarray([i for i in range(3, len(names)) if i not in set(leg_cols)])
    np.testing.assert_allclose(np.asarray(locked.features[:, other]), np.asarray(g.features[:, other]), atol=1e-6)
    assert np.abs(np.asarray(locked.features[:, leg_cols] - g.features[:, leg_cols])).max() > 1e-3
    assert float(np.asarray(locked.lowest).min()) >= -1e-3  # never below the floor
    import jax

    with pytest.raises(UserError, match="contact_intervals"):
        jax.jit(lambda a: style.grounded_transition(a, fits[1].model, sk, 8, dt, 0.0, 0.1, body_map=bm,
                                                     foot_lock=True).features)(
            fits[0].model)
    ivs = tuple(gait.contact_intervals(f.model, sk, body_map=bm) for f in fits)
    with pytest.raises(UserError, match=r"`stance` must be \[T\]"):
        gait.ground_features(x, sk, "euler", dt, body_map=bm, stance=np.ones(T - 1))
    with pytest.raises(UserError, match=r"weights in \[0, 1\] \(finite\)"):
        gait.ground_features(x, sk, "euler", dt, body_map=bm, stance=np.full(T, np.nan))
    with pytest.raises(UserError, match="concrete `frame_time_s`"):  # it sets the easing's frames
        jax.jit(lambda d: style.grounded_transition(fits[0].model, fits[1].model, sk, 8, d, 0.0, 0.1, body_map=bm,
                                                     contact_intervals=ivs).features)(dt)


# Bandai-1 walk_normal <-> run_normal (N = 5, 30 fps), measured 2026-12-04: the run part flies
# 40.0% walk -> run and 39.3% run -> walk against the captured 16.7%, as before the landing fix
# above (the same figures; its own 31.1%, was 31.7%). Unlocked it flies 0%: the low-harmonic
# landing foot sweeps in 0.4-0.9 contact bands over the floor at 137-449 units/s (1.4-4.5 m/s)
# for 5 frames a landing, so it is in the band but far from still, and the lock lifts it out.
# The issue's +-10 points on Bandai are not met; this test asserts the rest of `_assert_grounded`.
@pytest.mark.slow
def test_bandai_walk_run_transitions_are_grounded():
    if not BANDAI.is_dir():
        pytest.skip(f"Bandai-Namco data set not present at {BANDAI}")
    res = _check_transition(str(BANDAI / "dataset-1_walk_normal_001.bvh"), str(BANDAI / "dataset-1_run_normal_001.bvh"))
    _assert_grounded(res)


def test_transition_command_writes_the_grounded_motion(tmp_path):
    from fourierjax.cli import main

    a, b = str(data.path("02_01")), str(data.path("02_03"))
    out = tmp_path / "t.bvh"
    assert main(["transition", a, b, "--seconds", "4", "--start", "1.5", "--duration", "1.5", "--out", str(out)]) == 0
    mot = read_bvh(out)
    from fourierjax import body

    bm = body.infer_body_map(mot)
    feet, P = _foot_points(mot, bm)
    walk = slice(0, int(1.5 / mot.frame_time_s))
    local = feet - P[:, bm.pelvis, None, None, :] * np.eye(3)[[0, 2]].sum(0)  # ground-plane relative
    # Sole clearances as the grounding estimates them: from all the frames.
    clearance = np.asarray(gait.estimate_sole_clearance(jnp.asarray(local), up_axis=bm.up_axis))
    low = (feet[..., bm.up_axis] - clearance[None]).min(axis=(1, 2))
    floor = low[walk].min()
    assert np.mean(np.abs(low[walk] - floor) <= 0.02 * bm.height) >= 0.95  # standing on one floor
    assert low.min() >= floor - 1.0 / (100 * bm.metres_per_unit)  # never 1 cm below it
    travel = P[-1, bm.pelvis] - P[0, bm.pelvis]
    assert np.linalg.norm(travel[[0, 2]]) > 50  # walks, then runs: ~4 s at 20-46 units/s
    assert main(["transition", a, b, "--seconds", "4", "--start", "1.5", "--duration", "1.5", "--no-root-motion",
                 "--out", str(tmp_path / "n.bvh")]) == 0


def test_a_warm_grounded_transition_runs_a_few_saved_programs(monkeypatch, tmp_path):
    """Issue 25: a second `fourierjax transition` (from model files) was 552 XLA programs and 447
    traces, 8.9 s: the hip rule, root motion, floors, FK and foot locking ran as small eager and
    jitted pieces. The tail after the blend is one saved program now. As a new process with a
    warm cache (`jax.clear_caches()`, saved programs on): a handful of programs, the tail
    loaded, not traced, and the same frames. Counted with JAX's compile events, never a clock.
    Last in the file: the cleared caches cost later tests their compiled programs."""
    import jax

    from fourierjax import _compile_cache
    from fourierjax._programs import ProgramCount

    monkeypatch.delenv(_compile_cache.NO_CACHE_ENV, raising=False)
    monkeypatch.setenv(_compile_cache.CACHE_DIR_ENV, str(tmp_path / "cache"))
    monkeypatch.setattr(_compile_cache, "_enabled", True)
    motions, fits = _fits(("02_01", "02_03"), 5)
    dt = fits[0].frame_time_s
    args = (fits[0].model, fits[1].model, motions[0].skeleton(), int(round(3.0 / dt)), dt, 1.0, 1.0)
    first = style.grounded_transition(*args, body_map=fits[0].body_map)
    jax.clear_caches()
    with ProgramCount() as count:
        again = style.grounded_transition(*args, body_map=fits[0].body_map)
    np.testing.assert_allclose(np.asarray(again.features), np.asarray(first.features), rtol=0, atol=1e-5)
    np.testing.assert_allclose(np.asarray(again.root_position), np.asarray(first.root_position), atol=1e-4)
    assert "_grounded" not in count.by_name and "flat" not in count.by_name, count.by_name
    assert count.programs <= 16, (count.programs, dict(count.where))
