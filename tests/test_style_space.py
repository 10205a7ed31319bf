"""`style.cycle_distance` (issue #22) and the style-space experiment's pieces: classifiers, leave-one-take-out
without leakage, the body-map fitting pipeline; the Bandai-1 checks read `../shared/data/mocap/bandai1`."""

import pathlib

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

from fourierjax import data, fourier, style
from fourierjax.errors import UserError
from fourierjax.features import channel_names_for

ROOT = pathlib.Path(__file__).resolve().parent.parent
BANDAI = ROOT / ".." / "shared" / "data" / "mocap" / "bandai1" / "data"


@pytest.fixture(scope="module")
def cmu():
    m = data.load("07_01")
    return m, m.skeleton(), channel_names_for(m.topology, "euler")


def random_model(names, seed, scale=0.3, n=3):
    rng = np.random.default_rng(seed)
    c = len(names)
    off = rng.normal(0, scale, c)
    off[:3] = [0.0, 10.0, 17.0]  # root.vx, root.vz, root.y
    return fourier.FourierModel(jnp.asarray(off), jnp.asarray(np.abs(rng.normal(0, scale / 2, (c, n)))),
                                jnp.asarray(rng.uniform(-np.pi, np.pi, (c, n))), jnp.asarray(2 * np.pi),
                                representation="euler", channel_names=names)


def reference_distance(a, b, skeleton, k):
    """Slow NumPy reference: positions through `motion.model_joint_positions`, loops over shifts."""
    from fourierjax.motion import model_joint_positions

    th = 2 * np.pi * np.arange(k) / k
    pa = np.asarray(model_joint_positions(a, skeleton, th), float)
    pb = np.asarray(model_joint_positions(b, skeleton, th), float)
    pa, pb = pa - pa[:, :1], pb - pb[:, :1]  # root-relative (the root sits at the origin)
    best = np.inf
    for s in range(k):
        tot = 0.0
        for i in range(k):
            for j in range(pa.shape[1]):
                tot += np.sqrt(np.sum((pa[i, j] - pb[(i + s) % k, j]) ** 2))
        best = min(best, tot / (k * pa.shape[1]))
    return best


def test_zero_for_a_phase_shifted_copy(cmu):
    _, skel, names = cmu
    a = random_model(names, 0)
    assert float(style.cycle_distance(a, a, skel)) < 1e-4
    for s in (5, 17, 40):
        b = fourier.shift_phase(a, 2 * np.pi * s / 64)
        d, shift = style.cycle_distance_shift(a, b, skel, num_samples=64)
        assert float(d) < 1e-3, s
        assert int(shift) == (-s) % 64  # b at theta + 2 pi shift / K equals a at theta
    # off the sampling grid the distance is small, not zero; a different model is far
    b = fourier.shift_phase(a, 2 * np.pi * 5.5 / 64)
    far = float(style.cycle_distance(a, random_model(names, 1), skel))
    assert 0 < float(style.cycle_distance(a, b, skel)) < 0.05 * far


def test_symmetric_and_matches_numpy_reference(cmu):
    _, skel, names = cmu
    a, b = random_model(names, 2), random_model(names, 3)
    dab = float(style.cycle_distance(a, b, skel, num_samples=16))
    dba = float(style.cycle_distance(b, a, skel, num_samples=16))
    assert dab == pytest.approx(dba, rel=1e-5)
    assert dab == pytest.approx(reference_distance(a, b, skel, 16), rel=1e-4)
    assert dab > 0.1


def test_root_motion_does_not_count(cmu):
    _, skel, names = cmu
    a = random_model(names, 4)
    b = eqx.tree_at(lambda m: m.offset, a, a.offset.at[:3].add(jnp.asarray([3.0, 5.0, 2.0])))
    assert float(style.cycle_distance(a, b, skel)) < 1e-4


def test_batched_equals_single_and_one_trace(cmu):
    from fourierjax._style import distance

    _, skel, names = cmu
    ms = [random_model(names, s) for s in range(5, 9)]
    A, B = style.stack(ms[:2]), style.stack(ms[2:])
    d = np.asarray(style.cycle_distances(A, B, skel, num_samples=16))
    for i in range(2):
        assert d[i] == pytest.approx(float(style.cycle_distance(ms[i], ms[2 + i], skel, num_samples=16)), rel=1e-5)
    before = distance._cycle_distance_jit.num_traces()
    for s in range(3):
        style.cycle_distance(ms[s], ms[s + 1], skel, num_samples=16)
    assert distance._cycle_distance_jit.num_traces() == before  # same shapes: no retrace


def test_gradient_is_finite_at_zero_distance(cmu):
    _, skel, names = cmu
    a = random_model(names, 9)
    g = jax.grad(lambda off: style.cycle_distance(eqx.tree_at(lambda m: m.offset, a, off), a, skel,
                                                  num_samples=8))(a.offset)
    assert np.all(np.isfinite(np.asarray(g)))


def test_argument_errors(cmu):
    _, skel, names = cmu
    a = random_model(names, 0)
    with pytest.raises(UserError, match="num_samples"):
        style.cycle_distance(a, a, skel, num_samples=1)
    with pytest.raises(UserError, match="stacked"):
        style.cycle_distance(style.stack([a, a]), a, skel)
    with pytest.raises(UserError, match="Skeleton"):
        style.cycle_distance(a, a, "skeleton")


# ----------------------------------------------------------------------------- experiment pieces


def test_classifiers_separate_clusters():
    from experiments.style_space import CLASSIFIERS, classify

    rng = np.random.default_rng(0)
    centres = rng.normal(0, 3, (4, 50))
    xtr = np.concatenate([c + rng.normal(0, 1, (3, 50)) for c in centres])
    ytr = np.repeat(np.array(list("abcd"), object), 3)
    xte = centres + rng.normal(0, 1, (4, 50))
    for c in CLASSIFIERS:
        assert list(classify(c, xtr, ytr, xte, k=1, shrinkage=0.3)) == list("abcd"), c
    # a useless feature of huge scale does not blind them (z-scoring)
    xtr2 = np.concatenate([xtr, rng.normal(0, 1e6, (12, 1))], 1)
    xte2 = np.concatenate([xte, rng.normal(0, 1e6, (4, 1))], 1)
    assert list(classify("lda", xtr2, ytr, xte2, shrinkage=0.3)) == list("abcd")


def test_lda_uses_the_within_class_covariance():
    """Classes apart along a low-variance axis and mixed along a noisy one: LDA beats the plain mean."""
    from experiments.style_space import classify

    rng = np.random.default_rng(1)
    n = 40
    u, v = np.array([1.0, 1.0]) / np.sqrt(2), np.array([1.0, -1.0]) / np.sqrt(2)
    shift = 1.0 * u + 0.3 * v  # large along the noisy axis u, small along the quiet axis v

    def sample():
        e = rng.normal(0, 1, (2 * n, 2))
        return np.outer(2.0 * e[:, 0], u) + np.outer(0.05 * e[:, 1], v) + np.repeat([[0.0, 0.0], shift], n, 0)

    x, xt = sample(), sample()
    y = np.repeat(np.array(["a", "b"], object), n)
    acc = {c: np.mean(classify(c, x, y, xt, shrinkage=0.05) == y) for c in ("ncm", "lda")}
    assert acc["lda"] > 0.95 and acc["lda"] > acc["ncm"] + 0.05


def test_lda_scatter_from_other_rows_gives_one_example_classes_a_metric():
    """One training row per class: plain LDA is the nearest mean, blind to a noisy axis; within-class
    residual rows from elsewhere (`scatter=`) give it the covariance, without adding class examples."""
    from experiments._style_classify import classify

    rng = np.random.default_rng(2)
    k = 12
    means = np.stack([0.5 * np.arange(k), np.zeros(k)], 1)  # classes apart along axis 0 only

    def noise(n):  # quiet along axis 0, loud along axis 1
        return np.stack([0.05 * rng.normal(0, 1, n), 3.0 * rng.normal(0, 1, n)], 1)

    xtr, xte = means + noise(k), means + noise(k)
    y = np.array([f"s{i}" for i in range(k)], object)
    plain = np.mean(classify("lda", xtr, y, xte) == y)
    assert plain == np.mean(classify("ncm", xtr, y, xte) == y)  # no within-class scatter: the mean
    # little shrinkage: its target, a multiple of the identity, is the plain mean's metric
    metric = np.mean(classify("lda", xtr, y, xte, shrinkage=0.01, scatter=noise(200)) == y)
    assert metric > 0.75 and metric > plain + 0.3


def test_the_ceiling_trains_on_one_take_and_sees_nothing_of_the_other():
    """`one_per_style`: trained on one take (one row per style), tested on the other; a test row
    changed wildly changes no other prediction; the scatter comes from the other contents only."""
    from experiments._style_ceiling import SETTINGS, one_per_style
    from experiments._style_classify import within_style_residuals

    rng = np.random.default_rng(4)
    styles = list("abcdef")
    rows, y, content, take = [], [], [], []
    for c, t in (("walk", "1"), ("walk", "2"), ("run", "1"), ("dash", "1")):
        for k, s in enumerate(styles):
            rows.append({"walk": 0.0, "run": 4.0, "dash": -4.0}[c] + np.eye(6)[k] * 2 + rng.normal(0, 0.3, 6))
            y.append(s)
            content.append(c)
            take.append(t)
    x, y, content, take = np.array(rows), np.array(y, object), np.array(content), np.array(take)
    kw = {"k": 1, "l2": 0.01}
    r = one_per_style(x, np.ones(6), y, content, take, "walk", kw=kw)
    assert set(r) == set(SETTINGS) and all(n == 12 for _, n in r.values())
    assert all(acc >= 0.9 for acc, _ in r.values()), r
    # the residuals of run and dash: centred per content, then per style; walks are not in them
    res = within_style_residuals(x, y, content, ["run", "dash"])
    assert res.shape == (12, 6) and abs(res.sum(0)).max() < 1e-9
    x2 = x.copy()
    x2[(content == "walk") & (take == "2")] += rng.normal(0, 50, (6, 6))  # take 2 ruined
    r2 = one_per_style(x2, np.ones(6), y, content, take, "walk", kw=kw)
    assert all(r2[s][0] <= 0.6 for s in r2)  # the ruined take fails both as test and as training set
    r3 = one_per_style(x2, np.ones(6), y, content, take, "walk", kw=kw, centre=True)
    assert r3.keys() == r2.keys()


def test_feature_targets_recover_a_linear_map():
    """Target-content rows that are the source rows' offsets times per-feature slopes: the
    `slope` point is the held-out style's true target row; `identity` adds the offset as it is."""
    from experiments._style_ceiling import feature_targets

    rng = np.random.default_rng(6)
    xs = rng.normal(0, 1, (9, 5))
    slopes = np.array([0.5, 1.0, 2.0, -1.0, 0.0])
    xt = 3.0 + xs * slopes
    u = rng.normal(0, 1, 5)
    pts = feature_targets(xs[1:], xt[1:], u, sd=xt[1:].std(0) + 1e-12, column_weights=np.ones(5))
    np.testing.assert_allclose(pts["slope"], xt[1:].mean(0) + slopes * u, atol=1e-9)
    np.testing.assert_allclose(pts["identity"], xt[1:].mean(0) + u)
    assert {"spread", "ridge1", "ridge1_norm", "ridge10", "ridge10_norm"} <= set(pts)


def test_find_clips_parses_labels(tmp_path):
    from experiments.style_space import find_clips

    for n in ("dataset-1_walk_happy_001.bvh", "dataset-1_walk-back_sad_002.bvh", "dataset-1_bow_sad_001.bvh",
              "notes.txt"):
        (tmp_path / n).write_text("")
    pat = r"dataset-1_(?P<content>[a-z-]+)_(?P<style>[a-z-]+)_(?P<take>\d+)\.bvh$"
    got = [(c["content"], c["style"], c["take"]) for c in find_clips(tmp_path, pat, ["walk", "walk-back"], [])]
    assert got == [("walk-back", "sad", "002"), ("walk", "happy", "001")]
    assert find_clips(tmp_path, pat, ["walk", "walk-back"], ["happy"])[0]["style"] == "happy"


def test_config_schema_names_the_key(tmp_path):
    from fourierjax.config import ConfigError, load_experiment_config

    p = tmp_path / "c.toml"
    p.write_text('experiment = "style_space"\nfolders = ["x"]\npattern = "(?P<content>a)"\n')
    with pytest.raises(ConfigError, match="key 'pattern'.*named groups"):
        load_experiment_config(p)
    cfg = load_experiment_config(ROOT / "configs" / "experiments" / "style_space.toml", small=True)
    assert cfg["styles"] and cfg["transfers"] == [["walk", "run"]]


needs_bandai = pytest.mark.skipif(not BANDAI.is_dir(), reason="Bandai-1 not found at ../shared/data/mocap/bandai1")


@needs_bandai
def test_the_pipeline_roots_and_aligns_bandai_clips(tmp_path):
    """Through `fit_clips` (fit_motions with each clip's body map): the root channels follow the
    pelvis both in walks (travel on `Hips`) and in runs (`joint_Root` moves too), phase 0 is the
    left heel strike (the left ankle ahead of the right, the body facing +Z), and the fits
    come back from the on-disk cache unchanged. (This replaces the hand-made re-rooting and
    alignment the experiment had before the body-map pipeline.)"""
    from experiments._style_data import fit_clips

    clips = [{"path": BANDAI / f"dataset-1_{c}_normal_001.bvh", "content": c, "style": "normal", "take": "001"}
             for c in ("walk", "run")]
    models, skels, maps, motions, failed = fit_clips(clips, 3, "euler", tmp_path)
    assert not failed
    for m, sk, bm, mo in zip(models, skels, maps, motions, strict=True):
        names = list(m.channel_names)
        speed = float(np.hypot(m.offset[names.index("root.vx")], m.offset[names.index("root.vz")]))
        assert speed > 50, mo.source  # cm/s: the pelvis travels, whichever joint carries it in the file
        assert bm.pelvis == mo.topology.names.index("Hips")
        p = np.asarray(style.cycle_positions(m, sk, num_samples=32))
        lead = p[:, bm.left.ankle, 2] - p[:, bm.right.ankle, 2]
        assert lead[0] > 0.5 * lead.max() > 0, mo.source
    again, *_ = fit_clips(clips, 3, "euler", tmp_path)  # from the cache
    for a, b in zip(models, again, strict=True):
        np.testing.assert_allclose(a.amplitude, b.amplitude)
        assert a.channel_names == b.channel_names


def test_leave_one_take_out_uses_no_statistic_of_the_held_out_take():
    """Changing one held-out clip changes no other prediction: neither the z-scoring, the
    content centring, the PCA nor a classifier saw it."""
    from experiments._style_classify import CLASSIFIERS
    from experiments.style_space import loto

    rng = np.random.default_rng(3)
    styles = list("abcde")
    rows, y, content, take = [], [], [], []
    for c, shift in (("walk", 0.0), ("run", 5.0)):
        for t in (("1", "2") if c == "walk" else ("1",)):
            for k, s in enumerate(styles):
                rows.append(shift + np.eye(5)[k] * 3 + rng.normal(0, 0.3, 5))
                y.append(s)
                content.append(c)
                take.append(t)
    x, y, content, take = np.array(rows), np.array(y, object), np.array(content), np.array(take)
    kw = {"k": 1, "shrinkage": 0.5, "l2": 0.01}
    for pooled in (False, True):
        for k in (None, 3):
            idx, p0 = loto(x, np.ones(5), y, content, take, "walk", pooled=pooled, kw=kw, k=k)
            x2 = x.copy()
            x2[idx[0]] += 100.0  # the first held-out walk (take 1) changes wildly
            _, p1 = loto(x2, np.ones(5), y, content, take, "walk", pooled=pooled, kw=kw, k=k)
            fold = take[idx] == take[idx[0]]
            fold[0] = False  # the other clips of the held-out take
            for c in CLASSIFIERS:
                assert list(p0[c][fold]) == list(p1[c][fold]), (pooled, k, c)
                assert np.mean(p0[c] == y[idx]) >= 0.8, (pooled, k, c)


def test_style_space_schema_lives_in_config():
    """The experiment's schema is in `fourierjax.config.SCHEMAS` without importing the experiment."""
    import subprocess
    import sys

    code = ("import sys, fourierjax.config as c; assert 'style_space' in c.SCHEMAS; "
            "assert not any(m.startswith('experiments') for m in sys.modules)")
    subprocess.run([sys.executable, "-c", code], cwd=ROOT, check=True, timeout=120)


def test_cycle_positions_are_the_root_relative_poses(cmu):
    from fourierjax.motion import model_joint_positions

    _, skel, names = cmu
    a = random_model(names, 11)
    p = np.asarray(style.cycle_positions(a, skel, num_samples=8))
    ref = np.asarray(model_joint_positions(a, skel, 2 * np.pi * np.arange(8) / 8))
    assert p.shape == (8, skel.topology.num_joints, 3)
    np.testing.assert_allclose(p, ref - ref[:, :1], atol=1e-4)
    with pytest.raises(UserError, match="cycle_positions: `num_samples`"):
        style.cycle_positions(a, skel, num_samples=0)


def test_the_pelvis_comes_from_the_body_map(cmu):
    """`cycle_positions` puts the body map's pelvis at the origin (not joint 0); without a map it
    infers the model's own (`gait.model_body_map`); with both models traced it asks for one."""
    import dataclasses

    from fourierjax.gait import model_body_map

    _, skel, names = cmu
    a, b = random_model(names, 3), random_model(names, 4)
    bm = model_body_map(a, skel)
    p = np.asarray(style.cycle_positions(a, skel, num_samples=8, body_map=bm))
    assert np.abs(p[:, bm.pelvis]).max() < 1e-5
    np.testing.assert_allclose(np.asarray(style.cycle_positions(a, skel, num_samples=8)), p, atol=1e-6)
    other = dataclasses.replace(bm, pelvis=bm.spine[0])
    q = np.asarray(style.cycle_positions(a, skel, num_samples=8, body_map=other))
    assert np.abs(q[:, other.pelvis]).max() < 1e-5 and np.abs(q - p).max() > 1e-3
    d = float(style.cycle_distance(a, b, skel, num_samples=8, body_map=bm))
    assert float(style.cycle_distance(a, b, skel, num_samples=8)) == pytest.approx(d, rel=1e-6)
    from fourierjax._style import distance

    distance._INFERRED_PELVIS.clear()  # nothing inferred yet for this rig: a traced call must ask
    with pytest.raises(UserError, match="body_map="):
        jax.grad(lambda x: style.cycle_distance(x, x, skel, num_samples=8))(a)
    with pytest.raises(UserError, match="another skeleton"):
        style.cycle_distance(a, b, skel, body_map=dataclasses.replace(bm, joint_names=("x",) * len(bm.joint_names)))


def test_rotation_features_see_rotations_not_angle_branches(cmu):
    """The quaternion and 6-D features of the experiment: an Euler offset moved by a whole turn is the
    same rotation (same features); a constant pose has no harmonics, and its mean quaternion is a unit one."""
    from experiments._style_features import _rotation_harmonics
    from fourierjax.gait import model_body_map

    _, skel, names = cmu
    a = random_model(names, 7)
    bm = model_body_map(a, skel)
    turned = eqx.tree_at(lambda m: m.offset, a, a.offset.at[6:].add(2 * np.pi))
    fa, ft = _rotation_harmonics(a, skel, bm, 3), _rotation_harmonics(turned, skel, bm, 3)
    for k in ("quat", "sixd"):
        np.testing.assert_allclose(fa[k], ft[k], atol=1e-4)
    assert fa["quat"].shape == (skel.topology.num_joints, 4, 7) and fa["sixd"].shape[1:] == (6, 7)
    still = eqx.tree_at(lambda m: m.amplitude, a, jnp.zeros_like(a.amplitude))
    fs = _rotation_harmonics(still, skel, bm, 3)
    assert np.abs(fs["quat"][:, :, 1:]).max() < 1e-5 and np.abs(fs["sixd"][:, :, 1:]).max() < 1e-5
    np.testing.assert_allclose(np.linalg.norm(fs["quat"][:, :, 0], axis=1), 1.0, atol=1e-5)
    assert np.abs(fa["quat"][:, :, 1:]).max() > 1e-2  # a moving model has harmonics


def random_tangent_model(topology, seed, scale=0.3, n=3):
    """A tangent model (`R_j = M_j exp(d_j)`) with random coefficients and random clip means."""
    names = channel_names_for(topology, "tangent")
    a = random_model(names, seed, scale, n)
    k = sum(nm.endswith(".expmap_tangent0") for nm in names)
    q = np.random.default_rng(seed + 100).normal(size=(k, 4))
    q = q / np.linalg.norm(q, axis=1, keepdims=True) * np.sign(q[:, :1])
    return fourier.FourierModel(a.offset, a.amplitude, a.phase, a.omega, representation="tangent",
                                channel_names=names, frames=jnp.asarray(q))


def test_tangent_style_vectors_of_the_transfer_invert_about_the_base(cmu, tmp_path):
    """The experiment's tangent path: every clip's style vector is taken about the BASE's clip means
    (`branch_vectors`), so `model_from_style_vector(row, base)` gives back the clip itself (the same
    joint rotations at every phase, an independent check of the frames); the vector's layout (harmonic,
    joint group) covers the clip-mean entries; the fit cache keeps the frames."""
    from scipy.spatial.transform import Rotation

    from experiments._style_data import _load, _save
    from experiments._style_transfer import branch_vectors, vector_layout
    from fourierjax._fourier import _tangent
    from fourierjax.body import infer_body_map

    motion, skel, _ = cmu
    bm = infer_body_map(motion)
    base, *ms = (random_tangent_model(skel.topology, s) for s in (1, 2, 3))
    v = branch_vectors(ms, base)
    phase = jnp.linspace(0.0, 2 * np.pi, 16, endpoint=False)
    cols = _tangent.triples(base.channel_names, base.num_channels)

    def joint_rotations(x):  # R_j = M_j exp(d_j) by scipy, d from the coefficients as plain series
        series = fourier.FourierModel(x.offset, x.amplitude, x.phase, x.omega, representation="expmap")
        d = np.asarray(fourier.synthesize_phase(series, phase))[:, cols]
        q = np.asarray(x.frames)[None].repeat(len(phase), 0)
        r = Rotation.from_quat(q[..., [1, 2, 3, 0]].reshape(-1, 4)) * Rotation.from_rotvec(d.reshape(-1, 3))
        return r.as_matrix()

    for row, m in zip(v, ms, strict=True):
        back = style.model_from_style_vector(jnp.asarray(row, jnp.float32), base)
        np.testing.assert_allclose(joint_rotations(back), joint_rotations(m), atol=2e-4)  # every joint, phase
    harm, groups = vector_layout(base, bm, skel.topology)
    k = base.frames.shape[0]
    assert len(harm) == len(groups) == v.shape[1]
    assert (harm[-3 * k - 1:-1] == 0).all() and harm[-1] == base.amplitude.shape[1] + 1 and groups[-1] == 3
    assert set(groups[-3 * k - 1:-1]) <= {0, 1, 2}
    _save(tmp_path / "f.npz", [True, True], ms)
    ok, again = _load(tmp_path / "f.npz", "tangent")
    assert ok.all()
    for a, b in zip(ms, again, strict=True):
        np.testing.assert_allclose(a.frames, b.frames)
        np.testing.assert_allclose(a.amplitude, b.amplitude)
