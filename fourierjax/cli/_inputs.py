"""Gait arguments of the style commands: a model file (.npz) loaded as is, or a BVH clip fitted.

`interpolate`, `transition` and `characteristic` take two gaits. A model file written by
`fourierjax fit` is used without fitting again; BVH arguments are fitted on the fly, all in one
batched `fourierjax.motion.fit_motions` call.
"""

from __future__ import annotations

import argparse
import dataclasses
import pathlib
import sys

from fourierjax.cli._numbers import parse_number

DEFAULT_HARMONICS = 5


@dataclasses.dataclass(frozen=True)
class Gait:
    """A gait argument, resolved: its model, a Motion whose skeleton can be written (or None),
    and where it came from."""

    model: object
    template: object | None
    frame_time_s: float | None
    source: str
    provenance: dict
    alignment: str = "none"
    #: `[2, 2]` (left, right) x (start, end) contact phases of the gait: stored in the model file
    #: (`fourierjax fit`), learned from a fitted BVH's contacts, else None.
    contact_intervals: object | None = None
    #: The skeleton's `body.BodyMap` from the capture (stored in the model file, or the fit's):
    #: it knows which joint carried the travel, which a model's own cycle does not show (a
    #: Blender rig's `Root` under the hips, both with position channels). None when unknown.
    body_map: object | None = None
    #: The source file's up axis ("y", "z", "-z", ...): the model and `template` are Y-up, and
    #: BVH written from them is turned back to it (`cli._outputs.write_bvh_as_source`).
    up: str = "y"
    #: `[2]` the source clip's largest knee speeds (rad/s, `gait.fit_knee_speed`; stored in the
    #: model file by `fourierjax fit`): the foot lock's cap on the swing's knee. None when unknown.
    knee_speed_rad_s: object | None = None


def add_gait_arguments(parser: argparse.ArgumentParser) -> None:
    """The two positional gaits and the on-the-fly fit options."""
    parser.add_argument("a", metavar="A", help="first gait: a model file (.npz, from `fourierjax fit "
                        "--out`; used as is) or a BVH clip (fitted) or a bundled clip name")
    parser.add_argument("b", metavar="B", help="second gait: a model file (.npz) or a BVH clip")
    parser.add_argument(
        "--harmonics",
        default=str(DEFAULT_HARMONICS),
        metavar="N",
        help=f"harmonics when fitting a BVH argument (default {DEFAULT_HARMONICS})",
    )
    parser.add_argument(
        "--representation",
        default="tangent",
        metavar="REP",
        help="channel representation when fitting a BVH argument: tangent (default; "
        "rig-invariant), euler (Unuma's per-channel joint-angle series; depends on the rig's "
        "joint frames) or expmap",
    )


def read_clip(path: pathlib.Path, start_frame: int | None = None, stop_frame: int | None = None,
              up: str | None = None, body_map: str | None = None):
    """A BVH clip as every command reads it: `(motion, skip, body_map, up)`.

    ``motion`` is Y-up (a file whose body map finds another up axis, or with ``up`` given, is
    turned on reading, with a one-line notice), cut to ``[start_frame, stop_frame)`` or, without
    ``start_frame``, with its leading rest frames dropped (a notice); ``skip`` is the number of
    leading file frames dropped; ``up`` is the file's own up axis ("y", "z", "-z", ...).
    """
    from fourierjax.body import infer_body_map
    from fourierjax.data import detect_rest_frames
    from fourierjax.errors import UserError
    from fourierjax.io.axes import to_y_up, up_name
    from fourierjax.io.bvh import read_bvh

    motion = read_bvh(path)
    if stop_frame is not None:
        if not 1 < stop_frame <= motion.num_frames:
            raise UserError(f"--stop-frame: {stop_frame} is outside {path} (frames 0..{motion.num_frames - 1})")
        motion = motion[:stop_frame]
    bm = infer_body_map(motion, up=up, overrides=body_map)
    axis = "y"
    if (bm.up_axis, bm.up_sign) != (1, 1):
        axis = up_name(bm.up_axis, bm.up_sign)
        print(f"fourierjax: notice: {path}: {axis} is up; turned Y-up on reading", file=sys.stderr)
        motion = to_y_up(motion, axis)
        bm = infer_body_map(motion, overrides=body_map)
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
    if start_frame is not None and start_frame >= (stop_frame or motion.num_frames + skip):
        raise UserError(f"--start-frame {start_frame} is not before --stop-frame {stop_frame}")
    return motion, skip, bm, axis


def fit_bvhs(paths, harmonics: int, representation: str) -> list[Gait]:
    """Fit BVH clips as `fourierjax fit` does, in one batched call: drop leading rest frames,
    then `fourierjax.motion.fit_motions` (steady straight stretch, fit, phase aligned to the
    left heel strike, falling back to the left hip flexion peak)."""
    from fourierjax import gait
    from fourierjax import motion as fmotion

    clips = [read_clip(p) for p in paths]
    fits = fmotion.fit_motions([c[0] for c in clips], harmonics, representation, throw=True,
                               body_map=[c[2] for c in clips])
    gaits = []
    for path, (motion, rest, _, up), fit in zip(paths, clips, fits):
        provenance = fit.summary()
        provenance.update(source=str(path), rest_frames_dropped=rest, up=up)
        gaits.append(Gait(fit.model, motion, motion.frame_time_s, str(path), provenance, fit.alignment,
                          gait.fit_contact_intervals(fit, motion), body_map=fit.body_map, up=up,
                          knee_speed_rad_s=gait.fit_knee_speed(fit, motion)))
    return gaits


def _check_path(text: str, argument: str) -> pathlib.Path:
    from fourierjax.cli._paths import resolve_input

    return resolve_input(text, argument, "a BVH or model file")


def _load_model_file(path: pathlib.Path, argument: str) -> Gait:
    from fourierjax.errors import UserError
    from fourierjax.io import model_io

    try:
        mf = model_io.load_model(path)
    except UserError as err:
        hint = ""
        if "fourier_characteristic" in str(err):
            hint = " (a characteristic file: apply it with `fourierjax synth --add`)"
        raise UserError(f"{argument}: {err}{hint}") from None
    provenance = dict(mf.provenance or {})
    return Gait(
        mf.model, mf.template_motion(), mf.frame_time_s, str(path), provenance, mf.alignment or "none",
        getattr(mf, "contact_intervals", None), body_map=mf.body_map, up=source_up(provenance),
        knee_speed_rad_s=getattr(mf, "knee_speed_rad_s", None),
    )


def load_gaits(texts, arguments, harmonics: int, representation: str) -> list[Gait]:
    """Gait arguments: model files, or BVH files fitted on the fly (all BVH arguments in one
    batched fit). Every path is checked before any fitting starts. One-line UserErrors."""
    paths = [_check_path(t, a) for t, a in zip(texts, arguments)]
    is_bvh = [p.suffix.lower() == ".bvh" for p in paths]
    gaits: list[Gait | None] = [None if bvh else _load_model_file(p, a) for p, a, bvh in zip(paths, arguments, is_bvh)]
    fitted = iter(
        fit_bvhs([p for p, bvh in zip(paths, is_bvh) if bvh], harmonics, representation) if any(is_bvh) else []
    )
    return [g if g is not None else next(fitted) for g in gaits]


def load_gait_pair(args: argparse.Namespace):
    """Both gait arguments of a style command, checked compatible (one-line UserError)."""
    from fourierjax import fourier, style
    from fourierjax.errors import UserError

    harmonics = parse_number(args.harmonics, "--harmonics", positive=True, integer=True)
    if args.representation not in fourier.REPRESENTATIONS:
        raise UserError(f"--representation: {args.representation!r} is not one of {fourier.REPRESENTATIONS}")
    a, b = load_gaits((args.a, args.b), ("A", "B"), harmonics, args.representation)
    try:
        style.check_compatible(a.model, b.model, names=(f"A ({args.a})", f"B ({args.b})"))
    except ValueError as err:
        raise UserError(f"incompatible models: {err}") from None
    _check_units(a, b, args)
    if a.alignment != b.alignment:
        # Phases are only comparable when θ = 0 is the same gait event in both models.
        print(
            f"fourierjax: warning: A is aligned to {a.alignment!r} and B to {b.alignment!r}; "
            "their phases may not be comparable",
            file=sys.stderr,
        )
    return a, b


def source_up(provenance: dict) -> str:
    """The up axis of the file a model was fitted from, as `fourierjax fit` records it in the
    model file's provenance ("y" for files written before it did, and for Y-up files)."""
    from fourierjax.cli._outputs import UP_AXES

    up = str((provenance or {}).get("up", "y")).strip().lower().lstrip("+")
    return up if up in UP_AXES else "y"


def _check_units(a: Gait, b: Gait, args) -> None:
    """One-line UserError when the two gaits' lengths are in different units: their root
    channels (velocity, height) would be blended as numbers (a CMU walk and the same rig's run
    in metres, interpolated at s = 0.5, went 0.37 of the way of the two in CMU units)."""
    from fourierjax.errors import UserError

    ma, mb = (getattr(g.body_map, "metres_per_unit", None) for g in (a, b))
    la, lb = (getattr(g.body_map, "leg_length", None) for g in (a, b))
    # Units are a guess from the body's size: refused only when the legs' lengths in file units
    # differ too (the same rig in other units), not when one clip's guess flipped.
    if ma and mb and la and lb and abs(ma / mb - 1) > 1e-3 and max(la / lb, lb / la) > 1.5:
        units = [f"{g.body_map.units} ({m:g} m per unit)" for g, m in ((a, ma), (b, mb))]
        raise UserError(f"incompatible models: A ({args.a}) is in {units[0]}, B ({args.b}) in {units[1]}; "
                        "fit both on clips in the same units")
