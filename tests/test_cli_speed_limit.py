"""`fourierjax characteristic` records its clips' joint speeds, and `synth --add` keeps a
superposition within them (issue #22: no limb flips, on the command line too)."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from fourierjax import model_io, style
from fourierjax.cli import main
from fourierjax.cli._speed_limit import HEADER_KEY, excess, synth_limit


@pytest.fixture(scope="module")
def files(tmp_path_factory):
    d = tmp_path_factory.mktemp("speed_limit")
    assert main(["fit", "07_01", "07_12", "02_01", "--harmonics", "3", "--out", f"{d}/"]) == 0
    assert main(["characteristic", f"{d}/07_12.npz", f"{d}/07_01.npz", "--out", f"{d}/brisk.npz"]) == 0
    return d


def _peak(mf, model):
    sk = mf.template_motion().skeleton()
    return (float(style.peak_joint_speed(model, sk, per="second", body_map=mf.body_map)),
            float(style.peak_joint_speed(model, sk, per="radian", body_map=mf.body_map)))


def test_characteristic_records_the_fastest_clip_in_body_heights(files):
    _, header = model_io.load_characteristic(files / "brisk.npz")
    a, b = (model_io.load_model(files / f"{n}.npz") for n in ("07_12", "07_01"))
    rows = [np.divide(_peak(m, m.model), m.body_map.height) for m in (a, b)]
    entry = header[HEADER_KEY]
    assert entry["unit"] == "body heights"
    np.testing.assert_allclose([entry["per_second"], entry["per_radian"]], np.max(rows, axis=0), rtol=1e-6)
    # a brisk walk is faster than a slow one per second; per radian of phase about the same
    assert rows[0][0] > rows[1][0]


def test_the_limit_is_the_fastest_of_base_and_clips_and_binds(files):
    mf = model_io.load_model(files / "02_01.npz")
    char, header = model_io.load_characteristic(files / "brisk.npz")
    sk = mf.template_motion().skeleton()
    limit, why = synth_limit(mf.model, sk, mf.body_map, [header])
    assert why is None
    base = _peak(mf, mf.model)
    stored = np.multiply([header[HEADER_KEY]["per_second"], header[HEADER_KEY]["per_radian"]], mf.body_map.height)
    np.testing.assert_allclose([float(limit.max_speed), float(limit.max_phase_speed)],
                               np.maximum(base, stored), rtol=1e-6)
    model = jax.tree_util.tree_map(jnp.asarray, mf.model)
    char = jax.tree_util.tree_map(jnp.asarray, char)
    plain = style.superpose(model, [char], jnp.asarray([6.0]))
    assert excess(plain, sk, mf.body_map, limit) > 1.2  # six briskness outruns every clip
    limited = style.superpose(model, [char], jnp.asarray([6.0]), speed_limit=limit)
    assert excess(limited, sk, mf.body_map, limit) <= 1.0 + 1e-5
    assert excess(limited, sk, mf.body_map, limit) >= 0.99  # scaled to the limit, not to the base


def test_synth_add_says_when_the_limit_binds(files, capsys):
    d = files
    args = ["synth", f"{d}/02_01.npz", "--seconds", "2", "--add"]
    assert main([*args, f"{d}/brisk.npz=6", "--out", f"{d}/fast.bvh"]) == 0
    out = capsys.readouterr().out
    assert "speed limit: a joint would move" in out and "--no-speed-limit" in out
    assert main([*args, f"{d}/brisk.npz=6", "--no-speed-limit", "--out", f"{d}/free.bvh"]) == 0
    assert "speed limit" not in capsys.readouterr().out
    assert main([*args, f"{d}/brisk.npz=0.2", "--out", f"{d}/mild.bvh"]) == 0
    assert "speed limit" not in capsys.readouterr().out  # within the clips: the weights as given


def test_a_characteristic_without_speeds_adds_unlimited_with_a_note(files, capsys):
    d = files
    char, header = model_io.load_characteristic(d / "brisk.npz")
    model_io.save_characteristic(d / "old.npz", char, a=header["a"], b=header["b"])  # as written before
    assert HEADER_KEY not in model_io.load_characteristic(d / "old.npz")[1]
    assert main(["synth", f"{d}/02_01.npz", "--seconds", "2", "--add", f"{d}/old.npz=6",
                 "--out", f"{d}/old.bvh"]) == 0
    err = capsys.readouterr().err
    assert "without a speed limit" in err and "joint speeds" in err


def test_the_limited_program_has_no_host_callback(files):
    """A host callback (`eqx.error_if` on the bounds inside the jitted superposition) kept that
    program out of the persistent compile cache: 13-20 s of compile at every `synth --add`."""
    mf = model_io.load_model(files / "02_01.npz")
    char, header = model_io.load_characteristic(files / "brisk.npz")
    sk = mf.template_motion().skeleton()
    limit, _ = synth_limit(mf.model, sk, mf.body_map, [header])
    model = jax.tree_util.tree_map(jnp.asarray, mf.model)
    char = jax.tree_util.tree_map(jnp.asarray, char)
    jaxpr = jax.make_jaxpr(lambda: style.superpose(model, [char], jnp.asarray([6.0]), speed_limit=limit))()
    inner = [e.params["jaxpr"] for e in jaxpr.eqns if e.params.get("name") == "_superpose_limited"]
    assert len(inner) == 1, [e.params.get("name") for e in jaxpr.eqns]
    assert "callback" not in str(inner[0])
    assert "custom_jvp_call" in str(inner[0])  # the bisection is in there
