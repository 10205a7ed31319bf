"""Experiment (c): the hip-height rule (Unuma 1995 eq. 4-5) and step-constraint sweeps (§3.1).

A fitted run is synthesized with step constraints and root motion (`gait.synthesize_gait`) over
a grid of `gait` thresholds and `jump` heights, for each rule (faithful ``unuma1995``,
``continuous``, ``smooth``): flight fraction (both feet off the ground), the largest lift, and
the largest frame-to-frame jump of the root height (the faithful rule jumps by
jump·√(gait·Lmax) at the threshold; the others do not). A fitted walk is synthesized over a
sweep of `step` (amplitude scale): distance per cycle, foot skating while in contact and the
largest ground penetration.

Writes ``hip_rule_sweep.{csv,json,md}``, ``step_sweep.{csv,json,md}``, ``hip_rule_sweep.png``.
"""

from __future__ import annotations

import numpy as np

from experiments._util import parse, run_main, write_table


def body(argv=None) -> None:
    import jax.numpy as jnp

    from fourierjax import contacts, data, gait, viz
    from fourierjax.motion import fit_motions, foot_positions_of

    cfg, out = parse("hip_rule", __doc__.splitlines()[0], argv)
    names = [cfg["walk"], cfg["run"]]
    motions = {c: data.load(c) for c in names}
    fits = dict(zip(names, fit_motions([motions[c] for c in names], cfg["harmonics"], throw=True),
                    strict=True))

    def ground(clip):
        m = motions[clip]
        pts = contacts.foot_points(m.topology)
        g = contacts.estimate_ground(foot_positions_of(m, pts), m.frame_time_s)
        return pts, gait.groin_joints(m.topology), contacts.sole_clearance(g), g.height_threshold

    def synth(clip, **kw):
        pts, groins, clear, _ = ground(clip)
        m = motions[clip]
        dt = m.frame_time_s
        T = int(round(cfg["seconds"] / dt))
        return gait.synthesize_gait(fits[clip].model, m.skeleton(), T, dt, feet=pts,
                                    groins=groins, clearance=clear, **kw), clear, dt

    rows, traces = [], {}
    for rule in cfg["rules"]:
        for g in cfg["gaits"]:
            for j in cfg["jumps"]:
                r, _, dt = synth(cfg["run"], gait=g, jump=j, rule=rule)
                lowest = np.asarray(r.lowest).min(axis=1)
                hy = np.asarray(r.root_position[:, 1])
                rows.append({"rule": rule, "gait": g, "jump": j,
                             "flight_fraction": float(np.mean(lowest > 1e-3)),
                             "max_lift_units": float(np.max(np.asarray(r.hip.lift))),
                             "max_root_height_step_units": float(np.max(np.abs(np.diff(hy)))),
                             "l_max_units": float(r.hip.l_max)})
                traces[(rule, g, j)] = (np.arange(len(hy)) * dt, hy)
    md1 = write_table(rows, out, "hip_rule_sweep",
                      f"Hip-height rule on the fitted run {cfg['run']} ({cfg['seconds']} s)")

    steps = []
    pts, groins, clear, th = ground(cfg["walk"])
    cycle_s = 1 / fits[cfg["walk"]].fundamental_hz
    for s in cfg["steps"]:
        r, clear, dt = synth(cfg["walk"], step=s)
        root = np.asarray(r.root_position)
        dist = float(np.hypot(*(root[-1] - root[0])[[0, 2]]))
        sk = gait.foot_skating(r.foot_positions, dt, jnp.asarray(clear)[None],
                               height_threshold=th)
        pen, _ = gait.ground_penetration(r.foot_positions, jnp.asarray(clear))
        steps.append({"step": s, "distance_per_cycle_m": dist * 0.0564 / (cfg["seconds"] / cycle_s),
                      "skating_units_s": float(sk.mean_speed),
                      "max_penetration_units": float(pen),
                      "max_abs_lowest_foot_units": float(np.abs(np.asarray(r.lowest).min(1)).max())})
    md2 = write_table(steps, out, "step_sweep", f"Step sweep on the fitted walk {cfg['walk']}")
    print(md1, md2, sep="\n\n")

    import matplotlib.pyplot as plt

    fig, (a1, a2) = plt.subplots(1, 2, figsize=(11, 3.8))
    for rule, ls in zip(cfg["rules"], ["-", "--", ":"], strict=False):
        for j in cfg["jumps"]:
            rs = [r for r in rows if r["rule"] == rule and r["jump"] == j and r["gait"] < 1]
            a1.plot([r["gait"] for r in rs], [r["flight_fraction"] for r in rs], "o" + ls,
                    label=f"{rule}, jump {j:g}")
    a1.set_xlabel("gait threshold")
    a1.set_ylabel("flight fraction (both feet up)")
    a1.legend(fontsize=6, ncol=2)
    a1.grid(alpha=0.3)
    g0 = [g for g in cfg["gaits"] if g < 1]
    g0 = g0[len(g0) // 2] if g0 else cfg["gaits"][0]
    j0 = max(cfg["jumps"])
    for rule in cfg["rules"]:
        t, hy = traces[(rule, g0, j0)]
        a2.plot(t, hy * 0.0564, label=rule, lw=1.2)
    a2.set_xlabel("time (s)")
    a2.set_ylabel("root height (m)")
    a2.set_title(f"gait = {g0:g}, jump = {j0:g}", fontsize=9)
    a2.legend(fontsize=8)
    a2.grid(alpha=0.3)
    fig.suptitle(f"Hip-height rule sweep on the fitted run {cfg['run']}")
    fig.tight_layout()
    viz.save_figure(fig, out / "hip_rule_sweep.png")


def main(argv=None) -> int:
    return run_main(body, argv)


if __name__ == "__main__":
    raise SystemExit(main())
