"""`fourierjax synth`: synthesize a BVH motion of any length from a Fourier model file."""

from __future__ import annotations

import argparse
import pathlib

HELP = ("Synthesize a BVH motion from a model file, optionally with weighted characteristics "
        "(Unuma eq. 8) and noise harmonics.")


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("model", metavar="MODEL", nargs="?", help="model file written by `fourierjax fit`")
    parser.add_argument("--config", metavar="FILE.toml", help="a parameter set written by `fourierjax explore` "
                        "(in place of MODEL and the other flags): reproduces its export exactly")
    parser.add_argument("--seconds", type=float, metavar="S", help="length of the motion in seconds (required)")
    parser.add_argument("--fps", type=float, default=None, metavar="F",
                        help="frame rate (default: the source clip's, else 120)")
    parser.add_argument("--add", action="append", default=[], metavar="CHARACTERISTIC=WEIGHT",
                        help="superpose a characteristic file (from `fourierjax characteristic`) "
                        "with a weight, e.g. brisk.npz=1.37; repeatable")
    parser.add_argument("--no-speed-limit", action="store_true",
                        help="keep --add weights as given; by default they are scaled down where a joint "
                        "would move faster than in the base or the characteristics' clips (a limb flip)")
    parser.add_argument("--noise", type=float, default=0.0, metavar="X",
                        help="amplitude in degrees of random higher harmonics on every rotation "
                        "channel (Unuma's shivering; default 0)")
    parser.add_argument("--noise-harmonics", type=int, default=3, metavar="K",
                        help="number of noise harmonics above the model's N (default 3)")
    parser.add_argument("--seed", type=int, default=0, help="PRNG seed of the noise (default 0)")
    parser.add_argument("--out", required=True, metavar="OUT.bvh", help="BVH file to write")
    from fourierjax.cli._gait_args import add_gait_arguments  # step constraints (gait.py)

    add_gait_arguments(parser)
    from fourierjax.cli._outputs import add_out_up_argument

    add_out_up_argument(parser)


def _parse_add(text: str):
    from fourierjax.errors import UserError

    path, sep, weight = text.rpartition("=")
    if not sep or not path:
        raise UserError(f"--add: {text!r}: expected CHARACTERISTIC=WEIGHT, e.g. brisk.npz=1.37")
    try:
        w = float(weight)
    except ValueError:
        raise UserError(f"--add: {text!r}: weight {weight!r} is not a number") from None
    return path, w


def run(args: argparse.Namespace) -> int:
    import math

    import jax
    import jax.numpy as jnp
    import numpy as np

    from fourierjax import fourier, model_io
    from fourierjax.cli._inputs import source_up
    from fourierjax.cli._outputs import write_bvh_as_source
    from fourierjax.errors import UserError

    if args.config:  # the explorer's parameter set (issue 23)
        from fourierjax.cli._synth_config import run_config

        return run_config(args)
    if args.model is None or args.seconds is None:
        raise UserError("MODEL and --seconds S are required (or --config FILE.toml)")
    out = pathlib.Path(args.out)
    if out.suffix.lower() != ".bvh":
        raise UserError(f"--out: {args.out}: expected a .bvh file")
    if not out.parent.exists():
        raise UserError(f"--out: {out.parent}: no such directory")
    if not (math.isfinite(args.seconds) and args.seconds > 0):
        raise UserError(f"--seconds: must be a positive number, got {args.seconds}")
    if args.fps is not None and not (math.isfinite(args.fps) and args.fps > 0):
        raise UserError(f"--fps: must be a positive number, got {args.fps}")
    if not math.isfinite(args.noise) or args.noise < 0:
        raise UserError(f"--noise: must be >= 0 degrees, got {args.noise}")
    adds = [_parse_add(a) for a in args.add]
    mf = model_io.load_model(args.model)
    template = mf.template_motion()
    if template is None:
        raise UserError(f"{args.model}: the model file carries no skeleton to write a BVH on")
    model = mf.model
    if adds:
        from fourierjax import style
        from fourierjax.cli.characteristic import load_characteristic

        read = [load_characteristic(p) for p, _ in adds]
        chars = [c for c, _ in read]
        for (p, _), c in zip(adds, chars, strict=True):
            # Names the representation or the first channel that differs (an expmap model with
            # an Euler characteristic said "96 vs 96 channels").
            style.check_compatible(model, c, names=(f"the model {args.model}", f"--add {p}"))
        weights = jnp.asarray([w for _, w in adds])
        try:
            superposed = style.superpose(model, chars, weights)
        except ValueError as err:
            raise UserError(f"--add: {err}") from None
        if not args.no_speed_limit:
            superposed = _limited(model, superposed, chars, weights, [h for _, h in read], mf, template)
        model = superposed
    if args.noise > 0:
        from fourierjax import style

        if args.noise_harmonics < 1:
            raise UserError(f"--noise-harmonics: must be >= 1, got {args.noise_harmonics}")
        amp = np.where(fourier.angle_channel_mask(model.channel_names), np.radians(args.noise),
                       0.0)
        model = style.add_noise(model, jax.random.key(args.seed), jnp.asarray(amp),
                                harmonics=args.noise_harmonics)
    dt = 1.0 / args.fps if args.fps else (mf.frame_time_s or 1 / 120)
    from fourierjax.cli.interpolate import frame_count

    num = frame_count(args.seconds, dt)
    from fourierjax import _memory, gait

    # Under 100 fps the lock runs on denser frames (`gait.lock_supersampling`).
    dense = num * (gait.lock_supersampling(dt) if getattr(args, "foot_lock", True) else 1)
    _memory.check_synthesis(f"--seconds {args.seconds:g} at {1 / dt:g} fps", dense, model.num_channels,
                            model.num_harmonics)
    from fourierjax.cli._gait_args import apply_gait  # step, speed, hip rule, root motion

    intervals, source = _foot_lock_inputs(mf)
    # An edited model stands on the fitted model's ground: its own root height and stance no
    # longer match its legs (02_01 + 0.5 runness stood 1.9 cm under the captured floor).
    motion, gait_summary = apply_gait(args, model, template, num, dt, getattr(mf, "body_map", None),
                                      contact_intervals=intervals, source=source,
                                      # The capture's knee speed bounds its own model, not an edit.
                                      knee_speed_rad_s=getattr(mf, "knee_speed_rad_s", None) if model is mf.model
                                      else None,
                                      fitted=mf.model if model is not mf.model else None)
    write_bvh_as_source(motion, out, source_up(getattr(mf, "provenance", None) or {}), args.out_up)
    print(f"wrote {out}: {num} frames at {1 / dt:.6g} fps, "
          f"{float(model.omega) / (2 * np.pi):.3f} Hz gait cycle")
    print(gait_summary)
    return 0


def _limited(base, superposed, chars, weights, headers, mf, template):
    """`superposed`, or the superposition with its weights scaled down along their line where a
    joint of it moves faster than in the base and the characteristics' clips (one line said)."""
    import sys

    from fourierjax import style
    from fourierjax.cli._speed_limit import excess, synth_limit

    skeleton, body_map = template.skeleton(), getattr(mf, "body_map", None)
    limit, why = synth_limit(base, skeleton, body_map, headers)
    if limit is None:
        print(f"fourierjax: note: --add without a speed limit: {why}", file=sys.stderr)
        return superposed
    over = excess(superposed, skeleton, body_map, limit)
    if over <= 1.0:
        return superposed
    limited = style.superpose(base, chars, weights, speed_limit=limit)
    print(f"speed limit: a joint would move {over:.2f}x faster than in the base or the characteristics' "
          "clips; the weights were scaled down to stay within them (--no-speed-limit keeps them)")
    return limited


def _foot_lock_inputs(mf):
    """(contact intervals stored with the model or None, the fitted frames of the source clip or
    None): the clip is read again from the path the fit recorded, when it is still there."""
    intervals = getattr(mf, "contact_intervals", None)
    prov = getattr(mf, "provenance", None) or {}
    path = prov.get("path")
    if not path or not pathlib.Path(path).is_file():
        return intervals, None
    from fourierjax.errors import UserError
    from fourierjax.io.bvh import read_bvh

    try:
        clip = read_bvh(path)
    except (UserError, OSError):
        return intervals, None
    lo, hi = prov.get("frame_start"), prov.get("frame_stop")
    if isinstance(lo, int) and isinstance(hi, int) and 0 <= lo < hi <= clip.num_frames and hi - lo >= 2:
        clip = clip[lo:hi]
    if tuple(clip.topology.names) != tuple(mf.topology.names):
        return intervals, None
    # `fit` turned a clip that is not Y up Y-up on reading (a Blender file is Z up); measured
    # as read, the source's skating took a horizontal axis for up (02_03 as Z up: 10.41 units/s
    # against 7.17).
    from fourierjax.body import BodyMapError, infer_body_map
    from fourierjax.io.axes import to_y_up, up_name

    try:
        bm = infer_body_map(clip)
    except BodyMapError:
        return intervals, None
    if (bm.up_axis, bm.up_sign) != (1, 1):
        clip = to_y_up(clip, up_name(bm.up_axis, bm.up_sign))
    return intervals, clip
