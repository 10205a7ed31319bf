"""Tests of fourierjax.model_io: exact round trip, skeleton record, typed errors, no pickle."""

import io
import json

import numpy as np
import pytest

from fourierjax import data, model_io
from fourierjax.fourier import FourierModel


def _model(names=("root.vx", "a", "b")):
    rng = np.random.default_rng(0)
    C, N = len(names), 3
    return FourierModel(rng.normal(size=C), rng.uniform(0, 1, (C, N)),
                        rng.uniform(-np.pi, np.pi, (C, N)), np.asarray(6.1), "expmap",
                        tuple(names))


def test_round_trip_with_skeleton(tmp_path):
    motion = data.load("07_01")[:3]
    m = _model()
    path = tmp_path / "walk.npz"
    model_io.save_model(path, m, motion=motion, provenance={"rms": np.float32(1.5), "f": [1, 2]},
                        alignment="left_heel_strike")
    mf = model_io.load_model(path)
    for field in ("offset", "amplitude", "phase", "omega"):
        np.testing.assert_array_equal(np.asarray(getattr(mf.model, field)),
                                      np.asarray(getattr(m, field)))
    assert mf.model.representation == "expmap" and mf.model.channel_names == m.channel_names
    assert mf.topology == motion.topology and mf.alignment == "left_heel_strike"
    np.testing.assert_array_equal(mf.offsets, motion.offsets)
    assert mf.frame_time_s == motion.frame_time_s
    assert mf.provenance == {"rms": 1.5, "f": [1, 2]}
    tm = mf.template_motion()
    assert tm.topology == motion.topology and tm.num_frames == 1
    # No skeleton: loads, and has no template.
    model_io.save_model(tmp_path / "bare.npz", m)
    assert model_io.load_model(tmp_path / "bare.npz").template_motion() is None


def _write(path, header, **arrays):
    buf = io.BytesIO()
    np.savez(buf, header=np.array(json.dumps(header)), **arrays)
    path.write_bytes(buf.getvalue())


def test_bad_files_raise_typed_errors(tmp_path):
    good = tmp_path / "good.npz"
    model_io.save_model(good, _model())
    with np.load(good) as z:
        arrays = {k: z[k] for k in z.files if k != "header"}
        header = json.loads(str(z["header"]))
    assert header["format"] == model_io.FORMAT_NAME and header["version"] == 1

    text = tmp_path / "text.npz"
    text.write_text("hello")
    with pytest.raises(model_io.ModelFileError, match="not a fourierjax model file") as e:
        model_io.load_model(text)
    assert e.value.path == str(text)

    newer = tmp_path / "newer.npz"
    _write(newer, dict(header, version=99), **arrays)
    with pytest.raises(model_io.ModelFileError, match="newer"):
        model_io.load_model(newer)

    other = tmp_path / "other.npz"
    _write(other, dict(header, format="something.else"), **arrays)
    with pytest.raises(model_io.ModelFileError, match="format is 'something.else'"):
        model_io.load_model(other)

    shapes = tmp_path / "shapes.npz"
    _write(shapes, dict(header, num_harmonics=2), **arrays)
    with pytest.raises(model_io.ModelFileError, match="inconsistent shapes"):
        model_io.load_model(shapes)

    # An object array would need pickle: refused, never executed.
    pickled = tmp_path / "pickled.npz"
    buf = io.BytesIO()
    np.savez(buf, header=np.array([{"format": model_io.FORMAT_NAME}], dtype=object), **arrays)
    pickled.write_bytes(buf.getvalue())
    with pytest.raises(model_io.ModelFileError):
        model_io.load_model(pickled)

    with pytest.raises(FileNotFoundError):
        model_io.load_model(tmp_path / "missing.npz")
