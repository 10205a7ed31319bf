"""Tests of fourierjax.io.model_io: exact round trip, skeleton record, typed errors, no pickle."""

import io
import json
import pathlib

import numpy as np
import pytest

from fourierjax import data
from fourierjax.fourier import FourierModel
from fourierjax.io import model_io


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


# -- characteristic files (Unuma eq. 7) ------------------------------------------------------
def _gait_pair():
    import jax.numpy as jnp

    names = ("root.vz", "LeftLeg.Xrotation")
    ma = FourierModel(jnp.asarray([20.0, 0.3]), jnp.asarray([[1.0, 0.25], [0.5, 0.125]]),
                      jnp.asarray([[0.5, -1.0], [2.0, 3.0]]), jnp.asarray(6.0), "euler", names)
    mb = FourierModel(jnp.asarray([10.0, 0.1]), jnp.asarray([[0.5, 0.5], [0.25, 0.25]]),
                      jnp.asarray([[-0.5, 1.0], [-2.0, 0.0]]), jnp.asarray(7.5), "euler", names)
    return ma, mb


_CHAR_FIELDS = ("offset", "amplitude", "phase", "phasor", "log_omega")


def _archive(path):
    with np.load(path, allow_pickle=False) as z:
        return {k: z[k] for k in z.files}


def test_characteristic_file_written_before_the_move_still_loads(tmp_path):
    # tests/data/characteristic_v1.npz was written by fourierjax.cli.characteristic (the code
    # before save/load moved to model_io) from characteristic(A, B) of _gait_pair().
    from fourierjax import style

    path = pathlib.Path(__file__).parent / "data" / "characteristic_v1.npz"
    char, header = model_io.load_characteristic(path)
    assert header == {"format": "fourierjax.fourier_characteristic", "version": 1,
                      "representation": "euler",
                      "channel_names": ["root.vz", "LeftLeg.Xrotation"],
                      "num_channels": 2, "num_harmonics": 2, "phase_convention": "sine",
                      "a": "brisk.bvh", "b": "walk.bvh", "alignment": "left_heel_strike"}
    assert char.representation == "euler"
    assert char.channel_names == ("root.vz", "LeftLeg.Xrotation")
    # Closed forms of eq. 7 for the pair: A0_A - A0_B, A_A - A_B, log(6 / 7.5).
    np.testing.assert_allclose(char.offset, [10.0, 0.2], atol=1e-6)
    np.testing.assert_allclose(char.amplitude, [[0.5, -0.25], [0.25, -0.125]])
    np.testing.assert_allclose(char.log_omega, np.log(6.0 / 7.5), rtol=1e-6)
    ref = style.characteristic(*_gait_pair())
    for k in _CHAR_FIELDS:
        np.testing.assert_allclose(getattr(char, k), getattr(ref, k), atol=1e-6)
    # The new writer writes the same archive: entries, dtypes, values and header.
    new = tmp_path / "new.npz"
    model_io.save_characteristic(new, ref, a="brisk.bvh", b="walk.bvh",
                                 alignment="left_heel_strike")
    old_z, new_z = _archive(path), _archive(new)
    assert list(new_z) == list(old_z)
    assert json.loads(str(new_z.pop("header"))) == json.loads(str(old_z.pop("header")))
    # Bit for bit on CPU, where the archive was computed; another backend's sin/arctan2 may
    # round the float32 characteristic differently (measured on an H100: 1 ulp, 6e-8).
    import jax

    exact = jax.default_backend() == "cpu"
    for k, v in old_z.items():
        assert new_z[k].dtype == v.dtype == np.float64
        if exact:
            np.testing.assert_array_equal(new_z[k], v)
        else:
            np.testing.assert_allclose(new_z[k], v, rtol=3e-7, atol=1e-7)


def test_characteristic_round_trip_and_typed_errors(tmp_path):
    from fourierjax import style
    from fourierjax.errors import UserError

    ma, mb = _gait_pair()
    char = style.characteristic(ma, mb)
    path = tmp_path / "c.npz"
    model_io.save_characteristic(path, char, a="A", b="B")
    back, header = model_io.load_characteristic(path)
    for k in _CHAR_FIELDS:
        np.testing.assert_array_equal(getattr(back, k), np.asarray(getattr(char, k), np.float64))
    assert back.channel_names == char.channel_names and header["b"] == "B"
    assert header["format"] == model_io.CHARACTERISTIC_FORMAT_NAME
    # The CLI module still offers the same functions.
    from fourierjax.cli import characteristic as cli_char

    assert cli_char.load_characteristic is model_io.load_characteristic
    assert cli_char.save_characteristic is model_io.save_characteristic

    # A model file is not a characteristic file, and vice versa.
    model_io.save_model(tmp_path / "m.npz", ma)
    with pytest.raises(model_io.ModelFileError, match="m.npz: format is 'fourierjax.fourier_model'"):
        model_io.load_characteristic(tmp_path / "m.npz")
    with pytest.raises(model_io.ModelFileError,
                       match="format is 'fourierjax.fourier_characteristic'"):
        model_io.load_model(path)
    (tmp_path / "junk.npz").write_text("not a zip")
    with pytest.raises(UserError, match="junk.npz: not a fourierjax characteristic file"):
        model_io.load_characteristic(tmp_path / "junk.npz")
    with pytest.raises(UserError, match="nope.npz: no such file"):
        model_io.load_characteristic(tmp_path / "nope.npz")
    arrays = _archive(path)
    hdr = json.loads(str(arrays.pop("header")))
    bad = tmp_path / "bad.npz"
    _write(bad, dict(hdr, version=2), **arrays)
    with pytest.raises(model_io.ModelFileError, match="version 2 is newer"):
        model_io.load_characteristic(bad)
    _write(bad, dict(hdr, num_harmonics=3), **arrays)
    with pytest.raises(model_io.ModelFileError, match="inconsistent shapes: .*phasor"):
        model_io.load_characteristic(bad)
    _write(bad, hdr, **{k: v for k, v in arrays.items() if k != "phasor"})
    with pytest.raises(model_io.ModelFileError, match=r"missing array\(s\) \['phasor'\]"):
        model_io.load_characteristic(bad)
    with pytest.raises(UserError, match="one characteristic expected"):
        model_io.save_characteristic(tmp_path / "x.npz", style.stack([char, char]))


# -- contents checked at load time (audit item 10) -------------------------------------------
def _good_archive(tmp_path):
    """(header, arrays) of a valid model file with a skeleton record."""
    good = tmp_path / "good.npz"
    model_io.save_model(good, _model(), motion=data.load("07_01")[:3])
    arrays = _archive(good)
    return json.loads(str(arrays.pop("header"))), arrays


def _amp(a):
    return a["amplitude"]


BAD_CONTENTS = [
    ("nan amplitude", {}, {"amplitude": lambda a: np.full_like(_amp(a), np.nan)},
     "'amplitude' holds NaN or infinite"),
    ("inf offset", {}, {"offset": lambda a: np.full_like(a["offset"], np.inf)},
     "'offset' holds NaN or infinite"),
    ("nan skeleton offsets", {}, {"skeleton_offsets": lambda a: a["skeleton_offsets"] * np.nan},
     "'skeleton_offsets' holds NaN"),
    ("negative omega", {}, {"omega": lambda a: np.array(-3.0)}, "omega must be > 0"),
    ("zero omega", {}, {"omega": lambda a: np.array(0.0)}, "omega must be > 0"),
    ("complex amplitude", {}, {"amplitude": lambda a: _amp(a).astype(complex)},
     "'amplitude' has dtype complex128"),
    ("string amplitude", {}, {"amplitude": lambda a: np.full(_amp(a).shape, "a")},
     "'amplitude' has dtype <U1"),
    ("bool phase", {}, {"phase": lambda a: a["phase"] > 0}, "'phase' has dtype bool"),
    ("version true", {"version": True}, {}, "bad format version True"),
    ("num_channels true", {"num_channels": True}, {}, "num_channels must be a non-negative"),
    ("integer channel names", {"channel_names": [0, 1, 2]}, {}, "channel_names must be a list"),
    ("channel names string", {"channel_names": "abc"}, {}, "channel_names must be a list"),
    ("provenance list", {"provenance": [1, 2]}, {}, "provenance must be a JSON object"),
    ("alignment number", {"alignment": 3}, {}, "alignment must be a string"),
    ("short skeleton offsets", {}, {"skeleton_offsets": lambda a: a["skeleton_offsets"][:3]},
     "skeleton_offsets has shape (3, 3), expected (31, 3)"),
    ("end site offsets", {}, {"skeleton_end_site_offsets": lambda a: np.zeros((2, 3))},
     "skeleton_end_site_offsets has shape (2, 3), expected (7, 3)"),
    ("negative frame time", {"skeleton": {"frame_time_s": -1.0}}, {}, "frame_time_s must be"),
    ("zero frame time", {"skeleton": {"frame_time_s": 0}}, {}, "frame_time_s must be"),
    ("bool frame time", {"skeleton": {"frame_time_s": True}}, {}, "frame_time_s must be"),
    ("text frame time", {"skeleton": {"frame_time_s": "0.01"}}, {}, "frame_time_s must be"),
]  # fmt: skip


@pytest.mark.parametrize("case", BAD_CONTENTS, ids=[c[0] for c in BAD_CONTENTS])
def test_load_model_rejects_bad_contents_naming_the_path(tmp_path, case):
    _, header_edit, array_edit, fragment = case
    header, arrays = _good_archive(tmp_path)
    for k, v in header_edit.items():
        header[k] = dict(header[k], **v) if isinstance(v, dict) else v
    arrays = dict(arrays, **{k: f(arrays) for k, f in array_edit.items()})
    bad = tmp_path / "bad.npz"
    _write(bad, header, **arrays)
    with pytest.raises(model_io.ModelFileError) as e:
        model_io.load_model(bad)
    assert e.value.path == str(bad) and str(e.value).startswith(f"{bad}: "), str(e.value)
    assert fragment in e.value.message, str(e.value)


def test_load_model_checks_leave_valid_files_alone(tmp_path):
    header, arrays = _good_archive(tmp_path)
    # Integer arrays, a null provenance and an integer frame time are valid JSON/npz spellings.
    ok = tmp_path / "ok.npz"
    _write(ok, dict(header, provenance=None, skeleton=dict(header["skeleton"], frame_time_s=1)),
           **dict(arrays, offset=np.arange(3)))
    mf = model_io.load_model(ok)
    assert mf.provenance == {} and mf.frame_time_s == 1.0
    assert np.asarray(mf.model.offset).dtype == np.float64
    assert mf.template_motion().num_frames == 1


def test_characteristic_arrays_are_checked_too(tmp_path):
    from fourierjax import style

    path = tmp_path / "c.npz"
    model_io.save_characteristic(path, style.characteristic(*_gait_pair()))
    arrays = _archive(path)
    header = json.loads(str(arrays.pop("header")))
    _write(path, header, **dict(arrays, log_omega=np.array(np.nan)))
    with pytest.raises(model_io.ModelFileError, match="c.npz: array 'log_omega' holds NaN"):
        model_io.load_characteristic(path)


def test_save_model_rejects_provenance_that_is_not_json(tmp_path):
    from fourierjax.errors import UserError

    with pytest.raises(UserError, match="save_model: `provenance` must hold only JSON values"):
        model_io.save_model(tmp_path / "p.npz", _model(), provenance={"x": object()})
    assert not (tmp_path / "p.npz").exists()


def test_save_model_refuses_what_load_model_would_refuse(tmp_path):
    from fourierjax.errors import UserError

    m = _model()
    amp = np.array(m.amplitude)
    amp[0, 0] = np.nan
    nan = FourierModel(m.offset, amp, m.phase, m.omega, m.representation, m.channel_names)
    with pytest.raises(UserError, match=r"NaN or infinite values in \['amplitude'\]"):
        model_io.save_model(tmp_path / "n.npz", nan)
    still = FourierModel(m.offset, m.amplitude, m.phase, np.asarray(0.0), m.representation,
                         m.channel_names)
    with pytest.raises(UserError, match="omega must be > 0"):
        model_io.save_model(tmp_path / "s.npz", still)
    assert not (tmp_path / "n.npz").exists() and not (tmp_path / "s.npz").exists()
    # Characteristics too (load_characteristic refused the file save_characteristic wrote).
    import equinox as eqx
    import jax.numpy as jnp

    from fourierjax import style

    char = style.characteristic(*_gait_pair())
    bad = eqx.tree_at(lambda c: c.log_omega, char, jnp.asarray(np.inf, char.log_omega.dtype))
    with pytest.raises(UserError, match=r"save_characteristic: `char` holds NaN or infinite values in \['log_omega'\]"):
        model_io.save_characteristic(tmp_path / "c.npz", bad)
    assert not (tmp_path / "c.npz").exists()


def test_missing_files_raise_the_same_error_for_models_and_characteristics(tmp_path):
    for load in (model_io.load_model, model_io.load_characteristic):
        missing = tmp_path / "nope.npz"
        with pytest.raises(model_io.ModelFileError) as e:
            load(missing)
        assert e.value.path == str(missing) and str(e.value) == f"{missing}: no such file"
        # Still a FileNotFoundError (what load_model raised before), for existing handlers.
        assert isinstance(e.value, FileNotFoundError) and e.value.filename == str(missing)


def test_model_file_errors_survive_pickling(tmp_path):
    """Errors from batch workers cross process boundaries: they must unpickle with their fields."""
    import pickle

    bad = tmp_path / "bad.npz"
    bad.write_bytes(b"not a zip")
    missing = tmp_path / "nope.npz"
    errors = []
    for path in (bad, missing):
        with pytest.raises(model_io.ModelFileError) as e:
            model_io.load_model(path)
        errors.append(e.value)
    for err in errors:
        back = pickle.loads(pickle.dumps(err))
        assert type(back) is type(err)
        assert (back.path, back.message, str(back)) == (err.path, err.message, str(err))
    assert isinstance(pickle.loads(pickle.dumps(errors[1])), FileNotFoundError)


def _six_channel(motion):
    """`motion` rewritten as many exporters write it: X/Y/Z position channels on every joint,
    holding the OFFSETs (the same skeleton and FK)."""
    from fourierjax.io.bvh import Motion
    from fourierjax.skeleton import Topology

    t, starts = motion.topology, motion.topology.channel_offsets
    chans, cols = [], []
    for j, ch in enumerate(t.channels):
        if j:
            chans.append(("Xposition", "Yposition", "Zposition") + ch)
            cols.append(np.tile(motion.offsets[j], (motion.num_frames, 1)))
        else:
            chans.append(ch)
        cols.append(motion.channels[:, starts[j]:starts[j] + len(ch)])
    return Motion(Topology(t.names, t.parents, tuple(chans), t.end_site_parents), motion.offsets,
                  motion.end_site_offsets, np.concatenate(cols, 1), motion.frame_time_s)


def test_template_keeps_the_bones_of_files_with_positions_on_every_joint(tmp_path):
    """The template of a model fitted on a 6-channel-per-joint file had zeros in the non-root
    position channels, which replace the OFFSETs: synthesized files had every bone of length 0."""
    import jax.numpy as jnp

    from fourierjax import kinematics

    walk = data.load("07_01")[:2]
    six = _six_channel(walk)
    path = tmp_path / "six.npz"
    model_io.save_model(path, _model(), motion=six)
    template = model_io.load_model(path).template_motion()
    # The template's frame is the rest pose: the same joint positions as the 3-channel original
    # with every channel zero (FK from its OFFSETs alone).
    rest = kinematics.joint_positions(walk.skeleton(), jnp.zeros((1, walk.num_channels)))
    got = kinematics.joint_positions(template.skeleton(), jnp.asarray(template.channels))
    np.testing.assert_allclose(np.asarray(got), np.asarray(rest), atol=1e-5)
    assert np.ptp(np.asarray(got)[0, :, 1]) > 10  # a body, not a point (CMU units)


# -- corrupted files never escape as tracebacks (issue 24) ---------------------------------
def _good_bytes(tmp_path):
    good = tmp_path / "good.npz"
    model_io.save_model(good, _model())
    return good.read_bytes()


def _patch_zip(raw: bytes, **fields) -> bytes:
    """`raw` with fields of every local and central zip header overwritten (little endian)."""
    local = {"version": 4, "flags": 6, "method": 8}
    central = {"version": 6, "flags": 8, "method": 10}
    out = bytearray(raw)
    for sig, where in ((b"PK\x03\x04", local), (b"PK\x01\x02", central)):
        pos = out.find(sig)
        while pos >= 0:
            for name, value in fields.items():
                out[pos + where[name]:pos + where[name] + 2] = value.to_bytes(2, "little")
            pos = out.find(sig, pos + 4)
    return bytes(out)


def _header_of(tmp_path):
    with np.load(tmp_path / "good.npz") as z:
        return {k: z[k] for k in z.files if k != "header"}, json.loads(str(z["header"]))


def _huge_member_npz(arrays, header) -> bytes:
    """A valid archive whose `offset` member declares shape (10**12,) but holds 3 values."""
    import zipfile

    buf = io.BytesIO()
    with zipfile.ZipFile(buf, "w") as zf:
        for k, v in dict(arrays, header=np.array(json.dumps(header))).items():
            member = io.BytesIO()
            if k == "offset":
                np.lib.format.write_array_header_1_0(
                    member, {"descr": "<f8", "fortran_order": False, "shape": (10**12,)})
                member.write(np.zeros(3).tobytes())
            else:
                np.save(member, v)
            zf.writestr(k + ".npy", member.getvalue())
    return buf.getvalue()


CORRUPT = [
    # (id, how the file is made from the good bytes / arrays / header, fragment of the message)
    ("nested brackets (RecursionError)", "header", "[" * 100_000 + "]" * 100_000, "nested too deeply"),
    ("5000-digit integer (ValueError)", "header",
     '{"format": "fourierjax.fourier_model", "version": 1' + "0" * 5000 + "}", "not valid JSON"),
    ("bare .npy (TypeError)", "npy", None, "bare .npy array"),
    ("shape 10**12 (MemoryError)", "huge", None, "declares shape (1000000000000,)"),
    ("compression 99 (NotImplementedError)", "patch", {"method": 99}, "compression method 99"),
    ("zip version 200 (NotImplementedError)", "patch", {"version": 200}, "damaged archive"),
    ("encrypted flag (RuntimeError)", "patch", {"flags": 1}, "is encrypted"),
]  # fmt: skip


@pytest.mark.parametrize("case", CORRUPT, ids=[c[0] for c in CORRUPT])
def test_corrupted_model_files_raise_the_typed_error(tmp_path, case):
    _, how, arg, fragment = case
    raw = _good_bytes(tmp_path)
    arrays, header = _header_of(tmp_path)
    bad = tmp_path / "bad.npz"
    if how == "header":
        buf = io.BytesIO()
        np.savez(buf, header=np.array(arg), **arrays)
        bad.write_bytes(buf.getvalue())
    elif how == "npy":
        with open(bad, "wb") as f:
            np.save(f, np.zeros(3))
    elif how == "huge":
        bad.write_bytes(_huge_member_npz(arrays, header))
    else:
        bad.write_bytes(_patch_zip(raw, **arg))
    for load in (model_io.load_model, model_io.load_characteristic):
        with pytest.raises(model_io.ModelFileError) as e:
            load(bad)
        assert e.value.path == str(bad) and fragment in e.value.message, str(e.value)
        assert "\n" not in str(e.value)


def _edited(tmp_path, names=None, representation=None, **arrays):
    _good_bytes(tmp_path)
    base, header = _header_of(tmp_path)
    if names is not None:
        header["channel_names"] = list(names)
    if representation is not None:
        header["representation"] = representation
    bad = tmp_path / "bad.npz"
    _write(bad, header, **dict(base, **arrays))
    return bad, base


INCONSISTENT = [
    ("expmap on Euler names", dict(names=("root.vx", "Hips.Zrotation", "Hips.Xrotation"),
                                   representation="expmap"), "'Hips.Zrotation' is an Euler channel"),
    ("euler on expmap names", dict(names=("root.vx", "Hips.expmap0", "Hips.expmap1"),
                                   representation="euler"), "'Hips.expmap0' is an expmap channel"),
    ("negative amplitude", dict(amplitude=lambda a: a - 2.0), "is negative"),
    ("subnormal omega", dict(omega=np.array(5e-324)), "outside the physical range [0.05, 100]"),
    ("omega 1000 rad/s", dict(omega=np.array(1000.0)), "outside the physical range"),
]  # fmt: skip


@pytest.mark.parametrize("case", INCONSISTENT, ids=[c[0] for c in INCONSISTENT])
def test_inconsistent_model_files_are_refused(tmp_path, case):
    _, edit, fragment = case
    _good_bytes(tmp_path)
    base, _ = _header_of(tmp_path)
    edit = {k: (v(base[k]) if callable(v) else v) for k, v in edit.items()}
    bad, _ = _edited(tmp_path, **edit)
    with pytest.raises(model_io.ModelFileError) as e:
        model_io.load_model(bad)
    assert e.value.path == str(bad) and fragment in e.value.message, str(e.value)


def test_save_model_refuses_inconsistent_models(tmp_path):
    from fourierjax.errors import UserError

    m = _model(("root.vx", "Hips.Zrotation", "Hips.Xrotation"))  # expmap on Euler names
    with pytest.raises(UserError, match="save_model: `model`: representation is 'expmap'"):
        model_io.save_model(tmp_path / "r.npz", m)
    ok = _model()
    slow = FourierModel(ok.offset, ok.amplitude, ok.phase, np.asarray(0.01), ok.representation,
                        ok.channel_names)
    with pytest.raises(UserError, match="omega = 0.01 rad/s is outside the physical range"):
        model_io.save_model(tmp_path / "w.npz", slow)
    neg = FourierModel(ok.offset, -ok.amplitude, ok.phase, ok.omega, ok.representation,
                       ok.channel_names)
    with pytest.raises(UserError, match="is negative"):
        model_io.save_model(tmp_path / "a.npz", neg)
    assert not any((tmp_path / n).exists() for n in ("r.npz", "w.npz", "a.npz"))
    # The range's ends are valid.
    for omega in (model_io.OMEGA_MIN_RAD_S, model_io.OMEGA_MAX_RAD_S):
        edge = FourierModel(ok.offset, ok.amplitude, ok.phase, np.asarray(omega),
                            ok.representation, ok.channel_names)
        model_io.save_model(tmp_path / "e.npz", edge)
        assert float(model_io.load_model(tmp_path / "e.npz").model.omega) == omega


def test_the_old_import_path_still_works():
    import fourierjax.model_io as old

    assert old.load_model is model_io.load_model and old.ModelFileError is model_io.ModelFileError
    assert old.save_characteristic is model_io.save_characteristic


def test_a_folder_given_as_a_model_is_the_typed_error(tmp_path):
    (tmp_path / "m.npz").mkdir()
    with pytest.raises(model_io.ModelFileError, match="m.npz: cannot read the file"):
        model_io.load_model(tmp_path / "m.npz")


def test_body_map_travels_with_the_model(tmp_path):
    from fourierjax.body import BodyMapError, infer_body_map
    from fourierjax.errors import UserError
    from fourierjax.motion import fit_motions

    def fields(bm):
        return {k: v for k, v in bm.to_dict().items() if k != "sources"}

    m = data.load("07_01")[1:160]
    fit = fit_motions([m], 2)[0]
    assert fit.body_map == infer_body_map(m)
    path = tmp_path / "m.npz"
    model_io.save_model(path, fit.model, motion=m, body_map=fit.body_map)
    with np.load(path) as z:
        header = json.loads(str(z["header"]))
    assert header["version"] == 2 and model_io.FORMAT_VERSION == 4  # 3: with contact intervals, 4: tangent frames
    assert header["body_map"] == fit.body_map.to_dict()
    mf = model_io.load_model(path)
    assert mf.stored_body_map is not None and fields(mf.body_map) == fields(fit.body_map)
    # Version 1 (no map): still loads, the map inferred from the template's skeleton.
    old = tmp_path / "old.npz"
    model_io.save_model(old, fit.model, motion=m)
    with np.load(old) as z:
        assert json.loads(str(z["header"]))["version"] == 1
    mf1 = model_io.load_model(old)
    assert mf1.stored_body_map is None
    assert mf1.body_map.left.names == fit.body_map.left.names
    assert model_io.load_model(tmp_path / "m.npz").model.channel_names == fit.model.channel_names
    # A map of another skeleton, or one without a skeleton, is refused.
    with pytest.raises(UserError, match="needs `motion`"):
        model_io.save_model(tmp_path / "x.npz", fit.model, body_map=fit.body_map)
    arrays = {k: v for k, v in np.load(path).items() if k != "header"}
    bad = tmp_path / "bad.npz"
    broken = dict(header, body_map=dict(header["body_map"], pelvis="NoSuchJoint"))
    _write(bad, broken, **arrays)
    with pytest.raises(model_io.ModelFileError, match="bad body_map record"):
        model_io.load_model(bad)
    assert issubclass(BodyMapError, UserError)


def test_contact_intervals_travel_with_the_model(tmp_path):
    from fourierjax.errors import UserError
    from fourierjax.motion import fit_motions

    m = data.load("07_01")[1:160]
    fit = fit_motions([m], 2)[0]
    iv = np.array([[0.1, 3.9], [3.2, 7.0]])  # 7.0 rad is stored on [0, 2 pi)
    path = tmp_path / "m.npz"
    model_io.save_model(path, fit.model, motion=m, body_map=fit.body_map, contact_intervals=iv)
    with np.load(path) as z:
        header = json.loads(str(z["header"]))
    assert header["version"] == 3 and model_io.FORMAT_VERSION == 4
    mf = model_io.load_model(path)
    np.testing.assert_allclose(mf.contact_intervals, np.mod(iv, 2 * np.pi))
    # Older files (no intervals) still load, without them.
    model_io.save_model(tmp_path / "v2.npz", fit.model, motion=m, body_map=fit.body_map)
    assert model_io.load_model(tmp_path / "v2.npz").contact_intervals is None
    with pytest.raises(UserError, match="contact_intervals"):
        model_io.save_model(tmp_path / "x.npz", fit.model, motion=m, contact_intervals=[1.0, 2.0])
    arrays = {k: v for k, v in np.load(path).items() if k != "header"}
    _write(tmp_path / "bad.npz", dict(header, contact_intervals=[[0.0, "a"], [1.0, 2.0]]), **arrays)
    with pytest.raises(model_io.ModelFileError, match="contact_intervals"):
        model_io.load_model(tmp_path / "bad.npz")
