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
from tests.test_contacts import SHARED, _fk, _read_bvh, _Topo

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
    b = _read_bvh(SHARED / f"{name}.bvh")
    pos, es = _fk(b, b["frames"][1:])
    fp = C.foot_points(_Topo(b["names"], b["es_par"]))
    feet = np.asarray(C.gather_foot_positions(pos, es, fp))
    root = pos[:, 0]
    gi = [b["names"].index(n) for n in G.CMU_GROINS]
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
