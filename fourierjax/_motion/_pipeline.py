"""`fit_motions`: clips prepared in a background thread, fitted in bucketed chunks, streamed."""

from __future__ import annotations

import concurrent.futures
import dataclasses
import itertools
import os
import threading
import time
from collections.abc import Iterator

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from fourierjax import _jit, _passes, _saved
from fourierjax._motion._batch import prepare_chunk
from fourierjax._motion._clip import (
    ClipFit,
    _frame_range,
    _hip_flexion_channel,
    _hip_flexion_phase,
    _search_weights,
    _steps,
    closed_loop,
    winding_joints,
)
from fourierjax._motion._poses import _position_ve, foot_contacts_of, position_ve_batch
from fourierjax._motion._segment import feature_mask, glitch_joints, steady_segment
from fourierjax.errors import UserError
from fourierjax.features import features_from_motion


@dataclasses.dataclass
class _Clip:
    """A clip ready for the batched fit: frames ``[start, stop)`` of ``motion`` (``sub``), its
    features ``[F, C]`` and per-channel fit mask ``[F, C]`` (True: used), heel strikes and ω from
    steps. A mode that fits part of a clip (e.g. the straight passes of a turning walk) ANDs its
    frame mask ``[F]`` into ``mask`` here; per-pass time offsets would need the fit's sample
    times (``fit_batch`` assumes ``t = k * frame_time_s``)."""

    index: int
    motion: object
    start: int
    stop: int
    sub: object
    features: np.ndarray
    names: tuple[str, ...]
    mask: np.ndarray
    left: np.ndarray
    right: np.ndarray
    omega_steps: float
    body_map: object


def _prepare(index, m, bm, *, representation, segment, use_contacts, start_frame, stop_frame,
             timings, passes="longest") -> _Clip:
    """Everything before the fit for one clip: body map, steady segment, glitch masks,
    features, contacts and steps (``timings``: seconds added per stage)."""
    from fourierjax.body import BodyMapError, infer_body_map
    from fourierjax.io.bvh import read_bvh

    clock = _Clock(timings)
    if isinstance(m, (str, os.PathLike)):
        m = read_bvh(m)
        clock("read")
    lo, hi = _frame_range(m, start_frame, stop_frame)
    clip = m[lo:hi]
    if bm is None:
        try:
            bm = infer_body_map(clip)
        except BodyMapError:
            bm = None  # no legs: joint 0 carries the root, no contacts, no alignment
    clock("body_map")
    # --- hook (issue 21 item 4, fourierjax._passes): every straight pass of a walk that turns
    got = _passes.prepare_passes(clip, lo, representation, bm, use_contacts) if segment and passes == "auto" \
        else None
    if got is not None:
        _, a, b, sub, x, names, left, right, om, keep = got
        clock("segment")
        mask = np.broadcast_to(keep[:, None], x.shape).copy()
        return _Clip(index, m, a, b, sub, x, names, mask, left, right, om, bm)
    # --- end of hook
    a, b = steady_segment(clip, body_map=bm) if segment else (0, clip.num_frames)
    a, b = a + lo, b + lo
    sub = m[a:b]
    clock("segment")
    glitch = glitch_joints(sub)
    clock("glitch")
    x, names = features_from_motion(sub, representation, valid=~glitch, body_map=bm)
    mask = feature_mask(glitch, sub.topology, 0 if bm is None else bm.pelvis)
    clock("features")
    c = foot_contacts_of(sub, body_map=bm) if use_contacts and bm is not None else None
    left, right, om = _steps(c, sub.frame_time_s, closed_loop(sub))
    clock("contacts")
    return _Clip(index, m, a, b, sub, x, names, mask, left, right, om, bm)


class _Clock:
    """Adds the seconds since the last call to ``timings[stage]`` (no-op without timings)."""

    def __init__(self, timings):
        self.timings, self.t = timings, time.perf_counter()

    def __call__(self, stage):
        if self.timings is not None:
            now = time.perf_counter()
            self.timings[stage] = self.timings.get(stage, 0.0) + now - self.t
            self.t = now


def _group_key(c: _Clip, fit_kwargs) -> tuple:
    """The clips that one compiled fit program can take together: the same channel layout,
    the same ω-search weights and the same length bucket (so that a clip is padded to its own
    bucket, whichever clips share its batch)."""
    from fourierjax._fourier._buckets import length_bucket

    w = None if "channel_weights" in fit_kwargs else _search_weights(c.features, c.names,
                                                                     c.mask.any(axis=1))
    return c.names, w, length_bucket(len(c.features))


def _fit_clips(clips, num_harmonics, representation, dtype, fit_kwargs, timings,
               keys=None, pool=None) -> list[ClipFit]:
    """The batched fit of prepared clips: grouped by channel layout, search weights and length
    bucket (`_group_key`; ``keys``: theirs when known), cut into bucketed chunks
    (`_fourier._buckets`), then aligned and scored; one ClipFit per clip, in order. With
    ``pool`` (a one-thread executor), two chunks are fitted at once where two fit the memory
    budget (`_fit_jobs`)."""
    from fourierjax import fourier as fr
    from fourierjax._fourier._buckets import batch_plan, length_bucket
    from fourierjax._memory import fit_bytes_per_clip, resolve_limit

    limit = resolve_limit("fit_motions: max_memory", fit_kwargs.get("max_memory"))
    keys = keys or {}
    groups: dict[tuple, list[_Clip]] = {}
    for c in clips:
        key = keys.get(c.index) or _group_key(c, fit_kwargs)
        groups.setdefault(key, []).append(c)
    itemsize = jnp.zeros((), dtype).dtype.itemsize
    jobs = []
    for (names, weights, _), group in groups.items():
        kw = dict(fit_kwargs)
        if weights is not None:
            kw["channel_weights"] = jnp.asarray(weights, dtype)
        group = sorted(group, key=lambda c: len(c.features))
        C, longest = len(names), len(group[-1].features)
        per_clip = fit_bytes_per_clip(length_bucket(longest), C, num_harmonics, itemsize)
        for start, size in batch_plan(len(group), per_clip, limit, name=(
                f"fit_motions: a clip of {longest} frames x {C} channels")):
            chunk = group[start:start + size]
            program = (size, length_bucket(max(len(c.features) for c in chunk)), names,
                       weights, representation, num_harmonics, jnp.dtype(dtype).str)
            jobs.append((program, size * per_clip, (chunk, size, names, num_harmonics,
                                                    representation, dtype, kw)))
    out: dict[int, ClipFit] = {}
    for rows in _fit_jobs(jobs, limit, pool, timings, fr, length_bucket):
        out.update(rows)
    return [out[c.index] for c in clips]


#: The chunk programs (`_fit_jobs`' keys) that have run once in this process: a new one runs
#: alone first, so that two threads never compile one program twice at once.
_RUN_PROGRAMS: set = set()


def _fit_jobs(jobs, limit, pool, timings, fr, length_bucket) -> list:
    """`_fit_chunk` of each job ``(program key, bytes, arguments)``, in order; with ``pool``,
    chunks whose programs have run before are fitted two at once (this thread and the pool's)
    when two of the largest fit the memory budget ``limit``. A chunk's fit is its own program
    on its own inputs, whichever thread runs it: the same ClipFits. The fit of a chunk runs
    mostly on one core (500 Bandai-1 clips, tangent: 1.73 CPU-s in 1.62 s), so the second
    core served only the reader before; ``timings``: both threads' seconds, summed."""
    def run(job, t):
        return _fit_chunk(*job[2], t, fr, length_bucket)

    out: list = [None] * len(jobs)
    done = [False] * len(jobs)
    for k, job in enumerate(jobs):  # a new program's first chunk: compiled once, here
        if job[0] not in _RUN_PROGRAMS:
            out[k], done[k] = run(job, timings), True
            _RUN_PROGRAMS.add(job[0])
    left = [k for k in range(len(jobs)) if not done[k]]
    rest = iter(left)
    if pool is None or len(left) < 2 or 2 * max(j[1] for j in jobs) > limit:
        for k in rest:
            out[k] = run(jobs[k], timings)
        return out
    lock = threading.Lock()
    stop = threading.Event()
    theirs = None if timings is None else {}

    def worker(t):
        while not stop.is_set():
            with lock:
                k = next(rest, None)
            if k is None:
                return
            try:
                out[k] = run(jobs[k], t)
            except BaseException:
                stop.set()
                raise

    helper = pool.submit(worker, theirs)
    try:
        worker(timings)
    finally:
        concurrent.futures.wait([helper])
    helper.result()
    for k, v in (theirs or {}).items():
        timings[k] = timings.get(k, 0.0) + v
    return out


def _hold_back(held, new, fit_kwargs, final, known=None) -> tuple[list[_Clip], list[_Clip], dict]:
    """What the stream fits now and what it holds back for the next chunk: ``(now, keep,
    keys)``. Clips are grouped as the fit groups them (`_group_key`), oldest first; of each
    group, whole batches of `SMALL_BATCH` clips are fitted now (so the fit of chunk k runs
    while chunk k + 1 is read, not at the end of the stream) and the rest waits for clips of its
    bucket from the next chunk. A group with fewer than `SMALL_BATCH` clips that holds a clip
    held back before (``held``), and every group at the end of the stream (``final``), is
    fitted whole: a clip waits at most one chunk (the held clips of a group, fewer than a
    batch, are its oldest and go with its first batch), so the stream holds at most one
    chunk's clips back. ``known``: the keys of the clips held back, from the call before (a
    key's search weights cost about 0.2 ms a clip)."""
    from fourierjax._fourier._buckets import SMALL_BATCH

    known = known or {}
    keys = {c.index: known.get(c.index) or _group_key(c, fit_kwargs) for c in (*held, *new)}
    groups: dict[tuple, list[_Clip]] = {}
    for c in (*held, *new):
        groups.setdefault(keys[c.index], []).append(c)
    old = {c.index for c in held}
    now, keep = [], []
    for group in groups.values():
        n = len(group) - len(group) % SMALL_BATCH
        if final or not STREAM_HOLD or any(c.index in old for c in group[n:]):
            n = len(group)
        now += group[:n]
        keep += group[n:]
    return now, keep, keys


def _fit_chunk(chunk, size, names, num_harmonics, representation, dtype, kw, timings, fr,
               length_bucket):
    """One bucketed program for ``chunk`` (padded to ``size`` clips with copies of the last, and
    to a length bucket): the fit, its synthesis and the position metric; then alignment and the
    ClipFits: ``[(index, ClipFit), ...]``."""
    clock = _Clock(timings)
    T = length_bucket(max(len(c.features) for c in chunk))
    C = len(names)
    rows = [chunk[min(k, len(chunk) - 1)] for k in range(size)]
    feats = np.zeros((size, T, C))
    mask = np.zeros((size, T, C), bool)
    for k, c in enumerate(rows):
        n = len(c.features)
        feats[k, :n] = c.features
        feats[k, n:] = c.features[-1]
        mask[k, :n] = c.mask
    dts = np.array([c.sub.frame_time_s for c in rows])
    om_steps = np.array([c.omega_steps for c in rows])
    pelvis = {0 if c.body_map is None else c.body_map.pelvis for c in chunk}
    shared = len({c.sub.topology for c in chunk}) == 1 and len(pelvis) == 1
    # Host arrays go to the device as they are (device_put, already in the fit's dtype): a
    # conversion by jnp.asarray would compile a small program for every new chunk shape.
    put = lambda x, dt=dtype: jax.device_put(np.asarray(x, dt))  # noqa: E731
    skel = None
    if shared:  # one skeleton pytree with a leading clip axis (bone lengths differ per clip)
        skel = eqx.tree_at(lambda s: (s.offsets, s.end_site_offsets), chunk[0].sub.skeleton(),
                           (put(np.stack([c.sub.offsets for c in rows])),
                            put(np.stack([c.sub.end_site_offsets for c in rows]))))
    K = max(32, length_bucket(max(len(c.left) for c in rows)))
    strikes = np.zeros((size, K))
    for k, c in enumerate(rows):
        strikes[k, :len(c.left)] = c.left
    counts = np.array([len(c.left) for c in rows])
    # A chunk whose masks leave out whole frames only is fitted with a frame mask [B, T]: the
    # same fit, by a program without the per-channel refill (about 40% less to compile).
    frames = mask.any(axis=2)
    if not (frames[..., None] & ~mask).any():
        mask = frames
    res, pve, shifted, rows = _chunk_program(
        skel, put(feats), put(mask, bool), put(dts), put(om_steps), put(strikes),
        put(counts, np.int32),
        num_harmonics=num_harmonics, representation=representation, names=names,
        pelvis=min(pelvis), kw=kw)
    # One transfer, then host reads per clip.
    res, pve, shifted = jax.tree.map(np.asarray, (res, pve, shifted))
    clock("fit")
    if not shared:
        pve = _position_ves(chunk, representation, feats, res, dts, dtype)
    out = [(c.index, _clip_fit(c, k, res, rows[k][0], (shifted[0], rows[k][1]), names, pve[k],
                               fr))
           for k, c in enumerate(chunk)]
    clock("align_metrics")
    return out


def _chunk_impl(skeleton, feats, mask, dts, om_steps, strikes, counts, *, num_harmonics,
                representation, names, pelvis, kw):
    """The fit of a chunk, the phase shift to the left heel strikes (``strikes [B, K]`` frames,
    the first ``counts`` of each row; fourier.align_to_events: their circular mean), the models'
    synthesis and (with a stacked ``skeleton``) the position variance explained, in one
    compiled program per shape bucket. Returns ``(FitResult, pve [B] or None, (delta [B],
    shifted model), rows)``, ``rows``: each clip's ``(model, shifted model)``, sliced here (a
    device_put of 500 clips' rows of host arrays, 4,000 of them, cost 0.05-0.1 CPU-s; the
    program's outputs cost about a tenth)."""
    from fourierjax import fourier as fr
    from fourierjax._fourier import _synthesis

    res = fr.fit_batch(feats, dts, num_harmonics, mask=mask, omega_steps=om_steps,
                       representation=representation, channel_names=names, throw=False,
                       **dict(kw))
    th = res.omega_fit[:, None] * strikes * dts[:, None]
    used = jnp.arange(strikes.shape[1])[None, :] < counts[:, None]
    delta = jnp.arctan2(jnp.sum(jnp.where(used, jnp.sin(th), 0.0), axis=1),
                        jnp.sum(jnp.where(used, jnp.cos(th), 0.0), axis=1))
    shifted = jax.vmap(fr.shift_phase)(res.model, delta)
    rows = tuple(jax.tree.map(lambda v, k=k: v[k], (res.model, shifted))
                 for k in range(feats.shape[0]))
    if skeleton is None:
        return res, None, (delta, shifted), rows
    t = jnp.arange(feats.shape[1], dtype=feats.dtype)[None, :] * dts[:, None]
    frames = jnp.any(mask, axis=2) if mask.ndim == 3 else mask
    # The same metric as `_position_ve_impl` per clip (to float32 round-off), FK with the batch
    # axes minor: 3.5x less CPU (500 Bandai clips: 0.4 of the fit's 1.07 CPU-s before). A
    # tangent model's rotations go to FK as quaternions, not through its features.
    if representation == "tangent":
        m = res.model
        d = _synthesis._synthesize_batch_jit(m.offset, m.amplitude, m.phase, m.omega, t)
        pve = position_ve_batch(skeleton, feats, d, frames, representation, pelvis, means=m.frames)
    else:
        xhat = fr.synthesize_batch(res.model, t)
        pve = position_ve_batch(skeleton, feats, xhat, frames, representation, pelvis)
    return res, pve, (delta, shifted), rows


_chunk_program = _saved.saved(_jit.filter_jit(_chunk_impl))


def _position_ves(chunk, representation, feats, res, dts, dtype) -> np.ndarray:
    """Position variance explained of each clip of a chunk whose clips do not share a topology
    and pelvis: one call per clip."""
    from fourierjax import fourier as fr

    out = []
    for k, c in enumerate(chunk):
        model = jax.tree.map(lambda v, k=k: jnp.asarray(v[k]), res.model)
        xhat = fr.synthesize(model, jnp.arange(feats.shape[1], dtype=dtype) * dts[k])
        out.append(float(_position_ve(c.sub.skeleton(), representation,
                                      jnp.asarray(feats[k], dtype), xhat,
                                      jnp.asarray(c.mask.any(axis=1).tolist()
                                                  + [False] * (feats.shape[1] - len(c.mask))),
                                      0 if c.body_map is None else c.body_map.pelvis)))
    return np.array(out)


def _clip_fit(c: _Clip, k, res, raw, shifted, names, pve, fr) -> ClipFit:
    """The ClipFit of clip ``c``: row ``k`` of the chunk's host-side FitResult ``res``, its
    model ``raw`` and its model shifted to the heel strikes (``shifted``: ``(delta [B], model)``)."""
    dt = c.sub.frame_time_s
    if len(c.left):
        delta, model = float(shifted[0][k]), shifted[1]
        alignment = "left_heel_strike"
    else:
        hip = None if c.body_map is None else _hip_flexion_channel(raw, names, c.body_map)
        if hip is not None:
            delta = _hip_flexion_phase(raw, c.sub, hip, c.body_map)
            model = fr.shift_phase(raw, delta)
            alignment = "left_hip_flexion"
        else:
            model, delta, alignment = raw, 0.0, "none"
    status = fr.FitStatus(int(res.result[k]))
    message = "" if status == fr.FitStatus.SUCCESSFUL else (
        f"fit_motions: clip {c.index} ({c.motion.source or 'no file'}): {status.message} (fitted "
        f"fundamental {float(res.omega_fit[k]) / (2 * np.pi):.3f} Hz)")
    return ClipFit(
        source=c.motion.source, frame_start=int(c.start), frame_stop=int(c.stop),
        frame_time_s=float(dt), model=model, raw_model=raw, alignment=alignment,
        phase_shift=float(delta), omega_spectral=float(res.omega_spectral[k]),
        omega_steps=float(c.omega_steps), omega_fit=float(res.omega_fit[k]),
        rms=np.asarray(res.rms[k]), rms_deg=float(res.rms_deg[k]),
        variance_explained_angles=float(res.variance_explained_angles[k]),
        variance_explained_positions=float(pve),
        left_heel_strikes=tuple(int(v) for v in c.left),
        right_heel_strikes=tuple(int(v) for v in c.right),
        masked_frames=int(np.sum(~c.mask.all(axis=1))), masked_entries=int(np.sum(~c.mask)),
        result=status.name.lower(), message=message, body_map=c.body_map,
        winding_joints=winding_joints(c.features, c.names, c.mask.any(axis=1)),
    )


#: Clips per streamed chunk of `fit_motions` (fewer when the memory budget asks for it). A
#: chunk is prepared while the one before is fitted: smaller chunks overlap more of the two
#: (the first chunk's preparation and the last one's fit are not overlapped), larger ones cost
#: less preparation per clip (Bandai-1, CPU per clip: 64 clips +15%, 128 +5% over 256).
STREAM_CHUNK = 128

#: Whether the stream holds clips back for one chunk to fill whole batches of their length
#: bucket (`_hold_back`); False fits each chunk's clips as the chunk arrives.
STREAM_HOLD = True


def iter_fit_motions(
    motions,
    num_harmonics: int = 3,
    representation: str = "euler",
    *,
    segment: bool = True,
    use_contacts: bool = True,
    dtype=None,
    body_map=None,
    start_frame: int | None = None,
    stop_frame: int | None = None,
    chunk_size: int | None = None,
    progress: bool | None = False,
    timings: dict | None = None,
    passes: str = "longest",
    **fit_kwargs,
) -> Iterator[ClipFit]:
    """:func:`fit_motions` as a generator: each chunk's ClipFits, in order, as soon as the chunk
    is fitted (so that a caller can write models and let go of them while the next chunk is
    read). The arguments are :func:`fit_motions`' but ``throw``.

    Fit Fourier models to clips: segment, convert, find ω three ways, fit, align, score.

    Per clip: the steady straight stretch (:func:`steady_segment`, unless ``segment=False``),
    capture glitches masked out per joint (:func:`glitch_joints`: a glitchy joint's channels at
    those frames, :func:`feature_mask`), its features (:func:`features_from_motion`), heel
    strikes from FK foot contacts (``fourierjax.contacts``; ω from steps, Tilmanne §2.2). Then
    batched :func:`fourierjax.fourier.fit_batch` calls for the clips that share a channel layout,
    padded to shape buckets (clip lengths to powers of two, batches to chunks of 16 or 128
    clips: `fourierjax._fourier._buckets`) so that new lengths and batch sizes reuse compiled
    code; phase alignment to the left heel strike (fallback: the peak of the left hip flexion
    fundamental: the body map's left hip channel with the largest fundamental), and the metrics.
    Feet, legs, pelvis and trajectory come from each clip's body map.

    ``motions`` is read as a stream, ``chunk_size`` clips at a time: the next chunk is read and
    prepared in a background thread while the current one is fitted (in two threads, half the
    chunk each, once a chunk has run the preparation's programs), and the fit's chunks run two
    at once (`_fit_jobs`). Each clip is fitted with
    the clips of its length bucket: of the clips of a bucket that a chunk brings, whole batches
    are fitted at once and the rest waits one chunk for more of its bucket (`STREAM_HOLD`), so
    a clip is padded to its own bucket and batches are full. ClipFits come out in the input
    order; a generator that reads the files of a large folder (or the paths themselves) never
    holds more than three chunks (the one being read, the newest one and the clips held back).

    Arguments:
        motions: an iterable of Motions (e.g. after dropping a rest frame) or BVH paths (read
            with ``io.bvh.read_bvh``); a generator is consumed lazily.
        num_harmonics: N; representation: "euler" | "expmap".
        body_map: a `fourierjax.body.BodyMap` for every clip, an iterable of one per clip (read
            alongside ``motions``), or None to infer each clip's
            (``fourierjax.body.infer_body_map``).
        start_frame, stop_frame: only frames ``[start_frame, stop_frame)`` of each clip are
            used (the steady segment is looked for inside them); None: the clip's ends.
        chunk_size: clips per streamed chunk (default `STREAM_CHUNK`, fewer when three chunks'
            features would not fit the memory budget, ``max_memory``).
        progress: show a tqdm progress bar on stderr (None: only when stderr is a terminal).
        timings: a dict that receives the seconds spent per stage (``read``, ``body_map``,
            ``segment``, ``glitch``, ``features``, ``contacts``, ``fit``, ``align_metrics``;
            the stages before ``fit`` run in the background threads (their seconds summed),
            overlapping the fit; ``fit`` and ``align_metrics`` run in two threads too (their
            seconds summed); ``wait``: the fitting thread waiting for the preparation, so that
            the wall time is at most about ``wait + fit + align_metrics``).
        passes: ``"longest"`` fits the steady segment; ``"auto"`` fits a clip that walks back
            and forth over every straight pass, each in its own heading frame with the passes'
            heel strikes phase-aligned (``fourierjax._passes.prepare_passes``; its frames are
            then rows of that layout, the turns masked).
        fit_kwargs: passed on to ``fit_batch`` (search band, grid, ``max_memory``...).

    Returns:
        One :class:`ClipFit` per motion, in order. A clip that cannot be fitted (e.g. too short
        for a cycle) does not stop the others: its ``result`` and ``message`` say why.
    """
    from fourierjax.body import BodyMap

    _passes.check_mode(passes)

    dtype = dtype or jnp.zeros(()).dtype
    if body_map is None or isinstance(body_map, BodyMap):
        maps = itertools.repeat(body_map)
    else:
        if hasattr(body_map, "__len__") and hasattr(motions, "__len__") and (
                len(body_map) != len(motions)):
            raise UserError(f"fit_motions: {len(body_map)} body maps for {len(motions)} motions")
        maps = iter(body_map)
    total = len(motions) if hasattr(motions, "__len__") else None
    items = iter(motions)
    opts = dict(representation=representation, segment=segment, use_contacts=use_contacts,
                start_frame=start_frame, stop_frame=stop_frame, timings=timings, passes=passes)
    count = [0]
    size = [chunk_size]
    # The first chunk's preparation overlaps no fit: with the automatic chunk size it is half a
    # chunk, so that the fit starts sooner (and the stream's last chunk, whose fit overlaps no
    # preparation, is smaller on average).
    half = [chunk_size is None]
    warm = [chunk_size is None]  # the first clip alone runs the programs (below)

    def read_chunk() -> list[_Clip]:
        entries = []
        while size[0] is None or len(entries) < (max(1, size[0] // 2) if half[0] else size[0]):
            try:
                m = next(items)
            except StopIteration:
                break
            try:
                bm = next(maps)
            except StopIteration:
                raise UserError(f"fit_motions: fewer body maps than motions ({count[0]})") from None
            if size[0] is None:  # the first clip alone sizes the chunks; it runs the chunks'
                # programs (`_batch`'s whole blocks of rows), so later chunks compile nothing new
                first = prepare_chunk([(count[0], m, bm)], **opts)[0]
                size[0] = _stream_chunk(first, num_harmonics, fit_kwargs.get("max_memory"))
                entries.append(first)
            else:
                entries.append((count[0], m, bm))
            count[0] += 1
        half[0] = False
        done = [e for e in entries if isinstance(e, _Clip)]
        rest = [e for e in entries if not isinstance(e, _Clip)]
        # Split once a chunk (or the first clip) has run the preparation's programs: two halves
        # would otherwise compile the same new program twice, at once.
        got = _prepare_split(rest, helper, opts) if warm[0] else prepare_chunk(rest, **opts)
        warm[0] = True
        return done + got

    from tqdm import tqdm

    yielded = 0
    with (concurrent.futures.ThreadPoolExecutor(1) as pool,
          concurrent.futures.ThreadPoolExecutor(1) as helper,
          concurrent.futures.ThreadPoolExecutor(1) as fitter,
          tqdm(total=total, unit="clip", desc="fit_motions", disable=_no_bar(progress),
               leave=False) as bar):
        ahead = pool.submit(read_chunk)
        held: list[_Clip] = []
        keys: dict[int, tuple] = {}
        done: dict[int, ClipFit] = {}
        while True:
            clock = _Clock(timings)
            chunk = ahead.result()
            clock("wait")  # the fit waiting for the reader: preparation on the critical path
            if chunk:
                ahead = pool.submit(read_chunk)  # chunk k + 1 is read while chunk k is fitted
            now, held, keys = _hold_back(held, chunk, fit_kwargs, final=not chunk, known=keys)
            fits = _fit_clips(now, num_harmonics, representation, dtype, fit_kwargs, timings,
                              keys, fitter) if now else []
            done.update(zip((c.index for c in now), fits))
            bar.update(len(fits))
            while yielded in done:  # in the input order
                yield done.pop(yielded)
                yielded += 1
            if not chunk:
                break
    if not yielded:
        raise UserError("fit_motions: no motions given")
    if not isinstance(maps, itertools.repeat) and next(maps, None) is not None:
        raise UserError(f"fit_motions: more body maps than the {yielded} motions")


def fit_motions(motions, num_harmonics: int = 3, representation: str = "euler", *,
                throw: bool = False, **kwargs) -> list[ClipFit]:
    """Fit Fourier models to clips: segment, convert, find ω three ways, fit, align, score.

    The clips are read as a stream and fitted in bucketed chunks (:func:`iter_fit_motions`,
    which documents every step and argument).

    Arguments:
        motions: an iterable of Motions or BVH paths; num_harmonics: N;
        representation: "euler" | "expmap";
        throw: raise a UserError (the first failed clip's message, naming its file) after the
            fit instead of returning failed clips;
        kwargs: the options of :func:`iter_fit_motions` (``segment``, ``use_contacts``,
            ``dtype``, ``body_map``, ``start_frame``, ``stop_frame``, ``chunk_size``,
            ``progress``, ``timings``) and of ``fit_batch``.

    Returns:
        One :class:`ClipFit` per motion, in order. A clip that cannot be fitted (e.g. too short
        for a cycle) does not stop the others: its ``result`` and ``message`` say why.
    """
    results = list(iter_fit_motions(motions, num_harmonics, representation, **kwargs))
    failed = [r for r in results if not r.successful]
    if throw and failed:
        more = f" (and {len(failed) - 1} other clip(s))" if len(failed) > 1 else ""
        raise UserError(failed[0].message + more)
    return results


#: Fewest clips in a chunk whose preparation `_prepare_split` runs as two halves at once.
SPLIT_MIN = 16


def _prepare_split(entries, helper, opts) -> list[_Clip]:
    """`prepare_chunk` of ``entries`` as two halves at once, the first in ``helper`` (a
    one-thread executor), with the same clips (each clip's preparation is its own, whichever
    clips share its chunk). The preparation is the stream's critical path: per clip, NumPy and
    small JAX programs, much of it outside the GIL, so a second thread runs beside the fit
    (500 Bandai-1 clips, Euler, 2 cores at a load of 6-10: wall -11%, the median of 10
    paired rounds, CPU unchanged; tangent, whose fit is the critical path, no gain). ``opts``' ``timings``:
    each thread's own seconds, summed."""
    if len(entries) < SPLIT_MIN:
        return prepare_chunk(entries, **opts)
    h = len(entries) // 2
    theirs = None if opts["timings"] is None else {}
    first = helper.submit(prepare_chunk, entries[:h], **dict(opts, timings=theirs))
    try:
        second = prepare_chunk(entries[h:], **opts)
    finally:
        concurrent.futures.wait([first])  # the first half is done (or failed) either way
    got = first.result()
    for k, v in (theirs or {}).items():
        opts["timings"][k] = opts["timings"].get(k, 0.0) + v
    return got + second


def _no_bar(progress) -> bool | None:
    """tqdm's ``disable``: None (its rule: no bar unless stderr is a terminal) or a bool."""
    return None if progress is None else not progress


def _stream_chunk(first: _Clip, num_harmonics: int, max_memory) -> int:
    """Clips per streamed chunk: `STREAM_CHUNK`, fewer when three chunks of clips like ``first``
    (features and masks on the host, in float64, and the fit's working memory) exceed the
    budget; a multiple of the fit's batch buckets where it can be."""
    from fourierjax._fourier._buckets import LARGE_BATCH, SMALL_BATCH, length_bucket
    from fourierjax._memory import fit_bytes_per_clip, resolve_limit

    limit = resolve_limit("fit_motions: max_memory", max_memory)
    T, C = length_bucket(len(first.features)), first.features.shape[1]
    per_clip = 3 * (9 * T * C + first.motion.channels.nbytes) + fit_bytes_per_clip(
        T, C, num_harmonics, 8)
    n = max(1, min(STREAM_CHUNK, int(limit // max(per_clip, 1))))
    for step in (LARGE_BATCH, SMALL_BATCH):
        if n >= step:
            return n - n % step
    return n
