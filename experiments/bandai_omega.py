"""Issue #20: ω from step events against the fitted fundamental on every Bandai-1 locomotion clip.

Fits every walk, run, dash and walk-back clip of ``../shared/data/mocap/bandai1`` with
`fourierjax.motion.fit_motions` (N = 3) and prints, per clip, the step frequency (median heel
strike interval), the spectral and fitted fundamentals (Hz), their ratio, the alignment and the
heel strikes; writes the table as JSON (``--out``). Usage:
``python -m experiments.bandai_omega [--out FILE] [--only NAME ...]``.
"""

from __future__ import annotations

import argparse
import json
import pathlib
import sys

import numpy as np

DATA = pathlib.Path(__file__).resolve().parents[1] / ".." / "shared" / "data" / "mocap" / "bandai1" / "data"
LOCOMOTION = ("walk", "run", "dash", "walk-back")
BOUND = 0.05


def rows(only=None, num_harmonics: int = 3) -> list[dict]:
    """One dict per clip: name, frames, strikes, Hz (steps, spectral, guess, fit), ratio, pass."""
    from fourierjax.io.bvh import read_bvh
    from fourierjax.motion import fit_motions

    files = sorted(p for p in DATA.glob("*.bvh") if p.stem.split("_")[1] in LOCOMOTION)
    if only:
        files = [p for p in files if p.stem.removeprefix("dataset-1_") in only]
    motions = [read_bvh(p) for p in files]
    hz = 1 / (2 * np.pi)
    out = []
    for p, m, f in zip(files, motions, fit_motions(motions, num_harmonics), strict=True):
        ratio = f.omega_steps / f.omega_fit
        out.append({
            "clip": p.stem.removeprefix("dataset-1_"), "frames": m.num_frames,
            "segment": [f.frame_start, f.frame_stop], "alignment": f.alignment,
            "left_strikes": len(f.left_heel_strikes), "right_strikes": len(f.right_heel_strikes),
            "steps_hz": round(f.omega_steps * hz, 4), "spectral_hz": round(f.omega_spectral * hz, 4),
            "fit_hz": round(f.omega_fit * hz, 4), "steps_over_fit": round(float(ratio), 4),
            "within_5pct": bool(np.isfinite(ratio) and abs(ratio - 1) <= BOUND),
        })
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", type=pathlib.Path)
    ap.add_argument("--only", nargs="*")
    args = ap.parse_args(argv)
    if not DATA.is_dir():
        print(f"Bandai-Namco data not found at {DATA}")
        return 0
    table = rows(args.only)
    print("| clip | frames | segment | L/R strikes | steps Hz | spectral Hz | fit Hz | steps/fit | ok |")
    print("|---|---|---|---|---|---|---|---|---|")
    for r in table:
        print(f"| {r['clip']} | {r['frames']} | {r['segment'][0]}-{r['segment'][1]} | {r['left_strikes']}/"
              f"{r['right_strikes']} | {r['steps_hz']} | {r['spectral_hz']} | {r['fit_hz']} | "
              f"{r['steps_over_fit']} | {'yes' if r['within_5pct'] else '**no**'} |")
    ok = sum(r["within_5pct"] for r in table)
    print(f"\n{ok} of {len(table)} within {BOUND:.0%}")
    if args.out:
        args.out.write_text(json.dumps({"bound": BOUND, "within": ok, "clips": table}, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
