"""`fourierjax fit`: fit Fourier gait models to BVH clips and report ω and the fit quality."""

from __future__ import annotations

import argparse
import json
import pathlib
import sys

HELP = "Fit Fourier gait models (Unuma eq. 1) to BVH clips: fundamental three ways, fit quality."


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("files", nargs="+", metavar="FILE",
                        help="BVH files, or names of bundled clips (e.g. 07_12)")
    parser.add_argument("--harmonics", required=True, type=int, metavar="N",
                        help="number of harmonics N (Tilmanne: 2; Unuma: 3 to 7)")
    parser.add_argument("--representation", default="euler", choices=("euler", "expmap"),
                        help="rotation channels: the file's Euler angles made continuous "
                        "(default) or the continuous exponential map (Tilmanne)")
    parser.add_argument("--start-frame", type=int, default=None, metavar="K",
                        help="first frame of the file to use (default: drop leading rest/T-pose "
                        "frames, with a notice)")
    parser.add_argument("--all-frames", action="store_true",
                        help="fit every frame instead of the longest steady straight stretch")
    parser.add_argument("--out", default=None, metavar="MODEL",
                        help="model file to write (.npz); with several FILEs, a directory that "
                        "receives one <name>.npz per clip")
    parser.add_argument("--json", action="store_true",
                        help="print one JSON list (one object per clip) instead of a table")


def _resolve(text: str) -> pathlib.Path:
    from fourierjax import data
    from fourierjax.errors import UserError

    path = pathlib.Path(text)
    if path.exists():
        if path.is_dir():
            raise UserError(f"{text}: is a directory, expected a BVH file")
        return path
    if text.removesuffix(".bvh") in data.list() and "/" not in text:
        return data.path(text)
    raise UserError(f"{text}: no such file (bundled clips: {', '.join(data.list())})")


def _load(path: pathlib.Path, start_frame: int | None):
    """The motion to fit and the number of leading file frames dropped."""
    from fourierjax.data import detect_rest_frames
    from fourierjax.errors import UserError
    from fourierjax.io.bvh import read_bvh

    motion = read_bvh(path)
    if start_frame is not None:
        if not 0 <= start_frame < motion.num_frames - 1:
            raise UserError(
                f"--start-frame: {start_frame} is outside {path} (frames 0..{motion.num_frames - 1})"
            )
        skip = start_frame
    else:
        skip = detect_rest_frames(motion)
        if skip:
            print(f"fourierjax: notice: {path}: dropped {skip} leading rest frame(s) "
                  f"(use --start-frame to choose)", file=sys.stderr)
    motion = motion[skip:]
    if motion.num_frames < 16:
        raise UserError(f"{path}: only {motion.num_frames} frames to fit; need at least 16")
    return motion, skip


def run(args: argparse.Namespace) -> int:
    from fourierjax import __version__, model_io
    from fourierjax.errors import UserError
    from fourierjax.motion import fit_motions

    if args.harmonics < 1 or args.harmonics > 32:
        raise UserError(f"--harmonics: must be between 1 and 32, got {args.harmonics}")
    out = None if args.out is None else pathlib.Path(args.out)
    if out is not None:
        if len(args.files) > 1:
            if out.exists() and not out.is_dir():
                raise UserError(f"--out: {out} must be a directory when fitting several files")
        elif out.is_dir():
            raise UserError(f"--out: {out} is a directory; give a model file name (.npz)")
        elif not out.parent.exists():
            raise UserError(f"--out: {out.parent}: no such directory")
    paths = [_resolve(f) for f in args.files]
    loaded = [_load(p, args.start_frame) for p in paths]
    fits = fit_motions([m for m, _ in loaded], args.harmonics, args.representation,
                       segment=not args.all_frames)
    rows = []
    for text, path, (motion, skip), fit in zip(args.files, paths, loaded, fits, strict=True):
        row = {"file": text, "path": str(path)}
        row.update(fit.summary())
        row.pop("source", None)
        row["frame_start"] = skip + fit.frame_start  # file frame numbers
        row["frame_stop"] = skip + fit.frame_stop
        row["frames_used"] = [row["frame_start"], row["frame_stop"]]
        row["rest_frames_dropped"] = skip if args.start_frame is None else 0
        rows.append(row)
        if out is not None:
            target = out if len(paths) == 1 else out / f"{path.stem}.npz"
            if len(paths) > 1:
                out.mkdir(parents=True, exist_ok=True)
            prov = dict(row, fourierjax_version=__version__, command="fit")
            model_io.save_model(target, fit.model, motion=motion, provenance=prov,
                                alignment=fit.alignment)
            row["model"] = str(target)
    if args.json:
        print(json.dumps(rows))
        return 0
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
    return 0
