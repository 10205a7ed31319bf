"""Fourier model files: a versioned ``.npz`` with a JSON header (never pickle).

Format ``fourierjax.fourier_model``, version 1. An uncompressed NumPy ``.npz`` archive holding:

* ``header``: a 0-d unicode array with one JSON object::

      {"format": "fourierjax.fourier_model", "version": 1,
       "representation": "euler" | "expmap", "channel_names": [...C names...],
       "num_channels": C, "num_harmonics": N, "phase_convention": "sine",
       "skeleton": null | {"names": [...], "parents": [...], "channels": [[...], ...],
                           "end_site_parents": [...], "frame_time_s": float},
       "provenance": {...free JSON: source file, frames used, omega per method, metrics...},
       "alignment": "left_heel_strike" | "left_hip_flexion" | "none" | ...}

* ``offset [C]``, ``amplitude [C, N]``, ``phase [C, N]`` (radians, Unuma eq. 1 sine
  convention), ``omega []`` (rad/s), all float64;
* if the header has a skeleton: ``skeleton_offsets [J, 3]``, ``skeleton_end_site_offsets [E, 3]``
  (file units), so that ``fourierjax synth`` can write a BVH without the source clip.

Files are read with ``allow_pickle=False``. A file that is not such an archive, has another format
name, a newer version, or inconsistent shapes raises :class:`ModelFileError` naming the path.
"""

from __future__ import annotations

import dataclasses
import io
import json
import os
import zipfile

import numpy as np

from fourierjax.errors import UserError

FORMAT_NAME = "fourierjax.fourier_model"
FORMAT_VERSION = 1

__all__ = ["FORMAT_NAME", "FORMAT_VERSION", "ModelFileError", "ModelFile", "save_model",
           "load_model"]


class ModelFileError(UserError):
    """A model file that cannot be read: carries ``path`` and a message."""

    def __init__(self, path, message: str):
        self.path = str(path)
        self.message = message
        super().__init__(f"{self.path}: {message}")


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

    def template_motion(self):
        """A one-frame Motion on the stored skeleton (for ``motion_from_features``), or None."""
        if self.topology is None:
            return None
        from fourierjax.io.bvh import Motion

        return Motion(self.topology, self.offsets, self.end_site_offsets,
                      np.zeros((1, self.topology.num_channels)), self.frame_time_s or 1 / 120)


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


def save_model(path, model, *, motion=None, provenance: dict | None = None,
               alignment: str = "none") -> None:
    """Write one FourierModel (no batch axis) to ``path`` (format above).

    Arguments:
        path: output file (written as given; conventionally ``*.npz``).
        model: a FourierModel; motion: the source Motion (its skeleton and frame time are stored
        so ``synth`` can write BVH), or None; provenance: JSON-able fit details; alignment: the
        phase-alignment event name.
    """
    amp = np.asarray(model.amplitude, np.float64)
    if amp.ndim != 2:
        raise UserError(f"save_model: one model expected, amplitude has shape {amp.shape}")
    header = {
        "format": FORMAT_NAME,
        "version": FORMAT_VERSION,
        "representation": model.representation,
        "channel_names": list(model.channel_names),
        "num_channels": int(amp.shape[0]),
        "num_harmonics": int(amp.shape[1]),
        "phase_convention": "sine",
        "skeleton": None,
        "provenance": _jsonable(provenance or {}),
        "alignment": alignment,
    }
    arrays = {
        "offset": np.asarray(model.offset, np.float64),
        "amplitude": amp,
        "phase": np.asarray(model.phase, np.float64),
        "omega": np.asarray(model.omega, np.float64),
    }
    if motion is not None:
        topo = motion.topology
        header["skeleton"] = {
            "names": list(topo.names),
            "parents": list(topo.parents),
            "channels": [list(c) for c in topo.channels],
            "end_site_parents": list(topo.end_site_parents),
            "frame_time_s": float(motion.frame_time_s),
        }
        arrays["skeleton_offsets"] = np.asarray(motion.offsets, np.float64)
        arrays["skeleton_end_site_offsets"] = np.asarray(motion.end_site_offsets,
                                                         np.float64).reshape(-1, 3)
    arrays["header"] = np.array(json.dumps(header))
    buf = io.BytesIO()
    np.savez(buf, **arrays)
    with open(path, "wb") as f:
        f.write(buf.getvalue())


def load_model(path) -> ModelFile:
    """Read a model file written by :func:`save_model`.

    Raises:
        ModelFileError: not an npz archive, not this format, a newer version, bad shapes.
        FileNotFoundError: no such file.
    """
    from fourierjax.fourier import FourierModel

    path = os.fspath(path)
    if not os.path.exists(path):
        raise FileNotFoundError(2, "No such file", path)
    try:
        with np.load(path, allow_pickle=False) as z:
            data = {k: z[k] for k in z.files}
    except (zipfile.BadZipFile, ValueError, OSError, EOFError) as err:
        raise ModelFileError(path, f"not a fourierjax model file (.npz): {err}") from None
    if "header" not in data:
        raise ModelFileError(path, "not a fourierjax model file: no 'header' entry")
    try:
        header = json.loads(str(data["header"]))
    except (json.JSONDecodeError, TypeError) as err:
        raise ModelFileError(path, f"header is not valid JSON: {err}") from None
    if not isinstance(header, dict) or header.get("format") != FORMAT_NAME:
        got = header.get("format") if isinstance(header, dict) else None
        raise ModelFileError(path, f"format is {got!r}, expected {FORMAT_NAME!r}")
    version = header.get("version")
    if not isinstance(version, int) or version < 1:
        raise ModelFileError(path, f"bad format version {version!r}")
    if version > FORMAT_VERSION:
        raise ModelFileError(
            path, f"format version {version} is newer than this fourierjax reads "
            f"({FORMAT_VERSION}); upgrade fourierjax"
        )
    for key in ("offset", "amplitude", "phase", "omega"):
        if key not in data:
            raise ModelFileError(path, f"missing array {key!r}")
    names = tuple(header.get("channel_names", ()))
    C, N = header.get("num_channels"), header.get("num_harmonics")
    amp = data["amplitude"]
    if (amp.shape != (C, N) or data["phase"].shape != (C, N) or data["offset"].shape != (C,)
            or data["omega"].shape != () or (names and len(names) != C)):
        raise ModelFileError(
            path, f"inconsistent shapes: amplitude {amp.shape}, phase {data['phase'].shape}, "
            f"offset {data['offset'].shape}, omega {data['omega'].shape}, {len(names)} channel "
            f"names, header says C={C}, N={N}"
        )
    if header.get("phase_convention", "sine") != "sine":
        raise ModelFileError(path, f"unknown phase convention {header['phase_convention']!r}")
    try:
        model = FourierModel(data["offset"], amp, data["phase"], data["omega"],
                             header.get("representation", ""), names)
    except (ValueError, TypeError) as err:
        raise ModelFileError(path, str(err)) from None
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
            offsets = np.asarray(data["skeleton_offsets"], np.float64)
            ends = np.asarray(data["skeleton_end_site_offsets"], np.float64)
            frame_time = float(sk["frame_time_s"])
        except (KeyError, TypeError, ValueError) as err:
            raise ModelFileError(path, f"bad skeleton record: {err}") from None
    return ModelFile(model, topology, offsets, ends, frame_time,
                     header.get("provenance", {}), header.get("alignment", "none"))
