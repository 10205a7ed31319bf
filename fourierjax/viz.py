"""Plots and stick-figure animations of gaits, spectra, style spaces and stances (matplotlib).

NumPy in, matplotlib figures out: functions that draw return the `Figure`, `save_figure` writes
PNGs and `save_gif` animated GIFs. The matplotlib backend is left to the caller (Jupyter's inline
backend shows the figures; the CLI and `fourierjax.demo` choose Agg).
"""

from __future__ import annotations

import io
import os
from collections.abc import Sequence

import matplotlib.pyplot as plt
import numpy as np
from matplotlib.text import Text

from fourierjax._viz_gif import CMU_UNIT_M, gif_figure, save_gif
from fourierjax.io.atomic import write_bytes_atomic

__all__ = [
    "CMU_UNIT_M",
    "limb_colors",
    "joint_groups",
    "channel_groups",
    "GROUP_COLORS",
    "place_labels",
    "project",
    "plot_spectrum",
    "plot_decomposition",
    "plot_style_scatter",
    "draw_stick_figure",
    "plot_stick_figure",
    "plot_stick_strip",
    "plot_hip_rule",
    "plot_posture_range",
    "plot_crowd",
    "save_figure",
    "save_gif",
    "gif_figure",
]

_LEFT, _RIGHT, _TRUNK = "#1f5fbf", "#c8322a", "#555555"


def _close(fig) -> None:
    plt.close(fig)


def save_figure(fig, path: str | os.PathLike, *, dpi: int = 100) -> str:
    """Write a figure to ``path`` (PNG by extension) and close it. Returns the path as str."""
    buf = io.BytesIO()
    fmt = os.path.splitext(os.fspath(path))[1].lstrip(".").lower() or "png"
    try:
        fig.savefig(buf, dpi=dpi, bbox_inches="tight", format=fmt)
    finally:
        _close(fig)
    write_bytes_atomic(path, buf.getvalue())  # whole or nothing
    return os.fspath(path)


def limb_colors(names: Sequence[str]) -> list[str]:
    """Colour per joint (the bone to its parent): blue for ``Left*``, red for ``Right*``, grey else.

    Also recognises ``L``/``R`` prefixes followed by an upper-case letter (``LHipJoint``) and
    ``l_``/``r_`` prefixes (the stance skeleton).
    """
    out = []
    for n in names:
        low = n.lower()
        if low.startswith("left") or low.startswith("l_") or (len(n) > 1 and n[0] == "L" and n[1].isupper()):
            out.append(_LEFT)
        elif low.startswith("right") or low.startswith("r_") or (len(n) > 1 and n[0] == "R" and n[1].isupper()):
            out.append(_RIGHT)
        else:
            out.append(_TRUNK)
    return out


#: Colours of the body parts of `joint_groups` (left blue, right red, as `limb_colors`).
GROUP_COLORS = {"left leg": "#1f5fbf", "right leg": "#c8322a", "left arm": "#6fa8ff",
                "right arm": "#ff8a70", "trunk and head": "#555555"}
_CYCLE = ["#1f77b4", "#ff7f0e", "#2ca02c", "#d62728", "#9467bd", "#8c564b", "#e377c2",
          "#7f7f7f", "#bcbd22", "#17becf"]


def joint_groups(parents: Sequence[int], body_map) -> list[str]:
    """The body part of each joint, from a body map (never from joint names).

    Arguments:
        parents: parent index per joint (-1 for a root); body_map: a `fourierjax.body.BodyMap`
            of the same skeleton (its legs' hips and arms' collars start the limbs).
    Returns:
        One of `GROUP_COLORS`' keys per joint: a joint belongs to the limb whose first joint it
        is or descends from, else to "trunk and head".
    """
    starts = {body_map.left.hip: "left leg", body_map.right.hip: "right leg"}
    for arm, name in ((body_map.left_arm, "left arm"), (body_map.right_arm, "right arm")):
        if arm is not None:
            starts[arm.collar] = name
    out = []
    for j in range(len(parents)):
        k, group = j, "trunk and head"
        while k >= 0:
            if k in starts:
                group = starts[k]
                break
            k = parents[k]
        out.append(group)
    return out


def channel_groups(channel_names: Sequence[str], joint_names: Sequence[str],
                   parents: Sequence[int], body_map) -> list[str] | None:
    """The body part (`joint_groups`) of each ``"Joint.xxx"`` channel, for `plot_spectrum`.

    Arguments:
        channel_names: ``"Joint.suffix"`` names (e.g. ``"LeftLeg.expmap0"``); joint_names,
            parents: the skeleton; body_map: its `fourierjax.body.BodyMap`, or None.
    Returns:
        One part per channel (channels of no joint, e.g. ``root.vz``, count as the trunk), or
        None when ``body_map`` is None.
    """
    if body_map is None:
        return None
    by_joint = dict(zip(joint_names, joint_groups(parents, body_map), strict=True))
    return [by_joint.get(n.split(".")[0], "trunk and head") for n in channel_names]


def project(positions, azimuth_deg: float = 25.0, up_axis: int = 1,
            elevation_deg: float = 0.0) -> np.ndarray:
    """Oblique orthographic projection of points ``[..., 3]`` to picture coordinates ``[..., 2]``.

    The picture's horizontal axis is ``z cos(a) - x sin(a)`` (forward, +Z, seen from the walker's
    left side turned by ``a = azimuth_deg`` towards the front) and its vertical axis is the up
    axis, so lengths along Z and Y are true lengths when ``a = 0``. With ``elevation_deg = e``
    the view looks down by ``e``: the vertical axis is ``y cos(e) + d sin(e)``, with
    ``d = x cos(a) + z sin(a)`` the depth away from the viewer (farther points higher).
    """
    p = np.asarray(positions, dtype=np.float64)
    if p.shape[-1] != 3:
        raise ValueError(f"project: positions must be [..., 3], got shape {p.shape}")
    a, e = np.radians(azimuth_deg), np.radians(elevation_deg)
    x, z = p[..., 0], p[..., 2]
    if up_axis != 1:
        raise ValueError("project: only Y-up positions are supported (up_axis=1)")
    depth = x * np.cos(a) + z * np.sin(a)
    up = p[..., 1] if e == 0.0 else p[..., 1] * np.cos(e) + depth * np.sin(e)
    return np.stack([z * np.cos(a) - x * np.sin(a), up], axis=-1)


def _check_skeleton(positions: np.ndarray, parents: Sequence[int]) -> None:
    if positions.shape[-2] != len(parents):
        raise ValueError(
            f"positions have {positions.shape[-2]} joints but parents has {len(parents)} entries"
        )


def draw_stick_figure(ax, positions, parents: Sequence[int], *, names: Sequence[str] | None = None,
                      azimuth_deg: float = 25.0, scale: float = 1.0, offset=(0.0, 0.0),
                      linewidth: float = 2.0, alpha: float = 1.0, joints: bool = True):
    """Draw one pose ``[J, 3]`` as bones (joint to parent) on ``ax``; returns the Line2D list.

    The view is `project`'s oblique orthographic one (the figure walks along +Z, seen from its
    left); left limbs are blue, right limbs red, the trunk grey (`limb_colors`). ``scale``
    multiplies lengths (e.g. :data:`CMU_UNIT_M` to draw in metres), ``offset`` shifts the
    projected picture (after scaling).
    """
    p = np.asarray(positions, dtype=np.float64)
    _check_skeleton(p, parents)
    q = project(p, azimuth_deg) * scale + np.asarray(offset, dtype=np.float64)
    colors = limb_colors(names) if names is not None else [_TRUNK] * len(parents)
    lines = []
    for j, par in enumerate(parents):
        if par < 0:
            continue
        (ln,) = ax.plot(q[[par, j], 0], q[[par, j], 1], color=colors[j], lw=linewidth,
                        alpha=alpha, solid_capstyle="round")
        lines.append(ln)
    if joints:
        ax.plot(q[:, 0], q[:, 1], "o", color="k", ms=1.5, alpha=alpha)
    return lines


def _ground(ax, y: float, x0: float, x1: float) -> None:
    ax.axhline(y, color="#999999", lw=1.0, zorder=0)
    ax.set_xlim(x0, x1)


def plot_stick_figure(positions, parents: Sequence[int], *, names: Sequence[str] | None = None,
                      title: str | None = None, azimuth_deg: float = 25.0,
                      scale: float = CMU_UNIT_M, unit: str = "m", ground: float | None = None):
    """One pose as a stick figure with labelled axes (horizontal: the library's Z turned by
    `azimuth_deg`; vertical: up, whatever the file's up axis was).

    Arguments:
        positions: ``[J, 3]`` joint positions (file units); parents: parent index per joint
            (-1 for the root); names: joint names (colours left/right limbs).
        scale: file units -> ``unit`` (default CMU units -> metres); ground: floor height in
            file units (default the lowest joint).
    Returns:
        Figure.
    """
    p = np.asarray(positions, dtype=np.float64)
    fig, ax = plt.subplots(figsize=(3.2, 4.2))
    draw_stick_figure(ax, p, parents, names=names, azimuth_deg=azimuth_deg, scale=scale)
    q = project(p, azimuth_deg) * scale
    g = (p[:, 1].min() if ground is None else ground) * scale
    pad = 0.25 * (q[:, 1].max() - g)
    _ground(ax, g, q[:, 0].min() - pad, q[:, 0].max() + pad)
    ax.set_ylim(g - 0.05 * pad, q[:, 1].max() + pad / 2)
    ax.set_aspect("equal")
    ax.set_xlabel(f"horizontal ({unit})")
    ax.set_ylabel(f"up ({unit})")
    if title:
        ax.set_title(title, fontsize=10)
    return fig


def plot_stick_strip(poses: Sequence, parents: Sequence[int], labels: Sequence[str], *,
                     names: Sequence[str] | None = None, title: str | None = None,
                     azimuth_deg: float = 25.0, scale: float = CMU_UNIT_M, unit: str = "m",
                     frames_per_pose: int = 1):
    """A row of stick figures side by side (Unuma 1995 Fig. 3: inter/extrapolated walks).

    Arguments:
        poses: one ``[J, 3]`` pose per panel, or ``[K, J, 3]`` per panel to overlay K frames of a
            cycle as a faded trail (the last is drawn solid); each is re-centred horizontally
            on its root.
        parents, names: the skeleton; labels: a caption under each panel (e.g. ``s = -0.5``).
    Returns:
        Figure.
    """
    panels = [np.asarray(p, dtype=np.float64) for p in poses]
    panels = [p[None] if p.ndim == 2 else p for p in panels]
    if len(labels) != len(panels):
        raise ValueError(f"plot_stick_strip: {len(labels)} labels for {len(panels)} poses")
    ground = min(p[..., 1].min() for p in panels) * scale
    height = max(p[..., 1].max() for p in panels) * scale - ground
    width = 0.75 * height
    fig, ax = plt.subplots(figsize=(1.6 * len(panels) + 0.6, 3.4))
    for i, (p, lab) in enumerate(zip(panels, labels, strict=True)):
        root = project(p[-1, 0], azimuth_deg)[0] * scale
        k = len(p)
        for f in range(k):
            alpha = 1.0 if f == k - 1 else 0.15 + 0.35 * f / max(k - 1, 1)
            draw_stick_figure(ax, p[f], parents, names=names, azimuth_deg=azimuth_deg,
                              scale=scale, offset=(i * width - root, 0.0),
                              linewidth=2.0 if f == k - 1 else 1.0, alpha=alpha,
                              joints=f == k - 1)
        ax.text(i * width, ground - 0.09 * height, lab, ha="center", va="top", fontsize=9)
    _ground(ax, ground, -0.6 * width, (len(panels) - 0.4) * width)
    ax.set_ylim(ground - 0.2 * height, ground + 1.08 * height)
    ax.set_aspect("equal")
    ax.set_xticks([])
    ax.set_ylabel(f"up ({unit})")
    if title:
        ax.set_title(title, fontsize=10)
    return fig


def plot_spectrum(freqs_hz, amplitude, *, channel_names: Sequence[str] | None = None,
                  fundamental_hz: float | None = None, max_hz: float = 8.0,
                  unit: str = "rad", title: str | None = None, skip_dc: bool = False,
                  stems: bool = False, groups: Sequence[str] | None = None):
    """Amplitude spectra of many channels superimposed (Tilmanne & Dutoit Fig. 1).

    Arguments:
        freqs_hz: ``[K]`` frequencies; amplitude: ``[K, C]`` single-sided amplitudes (e.g.
            ``fourier.amplitude_spectrum``); fundamental_hz: draws the gait-cycle frequency and
            its harmonics as dashed lines; unit: the channels' unit for the y label; stems:
            draw each frequency as a vertical stem (a line spectrum, e.g. a model's harmonics).
        groups: a body part per channel (e.g. from `joint_groups`): one colour and one legend
            entry per part. Without it, up to 10 channels are named in the legend
            (``channel_names``); more share a legend entry.
    Returns:
        Figure.
    """
    f = np.asarray(freqs_hz, dtype=np.float64)
    a = np.asarray(amplitude, dtype=np.float64)
    if a.ndim != 2 or a.shape[0] != f.shape[0]:
        raise ValueError(f"plot_spectrum: amplitude {a.shape} must be [K={f.shape[0]}, C]")
    keep = f <= max_hz
    if skip_dc:
        keep &= f > 0
    C = a.shape[1]
    if groups is not None and len(groups) != C:
        raise ValueError(f"plot_spectrum: {len(groups)} groups for {C} channels")
    fig, ax = plt.subplots(figsize=(7.2, 4.0))
    if groups is not None:
        colors = {g: GROUP_COLORS.get(g, _CYCLE[k % len(_CYCLE)])
                  for k, g in enumerate(dict.fromkeys(groups))}
        counts = {g: list(groups).count(g) for g in colors}
        label_of = {g: f"{g} ({counts[g]})" for g in colors}
        styles = [(colors[g], label_of[g]) for g in groups]
    elif channel_names is not None and C <= 10:
        styles = [(_CYCLE[k % len(_CYCLE)], channel_names[k]) for k in range(C)]
    else:
        styles = [(_CYCLE[k % len(_CYCLE)], f"{C} channels" if k == 0 else None) for k in range(C)]
    seen = set()
    for k, (color, label) in enumerate(styles):
        label = None if label in seen else label
        seen.add(label)
        if stems:
            ax.vlines(f[keep], 0, a[keep, k], lw=0.6, alpha=0.4, color=color)
            ax.plot(f[keep], a[keep, k], "o", ms=3, alpha=0.7, color=color, label=label)
        else:
            ax.plot(f[keep], a[keep, k], lw=0.8, alpha=0.75, color=color, label=label)
    if fundamental_hz is not None and np.isfinite(fundamental_hz):
        for n in range(1, int(max_hz / fundamental_hz) + 1):
            ax.axvline(n * fundamental_hz, color="k" if n == 1 else "#999999", ls="--", lw=0.9,
                       label=f"gait cycle {fundamental_hz:.2f} Hz and harmonics" if n == 1 else None)
    ax.legend(loc="upper right", fontsize=8, title="channels by body part" if groups else None,
              title_fontsize=8)
    ax.set_xlabel("frequency (Hz)")
    ax.set_ylabel(f"amplitude ({unit})")
    ax.set_xlim(0, max_hz)
    n = a.shape[1]
    ax.set_title(title or f"Amplitude spectrum of {n} channels (superimposed)", fontsize=10)
    ax.grid(alpha=0.3)
    return fig


def plot_decomposition(t_s, data, offset, amplitude, phase, omega: float, *,
                       channel_labels: Sequence[str], unit: str = "rad",
                       title: str | None = None):
    """Data, offset, each harmonic and the sum, in stacked panels (Tilmanne & Dutoit Fig. 3).

    Arguments:
        t_s: ``[T]`` seconds (the data's, in the model's time axis); data: ``[T, K]`` K channels;
        offset ``[K]``, amplitude ``[K, N]``, phase ``[K, N]``, omega (rad/s): their Fourier model
        (Unuma eq. 1, sine convention); channel_labels: K legend entries.
    Returns:
        Figure with ``N + 3`` panels: data, constant, harmonics 1..N, approximation (over data).
    """
    t = np.asarray(t_s, dtype=np.float64)
    x = np.asarray(data, dtype=np.float64)
    off = np.asarray(offset, dtype=np.float64)
    amp = np.asarray(amplitude, dtype=np.float64)
    ph = np.asarray(phase, dtype=np.float64)
    if x.ndim != 2 or x.shape[0] != t.shape[0] or off.shape != (x.shape[1],):
        raise ValueError(f"plot_decomposition: data {x.shape}, t {t.shape}, offset {off.shape}")
    K, N = amp.shape
    n = np.arange(1, N + 1)
    comps = amp[None, :, :] * np.sin(n[None, None, :] * omega * t[:, None, None] + ph[None])
    approx = off[None, :] + comps.sum(-1)
    rows = [("motion capture", x), ("constant", np.broadcast_to(off, x.shape))]
    names = {1: "fundamental", 2: "2nd harmonic", 3: "3rd harmonic"}
    rows += [(names.get(k, f"{k}th harmonic"), comps[:, :, k - 1]) for k in n]
    rows += [(f"sum of {N} harmonics + constant", approx)]
    fig, axes = plt.subplots(len(rows), 1, figsize=(6.4, 1.25 * len(rows) + 0.6), sharex=True)
    colors = plt.rcParams["axes.prop_cycle"].by_key()["color"]
    for ax, (name, y) in zip(axes, rows, strict=True):
        for k in range(K):
            ax.plot(t, y[:, k], color=colors[k % len(colors)], lw=1.2,
                    label=channel_labels[k] if ax is axes[0] else None)
            if ax is axes[-1]:
                ax.plot(t, x[:, k], color=colors[k % len(colors)], lw=0.8, ls=":", alpha=0.8)
        ax.set_ylabel(unit, fontsize=8)
        ax.set_title(name, fontsize=9, loc="left", pad=2)
        ax.tick_params(labelsize=7)
        ax.grid(alpha=0.3)
    axes[0].legend(fontsize=7, ncol=K, loc="upper right")
    axes[-1].set_xlabel("time (s)")
    if title:
        fig.suptitle(title, fontsize=10)
    fig.tight_layout()
    return fig


def plot_style_scatter(coords, labels: Sequence[str], *, explained: Sequence[float] | None = None,
                       groups: Sequence[str] | None = None, title: str | None = None,
                       arrows: Sequence[tuple[int, int]] = ()):
    """Models as points on the first two principal components of style space (Troje).

    Arguments:
        coords: ``[M, >=2]`` PCA coordinates (``style.pca_project``); labels: one per model;
        explained: variance ratio per component (axis labels); groups: a category per model
        (colour and legend, e.g. "walk"/"run"); arrows: index pairs to join with an arrow
        (e.g. a characteristic).
    Returns:
        Figure.
    """
    c = np.asarray(coords, dtype=np.float64)
    if c.ndim != 2 or c.shape[1] < 2 or c.shape[0] != len(labels):
        raise ValueError(f"plot_style_scatter: coords {c.shape} for {len(labels)} labels")
    fig, ax = plt.subplots(figsize=(5.6, 4.4))
    groups = list(groups) if groups is not None else ["model"] * len(labels)
    colors = plt.rcParams["axes.prop_cycle"].by_key()["color"]
    for k, g in enumerate(dict.fromkeys(groups)):
        idx = [i for i, gi in enumerate(groups) if gi == g]
        ax.scatter(c[idx, 0], c[idx, 1], s=40, color=colors[k % len(colors)], label=g, zorder=3)
    for i, j in arrows:
        ax.annotate("", c[j, :2], c[i, :2], arrowprops=dict(arrowstyle="->", color="#888888"))
    ev = list(explained) if explained is not None else None
    ax.set_xlabel("PC 1" + (f" ({100 * ev[0]:.0f}% of variance)" if ev else ""))
    ax.set_ylabel("PC 2" + (f" ({100 * ev[1]:.0f}% of variance)" if ev and len(ev) > 1 else ""))
    ax.axhline(0, color="#cccccc", lw=0.8, zorder=0)
    ax.axvline(0, color="#cccccc", lw=0.8, zorder=0)
    ax.legend(fontsize=8, loc="best")
    ax.grid(alpha=0.3)
    ax.set_title(title or "Style space (PCA of phasor style vectors)", fontsize=10)
    ax.margins(0.18)  # room for labels at the edges
    place_labels(ax, c[:, :2], labels, fontsize=8)
    return fig


#: Label offsets tried by `place_labels`, in points from the point (then farther, with a line).
_OFFSETS = ((5, 5), (5, -5), (-5, 5), (-5, -5), (7, 0), (-7, 0), (0, 8), (0, -8))


def place_labels(ax, points, labels: Sequence[str], *, fontsize: float = 8.0) -> list:
    """Annotate points with labels that overlap neither each other nor the points.

    Each label tries offsets around its point (`_OFFSETS`, then 2, 3, 4 and 6 times as far,
    joined to the point by a thin line); the first whose box is clear of the labels already
    placed, of every point's marker and inside the axes is kept (else the last one tried).
    The axes' limits must be final: call it after plotting, and do not autoscale after.

    Arguments:
        ax: matplotlib Axes; points: ``[M, 2]`` data coordinates; labels: one per point;
        fontsize: in points.
    Returns:
        The annotations, in the order of ``labels``.
    """
    p = np.asarray(points, dtype=np.float64)
    fig = ax.figure
    renderer = fig.canvas.get_renderer()
    ax.autoscale_view()
    ax.set_xlim(ax.get_xlim())  # freeze the limits: placement is in screen coordinates
    ax.set_ylim(ax.get_ylim())
    to_px = ax.transData.transform
    r = 5.0 * fig.dpi / 72  # a marker's half size, pixels
    markers = [(x - r, y - r, x + r, y + r) for x, y in to_px(p)]
    frame = ax.get_window_extent(renderer)
    placed: list[tuple[float, float, float, float]] = []
    out = []
    for i, lab in enumerate(labels):
        ann = None
        for scale in (1, 2, 3, 4, 6):
            for dx, dy in _OFFSETS:
                if ann is not None:
                    ann.remove()
                ha = "left" if dx > 0 else "right" if dx < 0 else "center"
                va = "bottom" if dy > 0 else "top" if dy < 0 else "center"
                line = dict(arrowstyle="-", color="#999999", lw=0.6) if scale > 1 else None
                ann = ax.annotate(lab, p[i], textcoords="offset points",
                                  xytext=(dx * scale, dy * scale), ha=ha, va=va,
                                  fontsize=fontsize, arrowprops=line, zorder=4)
                ann.update_positions(renderer)  # else the box is at the origin until drawn
                bb = Text.get_window_extent(ann, renderer)  # the text, not its line
                box = (bb.x0 - 1, bb.y0 - 1, bb.x1 + 1, bb.y1 + 1)
                inside = (box[0] >= frame.x0 and box[2] <= frame.x1 and box[1] >= frame.y0
                          and box[3] <= frame.y1)
                others = placed + [m for k, m in enumerate(markers) if k != i or scale > 1]
                if inside and not any(_overlap(box, o) for o in others):
                    break
            else:
                continue
            break
        placed.append(box)
        out.append(ann)
    return out


def _overlap(a, b) -> bool:
    return a[0] < b[2] and b[0] < a[2] and a[1] < b[3] and b[1] < a[3]


def plot_hip_rule(phase, curves: dict, *, gait: float, jump: float, unit: str = "file units",
                  title: str | None = None):
    """The three hip-height rules side by side (Unuma 1995 eq. 4-5; ``gait.hip_rule_curves``).

    Arguments:
        phase: ``[T]`` x axis (cycle phase in radians, or time); curves: dict with ``"L"``,
            ``"N"``, ``"unuma1995"``, ``"continuous"``, ``"smooth"`` (each ``[T]``).
    Returns:
        Figure with two panels: L and the three L_run curves; N(t) against the gait threshold.
    """
    x = np.asarray(phase, dtype=np.float64)
    fig, (a1, a2) = plt.subplots(2, 1, figsize=(6.4, 4.8), sharex=True,
                                 gridspec_kw={"height_ratios": [2, 1]})
    a1.plot(x, np.asarray(curves["L"]), color="k", lw=1.0, ls=":", label="L = max(L_L, L_R) (eq. 4)")
    styles = {"unuma1995": ("C3", "-", "faithful eq. 5 (jumps at threshold)"),
              "continuous": ("C0", "--", "continuous"),
              "smooth": ("C2", "-.", "smooth (differentiable)")}
    for key, (col, ls, lab) in styles.items():
        if key in curves:
            a1.plot(x, np.asarray(curves[key]), color=col, ls=ls, lw=1.4, label=lab)
    a1.set_ylabel(f"hip height L_run ({unit})")
    a1.legend(fontsize=8, loc="lower right")
    a1.grid(alpha=0.3)
    a2.plot(x, np.asarray(curves["N"]), color="k", lw=1.0, label="N = (Lmax - L) / Lmax")
    a2.axhline(gait, color="C3", ls="--", lw=1.0, label=f"gait = {gait:g}")
    a2.set_ylabel("N")
    a2.set_xlabel("cycle phase (rad)")
    a2.legend(fontsize=8, loc="upper right")
    a2.grid(alpha=0.3)
    fig.suptitle(title or f"Hip-height rule, gait = {gait:g}, jump = {jump:g}", fontsize=10)
    fig.tight_layout()
    return fig


def plot_posture_range(poses: Sequence, parents: Sequence[int], intensities: Sequence[float], *,
                       names: Sequence[str] | None = None, title: str | None = None,
                       scale: float = 1.0, unit: str = "m", azimuth_deg: float = 15.0):
    """A continuous range of postures side by side (Neff & Fiume 2004 Fig. 5).

    Arguments:
        poses: ``[J, 3]`` joint positions per intensity (stance skeleton: metres, Y up, facing
            +Z); azimuth_deg: 0 is the side view (sagittal curves: posture scale), 90 the front
            view (coronal curves: beauty line); the default 15 is a slightly turned side view;
        intensities: the shape-set intensity of each pose (captions).
    Returns:
        Figure.
    """
    labels = [f"{v:+.2f}" for v in intensities]
    fig = plot_stick_strip(poses, parents, labels, names=names, azimuth_deg=azimuth_deg,
                           scale=scale, unit=unit,
                           title=title or "Posture range (intensity under each figure)")
    return fig


def plot_crowd(positions, parents: Sequence[int], values, *, value_label: str = "",
               title: str | None = None, azimuth_deg: float = 25.0, elevation_deg: float = 20.0,
               scale: float = CMU_UNIT_M, unit: str = "m"):
    """Many characters at one instant, seen from above at an angle, coloured by a value each.

    Arguments:
        positions: ``[B, J, 3]`` joint positions (Y up), e.g. ``crowd.crowd_positions``;
        parents: the skeleton's parent indices; values: ``[B]`` one number per character (e.g.
        its style parameter), shown by colour with a colour bar labelled ``value_label``;
        azimuth_deg, elevation_deg: the view (`project`: turned about the vertical, looking
        down); scale: length unit of the picture.
    Returns:
        Figure.
    """
    from matplotlib.collections import LineCollection

    p = np.asarray(positions, dtype=np.float64) * scale
    v = np.asarray(values, dtype=np.float64)
    if p.ndim != 3 or p.shape[-1] != 3 or v.shape != p.shape[:1]:
        raise ValueError(f"plot_crowd: positions {p.shape} must be [B, J, 3] with values [B], "
                         f"got values {v.shape}")
    _check_skeleton(p, parents)
    q = project(p, azimuth_deg, elevation_deg=elevation_deg)  # [B, J, 2]
    a = np.radians(azimuth_deg)
    depth = p[..., 0] * np.cos(a) + p[..., 2] * np.sin(a)  # away from the viewer
    bones = [(par, j) for j, par in enumerate(parents) if par >= 0]
    # Far characters first, so that near ones are drawn over them.
    order = np.argsort(-depth.mean(axis=1))
    segs = q[order][:, [b for b, _ in bones]], q[order][:, [c for _, c in bones]]
    segs = np.stack(segs, axis=2).reshape(-1, 2, 2)
    fig, ax = plt.subplots(figsize=(8.0, 5.0))
    lc = LineCollection(segs, array=np.repeat(v[order], len(bones)), cmap="viridis", lw=1.2)
    ax.add_collection(lc)
    ax.autoscale_view()
    ax.set_aspect("equal")
    ax.set_xlabel(f"{unit} (oblique view)")
    ax.set_yticks([])
    fig.colorbar(lc, ax=ax, label=value_label, shrink=0.7, pad=0.02)
    ax.set_title(title or f"{len(v)} characters", fontsize=10)
    return fig
