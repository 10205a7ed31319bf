"""Skeleton structure: a static, hashable `Topology` and a `Skeleton` with traced bone offsets."""

from __future__ import annotations

import dataclasses
from functools import cached_property
from typing import TYPE_CHECKING

import numpy as np

from fourierjax._host import as_default_float
from fourierjax._pytree import Record
from fourierjax.errors import UserError

if TYPE_CHECKING:
    from jaxtyping import Array, Float

POSITION_CHANNELS = ("Xposition", "Yposition", "Zposition")
ROTATION_CHANNELS = ("Xrotation", "Yrotation", "Zrotation")
CHANNEL_NAMES = POSITION_CHANNELS + ROTATION_CHANNELS


@dataclasses.dataclass(frozen=True)
class Topology:
    """The static part of a skeleton: names, hierarchy and channel layout, all tuples.

    Hashable and comparable by value, so it can be a `jax.jit` static argument or an equinox
    static field. Joints are in file order and every parent comes before its children.

    Arguments:
        names: joint names (End Sites excluded), unique.
        parents: parent index of each joint, `-1` for the root(s); `parents[i] < i`.
        channels: BVH channel names of each joint in file order, from `CHANNEL_NAMES`.
            Rotation channels are applied in the listed order (intrinsic): `("Zrotation",
            "Yrotation", "Xrotation")` means `R = Rz @ Ry @ Rx`. Position channels replace the
            matching components of the joint's OFFSET.
        end_site_parents: the parent joint of each End Site.
    """

    names: tuple[str, ...]
    parents: tuple[int, ...]
    channels: tuple[tuple[str, ...], ...]
    end_site_parents: tuple[int, ...] = ()

    def __post_init__(self):
        # Normalise lists to tuples so that equality and hashing are by value.
        object.__setattr__(self, "names", tuple(str(n) for n in self.names))
        object.__setattr__(self, "parents", tuple(int(p) for p in self.parents))
        object.__setattr__(self, "channels", tuple(tuple(str(c) for c in ch) for ch in self.channels))
        object.__setattr__(self, "end_site_parents", tuple(int(p) for p in self.end_site_parents))
        n = len(self.names)
        if n == 0:
            raise UserError("Topology: `names` is empty; a skeleton needs at least one joint")
        if len(self.parents) != n or len(self.channels) != n:
            raise UserError(
                f"Topology: `names` ({n}), `parents` ({len(self.parents)}) and `channels` "
                f"({len(self.channels)}) must have the same length"
            )
        if len(set(self.names)) != n:
            dup = sorted({x for x in self.names if self.names.count(x) > 1})
            raise UserError(f"Topology: duplicate joint names {dup}")
        for i, p in enumerate(self.parents):
            if not -1 <= p < i:
                raise UserError(
                    f"Topology: joint {self.names[i]!r} has parent index {p}; parents must "
                    "come before their children (-1 for a root)"
                )
        for name, chans in zip(self.names, self.channels):
            for c in chans:
                if c not in CHANNEL_NAMES:
                    raise UserError(f"Topology: joint {name!r} has unknown channel {c!r}")
            if len(set(chans)) != len(chans):
                raise UserError(f"Topology: joint {name!r} repeats a channel: {chans}")
        for p in self.end_site_parents:
            if not 0 <= p < n:
                raise UserError(f"Topology: End Site parent index {p} out of range")

    # -- counts -------------------------------------------------------------------------
    @property
    def num_joints(self) -> int:
        return len(self.names)

    @property
    def num_end_sites(self) -> int:
        return len(self.end_site_parents)

    @property
    def num_channels(self) -> int:
        return sum(len(c) for c in self.channels)

    # -- derived layout -----------------------------------------------------------------
    @property
    def channel_offsets(self) -> tuple[int, ...]:
        """Index of each joint's first channel in the flat per-frame channel vector."""
        out, k = [], 0
        for chans in self.channels:
            out.append(k)
            k += len(chans)
        return tuple(out)

    @property
    def rotation_orders(self) -> tuple[str | None, ...]:
        """Rotation order of each joint, e.g. `"ZYX"`; `None` for a joint without rotations.

        A joint with one or two rotation channels gets a one- or two-letter order.
        """
        out = []
        for chans in self.channels:
            order = "".join(c[0] for c in chans if c in ROTATION_CHANNELS)
            out.append(order or None)
        return tuple(out)

    @property
    def flat_channel_names(self) -> tuple[str, ...]:
        """`"Joint.Channel"` for every channel of a frame, in file order."""
        return tuple(f"{n}.{c}" for n, chans in zip(self.names, self.channels) for c in chans)

    def index(self, name: str) -> int:
        """Index of the joint called `name` (KeyError naming the valid joints otherwise)."""
        try:
            return self.names.index(name)
        except ValueError:
            raise KeyError(f"no joint named {name!r}; joints are {list(self.names)}") from None

    def children(self, joint: int) -> tuple[int, ...]:
        return tuple(i for i, p in enumerate(self.parents) if p == joint)

    @property
    def depths(self) -> tuple[int, ...]:
        """Depth of each joint in the hierarchy (roots have depth 0)."""
        d: list[int] = []
        for p in self.parents:
            d.append(0 if p < 0 else d[p] + 1)
        return tuple(d)

    @cached_property
    def _levels(self) -> tuple[tuple[int, ...], ...]:
        depths = self.depths
        return tuple(
            tuple(i for i, d in enumerate(depths) if d == level) for level in range(max(depths) + 1)
        )

    @property
    def levels(self) -> tuple[tuple[int, ...], ...]:
        """Joints grouped by depth: all joints of a level can be posed at once."""
        return self._levels


def common_ancestor(parents: tuple[int, ...], a: int, b: int) -> int:
    """The nearest joint above both `a` and `b` (e.g. the pelvis of two hips); -1 when none.

    Arguments:
        parents: parent index of each joint (-1 for a root), as `Topology.parents`.
        a, b: joint indices.

    Returns:
        A joint index, or -1.
    """
    up = set()
    while a >= 0:
        up.add(a)
        a = parents[a]
    while b >= 0 and b not in up:
        b = parents[b]
    return b


class Skeleton(Record):
    """A topology with its geometry: bone offsets are arrays, so they can be fitted or batched.

    A pytree: `offsets` and `end_site_offsets` are its leaves, `topology` is static (in the
    tree structure). Immutable; edit with `equinox.tree_at` or make a new one.

    Arguments:
        topology: the static `Topology`.
        offsets: `[J, 3]` local translation of each joint from its parent (file units).
        end_site_offsets: `[E, 3]` local translation of each End Site from its parent joint.
    """

    __leaves__ = ("offsets", "end_site_offsets")
    __static__ = ("topology",)
    offsets: Float[Array, "joints 3"]
    end_site_offsets: Float[Array, "end_sites 3"]
    topology: Topology

    def __init__(self, topology: Topology, offsets, end_site_offsets=None):
        self._set("topology", topology)
        # On the host for NumPy input: `jnp.asarray(x, float)` of float64 is a program per shape.
        self._set("offsets", as_default_float(offsets))
        if end_site_offsets is None:
            end_site_offsets = np.zeros((topology.num_end_sites, 3))
        self._set("end_site_offsets", as_default_float(end_site_offsets))
        self._check()

    def _check(self):
        j, e = self.topology.num_joints, self.topology.num_end_sites
        if self.offsets.shape[-2:] != (j, 3):
            raise UserError(f"Skeleton: `offsets` has shape {self.offsets.shape}, expected (..., {j}, 3)")
        if self.end_site_offsets.shape[-2:] != (e, 3):
            raise UserError(
                f"Skeleton: `end_site_offsets` has shape {self.end_site_offsets.shape}, "
                f"expected (..., {e}, 3)"
            )
