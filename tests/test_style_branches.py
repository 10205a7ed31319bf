"""Style algebra across clips on different angle branches, the `omega_mode=` rename, and value
checks that hold under jit."""

import io

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

from fourierjax import rotations, style
from fourierjax.errors import UserError
from fourierjax.fourier import FourierModel, synthesize_phase

DEG = np.pi / 180
ROOT = ("root.vx", "root.vz", "root.y")


def euler_pair(thigh_a_deg=179.0, thigh_b_deg=-179.0):
    """Two models whose thigh offsets sit near ±180° (as Bandai-Namco thighs do), root height 0 and 4."""
    names = (*ROOT, "LeftUpLeg.Zrotation", "LeftUpLeg.Xrotation")
    amp = jnp.asarray([[0.1, 0.0]] * 5)
    phase = jnp.zeros((5, 2))
    a = FourierModel(jnp.asarray([0.0, 1.0, 0.0, thigh_a_deg * DEG, 0.3]), amp, phase, jnp.asarray(6.0), "euler", names)
    b = FourierModel(jnp.asarray([0.0, 1.5, 4.0, thigh_b_deg * DEG, 0.2]), amp, phase, jnp.asarray(7.0), "euler", names)
    return a, b


THIGH = 3


def _off_pi_deg(x):
    """Distance of angles (rad) from ±180°, in degrees."""
    return np.degrees(np.abs(np.asarray(style.wrap_angle(np.asarray(x) - np.pi))))


@pytest.mark.parametrize("method", ["polar", "phasor"])
def test_euler_interpolation_across_plus_minus_180_stays_at_180(x64, method):
    a, b = euler_pair()
    mid = style.interpolate(a, b, 0.5, method=method)
    assert _off_pi_deg(mid.offset[THIGH]) < 1e-9  # ±180°, not 0°
    assert float(mid.offset[2]) == pytest.approx(2.0)  # root.y is no angle: plain average of 0 and 4
    for s in np.linspace(0.0, 1.0, 11):
        # a + s·wrap(b − a): from 179° through 180° to 181° (= −179°)
        got = float(style.interpolate(a, b, s, method=method).offset[THIGH])
        assert got == pytest.approx((179.0 + 2.0 * s) * DEG, abs=1e-12)
    # s = 1 is b's rotation on a's branch
    end = style.interpolate(a, b, 1.0, method=method)
    assert float(style.wrap_angle(end.offset[THIGH] - b.offset[THIGH])) == pytest.approx(0.0, abs=1e-12)


def test_euler_characteristic_and_superposition_across_plus_minus_180(x64):
    a, b = euler_pair()
    char = style.characteristic(a, b)
    assert float(char.offset[THIGH]) == pytest.approx(-2.0 * DEG, abs=1e-12)  # not +358°
    assert float(char.offset[2]) == pytest.approx(-4.0)  # root.y subtracts plainly
    assert float(style.characteristic(b, a).offset[THIGH]) == pytest.approx(2.0 * DEG, abs=1e-12)
    for method in ("polar", "phasor"):
        half = style.superpose(b, char, 0.5, method=method)
        moved = np.degrees(float(half.offset[THIGH] - b.offset[THIGH]))
        assert moved == pytest.approx(-1.0, abs=1e-9)  # 1°, not 179°
        assert _off_pi_deg(half.offset[THIGH]) < 1e-9
        # a characteristic written before the rule (offset +358°) superposes the same way
        old = eqx.tree_at(lambda c: c.offset, char, char.offset.at[THIGH].set(358.0 * DEG))
        again = style.superpose(b, old, 0.5, method=method)
        assert float(again.offset[THIGH]) == pytest.approx(float(half.offset[THIGH]), abs=1e-12)
    # style weights see the same 2° direction
    target = style.superpose(b, char, 0.7, method="phasor")
    assert float(style.fit_style_weights(b, char, target)[0]) == pytest.approx(0.7, abs=1e-9)


def test_euler_transition_across_plus_minus_180_turns_by_2_degrees(x64):
    a, b = euler_pair()
    t = jnp.linspace(0.0, 3.0, 301)
    x = np.asarray(style.transition(a, b, t, 1.0, 1.0, method="polar"))
    thigh = x[:, THIGH]
    # the thigh never swings through 0°: every frame is within 2° + its 0.1 rad oscillation of 180°
    assert _off_pi_deg(thigh).max() < 1.0 + 0.1 / DEG + 1e-6
    assert np.degrees(np.abs(np.diff(thigh))).max() < 5.0


# ------------------------------------------------------------------------- exponential map


def _angle_between(q1, q2):
    """Rotation angle (rad) between unit quaternions."""
    q1, q2 = np.asarray(q1), np.asarray(q2)
    chord = np.minimum(np.linalg.norm(q1 - q2, axis=-1), np.linalg.norm(q1 + q2, axis=-1))
    return 4 * np.arcsin(np.clip(chord / 2, 0.0, 1.0))  # |q1 − q2| = 2 sin(angle / 4), exact near 0


AXIS = np.asarray([1.0, 2.0, -0.5]) / np.linalg.norm([1.0, 2.0, -0.5])
EXPMAP_NAMES = (*ROOT, "LeftUpLeg.expmap0", "LeftUpLeg.expmap1", "LeftUpLeg.expmap2")
LEG = slice(3, 6)


def expmap_pair(amplitude_b=0.0):
    """a: π − 0.05 about AXIS; b: π + 0.05 about AXIS, stored on the antipodal branch
    −AXIS·(π − 0.05) (|v| near π, as a fit of a leg rotated by about 180° gives)."""
    n = 1
    amp_a = jnp.zeros((6, n))
    # b wobbles about an axis perpendicular to its rotation vector
    perp = np.cross(AXIS, [0.0, 0.0, 1.0])
    perp /= np.linalg.norm(perp)
    amp_b = jnp.zeros((6, n)).at[3:6, 0].set(jnp.asarray(np.abs(perp) * amplitude_b))
    phase_b = jnp.zeros((6, n)).at[3:6, 0].set(jnp.asarray(np.where(perp < 0, np.pi, 0.0)))
    off_a = jnp.concatenate([jnp.asarray([0.0, 1.0, 0.9]), jnp.asarray(AXIS * (np.pi - 0.05))])
    off_b = jnp.concatenate([jnp.asarray([0.0, 1.2, 0.8]), jnp.asarray(-AXIS * (np.pi - 0.05))])
    a = FourierModel(off_a, amp_a, jnp.zeros((6, n)), jnp.asarray(6.0), "expmap", EXPMAP_NAMES)
    b = FourierModel(off_b, amp_b, phase_b, jnp.asarray(7.0), "expmap", EXPMAP_NAMES)
    return a, b


def _quat(v):
    return rotations.quat_from_expmap(jnp.asarray(v))


def test_expmap_interpolation_on_antipodal_branches_goes_the_short_way(x64):
    a, b = expmap_pair()
    halfway = _quat(AXIS * np.pi)  # π about AXIS: between π − 0.05 and π + 0.05
    for method in ("polar", "phasor"):
        mid = style.interpolate(a, b, 0.5, method=method)
        assert _angle_between(_quat(mid.offset[LEG]), halfway) < 1e-9
        # the raw average of the vectors is the identity, π away
        assert _angle_between(_quat((a.offset[LEG] + b.offset[LEG]) / 2), halfway) > 3.0
        end = style.interpolate(a, b, 1.0, method=method)
        assert _angle_between(_quat(end.offset[LEG]), _quat(b.offset[LEG])) < 1e-9
        for s in np.linspace(0.0, 1.0, 6):
            m = style.interpolate(a, b, s, method=method)
            expected = _quat(AXIS * (np.pi - 0.05 + 0.1 * s))
            assert _angle_between(_quat(m.offset[LEG]), expected) < 1e-9


def test_expmap_characteristic_and_superposition_on_antipodal_branches(x64):
    a, b = expmap_pair()
    char = style.characteristic(a, b)
    # 0.1 rad about AXIS, not a 2π-long vector
    np.testing.assert_allclose(char.offset[LEG], -0.1 * AXIS, atol=1e-12)
    for method in ("polar", "phasor"):
        half = style.superpose(b, char, 0.5, method=method)
        q = _quat(half.offset[LEG])
        assert _angle_between(q, _quat(b.offset[LEG])) == pytest.approx(0.05, abs=1e-9)  # moved 0.05 rad
        assert _angle_between(q, _quat(AXIS * np.pi)) < 1e-9


def test_expmap_branch_change_keeps_the_motion_of_b(x64):
    # b's harmonics are mapped with its offset, so s = 1 plays b's rotations (to first order
    # in the amplitude), not a mirrored wobble.
    amp = 0.02
    a, b = expmap_pair(amplitude_b=amp)
    theta = np.linspace(0.0, 2 * np.pi, 17)
    qb = _quat(synthesize_phase(b, theta)[:, LEG])
    for method in ("polar", "phasor"):
        end = style.interpolate(a, b, 1.0, method=method)
        assert np.abs(np.asarray(end.offset[LEG]) - np.asarray(b.offset[LEG])).max() > 1.0  # moved branch
        q_end = _quat(synthesize_phase(end, theta)[:, LEG])
        assert _angle_between(q_end, qb).max() < 0.1 * amp
    # without the harmonics' map (offset moved alone) the wobble would be mirrored: 2·amp off
    moved_offset = eqx.tree_at(lambda m: m.offset, b, style.interpolate(a, b, 1.0).offset)
    q_naive = _quat(synthesize_phase(moved_offset, theta)[:, LEG])
    assert _angle_between(q_naive, qb).max() > amp


def test_expmap_branch_is_nan_free_at_zero_rotation(x64):
    a, b = expmap_pair()
    b0 = eqx.tree_at(lambda m: m.offset, b, b.offset.at[LEG].set(0.0))
    m = style.interpolate(a, b0, 0.5)
    np.testing.assert_allclose(m.offset[LEG], a.offset[LEG] / 2, atol=1e-12)  # k = 0 at |v| = 0

    def loss(offset):
        bb = eqx.tree_at(lambda mm: mm.offset, b, offset)
        return jnp.sum(style.interpolate(a, bb, 0.3).offset ** 2) + jnp.sum(style.characteristic(a, bb).offset)

    g = jax.grad(loss)(b0.offset)
    assert np.all(np.isfinite(np.asarray(g)))
    g = jax.grad(loss)(b.offset)
    assert np.all(np.isfinite(np.asarray(g)))


# -------------------------------------------------------------------------- omega_mode rename


def _models():
    a, b = euler_pair()
    return a, b


def test_omega_mode_is_the_new_name_and_omega_a_deprecated_alias(x64):
    a, b = _models()
    t = jnp.linspace(0.0, 2.0, 9)
    new = style.interpolate(a, b, 0.25, omega_mode="linear")
    assert float(new.omega) == pytest.approx(6.25)
    with pytest.warns(DeprecationWarning, match=r"^interpolate: the keyword `omega=` is deprecated, use `omega_mode=`"):
        old = style.interpolate(a, b, 0.25, omega="linear")
    assert float(old.omega) == float(new.omega)
    with pytest.warns(DeprecationWarning, match=r"^interpolate_omega: .*omega_mode"):
        assert float(style.interpolate_omega(6.0, 7.0, 0.5, omega="linear")) == pytest.approx(6.5)
    assert float(style.interpolate_omega(6.0, 7.0, 0.5, "linear")) == pytest.approx(6.5)  # positional still works
    with pytest.warns(DeprecationWarning, match=r"^transition: .*omega_mode"):
        x_old = style.transition(a, b, t, 0.5, 1.0, omega="linear")
    np.testing.assert_array_equal(x_old, style.transition(a, b, t, 0.5, 1.0, omega_mode="linear"))
    with pytest.warns(DeprecationWarning, match=r"^transition_schedule: .*omega_mode"):
        s_old = style.transition_schedule(6.0, 7.0, t, 0.5, 1.0, omega="linear")
    s_new = style.transition_schedule(6.0, 7.0, t, 0.5, 1.0, omega_mode="linear")
    np.testing.assert_array_equal(s_old[1], s_new[1])
    assert not np.allclose(s_new[1], style.transition_schedule(6.0, 7.0, t, 0.5, 1.0)[1])  # the mode matters
    with pytest.raises(UserError, match=r"^interpolate: give `omega_mode` only"):
        with pytest.warns(DeprecationWarning):
            style.interpolate(a, b, 0.5, omega_mode="linear", omega="geometric")
    with pytest.warns(DeprecationWarning, match="OmegaMode"):
        assert style.OmegaInterp is style.OmegaMode
    with pytest.raises(UserError, match=r"^interpolate: `omega_mode`='cubic'"):
        style.interpolate(a, b, 0.5, omega_mode="cubic")


# -------------------------------------------------------------- value checks under jit and vmap


def _refused(fn, *args, match):
    with pytest.raises(RuntimeError, match=match):
        jax.block_until_ready(fn(*args))


def test_traced_bad_values_are_refused():
    a, b = _models()
    t = jnp.linspace(0.0, 2.0, 5)
    char = style.characteristic(a, b)
    _refused(jax.jit(lambda s: style.interpolate(a, b, s).offset), jnp.nan, match=r"interpolate: `s` must be finite")
    _refused(
        jax.jit(lambda w: style.interpolate(a, eqx.tree_at(lambda m: m.omega, b, w), 0.5).offset),
        0.0,
        match=r"interpolate: `b.omega` must be finite and > 0",
    )
    _refused(
        jax.jit(lambda s: style.interpolate(a, b, s, omega_mode="linear").omega),
        -20.0,
        match=r"interpolate: linear ω interpolation is not > 0",
    )
    _refused(jax.jit(lambda w: style.interpolate_omega(w, 7.0, 0.5)), -1.0, match=r"interpolate_omega: `omega_a`")
    _refused(
        jax.jit(lambda w: style.characteristic(eqx.tree_at(lambda m: m.omega, a, w), b).log_omega),
        jnp.nan,
        match=r"characteristic: `a.omega`",
    )
    _refused(
        jax.jit(lambda w: style.superpose(a, char, w).offset), jnp.inf, match=r"superpose: `weights` must be finite"
    )
    _refused(
        jax.jit(lambda lo: style.superpose(a, eqx.tree_at(lambda c: c.log_omega, char, lo), 1.0).omega),
        jnp.inf,
        match=r"superpose: `characteristics` log_omega must be finite",
    )
    _refused(
        jax.jit(lambda d: style.transition(a, b, t, 0.5, d)),
        0.0,
        match=r"transition: `duration_s` must be finite and > 0",
    )
    _refused(
        jax.jit(lambda st: style.transition(a, b, t, st, 1.0)), jnp.nan, match=r"transition: `start_s` must be finite"
    )
    _refused(
        jax.jit(lambda d: style.transition_schedule(6.0, 7.0, t, 0.5, d)[1]),
        -1.0,
        match=r"transition_schedule: `duration_s`",
    )
    _refused(
        jax.jit(lambda r: style.fit_style_weights(a, char, b, ridge=r)),
        -1.0,
        match=r"fit_style_weights: `ridge` must be >= 0",
    )
    _refused(
        jax.jit(lambda x: style.add_noise(a, jax.random.key(0), x).amplitude),
        jnp.nan,
        match=r"add_noise: `amplitude` must be finite",
    )
    _refused(jax.jit(lambda p: style.blend_time_domain(a, b, 0.5, p)), jnp.inf, match=r"blend_time_domain: `phase`")
    # vmap over stacked models: one bad ω among them is refused
    bad = eqx.tree_at(lambda m: m.omega, b, jnp.asarray(0.0))
    _refused(jax.vmap(style.style_vector), style.stack([a, bad]), match=r"style_vector: `model.omega`")
    # and good traced values pass, with the same results as concrete ones
    np.testing.assert_allclose(
        jax.jit(lambda s: style.interpolate(a, b, s).offset)(0.3), style.interpolate(a, b, 0.3).offset, rtol=1e-6
    )
    np.testing.assert_allclose(
        jax.jit(lambda d: style.transition(a, b, t, 0.5, d))(0.8), style.transition(a, b, t, 0.5, 0.8), rtol=1e-6
    )


def test_the_public_face_re_exports_the_shared_helpers():
    from fourierjax import _math
    from fourierjax._style import characteristics

    assert style.wrap_angle is _math.wrap_angle
    assert style.Characteristic is characteristics.Characteristic
    assert sorted(style.__all__) == sorted(set(style.__all__))
    assert all(hasattr(style, name) for name in style.__all__)


BANDAI = __import__("pathlib").Path(__file__).resolve().parents[1] / ".." / "shared" / "data" / "mocap" / "bandai1"


def test_bandai_thighs_near_180_combine_on_one_branch():
    """Bandai-Namco walks (CC BY-NC, read in place): the left thigh's Z rotation sits at +177.6°
    in the proud walk and −181.5° in the normal one."""
    path = BANDAI / "data"
    if not path.is_dir():
        pytest.skip(f"Bandai-Namco data not found at {BANDAI} (see its README)")
    from fourierjax import fourier
    from fourierjax import motion as fmotion
    from fourierjax.io.bvh import read_bvh

    models = {}
    for name in ("proud", "normal"):
        motion = read_bvh(path / f"dataset-1_walk_{name}_001.bvh")
        x, names = fmotion.features_from_motion(motion, "euler")
        models[name] = fourier.fit(jnp.asarray(x, jnp.float32), motion.frame_time_s, 3, channel_names=names).model
    a, b = models["proud"], models["normal"]
    i = names.index("UpperLeg_L.Zrotation")
    raw = np.degrees(float(a.offset[i] - b.offset[i]))
    assert abs(raw) > 300  # the two fits sit on branches a turn apart
    char = np.degrees(float(style.characteristic(a, b).offset[i]))
    assert abs(char) < 10 and char == pytest.approx(raw - 360 * round(raw / 360), abs=1e-3)
    mid = np.degrees(float(style.interpolate(a, b, 0.5).offset[i]))
    assert abs(mid - np.degrees(float(a.offset[i]))) < 5  # next to both thighs, not swung round to ~0°


# ------------------------------------------- superposition onto a base on another branch


def _wobbling_pair(amp):
    """a: π − 0.1 about AXIS, b: π + 0.08 about an axis 0.15 rad from AXIS, stored on the
    other branch (|r| = π − 0.08 about minus that axis); each wobbles by `amp` in its own
    direction perpendicular to AXIS, with a second harmonic."""
    perp1 = np.cross(AXIS, [0.0, 0.0, 1.0])
    perp1 /= np.linalg.norm(perp1)
    perp2 = np.cross(AXIS, perp1)
    axis_b = np.cos(0.15) * AXIS + np.sin(0.15) * perp2

    def model(offset_leg, wobble, phase0, omega, n):
        amp_ = np.zeros((6, n))
        ph = np.zeros((6, n))
        for h in range(n):  # a signed amplitude along `wobble` as per-channel (|A|, φ)
            amp_[3:6, h] = np.abs(wobble) * amp / (h + 1)
            ph[3:6, h] = phase0 * (h + 1) + np.where(wobble < 0, np.pi, 0.0)
        off = np.concatenate([[0.0, 1.0, 0.9], offset_leg])
        return FourierModel(jnp.asarray(off), jnp.asarray(amp_), jnp.asarray(ph), jnp.asarray(omega),
                            "expmap", EXPMAP_NAMES)

    a = model(AXIS * (np.pi - 0.1), perp1 + 0.5 * perp2, 0.3, 6.0, 2)
    b = model(-axis_b * (np.pi - 0.08), perp2, -0.7, 7.0, 2)
    return a, b


def _twin(m):
    """The same motion with its leg offset on the antipodal branch (harmonics mapped with it)."""
    far = eqx.tree_at(lambda x: x.offset, m, m.offset.at[LEG].set(-m.offset[LEG]))
    return style.interpolate(far, m, 1.0)


def _scipy_rotations(model, theta):
    from scipy.spatial.transform import Rotation

    return Rotation.from_rotvec(np.array(synthesize_phase(model, theta))[:, LEG])


def _max_angle(r1, r2):
    return float(np.max((r1.inv() * r2).magnitude()))


@pytest.mark.parametrize("method", ["polar", "phasor"])
def test_superposing_a_characteristic_reproduces_a_whatever_branch_each_fit_landed_on(x64, method):
    # issue 22: the characteristic was taken on a's branch and added to b on b's, so near
    # |r| = π the offset moved by 2π·b̂ and the tangential swing was added with the wrong sign.
    amp = 0.02
    a, b = _wobbling_pair(amp)
    theta = np.linspace(0.0, 2 * np.pi, 33)
    ra = _scipy_rotations(a, theta)
    a_twin, b_twin = _twin(a), _twin(b)
    assert np.abs(np.asarray(a_twin.offset - a.offset)).max() > 3.0
    assert np.abs(np.asarray(b_twin.offset - b.offset)).max() > 3.0
    for aa in (a, a_twin):
        for bb in (b, b_twin):
            char = style.characteristic(aa, bb)
            for base in (b, b_twin):
                out = style.superpose(base, [char], [1.0], method=method)
                # a's rotations (to first order in the swings, as every branch change)
                assert _max_angle(_scipy_rotations(out, theta), ra) < 0.1 * amp
                # w = 0 is the base, on its own branch
                zero = style.superpose(base, [char], [0.0], method=method)
                np.testing.assert_allclose(zero.offset, base.offset, atol=1e-12)
                rb = _scipy_rotations(base, theta)
                assert _max_angle(_scipy_rotations(zero, theta), rb) < 1e-12


def test_superpose_gradients_across_branches_are_finite(x64):
    a, b = _wobbling_pair(0.02)
    b_twin = _twin(b)
    char = style.characteristic(a, b)
    theta = jnp.linspace(0.0, 2 * np.pi, 9)

    def loss(w, offset):
        base = eqx.tree_at(lambda m: m.offset, b_twin, offset)
        return jnp.sum(synthesize_phase(style.superpose(base, [char], w), theta) ** 2)

    gw, goff = jax.grad(loss, argnums=(0, 1))(jnp.asarray([0.4]), b_twin.offset)
    assert np.all(np.isfinite(np.asarray(gw))) and np.all(np.isfinite(np.asarray(goff)))
    assert float(jnp.abs(gw[0])) > 0


@pytest.mark.parametrize("method", ["polar", "phasor"])
def test_a_characteristic_file_keeps_the_branch_it_was_taken_on(x64, tmp_path, method):
    # A file without `reference` added on the base's own branch: read back, the characteristic
    # of a against b's twin put the swing 0.58 rad off a's rotations (see the test above).
    from fourierjax.io import model_io

    amp = 0.02
    a, b = _wobbling_pair(amp)
    b_twin = _twin(b)
    char = style.characteristic(a, b_twin)
    assert char.reference is not None
    model_io.save_characteristic(tmp_path / "c.npz", char, a="A", b="B twin")
    back, _ = model_io.load_characteristic(tmp_path / "c.npz")
    np.testing.assert_array_equal(back.reference, np.asarray(char.reference, np.float64))
    theta = np.linspace(0.0, 2 * np.pi, 33)
    ra = _scipy_rotations(a, theta)
    for base in (b, b_twin):
        out = style.superpose(base, [back], [1.0], method=method)
        assert _max_angle(_scipy_rotations(out, theta), ra) < 0.1 * amp
    # A reference of the wrong length is a clear error, not a wrong answer.
    import zipfile

    bad = tmp_path / "bad.npz"
    with zipfile.ZipFile(tmp_path / "c.npz") as src, zipfile.ZipFile(bad, "w") as dst:
        for info in src.infolist():
            data = src.read(info)
            if info.filename == "reference.npy":
                buf = io.BytesIO()
                np.save(buf, np.zeros(2))
                data = buf.getvalue()
            dst.writestr(info, data)
    with pytest.raises(model_io.ModelFileError, match="reference"):
        model_io.load_characteristic(bad)
