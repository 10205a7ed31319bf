"""Classifiers of the style-space experiment in NumPy: nearest class mean, shrinkage LDA, logistic regression, k-NN."""

from __future__ import annotations

import numpy as np

CLASSIFIERS = ("ncm", "lda", "logreg", "knn")


def zscore(train, *rest):
    """``train`` and ``rest`` standardised by the mean and deviation of ``train`` only."""
    mu, sd = train.mean(0), train.std(0)
    sd = np.where(sd > 1e-9 * max(sd.max(), 1e-300), sd, 1.0)
    return [(x - mu) / sd for x in (train, *rest)]


def _logreg(xtr, ytr_idx, num_classes, xte, l2, iters=300):
    """Multinomial logistic regression with an L2 penalty, full-batch Nesterov gradient descent."""
    m, d = xtr.shape
    y = np.eye(num_classes)[ytr_idx]
    w = np.zeros((d, num_classes))
    b = np.zeros(num_classes)
    # Step from the Lipschitz bound of the softmax loss: |X|^2 / (2 m) + l2.
    lr = 1.0 / (0.5 * np.linalg.norm(xtr, 2) ** 2 / m + l2)
    vw, vb = w.copy(), b.copy()
    for t in range(iters):
        z = xtr @ vw + vb
        z -= z.max(1, keepdims=True)
        p = np.exp(z)
        p /= p.sum(1, keepdims=True)
        gw = xtr.T @ (p - y) / m + l2 * vw
        gb = (p - y).mean(0)
        w_new, b_new = vw - lr * gw, vb - lr * gb
        mom = t / (t + 3)
        vw, vb = w_new + mom * (w_new - w), b_new + mom * (b_new - b)
        w, b = w_new, b_new
    return (xte @ w + b).argmax(1)


def classify(method: str, xtr, ytr, xte, *, k: int = 1, shrinkage: float = 0.5, l2: float = 1e-2,
             column_weights=None, scatter=None):
    """Predicted labels of ``xte`` (rows) by a classifier trained on ``(xtr, ytr)`` (z-scored on xtr).

    Arguments:
        method: ``"ncm"`` (nearest class mean); ``"lda"`` (linear discriminant with the pooled
            within-class covariance shrunk towards a multiple of the identity,
            ``(1 - s) S + s tr(S)/D I``, applied in the dual (Woodbury) form); ``"logreg"``
            (multinomial logistic regression, L2 penalty ``l2``); ``"knn"`` (majority of the
            ``k`` nearest training rows, ties to the nearest).
        xtr, ytr: training rows ``[M, D]`` and labels ``[M]``; xte: ``[n, D]``.
        k, shrinkage, l2: the classifiers' settings.
        column_weights: ``[D]`` multipliers applied after the z-scoring (feature-group weights).
        scatter: ``"lda"`` only: extra within-class residual rows ``[R, D]`` (deviations of real
            clips from their class mean, e.g. from other contents, `within_style_residuals`),
            pooled with the training rows' own residuals into the covariance. With one training
            row per class the plain LDA has no scatter and is the nearest mean; these rows give
            it one without adding class examples.

    Returns:
        ``[n]`` predicted labels.
    """
    ytr = np.asarray(ytr)
    xtr = np.asarray(xtr, float)
    if scatter is not None:  # residuals are differences: scaled by the training deviation, not shifted
        sd = xtr.std(0)
        scatter = np.asarray(scatter, float) / np.where(sd > 1e-9 * max(sd.max(), 1e-300), sd, 1.0)
    xtr, xte = zscore(xtr, np.asarray(xte, float))
    if column_weights is not None:
        xtr, xte = xtr * column_weights, xte * column_weights
        scatter = None if scatter is None else scatter * column_weights
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
    if method == "logreg":
        idx = np.array([classes.index(c) for c in ytr])
        return np.array(classes)[_logreg(xtr, idx, len(classes), xte, l2)]
    if method == "lda":
        r = xtr - means[[classes.index(c) for c in ytr]]  # within-class residuals [M, D]
        if scatter is not None:
            r = np.concatenate([r, scatter])
        m, dim = r.shape
        s = shrinkage
        alpha = s * float((r * r).sum()) / max(m, 1) / dim  # s tr(S) / D, S = R^T R / M
        if alpha <= 1e-12:  # one row per class: no within-class scatter, the identity (z-scored NCM)
            alpha, s = 1.0, 1.0
        beta = (1 - s) / max(m, 1)
        # Sigma = (1 - s) R^T R / M + alpha I; its inverse by Woodbury (M << D).
        inner = np.linalg.solve(alpha * np.eye(m) + beta * r @ r.T, r @ means.T)  # [M, K]
        w = (means - beta * (r.T @ inner).T) / alpha  # [K, D]
        b = -0.5 * (w * means).sum(1)
        return np.array(classes)[(xte @ w.T + b).argmax(1)]
    raise ValueError(method)


def within_style_residuals(x, y, content, contents):
    """Within-style residual rows of the clips of ``contents``: each content centred on its own
    mean, then every clip's deviation from its style's mean over those contents (styles seen
    in at least two of them). For `classify(..., scatter=)`: the metric of a classifier whose
    class means come from another content."""
    keep = np.isin(content, list(contents))
    xc = np.asarray(x, float)[keep].copy()
    yk, ck = np.asarray(y)[keep], np.asarray(content)[keep]
    for c in set(ck.tolist()):
        xc[ck == c] -= xc[ck == c].mean(0)
    rows = [xc[yk == s] - xc[yk == s].mean(0) for s in sorted(set(yk.tolist())) if (yk == s).sum() >= 2]
    return np.concatenate(rows) if rows else np.zeros((0, xc.shape[1]))


def pca_fit(x, k):
    """Mean and the first ``k`` principal directions of the rows of ``x``."""
    mu = x.mean(0)
    _, _, vt = np.linalg.svd(x - mu, full_matrices=False)
    return mu, vt[:k]
