"""The recognition ceiling of a one-clip-per-style classifier: trained on one real take, tested on another."""

from __future__ import annotations

import numpy as np

from experiments._style_classify import classify, within_style_residuals

#: Classifier settings of the ceiling search: name -> (classifier, shrinkage, metric). ``metric``:
#: None (z-scored features only) or "other" (LDA whose within-style scatter comes from the real
#: clips of the contents other than the classifier's own and the transfer's source).
SETTINGS = {"ncm": ("ncm", 0.5, None), "logreg": ("logreg", 0.5, None), "knn": ("knn", 0.5, None),
            **{f"lda_other_s{s}": ("lda", s, "other") for s in (0.1, 0.3, 0.5, 0.7, 0.9)}}


def one_per_style(x, cw, y, content, take, test_content, *, excluded=(), kw, settings=SETTINGS, centre=False):
    """Accuracy of classifiers trained on ONE take of ``test_content`` (one clip per style) and
    tested on each other take of it (both ways round).

    The "other" metric's scatter comes from the contents other than ``test_content`` and
    ``excluded``; nothing of the test take is in any statistic. ``centre``: each take is
    centred on its own mean (transductive: the test take's mean is a statistic of its 15
    clips), the subject/session normalisation.

    Returns ``{setting: (accuracy, n)}``.
    """
    idx = np.where(content == test_content)[0]
    takes = sorted(set(take[idx].tolist()))
    others = sorted(set(content.tolist()) - {test_content, *excluded})
    scatter = within_style_residuals(x, y, content, others) if others else None
    out = {}
    for name, (clf, s, metric) in settings.items():
        hit = n = 0
        for tr_take in takes:
            tr = idx[take[idx] == tr_take]
            for te_take in takes:
                if te_take == tr_take:
                    continue
                te = idx[take[idx] == te_take]
                xtr, xte = x[tr], x[te]
                if centre:
                    xtr, xte = xtr - xtr.mean(0), xte - xte.mean(0)
                p = classify(clf, xtr, y[tr], xte, column_weights=cw, **{**kw, "shrinkage": s},
                             scatter=scatter if metric == "other" else None)
                hit += int(np.sum(p == y[te]))
                n += len(te)
        out[name] = (hit / max(n, 1), n)
    return out


def run_classifier(x, cw, y, content, target_content, *, excluded=(), kw, setting):
    """The classifier of one content trained on its real clips only (one per style), with the
    metric of `SETTINGS[setting]`: a function ``predict(x_new) -> labels``."""
    clf, s, metric = SETTINGS[setting]
    tr = np.where(content == target_content)[0]
    others = sorted(set(content.tolist()) - {target_content, *excluded})
    scatter = within_style_residuals(x, y, content, others) if metric == "other" and others else None

    def predict(x_new):
        return classify(clf, x[tr], y[tr], np.atleast_2d(x_new), column_weights=cw, **{**kw, "shrinkage": s},
                        scatter=scatter)

    return predict


def feature_targets(xs, xt, u, *, sd, column_weights, ridge=(1.0, 10.0)) -> dict[str, np.ndarray]:
    """Ideal target points of a transfer made in the classifier's feature space.

    ``xs``, ``xt``: feature rows of the OTHER styles in the source and the target content
    (paired); ``u``: the held-out style's source row minus the mean of ``xs``; ``sd``: the
    target content's feature deviations (the classifier's z-scoring, here over the other
    styles); ``column_weights``: the classifier's. The maps, all fitted on the other styles:
    ``identity`` (the offset as it is), ``spread`` (each feature scaled by the ratio of the
    contents' spreads over styles), ``slope`` (each feature's least-squares slope) and
    ``ridge<l>`` (ridge regression in the whitened space, dual form) and ``ridge<l>_norm``
    (the same scaled to the median norm of the other styles' offsets). A model whose
    features equal such a point is the best any inversion of that map can do, so its
    recognition bounds every transfer through it.
    """
    ms, mt = xs.mean(0), xt.mean(0)
    dx, dy = xs - ms, xt - mt
    sds = np.where(xs.std(0) > 1e-12, xs.std(0), 1.0)
    sdt = np.where(xt.std(0) > 1e-12, xt.std(0), 1.0)
    out = {"identity": mt + u, "spread": mt + u * sdt / sds,
           "slope": mt + u * (dx * dy).sum(0) / np.maximum((dx * dx).sum(0), 1e-12)}
    zx, zu = dx / sds * column_weights, u / sds * column_weights
    for lam in ridge:
        p = np.linalg.solve(zx @ zx.T + lam * np.eye(len(zx)), zx @ zu) @ dy
        norm = np.median(np.linalg.norm(dy / sd * column_weights, axis=1))
        out[f"ridge{lam:g}"] = mt + p
        out[f"ridge{lam:g}_norm"] = mt + p * norm / max(float(np.linalg.norm(p / sd * column_weights)), 1e-12)
    return out


def _scorer_space(x, cw):
    """Rows of ``x`` in the scorer's metric space (z-scored on ``x``, group-weighted) and the map of new rows."""
    mu, sd = x.mean(0), x.std(0)
    sd = np.where(sd > 1e-9 * max(sd.max(), 1e-300), sd, 1.0)
    return (x - mu) / sd * cw, lambda r: (np.asarray(r, float) - mu) / sd * cw


def _deviations(z, k):
    """Row ``k``'s deviation from the mean of the other rows and its part in their span."""
    o = [j for j in range(len(z)) if j != k]
    m = z[o].mean(0)
    d, dev = z[k] - m, z[o] - m
    return m, d, dev.T @ np.linalg.lstsq(dev.T, d, rcond=None)[0]


def span_bound(x_src, x_dst, cw, y, normal) -> dict:
    """Where a style's identity lives in the scorer's space (``x_dst``: the real target-content
    clips, one per style, labels ``y``), and how much of it the source content carries.

    For every style ``k`` but ``normal``: its deviation ``d`` from the mean of the other styles'
    clips, split into the part in the span of the other styles' deviations and the rest.
    Returns the share recognised as ``k`` by the scorer (nearest class mean on ``x_dst``) of the
    mean plus the in-span part, plus twice it, plus the out-of-span part alone; the median share
    of ``|d|^2`` in the span; and the median cosine between each style's deviation in the source
    content (``x_src``, the same styles in the same order, in its own scorer space) and in the
    target content, whole and out-of-span (``_other``: between different styles).
    """
    zs, _ = _scorer_space(x_src, cw)
    zt, _ = _scorer_space(x_dst, cw)
    mu, sd = x_dst.mean(0), x_dst.std(0)
    sd = np.where(sd > 1e-9 * max(sd.max(), 1e-300), sd, 1.0)
    hits = {"in_span": [], "in_span_x2": [], "out_of_span": []}
    energy, rs, rt, cos_all = [], {}, {}, []
    ks = [k for k in range(len(y)) if y[k] != normal]
    for k in ks:
        m, d, p = _deviations(zt, k)
        energy.append(float(p @ p / max(d @ d, 1e-300)))
        pts = np.stack([m + p, m + 2 * p, m + d - p]) / cw * sd + mu
        pred = classify("ncm", x_dst, y, pts, column_weights=cw)
        for name, hit in zip(hits, pred == y[k], strict=True):
            hits[name].append(bool(hit))
        _, ds, ps = _deviations(zs, k)
        rs[k], rt[k] = ds - ps, d - p
        cos_all.append(float(ds @ d / max(np.linalg.norm(ds) * np.linalg.norm(d), 1e-300)))

    def cos(a, b):
        return float(a @ b / max(np.linalg.norm(a) * np.linalg.norm(b), 1e-300))

    return {**{f"recognised_{k}": float(np.mean(v)) for k, v in hits.items()},
            "span_energy_share": float(np.median(energy)), "cosine_deviation": float(np.median(cos_all)),
            "cosine_out_of_span": float(np.median([cos(rs[k], rt[k]) for k in ks])),
            "cosine_out_of_span_other": float(np.median([cos(rs[a], rt[b]) for a in ks for b in ks if a != b])),
            "n": len(ks)}


def scorer_distances(x_real, cw, k, rows) -> tuple[np.ndarray, np.ndarray]:
    """Distances, in the scorer's space of the real clips ``x_real``, of ``rows`` to real clip
    ``k`` (the target) and to the nearest other real clip."""
    z, to = _scorer_space(x_real, cw)
    d = np.linalg.norm(to(rows)[:, None] - z[None], axis=-1)
    return d[:, k], np.delete(d, k, axis=1).min(1)
