"""Segment masses and centre-of-mass locations (de Leva 1996), and the whole-body centre of mass.

de Leva, P. (1996). Adjustments to Zatsiorsky-Seluyanov's segment inertia parameters.
J. Biomechanics 29(9), 1223-1230, Table 4 (male values; the female column is not transcribed
yet). Mass is a fraction of body mass; the centre of mass lies at `com_fraction` of the way from
the proximal to the distal end of the segment.
"""

from __future__ import annotations

import dataclasses
from types import MappingProxyType
from typing import TYPE_CHECKING

import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float

from fourierjax.skeleton import Topology

if TYPE_CHECKING:
    from fourierjax.body import BodyMap


@dataclasses.dataclass(frozen=True)
class SegmentParameters:
    mass_fraction: float
    com_fraction: float  # from the proximal end, along the segment


# de Leva 1996, Table 4 (mass % and longitudinal CoM position % from the proximal endpoint).
# The head+neck segment is measured from the vertex in the paper; we store it from the
# cervicale (proximal, the body's neck joint) to the vertex, i.e. 1 - 0.5002 -> 0.4998.
# The trunk is cervicale (proximal) to mid-hip (distal).
DE_LEVA_1996 = MappingProxyType(
    {
        "male": MappingProxyType(
            {
                "head": SegmentParameters(0.0694, 0.4998),
                "trunk": SegmentParameters(0.4346, 0.4486),
                "upper_arm": SegmentParameters(0.0271, 0.5772),
                "forearm": SegmentParameters(0.0162, 0.4574),
                "hand": SegmentParameters(0.0061, 0.7900),
                "thigh": SegmentParameters(0.1416, 0.4095),
                "shank": SegmentParameters(0.0433, 0.4459),
                "foot": SegmentParameters(0.0137, 0.4415),
            }
        ),
    }
)


@dataclasses.dataclass(frozen=True)
class SegmentModel:
    """Body segments as pairs of points of a posed skeleton (static, hashable).

    Points index the concatenation `[joint positions; End Site positions]`.
    """

    names: tuple[str, ...]
    proximal: tuple[int, ...]
    distal: tuple[int, ...]
    mass_fraction: tuple[float, ...]
    com_fraction: tuple[float, ...]

    @property
    def total_mass_fraction(self) -> float:
        return float(sum(self.mass_fraction))


def segments_from_body_map(body_map: BodyMap, topology: Topology) -> dict[str, tuple[str, str]]:
    """The `segment_model` end points of a skeleton from its body map (any naming).

    Head: neck to the head's End Site (the vertex); trunk: neck to pelvis; arms: shoulder,
    elbow, wrist and the wrist's first child (the finger base) or its End Site; legs: hip, knee,
    ankle, toe (or the ankle's End Site). A part the map does not have is left out (the centre
    of mass normalises by the masses present). On a CMU rig: head `Neck`-`Head/end`, trunk
    `Neck`-`Hips`, e.g. left thigh `LeftUpLeg`-`LeftLeg`, left hand `LeftHand`-`LeftFingerBase`.

    Arguments:
        body_map: a `body.BodyMap` of `topology`.
        topology: the skeleton topology.

    Returns:
        segment name -> (proximal joint, distal joint or `"<joint>/end"`), by joint name.
    """
    name = body_map.name

    def tip(j: int) -> str | None:
        kids = topology.children(j)
        if kids:
            return name(kids[0])
        return f"{name(j)}/end" if j in topology.end_site_parents else None

    out: dict[str, tuple[str, str]] = {}
    top = body_map.neck if body_map.neck >= 0 else body_map.head
    if body_map.head >= 0 and body_map.head in topology.end_site_parents and top >= 0:
        out["head"] = (name(top), f"{name(body_map.head)}/end")
    if top >= 0:
        out["trunk"] = (name(top), name(body_map.pelvis))
    for side, arm in (("left", body_map.left_arm), ("right", body_map.right_arm)):
        if arm is None:
            continue
        out[f"{side}_upper_arm"] = (name(arm.shoulder), name(arm.elbow))
        out[f"{side}_forearm"] = (name(arm.elbow), name(arm.wrist))
        hand = tip(arm.wrist)
        if hand is not None:
            out[f"{side}_hand"] = (name(arm.wrist), hand)
    for side, leg in (("left", body_map.left), ("right", body_map.right)):
        out[f"{side}_thigh"] = (name(leg.hip), name(leg.knee))
        out[f"{side}_shank"] = (name(leg.knee), name(leg.ankle))
        foot = name(leg.toe) if leg.toe >= 0 else tip(leg.ankle)
        if foot is not None:
            out[f"{side}_foot"] = (name(leg.ankle), foot)
    return out


def segment_model(
    topology: Topology,
    segments: dict[str, tuple[str, str]] | None = None,
    sex: str = "male",
    *,
    body_map: BodyMap | None = None,
) -> SegmentModel:
    """Build a `SegmentModel` for a topology from named segment end points.

    Arguments:
        topology: the skeleton topology.
        segments: segment name -> (proximal joint, distal joint), where the distal point may be
            `"<joint>/end"` for that joint's End Site. Segment names end in one of the de Leva
            segments (`head`, `trunk`, `upper_arm`, `forearm`, `hand`, `thigh`, `shank`, `foot`).
            Defaults to the body map's segments (`segments_from_body_map`): of `body_map`
            when given, else of the map the joint names decide (`body.body_map_from_names`:
            CMU, Mixamo, Daz, 3ds Max, Bandai, SMPL, LAFAN names).
        sex: which de Leva table (only `"male"` is transcribed).
        body_map: a `body.BodyMap` of `topology` (`body.infer_body_map`), for any rig,
            whatever its names.

    Returns:
        a `SegmentModel`; raises `ValueError` naming a missing joint, or when no segments are
        given and names do not decide the body parts.
    """
    if sex not in DE_LEVA_1996:
        raise ValueError(f"segment_model: `sex` must be one of {list(DE_LEVA_1996)}, got {sex!r}")
    table = DE_LEVA_1996[sex]
    if segments is None:
        if body_map is None:
            from fourierjax.body import BodyMapError, body_map_from_names

            try:
                body_map = body_map_from_names(topology)
            except BodyMapError as err:
                raise ValueError(
                    "segment_model: the joint names are not in the skeleton name table, so they do not "
                    "decide the body segments; pass body_map=fourierjax.body.infer_body_map(motion) "
                    f"or `segments`. ({err})") from None
        segments = segments_from_body_map(body_map, topology)
    j = topology.num_joints

    def point(name: str) -> int:
        if name.endswith("/end"):
            parent = name[: -len("/end")]
            pj = _joint(parent)
            for k, p in enumerate(topology.end_site_parents):
                if p == pj:
                    return j + k
            raise ValueError(f"segment_model: joint {parent!r} has no End Site")
        return _joint(name)

    def _joint(name: str) -> int:
        if name not in topology.names:
            raise ValueError(
                f"segment_model: joint {name!r} not in the skeleton; pass `segments` to map "
                "this skeleton's joints onto body segments"
            )
        return topology.names.index(name)

    names, prox, dist, mass, com = [], [], [], [], []
    for seg, (a, b) in segments.items():
        kind = next((k for k in table if seg == k or seg.endswith("_" + k)), None)
        if kind is None:
            raise ValueError(f"segment_model: segment {seg!r} matches no de Leva segment {list(table)}")
        names.append(seg)
        prox.append(point(a))
        dist.append(point(b))
        mass.append(table[kind].mass_fraction)
        com.append(table[kind].com_fraction)
    return SegmentModel(tuple(names), tuple(prox), tuple(dist), tuple(mass), tuple(com))


def center_of_mass(
    model: SegmentModel,
    positions: Float[Array, "joints 3"],
    end_site_positions: Float[Array, "end_sites 3"] | None = None,
) -> Float[Array, 3]:
    """Whole-body centre of mass of one posed frame (mass-weighted segment centres).

    Arguments:
        model: the segment model (`segment_model(topology)`).
        positions: `[J, 3]` world joint positions (e.g. `FKResult.positions`).
        end_site_positions: `[E, 3]` End Site positions, needed when a segment ends at one.

    Returns:
        `[3]` centre of mass, in the units of `positions`.
    """
    points = positions
    if end_site_positions is not None:
        points = jnp.concatenate([positions, end_site_positions.astype(positions.dtype)], axis=0)
    prox = points[np.array(model.proximal)]
    dist = points[np.array(model.distal)]
    frac = jnp.asarray(model.com_fraction, positions.dtype)[:, None]
    centres = prox + frac * (dist - prox)
    mass = jnp.asarray(model.mass_fraction, positions.dtype)
    return (mass[:, None] * centres).sum(0) / mass.sum()
