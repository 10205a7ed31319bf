"""The `fourierjax demo` pipeline: fit the bundled CMU clips, synthesize styled gaits, plot, animate.

`run_demo(out_dir)` writes, under ``out_dir``:

* ``models/<clip>.npz``: fitted Fourier models (versioned model files, `fourierjax.io.model_io`);
* ``bvh/*.bvh``: synthesized motions (normal, brisk and tired walks by inter/extrapolation
  (Unuma 1995 eq. 3), a brisk run by superposition (eq. 8), walk->run and run->walk
  transitions, step/speed/gait/jump variants (Unuma §3.1), a shivering walk (§3.3));
* ``stance/*.bvh``: the expressive-stance gallery (Neff & Fiume 2004), when `fourierjax.stance`
  provides shape sets;
* ``plots/*.png``: spectrum (Tilmanne & Dutoit Fig. 1), decomposition (their Fig. 3), the
  inter/extrapolation strip (Unuma Fig. 3), the style-space PCA scatter, the hip-rule
  comparison, the posture range (Neff & Fiume Fig. 5), a crowd of 10,000 fitted walkers of
  different styles (`motion.channel_model`, `fourierjax.crowd`);
* ``gifs/*.gif``: animated stick figures of the main results;
* ``summary.json``: fit metrics per clip, what was written, what was skipped and why.

A part whose library module is missing is skipped with a printed notice (the rest still runs).
This is an edge module (files, plots); the core never imports it.
"""

from __future__ import annotations

import dataclasses
import json
import pathlib
import sys
import time
from collections.abc import Callable

import numpy as np

from fourierjax._demo_plots import (
    STANCE_GALLERY,
    _crowd,
    _gifs,
    _plot_decomposition,
    _plot_hip_rule,
    _plot_spectrum,
    _plot_strip,
    _plot_style_space,
    _stance,
)
from fourierjax._demo_synth import (
    RUNS,
    WALKS,
    _fit,
    _import,  # noqa: F401 - demo._import, as before the split
    _Skip,
    _State,
    _synth_noise,
    _synth_run,
    _synth_steps,
    _synth_transitions,
    _synth_walks,
)
from fourierjax.errors import UserError
from fourierjax.io.atomic import write_bytes_atomic

__all__ = ["DemoConfig", "run_demo", "WALKS", "RUNS", "STANCE_GALLERY"]


@dataclasses.dataclass(frozen=True)
class DemoConfig:
    """Settings of the demo (defaults: the full demo).

    - ``harmonics``: N of every fitted model (Unuma: 3 to 7; Tilmanne: 2).
    - ``seconds``: length of each synthesized BVH motion.
    - ``clips``: the bundled clips to fit (must include 07_01, 07_04, 07_12, 02_01, 02_03 and
      09_01 for every part to run; others are skipped with a notice when absent).
    - ``gif_frames``, ``gif_dpi``: size of the animations.
    - ``gifs``, ``stance``: switch those parts off.
    - ``crowd``: characters in the crowd of fitted walkers (0: no crowd).
    """

    harmonics: int = 3
    seconds: float = 4.0
    clips: tuple[str, ...] = tuple(WALKS) + tuple(RUNS)
    gif_frames: int = 40
    gif_dpi: int = 64
    gifs: bool = True
    stance: bool = True
    crowd: int = 10_000
    noise_deg: float = 2.0
    seed: int = 0


# ---------------------------------------------------------------------------------- pipeline

STEPS: tuple[tuple[str, Callable[[_State], None]], ...] = (
    ("fit models", _fit),
    ("walks (inter/extrapolation)", _synth_walks),
    ("brisk run (superposition)", _synth_run),
    ("transitions", _synth_transitions),
    ("step/gait/jump variants", _synth_steps),
    ("shivering walk", _synth_noise),
    ("spectrum plot", _plot_spectrum),
    ("decomposition plot", _plot_decomposition),
    ("inter/extrapolation strip", _plot_strip),
    ("style-space PCA", _plot_style_space),
    ("hip-rule plot", _plot_hip_rule),
    ("crowd of fitted walkers", _crowd),
    ("stance gallery", _stance),
    ("animated GIFs", _gifs),
)


def run_demo(out_dir, config: DemoConfig | None = None, *, progress: bool = True,
             log: Callable[[str], None] | None = None) -> dict:
    """Run the whole demo and write its outputs under ``out_dir`` (see the module docstring).

    Arguments:
        out_dir: output folder (created); config: a :class:`DemoConfig` (default: full demo);
        progress: show a tqdm progress bar on stderr; log: where notices go (default: stderr,
        through tqdm so the bar stays intact).
    Returns:
        The summary dict also written to ``out_dir/summary.json``.
    """
    from tqdm import tqdm

    cfg = config or DemoConfig()
    from fourierjax.cli import use_agg

    use_agg()  # the demo writes files: Agg, whatever backend the caller had
    from fourierjax._compile_cache import enable_compile_cache

    enable_compile_cache()
    if cfg.harmonics < 1 or cfg.harmonics > 16:
        raise UserError(f"--harmonics: must be between 1 and 16, got {cfg.harmonics}")
    if not (np.isfinite(cfg.seconds) and 0.5 <= cfg.seconds <= 60):
        raise UserError(f"--seconds: must be between 0.5 and 60, got {cfg.seconds}")
    from fourierjax import data

    unknown = [c for c in cfg.clips if c not in data.list()]
    if unknown:  # before the output folder is made: a typo leaves nothing behind
        raise UserError(f"--clips: unknown clip(s) {unknown}; bundled: {', '.join(data.list())}")
    out = pathlib.Path(out_dir)
    if out.exists() and not out.is_dir():
        raise UserError(f"--out: {out} exists and is not a directory")
    out.mkdir(parents=True, exist_ok=True)
    bar = tqdm(total=len(STEPS), desc="fourierjax demo", unit="step", disable=not progress,
               file=sys.stderr)
    write = log or (lambda s: tqdm.write(f"fourierjax: {s}", file=sys.stderr))
    st = _State(out=out, cfg=cfg, log=write)
    timings = {}
    t_all = time.perf_counter()
    for name, fn in STEPS:
        bar.set_postfix_str(name)
        t0 = time.perf_counter()
        try:
            fn(st)
        except _Skip as err:
            write(f"notice: {name} skipped: {err}")
            st.skipped.append({"part": name, "reason": str(err)})
        timings[name] = round(time.perf_counter() - t0, 2)
        bar.update(1)
    bar.close()
    summary = {
        "config": dataclasses.asdict(cfg),
        "fits": {c: f.summary() for c, f in st.fits.items()},
        "synthesis": st.extra.get("walk_normal") and {
            k: v for k, v in st.extra.items() if k in ("walk_normal", "run_flight",
                                                        "run_high_jump")},
        "style_pca_explained_variance_ratio": st.extra.get("pca_explained"),
        "stance": st.extra.get("stance"),
        "crowd": st.extra.get("crowd"),
        "written": st.written,
        "skipped": st.skipped,
        "timings_s": timings,
        "total_s": round(time.perf_counter() - t_all, 2),
    }
    write_bytes_atomic(out / "summary.json", json.dumps(summary, indent=2, default=_json_default).encode())
    return summary


def _json_default(x):
    if isinstance(x, np.generic):
        return x.item()
    if isinstance(x, np.ndarray):
        return x.tolist()
    return str(x)
