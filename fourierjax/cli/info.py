"""`fourierjax info`: a summary of a BVH file (skeleton, channels, frames, timing, body map and units)."""

from __future__ import annotations

import argparse
import collections
import json

HELP = ("Summarise a BVH file: joints, channels, frames, frame time, duration, rotation orders, "
        "and the inferred body map (legs, feet, trajectory, up axis, units).")


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("file", metavar="FILE.bvh", help="BVH file to read")
    parser.add_argument(
        "--json", action="store_true", help="print one JSON object instead of a table"
    )


def summary(motion) -> dict:
    """The facts `info` prints, as a JSON-serialisable dict (see `run`)."""
    from fourierjax.data import detect_rest_frames

    topo = motion.topology
    orders = collections.Counter(o or "none" for o in topo.rotation_orders)
    return {
        "file": motion.source,
        "joints": topo.num_joints,
        "end_sites": topo.num_end_sites,
        "channels": topo.num_channels,
        "frames": motion.num_frames,
        "frame_time_s": motion.frame_time_s,
        "fps": motion.fps,
        "duration_s": motion.duration_s,
        "rotation_orders": dict(orders.most_common()),
        "joints_with_position_channels": sum(
            any(c.endswith("position") for c in chans) for chans in topo.channels
        ),
        "root": topo.names[0],
        "leading_rest_frames": detect_rest_frames(motion),
        **_body_summary(motion),
    }


def _body_summary(motion) -> dict:
    """The inferred body map (`BodyMap.to_dict`, its `describe()` lines) and units, or why not."""
    from fourierjax.body import BodyMapError, infer_body_map

    try:
        bm = infer_body_map(motion)
    except BodyMapError as err:
        return {"body_map": None, "body_map_error": str(err), "units": None, "metres_per_unit": None}
    return {"body_map": bm.to_dict(), "body_map_description": bm.describe(), "units": bm.units,
            "metres_per_unit": bm.metres_per_unit}


def run(args: argparse.Namespace) -> int:
    from fourierjax.cli._paths import resolve_input
    from fourierjax.io.bvh import read_bvh

    path = resolve_input(args.file)
    info = summary(read_bvh(path))
    if args.json:
        print(json.dumps(info))
        return 0
    orders = ", ".join(f"{o} x{n}" for o, n in info["rotation_orders"].items())
    rest = info["leading_rest_frames"]
    rows = [
        ("file", info["file"]),
        ("joints", f"{info['joints']} (root {info['root']!r}; End Sites not counted)"),
        ("end sites", info["end_sites"]),
        ("channels", f"{info['channels']} per frame"),
        ("position channels", f"on {info['joints_with_position_channels']} joint(s)"),
        ("rotation orders", orders),
        ("frames", info["frames"]),
        ("frame time", f"{info['frame_time_s']:g} s"),
        ("fps", f"{info['fps']:.4f}"),
        ("duration", f"{info['duration_s']:.3f} s"),
    ]
    if rest:
        rows.append(("rest frames", f"{rest} leading synthetic/rest frame(s) (T-pose or zeros)"))
    if info["body_map"] is not None:
        rows.append(("units", f"{info['units']} ({info['metres_per_unit']:g} m per unit)"))
    width = max(len(k) for k, _ in rows)
    for key, value in rows:
        print(f"{key + ':':<{width + 1}} {value}")
    if info["body_map"] is None:
        why = info["body_map_error"].split(". Its joints are")[0]  # the reason, one line
        print(f"body map: none: {why} (see --json for how to write one)")
    else:
        print("body map (inferred; override with fit --body-map FILE):")
        for line in info["body_map_description"].splitlines():
            print(f"  {line}")
    return 0
