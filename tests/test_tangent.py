"""Issue #20: the "tangent" representation fits the same motion whatever the rig's joint frames,
Euler orders or up axis (`fourierjax._fourier._tangent`)."""

import re

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest
from scipy.spatial.transform import Rotation

import fourierjax.data
from fourierjax import fourier, gait, style
from fourierjax import motion as fmotion
from fourierjax._fourier import _tangent
from fourierjax.body import infer_body_map
from fourierjax.errors import UserError
from fourierjax.features import features_from_motion, heading_of, root_relative_positions
from fourierjax.io.axes import to_y_up
from fourierjax.model_io import load_model, save_model
from tests.conventions import convention_names, convert
from tests.rigs import blender, rest_rotated
from tests.test_rigs import _map_and_steps

THETA = jnp.linspace(0.0, 2 * np.pi, 24, endpoint=False)


def _rewrites(m):
    names = m.topology.names
    return {
        "bandai": (convert(m, "bandai"), convention_names(m.topology, "bandai")),
        "zup": (to_y_up(convert(m, "zup"), "z"), names),
        "blender": (blender(m), tuple("mixamorig:" + n for n in names)),
        "rest_rotated": (rest_rotated(m), tuple(n.replace("ToeBase", "Toe") for n in names)),
    }


class _Fit(eqx.Module):
    model: fourier.FourierModel
    heading: float = eqx.field(static=True)


def _fit(clips, representation, omega_steps=None):
    """One `fit_batch` of clips of one feature layout (one compile for each layout and batch
    size: the euler and tangent fits of four clips share theirs)."""
    feats = [features_from_motion(c, representation) for c in clips]
    names = feats[0][1]
    res = fourier.fit_batch(np.stack([x for x, _ in feats]), clips[0].frame_time_s, 3,
                            representation=representation, channel_names=names,
                            omega_steps=None if omega_steps is None else np.full(len(clips), omega_steps))
    return [_Fit(jax.tree.map(lambda v, k=k: v[k], res.model), heading_of(c)) for k, c in enumerate(clips)]


@pytest.fixture(scope="module")
def fits():
    m = fourierjax.data.load("07_01")[:200]
    rew = _rewrites(m)
    same = ("cmu", "bandai", "zup", "rest_rotated")  # one feature layout (blender: 2 more joints)
    clips = {"cmu": m, **{k: r for k, (r, _) in rew.items()}}
    # Tangent: fit_batch's own omega search (spectrum and variable projection on the tangent
    # coordinates, whose per-joint power and residual a change of joint frames leaves alone).
    tangent = dict(zip(same, _fit([clips[k] for k in same], "tangent")))
    tangent["blender"] = _fit([clips["blender"]], "tangent")[0]
    # Euler at the CMU clip's step frequency (the rewrites step alike), so that its failure
    # below is the representation's, not the omega search's: on the Bandai rewrite the Euler
    # search alone finds 0.57 Hz (its UpperArm_L winds 388 degrees near gimbal lock; fit_motions
    # gives that joint no weight in the search, `_motion._clip._search_weights`).
    omega = _map_and_steps(m)[1][2]
    euler = dict(zip(("cmu", "bandai"), _fit([clips["cmu"], clips["bandai"]], "euler", omega)))
    return m, rew, tangent, euler


def _positions(fit, motion, representation):
    """Root-relative positions at the clip's first 200 frame times (heading frame)."""
    x = fourier.synthesize(fit.model, jnp.arange(0, 200, 8) * motion.frame_time_s)
    pelvis = infer_body_map(motion).pelvis
    P = np.asarray(root_relative_positions(motion.skeleton(), x, representation, pelvis), np.float64)
    return P, fit.heading


def _error(fits_, m, rew, key, representation):
    """Max position error (fraction of leg length) of the rewrite `key` against the CMU clip, in
    each clip's own heading frame (no yaw undone: the facing is the same on every rig)."""
    P0, _ = _positions(fits_["cmu"], m, representation)
    r, names = rew[key]
    P, _ = _positions(fits_[key], r, representation)
    P = P[:, [r.topology.names.index(n) for n in names]]
    t = m.topology
    leg = sum(np.linalg.norm(m.offsets[t.names.index(n)]) for n in ("LeftLeg", "LeftFoot"))
    return float(np.linalg.norm(P - P0, axis=-1).max() / leg)


@pytest.mark.parametrize("key", ["bandai", "zup", "blender", "rest_rotated"])
def test_rewritten_rigs_give_the_same_heading(fits, key):
    """The heading frame (`features.heading_of`, from the hips' line) is the same on every rig:
    measured within 1.5e-7 rad on 07_01 (it was 3.7e-3 apart when CMU's facing snapped to its
    pelvis's local +Z)."""
    _, _, tangent, _ = fits
    assert abs(tangent[key].heading - tangent["cmu"].heading) < 1e-6


@pytest.mark.parametrize("key", ["bandai", "zup", "blender", "rest_rotated"])
def test_rewritten_rigs_give_the_same_omega(fits, key):
    """fit_batch's own fundamental (no step events) is the CMU clip's (measured within 2e-5;
    the Euler search alone finds 0.57 Hz on the Bandai rewrite against 0.91 Hz)."""
    _, _, tangent, _ = fits
    assert float(tangent[key].model.omega) == pytest.approx(float(tangent["cmu"].model.omega), rel=1e-3)
    assert float(tangent["cmu"].model.omega) / (2 * np.pi) == pytest.approx(0.911, abs=0.005)


@pytest.mark.parametrize("key", ["bandai", "zup", "blender", "rest_rotated"])
def test_rewritten_rigs_give_the_same_positions(fits, key):
    m, rew, tangent, _ = fits
    assert _error(tangent, m, rew, key, "tangent") < 1e-3


def test_euler_fails_the_same_check(fits):
    m, rew, _, euler = fits
    assert _error(euler, m, rew, "bandai", "euler") > 0.1  # measured 0.52 of leg length


@pytest.mark.parametrize("representation", ["tangent", "expmap"])
def test_features_under_x64_equal_float32(representation):
    """With float64 on (`jax.enable_x64`), the pelvis rows written into the converted quaternions
    used to hit a read-only view ("assignment destination is read-only"): the same features."""
    m = fourierjax.data.load("07_01")[:64]
    x32, names = features_from_motion(m, representation)
    with jax.enable_x64(True):
        x64, names64 = features_from_motion(m, representation)
    assert names64 == names
    np.testing.assert_allclose(x64, x32, atol=1e-5)


def test_model_file_round_trip(fits, tmp_path):
    m, _, tangent, euler = fits
    model = tangent["cmu"].model
    assert model.channel_names[3].endswith(".expmap_tangent0") and model.frames.shape == (
        (len(model.channel_names) - 3) // 3, 4)
    save_model(tmp_path / "t.npz", model, motion=m)
    back = jax.tree.map(jnp.asarray, load_model(tmp_path / "t.npz").model)
    assert back.representation == "tangent"
    np.testing.assert_allclose(back.frames, model.frames, atol=1e-7)
    np.testing.assert_allclose(fourier.synthesize_phase(back, THETA),
                               fourier.synthesize_phase(model, THETA), atol=1e-5)
    save_model(tmp_path / "e.npz", euler["cmu"].model)  # other models keep the old versions
    assert load_model(tmp_path / "e.npz").model.frames is None


def test_jit_and_vmap_equal_eager(fits):
    _, _, tangent, _ = fits
    a, b = tangent["cmu"].model, tangent["bandai"].model
    eager = fourier.synthesize_phase(a, THETA)
    np.testing.assert_allclose(eqx.filter_jit(fourier.synthesize_phase)(a, THETA), eager, atol=1e-5)
    both = fourier.stack_models([a, a])
    np.testing.assert_allclose(jax.vmap(fourier.synthesize_phase, (0, None))(both, THETA)[1], eager,
                               atol=1e-5)
    t = THETA / a.omega
    np.testing.assert_allclose(fourier.synthesize_batch(both, t)[0], fourier.synthesize(a, t), atol=1e-4)
    assert b.frames.shape == a.frames.shape


def test_gradient_matches_finite_differences_and_is_finite_at_zero(fits, x64):
    _, _, tangent, _ = fits
    model = jax.tree.map(lambda x: jnp.asarray(x, jnp.float64), tangent["cmu"].model)

    def loss(offset, m=model):
        x = fourier.synthesize_phase(eqx.tree_at(lambda q: q.offset, m, offset), THETA)
        return jnp.sum(jnp.sin(x[:, 3:]))

    g = jax.grad(loss)(model.offset)
    rng = np.random.default_rng(0)
    v = jnp.asarray(rng.normal(size=model.offset.shape))
    h = 1e-6
    fd = (loss(model.offset + h * v) - loss(model.offset - h * v)) / (2 * h)
    assert float(jnp.vdot(g, v)) == pytest.approx(float(fd), rel=1e-5, abs=1e-6)
    # d = 0 everywhere (the clip means themselves): no NaN gradient
    zero = eqx.tree_at(lambda q: (q.offset, q.amplitude), model,
                       (jnp.zeros_like(model.offset), jnp.zeros_like(model.amplitude)))
    g0 = jax.grad(lambda o: loss(o, zero))(zero.offset)
    assert bool(jnp.all(jnp.isfinite(g0)))


def test_interpolate_ends_reproduce_the_models(fits):
    _, _, tangent, _ = fits
    a, b = tangent["cmu"].model, tangent["zup"].model
    for s, ref in ((0.0, a), (1.0, b)):
        np.testing.assert_allclose(fourier.synthesize_phase(style.interpolate(a, b, s), THETA),
                                   fourier.synthesize_phase(ref, THETA), atol=1e-4)


def test_refusals_name_tangent(fits):
    _, _, tangent, _ = fits
    a = tangent["cmu"].model
    # Per-channel transfer gains do not commute with a change of joint frame (a gain per tangent
    # channel), so they refuse tangent models.
    # channel gains other than 1 (the log-omega gain alone is allowed: `test_cadence_gain_on_tangent`)
    for name, call in (("transfer(gains=)", lambda: style.transfer(a, [a, a], [a, a], method="content_mean",
                                                                    gains=jnp.ones(a.offset.size + 1).at[3].set(2.0))),
                       ("fit_transfer_gains", lambda: style.fit_transfer_gains([a, a], [a, a]))):
        with pytest.raises(UserError, match=re.escape(name) + ": tangent.*--representation euler"):
            call()
    with pytest.raises(UserError, match="frames"):
        fourier.FourierModel(a.offset, a.amplitude, a.phase, a.omega, "tangent", a.channel_names)
    with pytest.raises(UserError, match="frames"):
        fourier.FourierModel(a.offset, a.amplitude, a.phase, a.omega, "euler", (), a.frames)


# ---------------------------------------------------------------- style algebra on tangent models

RIGS3 = ("bandai", "zup", "rest_rotated")


@pytest.fixture(scope="module")
def pair(fits):
    """07_01 (a) and 07_12 (b: the same subject and skeleton, so that bone-aligned rewrites turn
    both alike) as tangent fits on the CMU rig and three rewrites (one `fit_batch` of four clips:
    the program the `fits` fixture compiled)."""
    m, rew, tangent, _ = fits
    mb = fourierjax.data.load("07_12")[:200]
    clips = [mb, convert(mb, "bandai"), to_y_up(convert(mb, "zup"), "z"), rest_rotated(mb)]
    b = dict(zip(("cmu", *RIGS3), _fit(clips, "tangent")))
    return m, rew, {k: tangent[k].model for k in b}, {k: f.model for k, f in b.items()}


def _quat_r(q):
    return Rotation.from_quat(np.asarray(q, np.float64).reshape(-1, 4)[:, [1, 2, 3, 0]])


def _series(model, theta):
    """NumPy Σ: offset + Σ_n A_n sin(nθ + φ_n) (the coefficients, before any frames)."""
    n = np.arange(1, model.amplitude.shape[-1] + 1)
    return np.asarray(model.offset) + np.sum(np.asarray(model.amplitude) * np.sin(n * theta + np.asarray(model.phase)),
                                             axis=-1)


@pytest.mark.parametrize("key", RIGS3)
def test_style_algebra_is_rig_invariant(pair, key):
    """#20 Done-when for the algebra: characteristic + superpose (b + 0.5 (a − b), polar and
    phasor) and a transition a → b of tangent fits give the CMU rig's root-relative positions on
    every rewrite. Measured 1e-5..5e-5 of leg length (polar per channel, before the per-joint
    form: 0.059 Bandai, 0.093 rest-rotated; Euler fits: 0.07..0.70)."""
    m, rew, ta, tb = pair
    t = jnp.arange(0, 200, 8) * m.frame_time_s
    leg = sum(np.linalg.norm(m.offsets[m.topology.names.index(n)]) for n in ("LeftLeg", "LeftFoot"))

    def positions(k, motion):
        a, b = ta[k], tb[k]
        ch = style.characteristic(a, b)
        xs = [fourier.synthesize(style.superpose(b, ch, 0.5, method=meth), t) for meth in ("polar", "phasor")]
        xs.append(style.transition(a, b, t, 0.3, 1.5))
        pelvis = infer_body_map(motion).pelvis
        return [np.asarray(root_relative_positions(motion.skeleton(), x, "tangent", pelvis), np.float64) for x in xs]

    r, names = rew[key]
    ref = positions("cmu", m)
    got = positions(key, r)
    cols = [r.topology.names.index(n) for n in names]
    for what, p0, p in zip(("superpose polar", "superpose phasor", "transition"), ref, got):
        err = float(np.linalg.norm(p[:, cols] - p0, axis=-1).max() / leg)
        assert err < 1e-3, (what, err)


def test_frame_algebra_matches_scipy(pair):
    """Δ = M_b⁻¹ M_a, M_b Δ^w and the blend's slerped frames against scipy's rotations."""
    _, _, ta, tb = pair
    a, b = ta["cmu"], tb["cmu"]
    ch = style.characteristic(a, b)
    delta = _quat_r(b.frames).inv() * _quat_r(a.frames)
    assert (_quat_r(ch.frames) * delta.inv()).magnitude().max() < 1e-5
    w = 0.37
    ref = _quat_r(b.frames) * Rotation.from_rotvec(w * delta.as_rotvec())
    assert (_quat_r(style.superpose(b, ch, w).frames) * ref.inv()).magnitude().max() < 1e-5
    # blend_time_domain: the tangent coordinates blended, about the slerped clip means
    s, theta = 0.3, 1.1
    x = np.asarray(style.blend_time_domain(a, b, s, theta), np.float64)
    d = (1 - s) * _series(a, theta) + s * _series(b, theta)
    cols = _tangent.model_columns(a)
    mean = _quat_r(a.frames) * Rotation.from_rotvec(s * (_quat_r(a.frames).inv() * _quat_r(b.frames)).as_rotvec())
    ref = mean * Rotation.from_rotvec(d[cols])
    assert (Rotation.from_rotvec(x[cols]) * ref.inv()).magnitude().max() < 1e-5
    root = np.setdiff1d(np.arange(len(x)), cols.ravel())
    np.testing.assert_allclose(x[root], d[root], rtol=1e-5, atol=1e-5)
    # ... and it equals the phasor interpolation at θ (the docstring's rule)
    np.testing.assert_allclose(
        x, fourier.synthesize_phase(style.interpolate(a, b, s, method="phasor"), jnp.asarray([theta]))[0], atol=1e-5)


def test_superpose_inverts_the_characteristic(pair):
    """superpose(b, characteristic(a, b), 1) = a and w = 0 gives b (both methods); vmap over w."""
    _, _, ta, tb = pair
    a, b = ta["cmu"], tb["cmu"]
    ch = style.characteristic(a, b)
    for method in ("polar", "phasor"):
        for w, ref in ((1.0, a), (0.0, b)):
            out = style.superpose(b, ch, w, method=method)
            np.testing.assert_allclose(fourier.synthesize_phase(out, THETA), fourier.synthesize_phase(ref, THETA),
                                       atol=2e-5)
            np.testing.assert_allclose(np.abs(np.sum(np.asarray(out.frames) * np.asarray(ref.frames), -1)), 1.0,
                                       atol=1e-6)
            assert float(out.omega) == pytest.approx(float(ref.omega), rel=1e-6)
    ws = jnp.asarray([-0.5, 0.25, 1.5])
    batch = jax.vmap(lambda w: style.superpose(b, ch, w))(ws)
    for i, w in enumerate(ws):
        one = style.superpose(b, ch, w)
        np.testing.assert_allclose(batch.frames[i], one.frames, atol=1e-6)
        np.testing.assert_allclose(batch.amplitude[i], one.amplitude, atol=1e-5)


def test_superpose_gradient_in_w_is_finite_at_zero(pair):
    """d/dw at w = 0 matches central differences, and stays finite at Δ = I (a − a)."""
    _, _, ta, tb = pair
    a, b = ta["cmu"], tb["cmu"]

    @eqx.filter_jit  # one program for every w and characteristic below
    def f(w, ch):
        return jax.value_and_grad(
            lambda w: jnp.sum(jnp.sin(fourier.synthesize_phase(style.superpose(b, ch, w), THETA))))(w)

    ch = style.characteristic(a, b)
    h = jnp.float32(3e-3)  # float32: measured g = −60.809, central difference −60.793
    _, g = f(jnp.float32(0.0), ch)
    fd = (f(h, ch)[0] - f(-h, ch)[0]) / (2 * h)
    assert float(g) == pytest.approx(float(fd), rel=2e-3)
    assert np.isfinite(float(f(jnp.float32(1.0), ch)[1]))
    same = style.characteristic(b, b)
    same = eqx.tree_at(lambda c: c.frames, same, jnp.zeros_like(same.frames).at[:, 0].set(1.0))
    assert np.isfinite(float(f(jnp.float32(0.0), same)[1]))


def test_per_joint_polar_is_unuma_on_one_channel_and_commutes_with_frames():
    """The per-joint polar form against closed forms: a joint moving on one channel follows
    Unuma's per-channel polar eq. 3; turning the joint's frame (z → Cᵀz) turns the result."""
    rng = np.random.default_rng(0)
    K, N, s = 5, 3, 0.3
    amp, ph = rng.uniform(0.1, 1.0, (2, K, N)), rng.uniform(-np.pi, np.pi, (2, K, N))
    z = np.zeros((2, K, 3, N, 2))
    z[:, :, 0, :, 0], z[:, :, 0, :, 1] = amp * np.cos(ph), amp * np.sin(ph)
    out = np.asarray(_tangent.polar_interpolate(jnp.asarray(z[0]), jnp.asarray(z[1]), s))
    d = np.angle(np.exp(1j * (ph[1] - ph[0])))
    want = ((1 - s) * amp[0] + s * amp[1]) * np.exp(1j * (ph[0] + s * d))
    np.testing.assert_allclose(out[:, 0, :, 0] + 1j * out[:, 0, :, 1], want, atol=1e-6)
    np.testing.assert_allclose(out[:, 1:], 0.0, atol=1e-7)
    # random joints, random frames
    z = rng.normal(size=(3, K, 3, N, 2))
    C = Rotation.random(K, random_state=1).as_matrix()
    turn = lambda v: np.einsum("kji,kjnc->kinc", C, v)  # noqa: E731
    np.testing.assert_allclose(_tangent.polar_interpolate(*map(jnp.asarray, (turn(z[0]), turn(z[1]))), s),
                               turn(np.asarray(_tangent.polar_interpolate(jnp.asarray(z[0]), jnp.asarray(z[1]), s))),
                               atol=1e-5)
    d0, al0 = _tangent.polar_difference(jnp.asarray(z[0]), jnp.asarray(z[1]))
    d1, al1 = _tangent.polar_difference(jnp.asarray(turn(z[0])), jnp.asarray(turn(z[1])))
    np.testing.assert_allclose(d1, d0, atol=1e-5)
    np.testing.assert_allclose(al1, turn(np.asarray(al0)), atol=1e-5)
    back = _tangent.polar_superpose(jnp.asarray(z[1]), d0[None], al0[None], jnp.ones(1))
    np.testing.assert_allclose(back, z[0], atol=1e-5)


def test_cli_characteristic_and_transition_take_tangent_models(pair, fits, tmp_path, monkeypatch):
    from fourierjax import _compile_cache
    from fourierjax.cli import main
    from fourierjax.io.bvh import read_bvh
    from fourierjax.model_io import load_characteristic

    m, _, ta, tb = pair
    a, b = ta["cmu"], tb["cmu"]
    save_model(tmp_path / "a.npz", a, motion=m)
    save_model(tmp_path / "b.npz", b, motion=m)
    monkeypatch.setattr(_compile_cache, "enable_compile_cache", lambda: False)
    monkeypatch.chdir(tmp_path)
    assert main(["characteristic", "a.npz", "b.npz", "--out", "c.npz"]) == 0
    ch, _ = load_characteristic(tmp_path / "c.npz")
    assert ch.representation == "tangent" and ch.frames.shape == a.frames.shape
    back = style.superpose(b, jax.tree.map(jnp.asarray, ch), 1.0)
    np.testing.assert_allclose(fourier.synthesize_phase(back, THETA), fourier.synthesize_phase(a, THETA), atol=1e-4)
    assert main(["transition", "a.npz", "b.npz", "--seconds", "1", "--start", "0.2", "--duration", "0.5",
                 "--out", "t.bvh", "--no-root-motion"]) == 0
    assert read_bvh(tmp_path / "t.bvh").num_frames == 120


def test_style_vectors_of_tangent_models(pair):
    """Style vectors carry the frames as rotation vectors about a reference: they invert, their
    distances are the same on the CMU and Bandai rigs, and `fit_style_weights` recovers the weight
    of a phasor superposition (exact: linear in w)."""
    _, _, ta, tb = pair
    dists = {}
    for key in ("cmu", "bandai"):
        a, b = ta[key], tb[key]
        rows = style.style_matrix([b, a])
        k = a.frames.shape[0]
        assert rows.shape == (2, a.offset.size * 7 + 3 * k + 1)
        np.testing.assert_allclose(rows[0, -1 - 3 * k:-1], 0.0, atol=1e-6)  # b about itself
        np.testing.assert_allclose(rows[1], style.style_vector(a, reference=b.frames), atol=1e-6)
        back = style.model_from_style_vector(rows[1], b)
        np.testing.assert_allclose(fourier.synthesize_phase(back, THETA), fourier.synthesize_phase(a, THETA),
                                   atol=1e-4)
        dists[key] = float(jnp.linalg.norm(rows[1] - rows[0]))
    assert dists["bandai"] == pytest.approx(dists["cmu"], rel=1e-4)
    a, b = ta["cmu"], tb["cmu"]
    ch = style.characteristic(a, b)
    target = style.superpose(b, ch, 0.37, method="phasor")
    assert float(style.fit_style_weights(b, ch, target)[0]) == pytest.approx(0.37, abs=1e-4)
    with pytest.raises(UserError, match="reference"):
        style.style_vector(a, reference=jnp.zeros((3, 4)))


def test_content_mean_and_transfer_of_tangent_models(pair):
    """The content mean of two tangent models is their phasor interpolation at 1/2 (phasors
    averaged, frames slerped halfway, ω geometric); eq8 transfer of a's style onto b gives a."""
    _, _, ta, tb = pair
    a, b = ta["cmu"], tb["cmu"]
    mean = style.content_mean([a, b])
    half = style.interpolate(a, b, 0.5, method="phasor")
    np.testing.assert_allclose(fourier.synthesize_phase(mean, THETA), fourier.synthesize_phase(half, THETA), atol=1e-5)
    assert float(mean.omega) == pytest.approx(float(half.omega), rel=1e-6)
    out = style.transfer(a, b, b)
    np.testing.assert_allclose(fourier.synthesize_phase(out, THETA), fourier.synthesize_phase(a, THETA), atol=1e-4)


def test_cadence_gain_on_tangent(pair, fits):
    """The log-omega gain (the only rig-invariant one) on tangent models: `fit_transfer_gains(
    cadence_only=True)` is the shrunk least-squares slope of the targets' log omega on the sources'
    (closed form in NumPy; Euler models with the same omegas give the same gain), and the gained
    transfer is the plain one with omega `w_t (w_s / w_ms)^(g w)`. A channel gain is refused,
    also traced."""
    _, _, ta, tb = pair
    a, b = ta["cmu"], tb["cmu"]
    e = fits[3]["cmu"].model
    scale_s, scale_t = np.array([1.0, 0.8, 1.15, 1.3]), np.array([1.0, 0.9, 1.05, 1.2])

    def with_omega(m, f):
        return eqx.tree_at(lambda x: x.omega, m, m.omega * f)

    src = [with_omega(a if k % 2 else b, f) for k, f in enumerate(scale_s)]
    tgt = [with_omega(b if k % 2 else a, f) for k, f in enumerate(scale_t)]
    ridge = 0.25
    lx = np.log([float(m.omega) for m in src])
    ly = np.log([float(m.omega) for m in tgt])
    dx, dy = lx - lx.mean(), ly - ly.mean()
    want = np.clip((dx @ dy + ridge * dx @ dx) / ((1 + ridge) * dx @ dx), 0.0, 2.0)
    g = np.asarray(style.fit_transfer_gains(src, tgt, ridge=ridge, cadence_only=True))
    assert g.shape == (a.offset.size + 1,) and np.all(g[:-1] == 1.0)
    assert abs(g[-1] - want) < 1e-5 and abs(want - 1) > 0.1, (g[-1], want)
    g_euler = np.asarray(style.fit_transfer_gains([with_omega(e, float(m.omega / e.omega)) for m in src],
                                                  [with_omega(e, float(m.omega / e.omega)) for m in tgt],
                                                  ridge=ridge, cadence_only=True))
    assert abs(g_euler[-1] - want) < 1e-5, (g_euler[-1], want)

    source, refs_s, refs_t, w = src[0], src[1:], tgt[1:], 0.7
    plain = style.transfer(source, refs_s, refs_t, method="content_mean", weight=w)
    gained = style.transfer(source, refs_s, refs_t, method="content_mean", weight=w, gains=jnp.asarray(g))
    ms, mt = style.content_mean(refs_s), style.content_mean(refs_t)
    want_omega = float(mt.omega) * (float(source.omega) / float(ms.omega)) ** (g[-1] * w)
    assert abs(float(gained.omega) / want_omega - 1) < 1e-5
    for field in ("offset", "amplitude", "phase", "frames"):
        np.testing.assert_allclose(getattr(gained, field), getattr(plain, field), atol=1e-6)
    bad = jnp.asarray(g).at[0].set(1.5)
    with pytest.raises(RuntimeError, match=r"transfer\(gains=\): tangent models take the log-omega gain only"):
        jax.block_until_ready(jax.jit(lambda gg: style.transfer(source, refs_s, refs_t, method="content_mean",
                                                                weight=w, gains=gg).omega)(bad))


# ------------------------------------------------ grounded synthesis of tangent fits on every rig


@pytest.fixture(scope="module")
def gait_fits(fits):
    """`fit_motions` (body map, steady segment, heel-strike alignment, root channels) of 07_01
    and three rewrites, tangent, in one batch."""
    m, rew, _, _ = fits
    keys = ("cmu", *RIGS3)
    res = fmotion.fit_motions([m] + [rew[k][0] for k in RIGS3], 3, "tangent", throw=True)
    return m, rew, dict(zip(keys, res))


@pytest.mark.parametrize("key", RIGS3)
def test_grounded_synthesis_is_rig_invariant(gait_fits, key):
    """#20 Done-when on the rewrites (Bandai names, ZXY, bones along X; Z-up; rotated rest
    frames), through the whole path a user takes: heel strikes and aligned phases equal, and
    `synthesize_gait` (hip rule, root motion from the stance feet, foot lock) gives the CMU clip's
    root path, root advance and foot skating within 1%."""
    m, rew, f = gait_fits
    ref, fit = f["cmu"], f[key]
    assert fit.alignment == ref.alignment == "left_heel_strike"
    assert (fit.left_heel_strikes, fit.right_heel_strikes) == (ref.left_heel_strikes, ref.right_heel_strikes)
    assert abs(np.angle(np.exp(1j * (fit.phase_shift - ref.phase_shift)))) < 0.01 * 2 * np.pi
    dt, T = m.frame_time_s, 240
    a = gait.synthesize_gait(ref.model, m.skeleton(), T, dt)
    b = gait.synthesize_gait(fit.model, rew[key][0].skeleton(), T, dt)
    leg = sum(np.linalg.norm(m.offsets[m.topology.names.index(n)]) for n in ("LeftLeg", "LeftFoot"))
    pa, pb = np.asarray(a.root_position, np.float64), np.asarray(b.root_position, np.float64)
    assert np.abs(pb - pa).max() < 0.01 * leg, np.abs(pb - pa).max() / leg
    advance_a, advance_b = (np.linalg.norm((p[-1] - p[0])[[0, 2]]) for p in (pa, pb))
    assert advance_b == pytest.approx(advance_a, rel=0.01)
    skate = [float(gait.foot_skating(r.foot_positions, dt, r.floor + r.clearance[None]).mean_speed) for r in (a, b)]
    assert skate[1] == pytest.approx(skate[0], rel=0.01), skate


def test_clip_means_are_the_dominant_eigenvectors_numpy_finds():
    """The weighted chordal mean against `numpy.linalg.eigh` of ``sum_t w q q^T`` (an independent
    reference for the 4x4 scatter and its power steps), sign-free, and equivariant."""
    rng = np.random.default_rng(7)
    T, K = 90, 5
    centre = Rotation.random(K, random_state=1)
    spread = [1.2, 0.5, 0.2]  # radians, anisotropic: the plain sign-aligned average is not the mean
    q = np.stack([(Rotation.from_rotvec(rng.standard_normal((K, 3)) * spread) * centre).as_quat(scalar_first=True)
                  for _ in range(T)])
    q *= np.where(rng.random((T, K, 1)) < 0.5, -1.0, 1.0)  # either sign of each quaternion
    w = rng.random((T, K))
    w[rng.random((T, K)) < 0.2] = 0.0
    got = np.asarray(_tangent.clip_means(jnp.asarray(q, jnp.float32), jnp.asarray(w, jnp.float32)))
    for k in range(K):
        vals, vecs = np.linalg.eigh(np.einsum("t,ti,tj->ij", w[:, k], q[:, k], q[:, k]))
        assert vals[-1] > 1.5 * vals[-2]  # a clear dominant direction: power steps converge
        assert abs(got[k] @ vecs[:, -1]) == pytest.approx(1.0, abs=2e-5)
    # Equivariant: rotating every sample rotates the mean.
    a = Rotation.random(random_state=3)
    qa = np.stack([(a * Rotation.from_quat(q[t], scalar_first=True)).as_quat(scalar_first=True) for t in range(T)])
    rot = np.asarray(_tangent.clip_means(jnp.asarray(qa, jnp.float32), jnp.asarray(w, jnp.float32)))
    want = (a * Rotation.from_quat(got, scalar_first=True)).as_quat(scalar_first=True)
    np.testing.assert_allclose(np.abs(np.sum(rot * want, axis=-1)), 1.0, atol=2e-5)
