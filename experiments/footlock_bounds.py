"""Issue #21 foot-lock bounds on walks and runs: skating ratio, depth below the floor, knee steps.

Fits each clip (N = 4, Euler), synthesizes 5 s with foot locking, writes it as a BVH motion and
measures it with an independent FK of that motion (`motion_joint_positions`): skating of the
synthesized motion against the captured clip's (`gait.contact_skating`, target <= 0.25x), the
depth of the lowest foot point below the floor (target <= 0.5 cm) and the largest
frame-to-frame knee change (target <= the capture's). Usage:
``python -m experiments.footlock_bounds [--bandai] [--path circle:3] [--breakdown] [CLIP ...]``.
"""

from __future__ import annotations

import argparse
import json
import pathlib
import time

import numpy as np

BUNDLED = ("02_01", "02_03", "07_01", "07_04", "07_12", "09_01", "09_02")
BANDAI = pathlib.Path(__file__).resolve().parents[1] / ".." / "shared" / "data" / "mocap" / "bandai1" / "data"
STYLES = ("active", "angry", "childish", "chimpira", "feminine", "giant", "happy", "masculinity", "musical",
          "normal", "not-confident", "old", "proud", "sad", "tired")


def measure(mot, fit, *, foot_lock=True, seconds=5.0, path=None, knee_cap=True, frame_time_s=None):
    """dict: skating synthesized and captured (units/s), depth below the floor (m), largest knee
    step synthesized and captured (degrees), the most straight knee (degrees) and the flight
    fraction synthesized and captured (`gait.contact_flight_fraction`; the capture on its fitted
    ground plane, `contacts.estimate_ground`) of a clip's
    locked synthesis, through an independent FK of the written motion. `path` (a `GroundPath`)
    walks it along the path (`gait.synthesize_gait(path=...)`). `knee_cap` passes the capture's
    largest knee speed (`gait.fit_knee_speed`) to the lock; `frame_time_s` synthesizes at another
    frame rate than the clip's (the capture is measured at its own)."""
    from fourierjax import gait
    from fourierjax import motion as M
    from fourierjax.io.gait_bvh import gait_motion, grounded_motion

    bm, dt_cap = fit.body_map, mot.frame_time_s
    dt = dt_cap if frame_time_s is None else float(frame_time_s)
    sub = mot[fit.frame_start:fit.frame_stop]
    iv = gait.contact_intervals(fit.model, mot.skeleton(), body_map=bm, contacts=M.foot_contacts_of(sub, body_map=bm),
                                frame_time_s=dt_cap, phase_shift=fit.phase_shift)
    T = int(round(seconds / dt))
    kw = {} if path is None else {"path": path}
    if knee_cap:
        kw["knee_speed_rad_s"] = gait.fit_knee_speed(fit, mot)
    r = gait.synthesize_gait(fit.model, mot.skeleton(), T, dt, body_map=bm, contact_intervals=iv,
                             foot_lock=foot_lock, **kw)
    if path is None:
        out = gait_motion(mot, r, fit.model.channel_names, dt, body_map=bm)
    else:
        out = grounded_motion(mot, r.features, r.root_position, fit.model.channel_names, dt, body_map=bm)
    p_syn = M.foot_positions_of(out, body_map=bm)
    p_cap = M.foot_positions_of(sub, body_map=bm)
    s_syn = float(gait.contact_skating(p_syn, dt, body_map=bm).mean_speed)
    s_cap = float(gait.contact_skating(p_cap, dt_cap, body_map=bm).mean_speed)
    low = p_syn[..., bm.up_axis] - np.asarray(r.clearance)[None] - float(r.floor)  # over the captured floor
    depth_m = max(0.0, -float(low.min())) * bm.metres_per_unit
    from fourierjax import contacts

    ground = contacts.estimate_ground(p_cap, dt_cap, up_axis=bm.up_axis)
    f_cap = float(gait.contact_flight_fraction(p_cap, body_map=bm,
                                               floor=contacts.floor_heights(ground, p_cap, up_axis=bm.up_axis)))
    f_syn = float(gait.contact_flight_fraction(p_syn, body_map=bm,
                                               floor=float(r.floor) + np.asarray(r.clearance)[None]))
    ka_syn = gait.knee_angles(M.motion_joint_positions(out), bm)
    k_syn = np.abs(np.diff(ka_syn, axis=0)).max()
    # The capture's largest knee speed, as a step at the synthesized frame rate.
    k_cap = np.abs(np.diff(gait.knee_angles(M.motion_joint_positions(sub), bm), axis=0)).max() * dt / dt_cap
    return {"skating_synth": s_syn, "skating_capture": s_cap, "ratio": s_syn / s_cap, "depth_m": depth_m,
            "knee_step_synth_deg": float(np.degrees(k_syn)), "knee_step_capture_deg": float(np.degrees(k_cap)),
            "straightest_knee_deg": float(np.degrees(ka_syn.max())), "flight_synth": f_syn, "flight_capture": f_cap,
            "result": r, "motion": out}


def skating_breakdown(positions, frame_time_s, body_map):
    """`[P, 3]` each foot point's share of `gait.contact_skating`'s mean speed (file units / s,
    summing to it), by the part of its run of contact frames: the first quarter (landing), the
    middle half, the last quarter (release); both feet together. Same contact rule (each point's
    5th-percentile height as its floor, 2% of the body height)."""
    from fourierjax.contacts import point_speeds

    p = np.asarray(positions)
    y = p[..., body_map.up_axis] * body_map.up_sign
    on = (y - np.percentile(y, 5.0, axis=0)[None]) < 0.02 * float(body_map.height)
    v = np.asarray(point_speeds(p, frame_time_s, up_axis=int(body_map.up_axis)))
    T, _, P = on.shape
    out = np.zeros((P, 3))
    for f in range(2):
        for q in range(P):
            o = np.concatenate([[False], on[:, f, q], [False]])
            starts, stops = np.flatnonzero(o[1:] & ~o[:-1]), np.flatnonzero(~o[1:] & o[:-1])
            for a, b in zip(starts, stops, strict=True):
                k = np.arange(b - a)
                part = np.where(k < (b - a) / 4, 0, np.where(k >= 3 * (b - a) / 4, 2, 1))
                np.add.at(out[q], part, v[a:b, f, q])
    return out / max(int(on.sum()), 1)


def met(row) -> bool:
    return (row["ratio"] <= 0.25 and row["depth_m"] <= 0.005
            and row["knee_step_synth_deg"] <= row["knee_step_capture_deg"])


def fits_of(names, harmonics=4, cache=None):
    """(motions, fits) of the clips; `cache` a folder for pickled fits (development)."""
    import pickle

    from fourierjax import data
    from fourierjax import motion as M
    from fourierjax.io.bvh import read_bvh

    motions = [read_bvh(n) if str(n).endswith(".bvh") else data.load(n) for n in names]
    if cache is None:
        return motions, M.fit_motions(motions, harmonics)
    files = [pathlib.Path(cache) / f"{pathlib.Path(n).stem}_N{harmonics}.pkl" for n in names]
    todo = [i for i, f in enumerate(files) if not f.is_file()]
    if todo:
        for i, fit in zip(todo, M.fit_motions([motions[i] for i in todo], harmonics), strict=True):
            files[i].write_bytes(pickle.dumps(fit))
    return motions, [pickle.loads(f.read_bytes()) for f in files]


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("clips", nargs="*")
    ap.add_argument("--bandai", action="store_true", help="the 15 walk and 15 run _001 clips of Bandai-1")
    ap.add_argument("--path", default=None, help="e.g. circle:3 (metres)")
    ap.add_argument("--out", default=None, help="JSON file")
    ap.add_argument("--cache", default=None, help="folder of pickled fits (development)")
    ap.add_argument("--no-knee-cap", action="store_true", help="without the capture's knee speed cap")
    ap.add_argument("--fps", type=float, default=None, help="synthesize at this frame rate (default: the clip's)")
    ap.add_argument("--breakdown", action="store_true",
                    help="also print the synthesized skating by foot point and by landing / mid / release")
    args = ap.parse_args(argv)
    names = list(args.clips)
    if args.bandai:
        names += [str(BANDAI / f"dataset-1_{k}_{s}_001.bvh") for k in ("walk", "run") for s in STYLES]
    if not names:
        names = list(BUNDLED)
    t0 = time.perf_counter()
    motions, fits = fits_of(names, cache=args.cache)
    rows = []
    for n, m, f in zip(names, motions, fits, strict=True):
        path = None
        if args.path:
            from fourierjax.cli._gait_args import parse_path

            path = parse_path(args.path, f.body_map.metres_per_unit)
        row = measure(m, f, path=path, knee_cap=not args.no_knee_cap,
                      frame_time_s=None if args.fps is None else 1.0 / args.fps)
        _, mot = row.pop("result"), row.pop("motion")
        if args.breakdown:
            from fourierjax import motion as M

            row["breakdown"] = skating_breakdown(M.foot_positions_of(mot, body_map=f.body_map), mot.frame_time_s,
                                                 f.body_map).tolist()
        row["clip"] = pathlib.Path(n).stem.replace("dataset-1_", "")
        row["met"] = met(row)
        rows.append(row)
        print(f"{row['clip']:28s} skating {row['skating_synth']:7.2f} vs {row['skating_capture']:7.2f} "
              f"({row['ratio']:.3f}x)  below {100 * row['depth_m']:.3f} cm  knee step "
              f"{row['knee_step_synth_deg']:5.1f} vs {row['knee_step_capture_deg']:5.1f} deg  flight "
              f"{100 * row['flight_synth']:3.0f}% vs {100 * row['flight_capture']:3.0f}%  "
              f"{'met' if row['met'] else 'NOT met'}", flush=True)
        if args.breakdown:
            for q, parts in enumerate(row["breakdown"]):
                print(f"    foot point {q}: landing {parts[0]:.3f}  mid {parts[1]:.3f}  release {parts[2]:.3f} units/s")
    print(f"{sum(r['met'] for r in rows)}/{len(rows)} met, {time.perf_counter() - t0:.0f} s")
    if args.out:
        pathlib.Path(args.out).write_text(json.dumps(rows, indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
