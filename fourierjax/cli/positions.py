"""`fourierjax positions`: world positions of every joint for every frame, saved as .npy."""

from __future__ import annotations

import argparse
import io
import pathlib

HELP = "World positions of every joint for every frame of a BVH file, saved as [frames, joints, 3] .npy."


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("file", metavar="FILE.bvh", help="BVH file to read, or a bundled clip name (e.g. 07_01)")
    parser.add_argument("--out", required=True, metavar="P.npy", help="output .npy file")


def run(args: argparse.Namespace) -> int:
    import jax.numpy as jnp
    import numpy as np

    from fourierjax.errors import UserError
    from fourierjax.io.atomic import write_bytes_atomic
    from fourierjax.io.bvh import read_bvh
    from fourierjax.kinematics import joint_positions

    out = pathlib.Path(args.out)
    if out.suffix != ".npy":
        raise UserError(f"--out {args.out}: the output file must end in .npy")
    if not out.parent.exists():
        raise UserError(f"--out {args.out}: folder {out.parent} does not exist")
    from fourierjax.cli._paths import resolve_input

    motion = read_bvh(resolve_input(args.file))
    # float64 keeps the file's precision; FK in float32 would add ~1e-5 units of rounding.
    import jax

    with jax.enable_x64(True):
        pos = joint_positions(motion.skeleton(), jnp.asarray(motion.channels, jnp.float64))
        pos = np.asarray(pos)
    buf = io.BytesIO()
    np.save(buf, pos)
    write_bytes_atomic(out, buf.getvalue())
    print(f"{out}: {pos.shape[0]} frames x {pos.shape[1]} joints x 3 ({motion.source})")
    return 0
