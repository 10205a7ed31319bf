"""Bundled CMU motion-capture clips (walks, runs, stylized walks) and their loader.

The data used in this project was obtained from mocap.cs.cmu.edu. The database was created
with funding from NSF EIA-0196217. See `README.md` and `LICENSE-CMU.txt` in this folder.

Quirks handled by `load` (and kept by `load(name, raw=True)`):

* `cmu_mb` clips (CMU 2010 "MotionBuilder-friendly" BVH release) start with a synthetic
  T-pose frame (whole-degree angles, mostly zero) that the converter inserted; `load` drops it.
* `07_12` also has an all-zero frame 1 (a glitch of the original take); `load` drops it too.
* `cmu_stylized` clips have no synthetic frame; nothing is dropped. Their root Euler angles
  wrap and pass gimbal lock (fit quaternions/expmaps), and 142_02 has a left-arm glitch
  around frame 1140 (see `describe`).
"""

from __future__ import annotations

import builtins
import functools
import pathlib

import numpy as np

from fourierjax.errors import UserError
from fourierjax.io.bvh import Motion, read_bvh

__all__ = ["describe", "detect_rest_frames", "list", "load", "path"]

_ROOT = pathlib.Path(__file__).resolve().parent

_MB_SOURCE = "chrystianosaraujo/motion-viewer@6d7ca60c300f123528be0fd0939cf7a584a13f65"
_STYLIZED_SOURCE = "svdhcn/Style_Learning@d69de4194358c56781e239659d37ea672961e3d7"
_MB_NOTES = (
    "CMU 2010 MotionBuilder-friendly BVH (cgspeed). Frame 0 is a synthetic T-pose inserted by "
    "the converter (whole-degree angles; its root position copies frame 1); load() drops it. "
    "Frame Time .0083333 s (120 fps nominal). 22 channels never move: LHipJoint, RHipJoint, "
    "the shoulders and HandIndex1 joints (all angles), and Z and Y of both hands."
)
_STYLIZED_NOTES = (
    "CMU subject 142 'Stylized Walks', retargeted by a third party to the standard CMU "
    "skeleton (other bone lengths than cmu_mb, all End Site offsets zero). No T-pose: frame 0 "
    "is motion. The subject walks back and forth, mostly along X: segment gait cycles before "
    "fitting. The root turns around, so its ZYX Euler angles pass gimbal lock and wrap (jumps "
    "of more than 90 degrees between frames while the rotation moves under 4 degrees): fit "
    "quaternions or continuous exponential maps, not raw Euler channels. CRLF line endings. "
    "Frame Time 0.008333 s (120 fps nominal)."
)


def _mb(name, description, sha256, frames, rest=1, notes=""):
    return {
        "name": name,
        "group": "cmu_mb",
        "subject": name.split("_")[0],
        "trial": name,
        "description": description,
        "fps": 120.0,
        "frames_in_file": frames,
        "rest_frames": rest,
        "notes": (_MB_NOTES + " " + notes).strip(),
        "source": f"{_MB_SOURCE}:data/{name.split('_')[0]}/{name}.bvh",
        "sha256": sha256,
    }


def _stylized(name, description, sha256, frames, notes=""):
    return {
        "name": name,
        "group": "cmu_stylized",
        "subject": name.split("_")[0],
        "trial": name,
        "description": description,
        "fps": 120.0,
        "frames_in_file": frames,
        "rest_frames": 0,
        "notes": (_STYLIZED_NOTES + " " + notes).strip(),
        "source": f"{_STYLIZED_SOURCE}:two_cmu_retargeted/{name}.bvh",
        "sha256": sha256,
    }


_CATALOG: dict[str, dict] = {
    c["name"]: c
    for c in [
        _mb("02_01", "walk",
            "b2558c5701c98f3382ae242860eebcecfce817fa53ca879bfea753a36390d2bc", 344),
        _mb("02_03", "run/jog",
            "8a67fae01bea08a7a75057ce806eafe3deb1b3d45d82ef7126fb7bea70d08ef0", 174),
        _mb("07_01", "walk",
            "cdfa9eb68a9e5a684a401fd8776be6a477272f9174cb80dd14e5dad6b736d82b", 317),
        _mb("07_04", "slow walk",
            "214f247a78c37e65450d38bfd1c2bb63c0d69a39d76cf20db99d4ec18e9d9532", 450),
        _mb("07_12", "brisk walk",
            "39a3de0fc98beda340df2cbbc62bd4e528eb09cce5b5d11bbc05f62e0a799bda", 264, rest=2,
            notes="Frame 1 is also all zeros (root at the origin, every angle 0): a glitch "
            "of the original take; load() drops frames 0 and 1."),
        _mb("09_01", "run",
            "ab916afe80c8808fc7b7febd0138ba651ddc394260a58c22e747a3eefb6b9007", 149),
        _mb("09_02", "run",
            "de1abe0fcf7d00d376c61d449c7905b866db8bc3eaeb0823d0aa01ce0136033d", 131),
        _stylized("142_02", "stylized walk (clumsy)",
                  "67fb0699a523640dd0a13f3fde767eba9ecc939cbb09d3572d227ec7393e6e45", 1882,
                  notes="Left-arm glitch around frame 1140: LeftShoulder, LeftArm and "
                  "LeftForeArm swing out and back within about 5 frames (LeftArm turns 60 "
                  "degrees from frame 1140 to 1141); avoid that stretch for arm channels."),
        _stylized("142_08", "stylized walk (happy)",
                  "4a8afcc58a0ac1526183a505af896daea2a522676055669fca12e97ed0e7d5e4", 3033),
    ]
}  # fmt: skip


def list() -> builtins.list[str]:  # noqa: A001 - the public name is part of the API
    """Names of the bundled clips, e.g. `["02_01", ..., "142_08"]` (CMU subject_trial)."""
    return builtins.list(_CATALOG)


def _entry(name: str) -> dict:
    key = name[:-4] if isinstance(name, str) and name.endswith(".bvh") else name
    if not isinstance(key, str) or key not in _CATALOG:
        raise UserError(
            f"no bundled clip named {name!r}; the bundled clips are: {', '.join(_CATALOG)}"
        )
    return _CATALOG[key]


def path(name: str) -> pathlib.Path:
    """Path of the bundled BVH file of clip `name` (e.g. `"07_01"`); UserError if unknown."""
    entry = _entry(name)
    return _ROOT / entry["group"] / f"{entry['name']}.bvh"


def describe(name: str) -> dict:
    """What is known about clip `name`, as a JSON-serialisable dict.

    Returns:
        keys `name`, `group` (`"cmu_mb"` or `"cmu_stylized"`), `subject` (CMU subject
        number as a string, e.g. `"07"`), `trial`, `description` (from the CMU index: `"walk"`,
        `"run/jog"`, `"slow walk"`, `"brisk walk"`, `"run"`, `"stylized walk (clumsy)"`, ...),
        `fps` (nominal, 120.0), `frames_in_file`, `rest_frames` (leading synthetic frames that
        `load` drops), `frames` (frames after `load`), `notes`, `source` (repository@commit:path
        it was copied from), `sha256` (of the bundled file), `path`.
    """
    entry = dict(_entry(name))
    entry["frames"] = entry["frames_in_file"] - entry["rest_frames"]
    entry["path"] = str(path(name))
    return entry


@functools.cache
def _read(name: str) -> Motion:
    return read_bvh(path(name))  # Motion arrays are read-only, so sharing the cache is safe


def load(name: str, *, raw: bool = False) -> Motion:
    """Load bundled clip `name` as a `Motion` (degrees, CMU units, 120 fps).

    Arguments:
        name: one of `list()`, e.g. `"07_01"`.
        raw: keep every frame of the file. By default the leading synthetic frames (the
            T-pose of `cmu_mb` clips, and the zero frame of `07_12`) are dropped.

    Returns:
        the `Motion`; UserError (listing the valid names) for an unknown name.
    """
    entry = _entry(name)
    motion = _read(entry["name"])
    return motion if raw else motion[entry["rest_frames"] :]


#: Degrees of round-off within which `detect_rest_frames` reads an angle as zero or whole (a
#: captured frame of the bundled clips has an angle 0.45° or more off a whole degree).
REST_TOLERANCE_DEG = 1e-6


def detect_rest_frames(motion: Motion) -> int:
    """Number of leading frames that are synthetic rest poses rather than captured motion.

    A frame counts as synthetic if all its rotation angles are zero, or if they are all whole
    degrees with at least half of them zero: the signature of the T-pose that BVH converters
    (cgspeed's CMU release) insert as frame 0. Captured angles are never all whole numbers.
    "Zero" and "whole" allow `REST_TOLERANCE_DEG` of round-off: a clip turned to another up
    axis in memory (a Z-up export's root holds the 90° turn) carries 1e-15° of it. Counting
    stops at the first captured frame; a clip made only of such frames returns
    `motion.num_frames`.

    Arguments:
        motion: a `Motion` with at least one rotation channel.

    Returns:
        the count (0 if frame 0 is captured motion).
    """
    rotation = [
        k
        for k, name in enumerate(c for chans in motion.topology.channels for c in chans)
        if name.endswith("rotation")
    ]
    if not rotation:
        return 0
    angles = np.asarray(motion.channels)[:, rotation]
    zero = np.abs(angles) <= REST_TOLERANCE_DEG
    all_zero = zero.all(axis=1)
    whole = np.abs(angles - np.round(angles)) <= REST_TOLERANCE_DEG
    synthetic = whole.all(axis=1) & (2 * zero.sum(axis=1) >= len(rotation))
    rest = all_zero | synthetic
    return int(motion.num_frames if rest.all() else np.argmin(rest))
