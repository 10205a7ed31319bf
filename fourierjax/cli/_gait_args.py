"""Step-constraint flags of `fourierjax synth` (Unuma 1995 §3.1): step, speed, gait, jump, hip rule."""

from __future__ import annotations

import argparse
import functools
import math

#: `gait.RULES`, repeated so that building the parser does not import JAX (a test checks they agree).
RULES = ("unuma1995", "continuous", "smooth")


def add_gait_arguments(parser: argparse.ArgumentParser) -> None:
    """Add `--step --speed --gait --jump --hip-rule --root-motion/--no-root-motion`."""
    g = parser.add_argument_group(
        "step constraints (Unuma 1995 §3.1)",
        "The defaults reproduce the model's own joint angles; with root motion (the default) "
        "the root height comes from the hip-height rule and its path from the feet on the "
        "ground; with foot locking (the default) the feet are then planted where they land "
        "(two-bone leg IK). The summary's foot skating is the mean horizontal speed of foot "
        "points within 2% of the body height of the floor, for the synthesized motion and the "
        "source clip side by side.",
    )
    g.add_argument("--step", type=float, default=1.0, metavar="S",
                   help="scale of every harmonic amplitude A_n, n >= 1 (step length; default 1)")
    g.add_argument("--speed", type=float, default=1.0, metavar="V",
                   help="pace through the gait cycle, 1 = as captured (default 1; 0 stands)")
    g.add_argument("--gait", type=float, default=1.0, metavar="G",
                   help="flight where N(t) = (Lmax - L)/Lmax exceeds G, in [0, 1] "
                   "(default 1: never, a walk). N stays small: it peaks at 0.03-0.09 on the "
                   "bundled CMU walks and runs (09_01: 0.086), so useful values are ~0.03-0.08; "
                   "the summary line prints the model's peak")
    g.add_argument("--jump", type=float, default=0.0, metavar="J",
                   help="flight height: eq. 5 adds J*sqrt(Lmax - L), J in sqrt(file units) "
                   "(default 0)")
    g.add_argument("--hip-rule", choices=RULES, default="unuma1995",
                   help="unuma1995 (eq. 5 as written, jumps at the threshold), continuous "
                   "(no jump) or smooth (differentiable, for fitting gait and jump: its sigmoid "
                   "also lifts frames just below the threshold, so stance feet float); default "
                   "unuma1995")
    g.add_argument("--body-map", default=None, metavar="FILE",
                   help="TOML body map (legs, feet, up; `fourierjax info` prints the inferred one) "
                   "overriding the map inferred from the model's poses")
    g.add_argument("--root-motion", action=argparse.BooleanOptionalAction, default=True,
                   help="root height from the hip rule and root path from the stance feet "
                   "(default on); --no-root-motion keeps the model's own root channels")
    add_path_argument(g)
    add_foot_lock_arguments(g)


def add_path_argument(group) -> None:
    """`--path`: walk along a ground-plane path (issue #21)."""
    group.add_argument("--path", default=None, metavar="PATH",
                       help="walk along a path in the ground plane at the model's speed: circle:R "
                       "(R in metres, turning left; circle:-R turns right), or a .toml/.json file with "
                       "points = [[x, z], ...] in metres (closed = true to go round), or "
                       "arc = {radius = R, angle_deg = A} (then straight on); corners are rounded over a "
                       "quarter of the leg length either side")


def parse_path(text: str, metres_per_unit: float):
    """A `gait.GroundPath` in file units from `--path` (metres: `circle:R`, or a TOML/JSON file)."""
    import json
    import pathlib
    import tomllib

    import numpy as np

    from fourierjax import gait
    from fourierjax.errors import UserError

    scale = 1.0 / float(metres_per_unit)
    if text.startswith("circle:"):
        try:
            r = float(text.partition(":")[2])
        except ValueError:
            raise UserError(f"--path: {text!r}: expected circle:R with R in metres, e.g. circle:3") from None
        if not (math.isfinite(r) and r != 0):
            raise UserError(f"--path: {text!r}: the radius must be a finite non-zero number of metres")
        return gait.circle_path(abs(r) * scale, left=r > 0)
    path = pathlib.Path(text)
    if not path.is_file():
        raise UserError(f"--path: {text}: not circle:R and no such file")
    try:
        raw = path.read_text()
        spec = json.loads(raw) if path.suffix.lower() == ".json" else tomllib.loads(raw)
    except (OSError, ValueError) as err:
        raise UserError(f"--path: {text}: cannot read it ({err})") from None
    if "arc" in spec:
        arc = spec["arc"]
        try:
            r, a = float(arc["radius"]), np.radians(float(arc["angle_deg"]))
        except (KeyError, TypeError, ValueError):
            raise UserError(f"--path: {text}: arc needs radius (metres) and angle_deg") from None
        if not (math.isfinite(r) and r > 0 and math.isfinite(a)):
            raise UserError(f"--path: {text}: arc radius must be > 0 and angle_deg finite")
        th = np.linspace(0.0, abs(a), max(8, int(abs(a) / (np.pi / 128)) + 1))
        side = 1.0 if a > 0 else -1.0
        return gait.polyline_path(np.stack([side * r * (1 - np.cos(th)), r * np.sin(th)], 1) * scale)
    if "points" not in spec:
        raise UserError(f"--path: {text}: expected `points = [[x, z], ...]` (metres) or `arc = {{...}}`")
    try:
        pts = np.asarray(spec["points"], np.float64)
    except (TypeError, ValueError):
        raise UserError(f"--path: {text}: `points` must be a list of [x, z] pairs (metres)") from None
    if pts.ndim != 2 or pts.shape[1] != 2:
        raise UserError(f"--path: {text}: `points` must be a list of [x, z] pairs, got shape {pts.shape}")
    return gait.polyline_path(pts * scale, closed=bool(spec.get("closed", False)))


def add_foot_lock_arguments(group, default: bool = True, why: str = "") -> None:
    """Add `--foot-lock/--no-foot-lock` (issue 21) to a group; `default` on unless said."""
    group.add_argument("--foot-lock", action=argparse.BooleanOptionalAction, default=default,
                       help="plant the feet where they land (two-bone leg IK, heel-to-toe roll; "
                       f"default {'on' if default else 'off'}{why}); --no-foot-lock keeps the step "
                       "constraints' frames")


def _check(args) -> None:
    from fourierjax.errors import UserError

    for name in ("step", "speed", "gait", "jump"):
        v = getattr(args, name)
        if not math.isfinite(v):
            raise UserError(f"--{name}: must be a finite number, got {v}")
    if args.step < 0:
        raise UserError(f"--step: must be >= 0, got {args.step}")
    if args.speed < 0:
        raise UserError(f"--speed: must be >= 0, got {args.speed}")
    if not 0.0 <= args.gait <= 1.0:
        raise UserError(f"--gait: must be in [0, 1], got {args.gait}")
    if args.jump < 0:
        raise UserError(f"--jump: must be >= 0, got {args.jump}")


def body_map_for(model, template, body_map=None, path=None):
    """The body map of a synthesis: `body_map` (e.g. stored with the model) when given, else the
    map of the model's own cycle, with the TOML file `path` (`--body-map`) overriding fields."""
    from fourierjax import gait

    if body_map is not None and path is None:
        return body_map
    return gait.model_body_map(model, template.skeleton(), overrides=path)


@functools.cache
def _skating():
    """`gait.contact_skating` as one saved program (`fourierjax._saved`): run eagerly, it was
    about 25 small programs per call, each traced, lowered and read from the compile cache on
    every call of the command."""
    from fourierjax import gait
    from fourierjax._jit import filter_jit
    from fourierjax._saved import saved

    return saved(filter_jit(gait.contact_skating))


def skating_summary(result, frame_time_s: float, bmap, source=None) -> str:
    """The summary's foot skating (issue 21's metric: horizontal speed of foot points within 2% of
    the body height of the floor), of the synthesized motion and of `source` (the fitted frames of
    the source clip, a `Motion`, or None when it is not at hand), side by side."""
    skating = _skating()
    ours = float(skating(result.foot_positions, frame_time_s, body_map=bmap).mean_speed)
    text = f"foot skating {ours:.2f} units/s"
    if source is None:
        return text + " (source clip not found: not compared)"
    from fourierjax.motion import foot_positions_of

    theirs = float(skating(foot_positions_of(source, body_map=bmap), source.frame_time_s,
                           body_map=bmap).mean_speed)
    return text + f" against {theirs:.2f} units/s in the source clip"


def apply_gait(args, model, template, num_frames: int, frame_time_s: float, body_map=None, *,
               contact_intervals=None, source=None, fitted=None, knee_speed_rad_s=None):
    """Synthesize `num_frames` under the step constraints, on any rig the body map understands.

    Arguments:
        args: the parsed flags of `add_gait_arguments`.
        model: a `FourierModel` on the template's skeleton.
        template: a `Motion` supplying the skeleton.
        num_frames: frames to synthesize.
        frame_time_s: seconds per frame.
        body_map: a `body.BodyMap` of the skeleton (e.g. stored in the model file); default the
            map of the model's own poses (`--body-map FILE` overrides its fields).
        contact_intervals: `[2, 2]` contact phases stored with the model (None: estimated).
        source: the fitted frames of the source clip (a `Motion`) for the skating comparison.
        fitted: the fitted model `model` was edited from (`--add`, `--noise`), or None: its
            ground (floor and sole clearances, `gait.model_ground`) is the synthesis's.
        knee_speed_rad_s: `[2]` the source clip's largest knee speed stored with the model
            (`gait.fit_knee_speed`): the foot lock's cap on the swing's knee; None: no cap.

    Returns:
        `(motion, summary line)`.
    """
    import numpy as np

    from fourierjax import gait
    from fourierjax.io.gait_bvh import gait_motion

    _check(args)
    bmap = body_map_for(model, template, body_map, getattr(args, "body_map", None))
    floor = clearance = None
    if fitted is not None:
        floor, clearance = gait.model_ground(fitted, template.skeleton(), body_map=bmap)
    result = gait.synthesize_gait(
        model, template.skeleton(), num_frames, frame_time_s, body_map=bmap,
        step=args.step, speed=args.speed, gait=args.gait, jump=args.jump, rule=args.hip_rule,
        root_motion=args.root_motion, foot_lock=getattr(args, "foot_lock", True),
        contact_intervals=contact_intervals, floor=floor, clearance=clearance, knee_speed_rad_s=knee_speed_rad_s,
        path=None if getattr(args, "path", None) is None else parse_path(args.path, bmap.metres_per_unit),
    )
    # The summary's numbers all come from the one GaitResult (no second pass through the model):
    # on a path, the walk is bent onto it before the feet are locked, and measured after both.
    motion = gait_motion(template, result, model.channel_names, frame_time_s, body_map=bmap)
    root = np.asarray(result.root_position)  # on the host: indexing on the device is 3 programs
    advance = root[-1] - root[0]
    advance[bmap.up_axis] = 0.0
    if args.root_motion:
        n_peak = float(np.max(np.asarray(result.hip.N)))
        # Both feet off the ground (the hip rule's ground is the model's captured floor).
        # The hip rule's flight frames (N(t) > gait): the foot lock may lift a foot a leg
        # cannot reach, which is not flight.
        flight = float(np.mean(np.asarray(result.hip.flight) > 0.5))
        flight_text = (f"flight {100 * flight:.1f}% of frames (N(t) peaks at {n_peak:.3f}: "
                       "--gait below that gives flight)")
    else:  # the model's own root height: no ground is enforced, so no flight to count
        flight_text = "flight not measured (the model's own root height)"
    summary = (
        f"step constraints: hip rule {args.hip_rule}, root motion "
        f"{'on' if args.root_motion else 'off'}; {flight_text}, "
        f"{skating_summary(result, frame_time_s, bmap, source)}, root advance "
        f"{float(np.linalg.norm(advance)):.1f} units, foot lock "
        f"{'on' if getattr(args, 'foot_lock', True) else 'off'}"
    )
    return motion, summary
