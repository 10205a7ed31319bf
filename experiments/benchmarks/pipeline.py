"""`fit_motions` end to end on real clips (Bandai-1 gaits repeated, or bundled clips cut to other
lengths), warm, with its per-stage breakdown, against `fit_batch` alone on the same features."""

from __future__ import annotations

import pathlib
import time

import numpy as np

from experiments.benchmarks._common import Record

#: Bandai-Namco dataset 1 (CC BY-NC, read in place, never copied): the gait clips.
BANDAI = pathlib.Path(__file__).resolve().parents[2] / ".." / "shared" / "data" / "mocap" / "bandai1" / "data"
GAITS = ("walk", "walk-back", "walk-left", "walk-right", "run", "dash")
XLA_COMPILE = "/jax/core/compile/backend_compile_duration"


def clips(num: int) -> tuple[list, str]:
    """``num`` clips and where they come from: the Bandai-1 gait clips, repeated, when
    ``../shared`` holds them; else the bundled CMU walks and runs cut to different lengths."""
    from fourierjax import data
    from fourierjax.io.bvh import read_bvh

    files = sorted(p for g in GAITS for p in BANDAI.glob(f"dataset-1_{g}_*.bvh")) if BANDAI.is_dir() else []
    if files:
        motions = [read_bvh(p) for p in files[:num]]
        source = f"Bandai-1: {len(motions)} gait clips ({', '.join(GAITS)}) repeated"
    else:
        motions = []
        names = ("02_01", "07_01", "07_04", "07_12", "09_01", "02_03", "142_08")
        for k in range(num):
            m = data.load(names[k % len(names)])
            n = min(m.num_frames, 130 + 13 * (k % 11))
            motions.append(m[:n])
        source = "bundled CMU clips cut to 130..260 frames"
    return [motions[k % len(motions)] for k in range(num)], source


def _fit_batch_alone(prepared, num_harmonics, dtype, chunk=128) -> float:
    """Seconds of `fit_batch` on the pipeline's features and masks, in chunks of ``chunk`` clips
    of similar lengths (padded like the pipeline's), warm."""
    import jax
    import jax.numpy as jnp

    from fourierjax import fourier

    order = sorted(range(len(prepared)), key=lambda i: len(prepared[i][0]))
    chunks = []
    for s in range(0, len(order), chunk):
        rows = [prepared[order[min(s + k, len(order) - 1)]] for k in range(chunk)]
        T = max(64, int(2 ** np.ceil(np.log2(max(len(r[0]) for r in rows)))))
        C = rows[0][0].shape[1]
        x = np.zeros((chunk, T, C), np.float32)
        m = np.zeros((chunk, T, C), bool)
        for k, (f, mk, _) in enumerate(rows):
            x[k, :len(f)], x[k, len(f):], m[k, :len(f)] = f, f[-1], mk
        chunks.append((jnp.asarray(x), jnp.asarray(m), jnp.asarray([r[2] for r in rows], dtype)))

    def go():
        return [fourier.fit_batch(x, dt, num_harmonics, mask=m, throw=False) for x, m, dt in chunks]

    jax.block_until_ready(go())  # compile
    t0 = time.perf_counter()
    jax.block_until_ready(go())
    return time.perf_counter() - t0


def _sweep_compiles(motions, bm, sizes) -> dict:
    """XLA programs compiled by `fit_motions` for each batch size of ``sizes`` (after one clip
    has compiled the small bucket): every program, fit, synthesis, metrics and eager ops."""
    from jax import monitoring

    from fourierjax.motion import fit_motions

    opts = dict(segment=False, use_contacts=False, body_map=bm)
    motions = motions[:1]  # one clip (and its body map), repeated
    fit_motions(motions, 3, **opts)
    counts = {}
    for size in sizes:
        events = []

        def listener(event, duration_secs, events=events, **_):
            events.append(event)

        monitoring.register_event_duration_secs_listener(listener)
        try:
            fit_motions([motions[k % len(motions)] for k in range(size)], 3, **opts)
        finally:
            monitoring.unregister_event_duration_listener(listener)
        counts[str(size)] = events.count(XLA_COMPILE)
    return counts


def _glitch_figures() -> dict:
    """142_02's left-arm glitch: frames and feature entries left out, by frame and by channel."""
    from fourierjax import data
    from fourierjax import motion as M
    from fourierjax.body import infer_body_map

    m = data.load("142_02")
    bm = infer_body_map(m)
    a, b = M.steady_segment(m, body_map=bm)
    sub = m[a:b]
    glitch = M.glitch_joints(sub)
    mask = M.feature_mask(glitch, sub.topology, bm.pelvis)
    frames = int(glitch.any(axis=1).sum())
    return {"clip": "142_02 steady segment", "frames": int(b - a), "channels": int(mask.shape[1]),
            "glitch_frames": frames,
            "entries_dropped_frame_mask": frames * int(mask.shape[1]),
            "entries_dropped_channel_mask": int((~mask).sum()),
            "joints_glitching": [sub.topology.names[j] for j in np.flatnonzero(glitch.any(0))]}


def run(size: str) -> list[Record]:
    import jax.numpy as jnp

    from fourierjax import motion as M
    from fourierjax.body import infer_body_map

    num = 500 if size == "full" else 4
    N = 3
    motions, source = clips(num)
    dtype = jnp.zeros(()).dtype
    t0 = time.perf_counter()
    M.fit_motions(motions, N)  # warm: every bucket compiled
    cold = time.perf_counter() - t0
    timings: dict = {}
    t0 = time.perf_counter()
    fits = M.fit_motions(motions, N, timings=timings)
    wall = time.perf_counter() - t0
    ok = sum(f.successful for f in fits)
    # The same features and masks, through fit_batch alone.
    prepared = []
    for m, f in zip(motions, fits, strict=True):
        sub = m[f.frame_start:f.frame_stop]
        bm = f.body_map
        glitch = M.glitch_joints(sub)
        x, _ = M.features_from_motion(sub, "euler", valid=~glitch, body_map=bm)
        prepared.append((x, M.feature_mask(glitch, sub.topology, bm.pelvis), sub.frame_time_s))
    fit_alone = _fit_batch_alone(prepared, N, dtype, 128 if size == "full" else 16)
    sizes = (8, 13, 50, 120, 500) if size == "full" else (2,)
    compiles = _sweep_compiles(motions, infer_body_map(motions[0]), sizes)
    print(f"    pipeline: {num} clips in {wall:.2f} s warm ({num / wall:.1f} clips/s; first call "
          f"{cold:.1f} s); fit_batch alone {fit_alone:.2f} s; stages {timings}", flush=True)
    ours, base = num / wall, num / fit_alone
    stages = {k: round(v, 3) for k, v in sorted(timings.items(), key=lambda kv: -kv[1])}
    rec = Record(
        "fit_motions_500", ours, base, "clips/s",
        target=300.0, target_on="ours",
        description=f"fourierjax.motion.fit_motions, N = {N}, warm, end to end on {num} clips "
                    f"({source}): steady segment, per-joint glitch masks, features, contacts, "
                    "bucketed fit, alignment, metrics",
        baseline_name="fourier.fit_batch alone on the same features and masks (chunks of 128)",
        details={
            "seconds_end_to_end": round(wall, 3), "seconds_first_call": round(cold, 3),
            "seconds_fit_batch_alone": round(fit_alone, 3), "clips_successful": ok,
            "stage_seconds": stages,
            "stage_ms_per_clip": {k: round(1e3 * v / num, 3) for k, v in stages.items()},
            "stage_note": "stages before 'fit' run in the reader thread, overlapping the fit "
                          "of the chunk before; their sum can exceed the wall time",
            "xla_compiles_per_batch_size": compiles,
            "xla_compiles_batch_size_sweep": int(sum(compiles.values())),
            "glitch_masks": _glitch_figures(),
        },
        notes=["2 shared CPU cores, loaded by other work: ratios from one run mean more than "
               "the absolute rates"],
    )
    return [rec.finish()]
