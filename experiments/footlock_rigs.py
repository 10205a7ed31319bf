"""Issue #21 foot-lock figures of the same walks and runs rewritten into other rigs, units, up axes and frame rates.

Each clip (CMU 02_01 walk, 02_03 run; Bandai-1 walk_normal, run_normal, run_happy when
``../shared/data/mocap/bandai1`` is present) is rewritten into every rig of `tests.rigs.RIGS`
(plus `composite`) and every convention of `tests.conventions.CONVENTIONS` (Bandai clips: the
rewrites that do not key on CMU joint names), and resampled to 30, 60 and 120 fps on its own rig
(`tests.rigs.resample`: slerp of the joint rotations). Each variant is measured with
`experiments.footlock_bounds.measure` (fit N = 4 Euler, 5 s of foot-locked synthesis, written
as BVH, independent FK): skating ratio, depth below the floor, largest knee step against the
capture's, flight fraction synthesized and captured. With ``--cli``, the user's defaults:
``fourierjax fit`` then ``fourierjax synth --seconds 5`` as subprocesses on a few rigs, the
written BVH measured the same way. Every row is compared with its clip's original-rig row.
Writes ``rows.json`` and ``table.md`` under ``--out``.

Measured (rig10, N = 4 Euler, 5 s): renames, units, a root joint above the pelvis and the BVH
round trip change the figures by at most 1.7e-4 in the skating ratio (after the body height
stopped counting the pelvis's ancestors: Unreal's 02_01 read 0.1343x against 0.1317x). Rigs that
change the joint frames (Blender's bones along Y, Z up, Bandai's ZXY along X, large rest
rotations, Daz's bend/twist split) change the Euler fit, so the figures move by up to 0.06
(rest-rotated 02_01: 0.1893x, knee step 5.90 against the capture's 3.49 deg); the tangent
representation (the command line's default) gives the CMU rig's figures on all of them but
Daz's split bones (02_01: 0.1318x against 0.1306x). Frame rate: the lock's easing is
``round(0.04 s / frame time)`` frames, 1 at 30 fps, and 02_01 at 30 fps popped the knee
(16.69 against 13.13 deg), 02_03 at 60 fps read 0.258x, Bandai-1 run_happy met all three
bounds at 60 fps (0.2145x) but not at its own 30 fps (0.3095x, flight 28.7% against 17.3%).
Since session 30 `synthesize_gait` locks on frames near 120 fps (`gait.lock_supersampling`) and
decimates: 02_01 at 30 fps 0.164x, knee 9.35 deg; 02_03 at 30 fps 0.242x, flight 15% against
16%; Bandai-1 run_happy 0.246x at its own 30 fps.
Usage:
``python -m experiments.footlock_rigs [--out DIR] [--clips 02_01,...] [--rigs a,b] [--fps 30,60,120]
[--cli] [--rep euler|tangent] [--seconds S]``.
"""

from __future__ import annotations

import argparse
import json
import pathlib
import subprocess
import sys
import time

import numpy as np

from experiments.footlock_bounds import BANDAI

CMU_CLIPS = ("02_01", "02_03")
BANDAI_CLIPS = ("walk_normal", "run_normal", "run_happy")
#: Rewrites that hold on any rig (no CMU joint names needed): used on the Bandai clips too.
GENERIC = ("blender", "rest_rotated", "zup", "metres", "scrambled")
CLI_RIGS = ("original", "mixamo", "zup", "metres", "bandai")
#: The figures compared across rigs, and what counts as float32 noise in each (absolute).
FIGURES = {"ratio": 2e-3, "skating_synth_mps": 2e-4, "skating_capture_mps": 2e-4, "depth_m": 2e-4,
           "knee_step_synth_deg": 0.05, "knee_step_capture_deg": 0.05, "flight_synth": 0.005,
           "flight_capture": 0.005}


def clips(names=None) -> dict:
    """name -> Motion: the CMU clips, and the Bandai ones when the dataset is present."""
    from fourierjax import data
    from fourierjax.io.bvh import read_bvh

    out = {}
    for n in names or (*CMU_CLIPS, *BANDAI_CLIPS):
        if n in BANDAI_CLIPS:
            f = BANDAI / f"dataset-1_{n}_001.bvh"
            if f.is_file():
                out[n] = read_bvh(f)
        else:
            out[n] = data.load(n)
    return out


def rig_names(clip: str) -> tuple[str, ...]:
    from tests.conventions import CONVENTIONS
    from tests.rigs import RIGS

    if clip in BANDAI_CLIPS:
        return GENERIC
    return (*RIGS, "composite", *CONVENTIONS)


def rewrite(motion, rig: str, clip: str):
    """`motion` in `rig`, as read by a user (a Z-up rig turned Y-up, as the Python API asks)."""
    from fourierjax.io.axes import to_y_up
    from tests import conventions, rigs

    if rig == "metres" and clip in BANDAI_CLIPS:
        return conventions.scale_units(motion, 0.01)  # Bandai-1 is in centimetres
    if rig == "zup":
        return to_y_up(conventions.convert(motion, "zup"), "z")
    if rig in ("scrambled",):
        return conventions.convert(motion, rig)
    if rig == "composite":
        return rigs.composite(motion)
    if rig in rigs.RIGS:
        return rigs.RIGS[rig](motion)
    return conventions.convert(motion, rig)


def _round_trip(motion):
    """`motion` written as BVH text and read back (what every user's file goes through)."""
    import tempfile

    from fourierjax.io.bvh import read_bvh, write_bvh

    with tempfile.TemporaryDirectory() as d:
        f = pathlib.Path(d) / "m.bvh"
        write_bvh(motion, f)
        return read_bvh(f)


def measure_variants(variants: dict, harmonics: int, rep: str, seconds: float, log=print) -> dict:
    """key -> figures of `measure` (plus m/s skating and the fit's body map facts) for each Motion."""
    from experiments.footlock_bounds import measure
    from fourierjax import motion as M

    keys = list(variants)
    fits = M.fit_motions([variants[k] for k in keys], harmonics, rep)
    out = {}
    for k, f in zip(keys, fits, strict=True):
        t0 = time.process_time()
        if not f.successful:
            out[k] = {"error": f.message}
            log(f"{k}: {f.message}", flush=True)
            continue
        try:
            r = measure(variants[k], f, seconds=seconds)
        except Exception as e:  # a row, not the run, dies
            out[k] = {"error": f"{type(e).__name__}: {e}"}
            log(f"{k}: {out[k]['error']}", flush=True)
            continue
        r.pop("result"), r.pop("motion")
        mpu = float(f.body_map.metres_per_unit)
        r["skating_synth_mps"] = r["skating_synth"] * mpu
        r["skating_capture_mps"] = r["skating_capture"] * mpu
        r["metres_per_unit"] = mpu
        r["frames"] = [int(f.frame_start), int(f.frame_stop)]
        r["omega"] = float(f.model.omega)
        r["cpu_s"] = round(time.process_time() - t0, 1)
        out[k] = r
        log(f"{k}: " + _line(r), flush=True)
    return out


def _line(r: dict) -> str:
    if "error" in r:
        return r["error"]
    return (f"ratio {r['ratio']:.4f} ({r['skating_synth_mps']:.4f} vs {r['skating_capture_mps']:.4f} m/s) "
            f"below {100 * r['depth_m']:.3f} cm  knee {r['knee_step_synth_deg']:.2f} vs "
            f"{r['knee_step_capture_deg']:.2f} deg  flight {100 * r['flight_synth']:.1f}% vs "
            f"{100 * r['flight_capture']:.1f}%")


def compare(row: dict, base: dict) -> dict:
    """figure -> row - base, for the figures of `FIGURES`; and which exceed the noise."""
    if "error" in row or "error" in base:
        return {"beyond": ["error"]}
    d = {k: row[k] - base[k] for k in FIGURES}
    d["beyond"] = [k for k, tol in FIGURES.items() if abs(d[k]) > tol]
    return d


def cli_rows(motions: dict, rigs, out: pathlib.Path, seconds: float, log=print) -> dict:
    """(clip, rig) -> the user's defaults: `fourierjax fit` (default representation and N) then
    `fourierjax synth --seconds`, as subprocesses; the written BVH (turned Y-up) measured with the
    same metric: skating against the fitted capture frames, depth of each foot point below its
    resting height in the capture (5th percentile), knee steps, flight fraction."""
    from fourierjax.io.axes import to_y_up
    from fourierjax.io.bvh import read_bvh, write_bvh
    from tests import conventions

    res = {}
    for rig in rigs:
        d = out / "cli" / rig
        d.mkdir(parents=True, exist_ok=True)
        files = {}
        for clip, m in motions.items():
            bandai = clip in BANDAI_CLIPS
            if bandai and rig in ("mixamo", "bandai"):  # CMU names only (a Bandai clip is the bandai rig)
                continue
            if rig == "original":
                v = m
            elif rig == "metres" and bandai:
                v = conventions.scale_units(m, 0.01)
            else:
                v = conventions.convert(m, rig)
            files[clip] = d / f"{clip}.bvh"
            write_bvh(v, files[clip])
        if not files:
            continue
        env_cmd = [sys.executable, "-m", "fourierjax"]
        p = subprocess.run([*env_cmd, "fit", *[f.name for f in files.values()], "--out", "m/", "--json"], cwd=d,
                           capture_output=True, text=True)
        if p.returncode:
            for clip in files:
                res[(clip, rig)] = {"error": f"fit exit {p.returncode}: {p.stderr.strip()[-300:]}"}
            continue
        used = {pathlib.Path(r["file"]).stem: r["frames_used"] for r in json.loads(p.stdout)}
        for clip, f in files.items():
            s = subprocess.run([*env_cmd, "synth", f"m/{f.stem}.npz", "--seconds", str(seconds), "--out",
                                f"{f.stem}_synth.bvh"], cwd=d, capture_output=True, text=True)
            if s.returncode:
                res[(clip, rig)] = {"error": f"synth exit {s.returncode}: {s.stderr.strip()[-300:]}"}
                continue
            src, syn = read_bvh(f), read_bvh(d / f"{f.stem}_synth.bvh")
            if rig == "zup":
                src, syn = to_y_up(src, "z"), to_y_up(syn, "z")
            r = measure_files(src, syn, used[f.stem])
            r["printed"] = next((ln.strip() for ln in s.stdout.splitlines() if "skating" in ln), "")
            res[(clip, rig)] = r
            log(f"cli {clip} {rig}: " + _line(r), flush=True)
    return res


def measure_files(source, synth, frames) -> dict:
    """The #21 figures of a synthesized Motion against its source clip's fitted `frames`
    (`[start, stop)` of the file, as `fit --json` reports them)."""
    from fourierjax import contacts, gait
    from fourierjax import motion as M
    from fourierjax.body import infer_body_map

    bm = infer_body_map(source)
    a, b = frames
    sub = source[a:b]
    dt = source.frame_time_s
    p_syn = M.foot_positions_of(synth, body_map=bm)
    p_cap = M.foot_positions_of(sub, body_map=bm)
    s_syn = float(gait.contact_skating(p_syn, synth.frame_time_s, body_map=bm).mean_speed)
    s_cap = float(gait.contact_skating(p_cap, dt, body_map=bm).mean_speed)
    up = int(bm.up_axis)
    rest = np.percentile(p_cap[..., up], 5.0, axis=0)  # [2, P]
    depth = max(0.0, -float((p_syn[..., up] - rest[None]).min())) * bm.metres_per_unit
    ground = contacts.estimate_ground(p_cap, dt, up_axis=up)
    f_cap = float(gait.contact_flight_fraction(p_cap, body_map=bm,
                                               floor=contacts.floor_heights(ground, p_cap, up_axis=up)))
    f_syn = float(gait.contact_flight_fraction(p_syn, body_map=bm, floor=rest[None]))
    k_syn = np.abs(np.diff(gait.knee_angles(M.motion_joint_positions(synth), bm), axis=0)).max()
    k_cap = np.abs(np.diff(gait.knee_angles(M.motion_joint_positions(sub), bm), axis=0)).max()
    mpu = float(bm.metres_per_unit)
    return {"skating_synth": s_syn, "skating_capture": s_cap, "ratio": s_syn / s_cap, "depth_m": depth,
            "knee_step_synth_deg": float(np.degrees(k_syn)), "knee_step_capture_deg": float(np.degrees(k_cap)),
            "flight_synth": f_syn, "flight_capture": f_cap, "skating_synth_mps": s_syn * mpu,
            "skating_capture_mps": s_cap * mpu, "metres_per_unit": mpu, "frames": [a, b]}


def table(rows: list[dict]) -> str:
    """Markdown: clip x variant -> the #21 figures, and the difference from the original rig's row."""
    lines = ["| clip | variant | ratio | synth / capture skating (mm/s) | below (cm) | knee step synth / capture "
             "(deg) | flight synth / capture (%) | beyond noise vs original |", "|" + "---|" * 8]
    for r in rows:
        if "error" in r:
            lines.append(f"| {r['clip']} | {r['variant']} | error: {r['error'][:120]} |||||| |")
            continue
        beyond = ", ".join(f"{k} {r['diff'][k]:+.4g}" for k in r.get("diff", {}).get("beyond", [])
                           if k in r["diff"]) or ("—" if "diff" in r else "(reference)")
        lines.append(
            f"| {r['clip']} | {r['variant']} | {r['ratio']:.4f} | {1e3 * r['skating_synth_mps']:.2f} / "
            f"{1e3 * r['skating_capture_mps']:.2f} | {100 * r['depth_m']:.3f} | {r['knee_step_synth_deg']:.2f} / "
            f"{r['knee_step_capture_deg']:.2f} | {100 * r['flight_synth']:.1f} / {100 * r['flight_capture']:.1f} | "
            f"{beyond} |")
    return "\n".join(lines)


def main(argv=None) -> int:
    p = argparse.ArgumentParser(prog="python -m experiments.footlock_rigs", description=__doc__.splitlines()[0])
    p.add_argument("--out", default="out/experiments/footlock_rigs")
    p.add_argument("--clips", default=None, help="comma-separated (default: CMU 02_01, 02_03 and the Bandai ones)")
    p.add_argument("--rigs", default=None, help="comma-separated subset of the rigs (default: all that apply)")
    p.add_argument("--fps", default="30,60,120")
    p.add_argument("--rep", default="euler", help="representation of the Python fits (#21: euler)")
    p.add_argument("--harmonics", type=int, default=4)
    p.add_argument("--seconds", type=float, default=5.0)
    p.add_argument("--cli", action="store_true", help="also the command line's defaults on " + ", ".join(CLI_RIGS))
    p.add_argument("--no-python", action="store_true", help="only the command-line rows")
    a = p.parse_args(argv)
    from tests.rigs import resample

    out = pathlib.Path(a.out).resolve()
    out.mkdir(parents=True, exist_ok=True)
    motions = clips(a.clips.split(",") if a.clips else None)
    only = set(a.rigs.split(",")) if a.rigs else None
    fps = [float(x) for x in a.fps.split(",") if x]
    rows = []

    def save():
        (out / "rows.json").write_text(json.dumps(rows, indent=1))
        (out / "table.md").write_text(table(rows) + "\n")

    t0 = time.perf_counter()
    for clip, m in motions.items() if not a.no_python else ():
        variants = {"original": m}
        for rig in rig_names(clip):
            if only is None or rig in only:
                variants[rig] = rewrite(m, rig, clip)
        src_fps = 1.0 / m.frame_time_s
        for f in fps:
            variants[f"{f:g} fps"] = resample(m, f)
        variants["original (BVH round trip)"] = _round_trip(m)
        got = measure_variants(variants, a.harmonics, a.rep, a.seconds)
        base = got["original"]
        for k, r in got.items():
            row = {"clip": clip, "variant": k, "kind": "fps" if k.endswith(" fps") else "rig",
                   "source_fps": round(src_fps, 3), **r}
            if k != "original":
                row["diff"] = compare(r, base)
            rows.append(row)
        save()
        print(f"{clip} done, {time.perf_counter() - t0:.0f} s", flush=True)
    if a.cli:
        motions_cli = {k: v for k, v in motions.items()}
        got = cli_rows(motions_cli, CLI_RIGS, out, a.seconds)
        for clip in motions_cli:
            ref = got.get((clip, "original"))
            for rig in CLI_RIGS:
                if (clip, rig) not in got:
                    continue
                r = got[(clip, rig)]
                row = {"clip": clip, "variant": f"cli {rig}", "kind": "cli", **r}
                if ref is not None and r is not ref:
                    row["diff"] = compare(r, ref)
                rows.append(row)
        save()
    print(table(rows))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
