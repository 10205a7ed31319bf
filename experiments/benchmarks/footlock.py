"""Foot locking for a crowd: frames/s of `crowd_positions` with and without `gait.lock_crowd`."""

from __future__ import annotations

from experiments.benchmarks._common import Record, timeit


def run(size: str) -> list[Record]:
    import jax
    import jax.numpy as jnp
    import numpy as np

    from experiments.benchmarks.crowd import crowd_models
    from fourierjax import crowd as crowd_mod
    from fourierjax import data
    from fourierjax.body import infer_body_map

    B = 10_000 if size == "full" else 64
    repeats = 10 if size == "full" else 2
    skel, models = crowd_models(B)
    crowd = crowd_mod.make_crowd(skel, models)
    bm = infer_body_map(data.load("07_01"))
    rng = np.random.default_rng(0)
    start = rng.uniform(0, 2 * np.pi, (B, 2))
    iv = jnp.asarray(np.stack([start, start + 3.8], -1), jnp.float32)  # 60% of the cycle in stance
    state = {"s": None, "t": 0.0}

    def plain():
        state["t"] += 1 / 60
        return crowd_mod.crowd_positions(crowd, jnp.float32(state["t"]))

    def locked():
        state["t"] += 1 / 60
        t = jnp.float32(state["t"])
        p, state["s"] = crowd_mod.crowd_positions(crowd, t, foot_lock=True, body_map=bm, intervals=iv,
                                                  state=state["s"])
        return p

    jax.block_until_ready(plain())
    jax.block_until_ready(locked())
    t_plain = timeit(plain, repeats)
    t_lock = timeit(locked, repeats)
    ours, base = 1.0 / t_lock["median"], 1.0 / t_plain["median"]
    rec = Record(
        "footlock_crowd_10k", ours, base, "animation frames/s", target=60.0, target_on="ours",
        description=f"{B} characters: crowd.crowd_positions(foot_lock=True): the crowd's FK then "
                    "gait.lock_crowd (held foot points, two-bone leg IK on positions) per frame",
        baseline_name="crowd.crowd_positions alone, same run",
        ours_stats=t_lock, baseline_stats=t_plain, details={"characters": B},
        notes=["the machine is shared (7 engineers on 2 cores): compare the ratio, not the rates"])
    return [rec.finish()]
