"""`style.transfer` and `style.content_mean` (issue #22): eq. 8 as the default, the content-mean
option, angle branches, errors, jit; the Bandai-1 checks read `../shared/data/mocap/bandai1`."""

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
    return m.skeleton(), channel_names_for(m.topology, "euler")


def model(names, seed, scale=0.3, n=3, omega=2 * np.pi):
    rng = np.random.default_rng(seed)
    c = len(names)
    off = rng.normal(0, scale, c)
    off[:3] = [0.0, 10.0, 17.0]
    return fourier.FourierModel(jnp.asarray(off), jnp.asarray(np.abs(rng.normal(0, scale / 2, (c, n)))),
                                jnp.asarray(rng.uniform(-np.pi, np.pi, (c, n))), jnp.asarray(omega),
                                representation="euler", channel_names=names)


def signal(m, k=16):
    return np.asarray(fourier.synthesize_phase(m, jnp.arange(k) * (2 * jnp.pi / k)))


def test_eq8_is_the_default_and_is_unumas_superposition(cmu):
    _, names = cmu
    a, b, base = model(names, 1), model(names, 2), model(names, 3)
    for w in (1.0, 0.5):
        got = style.transfer(a, b, base, weight=w)
        ref = style.superpose(base, [style.characteristic(a, b)], [w])
        for x, y in zip(jax.tree.leaves(got), jax.tree.leaves(ref), strict=True):
            np.testing.assert_allclose(x, y, atol=1e-6)
    # the source's own neutral model as the target: the source comes back
    np.testing.assert_allclose(signal(style.transfer(a, b, b)), signal(a), atol=1e-5)


def test_content_mean_is_the_mean_signal(cmu):
    _, names = cmu
    ms = [model(names, s, omega=2 * np.pi) for s in range(4)]
    mean = style.content_mean(ms)
    np.testing.assert_allclose(signal(mean), np.mean([signal(m) for m in ms], 0), atol=1e-5)
    np.testing.assert_allclose(signal(style.content_mean(ms[:1])), signal(ms[0]), atol=1e-6)
    # omega is averaged geometrically
    ws = [eqx.tree_at(lambda m: m.omega, m, jnp.asarray(w)) for m, w in zip(ms, (2.0, 8.0, 4.0, 4.0), strict=True)]
    assert float(style.content_mean(ws).omega) == pytest.approx(4.0, rel=1e-5)


def test_content_mean_compares_offsets_on_one_branch(cmu):
    """A clip whose Euler offsets sit 2 pi away is the same motion: the mean must not move."""
    _, names = cmu
    ms = [model(names, s) for s in range(3)]
    turned = eqx.tree_at(lambda m: m.offset, ms[1], ms[1].offset.at[3:].add(2 * np.pi))
    a, b = style.content_mean(ms), style.content_mean([ms[0], turned, ms[2]])
    np.testing.assert_allclose(signal(a), signal(b), atol=1e-5)
    # the naive mean (no branch rule) is 2 pi / 3 off on every angle channel
    naive = np.mean([signal(m) for m in (ms[0], turned, ms[2])], 0)
    assert np.abs(naive[:, 3:] - signal(a)[:, 3:]).min() > 2.0


def test_content_mean_transfer(cmu):
    _, names = cmu
    src = [model(names, s) for s in range(4)]
    dst = [model(names, 10 + s) for s in range(4)]
    styled = model(names, 20)
    m_s, m_t = style.content_mean(src), style.content_mean(dst)
    # weight 0: the target content's mean; a source equal to its content's mean: the same
    np.testing.assert_allclose(signal(style.transfer(styled, src, dst, method="content_mean", weight=0.0)),
                               signal(m_t), atol=1e-5)
    np.testing.assert_allclose(signal(style.transfer(m_s, src, dst, method="content_mean")), signal(m_t), atol=1e-5)
    # linear in the weight at a common phase: m_t + w (source - m_s)
    for w in (0.5, 1.5):
        got = signal(style.transfer(styled, src, dst, method="content_mean", weight=w))
        want = signal(m_t) + w * (signal(styled) - signal(m_s))
        np.testing.assert_allclose(got[:, 3:], want[:, 3:], atol=1e-4)
    # a single model as a reference is used as it is
    np.testing.assert_allclose(signal(style.transfer(styled, m_s, m_t, method="content_mean")),
                               signal(style.transfer(styled, src, dst, method="content_mean")), atol=1e-5)


def test_transfer_traces_and_differentiates(cmu):
    _, names = cmu
    a, b, base = model(names, 1), model(names, 2), model(names, 3)
    f = jax.jit(lambda w: style.transfer(a, [b, a], [base, b], method="content_mean", weight=w).offset.sum())
    assert np.isfinite(float(f(0.5)))
    g = jax.grad(lambda w: style.transfer(a, b, base, weight=w).amplitude.sum())(0.7)
    assert np.isfinite(float(g))


def test_transfer_errors(cmu):
    _, names = cmu
    a, b = model(names, 1), model(names, 2)
    with pytest.raises(UserError, match="`method` must be one of"):
        style.transfer(a, b, b, method="ridge")
    with pytest.raises(UserError, match="'eq8' takes one model as `source_reference`"):
        style.transfer(a, [a, b], b)
    with pytest.raises(UserError, match="non-empty sequence"):
        style.content_mean([])
    with pytest.raises(UserError, match=r"models\[1\]"):
        style.content_mean([a, "b"])
    with pytest.raises(UserError, match="stacked"):
        style.transfer(a, style.stack([a, b]), b, method="content_mean")
    other = fourier.FourierModel(a.offset[:5], a.amplitude[:5], a.phase[:5], a.omega, representation="euler",
                                 channel_names=names[:5])
    with pytest.raises(UserError):
        style.content_mean([a, other])


@pytest.mark.skipif(not BANDAI.is_dir(), reason="Bandai-1 not found at ../shared/data/mocap/bandai1")
def test_no_limb_flip_at_any_weight_on_bandai():
    """Walk -> run on Bandai-1 through fit -> synthesize -> FK: at weights 0 to 1.5 the
    content-mean transfer's largest joint jump per frame stays within the sources' (issue #22,
    item 4); a transfer that crossed an angle branch would jump by a limb length."""
    from experiments._style_data import fit_clips
    from experiments._style_transfer import max_jump

    keys = [(c, s) for c in ("walk", "run") for s in ("normal", "sad", "happy", "old")]
    clips = [{"path": BANDAI / f"dataset-1_{c}_{s}_001.bvh", "content": c, "style": s, "take": "001"}
             for c, s in keys]
    # the experiment's on-disk cache (outside the repository; keyed by the clips and settings)
    fitted, skels, _, motions, failed = fit_clips(clips, 3, "euler", pathlib.Path("/tmp/fourierjax_style_space_cache"))
    assert not failed
    models = dict(zip(keys, fitted, strict=True))
    skel, dt = skels[keys.index(("run", "normal"))], motions[keys.index(("run", "normal"))].frame_time_s
    ref = max(max_jump(m, skel, dt) for m in models.values())
    others = ["normal", "happy", "old"]
    for w in (0.0, 0.5, 1.0, 1.5):
        m = style.transfer(models[("walk", "sad")], [models[("walk", s)] for s in others],
                           [models[("run", s)] for s in others], method="content_mean", weight=w)
        assert max_jump(m, skel, dt) <= 1.01 * ref, w


def test_no_retrace_for_new_weights_or_models(cmu):
    """Weights are arrays and models leaves: new values of either reuse the compiled programs."""
    import importlib

    from fourierjax._style import characteristics

    # the module (its package re-exports the function `transfer` under the same name)
    transfer = importlib.import_module("fourierjax._style.transfer")
    _, names = cmu
    ms = [model(names, s) for s in range(6)]
    style.transfer(ms[0], ms[1:3], ms[3:5], method="content_mean", weight=0.5)
    style.transfer(ms[0], ms[1], ms[2], weight=0.5)
    before = (transfer._content_mean.num_traces(), characteristics._superpose.num_traces())
    for w in (0.25, 0.75, 1.5):
        style.transfer(ms[5], ms[2:4], ms[0:2], method="content_mean", weight=w)
        style.transfer(ms[5], ms[3], ms[4], weight=w)
    assert (transfer._content_mean.num_traces(), characteristics._superpose.num_traces()) == before
