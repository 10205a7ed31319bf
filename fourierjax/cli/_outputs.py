"""BVH written by the commands keeps the up axis of the file it came from (issue 20).

Every clip is turned Y-up on reading (`fourierjax.cli._inputs.read_clip`) and every model is
Y-up; a BVH written from a model of a Z-up file (Blender) is turned back to Z-up, unless the
user asks for another axis with ``--out-up``.
"""

from __future__ import annotations

import argparse
import sys

UP_AXES = ("y", "z", "-z", "x", "-x", "-y")


def add_out_up_argument(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--out-up", default=None, metavar="AXIS", type=str.lower, choices=UP_AXES,
                        help="up axis of the written BVH (y, z, -z, ...; default: that of the "
                        "file the model was fitted from, e.g. z for a Blender export)")


def write_bvh_as_source(motion, out, up: str = "y", out_up: str | None = None) -> str:
    """Write ``motion`` (Y-up) to the BVH file ``out`` with ``out_up`` as its up axis, or the
    source's ``up`` when None; a one-line notice when that is not Y. Returns the axis written."""
    from fourierjax.io.axes import from_y_up
    from fourierjax.io.bvh import write_bvh

    axis = (out_up or up or "y").lower().lstrip("+")
    if axis != "y":
        motion = from_y_up(motion, axis)
        if out_up is None:
            print(f"fourierjax: notice: {out}: written {axis}-up like its source "
                  "(--out-up y writes it Y-up)", file=sys.stderr)
    write_bvh(motion, out)
    return axis
