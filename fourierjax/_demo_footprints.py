"""The demo's before/after image: footprints of a synthesized walk without and with foot locking."""

from __future__ import annotations

import numpy as np


def footprints(st, clip: str = "07_01") -> None:
    """Plot, from above, where the foot points touch the floor (within 2% of the body height) in a
    synthesized walk of `clip`, with foot locking off (top) and on (bottom), and write
    `plots/footprints.png`; the skating metric of each is in the panel titles."""
    if clip not in st.fits:
        st.skipped.append(f"footprints: needs the fitted clip {clip}")
        return
    import matplotlib.figure

    from fourierjax import gait

    fit, m = st.fits[clip], st.motions[clip]
    bm, dt = fit.body_map, fit.frame_time_s
    T = max(2, int(round(min(st.cfg.seconds, 6.0) / dt)))
    iv = gait.fit_contact_intervals(fit, m)
    up = bm.up_axis
    horiz = [k for k in range(3) if k != up]
    panels = []
    for lock in (False, True):
        r = gait.synthesize_gait(fit.model, m.skeleton(), T, dt, body_map=bm, foot_lock=lock, contact_intervals=iv)
        p = np.asarray(r.foot_positions)  # [T, 2, P, 3]
        low = p[..., up] - float(r.floor) - np.asarray(r.clearance)[None] < 0.02 * bm.height
        panels.append((lock, p, low, float(gait.contact_skating(p, dt, body_map=bm).mean_speed)))
    # The prints span far more travel than side: stretch the side axis by a whole factor so that a
    # panel is about 1.5 in tall rather than a thin strip, and say so on the axis.
    pts = np.concatenate([p[low] for _, p, low, _ in panels] + [panels[0][1].reshape(-1, 3)[:1]])
    extent = np.ptp(pts[:, horiz], axis=0) + 0.05 * bm.height
    width = 11.0
    stretch = max(1, int(round(1.5 / (width * 0.9 * extent[0] / max(extent[1], 1e-9)))))
    fig = matplotlib.figure.Figure(figsize=(width, 4.8), layout="constrained")
    axes = fig.subplots(2, 1, sharex=True, sharey=True)
    for ax, (lock, p, low, skate) in zip(axes, panels, strict=True):
        for f, colour in ((0, "tab:blue"), (1, "tab:red")):
            q = p[:, f][low[:, f]]
            ax.plot(q[:, horiz[1]], q[:, horiz[0]], ".", ms=2, color=colour,
                    label=("left" if f == 0 else "right") + " foot")
        ax.set_title(f"foot lock {'on' if lock else 'off'}: skating {skate:.2f} units/s")
        ax.set_xlabel("travel (file units)")
        ax.set_aspect(stretch, adjustable="box")
    for ax in axes:
        ax.set_ylabel("side (file units)" + (f"\nstretched ×{stretch}" if stretch > 1 else ""))
    axes[0].legend(loc="upper right", fontsize=8)
    fig.suptitle(f"Footprints of a synthesized {clip} walk: foot points within 2% of the body height of the floor")
    fig.savefig(st.path("plots", "footprints.png"), dpi=110)
