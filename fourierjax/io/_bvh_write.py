"""BVH writing: canonical text of a `Motion`, written whole or not at all."""

from __future__ import annotations

import os

import numpy as np

from fourierjax.errors import UserError
from fourierjax.io._bvh_motion import Motion, _show
from fourierjax.io.atomic import write_bytes_atomic
from fourierjax.skeleton import Topology


def _check_writable(topology: Topology) -> None:
    """BVH stores joints depth first: each joint's parent must be on the current path."""
    path: list[int] = []
    for i, p in enumerate(topology.parents):
        while path and path[-1] != p:
            path.pop()
        if p >= 0 and not path:
            raise UserError(
                f"format_bvh: joint {topology.names[i]!r} is not in depth-first order "
                "(BVH lists every joint right after its parent's earlier subtree); reorder "
                "the topology before writing"
            )
        path.append(i)
    for name in topology.names:
        if (
            not name
            or name != " ".join(name.split())
            or "{" in name
            or "}" in name
        ):
            raise UserError(f"format_bvh: joint name {_show(name)} cannot be written to BVH")


def format_bvh(motion: Motion, precision: int = 6) -> str:
    """The BVH text of `motion` (LF line endings, tab indents, canonical channel names).

    Arguments:
        motion: the clip; needs at least one frame and finite values.
        precision: digits after the decimal point for offsets and channel values.

    Returns:
        the file contents. `parse_bvh(format_bvh(m))` gives the same topology and
        the same values to within `0.5 * 10**-precision`; the frame time round-trips exactly.
    """
    if not isinstance(motion, Motion):
        raise TypeError(f"format_bvh expects a Motion, got {type(motion).__name__}")
    if isinstance(precision, bool) or not isinstance(precision, int) or not 0 <= precision <= 17:
        raise UserError(f"format_bvh: `precision` must be an int in [0, 17], got {precision!r}")
    if motion.num_frames == 0:
        raise UserError("format_bvh: the motion has no frames (BVH needs at least one)")
    if motion.num_channels == 0:
        raise UserError("format_bvh: the topology has no channels")
    for what, arr in (
        ("offsets", motion.offsets),
        ("end_site_offsets", motion.end_site_offsets),
        ("channels", motion.channels),
    ):
        if not np.isfinite(arr).all():
            raise UserError(f"format_bvh: `{what}` holds NaN or infinite values")
    topo = motion.topology
    _check_writable(topo)

    f = f"%.{precision}f"
    out = ["HIERARCHY"]
    ends = topo.end_site_parents
    next_end = 0

    def offset_line(depth, xyz):
        return "\t" * depth + "OFFSET " + " ".join(f % float(v) for v in xyz)

    def write_end_sites(joint, depth):
        # End Sites of `joint` that come next in file order; writing them here keeps their order.
        nonlocal next_end
        while next_end < len(ends) and ends[next_end] == joint:
            tabs = "\t" * depth
            out.extend([tabs + "End Site", tabs + "{"])
            out.append(offset_line(depth + 1, motion.end_site_offsets[next_end]))
            out.append(tabs + "}")
            next_end += 1

    depths = topo.depths
    open_joints: list[int] = []
    for i, p in enumerate(topo.parents):
        while open_joints and open_joints[-1] != p:
            j = open_joints.pop()
            write_end_sites(j, depths[j] + 1)
            out.append("\t" * depths[j] + "}")
        if p >= 0:
            write_end_sites(p, depths[p] + 1)
        tabs = "\t" * depths[i]
        out.append(f"{tabs}{'ROOT' if p < 0 else 'JOINT'} {topo.names[i]}")
        out.append(tabs + "{")
        out.append(offset_line(depths[i] + 1, motion.offsets[i]))
        chans = topo.channels[i]
        out.append(f"{tabs}\tCHANNELS {len(chans)}" + "".join(" " + c for c in chans))
        open_joints.append(i)
    while open_joints:
        j = open_joints.pop()
        write_end_sites(j, depths[j] + 1)
        out.append("\t" * depths[j] + "}")
    if next_end != len(ends):
        raise UserError(
            "format_bvh: the End Sites are not in file order (each joint's End Sites must "
            "follow the End Sites of the joints written before it)"
        )
    out.append("MOTION")
    out.append(f"Frames: {motion.num_frames}")
    out.append(f"Frame Time: {motion.frame_time_s!r}")
    row = " ".join([f] * motion.num_channels)
    out.extend(row % tuple(r) for r in motion.channels.tolist())
    out.append("")
    return "\n".join(out)


def write_bvh(motion: Motion, path: str | os.PathLike, precision: int = 6) -> None:
    """Write `motion` to `path` as BVH (see `format_bvh`); UTF-8, LF line endings, written
    completely or not at all (`io.atomic`)."""
    # Whole or nothing: a write that fails (disk full, size limit) leaves no truncated file.
    write_bytes_atomic(path, format_bvh(motion, precision).encode("utf-8"))
