"""Foot locking for a crowd: frames/s of `crowd_positions` with and without `foot_lock`, same run."""

from __future__ import annotations

from experiments.benchmarks._common import Record


def lock_record(size: str) -> Record:
    """`crowd_lock_10k`: the crowd with foot locking (ours) against the plain crowd (baseline),
    timed in alternating calls (one of each per round) so that the shared machine's load falls on
    both alike; also the lock alone on a posed frame, and the old two-dispatch form."""
    import time

    import jax
    import jax.numpy as jnp
    import numpy as np

    from experiments.benchmarks.crowd import crowd_models
    from experiments.benchmarks.synthesis import _interleaved
    from fourierjax import crowd as crowd_mod
    from fourierjax import data, gait
    from fourierjax._gait import crowdlock
    from fourierjax.body import infer_body_map

    B = 10_000 if size == "full" else 64
    repeats = 30 if size == "full" else 2
    skel, models = crowd_models(B)
    crowd = crowd_mod.make_crowd(skel, models)
    bm = infer_body_map(data.load("07_01"))
    rng = np.random.default_rng(0)
    start = rng.uniform(0, 2 * np.pi, (B, 2))
    iv = jnp.asarray(np.stack([start, start + 3.8], -1), jnp.float32)  # 60% of the cycle in stance
    clock = {"t": 0.0, "s": None, "s2": None}

    def tick():
        clock["t"] += 1 / 60
        return jnp.float32(clock["t"])

    def plain():
        return crowd_mod.crowd_positions(crowd, tick())

    def locked():
        p, clock["s"] = crowd_mod.crowd_positions(crowd, tick(), foot_lock=True, body_map=bm, intervals=iv,
                                                  state=clock["s"])
        return p

    def two_dispatches():  # the crowd's positions, then gait.lock_crowd on them: two programs
        t = tick()
        p, clock["s2"] = gait.lock_crowd(crowd_mod.crowd_positions(crowd, t), crowd.omega * t, iv, clock["s2"],
                                         body_map=bm, parents=skel.topology.parents)
        return p

    t0 = time.perf_counter()
    jax.block_until_ready(locked())
    first_call_s = time.perf_counter() - t0
    plan = crowdlock.lock_plan(bm, skel.topology.parents, skel.topology.num_joints)
    pose = jax.jit(crowd_mod._pose)(crowd, jnp.float32(0.5))
    args = crowdlock.check_inputs("bench", plan, B, jnp.float32, crowd.omega * 0.5, iv, None, None, None)
    lock_alone = jax.jit(crowdlock.lock_pose, static_argnames=("plan",))

    stats, _ = _interleaved({
        "locked": locked, "plain": plain, "two_dispatches": two_dispatches,
        "lock_alone": lambda: lock_alone(pose, *args, plan=plan),
    }, repeats, warmup=2)
    ours, base = 1.0 / stats["locked"]["median"], 1.0 / stats["plain"]["median"]
    ms = {k: 1e3 * v["median"] for k, v in stats.items()}
    rec = Record(
        "crowd_lock_10k", ours, base, "animation frames/s", target=60.0, target_on="ours",
        description=f"{B} characters: crowd.crowd_positions(foot_lock=True), the crowd's synthesis, FK and "
                    "foot lock (held foot points, two-bone leg IK on positions) in one jitted call per frame",
        baseline_name="crowd.crowd_positions alone (no locking), alternating calls in the same run",
        ours_stats=stats["locked"], baseline_stats=stats["plain"],
        details={"characters": B, "first_call_s": first_call_s,
                 "ms_per_frame_locked": ms["locked"], "ms_per_frame_plain": ms["plain"],
                 "lock_cost_ms": ms["locked"] - ms["plain"],
                 "lock_alone_ms": ms["lock_alone"],
                 "two_dispatches_frames_per_s": 1.0 / stats["two_dispatches"]["median"],
                 "min_ms": {k: 1e3 * v["min"] for k, v in stats.items()}},
        notes=["the machine is shared: compare the ratio, not the rates"])
    return rec.finish()


def run(size: str) -> list[Record]:
    return [lock_record(size)]
