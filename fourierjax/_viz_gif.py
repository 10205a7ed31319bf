"""Stick-figure animations written as GIFs (public in `fourierjax.viz`: `save_gif`, `gif_figure`)."""

from __future__ import annotations

import os
from collections.abc import Sequence

import matplotlib.pyplot as plt
import numpy as np

from fourierjax.io.atomic import temporary_beside

#: One CMU length unit in metres (the CMU skeletons are in inches / 0.45); `fourierjax.viz.CMU_UNIT_M`.
CMU_UNIT_M = 0.0564

#: Colours in a GIF's palette (the figures' limbs, text, ground and their anti-aliased edges).
GIF_COLORS = 32

#: Height of a GIF panel over its width. A GIF's bytes grow with the area that changes between
#: frames (LZW spends tens of bytes on each row even when it is blank): square panels keep a
#: 3-panel, 40-frame walk of 480 px panels near 300 KB.
PANEL_ASPECT = 1.0


def save_gif(sequences: Sequence, parents: Sequence[int], path: str | os.PathLike, *,
             frame_time_s: float, names: Sequence[str] | None = None,
             titles: Sequence[str] | None = None, max_frames: int = 40, dpi: int = 100,
             azimuth_deg: float = 25.0, scale: float = CMU_UNIT_M, unit: str = "m",
             follow: bool = True, title: str | None = None, panel_px: int = 480) -> str:
    """Animated stick figures side by side, written as a GIF (pillow writer).

    Arguments:
        sequences: one ``[F, J, 3]`` array per figure (same skeleton, same F); parents, names:
            the skeleton; frame_time_s: seconds per frame of the sequences; titles: a caption
            per figure; max_frames: the animation is subsampled to at most this many frames
            (playback stays real time); panel_px: width of each panel in pixels (its height
            is `PANEL_ASPECT` times that); dpi: rendering resolution (text and lines are sized in pixels,
            so the picture looks the same at any dpi); follow: the camera follows each
            figure's root along the ground, whose ticks are labelled in ``unit``, else a fixed
            camera over the whole path.
    Returns:
        The path written.
    """
    fig, update, num, step = gif_figure(sequences, parents, frame_time_s=frame_time_s, names=names,
                                        titles=titles, max_frames=max_frames, dpi=dpi,
                                        azimuth_deg=azimuth_deg, scale=scale, unit=unit,
                                        follow=follow, title=title, panel_px=panel_px)
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from PIL import Image

    fps = max(1.0, 1.0 / (frame_time_s * step))
    try:
        canvas = FigureCanvasAgg(fig)  # whatever the backend (Jupyter's, svg): pixels
        frames = []
        for i in range(num):
            update(i)
            canvas.draw()
            frames.append(Image.fromarray(np.asarray(canvas.buffer_rgba())[..., :3]))
    finally:
        plt.close(fig)
    # One small palette for every frame, without dithering: a stick figure has a few colours
    # (Pillow stores each frame's rectangle that changed).
    palette = frames[0].quantize(colors=GIF_COLORS, method=Image.Quantize.MEDIANCUT)
    frames = [f.quantize(palette=palette, dither=Image.Dither.NONE) for f in frames]
    with temporary_beside(path) as tmp:  # whole or nothing
        # optimize=False: Pillow's palette optimisation made these GIFs a third larger.
        frames[0].save(tmp, format="GIF", save_all=True, append_images=frames[1:], loop=0,
                       duration=int(round(1000 / fps)), optimize=False)
    return os.fspath(path)


def _nice_step(span: float) -> float:
    """A round tick spacing (1, 2 or 5 times a power of ten) giving about four ticks on ``span``."""
    raw = span / 4
    mag = 10 ** np.floor(np.log10(raw))
    return float(min((m * mag for m in (1, 2, 5, 10)), key=lambda v: abs(v - raw)))


def gif_figure(sequences: Sequence, parents: Sequence[int], *, frame_time_s: float,
               names: Sequence[str] | None = None, titles: Sequence[str] | None = None,
               max_frames: int = 40, dpi: int = 100, azimuth_deg: float = 25.0,
               scale: float = CMU_UNIT_M, unit: str = "m", follow: bool = True,
               title: str | None = None, panel_px: int = 480):
    """The figure `save_gif` animates (arguments as there), for drawing one frame or testing.

    Returns:
        ``(fig, update, num_frames, step)``: ``update(i)`` poses the figures at animation frame
        ``i`` (of ``num_frames``, every ``step``-th frame of the sequences).
    """
    from matplotlib.ticker import FormatStrFormatter, MultipleLocator

    from fourierjax.viz import limb_colors, project

    seqs = [np.asarray(s, dtype=np.float64) for s in sequences]
    if not seqs:
        raise ValueError("save_gif: no sequences")
    F = seqs[0].shape[0]
    for s in seqs:
        if s.ndim != 3 or s.shape[0] != F:
            raise ValueError(f"save_gif: every sequence must be [F={F}, J, 3] (the same F), got {s.shape}")
        if s.shape[1] != len(parents):
            raise ValueError(f"positions have {s.shape[1]} joints but parents has {len(parents)} entries")
    step = max(1, int(np.ceil(F / max_frames)))
    idx = np.arange(0, F, step)
    proj = [project(s, azimuth_deg) * scale for s in seqs]  # [F, J, 2]
    ground = min(s[..., 1].min() for s in seqs) * scale
    height = max(s[..., 1].max() for s in seqs) * scale - ground
    n = len(seqs)
    pt = 72.0 / dpi  # points per pixel: text and lines are sized in pixels
    w_px, h_px = panel_px, int(round(PANEL_ASPECT * panel_px))
    top_px = 40 if title else 0
    fig = plt.figure(figsize=(n * w_px / dpi, (h_px + top_px) / dpi), dpi=dpi)
    fig_h = h_px + top_px
    # Each panel: its axes inset by margins (pixels) for the title above and the tick labels
    # below; the x range is set so that one metre is as long across as up (equal aspect).
    left, right, bottom, top = 10, 10, 52, 40 if titles is not None else 12
    box_w, box_h = w_px - left - right, h_px - bottom - top
    y0, y1 = ground - 0.02 * height, ground + 1.12 * height
    x_span = (y1 - y0) * box_w / box_h
    tick = _nice_step(x_span)
    colors = limb_colors(names if names is not None else [""] * len(parents))  # grey: the trunk's
    axes, artists = [], []
    for k in range(n):
        ax = fig.add_axes([(k * w_px + left) / (n * w_px), bottom / fig_h, box_w / (n * w_px),
                           box_h / fig_h])
        # Bones without anti-aliasing: a GIF of flat colours compresses to under half the size.
        lines = [ax.plot([], [], color=colors[j], lw=4 * pt, solid_capstyle="round",
                         antialiased=False)[0] for j, par in enumerate(parents) if par >= 0]
        ax.set_ylim(y0, y1)
        if follow:
            ax.set_xlim(-x_span / 2, x_span / 2)
        else:
            lo, hi = proj[k][..., 0].min(), proj[k][..., 0].max()
            mid, half = 0.5 * (lo + hi), 0.5 * max(x_span, hi - lo + 0.2 * height)
            ax.set_xlim(mid - half, mid + half)
            ax.set_ylim(y0, y0 + 2 * half * box_h / box_w)
        for side in ("top", "left", "right"):
            ax.spines[side].set_visible(False)
        # The ground is the x axis: ticks every `tick` metres, labelled, moving with the camera.
        ax.spines["bottom"].set_position(("data", ground))
        ax.spines["bottom"].set_color("#777777")
        ax.spines["bottom"].set_linewidth(1.5 * pt)
        ax.xaxis.set_major_locator(MultipleLocator(tick))
        ax.xaxis.set_major_formatter(FormatStrFormatter("%g"))
        ax.tick_params(axis="x", direction="inout", length=10 * pt, width=1.5 * pt,
                       labelsize=14 * pt, colors="#444444", pad=3 * pt)
        ax.set_yticks([])
        ax.set_xlabel(f"ground, forward Z ({unit})", fontsize=14 * pt, color="#444444",
                      labelpad=2 * pt)
        ax.patch.set_alpha(0.0)
        if titles is not None:
            ax.set_title(titles[k], fontsize=18 * pt, pad=8 * pt)
        axes.append(ax)
        artists.append(lines)
    if title:
        fig.suptitle(title, fontsize=20 * pt, y=1 - 8 / fig_h, va="top")
    bones = [(j, par) for j, par in enumerate(parents) if par >= 0]

    def update(i):
        out = []
        for k, lines in enumerate(artists):
            q = proj[k][idx[i]]
            for ln, (j, par) in zip(lines, bones, strict=True):
                ln.set_data(q[[par, j], 0], q[[par, j], 1])
            if follow:
                cx = q[0, 0]
                axes[k].set_xlim(cx - x_span / 2, cx + x_span / 2)
            out += lines
        return out

    update(0)
    return fig, update, len(idx), step
