"""Tests of fourierjax.gait: Unuma 1995 §3.1 step constraints, hip-height rule, root motion."""

from __future__ import annotations

import functools
import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from fourierjax import contacts as C
from fourierjax import gait as G
from fourierjax.errors import UserError
from tests.helpers import CMU_BUNDLED, NamesTopology, fk_oracle, read_bvh_oracle

# ----------------------------------------------------------------------------- hip rule, pure


def test_faithful_rule_matches_hand_computed_eq4_eq5():
    leg = jnp.array([[10.0, 8.0], [9.0, 9.5], [7.0, 6.0], [8.0, 10.0], [9.6, 2.0]])
    # eq. 4: L = max(L_L, L_R); Lmax = 10; N = (Lmax - L) / Lmax.
    h = G.hip_rule(leg, 0.1, 2.0)
    np.testing.assert_allclose(h.L, [10.0, 9.5, 7.0, 10.0, 9.6])
    np.testing.assert_allclose(h.l_max, 10.0)
    np.testing.assert_allclose(h.N, [0.0, 0.05, 0.3, 0.0, 0.04], atol=1e-7)
    # eq. 5: only frame 2 has N > gait; L_run = L + jump * sqrt(Lmax - L) = 7 + 2 sqrt(3).
    np.testing.assert_allclose(h.lift, [0.0, 0.0, 2 * math.sqrt(3.0), 0.0, 0.0], rtol=1e-6)
    np.testing.assert_array_equal(h.flight, [0, 0, 1, 0, 0])
    h2 = G.hip_rule(leg, 0.045, 2.0)
    np.testing.assert_allclose(h2.lift, [0, 2 * math.sqrt(0.5), 2 * math.sqrt(3.0), 0, 0],
                               rtol=1e-6)
    # An explicit Lmax (a cycle's) is used as given.
    h3 = G.hip_rule(leg, 0.1, 1.0, l_max=12.0)
    np.testing.assert_allclose(h3.N, (12.0 - h.L) / 12.0, rtol=1e-6)


def test_faithful_rule_jumps_at_threshold_continuous_does_not(x64):
    lmax, gait, jump = 10.0, 0.2, 1.5
    # Sweep L through the threshold L = (1 - gait) Lmax = 8 with a fine step.
    L = jnp.linspace(7.9, 8.1, 2001)
    leg = jnp.stack([L, L - 1.0], -1)
    f = G.hip_rule(leg, gait, jump, rule="unuma1995", l_max=lmax)
    c = G.hip_rule(leg, gait, jump, rule="continuous", l_max=lmax)
    step_f = jnp.max(jnp.abs(jnp.diff(f.L + f.lift)))
    step_c = jnp.max(jnp.abs(jnp.diff(c.L + c.lift)))
    # The faithful rule jumps by jump * sqrt(gait Lmax) at N = gait ...
    np.testing.assert_allclose(step_f, jump * math.sqrt(gait * lmax), rtol=1e-3)
    # ... the continuous one moves no more than its slope allows (L step 1e-4).
    assert step_c < 1e-3
    # Same flight frames; continuous = faithful - jump sqrt(gait Lmax) in flight.
    np.testing.assert_array_equal(f.flight, c.flight)
    fl = f.flight > 0
    np.testing.assert_allclose(c.lift[fl], f.lift[fl] - jump * math.sqrt(gait * lmax), atol=1e-9)
    np.testing.assert_allclose(c.lift[~fl], 0.0)


def test_smooth_rule_tends_to_faithful(x64):
    rng = np.random.default_rng(1)
    leg = jnp.asarray(rng.uniform(8.0, 10.0, size=(200, 2)))
    f = G.hip_rule(leg, 0.1, 1.0)
    s = G.hip_rule(leg, 0.1, 1.0, rule="smooth", temperature=1e-5, width=1e-5)
    away = np.abs(np.asarray(f.N) - 0.1) > 1e-3
    np.testing.assert_allclose(np.asarray(s.L + s.lift)[away], np.asarray(f.L + f.lift)[away],
                               atol=2e-3)  # the softened sqrt is off by at most 1e-4 Lmax


def test_hip_rule_curves_for_the_plot():
    L = 9.0 + np.sin(np.linspace(0, 4 * np.pi, 100))
    leg = jnp.asarray(np.stack([L, 19.0 - L - 0.5], -1))
    out = G.hip_rule_curves(leg, 0.05, 1.0)
    assert set(out) == {"L", "N", "unuma1995", "continuous", "smooth"}
    for k in ("unuma1995", "continuous"):
        assert out[k].shape == (100,) and bool(jnp.all(out[k] >= out["L"]))
    assert bool(jnp.all(out["continuous"] <= out["unuma1995"] + 1e-6))


def test_hip_rule_bad_input():
    with pytest.raises(UserError, match="hip rule"):
        G.hip_rule(jnp.ones((4, 2)), 0.5, 1.0, rule="bouncy")
    with pytest.raises(UserError, match="leg"):
        G.hip_rule(jnp.ones((4, 3)), 0.5, 1.0)


def test_hip_rule_degenerate_legs_error_when_concrete_and_stay_finite_when_traced():
    # All-zero legs: N = 0/0 = NaN (and NaN lift for the smooth rule), silently.
    zeros = jnp.zeros((4, 2))
    for rule in G.RULES:
        with pytest.raises(UserError, match=r"^hip_rule: Lmax \(the largest leg height in `leg`\)"):
            G.hip_rule(zeros, 0.1, 1.0, rule=rule)
    with pytest.raises(UserError, match=r"^hip_rule: Lmax \(`l_max`\) must be finite and > 0"):
        G.hip_rule(jnp.ones((4, 2)), 0.1, 1.0, l_max=0.0)
    with pytest.raises(UserError, match=r"^hip_rule: Lmax"):
        G.hip_rule(jnp.full((4, 2), jnp.nan), 0.1, 1.0)
    with pytest.raises(UserError, match=r"^hip_rule: `jump` must be >= 0"):
        G.hip_rule(jnp.ones((4, 2)), 0.1, -1.0)
    with pytest.raises(UserError, match=r"^hip_rule: `gait` must be finite"):
        G.hip_rule(jnp.ones((4, 2)), float("nan"), 1.0)
    # Traced: no value check; N = 0 (no flight), lift 0, finite gradients instead of 0/0.
    for rule in G.RULES:
        h = jax.jit(lambda leg, r=rule: G.hip_rule(leg, 0.1, 1.0, rule=r))(zeros)
        for field in (h.N, h.lift, h.flight, h.L):
            assert bool(jnp.all(jnp.isfinite(field))), (rule, h)
        np.testing.assert_array_equal(h.N, 0.0)
        np.testing.assert_array_equal(h.lift, 0.0)
        grads = _grad_all(zeros, jnp.float32(0.1), jnp.float32(1.0), rule)
        assert all(bool(jnp.all(jnp.isfinite(x))) for x in grads), rule


_grad_all = jax.jit(
    jax.grad(
        lambda leg, gait, jump, rule: jnp.sum(
            G.hip_rule(leg, gait, jump, rule=rule).L + G.hip_rule(leg, gait, jump, rule=rule).lift
        ),
        argnums=(0, 1, 2),
    ),
    static_argnums=3,
)


@settings(max_examples=60, deadline=None)
@given(
    st.lists(st.tuples(st.floats(0.5, 20.0), st.floats(0.5, 20.0)), min_size=1, max_size=8),
    st.floats(-0.2, 1.2),
    st.floats(0.0, 10.0),
    st.booleans(),
)
def test_rule_gradients_finite_everywhere(pairs, gait, jump, tie):
    leg = np.array(pairs, dtype=np.float32)
    if tie:  # exact ties L_L = L_R and frames at exactly L = Lmax
        leg[:, 1] = leg[:, 0]
        leg[0] = leg.max()
    leg = np.concatenate([leg, np.repeat(leg[:1], 8 - len(leg), 0)])  # one shape: one compile
    for rule in G.RULES:
        grads = _grad_all(jnp.asarray(leg), jnp.float32(gait), jnp.float32(jump), rule)
        for g in grads:
            assert bool(jnp.all(jnp.isfinite(g))), (rule, g)


def test_gradient_at_lmax_is_finite_and_sqrt_gap_is_zero_there():
    leg = jnp.array([[10.0, 9.0], [9.0, 8.0]])
    for rule in G.RULES:
        g = jax.grad(lambda x: G.hip_rule(x, -0.1, 2.0, rule=rule).lift.sum())(leg)
        assert bool(jnp.all(jnp.isfinite(g)))
        # At L = Lmax the lift is 0 even with a negative gait (everything "in flight").
        assert float(G.hip_rule(leg, -0.1, 2.0, rule=rule).lift[0]) == pytest.approx(0, abs=1e-6)


def test_hip_rule_refuses_bad_width_and_temperature_concrete_and_traced():
    leg = jnp.array([[10.0, 8.0], [9.0, 9.5], [7.0, 6.0]])
    bad = [(0.0, None), (-0.01, None), (float("nan"), None), (float("inf"), None),
           (0.01, 0.0), (0.01, -1.0), (0.01, float("nan")), (0.01, float("inf"))]
    for width, temperature in bad:
        name = "width" if temperature is None else "temperature"
        for rule in G.RULES:
            with pytest.raises(UserError, match=rf"^hip_rule: `{name}` .* must be finite and > 0"):
                G.hip_rule(leg, 0.1, 1.0, rule=rule, width=width, temperature=temperature)
        with pytest.raises(UserError, match=rf"`{name}`"):
            G.hip_rule_curves(leg, 0.1, 1.0, width=width, temperature=temperature)
    # Traced: width 0 gave NaN gradients, temperature 0 NaN values; now the program fails.
    f = jax.jit(lambda w, t: G.hip_rule(leg, 0.1, 1.0, rule="smooth", width=w, temperature=t).lift)
    assert bool(jnp.all(jnp.isfinite(f(0.01, 0.02))))
    for width, temperature in bad:
        with pytest.raises(Exception, match="`width` and `temperature` must be finite and > 0"):
            jax.block_until_ready(f(width, 0.02 if temperature is None else temperature))
    g = jax.jit(lambda w: G.hip_rule(leg, 0.1, 1.0, rule="smooth", width=w).lift)
    with pytest.raises(Exception, match="`width` and `temperature` must be finite and > 0"):
        jax.block_until_ready(g(0.0))
    # Under grad and vmap too (one bad item in a batch).
    with pytest.raises(Exception, match="must be finite and > 0"):
        jax.block_until_ready(jax.grad(lambda w: jnp.sum(g(w)))(0.0))
    with pytest.raises(Exception, match="must be finite and > 0"):
        jax.block_until_ready(jax.vmap(g)(jnp.array([0.01, 0.0])))


def test_hip_rule_refuses_bad_gait_and_jump_when_traced():
    leg = jnp.array([[10.0, 8.0], [9.0, 9.5], [7.0, 6.0]])
    f = jax.jit(lambda g, j: G.hip_rule(leg, g, j).lift)
    np.testing.assert_allclose(f(0.1, 2.0), G.hip_rule(leg, 0.1, 2.0).lift)
    for gait, jump in ((0.1, -1.0), (float("nan"), 1.0), (0.1, float("inf"))):
        with pytest.raises(Exception, match="`gait` must be finite and `jump` finite and >= 0"):
            jax.block_until_ready(f(gait, jump))


def test_gradients_finite_at_zero_leg_length_with_traced_l_max():
    # The smooth rule's softened sqrt had d/d l_max sqrt((1e-4 l_max)^2) = NaN at l_max = 0.
    zeros = jnp.zeros((4, 2))

    def total(leg, gait, jump, l_max, rule):
        h = G.hip_rule(leg, gait, jump, rule=rule, l_max=l_max)
        return jnp.sum(h.L + h.lift + h.N)

    grad = jax.jit(jax.grad(total, argnums=(0, 1, 2, 3)), static_argnums=4)
    for rule in G.RULES:
        for l_max in (0.0, 1.0):
            grads = grad(zeros, 0.1, 1.0, l_max, rule)
            assert all(bool(jnp.all(jnp.isfinite(x))) for x in grads), (rule, l_max, grads)
        # Eagerly too (concrete legs of zero length with a concrete positive l_max).
        grads = jax.grad(total, argnums=(0, 3))(zeros, 0.1, 1.0, 1.0, rule)
        assert all(bool(jnp.all(jnp.isfinite(x))) for x in grads), (rule, grads)


def test_smooth_rule_tiny_temperature_is_finite_and_exact_under_jit():
    # tau = 1e-30 overflowed leg / tau inside the log-sum-exp (inf - inf = NaN under jit).
    leg = jnp.array([[10.0, 8.0], [9.0, 9.5], [7.0, 6.0], [8.0, 10.0]])
    f = jax.jit(lambda t: G.hip_rule(leg, 0.1, 1.0, rule="smooth", temperature=t))
    for tau in (1e-30, 1e-20, 1e-6):
        h = f(tau)
        np.testing.assert_allclose(h.L, jnp.max(leg, axis=-1), rtol=1e-6)
        assert all(bool(jnp.all(jnp.isfinite(x))) for x in h)
        g = jax.grad(lambda x, t=tau: jnp.sum(G.hip_rule(x, 0.1, 1.0, rule="smooth", temperature=t).L))(leg)
        assert bool(jnp.all(jnp.isfinite(g)))
        # The soft max picks the larger leg: gradient one-hot per frame.
        np.testing.assert_allclose(jnp.sum(g, axis=-1), 1.0, rtol=1e-5)


# ------------------------------------------------------------------------------ step, speed


def test_integrate_phase():
    om, dt = 5.8, 1 / 120
    ph = G.integrate_phase(1.0, om, 50, dt)
    np.testing.assert_array_equal(ph, om * (jnp.arange(50, dtype=ph.dtype) * dt))
    sched = jnp.concatenate([jnp.ones(10), jnp.linspace(1, 0, 10), jnp.zeros(10)])
    ph = G.integrate_phase(sched, om, 30, dt, phase0=1.0)
    assert ph[0] == 1.0
    d = jnp.diff(ph)
    assert bool(jnp.all(d >= 0)) and bool(jnp.all(d[-9:] == 0))
    np.testing.assert_allclose(d, om * dt * sched[:-1], rtol=1e-5)


# ----------------------------------------------------------------------- real-clip pose data


@functools.cache
def clip_pose(name: str):
    """(feet [T,2,3,3] world, feet_local, groins_local [T,2,3], root [T,3], frame_time)."""
    b = read_bvh_oracle(CMU_BUNDLED / f"{name}.bvh")
    pos, es = fk_oracle(b, b["frames"][1:])
    fp = C.foot_points(NamesTopology(b["names"], b["es_par"]))
    feet = np.asarray(C.gather_foot_positions(pos, es, fp))
    root = pos[:, 0]
    gi = [b["names"].index(n) for n in ("LeftUpLeg", "RightUpLeg")]
    return feet, feet - root[:, None, None], pos[:, gi] - root[:, None], root, b["frame_time"]


def _measured(name):
    feet, fl, groins, root, ft = clip_pose(name)
    g = C.estimate_ground(feet, ft)
    clear = C.sole_clearance(g)
    ground_under_root = g.intercepts.min(-1).mean() + root[:, [0, 2]] @ g.slope
    return fl, groins, clear, root[:, 1] - ground_under_root, root, ft


def test_root_trajectory_recovers_captured_advance():
    # From the real poses alone (pelvis at the origin) and the measured height, the stance feet
    # give back the captured root path of 07_01 to within its own foot skating.
    fl, _, clear, H, root, ft = _measured("07_01")
    T = len(H)
    traj = np.asarray(G.root_trajectory(jnp.asarray(fl), jnp.asarray(H),
                                        jnp.arange(T, dtype=jnp.float32), jnp.asarray(clear)))
    real = root[-1, [0, 2]] - root[0, [0, 2]]
    est = traj[-1, [0, 2]]
    assert 0.85 < est[1] / real[1] < 1.05, (est, real)
    assert abs(est[0] - real[0]) < 2.0
    np.testing.assert_allclose(traj[:, 1], H, rtol=1e-6)


def test_root_trajectory_planted_point_stays_put_and_flight_carries_velocity():
    T = 40
    t = np.arange(T, dtype=np.float32)
    feet = np.zeros((T, 2, 1, 3), np.float32)
    # Left foot on the ground sliding back in the pelvis frame by 0.5/frame until frame 20.
    feet[:, 0, 0, 2] = -0.5 * t
    feet[:, 0, 0, 1] = -10.0
    feet[:, 1, 0, 1] = -8.0  # right foot up
    height = np.full(T, 10.0, np.float32)
    height[21:] = 12.0  # flight from frame 21: both feet 2+ units up
    root = np.asarray(G.root_trajectory(jnp.asarray(feet), jnp.asarray(height),
                                        jnp.asarray(0.1 * t), jnp.zeros((2, 1))))
    world_left = root[:21, 2] + feet[:21, 0, 0, 2]
    np.testing.assert_allclose(world_left, 0.0, atol=1e-4)  # planted: no skating
    np.testing.assert_allclose(np.diff(root[22:, 2]), 0.5, atol=1e-4)  # velocity carried
    np.testing.assert_allclose(root[:, 0], 0.0, atol=1e-5)


def test_fit_gait_and_jump_to_real_run_09_01():
    fl, groins, clear, H, _, _ = _measured("09_01")
    fit = G.fit_hip_rule(groins, fl, clear, H, rule="smooth")
    print(f"\n09_01 smooth hip rule fit: gait={float(fit.gait):.4f} jump={float(fit.jump):.3f} "
          f"RMS root height {float(fit.rms_before):.3f} -> {float(fit.rms_after):.3f} units")
    assert float(fit.rms_after) < 0.95 * float(fit.rms_before)
    assert 0.0 < float(fit.gait) < 0.1 and float(fit.jump) > 0.0
    # The walk rule (gait = 1, jump = 0) is what "before" measures: the feet-on-ground height.
    D = G.contact_height(jnp.asarray(fl), jnp.asarray(clear))
    np.testing.assert_allclose(fit.rms_before, np.sqrt(np.mean((np.asarray(D) - H) ** 2)),
                               rtol=1e-4)


def test_skating_metric_on_real_and_planted_feet():
    feet, _, _, _, ft = clip_pose("07_01")
    g = C.estimate_ground(feet, ft)
    s = G.foot_skating(feet, ft, C.floor_heights(g, feet), height_threshold=g.height_threshold)
    assert 2.0 < float(s.mean_speed) < 40.0
    np.testing.assert_allclose(s.mean_per_frame, s.mean_speed * ft, rtol=1e-6)
    still = np.zeros((10, 2, 3, 3))
    s0 = G.foot_skating(still, ft, 0.0)
    assert float(s0.mean_speed) == 0.0 and float(s0.contact_fraction) == 1.0
    depth_max, depth_mean = G.ground_penetration(still - 0.25, np.zeros((2, 3)))
    assert float(depth_max) == pytest.approx(0.25) and float(depth_mean) == pytest.approx(0.25)


# --------------------------------------------------------------------- synthesis (Core models)

SECONDS, HARMONICS = 10.0, 5


def _fit_numpy(feats, frame_time_s, omega, num_harmonics):
    """Independent linear least-squares Fourier fit at a fixed ω (numpy lstsq)."""
    t = np.arange(len(feats)) * frame_time_s
    n = np.arange(1, num_harmonics + 1)
    basis = np.concatenate([np.ones((len(t), 1)), np.sin(np.outer(t, n) * omega),
                            np.cos(np.outer(t, n) * omega)], axis=1)
    coef = np.linalg.lstsq(basis, feats, rcond=None)[0]
    return coef[0], coef[1 : 1 + num_harmonics].T, coef[1 + num_harmonics :].T


@functools.cache
def fitted(name: str):
    """(model, motion, foot points, groins, clearance, real skating) for a bundled clip."""
    pytest.importorskip("fourierjax.kinematics")
    pytest.importorskip("fourierjax.motion")
    from fourierjax import data
    from fourierjax import fourier as F
    from fourierjax import motion as M

    mot = data.load(name)
    feet, _, _, _, ft = clip_pose(name)
    contacts = C.foot_contacts(feet, ft)
    omega = 2 * np.pi / (2 * C.mean_step_period_s(contacts, ft))  # cycle = two steps
    feats, names = M.features_from_motion(mot, "euler")
    offset, a, b = _fit_numpy(feats, ft, omega, HARMONICS)
    model = F.FourierModel.from_sin_cos(jnp.asarray(offset, jnp.float32),
                                        jnp.asarray(a, jnp.float32), jnp.asarray(b, jnp.float32),
                                        jnp.float32(omega), "euler", names)
    g = C.estimate_ground(feet, ft)
    skate = G.foot_skating(feet, ft, C.floor_heights(g, feet), height_threshold=g.height_threshold)
    return model, mot, C.foot_points(mot.topology), G.groin_joints(mot.topology), \
        C.sole_clearance(g), skate, g.height_threshold


def synth(name, **kw):
    model, mot, fp, groins, clear, _, _ = fitted(name)
    T = int(round(SECONDS / mot.frame_time_s))
    # One static configuration for every call below: one compilation. These tests are about the
    # step constraints: foot locking (on by default, tests/test_footlock.py) is off.
    kw.setdefault("foot_lock", False)
    return G.synthesize_gait(model, mot.skeleton(), T, mot.frame_time_s, feet=fp, groins=groins,
                             clearance=clear, **kw)


def test_synthesized_walk_touches_ground_without_skating():
    r = synth("07_01")
    _, mot, _, _, clear, real_skate, th = fitted("07_01")
    lowest = np.asarray(r.lowest).min(axis=1)
    assert np.max(np.abs(lowest)) <= 1e-3  # the lowest foot point is on the floor every frame
    floor = float(r.floor) + jnp.asarray(clear)[None]  # each point's floor: the captured one
    ours = G.foot_skating(r.foot_positions, mot.frame_time_s, floor, height_threshold=th)
    print(f"\nskating 07_01: synthesized {float(ours.mean_speed):.2f} units/s "
          f"({float(ours.mean_per_frame):.4f}/frame), real {float(real_skate.mean_speed):.2f} "
          f"units/s ({float(real_skate.mean_per_frame):.4f}/frame)")
    assert float(ours.mean_speed) <= float(real_skate.mean_speed)
    depth_max, _ = G.ground_penetration(r.foot_positions, clear, ground=r.floor)
    assert float(depth_max) <= 1e-3
    # It walks: alternating contacts, double support, no flight, a plausible pace along +Z.
    c = C.foot_contacts(np.asarray(r.foot_positions), mot.frame_time_s)
    assert C.flight_fraction(c) == 0.0 and C.double_support_fraction(c) > 0.05
    assert len(C.step_events(c)[0]) >= 7 and len(C.step_events(c)[1]) >= 7
    real_speed = (mot.channels[-1, 2] - mot.channels[0, 2]) / mot.duration_s
    ours_speed = float(r.root_position[-1, 2] - r.root_position[0, 2]) / SECONDS
    assert 0.8 * real_speed < ours_speed < 1.1 * real_speed, (ours_speed, real_speed)


def test_synthesized_run_flies_exactly_where_N_exceeds_gait():
    gait, jump = 0.06, 1.0
    r = synth("09_01", gait=gait, jump=jump)
    lowest = np.asarray(r.lowest).min(axis=1)
    N = np.asarray(r.hip.N)
    airborne = lowest > 1e-3
    np.testing.assert_array_equal(airborne, N > gait)
    # On the ground elsewhere, exactly.
    assert np.max(np.abs(lowest[~airborne])) <= 1e-3
    frac = float(np.mean(airborne))
    print(f"\nrun 09_01 gait={gait} jump={jump}: flight fraction {frac:.3f}, "
          f"max lift {float(np.max(r.hip.lift)):.2f} units")
    assert 0.2 < frac < 0.6  # the real 09_01 is airborne ~34% of the time
    # Still: lift at take-off is jump * sqrt(gait Lmax) or more (the faithful rule's jump).
    assert np.min(np.asarray(r.hip.lift)[airborne]) >= jump * np.sqrt(gait * r.hip.l_max) - 1e-4


@pytest.mark.parametrize("kw", [{}, {"gait": 0.06, "jump": 5.0}])
def test_synthesized_run_never_moves_the_pelvis_backwards(kw):
    """A run's landing foot is lowest while still swinging forward; carrying the root it dragged
    the pelvis backwards (09_01 with the default rule: down to -45 units/s in 64 of 480 frames;
    with Unuma's gait 0.06, jump 5: -29 units/s). The captured pelvis never slows below +50."""
    r = synth("09_01", **kw)
    _, mot, *_ = fitted("09_01")
    vz = np.gradient(np.asarray(r.root_position)[:, 2], mot.frame_time_s)
    real = (mot.channels[-1, 2] - mot.channels[0, 2]) / mot.duration_s
    print(f"\nrun 09_01 {kw}: root speed min {vz.min():.1f}, mean {vz.mean():.1f}, captured {real:.1f}")
    assert vz.min() > 0.0
    assert 0.7 * real < vz.mean() < 1.1 * real


def test_neutral_parameters_reproduce_unconstrained_synthesis():
    from fourierjax import fourier as F

    model, mot, *_ = fitted("07_01")
    T = int(round(SECONDS / mot.frame_time_s))
    plain = F.synthesize(model, jnp.arange(T, dtype=jnp.float32) * mot.frame_time_s)
    off = synth("07_01", step=1.0, speed=1.0, gait=1.0, jump=0.0, root_motion=False)
    np.testing.assert_array_equal(off.features, plain)
    on = synth("07_01", step=1.0, speed=1.0, gait=1.0, jump=0.0)
    np.testing.assert_array_equal(on.features[:, 3:], plain[:, 3:])
    assert float(jnp.max(on.hip.lift)) == 0.0
    # Without root motion the root follows the model's own channels.
    np.testing.assert_allclose(off.root_position[:, 1], plain[:, 2])


def test_speed_to_zero_comes_to_rest_without_a_jump():
    model, mot, *_ = fitted("07_01")
    T = int(round(SECONDS / mot.frame_time_s))
    ramp = np.clip(np.linspace(2.0, -1.0, T), 0.0, 1.0).astype(np.float32)  # 1 ... 0, then 0
    r = synth("07_01", speed=ramp)
    ref = synth("07_01")
    pose_step = np.abs(np.diff(np.asarray(r.features[:, 3:]), axis=0)).max(1)
    ref_step = np.abs(np.diff(np.asarray(ref.features[:, 3:]), axis=0)).max(1)
    root_step = np.linalg.norm(np.diff(np.asarray(r.root_position), axis=0), axis=1)
    ref_root = np.linalg.norm(np.diff(np.asarray(ref.root_position), axis=0), axis=1)
    assert pose_step.max() <= ref_step.max() + 1e-6
    assert root_step.max() <= ref_root.max() + 1e-3
    rest = ramp[:-1] == 0
    assert np.all(pose_step[rest] == 0.0) and np.all(root_step[rest] < 1e-5)
    # Still standing on the ground at rest.
    assert np.max(np.abs(np.asarray(r.lowest).min(1))) <= 1e-3


def test_step_scales_harmonics():
    model, *_ = fitted("07_01")
    m2 = G.apply_step(model, 1.5)
    np.testing.assert_allclose(m2.amplitude, 1.5 * model.amplitude, rtol=1e-6)
    np.testing.assert_array_equal(m2.offset, model.offset)
    np.testing.assert_array_equal(m2.phase, model.phase)
    # A longer step moves the walker further per cycle.
    r = synth("07_01", step=1.3)
    base = synth("07_01")
    assert float(r.root_position[-1, 2]) > 1.1 * float(base.root_position[-1, 2])


def test_exported_bvh_carries_root_motion(tmp_path):
    from fourierjax.io.bvh import read_bvh, write_bvh
    from fourierjax.io.gait_bvh import gait_motion

    model, mot, fp, _, clear, _, _ = fitted("07_01")
    r = synth("07_01")
    out = gait_motion(mot, r, model.channel_names, mot.frame_time_s)
    write_bvh(out, tmp_path / "walk.bvh")
    back = read_bvh(tmp_path / "walk.bvh")
    np.testing.assert_allclose(back.channels[:, :3], np.asarray(r.root_position), atol=1e-4)
    # Independent numpy FK of the file: the feet stand on the ground and advance.
    b = read_bvh_oracle(tmp_path / "walk.bvh")
    pos, es = fk_oracle(b, b["frames"][::7])
    feet = np.asarray(C.gather_foot_positions(pos, es, fp))
    low = (feet[..., 1] - clear).min(axis=(1, 2)) - float(r.floor)
    assert np.max(np.abs(low)) < 2e-3
    assert back.channels[-1, 2] > 150.0


def test_gait_motion_old_path_is_a_deprecated_alias():
    from fourierjax.io.gait_bvh import gait_motion

    model, mot, _, _, _, _, _ = fitted("07_01")
    r = synth("07_01")
    new = gait_motion(mot, r, model.channel_names, mot.frame_time_s)
    with pytest.warns(DeprecationWarning, match="fourierjax.io.gait_bvh.gait_motion"):
        old = G.gait_motion(mot, r, model.channel_names, mot.frame_time_s)
    np.testing.assert_array_equal(old.channels, new.channels)
    assert old.topology == new.topology and old.frame_time_s == new.frame_time_s


def test_core_gait_modules_do_not_import_the_edges():
    import ast
    from pathlib import Path

    import fourierjax

    root = Path(fourierjax.__file__).parent
    edges = ("fourierjax.io", "fourierjax.cli", "fourierjax.viz", "fourierjax.demo", "matplotlib")

    def imported(tree):
        for node in ast.walk(tree):
            if isinstance(node, ast.ImportFrom) and node.module:
                yield node.module
            elif isinstance(node, ast.Import):
                yield from (a.name for a in node.names)

    files = sorted((root / "_gait").glob("*.py"))
    assert len(files) >= 6
    for f in files:  # the private modules: never, not even inside a function
        bad = [m for m in imported(ast.parse(f.read_text())) if m.startswith(edges)]
        assert not bad, (f.name, bad)
    face = ast.parse((root / "gait.py").read_text())
    # The face: only the deprecated alias imports io, at call time.
    top = [m for node in face.body if isinstance(node, ast.Import | ast.ImportFrom)
           for m in imported(node)]
    assert not [m for m in top if m.startswith(edges)]
    lazy = {fn.name for fn in face.body if isinstance(fn, ast.FunctionDef)
            if any(m.startswith(edges) for m in imported(fn))}
    assert lazy == {"gait_motion"}


# ------------------------------------------------------- a small leg skeleton: vmap, gradients


@functools.cache
def toy():
    """Legs-only CMU-like skeleton and a random 2-harmonic model on its channels."""
    pytest.importorskip("fourierjax.kinematics")
    pytest.importorskip("fourierjax.motion")
    from fourierjax import motion as M
    from fourierjax.skeleton import Skeleton, Topology

    rot = ("Zrotation", "Yrotation", "Xrotation")
    names = ("Hips", "LeftUpLeg", "LeftLeg", "LeftFoot", "LeftToeBase",
             "RightUpLeg", "RightLeg", "RightFoot", "RightToeBase")
    parents = (-1, 0, 1, 2, 3, 0, 5, 6, 7)
    chans = (("Xposition", "Yposition", "Zposition") + rot,) + (rot,) * 8
    topo = Topology(names, parents, chans, end_site_parents=(4, 8))
    offsets = np.array([[0, 0, 0], [1.7, -1.7, 0.8], [2.4, -6.5, 0], [2.5, -7.0, 0],
                        [0.2, -0.4, 1.9], [-1.7, -1.7, 0.8], [-2.4, -6.5, 0], [-2.5, -7.0, 0],
                        [-0.2, -0.4, 1.9]])
    sk = Skeleton(topo, offsets, np.array([[0, 0, 1.0], [0, 0, 1.0]]))
    return sk, C.foot_points(topo), G.groin_joints(topo), M.channel_names_for(topo, "euler")


def toy_model(seed, scale=0.3):
    from fourierjax import fourier as F

    sk, _, _, names = toy()
    rng = np.random.default_rng(seed)
    c = len(names)
    off = rng.normal(scale=0.1, size=c)
    off[2] = 16.0  # root.y
    return F.FourierModel.from_sin_cos(
        jnp.asarray(off, jnp.float32), jnp.asarray(rng.normal(scale=scale, size=(c, 2)), jnp.float32),
        jnp.asarray(rng.normal(scale=scale, size=(c, 2)), jnp.float32), jnp.float32(6.0),
        "euler", names)


def _toy_loss(model, gait, jump, rule="smooth"):
    sk, fp, groins, _ = toy()
    r = G.synthesize_gait(model, sk, 12, 1 / 30, feet=fp, groins=groins, gait=gait, jump=jump,
                          rule=rule, num_cycle_samples=8, foot_lock=False)
    return jnp.sum(r.root_position) + jnp.sum(r.hip.lift) + jnp.sum(r.lowest)


_toy_grad = jax.jit(jax.grad(_toy_loss, argnums=(0, 1, 2)))


@pytest.mark.slow
@settings(max_examples=15, deadline=None)
@given(st.integers(0, 10_000), st.floats(-0.1, 1.1), st.floats(0.0, 5.0),
       st.sampled_from(["moving", "still", "tiny"]))
def test_smooth_rule_gradients_finite_through_model(seed, gait, jump, kind):
    model = toy_model(seed)
    if kind == "still":  # every frame at L = Lmax exactly: the sqrt(0) trap
        model = G.apply_step(model, 0.0)
    elif kind == "tiny":
        model = G.apply_step(model, 1e-6)
    gm, gg, gj = _toy_grad(model, jnp.float32(gait), jnp.float32(jump))
    for leaf in jax.tree.leaves((gm, gg, gj)):
        assert bool(jnp.all(jnp.isfinite(leaf))), (seed, gait, jump, kind)


@pytest.mark.slow
def test_smooth_rule_gradient_matches_finite_differences(x64):
    model = jax.tree.map(lambda x: x.astype(jnp.float64) if hasattr(x, "astype") else x,
                         toy_model(3))
    gait, jump = 0.01, 2.0
    gm, gg, gj = jax.grad(_toy_loss, argnums=(0, 1, 2))(model, gait, jump)
    eps = 1e-6
    fd_j = (_toy_loss(model, gait, jump + eps) - _toy_loss(model, gait, jump - eps)) / (2 * eps)
    fd_g = (_toy_loss(model, gait + eps, jump) - _toy_loss(model, gait - eps, jump)) / (2 * eps)
    np.testing.assert_allclose(gj, fd_j, rtol=1e-5)
    np.testing.assert_allclose(gg, fd_g, rtol=1e-4, atol=1e-6)
    bump = model.offset.at[5].add(eps)
    minus = model.offset.at[5].add(-eps)
    import equinox as eqx

    fd_o = (_toy_loss(eqx.tree_at(lambda m: m.offset, model, bump), gait, jump)
            - _toy_loss(eqx.tree_at(lambda m: m.offset, model, minus), gait, jump)) / (2 * eps)
    np.testing.assert_allclose(gm.offset[5], fd_o, rtol=1e-4, atol=1e-6)


def test_vmap_over_characters_equals_one_by_one():
    from fourierjax import fourier as F

    sk, fp, groins, _ = toy()
    models = [toy_model(s) for s in (1, 2, 3)]
    gaits = jnp.array([0.02, 0.05, 1.0])
    stacked = F.stack_models(models)

    def one(m, g):
        return G.synthesize_gait(m, sk, 12, 1 / 30, feet=fp, groins=groins, gait=g, jump=1.0,
                                 num_cycle_samples=8, foot_lock=False)

    batched = jax.vmap(one)(stacked, gaits)
    # XLA:GPU orders the batched float32 sums differently: measured on an H100, 1.7e-5 relative
    # (8e-5 on a root channel of magnitude ~5-70) where XLA:CPU stays within 1e-5.
    tol = 1e-5 if jax.default_backend() == "cpu" else 5e-5
    for i, m in enumerate(models):
        single = one(m, gaits[i])
        np.testing.assert_allclose(batched.root_position[i], single.root_position, rtol=tol, atol=tol)
        np.testing.assert_allclose(batched.features[i], single.features, rtol=tol, atol=tol)


def test_synthesize_gait_bad_input():
    sk, fp, groins, _ = toy()
    model = toy_model(0)
    with pytest.raises(UserError, match="hip rule"):
        G.synthesize_gait(model, sk, 12, 1 / 30, feet=fp, groins=groins, rule="hop")
    with pytest.raises(UserError, match="speed"):
        G.synthesize_gait(model, sk, 12, 1 / 30, feet=fp, groins=groins, speed=jnp.ones(5))
    with pytest.raises(UserError, match="clearance"):
        G.synthesize_gait(model, sk, 12, 1 / 30, feet=fp, groins=groins,
                          clearance=jnp.zeros((2, 2)))
    with pytest.raises(UserError, match="RightUpLeg"):
        G.groin_joints(NamesTopology(("Hips", "LeftUpLeg"), ()))


def test_synthesize_gait_does_not_retrace_for_new_numbers(monkeypatch):
    # filter_jit holds Python numbers static: frame time, width and temperature go in as arrays.
    from fourierjax._gait import synthesis

    sk, fp, groins, _ = toy()
    model = toy_model(0)
    traces = []

    def counting_apply_step(m, step):
        traces.append(1)
        return G.apply_step(m, step)

    monkeypatch.setattr(synthesis, "apply_step", counting_apply_step)
    outs = [
        G.synthesize_gait(model, sk, 12, dt, feet=fp, groins=groins, rule="smooth", width=w,
                          temperature=t, gait=g, jump=1.0, num_cycle_samples=8, foot_lock=False)
        for dt, w, t, g in ((1 / 30, 0.01, 0.1, 0.05), (1 / 25, 0.02, 0.2, 0.06), (1 / 24, 0.03, 0.3, 0.07))
    ]
    assert len(traces) <= 1
    # ... and the values still matter.
    assert not np.allclose(outs[0].root_position, outs[1].root_position)
    # Locked, the frames are denser under 100 fps and start a pre-roll earlier, a frame count set by
    # the frame time (at 30 fps 45 + 120 dense frames, at 24 fps 56 + 120): one program a frame
    # rate, whatever the other numbers.
    traces.clear()
    for w, t, g in ((0.01, 0.1, 0.05), (0.02, 0.2, 0.06), (0.03, 0.3, 0.07)):
        G.synthesize_gait(model, sk, 12, 1 / 30, feet=fp, groins=groins, rule="smooth", width=w,
                          temperature=t, gait=g, jump=1.0, num_cycle_samples=8)
    assert len(traces) <= 1


def test_synthesize_gait_rejects_bad_numbers_and_indices():
    sk, fp, groins, _ = toy()
    model = toy_model(0)

    def run(num_frames=12, frame_time_s=1 / 30, **kw):
        kw.setdefault("groins", groins)
        kw.setdefault("feet", fp)
        return G.synthesize_gait(model, sk, num_frames, frame_time_s, num_cycle_samples=8, **kw)

    # NaN/inf passed the `<= 0` check and gave an all-NaN root path.
    for dt in (float("nan"), float("inf"), np.float32("nan"), 0.0, -1 / 30):
        with pytest.raises(UserError, match=r"^synthesize_gait: `frame_time_s` must be finite and > 0"):
            run(frame_time_s=dt)
    # Out-of-range indices were clamped by JAX: a wrong joint, a wrong leg length.
    with pytest.raises(UserError, match=r"^synthesize_gait: `groins`=\(50, 51\).* 9 joints"):
        run(groins=(50, 51))
    with pytest.raises(UserError, match=r"^synthesize_gait: `groins`"):
        run(groins=(1,))
    with pytest.raises(UserError, match=r"^synthesize_gait: `groins`"):
        run(groins=(1.0, 5.0))
    with pytest.raises(UserError, match=r"^synthesize_gait: `feet.right`"):
        run(feet=C.FootPoints(fp.left, (7, 8, 40), fp.names))
    # The docs (and eq. 5: jump is the flight height) say jump >= 0; a negative jump pushed the
    # stance foot into the ground.
    with pytest.raises(UserError, match=r"^synthesize_gait: `jump` must be >= 0"):
        run(jump=-5.0, gait=0.0)
    # 10.7 frames was truncated to 10.
    for n in (10.7, 12.0):
        with pytest.raises(UserError, match=r"^synthesize_gait: `num_frames` must be an integer"):
            run(num_frames=n)
    for name in ("step", "speed", "gait", "jump", "phase0"):
        with pytest.raises(UserError, match=rf"^synthesize_gait: `{name}` must be finite"):
            run(**{name: float("nan")})
    with pytest.raises(UserError, match=r"^synthesize_gait: `up_axis`"):
        run(up_axis=5)
    for kw in ({"width": 0.0}, {"width": float("nan")}, {"temperature": 0.0}, {"temperature": -1.0}):
        with pytest.raises(UserError, match=rf"^synthesize_gait: `{next(iter(kw))}` .* must be finite and > 0"):
            run(rule="smooth", **kw)
    # NumPy integers and Python-style negative joint indices are fine (same compiled function).
    ref = run()
    same = run(num_frames=np.int64(12), groins=(groins[0] - 9, groins[1] - 9))
    np.testing.assert_array_equal(same.root_position, ref.root_position)


def test_estimated_sole_clearance_matches_the_real_floor_fit():
    for name in ("07_01", "09_01"):
        fl, _, clear, *_ = _measured(name)
        est = np.asarray(G.estimate_sole_clearance(jnp.asarray(fl)))
        np.testing.assert_allclose(est, clear, atol=0.3)  # ~5% of a foot length
        assert np.all(est[:, 0] > 0.5)  # the ankle stands well above the sole


# ------------------------------------------------------------------------------ command line


def _toy_template():
    from fourierjax.io.bvh import Motion

    sk, *_ = toy()
    topo = sk.topology
    return Motion(topo, np.asarray(sk.offsets), np.asarray(sk.end_site_offsets),
                  np.zeros((1, topo.num_channels)), 1 / 30)


def test_cli_gait_flags():
    import argparse

    from fourierjax.cli._gait_args import add_gait_arguments, apply_gait

    p = argparse.ArgumentParser()
    add_gait_arguments(p)
    a = p.parse_args([])
    assert (a.step, a.speed, a.gait, a.jump, a.hip_rule, a.root_motion) == (
        1.0, 1.0, 1.0, 0.0, "unuma1995", True)
    a = p.parse_args(["--step", "1.2", "--speed", "0.5", "--gait", "0.05", "--jump", "2",
                      "--hip-rule", "smooth", "--no-root-motion"])
    assert (a.step, a.speed, a.gait, a.jump, a.hip_rule, a.root_motion) == (
        1.2, 0.5, 0.05, 2.0, "smooth", False)
    with pytest.raises(SystemExit):
        p.parse_args(["--hip-rule", "hop"])
    template = _toy_template()
    m = toy_model(5)
    # Model files load as float64 NumPy arrays: they must run warning-free without x64.
    model = type(m)(*(np.asarray(x, np.float64) for x in (m.offset, m.amplitude, m.phase,
                                                            m.omega)), m.representation,
                    m.channel_names)
    motion, summary = apply_gait(p.parse_args(["--gait", "0.02", "--jump", "1"]), model,
                                 template, 12, 1 / 30)
    assert motion.num_frames == 12 and "flight" in summary
    assert np.any(motion.channels[:, 2] != motion.channels[0, 2])  # the root moves
    # The summary gives N's peak, so a --gait that never triggers flight (README once used
    # 0.5 on a run whose N peaks at 0.086) shows why; flight happens iff --gait is below it.
    import re

    flights = []
    for g in ("0.02", "0.9"):
        _, summary = apply_gait(p.parse_args(["--gait", g, "--jump", "1"]), model, template, 12, 1 / 30)
        flight = float(re.search(r"flight ([\d.]+)% of frames", summary).group(1))
        peak = float(re.search(r"N\(t\) peaks at ([\d.]+)", summary).group(1))
        assert (flight > 0) == (float(g) < peak), summary
        flights.append(flight)
    assert flights[0] > 0 == flights[1]
    # Without root motion no ground is enforced: no flight figure (it said 100% for a walk).
    _, summary = apply_gait(p.parse_args(["--no-root-motion"]), model, template, 12, 1 / 30)
    assert "flight not measured" in summary and "% of frames" not in summary
    for bad in (["--gait", "1.5"], ["--jump", "-1"], ["--speed", "-0.1"], ["--step", "nan"]):
        with pytest.raises(UserError, match=bad[0]):
            apply_gait(p.parse_args(bad), model, template, 12, 1 / 30)


def test_model_hip_curves_one_call_for_the_plot():
    sk, fp, groins, _ = toy()
    out = G.model_hip_curves(toy_model(7), sk, feet=fp, groins=groins, gait=0.02, jump=1.0,
                             num_samples=32)
    assert out["phase"].shape == (32,)
    np.testing.assert_allclose(out["L"], np.maximum(out["L_L"], out["L_R"]), rtol=1e-6)
    assert bool(jnp.all(out["unuma1995"] >= out["continuous"] - 1e-6))
    assert bool(jnp.all(out["continuous"] >= out["L"] - 1e-6))


def test_synth_command_with_step_constraints(tmp_path, capsys):
    from fourierjax import model_io
    from fourierjax.cli import main
    from fourierjax.io.bvh import read_bvh

    template = _toy_template()
    model = toy_model(5)
    model_io.save_model(tmp_path / "toy.npz", model, motion=template)
    out = tmp_path / "run.bvh"
    code = main(["synth", str(tmp_path / "toy.npz"), "--seconds", "0.4", "--fps", "30",
                 "--step", "1.1", "--gait", "0.02", "--jump", "1", "--hip-rule", "continuous",
                 "--out", str(out)])
    assert code == 0
    assert "step constraints: hip rule continuous" in capsys.readouterr().out
    m = read_bvh(out)
    assert m.num_frames == 12
    assert np.ptp(m.channels[:, 1]) > 0  # the root height follows the hip rule
    # --no-root-motion: the root height is the model's own root.y channel again.
    code = main(["synth", str(tmp_path / "toy.npz"), "--seconds", "0.4", "--fps", "30",
                 "--no-root-motion", "--out", str(out)])
    assert code == 0
    from fourierjax import fourier as F

    plain = F.synthesize(model, jnp.arange(12) / 30.0)
    np.testing.assert_allclose(read_bvh(out).channels[:, 1], plain[:, 2], atol=1e-4)
    assert main(["synth", str(tmp_path / "toy.npz"), "--seconds", "0.4", "--gait", "2",
                 "--out", str(out)]) == 2


def test_cli_hip_rules_match_the_library():
    # cli/_gait_args repeats the rule names so that building the parser does not import JAX.
    from fourierjax.cli import _gait_args

    assert _gait_args.RULES == G.RULES


def test_cli_apply_gait_in_process():
    # In-process (pytest turns warnings into errors): the CLI uses io.gait_bvh, not the
    # deprecated gait.gait_motion; its flight count is gait.flight_fraction's.
    import argparse

    from fourierjax.cli._gait_args import add_gait_arguments, apply_gait

    model, mot, _, _, _, _, _ = fitted("07_01")
    parser = argparse.ArgumentParser()
    add_gait_arguments(parser)
    args = parser.parse_args(["--gait", "0.05", "--jump", "1"])
    motion, summary = apply_gait(args, model, mot, 60, mot.frame_time_s)
    assert motion.num_frames == 60
    assert summary.startswith("step constraints: hip rule unuma1995, root motion on; flight ")
    assert "foot skating" in summary and "root advance" in summary
    off = parser.parse_args(["--no-root-motion"])
    _, summary_off = apply_gait(off, model, mot, 60, mot.frame_time_s)
    assert "flight not measured" in summary_off


def test_contact_flight_fraction_is_the_skating_metrics_contact():
    """Flight (issue 21): the frames on which no foot point is within 2% of the body height of its
    floor, as `contact_skating` counts contact; a sloped floor given as `floor` is followed."""
    from types import SimpleNamespace

    bm = SimpleNamespace(left=SimpleNamespace(foot_points=(0, 1)), right=SimpleNamespace(foot_points=(2, 3)),
                         up_axis=1, up_sign=1.0, height=50.0)  # band: 1 unit
    T = 40
    k = np.arange(T)
    p = np.zeros((T, 2, 2, 3))
    p[..., 1] = 5.0  # both feet up ...
    p[k % 4 == 0, 0, 1, 1] = 0.5  # ... but the left toe within the band on every 4th frame
    p[k % 4 == 1, 1, 0, 1] = 0.99  # ... the right heel just inside it on the next
    p[k % 4 == 2, 1, 0, 1] = 1.01  # ... just outside on the one after
    got = float(G.contact_flight_fraction(p, body_map=bm, floor=0.0))
    assert got == pytest.approx(0.5)
    assert float(G.contact_skating(p, 0.01, body_map=bm, floor=0.0).contact_fraction) == pytest.approx(1 / 8)
    # (2 of 16 point-frames in contact.) A floor rising 3 units over the clip, the feet on it: no
    # flight against it, most frames in flight against a level one.
    slope = np.linspace(0.0, 3.0, T)[:, None, None]
    climb = np.zeros((T, 2, 2, 3))
    climb[..., 1] = slope + 0.2
    assert float(G.contact_flight_fraction(climb, body_map=bm, floor=slope)) == 0.0
    assert float(G.contact_flight_fraction(climb, body_map=bm, floor=0.0)) > 0.6
    # [T, J + E, 3] positions take the body map's foot points; a wrong shape is refused.
    np.testing.assert_allclose(float(G.contact_flight_fraction(p.reshape(T, 4, 3), body_map=bm, floor=0.0)), got)
    with pytest.raises(UserError, match="contact_flight_fraction"):
        G.contact_flight_fraction(np.zeros((T, 3, 2, 3)), body_map=bm)
