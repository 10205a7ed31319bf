"""`fit_motions` end to end on real clips (Bandai-1 gaits repeated, or bundled clips cut to other
lengths), warm, with its per-stage breakdown, against `fit_batch` alone on the same features."""

from __future__ import annotations

import contextlib
import os
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


def _euler_loop(flat, twins, ok):
    """The Euler continuity of the last session: one frame at a time (`_eulerscan.continuous`'s
    arguments and result)."""
    flat = flat.copy()
    F, K, _ = flat.shape
    ref, cols, two_pi = np.zeros(K, int), np.arange(K), 2 * np.pi
    for t in range(1, F):
        prev = np.where(ok[t][:, None], flat[ref, cols], flat[t - 1])
        c0 = flat[t] + two_pi * np.round((prev - flat[t]) / two_pi)
        c1 = twins[t] + two_pi * np.round((prev - twins[t]) / two_pi)
        d0, d1 = np.sum((c0 - prev) ** 2, axis=-1), np.sum((c1 - prev) ** 2, axis=-1)
        flat[t] = np.where((d1 < d0 - 1e-12)[:, None], c1, c0)
        ref = np.where(ok[t] | ~ok[ref, cols], t, ref)
    return flat


def _foot_contacts_loop(p, frame_time_s, *, up_axis=1):
    """The contact detection of the last session: eager JAX speeds, loops over frames and runs."""
    from fourierjax import contacts as C

    p = C._as_points(p)
    g = C.estimate_ground(p, frame_time_s, up_axis=up_axis)
    above = p[..., up_axis] - g.intercepts - np.delete(p, up_axis, axis=-1) @ g.slope
    speed = np.asarray(C.point_speeds(p, frame_time_s))
    enter = (above < g.height_threshold) & (speed < g.speed_threshold)
    stay = (above < 1.5 * g.height_threshold) & (speed < 1.5 * g.speed_threshold)
    min_len, max_gap = max(1, int(round(0.04 / frame_time_s))), int(round(0.025 / frame_time_s))
    out = np.zeros(p.shape[:2], bool)
    for f in range(p.shape[1]):
        pts = []
        for k in range(p.shape[2]):
            on, row = False, np.zeros(len(p), bool)
            for t in range(len(p)):
                on = bool(enter[t, f, k]) or (on and bool(stay[t, f, k]))
                row[t] = on
            pts.append(row)
        c = np.any(pts, axis=0)
        starts, stops = C._runs(~c)
        for a, b in zip(starts, stops, strict=True):
            if a > 0 and b < len(c) and b - a <= max_gap:
                c[a:b] = True
        starts, stops = C._runs(c)
        for a, b in zip(starts, stops, strict=True):
            if b - a < min_len:
                c[a:b] = False
        out[:, f] = c
    return out


@contextlib.contextmanager
def per_clip_pipeline():
    """`fit_motions` as in the last session, for a baseline in the same run: every clip
    prepared on its own (`_pipeline._prepare`), Euler continuity frame by frame and the contact
    loops (the fit itself is the same)."""
    from fourierjax import _eulerscan
    from fourierjax import contacts as C
    from fourierjax._motion import _pipeline

    def per_clip(entries, **opts):
        return [_pipeline._prepare(i, m, bm, **opts) for i, m, bm in entries]

    saved = (_pipeline.prepare_chunk, _eulerscan.continuous, C.foot_contacts)
    _pipeline.prepare_chunk, _eulerscan.continuous, C.foot_contacts = (
        per_clip, _euler_loop, _foot_contacts_loop)
    try:
        yield
    finally:
        _pipeline.prepare_chunk, _eulerscan.continuous, C.foot_contacts = saved


@contextlib.contextmanager
def per_chunk_stream():
    """`fit_motions`' stream as in the last session, for a baseline in the same run: each
    chunk's clips sorted by length on their own and cut into batches, every clip padded to the
    bucket of its batch's longest (no length grouping, nothing held back for the next chunk)."""
    from fourierjax._motion import _pipeline

    saved = (_pipeline._group_key, _pipeline.STREAM_HOLD)

    def layout_only(c, fit_kwargs):
        return (*saved[0](c, fit_kwargs)[:2], 0)

    _pipeline._group_key, _pipeline.STREAM_HOLD = layout_only, False
    try:
        yield
    finally:
        _pipeline._group_key, _pipeline.STREAM_HOLD = saved


@contextlib.contextmanager
def one_reader_thread():
    """`fit_motions` with each chunk prepared by the reader thread alone, as in the last
    session (no second thread preparing half of it: `_pipeline._prepare_split`)."""
    from fourierjax._motion import _pipeline

    saved = _pipeline.SPLIT_MIN
    _pipeline.SPLIT_MIN = 1 << 62
    try:
        yield
    finally:
        _pipeline.SPLIT_MIN = saved


@contextlib.contextmanager
def one_fit_thread():
    """`fit_motions` with each fit step's chunks fitted one after the other, as in the last
    session (not two at once: `_pipeline._fit_jobs`)."""
    from fourierjax._motion import _pipeline

    saved = _pipeline._fit_jobs

    def one(jobs, limit, pool, *args):
        return saved(jobs, limit, None, *args)

    _pipeline._fit_jobs = one
    try:
        yield
    finally:
        _pipeline._fit_jobs = saved


def _companions(motions, fits, N, ctx) -> dict:
    """How much a clip's fit depends on the clips fitted with it: the first 100 clips fitted
    alone against the same clips in the whole run (``fits``), under ``ctx``'s stream."""
    from fourierjax import motion as M

    n = min(100, len(motions))
    with ctx:
        alone = M.fit_motions(motions[:n], N)
    om = [abs(a.omega_fit / b.omega_fit - 1) for a, b in zip(alone, fits, strict=False)]
    amp = [float(np.max(np.abs(np.asarray(a.raw_model.amplitude) - np.asarray(b.raw_model.amplitude))))
           for a, b in zip(alone, fits, strict=False)]
    return {"clips": n, "omega_fit_max_rel_diff": float(np.max(om)),
            "clips_omega_differs": int(np.sum(np.array(om) > 0)),
            "amplitude_max_abs_diff": float(np.max(amp))}


def _fit_batch_alone(prepared, num_harmonics, dtype, chunk=128, representation="euler",
                     names=()) -> float:
    """Seconds of `fit_batch` on the pipeline's features and masks (``representation``, channel
    ``names``), in chunks of ``chunk`` clips of similar lengths (padded like the pipeline's),
    warm."""
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
        return [fourier.fit_batch(x, dt, num_harmonics, mask=m, throw=False,
                                  representation=representation, channel_names=names)
                for x, m, dt in chunks]

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

    # FOURIERJAX_BENCH_PIPELINE_CLIPS: fewer clips than the 500 (a loaded machine).
    num = int(os.environ.get("FOURIERJAX_BENCH_PIPELINE_CLIPS", 500)) if size == "full" else 4
    N = 3
    motions, source = clips(num)
    dtype = jnp.zeros(()).dtype
    t0 = time.perf_counter()
    M.fit_motions(motions, N)  # warm: every bucket compiled
    cold = time.perf_counter() - t0
    with per_clip_pipeline():
        M.fit_motions(motions[: min(num, 16)], N)  # warm the per-clip path's small programs
    with per_chunk_stream():
        M.fit_motions(motions, N)  # warm the per-chunk stream's buckets
    runs, cpu = {}, {}
    # Interleaved (load drifts): the per-chunk stream of two sessions ago, the last session's
    # one reader thread and this one; the per-clip path of three sessions ago once.
    for name in ("chunk", "one_reader", "one_fit", "after", "chunk_again", "one_reader_again",
                 "one_fit_again", "after_again", "before"):
        timings: dict = {}
        ctx = (per_clip_pipeline() if name == "before" else per_chunk_stream()
               if name.startswith("chunk") else one_reader_thread()
               if name.startswith("one_reader") else one_fit_thread()
               if name.startswith("one_fit") else contextlib.nullcontext())
        with ctx:
            c0, t0 = _cpu_s(), time.perf_counter()
            fits = M.fit_motions(motions, N, timings=timings)
            runs[name] = (time.perf_counter() - t0, timings, fits)
            cpu[name] = _cpu_s() - c0
    runs["before_again"] = runs["before"]
    wall = min(runs["after"][0], runs["after_again"][0])
    wall_before = min(runs["before"][0], runs["before_again"][0])
    wall_chunk = min(runs["chunk"][0], runs["chunk_again"][0])
    wall_one = min(runs["one_reader"][0], runs["one_reader_again"][0])
    wall_one_fit = min(runs["one_fit"][0], runs["one_fit_again"][0])
    timings_one = min((runs["one_reader"], runs["one_reader_again"]), key=lambda r: r[0])[1]
    timings = min((runs["after"], runs["after_again"]), key=lambda r: r[0])[1]
    timings_before = min((runs["before"], runs["before_again"]), key=lambda r: r[0])[1]
    timings_chunk = min((runs["chunk"], runs["chunk_again"]), key=lambda r: r[0])[1]
    fits = runs["after"][2]
    fits_chunk = runs["chunk"][2]
    om = [abs(a.omega_fit / b.omega_fit - 1) for a, b in zip(fits, fits_chunk, strict=True)]
    companions = {"bucketed_stream": _companions(motions, fits, N, contextlib.nullcontext()),
                  "per_chunk_stream": _companions(motions, fits_chunk, N, per_chunk_stream())}
    same = all(a.frame_start == b.frame_start and a.frame_stop == b.frame_stop
               and a.left_heel_strikes == b.left_heel_strikes and a.omega_fit == b.omega_fit
               for a, b in zip(fits, runs["before"][2], strict=True))
    ok = sum(f.successful for f in fits)
    # The same features and masks, through fit_batch alone.
    prepared = [(c.features, c.mask, c.sub.frame_time_s) for c in _prepared(motions)]
    fit_alone = _fit_batch_alone(prepared, N, dtype, 128 if size == "full" else 16)
    sizes = (8, 13, 50, 120, 500) if size == "full" else (2,)
    compiles = _sweep_compiles(motions, infer_body_map(motions[0]), sizes)
    print(f"    pipeline: {num} clips in {wall:.2f} s warm ({num / wall:.1f} clips/s; per-clip "
          f"path {num / wall_before:.1f} clips/s; one reader thread {num / wall_one:.1f} "
          f"clips/s; per-chunk stream {num / wall_chunk:.1f} clips/s; first call {cold:.1f} s); "
          f"fit_batch alone {fit_alone:.2f} s; stages "
          f"{timings}; per-chunk stages {timings_chunk}; per-clip stages {timings_before}; "
          f"companions {companions}", flush=True)

    def per_clip_ms(t):
        return {k: round(1e3 * v / num, 3) for k, v in sorted(t.items(), key=lambda kv: -kv[1])}

    ours, base = num / wall, num / fit_alone
    stages = {k: round(v, 3) for k, v in sorted(timings.items(), key=lambda kv: -kv[1])}
    rec = Record(
        "fit_motions_500", ours, base, "clips/s",
        target=300.0, target_on="ours",
        description=f"fourierjax.motion.fit_motions, N = {N}, warm, end to end on {num} clips "
                    f"({source}): steady segment, per-joint glitch masks, features, contacts "
                    "(prepared per chunk, `_motion._batch`), bucketed fit, alignment, metrics",
        baseline_name="fourier.fit_batch alone on the same features and masks (chunks of 128)",
        details={
            "seconds_end_to_end": round(wall, 3), "seconds_first_call": round(cold, 3),
            "cpu_seconds_end_to_end": round(min(cpu["after"], cpu["after_again"]), 3),
            "cpu_seconds_per_chunk_stream": round(min(cpu["chunk"], cpu["chunk_again"]), 3),
            "seconds_fit_batch_alone": round(fit_alone, 3), "clips_successful": ok,
            "stage_seconds": stages,
            "stage_ms_per_clip": per_clip_ms(timings),
            "per_clip_path": {
                "clips_per_s": round(num / wall_before, 3),
                "seconds_end_to_end": round(wall_before, 3),
                "stage_ms_per_clip": per_clip_ms(timings_before),
                "speedup_of_the_chunked_path": round(wall_before / wall, 3),
                "same_segments_strikes_and_omega": bool(same)},
            "one_reader_thread": {
                "clips_per_s": round(num / wall_one, 3),
                "seconds_end_to_end": round(wall_one, 3),
                "cpu_seconds_end_to_end": round(min(cpu["one_reader"],
                                                    cpu["one_reader_again"]), 3),
                "stage_seconds": {k: round(v, 3) for k, v in sorted(
                    timings_one.items(), key=lambda kv: -kv[1])},
                "speedup_of_two_preparing_threads": round(wall_one / wall, 3)},
            "one_fit_thread": {
                "clips_per_s": round(num / wall_one_fit, 3),
                "cpu_seconds_end_to_end": round(min(cpu["one_fit"], cpu["one_fit_again"]), 3),
                "speedup_of_two_fitting_threads": round(wall_one_fit / wall, 3)},
            "per_chunk_stream": {
                "clips_per_s": round(num / wall_chunk, 3),
                "seconds_end_to_end": round(wall_chunk, 3),
                "stage_seconds": {k: round(v, 3) for k, v in sorted(
                    timings_chunk.items(), key=lambda kv: -kv[1])},
                "speedup_of_the_bucketed_stream": round(wall_chunk / wall, 3),
                "omega_fit_max_rel_diff_to_bucketed": float(np.max(om))},
            "fit_stage_over_fit_batch_alone": round(timings.get("fit", 0.0) / fit_alone, 3),
            "a_clip_alone_vs_in_the_run": companions,
            "stage_note": "stages before 'fit' run in the reader threads (two, half a chunk "
                          "each, their seconds summed), overlapping the fit of the chunk "
                          "before; their sum can exceed the wall time; 'fit' and "
                          "'align_metrics' sum two fitting threads too; 'wait' is "
                          "the fitting thread waiting for them (wall <~ wait + fit + "
                          "align_metrics: the preparation on the critical path). Each wall "
                          "time is the faster of two interleaved runs (the per-clip path: one "
                          "run)",
            "xla_compiles_per_batch_size": compiles,
            "xla_compiles_batch_size_sweep": int(sum(compiles.values())),
            "glitch_masks": _glitch_figures(),
        },
        notes=["2 shared CPU cores, loaded by other work: ratios from one run mean more than "
               "the absolute rates"],
    )
    return [rec.finish(), _tangent(motions, source, num, N, dtype, size, wall)]


def _tangent(motions, source, num, N, dtype, size, wall_euler) -> Record:
    """`fit_motions` with the command line's default representation (``"tangent"``), warm,
    against `fit_batch` alone on its features; the Euler run above in the same process."""
    from fourierjax import motion as M

    M.fit_motions(motions, N, "tangent")  # warm
    runs, one_fit = [], []
    for _ in range(2):  # interleaved with the last session's one fitting thread
        with one_fit_thread():
            t0 = time.perf_counter()
            M.fit_motions(motions, N, "tangent")
            one_fit.append(time.perf_counter() - t0)
        timings: dict = {}
        c0, t0 = _cpu_s(), time.perf_counter()
        fits = M.fit_motions(motions, N, "tangent", timings=timings)
        runs.append((time.perf_counter() - t0, timings, fits, _cpu_s() - c0))
    wall, timings, fits, cpu = min(runs, key=lambda r: r[0])
    prepared = _prepared(motions, "tangent")
    fit_alone = _fit_batch_alone([(c.features, c.mask, c.sub.frame_time_s) for c in prepared], N,
                                 dtype, 128 if size == "full" else 16, "tangent",
                                 prepared[0].names)
    print(f"    pipeline (tangent): {num} clips in {wall:.2f} s warm ({num / wall:.1f} clips/s, "
          f"euler {num / wall_euler:.1f}); fit_batch alone {fit_alone:.2f} s; stages {timings}",
          flush=True)
    return Record(
        "fit_motions_500_tangent", num / wall, num / fit_alone, "clips/s",
        target=300.0, target_on="ours",
        description=f"fourierjax.motion.fit_motions(representation='tangent', the command "
                    f"line's default), N = {N}, warm, end to end on {num} clips ({source})",
        baseline_name="fourier.fit_batch(representation='tangent') alone on the same features "
                      "and masks (chunks of 128)",
        details={
            "seconds_end_to_end": round(wall, 3), "seconds_fit_batch_alone": round(fit_alone, 3),
            "cpu_seconds_end_to_end": round(cpu, 3),
            "clips_successful": sum(f.successful for f in fits),
            "euler_clips_per_s_same_process": round(num / wall_euler, 3),
            "tangent_over_euler": round(wall_euler / wall, 3),
            "one_fit_thread_clips_per_s": round(num / min(one_fit), 3),
            "speedup_of_two_fitting_threads": round(min(one_fit) / wall, 3),
            "stage_seconds": {k: round(v, 3) for k, v in sorted(timings.items(),
                                                                key=lambda kv: -kv[1])},
            "stage_note": "the faster of two runs; stages before 'fit' overlap the fit"},
        notes=["2 shared CPU cores, loaded by other work: ratios from one run mean more than "
               "the absolute rates"],
    ).finish()


def _cpu_s() -> float:
    """CPU seconds of this process, all threads (XLA's included): on shared cores a steadier
    measure of work than the wall time."""
    t = os.times()
    return t.user + t.system


def _prepared(motions, representation="euler"):
    """The pipeline's prepared clips (features, masks) of ``motions``, as `fit_motions` makes
    them."""
    from fourierjax._motion._batch import prepare_chunk

    opts = dict(representation=representation, segment=True, use_contacts=True, start_frame=None,
                stop_frame=None, timings=None)
    return prepare_chunk([(k, m, None) for k, m in enumerate(motions)], **opts)
