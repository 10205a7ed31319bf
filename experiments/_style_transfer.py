"""Transfer methods of the style-space experiment: each builds the target content's model in the held-out style."""

from __future__ import annotations

import numpy as np

#: Transfer methods in table order; "baseline" is the target content's neutral clip unchanged and
#: "content_mean_only" the mean of its other styles (no style information at all); the last two have
#: no limb-flip rows (their weights are swept directly, the ``transfer_weights`` rows).
METHODS = ("baseline", "content_mean_only", "eq8", "eq8_phasor", "amplitude_ratio", "eq8_ls_weight",
           "ls_weights", "harmonic_weights", "group_weights", "ridge_map", "content_mean", "content_mean_w",
           "content_mean_cv", "content_mean_gains", "content_mean_gains_cv", "content_mean_cadence_cv",
           "content_mean_cadence_cv_sat", "content_mean_rec_cv")
#: Methods whose extrapolation saturates (`style.superpose(saturation=SATURATION)`): the
#: transfer is the unsaturated method's at its weight (<= 1), and the limb-flip line beyond 1
#: moves the posture by the weight, the swings and the cadence by the saturated weight.
SATURATED = {"content_mean_cadence_cv_sat": "content_mean_cadence_cv"}
#: Their saturation: the swings and the cadence never beyond 1.05 of the transfer's. Not tuned
#: per data set (0.02 and 0.1 are compared in docs/findings.md, section 3).
SATURATION = 0.05
#: Methods of the per-weight limb-flip table (`flips_by_weight`): eq. 8 plain, the distance
#: winner and its saturated form.
FLIP_TABLE_METHODS = ("eq8", "content_mean_cadence_cv", "content_mean_cadence_cv_sat")


def branch_vectors(models, reference):
    """Style vectors (phasor coordinates, `style.style_vector`) with every model's angle
    offsets first moved onto ``reference``'s branch, so that means and regressions over clips
    compare angles on one branch. Tangent models have no branch: their clip means are taken
    as rotation vectors about ``reference``'s frames (`style.style_matrix(reference=)`), so
    `style.model_from_style_vector(v, reference)` inverts a row."""
    from fourierjax import style

    if reference.representation == "tangent":
        return np.asarray(style.style_matrix(list(models), reference=reference.frames), float)
    return np.asarray(style.style_matrix([_on_branch(reference, m) for m in models]), float)


def vector_layout(model, body_map, topology) -> tuple[np.ndarray, np.ndarray]:
    """Harmonic (0 offset, 1..N, N + 1 log omega) and joint group (`channel_groups`, 3 for log
    omega) of every style-vector entry of ``model``; a tangent model's clip-mean rotation vectors
    (3 per joint, before log omega) count as offsets of their joint's group."""
    c, n = model.amplitude.shape
    harm = [np.tile(np.array([0] + [1 + k // 2 for k in range(2 * n)]), c)]
    groups = [np.repeat(channel_groups(model, body_map, topology), 1 + 2 * n)]
    if model.representation == "tangent":
        names = [nm for nm in model.channel_names if nm.endswith(".expmap_tangent0")]
        g = channel_groups(model, body_map, topology)
        first = [list(model.channel_names).index(nm) for nm in names]
        harm.append(np.zeros(3 * len(first), int))
        groups.append(np.repeat(g[first], 3))
    return np.concatenate([*harm, [n + 1]]), np.concatenate([*groups, [3]])


def _on_branch(reference, model):
    from fourierjax import style

    # superpose(reference, [characteristic(model, reference)], [1], "phasor") is `model` on the
    # reference's branch (characteristic compares offsets on one branch).
    return style.superpose(reference, [style.characteristic(model, reference)], [1.0], method="phasor")


def channel_groups(model, body_map, topology) -> np.ndarray:
    """Joint group of every channel: 0 legs (and root channels), 1 trunk and head, 2 arms and hands."""
    names = model.channel_names
    legs = {body_map.left.hip, body_map.left.knee, body_map.left.ankle, body_map.left.toe,
            body_map.right.hip, body_map.right.knee, body_map.right.ankle, body_map.right.toe} - {-1}
    arms = set()
    for a in (body_map.left_arm, body_map.right_arm):
        if a is not None:
            arms |= {a.collar, a.shoulder, a.elbow, a.wrist} - {-1}
    group = np.ones(topology.num_joints, int)
    for j in range(topology.num_joints):
        chain, p = [j], topology.parents[j]
        while p >= 0:
            chain.append(p)
            p = topology.parents[p]
        if any(k in legs for k in chain):
            group[j] = 0
        elif any(k in arms for k in chain):
            group[j] = 2
    index = {n: i for i, n in enumerate(topology.names)}
    return np.array([0 if n.startswith("root.") else group[index[n.rsplit(".", 1)[0]]] for n in names])


def _ls(dx, dy):
    return float((dx * dy).sum() / max((dx * dx).sum(), 1e-12))


def vector_methods(vs, vt, styles, target, normal, *, ridge, weight, column_groups, harmonic_kinds):
    """Target-content style vectors of the style ``target`` by the style-space methods.

    ``vs``, ``vt``: dicts style -> branch-aligned style vector of the source and the target
    content. Nothing here reads ``vt[target]``: every mean, weight and map is fitted on the
    other styles.
    """
    others = [s for s in styles if s != target]
    xs, ys = np.stack([vs[s] for s in others]), np.stack([vt[s] for s in others])
    ms, mt = xs.mean(0), ys.mean(0)
    d = vs[target] - ms
    dx, dy = xs - ms, ys - mt
    out = {"content_mean_only": mt, "content_mean": mt + d, "content_mean_w": mt + weight * d}
    # one least-squares weight per channel, per harmonic (offset, 1..N, log omega), per joint group
    per = np.array([_ls(dx[:, i], dy[:, i]) for i in range(dx.shape[1])])
    out["ls_weights"] = mt + np.clip(per, 0.0, 1.5) * d
    for name, kinds in (("harmonic_weights", harmonic_kinds), ("group_weights", column_groups)):
        w = np.zeros(d.shape)
        for k in np.unique(kinds):
            m = kinds == k
            w[m] = np.clip(_ls(dx[:, m], dy[:, m]), 0.0, 1.5)
        out[name] = mt + w * d
    # eq. 8 with one weight fitted on the other styles' normal-relative pairs
    train = [s for s in others if s != normal]
    ex = np.stack([vs[s] - vs[normal] for s in train])
    ey = np.stack([vt[s] - vt[normal] for s in train])
    out["eq8_ls_weight"] = vt[normal] + _ls(ex, ey) * (vs[target] - vs[normal])
    # ridge regression (dual form, z-scored inputs) from source styles to target styles
    sx = np.where(xs.std(0) > 1e-12, xs.std(0), 1.0)
    zx = dx / sx
    a = np.linalg.solve(zx @ zx.T + ridge * np.eye(len(others)), dy)
    out["ridge_map"] = mt + (d / sx) @ zx.T @ a
    return out


def amplitude_ratio(base, a, b):
    """Eq. 8 with the amplitudes scaled by ``A_a / A_b`` instead of shifted by ``A_a - A_b``."""
    import equinox as eqx
    import jax.numpy as jnp

    from fourierjax import style

    out = style.superpose(base, [style.characteristic(a, b)], [1.0])
    ratio = jnp.clip((a.amplitude + 1e-3) / (b.amplitude + 1e-3), 0.0, 4.0)
    return eqx.tree_at(lambda m: m.amplitude, out, base.amplitude * ratio)


def max_phase_jump(model, skeleton, num_samples: int = 256, *, body_map=None) -> float:
    """Largest joint displacement per radian of cycle phase over one synthesized cycle (file
    units per radian): the limb-flip criterion of the transfer tables.

    A flip is a change of POSE between neighbouring phases of the cycle: a joint crossing an
    angle branch (an offset or a harmonic 2π off, averaged to π) turns its limb through a large
    angle while the rest of the body moves a little, so some joint covers far more distance per
    radian of phase than any joint of the clips read. Cadence does not change the poses of a
    cycle, only how many frames a radian takes: the per-frame jump (`max_jump`) is this value
    times ``omega * frame_time_s``, so a transfer that carries a faster cadence (the walk's
    cadence ratio at w = 1.5 made a run's omega 1.9x the neutral run's) reads as a flip per frame
    with no pose changing faster within the cycle. Per radian of phase, a pure cadence change
    leaves the value exactly as it was and a branch change still shows
    (`tests/test_transfer.py::test_phase_jump_catches_a_branch_change_not_a_faster_cadence`).
    The amplitude extrapolation of weights above 1 is not removed: larger swings cover more
    distance per radian, and the tables compare with the largest of the clips read.

    Arguments:
        model: one FourierModel; skeleton: its Skeleton; num_samples: phases per cycle;
        body_map: the rig's body map (its pelvis is the origin; `style.cycle_positions`).

    Returns:
        The largest joint displacement between consecutive phase samples over the phase step.
    """
    from fourierjax import style

    return float(style.peak_joint_speed(model, skeleton, per="radian", num_samples=num_samples, body_map=body_map))


def max_jump(model, skeleton, frame_time_s, num_samples: int = 256, *, body_map=None) -> float:
    """Largest joint displacement between consecutive frames over one synthesized cycle (file
    units): `max_phase_jump` times the radians of phase per frame, ``omega * frame_time_s``
    (a smooth cycle, so linear). It grows with the cadence; the flip criterion is per phase."""
    return max_phase_jump(model, skeleton, num_samples, body_map=body_map) * float(model.omega) * frame_time_s


def fit_recognition_weight(sources, targets, x_targets, featurise, grid, *, column_weights=None,
                           classifier: str = "ncm") -> tuple[float, dict]:
    """The content-mean transfer's weight that the runs-only scorer recognises best, chosen
    by leaving one reference style out at a time.

    For every style ``k`` of ``sources`` / ``targets`` (dicts style -> model of the source and
    the target content; the held-out style of the experiment is in neither) and every weight
    ``w`` of ``grid``: ``k``'s source clip transferred with the references and the cadence gain
    of the other styles (`style.fit_transfer_gains(..., cadence_only=True)`), featurised by
    ``featurise`` (model -> feature row) and classified by ``classifier`` trained on
    ``x_targets`` (the real target clips of ``targets``' styles, in their order). Returns the
    weight with the largest share recognised as ``k`` (ties: the smaller weight, the nearer the
    real clips) and ``{w: share}``.
    """
    from experiments._style_classify import classify
    from fourierjax import style

    labels = np.array(list(targets), object)
    hits = {float(w): [] for w in grid}
    for k in targets:
        rest = [s for s in targets if s != k]
        src, dst = [sources[s] for s in rest], [targets[s] for s in rest]
        cadence = style.fit_transfer_gains(src, dst, cadence_only=True)
        rows = [featurise(style.transfer(sources[k], src, dst, method="content_mean", weight=float(w),
                                         gains=cadence)) for w in grid]
        pred = classify(classifier, x_targets, labels, np.stack(rows), column_weights=column_weights)
        for w, p in zip(grid, pred, strict=True):
            hits[float(w)].append(p == k)
    scores = {w: float(np.mean(h)) for w, h in hits.items()}
    best = max(scores.values())
    return min(w for w, v in scores.items() if v == best), scores
