"""Fourier model and characteristic files: versioned ``.npz`` archives with a JSON header,
read without pickle and checked (sizes before allocation, contents against the header) so that
every bad file raises `ModelFileError` naming its path."""

from __future__ import annotations

import dataclasses
import errno
import functools
import io
import json
import math
import os
import re
import zipfile
import zlib

import numpy as np

from fourierjax.errors import UserError
from fourierjax.io.atomic import write_bytes_atomic

FORMAT_NAME = "fourierjax.fourier_model"
FORMAT_VERSION = 4
CHARACTERISTIC_FORMAT_NAME = "fourierjax.fourier_characteristic"
CHARACTERISTIC_FORMAT_VERSION = 1

__all__ = ["FORMAT_NAME", "FORMAT_VERSION", "CHARACTERISTIC_FORMAT_NAME",
           "CHARACTERISTIC_FORMAT_VERSION", "MAX_ARCHIVE_BYTES", "OMEGA_MAX_RAD_S",
           "OMEGA_MIN_RAD_S", "ModelFileError", "ModelFile", "save_model",
           "load_model", "save_characteristic", "load_characteristic"]

#: The physical range of a model's fundamental ω, rad/s: one cycle in 2 min to 16 cycles a
#: second. A file outside it is corrupt; ``omega = 5e-324`` loaded and froze the pose.
OMEGA_MIN_RAD_S = 0.05
OMEGA_MAX_RAD_S = 100.0
#: The most bytes the arrays of one file may declare (a 1,000-joint, 64-harmonic model is 3 MB).
MAX_ARCHIVE_BYTES = 1 << 30
_MAX_ELEMENTS = 1 << 28

_MODEL_ARRAYS = ("offset", "amplitude", "phase", "omega")
_CHARACTERISTIC_ARRAYS = ("offset", "amplitude", "phase", "phasor", "log_omega")
#: Written only for tangent characteristics (`style.characteristic`): ``frames [K, 4]`` (wxyz
#: clip-mean differences M_B^-1 M_A) and ``aligned [C, N, 2]`` (per-joint polar differences).
_TANGENT_CHARACTERISTIC_ARRAYS = ("frames", "aligned")
# Exponential-map characteristics: B's offsets, the branch the differences were taken on.
_REFERENCE_CHARACTERISTIC_ARRAYS = ("reference",)


class ModelFileError(UserError):
    """A model or characteristic file that cannot be read: carries ``path`` and a message."""

    def __init__(self, path, message: str):
        self.path = str(path)
        self.message = message
        super().__init__(f"{self.path}: {message}")

    def __reduce__(self):
        # The default pickles `args` (the formatted text), which `__init__` cannot take back:
        # a batch worker's error would not reach its parent process.
        return type(self), (self.path, self.message)


class _MissingModelFile(ModelFileError, FileNotFoundError):
    """No such file: a ModelFileError, and also the FileNotFoundError that ``load_model`` used
    to raise (so an existing ``except FileNotFoundError`` still works)."""

    def __init__(self, path):
        super().__init__(path, "no such file")
        self.errno, self.strerror, self.filename = errno.ENOENT, "no such file", str(path)

    def __str__(self) -> str:  # OSError's would be "[Errno 2] ..."
        return f"{self.path}: {self.message}"

    def __reduce__(self):
        return type(self), (self.path,)


@dataclasses.dataclass(frozen=True)
class ModelFile:
    """What a model file holds: the model, the source skeleton (or None) and metadata."""

    model: object  # fourierjax.fourier.FourierModel
    topology: object | None = None  # fourierjax.skeleton.Topology
    offsets: np.ndarray | None = None
    end_site_offsets: np.ndarray | None = None
    frame_time_s: float | None = None
    provenance: dict = dataclasses.field(default_factory=dict)
    alignment: str = "none"
    stored_body_map: object | None = None  # fourierjax.body.BodyMap read from the header
    #: `[2, 2]` (left, right) × (start, end) contact phases in radians (version 3), or None.
    contact_intervals: np.ndarray | None = None
    #: `[2]` (left, right) the capture's largest knee speed in rad/s (`gait.fit_knee_speed`), or
    #: None (an optional header key: older readers ignore it, older files have none).
    knee_speed_rad_s: np.ndarray | None = None

    @functools.cached_property
    def body_map(self):
        """The skeleton's `fourierjax.body.BodyMap`: the one stored in the file (version 2), else
        inferred from the model's own poses over a cycle (`gait.model_body_map`: a rest template
        that is not a T-pose, e.g. Bandai's, does not show which way is up), else from the
        template; None without a skeleton or when no legs can be found."""
        if self.stored_body_map is not None:
            return self.stored_body_map
        template = self.template_motion()
        if template is None:
            return None
        from fourierjax.body import BodyMapError, infer_body_map
        from fourierjax.errors import UserError
        from fourierjax.gait import model_body_map

        try:
            return model_body_map(self.model, template.skeleton())
        except UserError:
            pass
        try:
            return infer_body_map(template)
        except BodyMapError:
            return None

    def template_motion(self):
        """A one-frame Motion on the stored skeleton (for ``motion_from_features``), or None.

        Its frame is the rest pose: rotations zero and the position channels of non-root
        joints equal to their OFFSETs. Position channels replace OFFSETs (``Topology``), and
        ``motion_from_features`` keeps the template's values for them: zeros would collapse
        every bone of a file that writes positions on all joints (6-channel exports) to length 0.
        """
        if self.topology is None:
            return None
        from fourierjax.io.bvh import Motion

        topo = self.topology
        frame = np.zeros((1, topo.num_channels))
        for j, (chans, start) in enumerate(zip(topo.channels, topo.channel_offsets, strict=True)):
            if topo.parents[j] < 0:
                continue  # the root's position comes from the model (or stays at the origin)
            for k, c in enumerate(chans):
                if c.endswith("position"):
                    frame[0, start + k] = self.offsets[j]["XYZ".index(c[0])]
        return Motion(topo, self.offsets, self.end_site_offsets, frame, self.frame_time_s or 1 / 120)


def _jsonable(x):
    if isinstance(x, dict):
        return {str(k): _jsonable(v) for k, v in x.items()}
    if isinstance(x, list | tuple):
        return [_jsonable(v) for v in x]
    if isinstance(x, np.generic):
        return x.item()
    if isinstance(x, np.ndarray) or hasattr(x, "__array__"):
        a = np.asarray(x)
        return a.item() if a.ndim == 0 else a.tolist()
    return x


def _header(format_name: str, format_version: int, obj, kind: str, **extra) -> dict:
    """The header keys shared by model and characteristic files (``obj``: one, unstacked)."""
    amp = np.asarray(obj.amplitude, np.float64)
    if amp.ndim != 2:
        raise UserError(f"save_{kind}: one {kind} expected, amplitude has shape {amp.shape}")
    return {
        "format": format_name,
        "version": format_version,
        "representation": obj.representation,
        "channel_names": list(obj.channel_names),
        "num_channels": int(amp.shape[0]),
        "num_harmonics": int(amp.shape[1]),
        "phase_convention": "sine",
        **extra,
    }


def _write_archive(path, header: dict, arrays: dict) -> None:
    """One uncompressed ``.npz``: the float64 arrays and the JSON header (written in one go)."""
    arrays = {k: np.asarray(v, np.float64) for k, v in arrays.items()}
    arrays["header"] = np.array(json.dumps(header))
    buf = io.BytesIO()
    np.savez(buf, **arrays)
    write_bytes_atomic(path, buf.getvalue())


def _not_npz_reason(path, err) -> str:
    """Why a file is not an ``.npz`` archive, in words: a BVH clip or a bare ``.npy`` array
    passed for a model, a text file, or the zip reader's message."""
    try:
        with open(path, "rb") as f:
            head = f.read(64).lstrip()
    except OSError:
        return str(err)
    if head.upper().startswith(b"HIERARCHY"):
        return "it is a BVH motion file; fit a model to it first (fourierjax fit)"
    if head.startswith(b"\x93NUMPY"):
        return "it is a bare .npy array, not an .npz archive of a model"
    if not head.startswith(b"PK"):
        return "it is not an .npz archive"
    return str(err)


# What a damaged archive raises inside `zipfile` / `zlib` / NumPy's header parser: a bad CRC
# or size (BadZipFile, EOFError), an unknown compression or zip version (NotImplementedError),
# the "encrypted" flag (RuntimeError), a corrupt stream (zlib.error) or header (ValueError,
# SyntaxError from its literal parser).
_ARCHIVE_ERRORS = (zipfile.BadZipFile, zlib.error, EOFError, OSError, ValueError, SyntaxError,
                   NotImplementedError, RuntimeError, MemoryError, OverflowError)


def _read_member(zf: zipfile.ZipFile, info: zipfile.ZipInfo, path: str) -> np.ndarray:
    """One ``.npy`` member, its declared shape and dtype checked against its size first."""
    with zf.open(info) as f:
        version = np.lib.format.read_magic(f)
        if version == (1, 0):
            shape, fortran, dtype = np.lib.format.read_array_header_1_0(f)
        elif version == (2, 0):
            shape, fortran, dtype = np.lib.format.read_array_header_2_0(f)
        else:
            raise ModelFileError(path, f"member {info.filename!r}: unsupported .npy version "
                                       f"{version[0]}.{version[1]}")
        if dtype.hasobject:
            raise ModelFileError(path, f"member {info.filename!r} holds Python objects "
                                       "(dtype object needs pickle, which is never used)")
        count = math.prod(int(d) for d in shape)
        size = count * dtype.itemsize
        held = info.file_size - f.tell()
        if count > _MAX_ELEMENTS or size != held:
            raise ModelFileError(path, f"member {info.filename!r} declares shape {str(shape)[:80]} "
                                       f"of {dtype} ({size} bytes) but holds {held} bytes")
        buf = f.read(size)
    if len(buf) != size:  # pragma: no cover - zipfile raises on a short member first
        raise ModelFileError(path, f"member {info.filename!r} is truncated")
    a = np.frombuffer(buf, dtype=dtype) if size else np.zeros(count, dtype)
    return a.reshape(shape, order="F" if fortran else "C").copy()


def _load_npz(path: str, kind: str) -> dict:
    """The arrays of an ``.npz`` archive without pickle, refusing before any allocation a
    member whose header declares more bytes than it holds, and encrypted or oddly compressed
    members (the format writes them stored)."""
    def refuse(why):
        return ModelFileError(path, f"not a fourierjax {kind} file (.npz): {why}")

    try:
        with zipfile.ZipFile(path) as zf:
            infos = zf.infolist()
            total = 0
            for info in infos:
                if info.flag_bits & 0x1:
                    raise refuse(f"member {info.filename!r} is encrypted")
                if info.compress_type not in (zipfile.ZIP_STORED, zipfile.ZIP_DEFLATED):
                    raise refuse(f"member {info.filename!r} uses compression method "
                                 f"{info.compress_type} (expected stored or deflated)")
                if not info.filename.endswith(".npy"):
                    raise refuse(f"member {info.filename!r} is not an .npy array")
                total += info.file_size
                if total > MAX_ARCHIVE_BYTES:
                    raise refuse(f"its members declare more than {MAX_ARCHIVE_BYTES} bytes")
            return {info.filename[:-4]: _read_member(zf, info, path) for info in infos}
    except ModelFileError:
        raise
    except _ARCHIVE_ERRORS as err:
        if isinstance(err, zipfile.BadZipFile):
            raise refuse(_not_npz_reason(path, err)) from None
        if isinstance(err, OSError):  # a directory, no permission, a failing disk
            raise ModelFileError(path, f"cannot read the file: {err.strerror or err}") from None
        raise refuse(f"damaged archive ({type(err).__name__}: {str(err)[:120]})") from None


def _read_archive(path: str, format_name: str, format_version: int,
                  kind: str) -> tuple[dict, dict]:
    """(header, arrays) of an archive of ``format_name`` (no pickle); checks format and version."""
    data = _load_npz(path, kind)
    if "header" not in data:
        raise ModelFileError(path, f"not a fourierjax {kind} file: no 'header' entry")
    raw = data.pop("header")
    if raw.ndim != 0 or raw.dtype.kind != "U":
        raise ModelFileError(path, f"header must be one JSON string, got an array of {raw.dtype} "
                                   f"with shape {raw.shape}")
    try:
        header = json.loads(str(raw))
    except RecursionError:
        raise ModelFileError(path, "header is not valid JSON: nested too deeply") from None
    except ValueError as err:  # JSONDecodeError, and integers of more than 4300 digits
        raise ModelFileError(path, f"header is not valid JSON: {str(err)[:120]}") from None
    if not isinstance(header, dict) or header.get("format") != format_name:
        got = header.get("format") if isinstance(header, dict) else None
        raise ModelFileError(path, f"format is {got!r}, expected {format_name!r}")
    version = header.get("version")
    if isinstance(version, bool) or not isinstance(version, int) or version < 1:
        raise ModelFileError(path, f"bad format version {version!r}")
    if version > format_version:
        raise ModelFileError(
            path, f"format version {version} is newer than this fourierjax reads "
            f"({format_version}); upgrade fourierjax"
        )
    if header.get("phase_convention", "sine") != "sine":
        raise ModelFileError(path, f"unknown phase convention {header['phase_convention']!r}")
    return header, data


def _check_real(path: str, name: str, a: np.ndarray) -> np.ndarray:
    """``a`` as float64 if it holds finite real numbers (float or int dtype), else ModelFileError."""
    if a.dtype.kind not in "fiu":
        raise ModelFileError(path, f"array {name!r} has dtype {a.dtype}, expected real numbers "
                                   "(float64)")
    a = a.astype(np.float64)
    if not np.isfinite(a).all():
        raise ModelFileError(path, f"array {name!r} holds NaN or infinite values")
    return a


def _check_arrays(path: str, header: dict, data: dict, trailing: dict) -> tuple[str, ...]:
    """Check the Fourier arrays against the header's C and N; returns the channel names.

    Also converts every array of ``data`` to float64 in place, after checking that it holds
    finite real numbers. ``trailing``: array name -> its shape with ``"C"`` / ``"N"`` standing
    for the counts.
    """
    missing = [k for k in trailing if k not in data]
    if missing:
        raise ModelFileError(path, f"missing array(s) {missing}")
    for k in data:
        data[k] = _check_real(path, k, data[k])
    names = header.get("channel_names", [])
    if not isinstance(names, list) or not all(isinstance(n, str) for n in names):
        raise ModelFileError(path, f"channel_names must be a list of strings, got {names!r:.80}")
    names = tuple(names)
    counts = {"C": header.get("num_channels"), "N": header.get("num_harmonics")}
    for key, n in (("num_channels", counts["C"]), ("num_harmonics", counts["N"])):
        if isinstance(n, bool) or not isinstance(n, int) or n < 0:
            raise ModelFileError(path, f"{key} must be a non-negative integer, got {n!r}")
    expected = {k: tuple(counts.get(d, d) for d in dims) for k, dims in trailing.items()}
    shapes = {k: data[k].shape for k in trailing}
    if shapes != expected or (names and len(names) != counts["C"]):
        got = ", ".join(f"{k} {v}" for k, v in shapes.items())
        raise ModelFileError(
            path, f"inconsistent shapes: {got}, {len(names)} channel names, header says "
            f"C={counts['C']}, N={counts['N']}"
        )
    return names


def save_model(path, model, *, motion=None, provenance: dict | None = None,
               alignment: str = "none", body_map=None, contact_intervals=None, knee_speed_rad_s=None) -> None:
    """Write one FourierModel (no batch axis) to ``path``, written whole or not at all.

    Format ``fourierjax.fourier_model``, version 1: an uncompressed ``.npz`` holding ``header``
    (a 0-d unicode array, one JSON object: ``format``, ``version``, ``representation``
    ("euler" | "expmap" | "tangent"), ``channel_names``, ``num_channels`` C, ``num_harmonics`` N,
    ``phase_convention`` "sine", ``skeleton`` (null or names, parents, channels,
    end_site_parents, frame_time_s), ``provenance`` (free JSON), ``alignment``); float64
    ``offset [C]``, ``amplitude [C, N]`` (A_n >= 0), ``phase [C, N]`` (radians, Unuma eq. 1
    sine convention), ``omega []`` (rad/s, in [`OMEGA_MIN_RAD_S`, `OMEGA_MAX_RAD_S`]); with a
    skeleton, ``skeleton_offsets [J, 3]`` and ``skeleton_end_site_offsets [E, 3]`` (file units),
    so that ``fourierjax synth`` can write a BVH without the source clip. Version 2 adds
    ``body_map`` to the header (`fourierjax.body.BodyMap.to_dict`, joints by name); a file
    without a body map is written as version 1, which older readers still read. Version 3 adds
    ``contact_intervals`` (``[[left start, left end], [right start, right end]]``, radians of the
    cycle; `fourierjax.gait.contact_intervals`); a file without them keeps version 1 or 2.
    Version 4 adds ``frames [K, 4]`` (wxyz), the clip means of a ``"tangent"`` model, only
    written for such models (other models keep versions 1-3). An optional ``knee_speed_rad_s``
    (``[left, right]`` rad/s, `fourierjax.gait.fit_knee_speed`) in the header needs no version:
    a reader that does not know it ignores it.

    Arguments:
        path: output file (written as given; conventionally ``*.npz``).
        model: a FourierModel.
        motion: the source Motion (its skeleton and frame time are stored), or None.
        provenance: JSON-able fit details.
        alignment: the phase-alignment event name.
        body_map: the skeleton's `fourierjax.body.BodyMap` (e.g. ``ClipFit.body_map``), stored
            with ``motion``'s skeleton, or None.
        contact_intervals: ``[2, 2]`` contact phases of the feet (radians), or None.
        knee_speed_rad_s: ``[2]`` the source clip's largest knee speed per leg (rad/s), or None.

    Raises:
        UserError, before anything is written, for what `load_model` would refuse.
    """
    provenance = _jsonable(provenance or {})
    try:
        json.dumps(provenance)
    except (TypeError, ValueError) as err:
        raise UserError(f"save_model: `provenance` must hold only JSON values (dict, list, str, "
                        f"number, bool, None, NumPy arrays): {err}") from None
    if body_map is not None and motion is None:
        raise UserError("save_model: `body_map` needs `motion` (the skeleton it names)")
    version = 2 if body_map is not None else 1
    intervals = _contact_intervals(os.fspath(path), contact_intervals, UserError)
    if intervals is not None:
        version = 3
    knee_speed = _knee_speed(os.fspath(path), knee_speed_rad_s, UserError)
    if getattr(model, "frames", None) is not None:
        version = FORMAT_VERSION  # a tangent model: its joints' clip means
    header = _header(FORMAT_NAME, version, model, "model", skeleton=None,
                     provenance=provenance, alignment=alignment)
    arrays = {k: getattr(model, k) for k in _MODEL_ARRAYS}
    if getattr(model, "frames", None) is not None:
        arrays["frames"] = model.frames
    _refuse_non_finite("save_model", "model", arrays, path)
    if not float(np.asarray(model.omega)) > 0:
        raise UserError(f"save_model: `model` omega must be > 0 rad/s, got "
                        f"{float(np.asarray(model.omega))}; not written to {os.fspath(path)}")
    problem = _model_problem(model.representation, model.channel_names, model.amplitude,
                             model.omega)
    if problem:
        raise UserError(f"save_model: `model`: {problem}; not written to {os.fspath(path)}")
    if motion is not None:
        topo = motion.topology
        header["skeleton"] = {
            "names": list(topo.names),
            "parents": list(topo.parents),
            "channels": [list(c) for c in topo.channels],
            "end_site_parents": list(topo.end_site_parents),
            "frame_time_s": float(motion.frame_time_s),
        }
        arrays["skeleton_offsets"] = motion.offsets
        arrays["skeleton_end_site_offsets"] = np.asarray(motion.end_site_offsets,
                                                         np.float64).reshape(-1, 3)
        if body_map is not None:
            if tuple(body_map.joint_names) != tuple(topo.names):
                raise UserError("save_model: `body_map` was made for another skeleton than `motion`'s")
            header["body_map"] = body_map.to_dict()
    if intervals is not None:
        header["contact_intervals"] = intervals.tolist()
    if knee_speed is not None:
        header["knee_speed_rad_s"] = knee_speed.tolist()
    _write_archive(path, header, arrays)


def _knee_speed(path: str, value, error):
    """``value`` as a finite ``[2]`` float64 array >= 0 (None stays None), else ``error``."""
    return _contact_intervals(path, value, error, shape=(2,), least=0.0, wrap=False,
                              what="knee_speed_rad_s must be 2 finite numbers >= 0 (left, right) rad/s")


def _contact_intervals(path: str, value, error, *, shape=(2, 2), least=-np.inf, wrap=True,
                       what="contact_intervals must be 2 x 2 finite numbers (left, right) x (start, end) radians"):
    """``value`` as a finite ``[2, 2]`` float64 array, wrapped into [0, 2 pi) (None stays None),
    else ``error`` (another ``shape``, a ``least`` value, no wrap and the message ``what`` serve
    `_knee_speed`)."""
    if value is None:
        return None
    try:
        a = np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError):
        a = None
    if a is None or a.shape != shape or not np.all(np.isfinite(a)) or np.any(a < least):
        if error is UserError:
            raise UserError(f"save_model: {what}; not written to {path}")
        raise error(path, what)
    return np.mod(a, 2 * np.pi) if wrap else a


def load_model(path) -> ModelFile:
    """Read a model file written by :func:`save_model`.

    Raises:
        ModelFileError (a ``UserError``, one line naming the path): no such file (this one is
        also a ``FileNotFoundError``), not an npz archive or a damaged, encrypted or oddly
        compressed one, members that declare more bytes than they hold, a header that is not
        JSON, not this format, a newer version, bad shapes, non-finite or non-real arrays,
        channel names of the other representation, negative amplitudes, ``omega`` outside
        [`OMEGA_MIN_RAD_S`, `OMEGA_MAX_RAD_S`], a bad skeleton record.
    """
    from fourierjax.fourier import FourierModel

    path = os.fspath(path)
    if not os.path.exists(path):
        raise _MissingModelFile(path)
    header, data = _read_archive(path, FORMAT_NAME, FORMAT_VERSION, "model")
    names = _check_arrays(path, header, data, {"offset": ("C",), "amplitude": ("C", "N"),
                                                "phase": ("C", "N"), "omega": ()})
    try:
        frames = data.get("frames")
        if frames is not None and not np.allclose(np.linalg.norm(frames, axis=-1), 1.0, atol=1e-5):
            raise ModelFileError(path, "frames must be unit quaternions (wxyz)")
        model = FourierModel(*(data[k] for k in _MODEL_ARRAYS),
                             header.get("representation", ""), names, frames)
    except (ValueError, TypeError) as err:
        raise ModelFileError(path, str(err)) from None
    problem = _model_problem(model.representation, names, data["amplitude"], data["omega"])
    if problem:
        raise ModelFileError(path, problem)
    provenance = header.get("provenance")
    provenance = {} if provenance is None else provenance
    if not isinstance(provenance, dict):
        raise ModelFileError(path, f"provenance must be a JSON object, got {provenance!r:.80}")
    alignment = header.get("alignment")
    alignment = "none" if alignment is None else alignment
    if not isinstance(alignment, str):
        raise ModelFileError(path, f"alignment must be a string, got {alignment!r:.80}")
    sk = header.get("skeleton")
    topology = offsets = ends = frame_time = None
    if sk is not None:
        from fourierjax.skeleton import Topology

        try:
            topology = Topology(
                names=tuple(sk["names"]),
                parents=tuple(int(p) for p in sk["parents"]),
                channels=tuple(tuple(c) for c in sk["channels"]),
                end_site_parents=tuple(int(p) for p in sk["end_site_parents"]),
            )
            offsets = data["skeleton_offsets"]
            ends = data["skeleton_end_site_offsets"]
            frame_time = sk["frame_time_s"]
        except (KeyError, TypeError, ValueError) as err:
            raise ModelFileError(path, f"bad skeleton record: {err}") from None
        # What `template_motion` builds a Motion from: checked here, where the path is known.
        for name, a, rows in (("skeleton_offsets", offsets, topology.num_joints),
                              ("skeleton_end_site_offsets", ends, topology.num_end_sites)):
            if a.shape != (rows, 3):
                raise ModelFileError(path, f"bad skeleton record: {name} has shape {a.shape}, "
                                           f"expected ({rows}, 3) for its {rows} entries")
        if (isinstance(frame_time, bool) or not isinstance(frame_time, int | float)
                or not (math.isfinite(frame_time) and frame_time > 0)):
            raise ModelFileError(path, "bad skeleton record: frame_time_s must be a finite "
                                       f"number > 0, got {frame_time!r}")
        frame_time = float(frame_time)
    stored = header.get("body_map")
    body_map = None
    if stored is not None:
        if topology is None:
            raise ModelFileError(path, "a body_map without a skeleton record")
        from fourierjax.body import BodyMapError, body_map_from_dict

        if not isinstance(stored, dict):
            raise ModelFileError(path, f"body_map must be a JSON object, got {stored!r:.80}")
        try:
            body_map = body_map_from_dict(stored, topology)
        except (BodyMapError, KeyError, TypeError, ValueError) as err:
            raise ModelFileError(path, f"bad body_map record: {err}") from None
    intervals = _contact_intervals(path, header.get("contact_intervals"), ModelFileError)
    knee_speed = _knee_speed(path, header.get("knee_speed_rad_s"), ModelFileError)
    return ModelFile(model, topology, offsets, ends, frame_time, provenance, alignment, body_map, intervals,
                     knee_speed)


_EULER_NAME = re.compile(r"\.[XYZ]rotation$")
_EXPMAP_NAME = re.compile(r"\.expmap[0-2]$")


def _model_problem(representation: str, names, amplitude, omega) -> str | None:
    """What the model format forbids in a model's values, in words (None when nothing is):
    channel names of the other representation, a negative amplitude (the format stores
    A_n >= 0, signs folded into the phase), ω outside the physical range."""
    amplitude = np.asarray(amplitude, np.float64)
    omega = float(np.asarray(omega))
    other = {"expmap": (_EULER_NAME, "an Euler"), "euler": (_EXPMAP_NAME, "an expmap"),
             "tangent": (_EULER_NAME, "an Euler")}
    if representation in other:
        pattern, what = other[representation]
        bad = [n for n in names if pattern.search(n)]
        if bad:
            return (f"representation is {representation!r} but channel {bad[0]!r} is {what} "
                    f"channel ({len(bad)} such channels)")
    if amplitude.size and amplitude.min() < 0:
        c, n = np.unravel_index(int(np.argmin(amplitude)), amplitude.shape)
        name = f" ({names[c]})" if c < len(names) else ""
        return (f"amplitude[{c}, {n}]{name} = {amplitude[c, n]:g} is negative (the format "
                "stores A_n >= 0, signs folded into the phase)")
    if not omega > 0:
        return f"omega must be > 0 rad/s, got {omega}"
    if not OMEGA_MIN_RAD_S <= omega <= OMEGA_MAX_RAD_S:
        return (f"omega = {omega:g} rad/s is outside the physical range [{OMEGA_MIN_RAD_S:g}, "
                f"{OMEGA_MAX_RAD_S:g}] rad/s")
    return None


def _refuse_non_finite(fn: str, what: str, arrays: dict, path) -> None:
    """What the loaders refuse is not written in the first place."""
    bad = [k for k, v in arrays.items() if not np.isfinite(np.asarray(v)).all()]
    if bad:
        raise UserError(f"{fn}: `{what}` holds NaN or infinite values in {bad}; not written "
                        f"to {os.fspath(path)}")


def save_characteristic(path, char, *, a: str = "", b: str = "", alignment: str = "none",
                        joint_speed: dict | None = None) -> None:
    """Write one (unstacked) `fourierjax.style.Characteristic` to ``path``.

    Format ``fourierjax.fourier_characteristic``, version 1: the archive layout of `save_model`,
    whose header has its first seven keys plus ``a``, ``b`` (the sources of A and B) and
    ``alignment``, and float64 arrays ``offset [C]`` (A0_A - A0_B), ``amplitude [C, N]``
    (A_A - A_B, may be negative), ``phase [C, N]`` (phi_A - phi_B wrapped to (-pi, pi]),
    ``phasor [C, N, 2]`` (c_A - c_B with c = (A cos phi, A sin phi)), ``log_omega []``
    (log omega_A / omega_B); tangent characteristics also ``frames [K, 4]`` (wxyz, M_B^-1 M_A)
    and ``aligned [C, N, 2]`` (per-joint polar differences, `style.characteristic`);
    exponential-map characteristics also ``reference [C]`` (B's offsets: the branch
    `style.superpose` adds them on; files without it add on the base's own branch). Apply one
    with ``style.superpose(base, [char], [weight])``.

    Arguments:
        path: output file (conventionally ``*.npz``).
        char: ``style.characteristic(A, B)`` (Unuma 1995 eq. 7).
        a: where A came from (free text).
        b: where B came from (free text).
        alignment: the phase-alignment event of the models.
        joint_speed: optional header entry ``{"per_second", "per_radian", "unit"}``: the
            fastest joint of A and B (`style.peak_joint_speed`) in body heights, which
            ``fourierjax synth --add`` limits the superposition to (files without it: no limit).
    """
    extra = {} if joint_speed is None else {"joint_speed": dict(joint_speed)}
    header = _header(CHARACTERISTIC_FORMAT_NAME, CHARACTERISTIC_FORMAT_VERSION, char,
                     "characteristic", a=a, b=b, alignment=alignment, **extra)
    arrays = {k: getattr(char, k) for k in _CHARACTERISTIC_ARRAYS}
    for k in _TANGENT_CHARACTERISTIC_ARRAYS + _REFERENCE_CHARACTERISTIC_ARRAYS:  # when present
        if getattr(char, k, None) is not None:
            arrays[k] = getattr(char, k)
    _refuse_non_finite("save_characteristic", "char", arrays, path)
    _write_archive(path, header, arrays)


def load_characteristic(path):
    """Read a characteristic file written by :func:`save_characteristic`.

    Returns:
        ``(Characteristic, header dict)``; the leaves are float64 NumPy arrays.
    Raises:
        ModelFileError (a ``UserError``, one line naming the path): no such file, not an npz
        archive, not this format, a newer version, bad shapes.
    """
    from fourierjax.style import Characteristic

    path = os.fspath(path)
    if not os.path.exists(path):
        raise _MissingModelFile(path)
    header, data = _read_archive(path, CHARACTERISTIC_FORMAT_NAME, CHARACTERISTIC_FORMAT_VERSION,
                                 "characteristic")
    names = _check_arrays(path, header, data, {"offset": ("C",), "amplitude": ("C", "N"),
                                                "phase": ("C", "N"), "phasor": ("C", "N", 2),
                                                "log_omega": ()})
    extra = {k: data[k] for k in _TANGENT_CHARACTERISTIC_ARRAYS + _REFERENCE_CHARACTERISTIC_ARRAYS
             if k in data}
    if "reference" in extra and extra["reference"].shape != data["offset"].shape:
        raise ModelFileError(path, f"inconsistent shapes: reference {extra['reference'].shape}, "
                                   f"offset {data['offset'].shape}")
    char = Characteristic(**{k: data[k] for k in _CHARACTERISTIC_ARRAYS}, **extra,
                          representation=str(header.get("representation", "")),
                          channel_names=names)
    return char, header
