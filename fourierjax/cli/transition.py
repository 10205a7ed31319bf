"""`fourierjax transition`: a BVH motion that changes from gait A to gait B over a time window."""

from __future__ import annotations

import argparse
import sys

HELP = "Transition from gait A to gait B (e.g. walk -> run, run -> walk) and write a BVH."


def add_arguments(parser: argparse.ArgumentParser) -> None:
    from fourierjax.cli._inputs import add_gait_arguments

    add_gait_arguments(parser)
    parser.add_argument("--seconds", required=True, metavar="S", help="length of the motion")
    parser.add_argument("--start", required=True, metavar="T", help="time (s) at which the transition starts")
    parser.add_argument(
        "--duration",
        required=True,
        metavar="D",
        help="length (s) of the transition window (about one gait cycle or more looks natural)",
    )
    parser.add_argument("--out", required=True, metavar="OUT.bvh", help="BVH file to write")
    parser.add_argument("--fps", default=None, metavar="F", help="frame rate (default: that of A's clip, else 120)")
    parser.add_argument(
        "--ease",
        default="smoothstep",
        choices=("smoothstep", "smootherstep", "linear"),
        help="blend curve s(t) over the window (default smoothstep)",
    )
    parser.add_argument(
        "--method",
        default="polar",
        choices=("polar", "phasor"),
        help="interpolation of the harmonics (default polar, Unuma eq. 3)",
    )
    add_grounding_arguments(parser)
    from fourierjax.cli._outputs import add_out_up_argument

    add_out_up_argument(parser)


def add_grounding_arguments(parser: argparse.ArgumentParser) -> None:
    """`--root-motion/--no-root-motion` and `--foot-lock/--no-foot-lock` (issue #21: grounded
    transitions, planted feet)."""
    from fourierjax.cli._gait_args import add_foot_lock_arguments

    g = parser.add_argument_group("grounding (issue 21)")
    g.add_argument("--root-motion", action=argparse.BooleanOptionalAction, default=True,
                   help="root path from the stance feet and the lowest foot on the captured floor, "
                   "flying only where the run does (default on); --no-root-motion keeps the "
                   "blended models' own root channels (and no foot lock)")
    add_foot_lock_arguments(g)


def grounded_motion_of(args, a, b, template, num_frames: int, dt: float, start: float, duration: float):
    """The grounded transition as a writeable `Motion` (`style.grounded_transition`)."""
    from fourierjax import gait, style
    from fourierjax.cli.interpolate import body_map_of
    from fourierjax.io.gait_bvh import grounded_motion

    skeleton = template.skeleton()
    bmap = body_map_of(a, b, a.model, template)
    foot_lock = getattr(args, "foot_lock", True)
    # The contact phases each model learned from its clip (model file or BVH fit), as `synth`
    # uses them; estimated from the model's own cycle where a source has none.
    intervals = None
    if foot_lock:
        intervals = tuple(g.contact_intervals if getattr(g, "contact_intervals", None) is not None
                          else gait.contact_intervals(g.model, skeleton, body_map=bmap) for g in (a, b))
    # The sources' knee speeds cap the lock's swing knee, as in `synth` (when both are known).
    knees = tuple(getattr(g, "knee_speed_rad_s", None) for g in (a, b))
    r = style.grounded_transition(a.model, b.model, skeleton, num_frames, dt, start, duration,
                                  body_map=bmap, ease=args.ease, method=args.method,
                                  foot_lock=foot_lock, contact_intervals=intervals,
                                  knee_speed_rad_s=None if any(k is None for k in knees) else knees)
    return grounded_motion(template, r.features, r.root_position, a.model.channel_names, dt, body_map=bmap)


def run(args: argparse.Namespace) -> int:
    import jax.numpy as jnp

    from fourierjax import style
    from fourierjax.cli._inputs import load_gait_pair
    from fourierjax.cli.interpolate import body_map_of, check_out, frame_count, parse_number, template_of, write_motion
    from fourierjax.errors import UserError

    seconds = parse_number(args.seconds, "--seconds", positive=True)
    start = parse_number(args.start, "--start", nonnegative=True)
    duration = parse_number(args.duration, "--duration", positive=True)
    if start >= seconds:  # the file would hold A only (it said "transition 10s to 12s")
        raise UserError(f"--start: the transition starts at {start:g} s, at or after the end of "
                        f"the {seconds:g} s motion; start it before --seconds")
    if start + duration > seconds:
        print(f"fourierjax: notice: the transition ends at {start + duration:g} s, after the "
              f"{seconds:g} s motion: the file stops part-way through it", file=sys.stderr)
    fps = None if args.fps is None else parse_number(args.fps, "--fps", positive=True)
    out = check_out(args.out, (".bvh",))
    a, b = load_gait_pair(args)
    template, frame_time_s = template_of(a, b, "transition")
    dt = 1.0 / fps if fps is not None else (frame_time_s or 1 / 120)
    t = jnp.arange(frame_count(seconds, dt)) * dt
    src = a if a.template is not None else b  # the gait whose skeleton (and up axis) is written
    if getattr(args, "root_motion", False):
        from fourierjax.cli._outputs import write_bvh_as_source

        write_bvh_as_source(grounded_motion_of(args, a, b, template, t.shape[0], dt, start, duration), out,
                            src.up, args.out_up)
    else:
        values = style.transition(a.model, b.model, t, start, duration, ease=args.ease, method=args.method)
        write_motion(out, values, a.model.channel_names, dt, template, a.model, body_map_of(a, b, a.model, template),
                     up=src.up, out_up=args.out_up)
    print(f"wrote {out}: {t.shape[0]} frames at {1 / dt:g} fps, transition {start:g}s to {start + duration:g}s")
    return 0
