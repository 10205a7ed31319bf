"""`fourierjax stance`: solve an expressive stance from a shape set and write it as BVH."""

import argparse
import functools
import json
import math
import os
import sys

HELP = "Solve an expressive stance (Neff & Fiume 2004 shape sets) and write the pose as BVH."


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--list", action="store_true", help="list the shape sets and exit")
    parser.add_argument(
        "--shape-set", metavar="NAME", help="built-in shape set name, or a .toml shape set file"
    )
    parser.add_argument(
        "--intensity", type=str, default="1.0", help="the intensity knob (0 = neutral; default 1)"
    )
    parser.add_argument(
        "--object", metavar="X,Y,Z", help="world position of the object reacted to (m; the "
        "character stands at the origin facing +Z, Y up, its right hand on the -X side)"
    )
    parser.add_argument(
        "--target",
        metavar="X,Y,Z",
        help="world wrist target to reach (m); write --target=-0.3,1.1,0.5 when X is negative",
    )
    parser.add_argument(
        "--hand", choices=("left", "right"), default="right", help="hand that reaches (default right)"
    )
    parser.add_argument("--height", type=str, default="1.75", help="character height in m")
    parser.add_argument("--out", metavar="POSE.bvh", help="BVH file to write")
    parser.add_argument("--json", action="store_true", help="print one JSON object with the result")


def _number(text: str, what: str) -> float:
    from fourierjax.errors import UserError

    try:
        v = float(text)
    except ValueError:
        raise UserError(f"{what}: expected a number, got {text!r}") from None
    if not math.isfinite(v):
        raise UserError(f"{what}: must be finite, got {text!r}")
    return v


def _point(text: str | None, what: str):
    from fourierjax.errors import UserError

    if text is None:
        return None
    parts = text.split(",")
    if len(parts) != 3:
        raise UserError(f"{what}: expected three coordinates x,y,z in metres, got {text!r}")
    return [_number(p.strip(), what) for p in parts]


def _array(xyz, body):
    import numpy as np

    return None if xyz is None else np.asarray(xyz, body.offsets.dtype)


@functools.cache
@functools.cache
def _build_problem():
    """`shape_set.problem` as one jitted program (built eagerly, it was about 80 small ones, each
    traced, lowered and read from the compile cache on every call of the command), saved
    (`fourierjax._saved`: a warm call skips its trace)."""
    from fourierjax._jit import filter_jit
    from fourierjax._saved import saved

    def build(shape_set, body, intensity, obj, target, hand):
        kw = {f"target_{hand}": target} if target is not None else {}
        return shape_set.problem(body, intensity, obj, **kw)

    return saved(filter_jit(build))


@functools.cache
def _solver():
    """`solve_stance`, saved (`fourierjax._saved`): its trace is most of a warm call."""
    from fourierjax._saved import saved
    from fourierjax.stance.solver import solve_stance

    return saved(solve_stance)


def run(args: argparse.Namespace) -> int:
    from fourierjax.errors import UserError
    from fourierjax.stance.shape_sets import builtin_shape_sets, get_shape_set

    if args.list:
        obj = {"none": "", "optional": " [--object optional]", "required": " [needs --object]"}
        lines = [f"{n}\t{s.description}{obj[s.object_mode]}" for n, s in builtin_shape_sets().items()]
        try:
            print("\n".join(lines))
            sys.stdout.flush()
        except BrokenPipeError:  # `fourierjax stance --list | head -1`
            os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return 0
    if not args.shape_set:
        raise UserError("--shape-set is required (see `fourierjax stance --list`)")
    if not args.out:
        raise UserError("--out POSE.bvh is required")
    if not args.out.lower().endswith(".bvh"):  # a BVH under another name: `synth` would refuse it
        raise UserError(f"--out: {args.out}: expected a .bvh file")
    intensity = _number(args.intensity, "--intensity")
    height = _number(args.height, "--height")
    obj = _point(args.object, "--object")
    target = _point(args.target, "--target")
    shape_set = get_shape_set(args.shape_set)
    if shape_set.needs_object and obj is None:
        raise UserError(f"shape set {shape_set.name!r} needs --object x,y,z")
    if shape_set.object_mode == "none" and obj is not None:
        raise UserError(f"--object: shape set {shape_set.name!r} takes no object (it would be "
                        "ignored); `fourierjax stance --list` marks the sets that do")
    out_dir = os.path.dirname(os.path.abspath(args.out))
    if not os.path.isdir(out_dir):
        raise UserError(f"--out: directory {out_dir} does not exist")

    from fourierjax._compile_cache import enable_compile_cache

    enable_compile_cache()
    import numpy as np

    from fourierjax.io.stance_bvh import write_stance_bvh
    from fourierjax.stance.skeleton48 import make_body
    try:
        body = make_body(height)
    except UserError as err:
        raise UserError(f"--height: {err}") from None
    problem = _build_problem()(shape_set, body, np.asarray(intensity, body.offsets.dtype),
                               _array(obj, body), _array(target, body), args.hand)
    # The checks `shape_set.problem` makes on known values, made on the built problem.
    shape_set.check_shape(np.asarray(problem.shape), intensity, obj)
    sol = _solver()(problem)
    hand = 0 if args.hand == "right" else 1
    if not np.isfinite(np.asarray(sol.pose.quats)).all():
        raise UserError("the solver produced an invalid pose (NaN); try a smaller intensity")
    write_stance_bvh(args.out, body, sol.pose)
    from fourierjax.stance.problem import AMPLITUDES

    result = {
        "shape_set": shape_set.name,
        "intensity": intensity,
        "converged": bool(sol.converged),
        "iterations": int(sol.iterations),
        "objective": float(sol.objective),
        # NumPy indexing: indexing a JAX array eagerly is one more program.
        "reach_error_m": None if target is None else float(np.asarray(sol.reach_error_m)[hand]),
        "reach_gap_m": None if target is None else float(np.asarray(sol.reach_gap_m)[hand]),
        "com_error_m": float(sol.com_error_m),
        "amplitudes": {k: float(v) for k, v in zip(AMPLITUDES, np.asarray(sol.amplitudes))},
        "balance_offsets_rad": [float(v) for v in np.asarray(sol.balance_xz)],
        "out": args.out,
    }
    if args.json:
        print(json.dumps(result))
    else:
        msg = f"wrote {args.out}: {shape_set.name} at intensity {intensity:g}"
        msg += f", objective {result['objective']:.4g}, COM error {result['com_error_m']:.2e} m"
        if target is not None:
            gap = result["reach_gap_m"]
            msg += f", reach error {result['reach_error_m']:.2e} m"
            if gap and gap > 0:
                msg += f" (target {gap:.3f} m beyond the arm: pointing at it)"
        print(msg, file=sys.stdout)
    return 0
