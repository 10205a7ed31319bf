"""Experiment (d): Neff & Fiume 2004 posture range and recoil sets; gradient solver vs reference.

For each shape set and intensity, one batched gradient-based solve (`stance.solver.solve_stances`,
BFGS with balance and analytic IK inside) and, for comparison, the paper's method: coordinate
direction-set with Brent line minimisation (`benchmarks.stance_reference.solve_reference`, scipy Powell).
Reported per problem: objective (eq. 5) of both, iterations of both, COM error, and the time per
solve. Recoil sets use an object 0.7 m ahead, 0.4 m to the left, at 1.2 m.

Writes ``stance.{csv,json,md}``, ``solver_summary.json`` and one ``posture_range_<set>.png`` each.
"""

from __future__ import annotations

import json
import time

import numpy as np

from experiments._util import parse, run_main, write_table

OBJECT = (0.4, 1.2, 0.7)


def body(argv=None) -> None:
    import jax
    import jax.numpy as jnp

    from fourierjax import viz
    from fourierjax.io.stance_bvh import pose_to_motion
    from fourierjax.motion import motion_joint_positions
    from fourierjax.stance.shape_sets import get_shape_set
    from fourierjax.stance.skeleton48 import make_body
    from fourierjax.stance.solver import solve_stances, stack_problems

    cfg, out = parse("stance", __doc__.splitlines()[0], argv)
    from fourierjax import enable_compile_cache

    enable_compile_cache()  # the solver compiles slowly: share it with the demo and notebook
    body_ = make_body(1.75)
    problems, labels = [], []
    for name in cfg["shape_sets"]:
        ss = get_shape_set(name)
        obj = jnp.asarray(OBJECT) if ss.object_mode != "none" else None
        for i in cfg["intensities"]:
            problems.append(ss.problem(body_, i, obj))
            labels.append((name, i))
    batch = stack_problems(problems)
    t0 = time.perf_counter()
    sol = jax.block_until_ready(solve_stances(batch))
    first = time.perf_counter() - t0
    t0 = time.perf_counter()
    sol = jax.block_until_ready(solve_stances(batch))
    per_solve = (time.perf_counter() - t0) / len(problems)
    ref = {}
    if cfg["reference"]:
        from experiments.benchmarks.stance_reference import solve_reference

        for k in range(min(len(problems), cfg["reference_max_problems"])):
            ref[k] = solve_reference(problems[k])
    rows = []
    for k, (name, i) in enumerate(labels):
        r = ref.get(k)
        rows.append({"shape_set": name, "intensity": i, "converged": bool(sol.converged[k]),
                     "iterations": int(sol.iterations[k]), "objective": float(sol.objective[k]),
                     "com_error_mm": 1000 * float(sol.com_error_m[k]),
                     "ref_objective": None if r is None else float(r["objective"]),
                     "ref_iterations": None if r is None else int(r["iterations"]),
                     "ref_evaluations": None if r is None else int(r["evaluations"]),
                     "ref_seconds": None if r is None else float(r["seconds"]),
                     "gradient_no_worse": None if r is None else bool(
                         float(sol.objective[k]) <= float(r["objective"]) + 1e-6)})
    md = write_table(rows, out, "stance", "Stance solves: gradient (BFGS, batched) vs "
                     "direction-set reference (Powell/Brent)")
    summary = {"problems": len(problems), "batched_first_call_s": first,
               "batched_s_per_solve": per_solve, "solves_per_s": 1 / per_solve,
               "reference_mean_s": float(np.mean([r["seconds"] for r in ref.values()])) if ref else None,
               "all_converged": bool(np.all(np.asarray(sol.converged))),
               "gradient_no_worse_everywhere": all(r["gradient_no_worse"] for r in rows
                                                   if r["gradient_no_worse"] is not None)}
    (out / "solver_summary.json").write_text(json.dumps(summary, indent=1))
    print(md, json.dumps(summary, indent=1), sep="\n\n")
    motion = pose_to_motion(body_, sol.pose)
    pos = motion_joint_positions(motion)
    topo = motion.topology
    for name in cfg["shape_sets"]:
        idx = [k for k, (n, _) in enumerate(labels) if n == name]
        fig = viz.plot_posture_range([pos[k] for k in idx], topo.parents,
                                     [labels[k][1] for k in idx], names=topo.names,
                                     azimuth_deg=90.0 if name == "beauty_line" else 15.0,
                                     title=f"Shape set '{name}': intensity under each figure")
        viz.save_figure(fig, out / f"posture_range_{name}.png")


def main(argv=None) -> int:
    return run_main(body, argv)


if __name__ == "__main__":
    raise SystemExit(main())
