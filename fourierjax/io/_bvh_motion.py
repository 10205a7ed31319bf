"""The `Motion` container of a BVH clip and `BVHError`, the one error type of BVH files."""

from __future__ import annotations

import contextlib
import contextvars
import dataclasses
import math
from typing import TYPE_CHECKING

import numpy as np

from fourierjax.errors import UserError
from fourierjax.skeleton import Topology

if TYPE_CHECKING:  # pragma: no cover
    from fourierjax.skeleton import Skeleton

class BVHError(UserError):
    """A BVH file that cannot be read: names the file, the 1-based line (or None) and the problem.

    A `fourierjax.errors.UserError` (so also a `ValueError`): `except UserError` catches it.

    `str(err)` is `"path:line: message"`, or `"path: message"` when no line applies (a missing
    or unreadable file). Attributes: `path` (str), `line` (int | None), `message` (str).
    """

    def __init__(self, path: str, line: int | None, message: str):
        super().__init__(path, line, message)  # args kept so that the error pickles
        self.path = str(path)
        self.line = line
        self.message = message

    def __str__(self) -> str:
        if self.line is None:
            return f"{self.path}: {self.message}"
        return f"{self.path}:{self.line}: {self.message}"



# The shortest frame time accepted (1 MHz). Real capture runs at 10 kHz at most; a smaller value
# is a corrupt header, and a subnormal one would make `Motion.fps` infinite.
MIN_FRAME_TIME_S = 1e-6
# The longest frame time accepted (one frame a minute). A motion file sampled more slowly is a
# corrupt header: "Frame Time: 1e300" made a clip's duration infinite and its frequencies 0.
MAX_FRAME_TIME_S = 60.0
# The largest magnitude of a channel value or OFFSET accepted. Real clips stay far below it (an
# angle of 1e6 degrees, a position of 1 km in millimetres); 1e308 was accepted and float32
# forward kinematics then gave inf and NaN.
MAX_ABS_VALUE = 1e6


def _show(s: str, limit: int = 40) -> str:
    """`repr(s)`, shortened: error messages stay one readable line whatever the input."""
    return repr(s if len(s) <= limit else s[:limit] + "...")


# -- Motion ------------------------------------------------------------------------------


# Set by the BVH reader while it builds a Motion from arrays it has just made and holds no
# other reference to: they are frozen in place instead of copied (a copy of a 100 MB file's
# frames is 115 MB more at the peak).
_OWNED = contextvars.ContextVar("fourierjax_bvh_owned_arrays", default=False)


@contextlib.contextmanager
def _owned_arrays():
    token = _OWNED.set(True)
    try:
        yield
    finally:
        _OWNED.reset(token)


def _frozen_array(x, name: str, ndim: int) -> np.ndarray:
    if (_OWNED.get() and isinstance(x, np.ndarray) and x.dtype == np.float64
            and x.ndim == ndim and x.flags.c_contiguous):
        x.setflags(write=False)
        return x
    try:
        a = np.array(x, dtype=np.float64)  # always a private copy
    except (TypeError, ValueError) as err:
        raise UserError(f"Motion: `{name}` is not a numeric array ({err})") from None
    if a.ndim != ndim:
        raise UserError(f"Motion: `{name}` must have {ndim} dimensions, got shape {a.shape}")
    a.setflags(write=False)
    return a


@dataclasses.dataclass(frozen=True, eq=False, repr=False)
class Motion:
    """A BVH clip held in NumPy: the skeleton layout plus one row of channel values per frame.

    Values are stored exactly as the file has them: positions in file units (CMU: 1 unit ~
    0.0564 m), rotations in **degrees**, channels in file order (`topology.channels`). Position
    channels give a joint's local translation and *replace* the matching OFFSET components;
    that semantic is applied by `fourierjax.kinematics`, not here. Arrays are read-only copies,
    so a `Motion` can be shared and cached safely; use `with_channels` or slicing for new ones.

    Arguments:
        topology: `fourierjax.skeleton.Topology` (names, parents, channel names, End Sites).
        offsets: `[J, 3]` float64, each joint's OFFSET from its parent (file units).
        end_site_offsets: `[E, 3]` float64, each End Site's OFFSET from its parent joint.
        channels: `[F, C]` float64, `C = topology.num_channels`.
        frame_time_s: seconds per frame (> 0).
        source: where the clip came from (a path) or None.
    """

    topology: Topology
    offsets: np.ndarray
    end_site_offsets: np.ndarray
    channels: np.ndarray
    frame_time_s: float
    source: str | None = None

    def __post_init__(self):
        if not isinstance(self.topology, Topology):
            raise TypeError(f"Motion: `topology` must be a Topology, got {type(self.topology)}")
        topo = self.topology
        offsets = _frozen_array(self.offsets, "offsets", 2)
        ends = _frozen_array(
            np.reshape(self.end_site_offsets, (-1, 3))
            if np.size(self.end_site_offsets) == 0
            else self.end_site_offsets,
            "end_site_offsets",
            2,
        )
        channels = _frozen_array(self.channels, "channels", 2)
        if offsets.shape != (topo.num_joints, 3):
            raise UserError(
                f"Motion: `offsets` has shape {offsets.shape}, expected ({topo.num_joints}, 3)"
            )
        if ends.shape != (topo.num_end_sites, 3):
            raise UserError(
                f"Motion: `end_site_offsets` has shape {ends.shape}, "
                f"expected ({topo.num_end_sites}, 3)"
            )
        if channels.shape[1] != topo.num_channels:
            raise UserError(
                f"Motion: `channels` has shape {channels.shape}, expected (frames, "
                f"{topo.num_channels}) for this topology"
            )
        try:
            frame_time_s = float(self.frame_time_s)
        except (TypeError, ValueError):
            raise UserError(f"Motion: `frame_time_s` must be a number, got {self.frame_time_s!r}")
        if not (math.isfinite(frame_time_s) and MIN_FRAME_TIME_S <= frame_time_s <= MAX_FRAME_TIME_S):
            raise UserError(f"Motion: `frame_time_s` must be between {MIN_FRAME_TIME_S:g} and "
                            f"{MAX_FRAME_TIME_S:g} s, got {frame_time_s}")
        object.__setattr__(self, "offsets", offsets)
        object.__setattr__(self, "end_site_offsets", ends)
        object.__setattr__(self, "channels", channels)
        object.__setattr__(self, "frame_time_s", frame_time_s)
        object.__setattr__(self, "source", None if self.source is None else str(self.source))

    @property
    def num_frames(self) -> int:
        return int(self.channels.shape[0])

    @property
    def num_joints(self) -> int:
        return self.topology.num_joints

    @property
    def num_channels(self) -> int:
        return self.topology.num_channels

    @property
    def duration_s(self) -> float:
        """`num_frames * frame_time_s` (the BVH convention: each frame lasts one frame time)."""
        return self.num_frames * self.frame_time_s

    @property
    def fps(self) -> float:
        """Frames per second, `1 / frame_time_s` (CMU's `.0083333` gives 120.0005)."""
        return 1.0 / self.frame_time_s

    def skeleton(self) -> Skeleton:
        """The `fourierjax.skeleton.Skeleton` of this clip.

        Offsets become JAX arrays of the default float dtype (float32, or float64 under x64).
        """
        from fourierjax.skeleton import Skeleton

        return Skeleton(self.topology, self.offsets, self.end_site_offsets)

    def __getitem__(self, index: slice) -> Motion:
        """`motion[a:b:step]`: the same skeleton with the frames sliced.

        A step multiplies the frame time by `abs(step)` (so `motion[::2]` keeps real time).
        Only slices are accepted, so that the result is always a `Motion`.
        """
        if not isinstance(index, slice):
            raise TypeError(
                f"Motion indexing takes a slice of frames (e.g. motion[1:]); got "
                f"{type(index).__name__}. Use motion.channels[i] for one frame's values."
            )
        step = 1 if index.step is None else int(index.step)
        return dataclasses.replace(
            self, channels=self.channels[index], frame_time_s=self.frame_time_s * abs(step)
        )

    def with_channels(self, channels) -> Motion:
        """The same skeleton, frame time and source with new frames `channels` `[F', C]`."""
        return dataclasses.replace(self, channels=channels)

    def __len__(self) -> int:
        return self.num_frames

    def __repr__(self) -> str:
        return (
            f"Motion({self.num_joints} joints, {self.topology.num_end_sites} end sites, "
            f"{self.num_channels} channels, {self.num_frames} frames at "
            f"{self.fps:.6g} fps, source={self.source!r})"
        )
