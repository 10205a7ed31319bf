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
