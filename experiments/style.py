"""Experiment (b): Unuma 1995 brisk/tired inter/extrapolation (eq. 3) and superposition (eq. 8).

Models of a normal walk Θ, a tired (slow) walk Π, a brisk walk and a run are fitted
(`fit_motions`, aligned to the left heel strike). Along Ξ(s) = interpolate(Θ, Π, s) — s < 0
brisk, 0 < s < 1 a little tired, s > 1 very tired (Unuma Fig. 3) — the table reports what the
style changes: cadence, forward speed, stride, hip and knee swing, trunk lean. Then the brisk
characteristic (brisk − normal, eq. 7) is added to the run with weights w (eq. 8; Unuma's brisk
run is w = 1.37), and least-squares style weights say how much "tired" explains the brisk walk.

Writes ``interpolation.{csv,json,md}``, ``superposition.{csv,json,md}``, ``checks.json``,
``style_metrics.png`` and ``interpolation_strip.png``.
"""

from __future__ import annotations

import json

import numpy as np

from experiments._util import parse, run_main, write_table

CMU_UNIT_M = 0.0564


def metrics(model) -> dict:
    """Interpretable numbers of one gait model (CMU skeleton, Euler channels)."""
    names = list(model.channel_names)
    amp = np.degrees(np.asarray(model.amplitude[:, 0]))
    off = np.asarray(model.offset)
    hz = float(model.omega) / (2 * np.pi)
    speed = float(off[names.index("root.vz")]) * CMU_UNIT_M

    def a1(ch):
        return float(amp[names.index(ch)])

    return {"cadence_hz": hz, "speed_m_s": speed, "stride_m": speed / hz,
            "hip_swing_deg": a1("LeftUpLeg.Xrotation"), "knee_swing_deg": a1("LeftLeg.Xrotation"),
            "arm_swing_deg": a1("LeftArm.Yrotation") if "LeftArm.Yrotation" in names else float("nan"),
            "trunk_lean_deg": float(np.degrees(off[names.index("Spine.Xrotation")]))}


def body(argv=None) -> None:
    import jax.numpy as jnp

    from fourierjax import data, style, viz
    from fourierjax.motion import fit_motions, model_joint_positions

    cfg, out = parse("style", __doc__.splitlines()[0], argv)
    clips = [cfg["normal"], cfg["tired"], cfg["brisk"], cfg["run"]]
    fits = dict(zip(clips, fit_motions([data.load(c) for c in clips], cfg["harmonics"], throw=True),
                    strict=True))
    normal, tired = fits[cfg["normal"]].model, fits[cfg["tired"]].model
    brisk, run = fits[cfg["brisk"]].model, fits[cfg["run"]].model

    rows = []
    for s in cfg["s_values"]:
        rows.append({"s": s, **metrics(style.interpolate(normal, tired, s))})
    md1 = write_table(rows, out, "interpolation",
                      f"Xi(s) = interpolate({cfg['normal']} normal, {cfg['tired']} tired, s)")
    real = [{"s": f"real {c}", **metrics(fits[c].model)} for c in clips]
    write_table(real, out, "real_clips", "The fitted clips themselves")

    char = style.characteristic(brisk, normal)
    sup = []
    for w in cfg["weights"]:
        for method in ("polar", "phasor"):
            sup.append({"w": w, "method": method,
                        **metrics(style.superpose(run, [char], [w], method=method))})
    md2 = write_table(sup, out, "superposition",
                      f"{cfg['run']} run + w ({cfg['brisk']} brisk - {cfg['normal']} normal)")

    def vec_diff(a, b):
        return float(jnp.max(jnp.abs(style.style_vector(a) - style.style_vector(b))))

    w_tired = style.fit_style_weights(normal, [style.characteristic(tired, normal)], brisk)
    checks = {
        "interpolate_s0_equals_normal_max_abs": vec_diff(style.interpolate(normal, tired, 0.0),
                                                         normal),
        "interpolate_s1_equals_tired_max_abs": vec_diff(style.interpolate(normal, tired, 1.0),
                                                        tired),
        "superpose_w1_on_normal_equals_brisk_max_abs": vec_diff(
            style.superpose(normal, [char], [1.0]), brisk),
        "brisk_walk_as_normal_plus_w_tired": float(w_tired[0]),
        "note": "w < 0: the brisk walk lies on the extrapolated (s < 0) side of normal -> tired",
    }
    (out / "checks.json").write_text(json.dumps(checks, indent=1))
    print(md1, md2, json.dumps(checks, indent=1), sep="\n\n")

    import matplotlib.pyplot as plt

    keys = ["cadence_hz", "speed_m_s", "stride_m", "hip_swing_deg", "knee_swing_deg",
            "trunk_lean_deg"]
    units = {"cadence_hz": "cadence (Hz)", "speed_m_s": "speed (m/s)", "stride_m": "stride (m)",
             "hip_swing_deg": "hip swing A1 (deg)", "knee_swing_deg": "knee swing A1 (deg)",
             "trunk_lean_deg": "spine X offset (deg)"}
    fig, axes = plt.subplots(2, 3, figsize=(11, 5.5))
    s = [r["s"] for r in rows]
    for ax, k in zip(axes.ravel(), keys, strict=True):
        ax.plot(s, [r[k] for r in rows], "o-", label="Xi(s)")
        for r, mk in zip(real[:3], "s^D", strict=True):
            xs = {cfg["normal"]: 0.0, cfg["tired"]: 1.0}.get(r["s"].split()[1], None)
            if xs is not None:
                ax.plot([xs], [r[k]], mk, color="C3", ms=7, label=r["s"])
        ax.axhline(metrics(brisk)[k], color="C2", ls="--", lw=1, label=f"real {cfg['brisk']} brisk")
        ax.axvspan(min(s), 0, color="C2", alpha=0.07)
        ax.axvspan(1, max(s), color="C1", alpha=0.07)
        ax.set_xlabel("s (0 normal, 1 tired; < 0 brisk, > 1 very tired)")
        ax.set_ylabel(units[k])
        ax.grid(alpha=0.3)
    axes[0, 0].legend(fontsize=7)
    fig.suptitle("Unuma eq. 3 inter/extrapolation between a normal and a tired walk")
    fig.tight_layout()
    viz.save_figure(fig, out / "style_metrics.png")

    m = data.load(cfg["normal"])
    svals = [v for v in (-0.6, 0.0, 0.5, 1.0, 1.5)]
    poses = [model_joint_positions(style.interpolate(normal, tired, v), m.skeleton(),
                                   np.array([0.0]))[0] for v in svals]
    poses = [p - p[:, 1].min() * np.array([0.0, 1.0, 0.0]) for p in poses]
    fig = viz.plot_stick_strip(poses, m.topology.parents, [f"s = {v:+.1f}" for v in svals],
                               names=m.topology.names,
                               title="Xi(s) at the left heel strike (phase 0)")
    viz.save_figure(fig, out / "interpolation_strip.png")


def main(argv=None) -> int:
    return run_main(body, argv)


if __name__ == "__main__":
    raise SystemExit(main())
