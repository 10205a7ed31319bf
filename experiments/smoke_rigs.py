"""A new user's smoke test of the command line on CMU walks and runs rewritten into other rigs.

Each rig (`tests.conventions`, `tests.rigs`) gets the CMU walk 02_01 and run 02_03 written as BVH
files, then `fourierjax info / fit / synth (straight, circle:3, with a characteristic) /
interpolate / characteristic / transition / plot stick` run as subprocesses, the way a user types
them, with the default representation (tangent) and `fit --representation euler` for comparison.
Per command: exit code, a one-line error, no traceback, no NaN. Per synthesized BVH (numpy FK of
the written file, independent of the library's): root advance along the body's facing (as a
ratio of the CMU original's), its alignment with the facing, the turn radius on a circle
(metres), the lowest foot point over the captured floor (cm), and the printed foot skating.
Then, with ``--awkward``, inputs a user brings (`awkward_rows`). Not run by the test suite (about
15 minutes for every rig on 2 busy cores). Usage:
``python -m experiments.smoke_rigs [--rigs a,b] [--out DIR] [--reps tangent,euler] [--awkward]``.
"""

from __future__ import annotations

import argparse
import json
import pathlib
import re
import subprocess
import sys
import time

import numpy as np

RIGS = ("cmu", "bandai", "biped", "blender", "daz", "genesis8", "lafan", "max", "metres", "mixamo", "no_toes",
        "rest_rotated", "smpl", "unreal", "zup", "scrambled", "composite")
CLIPS = {"walk": "02_01", "run": "02_03"}


def rewrite(motion, rig: str):
    """`motion` (a CMU clip) as `rig` writes it (a Z-up rig stays Z-up: the file a Blender user has)."""
    from tests import rigs
    from tests.conventions import CONVENTIONS, convert

    if rig == "cmu":
        return motion
    if rig == "composite":
        return rigs.composite(motion)
    if rig in rigs.RIGS:
        return rigs.RIGS[rig](motion)
    assert rig in CONVENTIONS, rig
    return convert(motion, rig)


def cli(args: list[str], cwd: pathlib.Path) -> dict:
    """Run `fourierjax ARGS` as a user does: exit code, stdout, whether stderr is one clean line."""
    t0 = time.perf_counter()
    p = subprocess.run([sys.executable, "-m", "fourierjax", *args], cwd=cwd, capture_output=True, text=True)
    err = p.stderr.strip()
    lines = [ln for ln in err.splitlines() if ln.strip() and not ln.startswith("usage:")
             and not ln.startswith(" ")]
    bad = []
    if "Traceback" in err:
        bad.append("traceback")
    if p.returncode != 0 and len(lines) != 1:
        bad.append(f"{len(lines)} error lines")
    if re.search(r"\bnan\b", p.stdout + err, re.IGNORECASE):
        bad.append("nan printed")
    return {"args": args, "rc": p.returncode, "out": p.stdout, "err": err, "bad": bad,
            "s": round(time.perf_counter() - t0, 1)}


def _world(motion):
    from tests.rigs import world

    P, E, _ = world(motion)
    return np.concatenate([P, E], axis=1)


def _heights(motion, bm):
    """Per-frame lowest foot point (file units, along up) and the trajectory, facing per frame."""
    pts = _world(motion)
    up = np.zeros(3)
    up[bm.up_axis] = bm.up_sign
    feet = list(bm.feet[0]) + list(bm.feet[1])
    low = (pts[:, feet] @ up).min(axis=1)
    hips = pts[:, bm.left.hip] - pts[:, bm.right.hip]
    face = np.cross(hips, up)
    face -= np.outer(face @ up, up)
    face /= np.linalg.norm(face, axis=1, keepdims=True)
    root = pts[:, bm.trajectory]
    return low, root - np.outer(root @ up, up), face


def measure(path: pathlib.Path, floor: float, bm, frame_time_s: float, *, z_up: bool = False) -> dict:
    """Advance along the facing, its alignment, turn radius, lowest foot over `floor` (cm), NaN check.
    ``z_up``: the file is Z-up (the commands write a Z-up input's outputs Z-up); it is turned Y-up,
    as the sources were, before it is measured with their Y-up body map ``bm``."""
    from fourierjax.io.axes import to_y_up
    from fourierjax.io.bvh import read_bvh

    m = read_bvh(path)
    if z_up:
        m = to_y_up(m, "z")
    if not np.isfinite(m.channels).all():
        return {"nan": True}
    if tuple(m.topology.names) != tuple(bm.joint_names):
        return {"error": "output skeleton differs from the input's"}
    low, root, face = _heights(m, bm)
    cm = 100.0 * bm.metres_per_unit
    disp = root[-1] - root[0]
    mface = face.mean(axis=0)
    mface /= np.linalg.norm(mface)
    k = max(1, int(round(0.5 / frame_time_s)))
    vel = root[2 * k:] - root[:-2 * k]
    speed = np.linalg.norm(vel, axis=1)
    cosf = (vel * face[k:-k]).sum(axis=1) / np.maximum(speed, 1e-12)
    length = float(np.linalg.norm(np.diff(root, axis=0), axis=1).sum())
    up = np.zeros(3)
    up[bm.up_axis] = bm.up_sign
    ang = np.arctan2(np.cross(face[:-1], face[1:]) @ up, (face[:-1] * face[1:]).sum(axis=1))
    turn = float(np.abs(ang.sum()))
    xy = np.delete(root, bm.up_axis, axis=1)
    # Kasa's circle fit: x^2 + y^2 = 2 a x + 2 b y + c, radius sqrt(c + a^2 + b^2).
    (ca, cb, cc), *_ = np.linalg.lstsq(np.c_[2 * xy, np.ones(len(xy))], (xy ** 2).sum(axis=1), rcond=None)
    return {
        "advance": float(disp @ mface), "path_len": length,
        "forward_cos_min": float(cosf.min()) if len(cosf) else float("nan"),
        "radius_m": float(np.sqrt(cc + ca ** 2 + cb ** 2)) * bm.metres_per_unit if turn > 0.5 else None,
        "low_min_cm": float((low.min() - floor) * cm), "low_med_cm": float((np.median(low) - floor) * cm),
    }


def _skating(text: str):
    m = re.search(r"foot skating ([\d.]+) \S+ against ([\d.]+)", text)
    return (float(m.group(1)), float(m.group(2))) if m else (None, None)


def _fit_table(text: str) -> dict:
    out = {}
    for line in text.splitlines():
        parts = line.split()
        if parts and parts[0].endswith(".bvh") and len(parts) >= 9:
            out[pathlib.Path(parts[0]).stem.split("_")[-1]] = {"f_fit": float(parts[4]), "rms_deg": float(parts[5]),
                                                               "ve_pos": parts[7]}
    return out


def smoke_rig(rig: str, root: pathlib.Path, reps, log=print) -> list[dict]:
    from fourierjax import data
    from fourierjax.body import infer_body_map
    from fourierjax.io.bvh import read_bvh, write_bvh

    d = root / rig
    d.mkdir(parents=True, exist_ok=True)
    files = {}
    for kind, clip in CLIPS.items():
        files[kind] = d / f"{rig}_{kind}.bvh"
        write_bvh(rewrite(data.load(clip), rig), files[kind])
    src = {k: read_bvh(f) for k, f in files.items()}
    if rig == "zup":  # measured Y-up: the sources here, the commands' Z-up outputs in `measure`
        from fourierjax.io.axes import to_y_up

        src = {k: to_y_up(m, "z") for k, m in src.items()}
    bm = infer_body_map(src["walk"])
    # The captured floor: where the lowest foot point is at its lowest (2nd percentile of frames).
    floor = {k: float(np.percentile(_heights(m, bm)[0], 2)) for k, m in src.items()}
    dt = src["walk"].frame_time_s
    rows = []

    def run(name, args, measure_out=None, kind="walk", rep="tangent"):
        r = cli(args, d)
        row = {"rig": rig, "rep": rep, "cmd": name, "rc": r["rc"], "bad": ";".join(r["bad"]), "s": r["s"],
               "metres_per_unit": bm.metres_per_unit,
               "msg": (r["err"].splitlines() or [""])[-1][:160] if r["rc"] else ""}
        if name.startswith("synth"):
            row["skate_synth"], row["skate_capture"] = _skating(r["out"])
        if r["rc"] == 0 and measure_out:
            row.update(measure(d / measure_out, floor[kind], bm, dt, z_up=rig == "zup"))
        if name.startswith("fit"):
            row["fit"] = _fit_table(r["out"])
        log(json.dumps(row), flush=True)
        rows.append(row)
        return row

    run("info", ["info", files["walk"].name])
    for rep in reps:
        m = f"m_{rep}"
        w, r_ = f"{m}/{rig}_walk.npz", f"{m}/{rig}_run.npz"
        fit = ["fit", files["walk"].name, files["run"].name, "--harmonics", "3", "--out", f"{m}/"]
        if rep != "tangent":
            fit += ["--representation", rep]
        run("fit", fit, rep=rep)
        run("synth walk", ["synth", w, "--seconds", "4", "--out", f"{rep}_synth_walk.bvh"],
            f"{rep}_synth_walk.bvh", rep=rep)
        run("synth run", ["synth", r_, "--seconds", "4", "--out", f"{rep}_synth_run.bvh"],
            f"{rep}_synth_run.bvh", kind="run", rep=rep)
        run("transition", ["transition", w, r_, "--seconds", "6", "--start", "2", "--duration", "2",
                           "--out", f"{rep}_trans.bvh"], f"{rep}_trans.bvh", rep=rep)
        if rep != "tangent":
            continue
        run("synth circle:3", ["synth", w, "--seconds", "6", "--path", "circle:3", "--out", "circle.bvh"],
            "circle.bvh", rep=rep)
        run("interpolate", ["interpolate", w, r_, "--s", "0.5", "--seconds", "4", "--out", "interp.bvh"],
            "interp.bvh", rep=rep)
        run("characteristic", ["characteristic", r_, w, "--out", "runness.npz"], rep=rep)
        run("synth --add", ["synth", w, "--seconds", "4", "--add", "runness.npz=0.5", "--out", "add.bvh"],
            "add.bvh", rep=rep)
        run("plot stick", ["plot", "stick", w, "--out", "stick.png"], rep=rep)
    return rows


def _upper_body(motion):
    """`motion` without its legs (an arm-only rig)."""
    from tests.rigs import _Rig

    rig = _Rig.of(motion)
    for side in ("Left", "Right"):
        for part in ("ToeBase", "Foot", "Leg", "UpLeg"):
            rig.drop_leaf(f"{side}{part}", end_site=False)
        rig.drop_leaf(f"{side[0]}HipJoint", end_site=False)
    return rig.motion()


def awkward_rows(root: pathlib.Path, log=print) -> list[dict]:
    """What a user brings: a clip shorter than a cycle, no legs, 60 and 30 fps, mixed
    representations, models of other rigs or units, Z-up BVH arguments. Each row: the command,
    its exit code, the expected one, and the error line. Run after `smoke_rig` for cmu, metres,
    bandai and zup (their models and files under `root`)."""
    import dataclasses

    from fourierjax import data
    from fourierjax.io.bvh import write_bvh

    d = root / "awkward"
    d.mkdir(parents=True, exist_ok=True)
    w, r = data.load("02_01"), data.load("02_03")
    write_bvh(w[:60], d / "short.bvh")
    write_bvh(_upper_body(w), d / "upper.bvh")
    write_bvh(dataclasses.replace(w, channels=w.channels[::2], frame_time_s=2 * w.frame_time_s), d / "walk60.bvh")
    write_bvh(dataclasses.replace(r, channels=r.channels[::4], frame_time_s=4 * r.frame_time_s), d / "run30.bvh")
    t, e = root / "cmu" / "m_tangent", root / "cmu" / "m_euler"
    trans = ["--seconds", "6", "--start", "2", "--duration", "2"]
    cases = [
        ("short clip", ["fit", "short.bvh", "--out", "m/"], 2),
        ("no legs", ["fit", "upper.bvh", "--out", "m/"], 2),
        ("60 and 30 fps", ["fit", "walk60.bvh", "run30.bvh", "--harmonics", "3", "--out", "m/"], 0),
        ("60 fps synth", ["synth", "m/walk60.npz", "--seconds", "4", "--out", "w60.bvh"], 0),
        ("30 fps synth", ["synth", "m/run30.npz", "--seconds", "4", "--out", "r30.bvh"], 0),
        ("60 -> 30 fps transition", ["transition", "m/walk60.npz", "m/run30.npz", *trans, "--out", "t.bvh"], 0),
        ("euler -> tangent", ["transition", str(e / "cmu_walk.npz"), str(t / "cmu_run.npz"), *trans,
                              "--out", "t.bvh"], 2),
        ("euler + tangent characteristic", ["synth", str(e / "cmu_walk.npz"), "--seconds", "2", "--add",
                                            f"{root / 'cmu' / 'runness.npz'}=0.5", "--out", "a.bvh"], 2),
        ("cmu x bandai rig", ["interpolate", str(t / "cmu_walk.npz"),
                              str(root / "bandai" / "m_tangent" / "bandai_run.npz"), "--s", "0.5",
                              "--out", "i.bvh"], 2),
        ("cmu units x metres", ["interpolate", str(t / "cmu_walk.npz"),
                                str(root / "metres" / "m_tangent" / "metres_run.npz"), "--s", "0.5",
                                "--out", "i.bvh"], 2),
        ("Z-up BVH arguments", ["transition", str(root / "zup" / "zup_walk.bvh"), str(root / "zup" / "zup_run.bvh"),
                                "--harmonics", "3", *trans, "--out", "t.bvh"], 0),
    ]
    rows = []
    for name, args, want in cases:
        res = cli(args, d)
        row = {"case": name, "rc": res["rc"], "expected": want, "bad": ";".join(res["bad"]),
               "msg": (res["err"].splitlines() or [""])[-1][:200] if res["rc"] else ""}
        log(json.dumps(row), flush=True)
        rows.append(row)
    return rows


def table(rows: list[dict]) -> str:
    """Markdown: rig x command -> exit, skating synth/capture (CMU units/s), root advance against
    the CMU original's same command, lowest foot point over the captured floor (min / median, cm)."""
    ref = {(r["rep"], r["cmd"]): r for r in rows if r["rig"] == "cmu"}
    lines = ["| rig | rep | command | exit | skating synth/capture | advance / CMU | forward cos min | "
             "lowest foot min / median (cm) | radius (m) |", "|" + "---|" * 9]
    for r in rows:
        k = r["metres_per_unit"] / 0.0564
        skate = (f"{r['skate_synth'] * k:.2f} / {r['skate_capture'] * k:.2f}"
                 if r.get("skate_synth") is not None else "")
        c = ref.get((r["rep"], r["cmd"]), {})
        adv = f"{r['advance'] * r['metres_per_unit'] / (c['advance'] * c['metres_per_unit']):.4f}" \
            if "advance" in r and "advance" in c else ""
        low = f"{r['low_min_cm']:+.2f} / {r['low_med_cm']:+.2f}" if "low_min_cm" in r else ""
        cos = f"{r['forward_cos_min']:.3f}" if "forward_cos_min" in r else ""
        rad = f"{r['radius_m']:.3f}" if r.get("radius_m") else ""
        ex = f"{r['rc']}{' ' + r['bad'] if r['bad'] else ''}{' ' + r['msg'] if r['msg'] else ''}"
        lines.append(f"| {r['rig']} | {r['rep']} | {r['cmd']} | {ex} | {skate} | {adv} | {cos} | {low} | {rad} |")
    return "\n".join(lines)


def main(argv=None) -> int:
    p = argparse.ArgumentParser(prog="python -m experiments.smoke_rigs", description=__doc__.splitlines()[0])
    p.add_argument("--rigs", default=",".join(RIGS))
    p.add_argument("--reps", default="tangent,euler")
    p.add_argument("--out", default="out/experiments/smoke_rigs")
    p.add_argument("--awkward", action="store_true", help="then the awkward inputs (needs the cmu, metres, "
                   "bandai and zup rigs in --rigs or already under --out)")
    a = p.parse_args(argv)
    out = pathlib.Path(a.out).resolve()
    out.mkdir(parents=True, exist_ok=True)
    rows = []
    for rig in [x for x in a.rigs.split(",") if x]:  # --rigs "": the awkward inputs alone
        rows += smoke_rig(rig, out, a.reps.split(","))
        (out / "rows.json").write_text(json.dumps(rows, indent=1))
    if rows:
        (out / "table.md").write_text(table(rows) + "\n")
    if a.awkward:
        awk = awkward_rows(out)
        (out / "awkward.json").write_text(json.dumps(awk, indent=1))
        return int(any(r["rc"] != r["expected"] or r["bad"] for r in awk))
    return 0


if __name__ == "__main__":
    sys.exit(main())
