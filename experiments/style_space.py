"""Experiment: style recognition and style transfer on a labelled folder of clips (Bandai-1 by default).

Every locomotion clip whose file name matches the config's pattern (named groups ``content``,
``style``, ``take``) is fitted once through the body-map pipeline (``motion.fit_motions``,
cached on disk). Recognition: nearest class mean, shrinkage LDA, logistic regression and k-NN
on feature sets (style vectors, joint-angle and body-space harmonics), leaving one take out,
in PCA spaces, and across contents. Transfer from one content to another (walk -> run ...):
eq. 8 and the method-search variants against the baseline and the oracle rows (`ORACLES`: the
real target scored by the same path), scored by ``style.cycle_distance`` to the real target and
by classifiers trained on real target-content clips only; limb flips as the largest joint jump
per radian of phase (`max_phase_jump`) along the weights, against the clips read; once per
channel representation of the config (Euler, expmap, tangent; on tangent models the per-channel
gain methods get a "skipped" row, `fit_transfer_gains` refusing them; the cadence gain runs). Writes CSV,
Markdown and JSON tables, ``summary.json`` and PNG figures under ``<out>/style_space``.
"""

from __future__ import annotations

import json
import pathlib

import numpy as np

from experiments._style_ceiling import feature_targets, one_per_style, scorer_distances, span_bound
from experiments._style_classify import CLASSIFIERS, classify, pca_fit
from experiments._style_data import find_clips, fit_clips
from experiments._style_features import feature_matrix, features
from experiments._style_transfer import (
    FLIP_TABLE_METHODS,
    METHODS,
    SATURATED,
    SATURATION,
    amplitude_ratio,
    branch_vectors,
    fit_recognition_weight,
    max_jump,
    max_phase_jump,
    vector_layout,
    vector_methods,
)
from experiments._util import ROOT, parse, run_main, write_table

#: Feature sets compared for recognition: name -> groups (``"vector"`` is `style.style_vector`).
FEATURE_SETS = {"style_vector": ("vector",), "angles": ("angles",), "positions": ("positions",),
                "angles+positions": ("angles", "positions"), "all": ("angles", "positions", "timing"),
                "quat": ("quat",), "sixd": ("sixd",), "quat+positions": ("quat", "positions"),
                "sixd+positions": ("sixd", "positions")}
#: The feature set of the transfer's recognition check (the classifier of real target-content clips,
#: one per style): the best one-clip-per-style walk classifier of the ceiling search
#: (`recognition_ceiling`, chosen on real takes only, never on transfers).
MAIN_FEATURES = "quat+positions"
#: The scorer of the previous tables (session 13), reported next to it: nearest mean on these.
PREVIOUS_FEATURES = "angles+positions"
#: Feature sets of the ceiling search.
CEILING_SETS = ("style_vector", "angles", "positions", "angles+positions", "quat", "sixd", "quat+positions",
                "sixd+positions", "all")


#: The transfer methods with per-channel gains, which `style.fit_transfer_gains` refuses for
#: tangent models (their log-omega gain alone, `content_mean_cadence_cv`, is allowed).
GAIN_METHODS = ("content_mean_gains", "content_mean_gains_cv")
#: Rows built from the REAL target clip, scored exactly as the transfers (features of a model
#: through synthesize -> FK, the same scorer): ``oracle``, the target's own fit (a point of the
#: scorer's training set: any recognition below 1 would mean the two sides are featurised
#: differently); ``oracle_take_noise``, the target plus the source content's take-to-take
#: difference of the style (``characteristic(take 2, take 1)`` of the source, where it has two
#: takes): a simulated second capture of the target, which a runs-only scorer cannot otherwise
#: be tested on (Bandai-1 has one run per style); ``oracle_other_take``, the target content's
#: real second take (run -> walk). None of them enters a flip check.
ORACLES = ("oracle", "oracle_take_noise", "oracle_other_take")
GAINS_SKIPPED = ("skipped: style.fit_transfer_gains refuses per-channel gains on tangent models (a gain per "
                 "tangent channel does not commute with a change of joint frames)")


def _skipped_row(rows, representation, transfer, method, note) -> dict:
    """A summary row for a method not run on this representation: the columns of a full row
    (`rows`' keys where there are any), None but the labels and the note."""
    keys = rows[0].keys() if rows else ("representation", "transfer", "method", "note")
    return {**dict.fromkeys(keys), "representation": representation, "transfer": transfer, "method": method,
            "n": 0, "note": note}


def sweep_weights(cfg) -> list[float]:
    """The weights of the transfer weight sweep: the flip-check weights but 0, and 2."""
    return sorted({float(w) for w in cfg["weights"]} - {0.0} | {2.0})


def loto(x, cw, y, content, take, test_content, *, pooled, kw, k=None):
    """Leave one take of ``test_content`` out: predictions ``{classifier: [n]}`` for its clips.

    ``pooled``: the training set also holds every clip of the other contents, each content
    centred on the mean of ITS TRAINING rows (the held-out take is never in a mean, a
    deviation, a PCA or a classifier). ``k``: classify in the PCA space of the training fold.
    """
    idx = np.where(content == test_content)[0]
    preds = {c: np.empty(len(idx), object) for c in CLASSIFIERS}
    for t in sorted(set(take[idx])):
        te = idx[take[idx] == t]
        held = (content == test_content) & (take == t)
        tr = np.where(~held)[0] if pooled else idx[take[idx] != t]
        xc = x.copy()
        for c in set(content[tr]):
            xc[content == c] -= x[tr[content[tr] == c]].mean(0)
        xtr, xte, w = xc[tr], xc[te], cw
        if k is not None:
            mu, sd = xtr.mean(0), np.where(xtr.std(0) > 1e-12, xtr.std(0), 1.0)
            ztr, zte = (xtr - mu) / sd * cw, (xte - mu) / sd * cw
            m, comp = pca_fit(ztr, min(k, len(tr) - 1))
            xtr, xte, w = (ztr - m) @ comp.T, (zte - m) @ comp.T, None
        for c in CLASSIFIERS:
            preds[c][np.isin(idx, te)] = classify(c, xtr, y[tr], xte, column_weights=w, **kw)
    return idx, preds


def _confusion_plot(truth, pred, styles, title, path):
    import matplotlib.pyplot as plt

    from fourierjax import viz

    cm = np.zeros((len(styles), len(styles)), int)
    for t, p in zip(truth, pred, strict=True):
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
    ax.set_title(title, fontsize=9)
    fig.tight_layout()
    viz.save_figure(fig, path)


def recognition(cfg, out, clips, feats, summary):
    """Leave-one-take-out, PCA and across-content recognition tables; returns the best (set, protocol, classifier)."""
    import matplotlib.pyplot as plt

    from fourierjax import viz

    y = np.array([c["style"] for c in clips], object)
    content = np.array([c["content"] for c in clips])
    take = np.array([c["take"] for c in clips])
    styles = sorted(set(y))
    rc = cfg["recognition_content"]
    kw = {"k": cfg["knn"], "shrinkage": cfg["shrinkage"], "l2": cfg["l2"]}
    rows, best = [], (None, -1.0)
    for name, groups in FEATURE_SETS.items():
        x, cw = feature_matrix(feats, groups)
        for pooled in (False, True):
            idx, preds = loto(x, cw, y, content, take, rc, pooled=pooled, kw=kw)
            for c in CLASSIFIERS:
                acc = float(np.mean(preds[c] == y[idx]))
                protocol = "leave one take out" + (", + other contents (centred)" if pooled else "")
                rows.append({"features": name, "protocol": protocol, "classifier": c, "accuracy": acc,
                             "n": len(idx), "chance": 1 / len(styles)})
                if acc > best[1]:
                    best = ((name, pooled, c, y[idx], preds[c]), acc)
    write_table(rows, out, "recognition", f"Style recognition on {rc}, leaving one take out")
    summary["recognition"] = rows
    (name, pooled, c, truth, pred), acc = best
    summary["recognition_best"] = {"features": name, "pooled": pooled, "classifier": c, "accuracy": acc}
    _confusion_plot(truth, pred, styles, f"{rc}, leave one take out{' + other contents' if pooled else ''}: "
                    f"{name}, {c} {acc:.0%} (chance {1 / len(styles):.1%})", out / "confusion_walk.png")
    # PCA spaces of the training fold, on the best feature set and protocol
    x, cw = feature_matrix(feats, FEATURE_SETS[name])
    pca_rows = []
    for k in cfg["pca_k"]:
        idx, preds = loto(x, cw, y, content, take, rc, pooled=pooled, kw=kw, k=k)
        for cl in CLASSIFIERS:
            pca_rows.append({"features": name, "k": k, "classifier": cl,
                             "accuracy": float(np.mean(preds[cl] == y[idx]))})
    write_table(pca_rows, out, "recognition_pca", "The same in the PCA space of the training fold")
    summary["recognition_pca"] = pca_rows
    fig, ax = plt.subplots(figsize=(5, 3.5))
    for cl in CLASSIFIERS:
        ax.plot([r["k"] for r in pca_rows if r["classifier"] == cl],
                [r["accuracy"] for r in pca_rows if r["classifier"] == cl], "o-", label=cl)
        full = next(r["accuracy"] for r in rows if r["classifier"] == cl and r["features"] == name
                    and ("other" in r["protocol"]) == pooled)
        ax.axhline(full, ls=":", lw=1, color=ax.lines[-1].get_color())
    ax.set_xscale("log")
    ax.set_xlabel("PCA dimensions k (dotted: all features)")
    ax.set_ylabel(f"accuracy ({rc}, leave one take out)")
    ax.set_ylim(0, 1.02)
    ax.legend()
    ax.grid(alpha=0.3)
    fig.tight_layout()
    viz.save_figure(fig, out / "pca_accuracy.png")
    # across contents: trained on every other content (all takes), tested on one; no centring
    # (the test content's mean would be a statistic of the test clips)
    crow = []
    for test in cfg["contents"]:
        te, tr = np.where(content == test)[0], np.where(content != test)[0]
        if not len(te) or len(set(y[tr])) < 2:
            continue
        for fname in ("style_vector", MAIN_FEATURES):
            x, cw = feature_matrix(feats, FEATURE_SETS[fname])
            for cl in CLASSIFIERS:
                p = classify(cl, x[tr], y[tr], x[te], column_weights=cw, **kw)
                crow.append({"test_content": test, "features": fname, "classifier": cl,
                             "accuracy": float(np.mean(p == y[te])), "n": len(te)})
    write_table(crow, out, "recognition_contents", "Across contents: trained on the other contents, tested on one")
    summary["across_contents"] = crow
    summary["recognition_ceiling"] = ceiling(cfg, out, clips, feats)
    return best


def ceiling(cfg, out, clips, feats) -> list[dict]:
    """The ceiling of a classifier trained on ONE real clip per style: trained on one take of the
    recognition content, tested on the other (both ways round), per feature set and setting
    (`experiments._style_ceiling.SETTINGS`), without and with each take centred on its own mean."""
    y = np.array([c["style"] for c in clips], object)
    content = np.array([c["content"] for c in clips])
    take = np.array([c["take"] for c in clips])
    kw = {"k": cfg["knn"], "l2": cfg["l2"]}
    rows = []
    for name in CEILING_SETS:
        x, cw = feature_matrix(feats, FEATURE_SETS[name])
        for centre in (False, True):
            for setting, (acc, n) in one_per_style(x, cw, y, content, take, cfg["recognition_content"], kw=kw,
                                                   centre=centre).items():
                rows.append({"features": name, "setting": setting, "centred": centre, "accuracy": acc, "n": n})
    if rows and rows[0]["n"]:
        write_table(rows, out, "recognition_ceiling", f"One real clip per style: trained on one take of "
                    f"{cfg['recognition_content']}, tested on the other")
    return rows


def representation_recognition(cfg, clips, feats, representation) -> list[dict]:
    """Recognition of the walks by channel representation: the fit's own joint angles (Euler or
    expmap channels), and for the first representation the quaternion and 6-D rotation
    harmonics, alone and with the body-space positions (leave one take out, + other contents)."""
    y = np.array([c["style"] for c in clips], object)
    content = np.array([c["content"] for c in clips])
    take = np.array([c["take"] for c in clips])
    kw = {"k": cfg["knn"], "shrinkage": cfg["shrinkage"], "l2": cfg["l2"]}
    sets = {f"angles ({representation})": ("angles",), f"angles ({representation})+positions": ("angles", "positions")}
    if representation == cfg["representations"][0]:
        sets.update({k: FEATURE_SETS[k] for k in ("quat", "sixd", "quat+positions", "sixd+positions")})
    rows = []
    for name, groups in sets.items():
        x, cw = feature_matrix(feats, groups)
        idx, preds = loto(x, cw, y, content, take, cfg["recognition_content"], pooled=True, kw=kw)
        rows += [{"features": name, "classifier": c, "accuracy": float(np.mean(preds[c] == y[idx])), "n": len(idx)}
                 for c in CLASSIFIERS]
    return rows


def transfer(cfg, out, clips, models, skels, maps, motions, summary, representation):
    """Transfer tables (distance ratio, recognition) and the limb-flip check, for one representation."""
    import jax.numpy as jnp

    from fourierjax import style

    normal, ns = cfg["normal"], cfg["num_samples"]
    kw = {"k": cfg["knn"], "shrinkage": cfg["shrinkage"], "l2": cfg["l2"]}
    lab = {(c["content"], c["style"], c["take"]): i for i, c in enumerate(clips)}
    first_take = {}
    for (c, s, t), i in sorted(lab.items()):
        first_take.setdefault((c, s), i)
    styles = sorted({c["style"] for c in clips})
    y = np.array([c["style"] for c in clips], object)
    trows, flips, wrows, gain_omega, ftrows, rec_weights, fwrows = [], [], [], [], [], [], []
    fx_all: dict[int, dict] = {}  # features of the real clips the other-contents scorer reads
    # per-channel gains are refused on tangent models (`style.fit_transfer_gains`): a gain per
    # tangent channel does not commute with a change of joint frames; those methods get a row
    # saying so instead of numbers
    skipped = {m: GAINS_SKIPPED for m in GAIN_METHODS} if representation == "tangent" else {}
    for src, dst in cfg["transfers"]:
        sty = [s for s in styles if (src, s) in first_take and (dst, s) in first_take]
        if normal not in sty or len(sty) < 4:
            continue
        g = {(c, s): first_take[(c, s)] for c in (src, dst) for s in sty}
        ref = models[g[(dst, normal)]]
        vs = dict(zip(sty, branch_vectors([models[g[(src, s)]] for s in sty], ref), strict=True))
        vt = dict(zip(sty, branch_vectors([models[g[(dst, s)]] for s in sty], ref), strict=True))
        # the harmonic (0 offset, 1..N, N + 1 log omega) and joint group of every style-vector entry
        harm, groups = vector_layout(ref, maps[g[(dst, normal)]], skels[0].topology)
        # classifier of the transferred models: real target-content clips only, one take per style
        # (the first; a second take, where there is one, is the oracle and must not be in it)
        real = [g[(dst, s)] for s in sty]
        jump: dict[int, float] = {}  # largest joint jump per frame of each clip's model
        fx_real = [features(models[i], skels[i], maps[i]) for i in real]
        x_real, cw = feature_matrix(fx_real, FEATURE_SETS[MAIN_FEATURES])
        xp_real, cwp = feature_matrix(fx_real, FEATURE_SETS[PREVIOUS_FEATURES])
        x_src, _ = feature_matrix([features(models[g[(src, x)]], skels[g[(src, x)]], maps[g[(src, x)]])
                                   for x in sty], FEATURE_SETS[MAIN_FEATURES])
        # where a style's identity lives in the scorer's space and how much of it the source carries
        summary.setdefault("span_bound", []).append(
            {"representation": representation, "transfer": f"{src}->{dst}",
             **span_bound(x_src, x_real, cw, np.array(sty, object), normal)})
        # a second scorer that reads neither content: every real clip of the OTHER contents (all
        # takes, uncentred, as in the across-contents table), several per style
        oc = [i for i, c in enumerate(clips) if c["content"] not in (src, dst) and c["style"] in sty]
        for i in set(oc) - set(fx_all):
            fx_all[i] = features(models[i], skels[i], maps[i])
        x_oc = feature_matrix([fx_all[i] for i in oc], FEATURE_SETS[MAIN_FEATURES])[0] if oc else None
        if oc:
            rec_real = classify("ncm", x_oc, y[oc], x_real, column_weights=cw)
            summary.setdefault("other_contents_scorer", []).append(
                {"representation": representation, "transfer": f"{src}->{dst}",
                 "contents": sorted({clips[i]["content"] for i in oc}),
                 "real_target_recognised_ncm": float(np.mean(rec_real == y[real])), "n": len(real)})
        for s in sty:
            if s == normal:
                continue
            i_t, i_b = g[(dst, s)], g[(dst, normal)]
            a, b = models[g[(src, s)]], models[g[(src, normal)]]
            base, target, skel = models[i_b], models[i_t], skels[i_t]
            bm = maps[i_t]
            d0 = float(style.cycle_distance(base, target, skel, num_samples=ns, body_map=bm))
            others_src = [models[g[(src, x)]] for x in sty if x != s]
            others_dst = [models[g[(dst, x)]] for x in sty if x != s]
            cand = {"baseline": base,
                    "eq8": style.transfer(a, b, base),
                    "eq8_phasor": style.superpose(base, [style.characteristic(a, b)], [1.0], method="phasor"),
                    "amplitude_ratio": amplitude_ratio(base, a, b),
                    "content_mean": style.transfer(a, others_src, others_dst, method="content_mean")}
            vm = vector_methods(vs, vt, sty, s, normal, ridge=cfg["ridge"], weight=cfg["transfer_weight"],
                                column_groups=groups, harmonic_kinds=harm)
            for mth in ("content_mean_only", "content_mean_w", "eq8_ls_weight", "ls_weights", "harmonic_weights",
                        "group_weights", "ridge_map"):
                cand[mth] = style.model_from_style_vector(jnp.asarray(vm[mth]), base)
            # the weight of the content-mean transfer, chosen on the other styles (leaving s out of all)
            rest = [x for x in sty if x != s]
            w_cv = style.fit_transfer_weight(others_src, others_dst, skel, grid=cfg["weight_grid"], baseline=base,
                                             held_out=[k for k, x in enumerate(rest) if x != normal],
                                             body_map=bm, num_samples=ns).weight
            cand["content_mean_cv"] = style.transfer(a, others_src, others_dst, method="content_mean", weight=w_cv)
            gains = None
            if not skipped:
                # per-channel gains (and log omega's) fitted across the other styles: how much of a
                # style's offset from the source content's mean reappears in the target content
                gains = style.fit_transfer_gains(others_src, others_dst)
                cand["content_mean_gains"] = style.transfer(a, others_src, others_dst, method="content_mean",
                                                            gains=gains)
                cand["content_mean_gains_cv"] = style.transfer(a, others_src, others_dst, method="content_mean",
                                                               gains=gains, weight=w_cv)
            # the cadence gain alone (every channel's at 1; rig-invariant, so tangent takes it too):
            # what made the limbs fast above w = 1
            cadence = style.fit_transfer_gains(others_src, others_dst, cadence_only=True)
            gain_omega.append(float(cadence[-1]))
            cand["content_mean_cadence_cv"] = style.transfer(a, others_src, others_dst, method="content_mean",
                                                             gains=cadence, weight=w_cv)
            # the same with its extrapolation saturated: the same model at w_cv <= 1; the flip line
            # beyond 1 saturates the swings and the cadence (below)
            cand["content_mean_cadence_cv_sat"] = style.transfer(a, others_src, others_dst, method="content_mean",
                                                                 gains=cadence, weight=w_cv,
                                                                 saturation=SATURATION)
            # the weight the scorer recognises best on the other styles (their real target clips
            # only, s left out of the scorer too), with the cadence gain; grid: the sweep's weights
            keep = [k for k, x in enumerate(sty) if x != s]
            w_rec = fit_recognition_weight(
                {x: models[g[(src, x)]] for x in rest}, {x: models[g[(dst, x)]] for x in rest}, x_real[keep],
                lambda m: feature_matrix([features(m, skel, bm)], FEATURE_SETS[MAIN_FEATURES])[0][0],
                sweep_weights(cfg), column_weights=cw)[0]
            rec_weights.append(w_rec)
            cand["content_mean_rec_cv"] = style.transfer(a, others_src, others_dst, method="content_mean",
                                                         gains=cadence, weight=w_rec)
            # the weight sweep: recognition rises with w, the distance is best near 0.5
            sweep = {}
            for w in sweep_weights(cfg):
                sweep[("content_mean", w)] = style.transfer(a, others_src, others_dst, method="content_mean",
                                                            weight=w)
                if gains is not None:
                    sweep[("content_mean_gains", w)] = style.transfer(a, others_src, others_dst,
                                                                      method="content_mean", gains=gains, weight=w)
            # oracles (`ORACLES`): the real target itself; with the source content's take-to-take
            # difference of the style; another take of the real target, where there is one
            cand["oracle"] = target
            src_takes = sorted(i for (c2, s2, _), i in lab.items() if c2 == src and s2 == s)
            if len(src_takes) > 1:
                noise = style.characteristic(models[src_takes[1]], models[src_takes[0]])
                cand["oracle_take_noise"] = style.superpose(target, [noise], [1.0], method="phasor")
            other = [i for (c2, s2, t2), i in lab.items() if c2 == dst and s2 == s and i != i_t]
            if other:
                cand["oracle_other_take"] = models[other[0]]
            names = list(cand)
            fx = [features(cand[m], skel, maps[i_t]) for m in names]
            x_c, _ = feature_matrix(fx, FEATURE_SETS[MAIN_FEATURES])
            rec = {c: classify(c, x_real, y[real], x_c, column_weights=cw, **kw) for c in CLASSIFIERS}
            rec_oc = {c: (classify(c, x_oc, y[oc], x_c, column_weights=cw, **kw) if oc else np.full(len(x_c), None))
                      for c in CLASSIFIERS}
            rec_prev = classify("ncm", xp_real, y[real], feature_matrix(fx, FEATURE_SETS[PREVIOUS_FEATURES])[0],
                                column_weights=cwp)
            # ideal points of transfers made in the scorer's own (z-scored) feature space, maps fitted
            # on the other styles: the recognition any inversion of them back to a model could reach
            k_s = sty.index(s)
            d_tgt, d_oth = scorer_distances(x_real, cw, k_s, x_c)
            rest_k = [k for k in range(len(sty)) if k != k_s]
            pts = feature_targets(x_src[rest_k], x_real[rest_k], x_src[k_s] - x_src[rest_k].mean(0),
                                  sd=x_real[rest_k].std(0) + 1e-12, column_weights=cw)
            rec_pts = {c: classify(c, x_real, y[real], np.stack(list(pts.values())), column_weights=cw, **kw)
                       for c in CLASSIFIERS}
            for k, mth in enumerate(pts):
                ftrows.append({"representation": representation, "transfer": f"{src}->{dst}", "style": s,
                               "map": mth, **{f"recognised_{c}": bool(rec_pts[c][k] == s) for c in CLASSIFIERS}})
            fts = motions[i_t].frame_time_s
            ref_sweep = max(max_phase_jump(models[g[(c, x)]], skel, body_map=bm)
                            for c in (src, dst) for x in sty if (c, x) != (dst, s))
            ref_sweep_frame = max(max_jump(models[g[(c, x)]], skel, fts, body_map=bm)
                                  for c in (src, dst) for x in sty if (c, x) != (dst, s))
            x_s, _ = feature_matrix([features(m, skel, maps[i_t]) for m in sweep.values()],
                                    FEATURE_SETS[MAIN_FEATURES])
            rec_s = {c: classify(c, x_real, y[real], x_s, column_weights=cw, **kw) for c in CLASSIFIERS}
            rec_s_oc = classify("ncm", x_oc, y[oc], x_s, column_weights=cw) if oc else np.full(len(x_s), None)
            for k, ((mth, w), m) in enumerate(sweep.items()):
                wrows.append({"representation": representation, "transfer": f"{src}->{dst}", "style": s,
                              "method": mth, "weight": w,
                              "ratio": float(style.cycle_distance(m, target, skel, num_samples=ns, body_map=bm)) / d0,
                              "jump_ratio": max_phase_jump(m, skel, body_map=bm) / ref_sweep,
                              "frame_jump_ratio": max_jump(m, skel, fts, body_map=bm) / ref_sweep_frame,
                              **{f"recognised_{c}": bool(rec_s[c][k] == s) for c in CLASSIFIERS},
                              "recognised_oc_ncm": bool(rec_s_oc[k] == s)})
            for k, mth in enumerate(names):
                d = float(style.cycle_distance(cand[mth], target, skel, num_samples=ns, body_map=bm))
                trows.append({"representation": representation, "transfer": f"{src}->{dst}", "style": s,
                              "method": mth, "distance": d, "ratio": d / d0,
                              "weight": {"content_mean_rec_cv": w_rec}.get(
                                  mth, w_cv if mth.endswith(("_cv", "_cv_sat")) else None),
                              **{f"recognised_{c}": bool(rec[c][k] == s) for c in CLASSIFIERS},
                              "recognised_previous_ncm": bool(rec_prev[k] == s),
                              "scorer_to_target": float(d_tgt[k]), "scorer_to_other": float(d_oth[k]),
                              **{f"recognised_oc_{c}": bool(rec_oc[c][k] == s) for c in CLASSIFIERS}})
            # limb flips: weights along the phasor line from the base to each transferred model
            # Reference: the largest jump of the clips a method reads, through the same fit ->
            # synthesize -> FK path: eq. 8 and its variants read three (the two neutral clips and
            # the styled source), the style-space methods every clip of both contents but the
            # target's.
            # The criterion is per radian of phase (`max_phase_jump`): a flip changes the poses of
            # the cycle, a faster cadence only how many frames a radian takes; the per-frame jump
            # (the previous criterion) is kept as `frame_*` columns.
            for i in {i_b, *g.values()} - set(jump):
                jump[i] = (max_phase_jump(models[i], skel, body_map=bm), max_jump(models[i], skel, fts, body_map=bm))
            ref_eq8 = [max(jump[i][k] for i in (i_b, g[(src, s)], g[(src, normal)])) for k in (0, 1)]
            ref_all = [max(jump[g[(c, x)]][k] for c in (src, dst) for x in sty if (c, x) != (dst, s)) for k in (0, 1)]
            # the joint-speed limit of `style.superpose` (`style.joint_speed_limit`), from the same
            # clips as each reference: a method with it never outruns the clips it reads
            limits = {}
            if cfg.get("speed_limit", True):
                limits = {"eq8": style.joint_speed_limit([models[i] for i in (i_b, g[(src, s)], g[(src, normal)])],
                                                         skel, body_map=bm),
                          "all": style.joint_speed_limit([models[g[(c, x)]] for c in (src, dst) for x in sty
                                                          if (c, x) != (dst, s)], skel, body_map=bm)}
            for mth in names:
                if mth == "baseline" or mth in ORACLES:
                    continue
                ref_jump = ref_eq8 if mth in ("eq8", "eq8_phasor", "amplitude_ratio") else ref_all
                char = style.characteristic(cand[mth], base)
                sat = SATURATION if mth in SATURATED else None
                line = {w: style.superpose(base, [char], [w], method="phasor", saturation=sat) for w in cfg["weights"]}
                jumps = {w: max_phase_jump(m, skel, body_map=bm) for w, m in line.items()}
                fjumps = {w: max_jump(m, skel, fts, body_map=bm) for w, m in line.items()}
                if mth in FLIP_TABLE_METHODS:  # per weight: per radian, per frame and their ratio, the cadence's
                    fwrows += [{"transfer": f"{src}->{dst}", "style": s, "method": mth, "weight": w,
                                "phase_ratio": jumps[w] / ref_jump[0], "frame_ratio": fjumps[w] / ref_jump[1]}
                               for w in line]
                worst, fworst = max(jumps.values()), max(fjumps.values())
                upto1 = max((v for w, v in jumps.items() if w <= 1.0), default=float("nan"))
                fupto1 = max((v for w, v in fjumps.items() if w <= 1.0), default=float("nan"))
                limited = {}
                if limits:  # the same line with the speed limit; its w = 1 is the limited transfer
                    lim = limits["eq8" if ref_jump is ref_eq8 else "all"]
                    held = {w: style.superpose(base, [char], [w], method="phasor", saturation=sat, speed_limit=lim)
                            for w in {*cfg["weights"], 1.0}}
                    d1 = float(style.cycle_distance(held[1.0], target, skel, num_samples=ns, body_map=bm))
                    limited = {"limited_ratio": max(max_phase_jump(m, skel, body_map=bm) for m in held.values())
                               / ref_jump[0],
                               "limited_frame_ratio": max(max_jump(m, skel, fts, body_map=bm) for m in held.values())
                               / ref_jump[1],
                               "limited_distance_ratio": d1 / d0}
                flips.append({"representation": representation, "transfer": f"{src}->{dst}", "style": s,
                              "method": mth, "max_jump": worst, "max_jump_w_le_1": upto1,
                              "source_max_jump": ref_jump[0], "ratio": worst / ref_jump[0],
                              "ratio_w_le_1": upto1 / ref_jump[0], "ok": worst <= ref_jump[0] * 1.01,
                              "frame_ratio": fworst / ref_jump[1], "frame_ratio_w_le_1": fupto1 / ref_jump[1],
                              "frame_ok": fworst <= ref_jump[1] * 1.01, **limited})
        print(f"{representation} transfer {src}->{dst}: {len(sty) - 1} styles", flush=True)
    srows = []
    for tname in dict.fromkeys(r["transfer"] for r in trows):
        for mth in [METHODS[0], *ORACLES, *METHODS[1:]]:
            rs = [r for r in trows if r["transfer"] == tname and r["method"] == mth]
            if mth in skipped:
                srows.append(_skipped_row(srows, representation, tname, mth, skipped[mth]))
            if not rs:
                continue
            fl = [f for f in flips if f["transfer"] == tname and f["method"] == mth]
            srows.append({"representation": representation, "transfer": tname, "method": mth,
                          "median_ratio": float(np.median([r["ratio"] for r in rs])),
                          "median_distance": float(np.median([r["distance"] for r in rs])),
                          **{f"recognised_{c}": float(np.mean([r[f"recognised_{c}"] for r in rs]))
                             for c in CLASSIFIERS},
                          "recognised_previous_ncm": float(np.mean([r["recognised_previous_ncm"] for r in rs])),
                          "scorer_to_target": float(np.median([r["scorer_to_target"] for r in rs])),
                          "scorer_to_other": float(np.median([r["scorer_to_other"] for r in rs])),
                          **{f"recognised_oc_{c}": float(np.mean([r[f"recognised_oc_{c}"] for r in rs]))
                             for c in CLASSIFIERS},
                          "flip_free": all(f["ok"] for f in fl) if fl else None,
                          "max_jump_ratio": max((f["ratio"] for f in fl), default=None),
                          "max_jump_ratio_w_le_1": max((f["ratio_w_le_1"] for f in fl), default=None),
                          "frame_flip_free": all(f["frame_ok"] for f in fl) if fl else None,
                          "max_frame_jump_ratio": max((f["frame_ratio"] for f in fl), default=None),
                          # with `superpose(speed_limit=)` from the clips the method reads (strict: <= 1)
                          "limited_max_jump_ratio": max((f["limited_ratio"] for f in fl if "limited_ratio" in f),
                                                        default=None),
                          "limited_max_frame_jump_ratio": max((f["limited_frame_ratio"] for f in fl
                                                               if "limited_ratio" in f), default=None),
                          "limited_median_ratio": float(np.median([f["limited_distance_ratio"] for f in fl
                                                                   if "limited_ratio" in f]))
                          if any("limited_ratio" in f for f in fl) else None,
                          "n": len(rs), "note": ""})
    wsum = []
    for tname in dict.fromkeys(r["transfer"] for r in wrows):
        for mth in ("content_mean", "content_mean_gains"):
            for w in sweep_weights(cfg):
                rs = [r for r in wrows if r["transfer"] == tname and r["method"] == mth and r["weight"] == w]
                if mth in skipped:
                    wsum.append({**_skipped_row(wsum, representation, tname, mth, skipped[mth]), "weight": w})
                    continue
                wsum.append({"representation": representation, "transfer": tname, "method": mth, "weight": w,
                             "median_ratio": float(np.median([r["ratio"] for r in rs])),
                             **{f"recognised_{c}": float(np.mean([r[f"recognised_{c}"] for r in rs]))
                                for c in CLASSIFIERS},
                             "recognised_oc_ncm": float(np.mean([r["recognised_oc_ncm"] for r in rs])),
                             "max_jump_ratio": float(max(r["jump_ratio"] for r in rs)),
                             "max_frame_jump_ratio": float(max(r["frame_jump_ratio"] for r in rs)), "n": len(rs),
                             "note": ""})
    for tname in dict.fromkeys(r["transfer"] for r in ftrows):
        for mth in dict.fromkeys(r["map"] for r in ftrows):
            rs = [r for r in ftrows if r["transfer"] == tname and r["map"] == mth]
            summary.setdefault("feature_targets", []).append(
                {"representation": representation, "transfer": tname, "map": mth,
                 **{f"recognised_{c}": float(np.mean([r[f"recognised_{c}"] for r in rs])) for c in CLASSIFIERS},
                 "n": len(rs)})
    for tname in dict.fromkeys(r["transfer"] for r in fwrows):
        for mth in FLIP_TABLE_METHODS:
            for w in cfg["weights"]:
                rs = [r for r in fwrows if r["transfer"] == tname and r["method"] == mth and r["weight"] == w]
                if not rs:
                    continue
                ph, fr = max(rs, key=lambda r: r["phase_ratio"]), max(rs, key=lambda r: r["frame_ratio"])
                # per frame = per radian x the cadence ratio (the model's omega over the omega
                # at which the clips' largest per-radian jump would give their largest per-frame one)
                summary.setdefault("flips_by_weight", []).append(
                    {"representation": representation, "transfer": tname, "method": mth, "weight": w,
                     "phase_ratio": ph["phase_ratio"], "phase_style": ph["style"],
                     "frame_ratio": fr["frame_ratio"], "frame_style": fr["style"],
                     "frame_style_phase_ratio": fr["phase_ratio"],
                     "frame_style_cadence_ratio": fr["frame_ratio"] / fr["phase_ratio"],
                     "phase_ok": ph["phase_ratio"] <= 1.01, "frame_ok": fr["frame_ratio"] <= 1.01, "n": len(rs)})
    if rec_weights:
        summary.setdefault("recognition_weight", {})[representation] = {
            "median": float(np.median(rec_weights)), "values": [float(w) for w in rec_weights]}
    if gain_omega:
        summary.setdefault("gain_log_omega", {})[representation] = {
            "median": float(np.median(gain_omega)), "min": float(np.min(gain_omega)),
            "max": float(np.max(gain_omega))}
    return trows, flips, srows, wsum


def body(argv=None) -> None:
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
    summary: dict = {"folder": str(folder), "clips": len(clips), "harmonics": cfg["harmonics"],
                     "representations": cfg["representations"]}
    all_t, all_f, all_s, all_w, rep_rows = [], [], [], [], []
    for r, rep in enumerate(cfg["representations"]):
        models, skels, maps, motions, failed = fit_clips(clips, cfg["harmonics"], rep, cache)
        keep = [i for i, c in enumerate(clips) if c["path"].name not in failed]
        cl = [clips[i] for i in keep]
        ms, sk, bm, mo = ([v[i] for i in keep] for v in (models, skels, maps, motions))
        if r == 0:
            from fourierjax import style

            feats = [features(m, s, b) for m, s, b in zip(ms, sk, bm, strict=True)]
            vec = np.asarray(style.style_matrix(ms), float)
            for f, v in zip(feats, vec, strict=True):
                f["vector"] = v
            summary.update(failed=failed, styles=sorted({c["style"] for c in cl}), representation=rep)
            recognition(cfg, out, cl, feats, summary)
        else:
            feats = [features(m, s, b) for m, s, b in zip(ms, sk, bm, strict=True)]
        rep_rows += representation_recognition(cfg, cl, feats, rep)
        t, f, s, w = transfer(cfg, out, cl, ms, sk, bm, mo, summary, rep)
        all_w += w
        all_t += t
        all_f += f
        all_s += s
    write_table(all_t, out, "transfer", "Transfer per style: cycle distance to the real target and recognition")
    write_table(all_f, out, "flips", "Largest joint jump per radian of phase (frame_*: per frame) at the configured "
                "weights vs the sources'")
    write_table(all_s, out, "transfer_summary", "Transfer methods: median distance ratio and recognition rate")
    summary["transfer"] = all_s
    write_table(all_w, out, "transfer_weights", "Transfer by weight: median distance ratio, recognition by the "
                "classifier of real target-content clips, largest joint jump per frame over the clips'")
    summary["transfer_weights"] = all_w
    write_table(summary.get("flips_by_weight", []), out, "flips_by_weight",
                "Limb flips by weight, worst style: per radian of phase and per frame over the clips' largest; "
                "frame_style_cadence_ratio = frame_ratio / phase_ratio of the worst per-frame style")
    write_table(summary.get("other_contents_scorer", []), out, "other_contents_scorer",
                "The other-contents scorer on the real target clips (nearest mean)")
    write_table(summary.get("span_bound", []), out, "transfer_span_bound",
                "A style's deviation from the other styles' mean in the scorer's space: recognition of its part "
                "in the other styles' span and outside it; cosines between source and target deviations")
    write_table(summary.get("feature_targets", []), out, "transfer_feature_targets",
                "Ideal points of transfers in the scorer's feature space: share recognised as the intended style")
    write_table(rep_rows, out, "recognition_representations",
                "Walk recognition by rotation channels (leave one take out, + other contents, centred)")
    summary["recognition_representations"] = rep_rows
    _transfer_plot(all_s, cfg["representations"][0], out / "transfer_ratios.png")
    # take-to-take floor: two takes of one style against the neutral-to-style distance (walks)
    summary["take_to_take"] = take_floor(cfg, clips, fit_clips(clips, cfg["harmonics"], cfg["representations"][0],
                                                                 cache))
    (out / "summary.json").write_text(json.dumps(summary, indent=1, default=str))
    print(json.dumps(summary["recognition_best"]))
    print(json.dumps(summary["take_to_take"]))
    for row in all_s:
        print({k: (round(v, 3) if isinstance(v, float) else v) for k, v in row.items()})


def _transfer_plot(srows, representation, path):
    """Median distance ratio of every method per transfer (bars), the 0.8 target and the oracle."""
    import matplotlib.pyplot as plt

    from fourierjax import viz

    rows = [r for r in srows if r["representation"] == representation]
    transfers = list(dict.fromkeys(r["transfer"] for r in rows))
    methods = [m for m in METHODS if m != "baseline"]
    fig, ax = plt.subplots(figsize=(10, 4))
    width = 0.8 / len(transfers)
    for k, t in enumerate(transfers):
        by = {r["method"]: r for r in rows if r["transfer"] == t}
        xs = np.arange(len(methods)) + (k - (len(transfers) - 1) / 2) * width
        ax.bar(xs, [by[m]["median_ratio"] if m in by else np.nan for m in methods], width, label=t)
        if "oracle_other_take" in by:
            ax.axhline(by["oracle_other_take"]["median_ratio"], color="k", ls="--", lw=1,
                       label=f"{t}: another real take (oracle)")
    ax.axhline(1.0, color="k", lw=1)
    ax.axhline(0.8, color="r", ls=":", lw=1, label="target 0.8")
    ax.set_xticks(range(len(methods)), methods, rotation=35, ha="right", fontsize=8)
    ax.set_ylabel("median distance ratio to the baseline's")
    ax.set_ylim(0, 1.8)
    ax.set_title(f"Style transfer on Bandai-1 ({representation}): lower is closer to the real styled clip", fontsize=9)
    ax.legend(fontsize=7, ncol=2)
    ax.grid(alpha=0.3, axis="y")
    fig.tight_layout()
    viz.save_figure(fig, path)


def take_floor(cfg, clips, fitted) -> dict:
    """Median over styles of d(take 1, take 2) / d(neutral, take 1), per content with two takes."""
    from fourierjax import style

    models, skels, maps = fitted[0], fitted[1], fitted[2]
    lab = {(c["content"], c["style"], c["take"]): i for i, c in enumerate(clips)}
    out = {}
    for content in cfg["contents"]:
        takes = sorted({t for (c, _, t) in lab if c == content})
        if len(takes) < 2:
            continue
        t1, t2 = takes[:2]
        r = []
        for (c, s, t), i in lab.items():
            j, n = lab.get((c, s, t2)), lab.get((c, cfg["normal"], t1))
            if c != content or t != t1 or s == cfg["normal"] or j is None or n is None:
                continue
            kw = {"num_samples": cfg["num_samples"], "body_map": maps[i]}
            d12 = float(style.cycle_distance(models[j], models[i], skels[i], **kw))
            d0 = float(style.cycle_distance(models[n], models[i], skels[i], **kw))
            r.append(d12 / d0)
        if r:
            out[content] = {"median": float(np.median(r)), "min": float(np.min(r)), "max": float(np.max(r)),
                            "n": len(r)}
    return out


def main(argv=None) -> int:
    return run_main(body, argv)


if __name__ == "__main__":
    raise SystemExit(main())
