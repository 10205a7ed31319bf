"""`fourierjax interpolate`: a model between (or beyond) two gaits, Unuma 1995 eq. 3.

Also home of the output helpers the style commands share (`characteristic`, `transition`):
writing a synthesized motion. Gait arguments (a model file, or a BVH clip fitted on the fly) are
read by `cli._inputs`, numbers and frame counts by `cli._numbers`; both are re-exported here.
"""

from __future__ import annotations

import argparse
import pathlib

# Re-exported: synth, transition and characteristic imported them from here.
from fourierjax.cli._inputs import (  # noqa: F401
    DEFAULT_HARMONICS,
    Gait,
    add_gait_arguments,
    fit_bvhs,
    load_gait_pair,
    load_gaits,
)
from fourierjax.cli._numbers import MAX_FRAMES, frame_count, parse_number  # noqa: F401

HELP = "Inter/extrapolate two gaits (Unuma eq. 3): write the model (.npz) or a motion (.bvh)."


# ----------------------------------------------------------------------------- shared helpers


def write_motion(out: pathlib.Path, features, channel_names, frame_time_s, template, model=None, body_map=None,
                 up: str = "y", out_up: str | None = None) -> None:
    """Write synthesized features as a BVH on `template`'s skeleton (with `out_up`, else the
    source's `up`, as its up axis: `fourierjax.cli._outputs.write_bvh_as_source`).

    Features whose root channels do not move (a rig whose trajectory is not on joint 0, e.g.
    Bandai's `Hips` under a still `joint_Root`) would walk in place with the feet off the floor:
    their root path then comes from the stance feet (`gait.ground_features`, on the body map of
    `model`'s poses), with a notice.
    """
    import sys

    import numpy as np

    from fourierjax import motion as fmotion
    from fourierjax.cli._outputs import write_bvh_as_source

    x = np.asarray(features, np.float64)
    if body_map is None and model is not None:
        from fourierjax import gait

        # The map of the model's own poses: a rest template that is not a T-pose (Bandai's
        # bones along local X) does not show which way is up.
        body_map = gait.model_body_map(model, template.skeleton())
    if model is not None and len(x) >= 2 and not np.ptp(x[:, :3], axis=0).any():
        from fourierjax import gait
        from fourierjax.io.gait_bvh import grounded_motion

        bmap = body_map
        feats, root, _, _ = gait.ground_features(x, template.skeleton(), model.representation, frame_time_s,
                                                 body_map=bmap)
        print("fourierjax: notice: the model's root channels carry no travel (the rig's trajectory "
              f"joint, {bmap.name(bmap.pelvis)}, is not its root): root path from the stance feet",
              file=sys.stderr)
        motion = grounded_motion(template, feats, root, channel_names, frame_time_s, body_map=bmap)
    else:
        motion = fmotion.motion_from_features(template, x, channel_names, frame_time_s, body_map=body_map)
    write_bvh_as_source(motion, out, up, out_up)


def check_out(text: str, suffixes: tuple[str, ...]) -> pathlib.Path:
    """The output path: a known suffix and an existing directory, else a one-line UserError."""
    from fourierjax.errors import UserError

    out = pathlib.Path(text)
    if out.suffix.lower() not in suffixes:
        raise UserError(f"--out: {text}: expected a {' or '.join(suffixes)} file")
    if not out.parent.exists() and str(out.parent) not in ("", "."):
        raise UserError(f"--out: {out.parent}: no such directory")
    return out


def template_of(a: Gait, b: Gait, command: str):
    """The skeleton to write a BVH on: A's, else B's, else a one-line UserError."""
    from fourierjax.errors import UserError

    for g in (a, b):
        if g.template is not None:
            return g.template, g.frame_time_s
    raise UserError(
        f"{command}: neither {a.source} nor {b.source} carries a skeleton to write a BVH on; "
        "pass a BVH clip or a model saved with its skeleton"
    )


def body_map_of(a: Gait, b: Gait, model, template):
    """The body map to synthesize on `template` (`template_of`'s): the captured map of the gait
    whose skeleton it is (stored in its model file, or its fit's), else the map of `model`'s own
    poses. A model's cycle does not show which joint carried the travel: on a Blender rig
    (`Root` under the hips, both with position channels) the travel went to the hips and `Root`
    stood still, up in the air."""
    from fourierjax import gait

    for g in (a, b):
        if g.template is template and g.body_map is not None:
            return g.body_map
    return gait.model_body_map(model, template.skeleton())


def grounded_interpolation(model, template, num_frames: int, frame_time_s: float, *, foot_lock: bool = True,
                           contact_intervals=None, body_map=None):
    """An interpolated (or any) model synthesized as `synth` does, as a writeable `Motion`: the
    hip-height rule, root motion from the stance feet and, with `foot_lock`, planted feet
    (`gait.synthesize_gait` on the body map of the model's own poses), in contact over
    `contact_intervals` (`[2, 2]`; the sources' blended, `blended_contact_intervals`), else over
    intervals estimated from the blend's own cycle; on `body_map` (`body_map_of`), else the map
    of the model's own poses."""
    from fourierjax import gait
    from fourierjax.io.gait_bvh import gait_motion

    bmap = body_map if body_map is not None else gait.model_body_map(model, template.skeleton())
    r = gait.synthesize_gait(model, template.skeleton(), num_frames, frame_time_s, body_map=bmap,
                             foot_lock=foot_lock, contact_intervals=contact_intervals)
    return gait_motion(template, r, model.channel_names, frame_time_s, body_map=bmap)


def blended_contact_intervals(a: Gait, b: Gait, s: float):
    """`[2, 2]` contact phases of the blend at `s` (`gait.blend_contact_intervals`) from its
    sources': stored with a model file or learned from a fitted clip's contacts, else estimated
    from that source model's cycle (`gait.intervals_from_model`). None when neither gait
    carries a skeleton to estimate on.

    The blend's stance is its sources': estimated from the blend's own cycle instead, the
    stance of two walks with different duty factors, which polar interpolation makes slide
    (Bandai walk_normal/walk_old: the stance foot at 0.3 of the root speed, each source
    <= 0.21), was cut short, and the foot lock lifted the sliding foot."""
    import numpy as np

    from fourierjax import gait

    template = a.template if a.template is not None else b.template
    ivs = []
    for g in (a, b):
        iv = g.contact_intervals
        if iv is None:
            if template is None:
                return None
            skeleton = template.skeleton()
            iv = gait.intervals_from_model(g.model, skeleton, body_map=gait.model_body_map(g.model, skeleton))
        ivs.append(np.asarray(iv, np.float64))
    return np.asarray(gait.blend_contact_intervals(ivs[0], ivs[1], s), np.float64)


# ------------------------------------------------------------------------------------ command


def add_arguments(parser: argparse.ArgumentParser) -> None:
    add_gait_arguments(parser)
    parser.add_argument(
        "--s", required=True, metavar="S", help="blend parameter: 0 gives A, 1 gives B, outside [0, 1] extrapolates"
    )
    parser.add_argument(
        "--out", required=True, metavar="OUT", help="OUT.npz writes the model; OUT.bvh writes a synthesized motion"
    )
    parser.add_argument(
        "--method",
        default="polar",
        choices=("polar", "phasor"),
        help="polar: Unuma eq. 3, shorter-arc phases (default); phasor: the time-domain blend (1-s) A(θ) + s B(θ)",
    )
    parser.add_argument(
        "--seconds", default="4", metavar="S", help="length of the motion for a .bvh output (default 4)"
    )
    parser.add_argument(
        "--fps", default=None, metavar="F", help="frame rate of a .bvh output (default: that of A's clip, else 120)"
    )
    g = parser.add_argument_group(
        "grounding of a .bvh output (issue 21)",
        "As `fourierjax synth`: the hip-height rule puts the lowest foot point on the floor, the "
        "root path follows the stance feet, and foot locking plants them (two-bone leg IK).")
    g.add_argument("--root-motion", action=argparse.BooleanOptionalAction, default=True,
                   help="root height from the hip rule and root path from the stance feet (default "
                   "on); --no-root-motion keeps the interpolated model's own root channels (and no "
                   "foot lock)")
    from fourierjax.cli._gait_args import add_foot_lock_arguments
    from fourierjax.cli._outputs import add_out_up_argument

    add_foot_lock_arguments(g)
    add_out_up_argument(parser)


def run(args: argparse.Namespace) -> int:
    import jax
    import jax.numpy as jnp

    from fourierjax import fourier, style
    from fourierjax.cli._outputs import write_bvh_as_source
    from fourierjax.errors import UserError
    from fourierjax.io import model_io

    s = parse_number(args.s, "--s")
    out = check_out(args.out, (".npz", ".bvh"))
    seconds = parse_number(args.seconds, "--seconds", positive=True)
    fps = None if args.fps is None else parse_number(args.fps, "--fps", positive=True)
    a, b = load_gait_pair(args)
    model = style.interpolate(a.model, b.model, s, method=args.method)
    if not all(bool(jnp.isfinite(x).all()) for x in jax.tree.leaves(model)):
        raise UserError(f"--s: {s:g} extrapolates so far that the model overflows; use a smaller --s")
    intervals = blended_contact_intervals(a, b, s)
    src = a if a.template is not None else b  # the gait whose skeleton (and up axis) is written
    if out.suffix.lower() == ".npz":
        template = a.template if a.template is not None else b.template
        model_io.save_model(
            out,
            model,
            motion=template,
            body_map=None if template is None else body_map_of(a, b, model, template),
            provenance={"command": "interpolate", "a": a.source, "b": b.source, "s": s, "method": args.method,
                        "up": src.up},
            alignment=a.alignment,
            contact_intervals=intervals,
        )
    else:
        template, frame_time_s = template_of(a, b, "interpolate")
        dt = 1.0 / fps if fps is not None else (frame_time_s or 1 / 120)
        num = frame_count(seconds, dt)
        bmap = body_map_of(a, b, model, template)
        if getattr(args, "root_motion", True):
            write_bvh_as_source(grounded_interpolation(model, template, num, dt,
                                                       foot_lock=getattr(args, "foot_lock", True),
                                                       contact_intervals=intervals, body_map=bmap),
                                out, src.up, args.out_up)
        else:
            t = jnp.arange(num) * dt
            write_motion(out, fourier.synthesize(model, t), model.channel_names, dt, template, model, bmap,
                         up=src.up, out_up=args.out_up)
    print(f"wrote {out}")
    return 0
