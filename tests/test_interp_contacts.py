"""The contact intervals of a blend of two gaits come from its sources' (`gait.blend_contact_intervals`,
`fourierjax interpolate`): issue 20, the tangent default of the command line."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from fourierjax import data, gait, model_io
from fourierjax import motion as fmotion
from fourierjax.errors import UserError
from fourierjax.fourier import FourierModel

D = np.pi / 180.0
A = np.array([[0.0, 200.0], [180.0, 20.0]]) * D  # (left, right) x (start, end)
B = np.array([[350.0, 250.0], [190.0, 80.0]]) * D


def _midpoint(x, y):
    """The shorter arc's midpoint, independently: the direction of the sum of the unit phasors."""
    return np.mod(np.angle(np.exp(1j * x) + np.exp(1j * y)), 2 * np.pi)


def test_blend_closed_form():
    got = np.asarray(gait.blend_contact_intervals(A, B, 0.5))
    # Left: start 0 -> 350 by the shorter arc (-10 deg) halfway is 355; durations 200 and 260
    # average 230, so it ends at 355 + 230 = 225 (mod 360). Right: 185, durations 200 and 250: 50.
    np.testing.assert_allclose(got / D, [[355.0, 225.0], [185.0, 50.0]], atol=1e-4)
    # Halfway, the start and the end are the shorter arc's midpoints (ends closer than 180 deg).
    np.testing.assert_allclose(got, _midpoint(A, B), atol=1e-6)
    # The ends of the blend are the sources'.
    np.testing.assert_allclose(np.asarray(gait.blend_contact_intervals(A, B, 0.0)), A, atol=1e-6)
    np.testing.assert_allclose(np.asarray(gait.blend_contact_intervals(A, B, 1.0)), B, atol=1e-6)


def test_blend_extrapolates_without_flipping_and_vmaps():
    # s = 4: the left duration 200 + 4 * 60 = 440 deg is clipped short of a whole cycle, never
    # wrapped to 80 deg (the complement); the start moves on by the shorter arc, 0 - 40 = 320.
    far = np.asarray(gait.blend_contact_intervals(A, B, 4.0))
    assert np.isclose(far[0, 0] / D, 320.0, atol=1e-3)
    assert 359.0 < np.mod(far[0, 1] - far[0, 0], 2 * np.pi) / D < 360.0
    s = jnp.linspace(0.0, 1.0, 5)
    many = jax.jit(jax.vmap(lambda t: gait.blend_contact_intervals(A, B, t)))(s)
    for k, t in enumerate(np.asarray(s)):
        np.testing.assert_allclose(np.asarray(many[k]), np.asarray(gait.blend_contact_intervals(A, B, t)),
                                   atol=1e-5)
    with pytest.raises(UserError, match="2, 2"):
        gait.blend_contact_intervals(A[:, :1], B[:, :1], 0.5)


def _model(seed, names, omega, speed):
    rng = np.random.default_rng(seed)
    offset = rng.normal(scale=0.1, size=len(names))
    offset[:3] = (0.0, speed, 17.0)
    return FourierModel(jnp.asarray(offset), jnp.asarray(rng.uniform(0.0, 0.2, size=(len(names), 3))),
                        jnp.asarray(rng.uniform(-np.pi, np.pi, size=(len(names), 3))), jnp.asarray(omega),
                        "euler", names)


def test_interpolate_command_blends_and_stores_the_sources_intervals(tmp_path, monkeypatch):
    from fourierjax.cli import main

    template = data.load("02_01")[:2]
    names = fmotion.channel_names_for(template.topology, "euler")
    for k, (m, iv) in {"a": (_model(0, names, 6.0, 20.0), A), "b": (_model(1, names, 8.0, 40.0), B)}.items():
        model_io.save_model(tmp_path / f"{k}.npz", m, motion=template, alignment="left_heel_strike",
                            contact_intervals=iv)
    monkeypatch.chdir(tmp_path)
    want = np.asarray(gait.blend_contact_intervals(A, B, 0.25))
    assert main(["interpolate", "a.npz", "b.npz", "--s", "0.25", "--out", "m.npz"]) == 0
    # A later `synth m.npz` locks the feet over them.
    np.testing.assert_allclose(model_io.load_model(tmp_path / "m.npz").contact_intervals, want, atol=1e-6)
    seen = []
    real = gait.synthesize_gait

    def spy(*args, **kwargs):
        seen.append(kwargs.get("contact_intervals"))
        return real(*args, **kwargs)

    monkeypatch.setattr(gait, "synthesize_gait", spy)
    assert main(["interpolate", "a.npz", "b.npz", "--s", "0.25", "--out", "m.bvh", "--seconds", "0.5"]) == 0
    assert len(seen) == 1
    np.testing.assert_allclose(np.asarray(seen[0]), want, atol=1e-6)


def test_transition_command_locks_over_the_stored_intervals(tmp_path, monkeypatch):
    """`fourierjax transition` of two model files hands their stored contact phases to the
    grounded transition (as `synth` uses them), not phases re-estimated from the cycles."""
    from fourierjax import style
    from fourierjax.cli import main

    template = data.load("02_01")[:2]
    names = fmotion.channel_names_for(template.topology, "euler")
    for k, (m, iv) in {"a": (_model(0, names, 6.0, 20.0), A), "b": (_model(1, names, 8.0, 40.0), B)}.items():
        model_io.save_model(tmp_path / f"{k}.npz", m, motion=template, alignment="left_heel_strike",
                            contact_intervals=iv)
    monkeypatch.chdir(tmp_path)
    seen = []
    real = style.grounded_transition

    def spy(*args, **kwargs):
        seen.append(kwargs.get("contact_intervals"))
        return real(*args, **kwargs)

    monkeypatch.setattr(style, "grounded_transition", spy)
    assert main(["transition", "a.npz", "b.npz", "--seconds", "0.5", "--start", "0.1", "--duration", "0.2",
                 "--out", "t.bvh"]) == 0
    assert len(seen) == 1 and seen[0] is not None
    np.testing.assert_allclose(np.asarray(seen[0][0]), A, atol=1e-6)
    np.testing.assert_allclose(np.asarray(seen[0][1]), B, atol=1e-6)


def test_tangent_polar_turns_the_whole_body():
    """Tangent polar eq. 3 turns every joint of a harmonic by one `s D`, `D = arg sum_j <z_A,j, z_B,j>`
    (closed form), and commutes with a change of each joint's frame."""
    from scipy.spatial.transform import Rotation

    from fourierjax._style.interpolation import _body_polar

    za, zb = np.zeros((2, 3, 1, 2)), np.zeros((2, 3, 1, 2))  # two joints on their first channel
    za[:, 0, 0, 0] = 1.0
    zb[0, 0, 0] = np.cos(0.4), np.sin(0.4)
    zb[1, 0, 0] = 2 * np.cos(0.2), 2 * np.sin(0.2)
    s = 0.25
    d = np.angle(np.exp(0.4j) + 2 * np.exp(0.2j))
    want = [np.exp(1j * s * d) * ((1 - s) * 1 + s * amp * np.exp(1j * (ph - d))) for amp, ph in ((1, 0.4), (2, 0.2))]
    out = np.asarray(_body_polar(jnp.asarray(za), jnp.asarray(zb), s))
    np.testing.assert_allclose(out[:, 0, 0, 0] + 1j * out[:, 0, 0, 1], want, atol=1e-6)
    rng = np.random.default_rng(3)
    za, zb = rng.normal(size=(2, 4, 3, 3, 2))
    C = Rotation.random(4, random_state=2).as_matrix()
    turn = lambda v: np.einsum("kji,kjnc->kinc", C, v)  # noqa: E731
    np.testing.assert_allclose(_body_polar(jnp.asarray(turn(za)), jnp.asarray(turn(zb)), s),
                               turn(np.asarray(_body_polar(jnp.asarray(za), jnp.asarray(zb), s))), atol=1e-5)
