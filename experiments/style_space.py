"""Experiment: style recognition and style transfer on a labelled folder of clips (Bandai-1 by default).

Every locomotion clip whose file name matches the config's pattern (named groups ``content``,
``style``, ``take``) is fitted once (``motion.fit_motions``, cached under ``out/``) and phase-aligned
to a body event found through the body map. Style recognition: nearest class mean, shrinkage
LDA and k-NN on the style vectors (``style.style_vector``) and in PCA spaces, leaving one take
out on the walks and one content out across contents. Transfer from one content to another
(walk -> run ...): Unuma eq. 8 and the method-search variants against the baseline (the base
motion unchanged), scored by ``style.cycle_distance`` to the real target and by a classifier
trained on real target-content clips only.

Writes ``recognition.{csv,md}``, ``recognition_pca.{csv,md}``, ``recognition_contents.{csv,md}``,
``transfer.{csv,md}``, ``transfer_summary.{csv,md}``, ``flips.{csv,md}``, ``summary.json``,
``confusion_walk.png`` and ``pca_accuracy.png``.
"""

from __future__ import annotations

import hashlib
import json
import pathlib
import re

import numpy as np

from experiments._util import ROOT, parse, run_main, write_table
from fourierjax import config as _config


def _is_str(v):
    return None if isinstance(v, str) and v else f"expected a non-empty string, got {v!r}"


_STRS = _config.list_of(_is_str, "strings")


def _pattern(v):
    try:
        rx = re.compile(v)
    except (re.error, TypeError) as err:
        return f"expected a regular expression, got {v!r} ({err})"
    missing = {"content", "style", "take"} - set(rx.groupindex)
    return f"the pattern needs named groups {sorted(missing)}" if missing else None


def _pairs(v):
    if not isinstance(v, list) or not all(isinstance(p, list) and len(p) == 2 and all(isinstance(s, str) for s in p)
                                          for p in v):
        return f"expected a list of [source, target] content pairs, got {v!r}"
    return None


# The schema of this experiment's config (registered here, next to the code that reads it).
_config.SCHEMAS.setdefault("style_space", {
    "folders": _config.Field(_STRS, doc="folders to search, relative to the repository root; the first that exists"),
    "pattern": _config.Field(_pattern, r"dataset-1_(?P<content>[a-z-]+)_(?P<style>[a-z-]+)_(?P<take>\d+)\.bvh$",
                             "file-name regular expression with groups content, style, take"),
    "contents": _config.Field(_STRS, ["walk", "run", "dash", "walk-back", "walk-left", "walk-right"],
                              "locomotion contents to fit"),
    "styles": _config.Field(_config.list_of(_is_str, "strings", min_len=0), [], "styles to use (empty: all)"),
    "normal": _config.Field(_is_str, "normal", "the neutral style"),
    "harmonics": _config.Field(_config.integer(1, 16), 3),
    "representation": _config.Field(_config.choice("euler", "expmap"), "euler", "rotation channels"),
    "pca_k": _config.Field(_config.list_of(_config.integer(1, 1000), "integers"), [2, 5, 10, 20]),
    "knn": _config.Field(_config.integer(1, 50), 1, "k of the k-NN classifier"),
    "shrinkage": _config.Field(_config.number(0, 1), 0.5, "LDA covariance shrinkage towards the identity"),
    "ridge": _config.Field(_config.number(0, 1e6), 1.0, "ridge penalty of the style-space map (z-scored)"),
    "transfers": _config.Field(_pairs, [["walk", "run"], ["walk", "dash"], ["walk", "walk-back"], ["run", "walk"]]),
    "weights": _config.Field(_config.list_of(_config.number(0, 3), "numbers"), [0.0, 0.5, 1.0, 1.5],
                             "weights of the limb-flip check"),
    "num_samples": _config.Field(_config.integer(8, 512), 64, "cycle samples of the distance"),
    "cache": _config.Field(_is_str, "out/style_space_cache", "where fitted models are cached"),
})


# ----------------------------------------------------------------------------- clips and fits


def find_clips(folder: pathlib.Path, pattern: str, contents, styles) -> list[dict]:
    """Labelled clips of a folder: ``{"path", "content", "style", "take"}``, sorted by name."""
    rx = re.compile(pattern)
    out = []
    for p in sorted(folder.iterdir()):
        m = rx.search(p.name)
        if m and m["content"] in contents and (not styles or m["style"] in styles):
            out.append({"path": p, "content": m["content"], "style": m["style"], "take": m["take"]})
    return out


def pelvis_rooted(motion, body_map):
    """The clip with the root joint moved onto the body map's pelvis: FK-exact.

    Rigs whose travel sits on a child of joint 0 (Bandai: ``joint_Root`` stays at the origin in
    walks, ``Hips`` carries the travel; in runs it is the other way round) give the fit a root
    that does not move or a pelvis whose translation is dropped. The root's channels get the
    pelvis's world pose and the pelvis's own channels the identity; every joint's world pose
    is unchanged. A clip whose pelvis is joint 0 (or not a child of it) is returned as it is.
    """
    import dataclasses

    from fourierjax import rotations

    topo = motion.topology
    j = body_map.pelvis
    if j == 0 or topo.parents[j] != 0:
        return motion
    ch = motion.channels.copy()

    def pose(k):
        names, base = topo.channels[k], topo.channel_offsets[k]
        t = np.broadcast_to(np.asarray(motion.offsets[k], float), (motion.num_frames, 3)).copy()
        rot = [base + i for i, c in enumerate(names) if c.endswith("rotation")]
        pos = {c[0]: base + i for i, c in enumerate(names) if c.endswith("position")}
        for a, i in pos.items():
            t[:, "XYZ".index(a)] = ch[:, i]
        q = np.asarray(rotations.quat_from_euler(np.radians(ch[:, rot]), topo.rotation_orders[k]))
        return t, q, rot, pos

    t0, q0, rot0, pos0 = pose(0)
    t1, q1, rot1, pos1 = pose(j)
    if len(pos0) != 3 or len(rot0) != 3:
        return motion
    p_world = t0 + np.asarray(rotations.quat_apply(q0, t1))
    q_world = np.asarray(rotations.quat_multiply(q0, q1))
    # Without position channels the pelvis keeps its offset, which the root must absorb.
    local = np.zeros(3) if len(pos1) == 3 else np.asarray(motion.offsets[j], float)
    root_pos = p_world - np.asarray(rotations.quat_apply(q_world, np.broadcast_to(local, p_world.shape)))
    for a, i in pos0.items():
        ch[:, i] = root_pos[:, "XYZ".index(a)]
    ch[:, rot0] = np.degrees(np.asarray(rotations.euler_from_quat(q_world, topo.rotation_orders[0])))
    for i in pos1.values():
        ch[:, i] = 0.0
    ch[:, rot1] = 0.0
    return dataclasses.replace(motion, channels=ch)


def align_to_left_step(model, skeleton, body_map, num_samples: int = 64):
    """The model shifted so that phase 0 is where the left ankle is furthest ahead of the right.

    "Ahead" is the body's forward direction in the heading frame, the mean horizontal
    ankle-to-toe vector over the cycle (the travel direction when the rig has no toes), so
    the event is the same for walks, runs, backward and sideways walks.
    """
    from fourierjax import fourier, style

    p = np.asarray(style.cycle_positions(model, skeleton, num_samples=num_samples))  # [K, J, 3], heading frame, y up
    left, right = body_map.left, body_map.right
    d = (p[:, left.ankle] - p[:, right.ankle])[:, [0, 2]]  # [K, 2]
    if left.toe >= 0 and right.toe >= 0:
        fwd = np.concatenate([p[:, g.toe] - p[:, g.ankle] for g in (left, right)])[:, [0, 2]].mean(0)
    else:
        names = list(model.channel_names)
        off = np.asarray(model.offset)
        fwd = np.array([off[names.index("root.vx")], off[names.index("root.vz")]])
    fwd = fwd / max(np.linalg.norm(fwd), 1e-12)
    s = d @ fwd
    th = 2 * np.pi * np.arange(num_samples) / num_samples
    # The fundamental's peak: robust to flat tops and sampling.
    peak = float(np.arctan2((s * np.sin(th)).sum(), (s * np.cos(th)).sum()))
    return fourier.shift_phase(model, peak)


def fit_clips(clips, harmonics: int, representation: str, cache: pathlib.Path):
    """Fit, align and cache every clip. Returns ``(models, skeletons, body_maps, motions, failed)``."""
    from fourierjax import fourier
    from fourierjax.body import infer_body_map
    from fourierjax.io.bvh import read_bvh
    from fourierjax.motion import fit_motions

    motions, maps = [], []
    for c in clips:
        m = read_bvh(c["path"])
        bm = infer_body_map(m)
        motions.append(pelvis_rooted(m, bm))
        maps.append(bm)
    key = hashlib.sha256(json.dumps([harmonics, representation, [c["path"].name for c in clips]]).encode())
    path = cache / f"fits_{representation}_{harmonics}_{key.hexdigest()[:12]}.npz"
    names = None
    if path.exists():
        z = np.load(path)
        ok = z["ok"]
        names = tuple(str(s) for s in z["names"])
        raw = [fourier.FourierModel(z["offset"][i], z["amplitude"][i], z["phase"][i], z["omega"][i],
                                    representation=representation, channel_names=names) for i in range(len(clips))]
        print(f"loaded {len(clips)} fits from {path}", flush=True)
    else:
        fits = fit_motions(motions, harmonics, representation, throw=False)
        ok = np.array([f.successful for f in fits])
        raw = [f.model for f in fits]
        names = raw[0].channel_names
        cache.mkdir(parents=True, exist_ok=True)
        np.savez(path, ok=ok, names=np.array(names), offset=np.stack([np.asarray(m.offset) for m in raw]),
                 amplitude=np.stack([np.asarray(m.amplitude) for m in raw]),
                 phase=np.stack([np.asarray(m.phase) for m in raw]),
                 omega=np.stack([np.asarray(m.omega) for m in raw]))
        for f in fits:
            if not f.successful:
                print(f"  not fitted: {f.message}", flush=True)
    import jax.numpy as jnp

    ok = np.asarray(ok).copy()
    bad = [i for i in range(len(clips)) if not ok[i]]
    if bad:  # a clip whose steady stretch is too short for a cycle: fit the whole clip instead
        fb = cache / f"{path.stem}_whole.npz"
        if fb.exists():
            z = np.load(fb)
            res = [(bool(z["ok"][k]), fourier.FourierModel(z["offset"][k], z["amplitude"][k], z["phase"][k],
                                                          z["omega"][k], representation=representation,
                                                          channel_names=names)) for k in range(len(bad))]
        else:
            fits = fit_motions([motions[i] for i in bad], harmonics, representation, segment=False, throw=False)
            res = [(f.successful, f.model) for f in fits]
            np.savez(fb, ok=np.array([r[0] for r in res]), offset=np.stack([np.asarray(r[1].offset) for r in res]),
                     amplitude=np.stack([np.asarray(r[1].amplitude) for r in res]),
                     phase=np.stack([np.asarray(r[1].phase) for r in res]),
                     omega=np.stack([np.asarray(r[1].omega) for r in res]))
        for i, (good, m) in zip(bad, res, strict=True):
            if good:
                ok[i], raw[i] = True, m
                print(f"  {clips[i]['path'].name}: fitted on the whole clip", flush=True)
    models = [align_to_left_step(fourier.FourierModel(jnp.asarray(m.offset), jnp.asarray(m.amplitude),
                                                      jnp.asarray(m.phase), jnp.asarray(m.omega),
                                                      representation=representation, channel_names=names),
                                 motions[i].skeleton(), maps[i]) for i, m in enumerate(raw)]
    failed = [c["path"].name for c, o in zip(clips, ok, strict=True) if not o]
    return models, [m.skeleton() for m in motions], maps, motions, failed


# ----------------------------------------------------------------------------- classifiers


def _zscore(train, *rest):
    mu, sd = train.mean(0), train.std(0)
    sd = np.where(sd > 1e-9 * max(sd.max(), 1e-300), sd, 1.0)
    return [(x - mu) / sd for x in (train, *rest)]


def classify(method: str, xtr, ytr, xte, *, k: int = 1, shrinkage: float = 0.5):
    """Predicted labels of ``xte`` (rows) by a classifier trained on ``(xtr, ytr)`` (z-scored on xtr).

    ``"ncm"``: nearest class mean; ``"lda"``: linear discriminant with a pooled within-class
    covariance shrunk towards a multiple of the identity (Ledoit-Wolf style,
    ``(1 - s) S + s tr(S)/D I``), in the dual form when ``D`` exceeds the sample count;
    ``"knn"``: majority of the ``k`` nearest training rows (ties: the nearest).
    """
    ytr = np.asarray(ytr)
    xtr, xte = _zscore(np.asarray(xtr, float), np.asarray(xte, float))
    classes = sorted(set(ytr.tolist()))
    means = np.stack([xtr[ytr == c].mean(0) for c in classes])
    if method == "ncm":
        d = ((xte[:, None] - means[None]) ** 2).sum(-1)
        return np.array(classes)[d.argmin(1)]
    if method == "knn":
        d = ((xte[:, None] - xtr[None]) ** 2).sum(-1)
        order = np.argsort(d, axis=1)[:, :k]
        out = []
        for row in order:
            labels = ytr[row].tolist()
            counts = {c: labels.count(c) for c in labels}
            best = max(counts.values())
            out.append(next(c for c in labels if counts[c] == best))  # nearest among the tied
        return np.array(out)
    if method == "lda":
        r = xtr - means[[classes.index(c) for c in ytr]]  # within-class residuals [M, D]
        m, dim = r.shape
        s = shrinkage
        alpha = s * float((r * r).sum()) / max(m, 1) / dim  # s tr(S) / D, S = R^T R / M
        if alpha <= 1e-12:  # one row per class: no within-class scatter, the identity (z-scored NCM)
            alpha, s = 1.0, 1.0
        # Sigma = (1 - s) R^T R / M + alpha I; apply its inverse by Woodbury (M << D).
        beta = (1 - s) / max(m, 1)

        def sinv(v):  # v [n, D] -> v Sigma^{-1}
            if alpha <= 0:
                return v @ np.linalg.pinv(beta * r.T @ r)
            inner = np.linalg.solve(alpha * np.eye(m) + beta * r @ r.T, r @ v.T)  # [M, n]
            return (v - beta * (r.T @ inner).T) / alpha

        w = sinv(means)  # [K, D]
        b = -0.5 * (w * means).sum(1)
        return np.array(classes)[(xte @ w.T + b).argmax(1)]
    raise ValueError(method)


CLASSIFIERS = ("ncm", "lda", "knn")


def pca_fit(x, k):
    mu = x.mean(0)
    _, _, vt = np.linalg.svd(x - mu, full_matrices=False)
    return mu, vt[:k]


# ----------------------------------------------------------------------------- transfer methods


def _vectors(models):
    from fourierjax import style

    return np.asarray(style.style_matrix(models), float)


def transfer_vectors(method, vs, vt, styles, target, normal, ridge):
    """Style vector of the target content in style ``target``, from source-content vectors ``vs``
    and target-content vectors ``vt`` (dicts style -> vector); nothing fitted sees ``vt[target]``."""
    others = [s for s in styles if s != target]
    if method == "content_mean":
        ms = np.mean([vs[s] for s in others], 0)
        mt = np.mean([vt[s] for s in others], 0)
        return mt + (vs[target] - ms)
    if method == "ls_weights":
        # One weight per style-vector entry group (a channel's 1 + 2N numbers), least squares
        # over the other styles' pairs: vt[s] - vt[normal] ~ w (vs[s] - vs[normal]).
        train = [s for s in others if s != normal]
        dx = np.stack([vs[s] - vs[normal] for s in train])
        dy = np.stack([vt[s] - vt[normal] for s in train])
        w = (dx * dy).sum(0) / np.maximum((dx * dx).sum(0), 1e-12)
        return vt[normal] + w * (vs[target] - vs[normal])
    if method == "ridge_map":
        # Kernel (dual) ridge in z-scored style space, from source styles to target styles.
        xs = np.stack([vs[s] for s in others])
        ys = np.stack([vt[s] for s in others])
        mx, sx = xs.mean(0), np.where(xs.std(0) > 1e-12, xs.std(0), 1.0)
        my, sy = ys.mean(0), np.where(ys.std(0) > 1e-12, ys.std(0), 1.0)
        zx, zy = (xs - mx) / sx, (ys - my) / sy
        a = np.linalg.solve(zx @ zx.T + ridge * np.eye(len(others)), zy)
        z = ((vs[target] - mx) / sx) @ zx.T @ a
        return my + z * sy
    raise ValueError(method)


def amplitude_ratio(base, a, b):
    """Unuma's superposition with amplitudes scaled by the ratio ``A_a / A_b`` (not shifted by ``A_a - A_b``)."""
    import equinox as eqx
    import jax.numpy as jnp

    from fourierjax import style

    char = style.characteristic(a, b)
    out = style.superpose(base, [char], [1.0])
    ratio = jnp.clip((a.amplitude + 1e-3) / (b.amplitude + 1e-3), 0.0, 4.0)
    return eqx.tree_at(lambda m: m.amplitude, out, base.amplitude * ratio)


# ----------------------------------------------------------------------------- the experiment


def _max_jump(model, skeleton, frame_time_s):
    """Largest joint displacement between consecutive frames over one synthesized cycle (file units)."""
    from fourierjax import style

    k = 256  # fixed (one compile); the per-sample jump scaled to a frame (smooth, so linear)
    p = np.asarray(style.cycle_positions(model, skeleton, num_samples=k))
    per_sample = float(np.linalg.norm(np.diff(np.concatenate([p, p[:1]]), axis=0), axis=-1).max())
    return per_sample * k * float(model.omega) * frame_time_s / (2 * np.pi)


def _clip_max_jump(motion):
    """Largest root-relative joint displacement between consecutive frames of a real clip."""
    from fourierjax.motion import motion_joint_positions

    f = motion.num_frames
    frames = np.minimum(np.arange(-(-f // 128) * 128), f - 1)  # padded: few compiled lengths
    p = motion_joint_positions(motion, frames)[:f]
    p = p - p[:, :1]
    return float(np.linalg.norm(np.diff(p, axis=0), axis=-1).max())


def body(argv=None) -> None:
    import jax.numpy as jnp

    from fourierjax import style, viz

    cfg, out = parse("style_space", __doc__.splitlines()[0], argv)
    folder = next((ROOT / f for f in cfg["folders"] if (ROOT / f).is_dir()), None)
    if folder is None:
        print(f"style_space: skipped: none of the folders {cfg['folders']} exists")
        (out / "summary.json").write_text(json.dumps({"skipped": True}))
        return
    clips = find_clips(folder, cfg["pattern"], cfg["contents"], cfg["styles"])
    print(f"{len(clips)} clips in {folder}", flush=True)
    cache = pathlib.Path(cfg["cache"])
    cache = cache if cache.is_absolute() else ROOT / cache
    models, skels, maps, motions, failed = fit_clips(clips, cfg["harmonics"], cfg["representation"], cache)
    keep = [i for i, c in enumerate(clips) if c["path"].name not in failed]
    lab = {(clips[i]["content"], clips[i]["style"], clips[i]["take"]): i for i in keep}
    V = _vectors([models[i] for i in range(len(models))])
    styles = sorted({clips[i]["style"] for i in keep})
    np.savez(out / "vectors.npz", vectors=V, names=np.array(models[0].channel_names),
             style=np.array([c["style"] for c in clips]), content=np.array([c["content"] for c in clips]),
             take=np.array([c["take"] for c in clips]), fitted=np.array([i in keep for i in range(len(clips))]))
    normal = cfg["normal"]
    summary: dict = {"folder": str(folder), "clips": len(clips), "failed": failed, "styles": styles,
                     "representation": cfg["representation"], "harmonics": cfg["harmonics"]}
    kw = {"k": cfg["knn"], "shrinkage": cfg["shrinkage"]}

    # --- recognition on walks, leaving one take out
    walks = [i for i in keep if clips[i]["content"] == "walk"]
    takes = sorted({clips[i]["take"] for i in walks})
    y = np.array([clips[i]["style"] for i in range(len(clips))], dtype=object)

    def loto(idx, space=None):
        preds = {c: np.empty(len(idx), object) for c in CLASSIFIERS}
        for t in takes:
            te = [n for n, i in enumerate(idx) if clips[i]["take"] == t]
            tr = [n for n, i in enumerate(idx) if clips[i]["take"] != t]
            if not te or not tr:
                continue
            xtr, xte = V[[idx[n] for n in tr]], V[[idx[n] for n in te]]
            if space is not None:
                mu, comp = pca_fit(xtr, space)
                xtr, xte = (xtr - mu) @ comp.T, (xte - mu) @ comp.T
            for c in CLASSIFIERS:
                preds[c][te] = classify(c, xtr, y[[idx[n] for n in tr]], xte, **kw)
        return preds

    rows, best = [], ("", -1.0)
    preds = loto(walks)
    truth = y[walks]
    for c in CLASSIFIERS:
        acc = float(np.mean(preds[c] == truth))
        rows.append({"content": "walk", "protocol": "leave one take out", "classifier": c, "accuracy": acc,
                     "n": len(walks), "chance": 1 / len(styles)})
        best = max(best, (c, acc), key=lambda b: b[1])
    # The same, with every other locomotion clip in the training set (never a clip of the test take's
    # walks): each content centred on its training mean, so a style is what differs from the content.
    # It gives the classifiers several rows per style, i.e. a within-style scatter for LDA.
    pooled = {c: np.empty(len(walks), object) for c in CLASSIFIERS}
    for t in takes:
        te = [n for n, i in enumerate(walks) if clips[i]["take"] == t]
        tr = [i for i in keep if not (clips[i]["content"] == "walk" and clips[i]["take"] == t)]
        X = V.copy()
        for content in {clips[i]["content"] for i in keep}:
            rows_c = [i for i in tr if clips[i]["content"] == content]
            X[[i for i in range(len(clips)) if clips[i]["content"] == content]] -= V[rows_c].mean(0)
        for c in CLASSIFIERS:
            pooled[c][te] = classify(c, X[tr], y[tr], X[[walks[n] for n in te]], **kw)
    for c in CLASSIFIERS:
        acc = float(np.mean(pooled[c] == truth))
        rows.append({"content": "walk", "protocol": "leave one take out, + other contents (centred)",
                     "classifier": c, "accuracy": acc, "n": len(walks), "chance": 1 / len(styles)})
        if acc > best[1]:
            best, preds = (c, acc), {**preds, c: pooled[c]}
    summary["walk_loto"] = {f"{r['classifier']} ({r['protocol']})": r["accuracy"] for r in rows}
    # PCA spaces (fitted on the training fold of z-scored... raw vectors)
    pca_rows = []
    for k in cfg["pca_k"]:
        kk = min(k, len(walks) - len(walks) // max(len(takes), 1) - 1)
        p = loto(walks, kk)
        for c in CLASSIFIERS:
            pca_rows.append({"k": k, "k_used": kk, "classifier": c, "accuracy": float(np.mean(p[c] == truth))})
    write_table(rows, out, "recognition", "Style recognition on walks, leaving one take out")
    write_table(pca_rows, out, "recognition_pca", "The same in the PCA space of the training fold")
    summary["walk_loto_pca"] = pca_rows

    # --- across contents: train on the other contents, test on one
    crow = []
    for content in cfg["contents"]:
        te = [i for i in keep if clips[i]["content"] == content]
        tr = [i for i in keep if clips[i]["content"] != content]
        if not te or len({clips[i]["style"] for i in tr}) < 2:
            continue
        for c in CLASSIFIERS:
            p = classify(c, V[tr], y[tr], V[te], **kw)
            crow.append({"test_content": content, "classifier": c, "accuracy": float(np.mean(p == y[te])),
                         "n": len(te)})
    write_table(crow, out, "recognition_contents", "Across contents: trained on the other contents, tested on one")
    summary["across_contents"] = crow

    # confusion matrix of the best walk classifier
    import matplotlib.pyplot as plt

    cm = np.zeros((len(styles), len(styles)), int)
    for t, p in zip(truth, preds[best[0]], strict=True):
        cm[styles.index(t), styles.index(p)] += 1
    fig, ax = plt.subplots(figsize=(7, 6))
    ax.imshow(cm, cmap="Blues")
    ax.set_xticks(range(len(styles)), styles, rotation=60, ha="right", fontsize=8)
    ax.set_yticks(range(len(styles)), styles, fontsize=8)
    for a in range(len(styles)):
        for b in range(len(styles)):
            if cm[a, b]:
                ax.text(b, a, str(cm[a, b]), ha="center", va="center", fontsize=8)
    ax.set_xlabel("predicted")
    ax.set_ylabel("true")
    ax.set_title(f"Walks, leave one take out: {best[0]} {best[1]:.0%} (chance {1 / len(styles):.1%})", fontsize=9)
    fig.tight_layout()
    viz.save_figure(fig, out / "confusion_walk.png")
    fig, ax = plt.subplots(figsize=(5, 3.5))
    for c in CLASSIFIERS:
        ks = [r["k"] for r in pca_rows if r["classifier"] == c]
        ax.plot(ks, [r["accuracy"] for r in pca_rows if r["classifier"] == c], "o-", label=c)
        ax.axhline(next(r["accuracy"] for r in rows if r["classifier"] == c), ls=":", lw=1,
                   color=ax.lines[-1].get_color())
    ax.set_xscale("log")
    ax.set_xlabel("PCA dimensions k")
    ax.set_ylabel("accuracy (walks, leave one take out)")
    ax.legend()
    ax.grid(alpha=0.3)
    fig.tight_layout()
    viz.save_figure(fig, out / "pca_accuracy.png")

    # --- transfer
    trows, flips = [], []
    methods = ("baseline", "eq8", "eq8_phasor", "amplitude_ratio", "content_mean", "ls_weights", "ridge_map")
    for src, dst in cfg["transfers"]:
        take = takes[0]

        def get(content, s):
            return lab.get((content, s, take)) if (content, s, take) in lab else next(
                (i for (c2, s2, _), i in lab.items() if c2 == content and s2 == s), None)

        sty = [s for s in styles if get(src, s) is not None and get(dst, s) is not None]
        if normal not in sty or len(sty) < 3:
            continue
        vs = {s: V[get(src, s)] for s in sty}
        vt = {s: V[get(dst, s)] for s in sty}
        # classifier trained on real target-content clips only (all takes)
        tr = [i for i in keep if clips[i]["content"] == dst and clips[i]["style"] in sty]
        for s in sty:
            if s == normal:
                continue
            i_t, i_b = get(dst, s), get(dst, normal)
            a, b = models[get(src, s)], models[get(src, normal)]
            base, target, skel = models[i_b], models[i_t], skels[i_t]
            d0 = float(style.cycle_distance(base, target, skel, num_samples=cfg["num_samples"]))
            cand = {"baseline": base, "eq8": style.superpose(base, [style.characteristic(a, b)], [1.0]),
                    "eq8_phasor": style.superpose(base, [style.characteristic(a, b)], [1.0], method="phasor"),
                    "amplitude_ratio": amplitude_ratio(base, a, b)}
            for mth in ("content_mean", "ls_weights", "ridge_map"):
                v = transfer_vectors(mth, vs, vt, sty, s, normal, cfg["ridge"])
                cand[mth] = style.model_from_style_vector(jnp.asarray(v), base)
            # take-to-take floor (source content has two takes): how far the same style is from itself
            other = [i for (c2, s2, t2), i in lab.items() if c2 == src and s2 == s and t2 != take]
            floor = (float(style.cycle_distance(models[get(src, s)], models[other[0]], skels[other[0]],
                                                num_samples=cfg["num_samples"])) /
                     max(float(style.cycle_distance(b, a, skels[get(src, s)], num_samples=cfg["num_samples"])), 1e-9)
                     if other else float("nan"))
            vcand = _vectors([cand[mth] for mth in methods])
            for c in CLASSIFIERS:
                pred = classify(c, V[tr], y[tr], vcand, **kw)
                for mth, p in zip(methods, pred, strict=True):
                    if c == "ncm":
                        d = float(style.cycle_distance(cand[mth], target, skel, num_samples=cfg["num_samples"]))
                        trows.append({"transfer": f"{src}->{dst}", "style": s, "method": mth, "distance": d,
                                      "ratio": d / d0, "take_floor_ratio": floor})
                    next(r for r in trows if r["transfer"] == f"{src}->{dst}" and r["style"] == s
                         and r["method"] == mth)[f"recognised_{c}"] = bool(p == s)
            # limb-flip check: weights along the line base -> transferred
            # Reference: the source models through the same fit -> synthesize -> FK path (a fitted
            # model's cycle already jumps more than its clip's frames: walk_happy 15.5 against 11.4 cm).
            ref = max(_max_jump(models[i], skel, motions[i_t].frame_time_s)
                      for i in (i_b, get(src, s), get(src, normal)))
            ref_clip = max(_clip_max_jump(motions[i]) for i in (i_b, get(src, s)))
            for mth in methods[1:]:
                worst = 0.0
                for w in cfg["weights"]:
                    vb, vm = _vectors([base, cand[mth]])
                    mw = style.model_from_style_vector(jnp.asarray(vb + w * (vm - vb)), base)
                    worst = max(worst, _max_jump(mw, skel, motions[i_t].frame_time_s))
                flips.append({"transfer": f"{src}->{dst}", "style": s, "method": mth, "max_jump": worst,
                              "source_model_max_jump": ref, "source_clip_max_jump": ref_clip,
                              "ok": worst <= ref * 1.01})
        print(f"transfer {src}->{dst}: {len(sty) - 1} styles", flush=True)
    write_table(trows, out, "transfer", "Transfer per style: cycle distance to the real target and recognition")
    write_table(flips, out, "flips", "Largest joint jump per frame at weights in the config vs the source clips'")
    srows = []
    for tname in dict.fromkeys(r["transfer"] for r in trows):
        for mth in methods:
            rs = [r for r in trows if r["transfer"] == tname and r["method"] == mth]
            srows.append({"transfer": tname, "method": mth, "median_ratio": float(np.median([r["ratio"] for r in rs])),
                          "median_distance": float(np.median([r["distance"] for r in rs])),
                          **{f"recognised_{c}": float(np.mean([r[f"recognised_{c}"] for r in rs]))
                             for c in CLASSIFIERS},
                          "flip_free": all(f["ok"] for f in flips if f["transfer"] == tname and f["method"] == mth),
                          "n": len(rs)})
    write_table(srows, out, "transfer_summary", "Transfer methods: median distance ratio and recognition rate")
    summary["transfer"] = srows
    summary["take_floor_ratio_median"] = {t: float(np.nanmedian([r["take_floor_ratio"] for r in trows
                                                                   if r["transfer"] == t and r["method"] == "eq8"]))
                                          for t in dict.fromkeys(r["transfer"] for r in trows)}
    (out / "summary.json").write_text(json.dumps(summary, indent=1, default=str))
    print(json.dumps({k: summary[k] for k in ("walk_loto", "take_floor_ratio_median")}, indent=1))
    for r in srows:
        print(r)


def main(argv=None) -> int:
    return run_main(body, argv)


if __name__ == "__main__":
    raise SystemExit(main())
