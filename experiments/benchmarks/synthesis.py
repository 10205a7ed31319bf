"""Fourier synthesis (channel-samples/s) vs NumPy and vs the bound of writing the output."""

from __future__ import annotations

import os

import numpy as np

from experiments.benchmarks._common import Record, timeit


def random_models(num_chars: int, num_channels: int, num_harmonics: int, seed: int = 0):
    """Stacked `FourierModel`s with gait-like spectra (amplitudes ~ 1/n) and omega in 4..8 rad/s."""
    import jax.numpy as jnp

    from fourierjax.fourier import FourierModel

    rng = np.random.default_rng(seed)
    n = np.arange(1, num_harmonics + 1)
    amp = rng.uniform(0.05, 0.5, size=(num_chars, num_channels, num_harmonics)) / n
    ph = rng.uniform(-np.pi, np.pi, size=amp.shape)
    off = rng.normal(size=(num_chars, num_channels))
    om = rng.uniform(4.0, 8.0, size=(num_chars,))
    f = np.float32
    return FourierModel(jnp.asarray(off, f), jnp.asarray(amp, f), jnp.asarray(ph, f), jnp.asarray(om, f))


def numpy_synthesize(off, a, b, omega, t_s):
    """Vectorised NumPy synthesis of `[B]` models at shared times `[T]` -> `[B, T, C]`."""
    n = np.arange(1, a.shape[-1] + 1, dtype=a.dtype)
    nt = (omega[:, None] * t_s[None, :])[..., None] * n  # [B, T, N]
    return off[:, None, :] + np.sin(nt) @ np.swapaxes(a, 1, 2) + np.cos(nt) @ np.swapaxes(b, 1, 2)


def variants():
    """Per-character formulations measured under `jit(vmap(...))` (`crowd.py` uses "fused_basis")."""
    import jax
    import jax.numpy as jnp

    def matmul(a, b):  # full precision on every backend, as fourierjax's own products
        return jnp.matmul(a, b, precision=jax.lax.Precision.HIGHEST)

    def fused_basis(model, t_s):
        # One [T, 2N] basis and one contraction instead of two matmuls.
        a, b = model.sin_cos()
        n = jnp.arange(1, model.num_harmonics + 1, dtype=t_s.dtype)
        nt = (model.omega * t_s)[:, None] * n
        basis = jnp.concatenate([jnp.sin(nt), jnp.cos(nt)], axis=1)
        return model.offset + matmul(basis, jnp.concatenate([a, b], axis=1).T)

    def recurrence_elementwise(model, t_s):
        # sin/cos of theta once, harmonics by the angle-addition recurrence (2 trig calls per
        # sample instead of 2N), and the small-N contraction as broadcast multiply-adds.
        a, b = model.sin_cos()
        th = model.omega * t_s
        s1, c1 = jnp.sin(th), jnp.cos(th)
        s, c = s1, c1
        out = model.offset[None, :] + s[:, None] * a[None, :, 0] + c[:, None] * b[None, :, 0]
        for k in range(1, model.num_harmonics):
            s, c = s * c1 + c * s1, c * c1 - s * s1
            out = out + s[:, None] * a[None, :, k] + c[:, None] * b[None, :, k]
        return out

    return {"fused_basis": fused_basis, "recurrence_elementwise": recurrence_elementwise}


def _interleaved(fns: dict, repeats: int, warmup: int = 1) -> tuple[dict, dict]:
    """Time `fns` round-robin (one timed call of each per round, results blocked on).

    On a shared machine the load drifts between measurements; comparing calls made in the same
    round keeps a ratio honest. Off CPU each timed call follows an untimed one of the same
    function: on a GPU the first kernel after the ~75 ms NumPy baseline waits for the idle
    device to wake (measured on an H100: synthesize_batch of 1024 characters 813 us right after
    NumPy, 247 us after itself). Not on CPU, where an extra call changes which output buffers
    the allocator hands back, and with them the page faults the write bound is made of (one
    2-core run: write bound 2.3 G/s instead of ~0.55, ours bimodal between 6 and 26 ms).
    The order rotates from round to round, so no function always goes first.
    Returns `({name: stats as _common.timeit}, {name: [seconds]})`.
    """
    import time

    import jax

    for _ in range(warmup):
        for f in fns.values():
            jax.block_until_ready(f())
    settle = jax.default_backend() != "cpu"
    times: dict[str, list[float]] = {k: [] for k in fns}
    names = list(fns)
    for r in range(max(1, repeats)):
        # Each round starts at a different function: the first call of a round was measured
        # 1-2 us slower than the same call later in the round (single character, 2 cores).
        for k in names[r % len(names):] + names[:r % len(names)]:
            f = fns[k]
            if settle:
                jax.block_until_ready(f())
            t0 = time.perf_counter()
            jax.block_until_ready(f())
            times[k].append(time.perf_counter() - t0)
    stats = {}
    for k, ts in times.items():
        a = np.asarray(ts)
        stats[k] = {"median": float(np.median(a)), "min": float(a.min()), "max": float(a.max()),
                    "q25": float(np.percentile(a, 25)), "q75": float(np.percentile(a, 75)),
                    "repeats": len(ts)}
    return stats, times


def _one_character_parts(models, t_s) -> dict:
    """Calls timed with synthesis_1: a jitted call that only returns its first argument (the
    dispatch floor), and the straight product form under plain `jax.jit` (handed to a worker
    thread: XLA counts its ~200 kflop)."""
    import jax

    from fourierjax._fourier import _synthesis as S

    args = (models.offset, models.amplitude, models.phase, models.omega, t_s)
    floor = jax.jit(lambda *a: a[0])

    @jax.jit
    def product(offset, amplitude, phase, omega, t):
        one = S.FourierModel(offset[0], amplitude[0], phase[0], omega[0])
        return S._synthesize_one_product(one, one.omega * t)[None]

    return {"dispatch_floor": lambda: floor(*args), "product_form": lambda: product(*args)}


def _one_character_details(models, t_s, stats) -> dict:
    from fourierjax._fourier import _synthesis as S

    args = (models.offset, models.amplitude, models.phase, models.omega, t_s)
    cost = S._synthesize_batch_jit.lower(*args).compile().cost_analysis()
    cost = cost[0] if isinstance(cost, list) else cost
    us = {k: 1e6 * stats[k]["median"] for k in ("ours", "numpy", "dispatch_floor", "product_form")}
    return {"xla_counted_flops": cost.get("flops"), "inline_flop_limit": S._INLINE_FLOPS,
            "median_us": us, "product_form_ratio_vs_numpy": us["numpy"] / us["product_form"],
            "ours_minus_dispatch_floor_us": us["ours"] - us["dispatch_floor"]}


def run(size: str) -> list[Record]:
    import jax
    import jax.numpy as jnp

    from fourierjax import fourier

    C, N, T = 57, 3, 240
    cases = [("synthesis_1", 1), ("synthesis_1024", 1024)] if size == "full" else [
        ("synthesis_1", 1), ("synthesis_1024", 16)]
    repeats = 11 if size == "full" else 1
    out = []
    vmapped = jax.jit(jax.vmap(fourier.synthesize, in_axes=(0, None)))

    @jax.jit
    def write(offset, t):
        # The bound: only writing the [B, T, C] float32 output (same layout, same allocation).
        return offset[:, None, :] + 0.0 * t[None, :, None]

    for name, B in cases:
        models = random_models(B, C, N)
        t_s = jnp.arange(T, dtype=jnp.float32) / 120.0
        n = B * T * C
        ref = np.asarray(vmapped(models, t_s))
        got = np.asarray(fourier.synthesize_batch(models, t_s))
        a, b = (np.asarray(v) for v in models.sin_cos())
        off, om, ts = np.asarray(models.offset), np.asarray(models.omega), np.asarray(t_s)
        err = float(np.abs(numpy_synthesize(off, a, b, om, ts) - got).max())
        fns = {
            "ours": lambda: fourier.synthesize_batch(models, t_s),
            "write": lambda: write(models.offset, t_s),
            "vmap_synthesize": lambda: vmapped(models, t_s),
            "numpy": lambda: numpy_synthesize(off, a, b, om, ts),
        }
        if B == 1:  # where one character's time goes (issue 26): dispatch, hand-off, compute
            fns.update(_one_character_parts(models, t_s))
        stats, times = _interleaved(fns, repeats if B > 1 else 5 * repeats)
        ours, wr, old, base = (stats[k] for k in ("ours", "write", "vmap_synthesize", "numpy"))
        per_round = np.asarray(times["write"]) / np.asarray(times["ours"])
        per_round_old = np.asarray(times["write"]) / np.asarray(times["vmap_synthesize"])
        details = {
            "characters": B, "channels": C, "harmonics": N, "frames": T,
            "max_abs_diff_vs_numpy": err,
            "max_abs_diff_vs_vmap_synthesize": float(np.abs(got - ref).max()),
            "output_write_bound_rate": n / wr["median"],
            # Median over rounds of (write time / our time), each pair timed back to back.
            "fraction_of_write_bound": float(np.median(per_round)),
            "fraction_of_write_bound_from_medians": wr["median"] / ours["median"],
            "vmap_synthesize_rate": n / old["median"],
            "vmap_synthesize_fraction_of_write_bound": float(np.median(per_round_old)),
            "speedup_over_vmap_synthesize": old["median"] / ours["median"],
            "write_stats": wr, "vmap_synthesize_stats": old,
            # The write bound is mostly page faults on the fresh output buffer (glibc maps a
            # new one per call): ~0.6 G/s with 4 KiB pages, ~2.3 G/s with transparent huge
            # pages (GLIBC_TUNABLES=glibc.malloc.hugetlb=1) on the 2-core machine.
            "glibc_tunables": os.environ.get("GLIBC_TUNABLES"),
        }
        if B == 1:
            details.update(_one_character_details(models, t_s, stats))
        for vname, fn in variants().items():
            vf = jax.jit(jax.vmap(fn, in_axes=(0, None)))
            verr = float(np.abs(np.asarray(vf(models, t_s)) - ref).max())
            vt = timeit(lambda: vf(models, t_s), repeats=max(1, repeats // 2))
            details[f"variant_{vname}_rate"] = n / vt["median"]
            details[f"variant_{vname}_max_abs_diff"] = verr
        rec = Record(
            name, n / ours["median"], n / base["median"], "channel-samples/s",
            # synthesis_1: not slower than NumPy (issue 26); synthesis_1024: half the write bound.
            target=0.5 if name == "synthesis_1024" else 1.0,
            target_on="fraction_of_write_bound" if name == "synthesis_1024" else "ratio",
            description=f"{B} character(s) x {C} channels x {T} frames, N = {N}, own omega each, "
                        "fourier.synthesize_batch (old: jit(vmap(fourier.synthesize)) in details)",
            baseline_name="vectorised NumPy (sin/cos of n*theta, batched matmul)",
            ours_stats=ours, baseline_stats=base, details=details,
        )
        out.append(rec)
    return out
