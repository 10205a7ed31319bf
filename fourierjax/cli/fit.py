"""`fourierjax fit`: fit Fourier gait models to BVH clips and report ω and the fit quality."""

from __future__ import annotations

import argparse
import collections
import itertools
import json
import os
import pathlib
import sys

from fourierjax.cli._inputs import DEFAULT_HARMONICS, read_clip

HELP = "Fit Fourier gait models (Unuma eq. 1) to BVH clips: fundamental three ways, fit quality."


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("files", nargs="+", metavar="FILE",
                        help="BVH files, folders of them (every *.bvh inside), or names of "
                        "bundled clips (e.g. 07_12)")
    parser.add_argument("--harmonics", default=DEFAULT_HARMONICS, type=int, metavar="N",
                        help=f"number of harmonics N (default {DEFAULT_HARMONICS}, as when `transition` "
                        "or `interpolate` fit a BVH argument; Tilmanne: 2; Unuma: 3 to 7)")
    parser.add_argument("--representation", default="tangent", choices=("euler", "expmap", "tangent"),
                        help="rotation channels: tangent (default; rotations about each joint's "
                        "clip mean: rig-invariant, the same fit whatever the rig's joint frames and "
                        "Euler orders), euler (Unuma's per-channel joint-angle series: the file's "
                        "Euler angles made continuous; they depend on the rig's joint frames) or "
                        "expmap (the continuous exponential map, Tilmanne)")
    parser.add_argument("--start-frame", type=int, default=None, metavar="K",
                        help="first frame of the file to use (default: drop leading rest/T-pose "
                        "frames, with a notice)")
    parser.add_argument("--stop-frame", type=int, default=None, metavar="K",
                        help="frame of the file after the last one to use (default: the end)")
    parser.add_argument("--body-map", default=None, metavar="FILE",
                        help="TOML body map overriding the inferred one (legs, feet, trajectory, "
                        "up, units; see `fourierjax info`)")
    parser.add_argument("--up", default=None, metavar="AXIS",
                        help="the files' up axis (y, z, -z, ...; default: inferred); other than "
                        "+y, the clip is turned Y-up on reading, with a notice")
    parser.add_argument("--all-frames", action="store_true",
                        help="fit every frame instead of the longest steady straight stretch")
    parser.add_argument("--out", default=None, metavar="MODEL",
                        help="model file to write (.npz); with several FILEs, or ending in '/', "
                        "a directory that receives one <name>.npz per clip")
    parser.add_argument("--json", action="store_true",
                        help="print one JSON list (one object per clip) instead of a table")


#: A fit explaining less than this fraction of the angle variance is flagged on stderr (the
#: other bundled walks and runs, N = 3: 0.88-0.96; 142_02, whose arm channels pass near gimbal
#: lock: 0.17).
POOR_VARIANCE_EXPLAINED = 0.5


def _warn_if_poor(text: str, row: dict) -> None:
    """One stderr line when a fit looks wrong: little variance explained, or the fitted
    fundamental far (> 25%) from the step-based one."""
    reasons = []
    ve = row.get("variance_explained_angles")
    if ve is not None and ve < POOR_VARIANCE_EXPLAINED:
        reasons.append(f"it explains {100 * ve:.0f}% of the angle variance")
    f_fit, f_steps = row.get("fundamental_hz"), row.get("fundamental_hz_steps")
    if f_steps is not None and f_fit and abs(f_fit / f_steps - 1) > 0.25:
        reasons.append(f"its fundamental {f_fit:.3f} Hz is far from the steps' {f_steps:.3f} Hz")
    winding = row.get("winding_joints") or []
    if winding:
        shown = ", ".join(winding[:4]) + (f" and {len(winding) - 4} more" if len(winding) > 4 else "")
        print(f"fourierjax: notice: {text}: the Euler angles of {shown} pass near gimbal lock "
              "(a channel spans more than 180 degrees); their series depend on the rig's joint "
              "frames: --representation tangent fits the same rotations on any rig", file=sys.stderr)
    if reasons:
        print(f"fourierjax: warning: {text}: the fit looks poor ({'; '.join(reasons)}); check the "
              "clip is a steady periodic gait (try --all-frames, --start-frame, another "
              "--representation)", file=sys.stderr)


def run(args: argparse.Namespace) -> int:
    from fourierjax import __version__, model_io
    from fourierjax.cli._paths import resolve_input
    from fourierjax.errors import UserError
    from fourierjax.motion import iter_fit_motions

    if args.harmonics < 1 or args.harmonics > 32:
        raise UserError(f"--harmonics: must be between 1 and 32, got {args.harmonics}")
    out = None if args.out is None else pathlib.Path(args.out)
    # "--out models/" names a folder even for one clip (it wrote a model file called "models").
    to_folder = (len(args.files) > 1 or any(pathlib.Path(f).is_dir() for f in args.files)
                 or (args.out is not None and args.out.endswith(("/", os.sep))))
    if out is not None:
        if to_folder:
            if out.exists() and not out.is_dir():
                raise UserError(f"--out: {out} must be a directory when fitting several files")
        elif out.is_dir():
            raise UserError(f"--out: {out} is a directory; give a model file name (.npz)")
        elif not out.parent.exists():
            raise UserError(f"--out: {out.parent}: no such directory")
    files = _expand_folders(args.files)
    paths = [resolve_input(f) for f in files]
    if out is not None and to_folder:
        seen: dict[str, str] = {}
        for text, path in zip(files, paths, strict=True):
            if path.stem in seen:  # one would overwrite the other's model
                raise UserError(f"--out: {seen[path.stem]} and {text} would both be written to "
                                f"{out / (path.stem + '.npz')}; fit them into separate folders")
            seen[path.stem] = text
    # One clip that cannot be read or fitted does not stop the others (reported at the end).
    # The files are read as a stream (`iter_fit_motions`: chunk k + 1 is read while chunk k is
    # fitted) and each model is written as soon as its chunk is fitted.
    failed: list[str] = []
    loaded: collections.deque = collections.deque()

    def clips():
        for text, p in zip(files, paths, strict=True):
            try:
                motion, skip, bm, up = read_clip(p, args.start_frame, args.stop_frame, args.up,
                                                 args.body_map)
            except UserError as err:
                if len(files) == 1:
                    raise
                failed.append(f"{text}: {err}")
                continue
            loaded.append((text, p, motion, skip, up))
            yield motion, bm

    pairs_m, pairs_b = itertools.tee(clips())
    fits = iter_fit_motions((m for m, _ in pairs_m), args.harmonics, args.representation,
                            segment=not args.all_frames, body_map=(b for _, b in pairs_b),
                            progress=None if len(files) > 1 else False)
    rows = []
    try:
        for fit in fits:
            text, path, motion, skip, up = loaded.popleft()
            if not fit.successful:
                failed.append(f"{text}: {fit.message}")
                continue
            rows.append(_row(args, text, path, motion, skip, up, fit, out, to_folder, __version__,
                             model_io))
    except UserError as err:
        if "fit_motions: no motions given" not in str(err) or not failed:
            raise  # (every file failed to load: reported below)
    if args.json:
        print(json.dumps(rows))
        return _report_failures(failed, len(files))
    head = (f"{'file':<28} {'frames':>11} {'f_spec':>7} {'f_step':>7} {'f_fit':>7} "
            f"{'rms_deg':>8} {'VE_ang':>7} {'VE_pos':>7}  aligned to")
    print(head)
    for r in rows:
        fs = r["fundamental_hz_steps"]
        print(f"{r['file'][-28:]:<28} {r['frame_start']:>5}-{r['frame_stop']:<5} "
              f"{r['fundamental_hz_spectral']:7.3f} {fs if fs is None else round(fs, 3)!s:>7} "
              f"{r['fundamental_hz']:7.3f} {r['rms_deg']:8.2f} "
              f"{100 * r['variance_explained_angles']:6.1f}% "
              f"{100 * r['variance_explained_positions']:6.1f}%  {r['alignment']}")
        if "model" in r:
            print(f"  wrote {r['model']}")
    return _report_failures(failed, len(files))


def _row(args, text, path, motion, skip, up, fit, out, to_folder, version, model_io) -> dict:
    """The report row of one fitted clip; its model file written when ``--out`` is given (its
    provenance keeps the file's up axis, ``up``, so that BVH written from it can keep it too)."""
    row = {"file": text, "path": str(path), "up": up}
    row.update(fit.summary())
    row.pop("source", None)
    row["frame_start"] = skip + fit.frame_start  # file frame numbers
    row["frame_stop"] = skip + fit.frame_stop
    row["frames_used"] = [row["frame_start"], row["frame_stop"]]
    row["rest_frames_dropped"] = skip if args.start_frame is None else 0
    _warn_if_poor(text, row)
    if out is not None:
        target = out / f"{path.stem}.npz" if to_folder else out
        if to_folder:
            out.mkdir(parents=True, exist_ok=True)
        prov = dict(row, fourierjax_version=version, command="fit")
        from fourierjax import gait

        model_io.save_model(target, fit.model, motion=motion, provenance=prov,
                            alignment=fit.alignment, body_map=fit.body_map,
                            contact_intervals=gait.fit_contact_intervals(fit, motion),
                            knee_speed_rad_s=gait.fit_knee_speed(fit, motion))
        row["model"] = str(target)
    return row


def _expand_folders(files: list[str]) -> list[str]:
    """FILE arguments with each folder replaced by its ``*.bvh`` files (sorted)."""
    out = []
    for text in files:
        path = pathlib.Path(text)
        out += sorted(str(p) for p in path.glob("*.bvh")) if path.is_dir() else [text]
    return out


def _report_failures(failed: list[str], total: int) -> int:
    """One stderr line per clip that failed and a summary; the exit status (1 if any failed).
    One clip given, one that failed: its line alone and exit 2, as when it cannot be read."""
    if not failed:
        return 0
    if total == 1:
        print(f"fourierjax: error: {failed[0]}", file=sys.stderr)
        return 2
    for line in failed:
        print(f"fourierjax: error: {line}", file=sys.stderr)
    print(f"fourierjax: fitted {total - len(failed)} of {total} clips; {len(failed)} failed",
          file=sys.stderr)
    return 1
