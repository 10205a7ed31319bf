"""Inference of a `BodyMap` from joint names first and from the geometry of the motion where names do not decide."""

from __future__ import annotations

import functools

import numpy as np

from fourierjax._body import _names
from fourierjax._body._map import (
    UNITS,
    Arm,
    BodyMap,
    BodyMapError,
    Leg,
    missing_legs_message,
    parse_overrides,
    parse_units,
    parse_up,
    point_name,
    resolve_joint,
    resolve_point,
)
from fourierjax.skeleton import common_ancestor

_LEG_FIELDS = ("hip", "knee", "ankle", "toe")
_ARM_FIELDS = ("collar", "shoulder", "elbow", "wrist")
#: Hip to ankle of an adult, metres: the reference for guessing a file's units.
_LEG_LENGTH_M = 0.8
#: A bone shorter than this fraction of its chain counts as no bone (CMU's LHipJoint sits on Hips).
_COINCIDENT = 0.02
#: A clip travels when its trajectory joint moves this many leg lengths across the ground.
_TRAVELS = 0.5
#: Hip to ankle as a fraction of hip to toe tip along a leg chain.
_ANKLE_ARC = 0.85


def infer(topology, positions, end_site_positions, rotations, moving, *, up=None, overrides=None,
          pre=None) -> BodyMap:
    """The map of one clip. `positions` `[F, J, 3]`, `end_site_positions` `[F, E, 3]` and
    `rotations` `[F, J, 4]` (wxyz world quaternions, or None) are NumPy; `moving` lists the joints
    with moving position channels, in file order (None: judge from `positions`). `pre` maps a
    pelvis joint to this clip's row of `moments_many` about it (the same values, computed with
    other clips')."""
    pre = pre or {}
    names, parents, esp = topology.names, topology.parents, topology.end_site_parents
    J = len(names)
    ov = parse_overrides(overrides)
    sources: dict[str, str] = {}
    points = np.concatenate([positions, end_site_positions], axis=1)  # [F, J+E, 3]
    point_parents = tuple(parents) + tuple(esp)

    # -- up axis given -------------------------------------------------------------------
    up_given = None
    if up is not None:
        up_given, sources["up"] = parse_up(up), "argument"
    elif "up" in ov:
        up_given, sources["up"] = parse_up(ov["up"]), "file"

    # -- legs: the override file, then names, then geometry ------------------------------
    legs: dict[str, dict[str, int | None]] = {}
    legs_ov = ov.get("legs", {})
    for side in ("left", "right"):
        given = legs_ov.get(side, {})
        if all(k in given for k in ("hip", "knee", "ankle")):
            legs[side] = {k: (resolve_joint(names, given[k], f"legs.{side}.{k}") if given.get(k) else None)
                          for k in _LEG_FIELDS}
            kids = topology.children(legs[side]["ankle"])
            if "toe" not in given and len(kids) == 1:  # `toe = ""` says there is none
                legs[side]["toe"] = kids[0]
    if len(legs) == 2:
        sources["legs"] = "file"
    else:
        by_name = {s: _match_chain(names, parents, s, "leg") for s in ("left", "right")}
        if all(by_name.values()) and not set(_present(by_name["left"])) & set(_present(by_name["right"])):
            legs, sources["legs"] = by_name, "names"  # type: ignore[assignment]
        else:
            legs = {}
    if legs:
        pelvis = common_ancestor(parents, legs["left"]["hip"], legs["right"]["hip"])
        if pelvis < 0:
            raise BodyMapError(missing_legs_message("the two hips have no common ancestor", names))
        mean_world = pre[pelvis][0] if pelvis in pre else _mean_relative(points, pelvis)
        up_axis, up_sign = up_given or _up_from_legs(mean_world, pelvis, legs)
    else:
        pelvis, (up_axis, up_sign) = _pelvis_from_reach(points.mean(axis=0), point_parents, J, up_given)
        if pelvis < 0:
            raise BodyMapError(missing_legs_message(
                "no joint has two branches that reach down (two legs)", names))
    if "up" not in sources:
        sources["up"] = "geometry"
    u = np.zeros(3)
    u[up_axis] = up_sign

    # Mean pose in the pelvis's frame (a clip that turns around keeps its legs apart there).
    local, u_local = _mean_local(points, rotations, pelvis, u, pre.get(pelvis))
    if not legs:
        legs = _legs_from_geometry(local, u_local, point_parents, pelvis, J, names)
        sources["legs"] = "geometry"
        _check_not_arms(legs, names, parents)
    trunk = trunk_pelvis(parents, pelvis, (legs["left"]["hip"], legs["right"]["hip"]))
    if trunk != pelvis:
        pelvis = trunk
        local, u_local = _mean_local(points, rotations, pelvis, u, pre.get(pelvis))
    for side in ("left", "right"):  # single fields of the override file win
        for k in _LEG_FIELDS:
            if k in legs_ov.get(side, {}):
                v = legs_ov[side][k]
                legs[side][k] = resolve_joint(names, v, f"legs.{side}.{k}") if v else None
                if not sources["legs"].endswith("file"):
                    sources["legs"] += "+file"
    pelvis_ov = ov.get("pelvis")
    if pelvis_ov is not None:
        pelvis, sources["pelvis"] = resolve_joint(names, pelvis_ov, "pelvis"), "file"
    else:
        sources["pelvis"] = "names" if pelvis in _match_centre(names, "pelvis") else "geometry"

    left_leg = _leg(legs["left"], names, esp, ov, "left")
    right_leg = _leg(legs["right"], names, esp, ov, "right")

    # -- facing, forward, trajectory -----------------------------------------------------
    facing_local = _facing_local(local, u_local, left_leg, right_leg)
    facing = _world_facing(rotations, pelvis, facing_local, u,
                           pre[pelvis][1] if pelvis in pre else None)
    trajectory, sources["trajectory"] = _trajectory(ov, topology, positions, moving, pelvis)
    seg = np.linalg.norm(positions[:, left_leg.knee] - positions[:, left_leg.hip], axis=-1) + np.linalg.norm(
        positions[:, left_leg.ankle] - positions[:, left_leg.knee], axis=-1)
    leg_length = float(ov.get("leg_length", np.median(seg)))
    travel = positions[-1, trajectory] - positions[0, trajectory]
    travel = travel - u * (u @ travel)
    if "forward" in ov:
        forward, sources["forward"] = _unit(np.asarray(ov["forward"], float)), "file"
    elif np.linalg.norm(travel) > _TRAVELS * leg_length:
        forward, sources["forward"] = _unit(travel), "geometry"
    else:
        forward, sources["forward"] = facing, "geometry"
    if "facing" in ov:
        facing = _unit(np.asarray(ov["facing"], float))

    # -- trunk and arms ------------------------------------------------------------------
    leg_joints = set(_present(legs["left"])) | set(_present(legs["right"]))
    head, neck = _head_and_neck(ov, names, parents, esp, local, u_local, pelvis, leg_joints, sources)
    stop = neck if neck >= 0 else head
    spine = tuple(_path(parents, pelvis, stop)[1:-1]) if stop >= 0 else ()
    if "spine" in ov:
        spine = tuple(resolve_joint(names, n, "spine") for n in ov["spine"])
    left_arm, right_arm = _arms(ov, names, parents, sources)

    # -- scale and units -----------------------------------------------------------------
    heights = local[body_points(point_parents, pelvis, head)] @ u_local
    height = float(ov.get("height", heights.max() - heights.min()))
    if "units" in ov or "metres_per_unit" in ov:
        units, mpu = parse_units(ov["units"] if "units" in ov else ov["metres_per_unit"])
        if "metres_per_unit" in ov:
            mpu = float(ov["metres_per_unit"])
        sources["units"] = "file"
    else:
        units = min(UNITS, key=lambda k: abs(np.log(leg_length * UNITS[k] / _LEG_LENGTH_M)))
        mpu, sources["units"] = UNITS[units], "geometry"
    if "leg_length" in ov:
        sources["leg_length"] = "file"
    return BodyMap(
        joint_names=names, left=left_leg, right=right_leg, trajectory=trajectory, pelvis=pelvis, spine=spine,
        neck=neck, head=head, left_arm=left_arm, right_arm=right_arm, up_axis=up_axis, up_sign=up_sign,
        forward=_tuple3(forward), facing=_tuple3(facing), leg_length=leg_length, height=height, units=units,
        metres_per_unit=mpu, sources=tuple(sorted(sources.items())),
    )


# ------------------------------------------------------------------------------ names


def _match_chain(names, parents, side, kind: str):
    """`_names.match_chain` of a leg or an arm, once per skeleton (a fresh dict each call)."""
    found = _match_chain_cached(tuple(names), tuple(parents), side, kind)
    return None if found is None else dict(found)


@functools.lru_cache(maxsize=256)
def _match_chain_cached(names, parents, side, kind):
    roles, optional = (_names.LEG_ROLES, ("toe",)) if kind == "leg" else (_names.ARM_ROLES, ("collar",))
    return _names.match_chain(names, parents, side, roles, optional)


def _match_centre(names, role: str) -> list[int]:
    """`_names.match_centre`, once per skeleton."""
    return list(_match_centre_cached(tuple(names), role))


@functools.lru_cache(maxsize=256)
def _match_centre_cached(names, role):
    return tuple(_names.match_centre(names, role))


# ------------------------------------------------------------------------------ geometry


def _present(chain: dict) -> list[int]:
    return [j for j in chain.values() if j is not None]


def _unit(v: np.ndarray) -> np.ndarray:
    n = float(np.linalg.norm(v))
    if not np.isfinite(n) or n == 0.0:
        raise BodyMapError(f"body map: cannot normalise the direction {v.tolist()}")
    return v / n


def _tuple3(v) -> tuple[float, float, float]:
    return (float(v[0]), float(v[1]), float(v[2]))


def _path(parents, a: int, b: int) -> list[int]:
    """Joints from ancestor `a` down to `b`, both included ([] when `a` is not an ancestor)."""
    out = [b]
    while out[-1] != a:
        p = parents[out[-1]]
        if p < 0:
            return []
        out.append(p)
    return out[::-1]


def _subtree(point_parents, root: int) -> list[int]:
    """Points of the subtree at `root` (parents come before children, so one pass finds them)."""
    inside = {root}
    for i in range(root + 1, len(point_parents)):
        if point_parents[i] in inside:
            inside.add(i)
    return sorted(inside)


def body_points(point_parents, pelvis: int, head: int) -> list[int]:
    """The points (joints, then End Sites) that are the body: the trunk's subtree at `pelvis`.
    The pelvis's ancestors and their other branches are not (Unreal's `root` and Blender's
    `Armature -> Root` on the floor, a Bandai `joint_Root`, IK target bones): counted in the
    height, a joint on the floor under the mean pose's lifted feet made the same body 4% taller.
    Every point when the head is not below the pelvis (a trunk the names did not find)."""
    inside = _subtree(point_parents, pelvis)
    return inside if head < 0 or head in inside else list(range(len(point_parents)))


def _pelvis_from_reach(mean: np.ndarray, point_parents, J: int, up_given) -> tuple[int, tuple[int, int]]:
    """The joint two of whose branches reach farthest along one signed axis (the legs, down from
    the pelvis), and that axis's opposite (up); `(-1, (1, 1))` when no joint has two branches.

    `mean` `[J+E, 3]` is the mean pose. Every joint with two or more branches is a candidate, not
    only the shallowest with three: Daz's `hip` has two (`pelvis` and the abdomen) and its
    `pelvis` two (the thighs), while the chest has three (the neck and both arms), which
    hang down too, but less far than the legs. Ties go to the shallowest joint.
    """
    kids: dict[int, list[int]] = {}
    for c, p in enumerate(point_parents):
        if p >= 0:
            kids.setdefault(p, []).append(c)
    depth = _names.depths(tuple(point_parents))
    signs = [up_given] if up_given else [(a, s) for a in range(3) for s in (1, -1)]
    best, best_key = (-1, (1, 1)), None
    for j, cs in kids.items():
        if j >= J or len(cs) < 2:
            continue
        branches = [_subtree(point_parents, c) for c in cs]
        for axis, sign in signs:
            reach = sorted((float((-sign * (mean[b, axis] - mean[j, axis])).max()) for b in branches), reverse=True)
            key = (round(reach[1], 9), -depth[j], -j)
            if best_key is None or key > best_key:
                best, best_key = (j, (axis, sign)), key
    return best


def trunk_pelvis(parents, pelvis: int, hips: tuple[int, int]) -> int:
    """The joint the legs and the spine hang from: the hips' common ancestor `pelvis`, or its parent
    when every branch of `pelvis` holds a leg and the parent has another branch (Daz Genesis:
    `hip -> pelvis -> lThighBend, rThighBend`, `hip -> abdomenLower`: the trunk's root is `hip`)."""
    kids = [c for c, p in enumerate(parents) if p == pelvis]
    if any(all(h != c and not _names._is_ancestor(parents, c, h) for h in hips) for c in kids):
        return pelvis
    up = parents[pelvis]
    if up >= 0 and any(p == up and c != pelvis for c, p in enumerate(parents)):
        return up
    return pelvis


def _mean_relative(points: np.ndarray, pelvis: int) -> np.ndarray:
    return (points - points[:, pelvis : pelvis + 1]).mean(axis=0)


def _up_from_legs(mean: np.ndarray, pelvis: int, legs) -> tuple[int, int]:
    d = -0.5 * (mean[legs["left"]["ankle"]] + mean[legs["right"]["ankle"]])  # pelvis minus feet
    axis = int(np.argmax(np.abs(d)))
    return axis, int(np.sign(d[axis]) or 1)


def _mean_local(points, rotations, pelvis: int, u: np.ndarray, pre=None):
    """Mean pose relative to the pelvis in its own frame, and the up direction in that frame
    (``pre``: the clip's `moments_many` row about ``pelvis``)."""
    if pre is not None and rotations is not None:
        _, R, local = pre
        return local, _unit((u @ R).mean(axis=0))
    rel = points - points[:, pelvis : pelvis + 1]
    if rotations is None:
        return rel.mean(axis=0), u
    R = _matrices(rotations[:, pelvis])  # [F, 3, 3] world from pelvis
    # R^T rel and R^T u of every frame as row vectors times R (a matmul: einsum's generic loop
    # cost a clip 0.5 ms, a third of its map)
    local = np.matmul(rel, R).mean(axis=0)
    return local, _unit((u @ R).mean(axis=0))


def named_pelvises(topology) -> tuple[int, ...]:
    """The joints `infer` poses a clip of `topology` about when joint names decide its legs (and
    no override file or up axis is given): the hips' common ancestor and the trunk's root; ()
    when names do not decide the legs."""
    names, parents = topology.names, topology.parents
    legs = {s: _match_chain(names, parents, s, "leg") for s in ("left", "right")}
    if not all(legs.values()) or set(_present(legs["left"])) & set(_present(legs["right"])):
        return ()
    pelvis = common_ancestor(parents, legs["left"]["hip"], legs["right"]["hip"])
    if pelvis < 0:
        return ()
    return tuple(dict.fromkeys((pelvis, trunk_pelvis(parents, pelvis, (legs["left"]["hip"],
                                                                        legs["right"]["hip"])))))


def moments_many(points: np.ndarray, rotations: np.ndarray, pelvis: int) -> list[tuple]:
    """`infer`'s arrays about ``pelvis`` of many clips at once, its ``pre`` rows: per clip, the
    mean of every point relative to the pelvis ``[P, 3]`` (`_mean_relative`), the pelvis's
    world-from-pelvis matrices ``[F, 3, 3]`` and the mean pose in the pelvis frame ``[P, 3]``
    (`_mean_local`), with the same values as one clip at a time (the same reductions, each over
    one clip's frames). ``points [B, F, P, 3]``, ``rotations [B, F, J, 4]``."""
    mean_world, R, local = moments_arrays(points, rotations, pelvis)
    return [(mean_world[b], R[b], local[b]) for b in range(len(points))]


def moments_arrays(points: np.ndarray, rotations: np.ndarray, pelvis: int) -> tuple:
    """`moments_many` as arrays: ``(mean_world [B, P, 3], R [B, F, 3, 3], local [B, P, 3])``."""
    rel = points - points[:, :, pelvis : pelvis + 1]
    mean_world = rel.mean(axis=1)
    R = _matrices(rotations[:, :, pelvis])
    local = np.matmul(rel, R).mean(axis=1)
    return mean_world, R, local


def _matrices(q: np.ndarray) -> np.ndarray:
    w, x, y, z = np.moveaxis(q / np.linalg.norm(q, axis=-1, keepdims=True), -1, 0)
    return np.stack([
        np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)], -1),
        np.stack([2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)], -1),
        np.stack([2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)], -1),
    ], -2)


def _legs_from_geometry(local, u, point_parents, pelvis: int, J: int, names) -> dict:
    """The two branches of the pelvis that reach lowest, split into hip, knee, ankle and toe."""
    branches = [c for c in range(len(point_parents)) if point_parents[c] == pelvis]
    lows = []
    for c in branches:
        pts = _subtree(point_parents, c)
        leaves = [p for p in pts if p not in point_parents]
        lows.append((float((local[leaves] @ u).min()), c, min(leaves, key=lambda p: float(local[p] @ u))))
    lows.sort()
    if len(lows) < 2:
        raise BodyMapError(missing_legs_message("the pelvis has fewer than two branches", names))
    chains = []
    for _, c, leaf in lows[:2]:
        chain = _chain_from_geometry(local, u, point_parents, pelvis, c, leaf, J)
        if chain is None:
            raise BodyMapError(missing_legs_message(
                f"the branch at {names[c]!r} has no hip, knee and ankle that geometry can tell apart", names))
        chains.append(chain)
    a, b = chains
    lat = local[a["hip"]] - local[b["hip"]]
    facing = _facing_from_points(local, u, [a, b], [leaf for _, _, leaf in lows[:2]])
    left_dir = np.cross(u, facing)
    return {"left": a, "right": b} if lat @ left_dir > 0 else {"left": b, "right": a}


def _check_not_arms(legs: dict, names, parents) -> None:
    """BodyMapError when the chains geometry chose as legs hold joints the names call arms: a
    rig without legs (an upper body) would otherwise walk on its hands. Names win over reach."""
    arms = set()
    for side in ("left", "right"):
        chain = _match_chain(names, parents, side, "arm")
        arms |= set(_present(chain)) if chain else set()
    taken = sorted(arms & {legs[s][k] for s in ("left", "right") for k in ("hip", "knee", "ankle")})
    if taken:
        raise BodyMapError(missing_legs_message(
            "the two chains that reach lowest are the arms by name (" + ", ".join(names[j] for j in taken) + ")",
            names))


def _chain_from_geometry(local, u, point_parents, pelvis, c, leaf, J):
    path = [leaf]
    while path[-1] != c:
        path.append(point_parents[path[-1]])
    path = path[::-1]
    pts = [local[pelvis]] + [local[p] for p in path]
    scale = sum(float(np.linalg.norm(b - a)) for a, b in zip(pts[:-1], pts[1:]))
    kept, last = [], local[pelvis]
    for p in path:  # drop joints that sit on the previous one (no bone)
        if np.linalg.norm(local[p] - last) > _COINCIDENT * scale:
            kept.append(p)
            last = local[p]
    kept_joints = [p for p in kept if p < J]
    if len(kept_joints) < 3:
        return None
    # The ankle ends the second long bone: hip to ankle is ~85% of the way from the hip to the toe
    # tip along the chain (CMU 83%, Bandai 87%) whatever the pose; a twist joint or a toe is not.
    arc = np.cumsum([0.0] + [float(np.linalg.norm(local[b] - local[a])) for a, b in zip(kept[:-1], kept[1:])])
    ankle_at = min((k for k in range(2, len(kept)) if kept[k] < J), key=lambda k: abs(arc[k] / arc[-1] - _ANKLE_ARC))
    hip, ankle = kept[0], kept[ankle_at]
    between = [p for p in kept[1:ankle_at] if p < J]
    if hip >= J or not between:
        return None
    line = _unit(local[ankle] - local[hip])
    off = [np.linalg.norm((local[p] - local[hip]) - line * ((local[p] - local[hip]) @ line)) for p in between]
    knee = between[int(np.argmax(off))]
    # Thigh and shin are bones of about one length (CMU 0.94, Bandai ~1); a leg without a knee
    # joint (hip -> foot -> toe) would otherwise take its ankle for the knee and its toe for the ankle.
    k = kept.index(knee)
    if not 0.5 <= (arc[k] - arc[0]) / max(arc[ankle_at] - arc[k], 1e-12) <= 2.0:
        return None
    # The toe is the last joint past the ankle (Daz's lFoot -> lMetatarsals -> lToe: lToe), so that
    # its End Site, the toe tip, is a foot point.
    toes = [p for p in kept[ankle_at + 1:] if p < J]
    toe = toes[-1] if toes else None
    return {"hip": hip, "knee": knee, "ankle": ankle, "toe": toe}


def _facing_from_points(local, u, chains, tips) -> np.ndarray:
    """Where the feet (ankle to toe tip) and the knees (off the hip-ankle line) point, in the ground plane.

    Both count: a walker's feet point forward, a runner's mean foot points down while the knees
    lead by a tenth of the leg, and a straight-legged rest pose has only its feet.
    """
    v = np.zeros(3)
    for ch, tip in zip(chains, tips):
        v += local[tip] - local[ch["ankle"]]
        v += local[ch["knee"]] - 0.5 * (local[ch["hip"]] + local[ch["ankle"]])
    v = v - u * (u @ v)
    return _unit(v)


def _facing_local(local, u, left: Leg, right: Leg) -> np.ndarray:
    """Facing in the pelvis frame: `left hip − right hip` crossed with up (forward = left × up)."""
    lat = local[left.hip] - local[right.hip]
    f = np.cross(lat, u)
    f = f - u * (u @ f)
    return _unit(f)


def _world_facing(rotations, pelvis: int, facing_local, u, R=None) -> np.ndarray:
    """The pelvis-frame facing in world axes, averaged over frames in the ground plane (``R``:
    the pelvis's matrices when known)."""
    if rotations is None:
        f = facing_local
    else:
        per_frame = (_matrices(rotations[:, pelvis]) if R is None else R) @ facing_local
        per_frame = per_frame - np.outer(per_frame @ u, u)
        f = per_frame.mean(axis=0)
        if np.linalg.norm(f) < 0.25 * np.linalg.norm(per_frame, axis=-1).mean():
            f = per_frame[0]  # a clip that turns around: its first frame's facing
    return _unit(f - u * (u @ f))


def _trajectory(ov, topology, positions, moving, pelvis: int) -> tuple[int, str]:
    """Joint 0 when it moves, else the first joint that moves; when none does (a clip standing
    still, or a model's cycle with its root at the origin) the pelvis, or its nearest ancestor
    with position channels (the joint a BVH writer puts the travel on)."""
    names = topology.names
    if "trajectory" in ov:
        return resolve_joint(names, ov["trajectory"], "trajectory"), "file"
    if moving is None:
        span = np.ptp(positions, axis=0).max(axis=-1)  # [J]
        moving = [j for j in range(len(names)) if span[j] > 1e-6 * (1.0 + np.abs(positions).max())]
    if 0 in moving:
        return 0, "geometry"
    if moving:
        return int(moving[0]), "geometry"
    j = pelvis
    while j >= 0 and not any(c.endswith("position") for c in topology.channels[j]):
        j = topology.parents[j]
    return (pelvis if j < 0 else j), "geometry"


def _leg(chain, names, esp, ov, side) -> Leg:
    J = len(names)
    tip_of = chain["toe"] if chain["toe"] is not None else chain["ankle"]
    fp_ov = ov.get("legs", {}).get(side, {}).get("foot_points")
    if fp_ov is not None:
        fp = tuple(resolve_point(names, esp, s, f"legs.{side}.foot_points") for s in fp_ov)
    else:
        ends = [J + e for e, p in enumerate(esp) if p == tip_of][:1]
        fp = tuple([chain["ankle"]] + ([chain["toe"]] if chain["toe"] is not None else []) + ends)
    leg_names = tuple(names[chain[k]] if chain[k] is not None else "" for k in _LEG_FIELDS)
    return Leg(hip=chain["hip"], knee=chain["knee"], ankle=chain["ankle"],
               toe=-1 if chain["toe"] is None else chain["toe"], foot_points=fp,
               names=leg_names,  # type: ignore[arg-type]
               foot_point_names=tuple(point_name(names, esp, p) for p in fp))


def _head_and_neck(ov, names, parents, esp, local, u, pelvis, leg_joints, sources) -> tuple[int, int]:
    below = [j for j in range(len(names)) if j != pelvis and _path(parents, pelvis, j) and j not in leg_joints]
    if "head" in ov:
        head, sources["head"] = resolve_joint(names, ov["head"], "head"), "file"
    else:
        named = [j for j in _match_centre(names, "head") if j in below]
        if named:
            head, sources["head"] = named[0], "names"
        elif below:
            # The joint (or End Site's joint) highest above the pelvis in the mean pose.
            J = len(names)
            pts = [p for p in range(len(names) + len(esp)) if (p if p < J else esp[p - J]) in below]
            top = max(pts, key=lambda p: float(local[p] @ u))
            head, sources["head"] = (top if top < J else esp[top - J]), "geometry"
        else:
            return -1, -1
    if "neck" in ov:
        neck, sources["neck"] = resolve_joint(names, ov["neck"], "neck"), "file"
        return head, neck
    route = _path(parents, pelvis, head)[1:-1]
    named = [j for j in _match_centre(names, "neck") if j in route]
    if named:
        sources["neck"] = "names"
        return head, min(named, key=route.index)
    sources["neck"] = "geometry"
    return head, (route[-1] if route else -1)


def _arms(ov, names, parents, sources) -> tuple[Arm | None, Arm | None]:
    arms_ov = ov.get("arms", {})
    out = []
    for side in ("left", "right"):
        given = arms_ov.get(side)
        if given is not None:
            chain = {k: (resolve_joint(names, given[k], f"arms.{side}.{k}") if given.get(k) else None)
                     for k in _ARM_FIELDS}
            sources["arms"] = "file"
        else:
            chain = _match_chain(names, parents, side, "arm")
        if chain is None or any(chain[k] is None for k in _ARM_FIELDS[1:]):
            return None, None
        out.append(Arm(collar=-1 if chain["collar"] is None else chain["collar"], shoulder=chain["shoulder"],
                       elbow=chain["elbow"], wrist=chain["wrist"],
                       names=tuple(names[chain[k]] if chain[k] is not None else "" for k in _ARM_FIELDS)))
    sources.setdefault("arms", "names")
    return out[0], out[1]


def from_stored(d: dict, topology, how: str) -> BodyMap:
    """A map whose every field `d` names (a stored map or a complete TOML file), for `topology`."""
    required = ("up", "forward", "facing", "units", "metres_per_unit", "leg_length", "height", "trajectory",
                "pelvis", "spine", "legs")
    missing = [k for k in required if k not in d]
    if missing:
        raise BodyMapError(f"body map: field(s) {missing} missing; a stored map names every field")
    names = topology.names
    legs = []
    for side in ("left", "right"):
        g = d["legs"].get(side, {})
        chain = {k: (resolve_joint(names, g[k], f"legs.{side}.{k}") if g.get(k) else None) for k in _LEG_FIELDS}
        if any(chain[k] is None for k in ("hip", "knee", "ankle")):
            raise BodyMapError(f"body map: legs.{side} needs hip, knee and ankle")
        legs.append(_leg(chain, names, topology.end_site_parents, d, side))
    stored = dict(d.get("sources", {}))
    sources: dict[str, str] = {}
    left_arm, right_arm = _arms(d, names, topology.parents, sources) if "arms" in d else (None, None)
    up_axis, up_sign = parse_up(d["up"])
    units, _ = parse_units(d["units"]) if d["units"] != "custom" else ("custom", 0.0)
    return BodyMap(
        joint_names=names, left=legs[0], right=legs[1],
        trajectory=resolve_joint(names, d["trajectory"], "trajectory"),
        pelvis=resolve_joint(names, d["pelvis"], "pelvis"),
        spine=tuple(resolve_joint(names, n, "spine") for n in d["spine"]),
        neck=resolve_joint(names, d["neck"], "neck") if d.get("neck") else -1,
        head=resolve_joint(names, d["head"], "head") if d.get("head") else -1,
        left_arm=left_arm, right_arm=right_arm, up_axis=up_axis, up_sign=up_sign,
        forward=tuple(float(x) for x in d["forward"]),  # type: ignore[arg-type]
        facing=tuple(float(x) for x in d["facing"]),  # type: ignore[arg-type]
        leg_length=float(d["leg_length"]), height=float(d["height"]), units=units,
        metres_per_unit=float(d["metres_per_unit"]),
        sources=tuple(sorted((k, stored.get(k, how) if how == "stored" else how) for k in stored)),
    )


def from_names(topology, up=None) -> BodyMap:
    """The map that joint names alone decide, for a bare topology (no poses, so no geometry).

    Legs, arms, pelvis, spine, neck and head come from the name table as in `infer`; the
    trajectory is the pelvis or its nearest ancestor with position channels. The geometric
    fields are the library's defaults, marked "default" in `sources`: `up` (Y unless given),
    forward and facing along the next axis after up (+Z for Y up), leg length and height 0,
    units "custom" at 1 metre per unit.
    """
    names, parents, esp = topology.names, topology.parents, topology.end_site_parents
    sources = {k: "default" for k in ("up", "forward", "facing", "leg_length", "height", "units")}
    legs = {s: _names.match_chain(names, parents, s, _names.LEG_ROLES, ("toe",)) for s in ("left", "right")}
    if not all(legs.values()) or set(_present(legs["left"])) & set(_present(legs["right"])):
        raise BodyMapError(missing_legs_message(
            "joint names do not decide the legs (and a bare topology has no poses to find them from)", names))
    sources.update(legs="names", trajectory="names")
    pelvis = common_ancestor(parents, legs["left"]["hip"], legs["right"]["hip"])
    if pelvis < 0:
        raise BodyMapError(missing_legs_message("the two hips have no common ancestor", names))
    pelvis = trunk_pelvis(parents, pelvis, (legs["left"]["hip"], legs["right"]["hip"]))
    sources["pelvis"] = "names" if pelvis in _names.match_centre(names, "pelvis") else "hierarchy"
    leg_joints = set(_present(legs["left"])) | set(_present(legs["right"]))
    below = [j for j in range(len(names)) if j != pelvis and _path(parents, pelvis, j) and j not in leg_joints]
    heads = [j for j in _names.match_centre(names, "head") if j in below]
    head = heads[0] if heads else -1
    route = _path(parents, pelvis, head)[1:-1] if head >= 0 else []
    necks = [j for j in _names.match_centre(names, "neck") if j in route]
    neck = min(necks, key=route.index) if necks else (route[-1] if route else -1)
    sources.update(head="names", neck="names" if necks else "hierarchy")
    stop = neck if neck >= 0 else head
    spine = tuple(_path(parents, pelvis, stop)[1:-1]) if stop >= 0 else ()
    left_arm, right_arm = _arms({}, names, parents, sources)
    up_axis, up_sign = parse_up("y" if up is None else up)
    if up is not None:
        sources["up"] = "argument"
    facing = [0.0, 0.0, 0.0]
    facing[(up_axis + 1) % 3] = 1.0
    trajectory, _ = _trajectory({}, topology, None, [], pelvis)
    return BodyMap(
        joint_names=names, left=_leg(legs["left"], names, esp, {}, "left"),
        right=_leg(legs["right"], names, esp, {}, "right"), trajectory=trajectory, pelvis=pelvis, spine=spine,
        neck=neck, head=head, left_arm=left_arm, right_arm=right_arm, up_axis=up_axis, up_sign=up_sign,
        forward=_tuple3(facing), facing=_tuple3(facing), leg_length=0.0, height=0.0, units="custom",
        metres_per_unit=1.0, sources=tuple(sorted(sources.items())),
    )


# ------------------------------------------------------------------------------ many clips


def infer_named_many(topology, positions, rotations, moving, pre) -> list:
    """`infer` of many clips of one skeleton whose joint names decide the legs and the head (no
    override file, no up axis given), with the same maps bit for bit: the name-decided parts
    once, the geometry as array ops over the clips (each the same elementwise operations and
    reductions over one clip's frames as `infer`'s; a 3-vector's dot product and norm as
    ``(a * b).sum(-1)``, which is NumPy's own for one vector). ``positions [B, F, J, 3]`` and
    ``rotations [B, F, J, 4]`` (FK of each clip's posed frames), ``moving``: each clip's list
    (`infer`'s), ``pre``: ``{pelvis: (mean_world [B, P, 3], R [B, F, 3, 3], local [B, P, 3])}``
    (`moments_arrays` about `named_pelvises`). Returns a map per clip, None where `infer` itself
    must decide (a direction it cannot normalise: it raises); all None when names do not decide
    this skeleton's legs and head."""
    B = len(positions)
    plan = _named_plan(topology)
    if plan is None or any(p not in pre for p in (plan["pelvis0"], plan["pelvis"])):
        return [None] * B
    la, ra, pelvis = plan["left"]["ankle"], plan["right"]["ankle"], plan["pelvis"]
    # -- up (`_up_from_legs` of the hips' common ancestor's mean pose)
    d = -0.5 * (pre[plan["pelvis0"]][0][:, la] + pre[plan["pelvis0"]][0][:, ra])
    axis = np.argmax(np.abs(d), axis=1)
    ok = np.isfinite(d).all(axis=1)  # else `infer` decides (NaN poses)
    sign = np.sign(d[np.arange(B), axis])
    sign = np.where(sign == 0, 1, np.where(ok, sign, 1)).astype(int)
    u = np.zeros((B, 3))
    u[np.arange(B), axis] = sign
    # -- mean pose in the pelvis frame (`_mean_local` with `pre`)
    _, R, local = pre[pelvis]
    u_local = np.matmul(u[:, None, None, :], R)[:, :, 0].mean(axis=1)
    u_local, good = _units(u_local)
    ok &= good
    left, right = plan["left_leg"], plan["right_leg"]
    # -- facing (`_facing_local`, `_world_facing`)
    lat = local[:, left.hip] - local[:, right.hip]
    f = np.cross(lat, u_local)
    f = f - u_local * _dot(u_local, f)[:, None]
    facing_local, good = _units(f)
    ok &= good
    per_frame = np.matmul(R, facing_local[:, None, :, None])[..., 0]  # [B, F, 3]
    per_frame = per_frame - np.matmul(per_frame, u[:, :, None])[..., 0][..., None] * u[:, None, :]
    f = per_frame.mean(axis=1)
    turned = _norms(f) < 0.25 * np.linalg.norm(per_frame, axis=-1).mean(axis=1)
    f = np.where(turned[:, None], per_frame[:, 0], f)
    facing, good = _units(f - u * _dot(u, f)[:, None])
    ok &= good
    # -- trajectory, leg length, forward
    traj = [_trajectory({}, topology, None, moving[b], pelvis) for b in range(B)]
    seg = np.linalg.norm(positions[:, :, left.knee] - positions[:, :, left.hip], axis=-1) + np.linalg.norm(
        positions[:, :, left.ankle] - positions[:, :, left.knee], axis=-1)
    leg_length = np.median(seg, axis=1)
    tj = np.array([t for t, _ in traj])
    travel = positions[np.arange(B), -1, tj] - positions[np.arange(B), 0, tj]
    travel = travel - u * _dot(u, travel)[:, None]
    moves = _norms(travel) > _TRAVELS * leg_length
    along, good = _units(travel)
    ok &= good | ~moves
    forward = np.where(moves[:, None], along, facing)
    # -- height
    body = body_points(tuple(topology.parents) + tuple(topology.end_site_parents), pelvis, plan["head"])
    heights = np.matmul(local[:, body], u_local[:, :, None])[..., 0]
    height = heights.max(axis=1) - heights.min(axis=1)
    out: list = []
    for b in range(B):
        if not ok[b]:
            out.append(None)
            continue
        ll = float(leg_length[b])
        units = min(UNITS, key=lambda k, ll=ll: abs(np.log(ll * UNITS[k] / _LEG_LENGTH_M)))
        sources = dict(plan["sources"], trajectory=traj[b][1],
                       forward="geometry")
        sources["units"] = "geometry"
        out.append(BodyMap(
            joint_names=topology.names, left=left, right=right, trajectory=traj[b][0],
            pelvis=pelvis, spine=plan["spine"], neck=plan["neck"], head=plan["head"],
            left_arm=plan["arms"][0], right_arm=plan["arms"][1], up_axis=int(axis[b]),
            up_sign=int(sign[b]), forward=_tuple3(forward[b]), facing=_tuple3(facing[b]),
            leg_length=ll, height=float(height[b]), units=units, metres_per_unit=UNITS[units],
            sources=tuple(sorted(sources.items()))))
    return out


def _dot(a, b):
    return (a * b).sum(-1)


def _norms(v):
    return np.sqrt(_dot(v, v))


def _units(v) -> tuple[np.ndarray, np.ndarray]:
    """`_unit` of each row of ``v [B, 3]`` and whether it could normalise it."""
    n = _norms(v)
    good = np.isfinite(n) & (n != 0.0)
    return v / np.where(good, n, 1.0)[:, None], good


@functools.lru_cache(maxsize=64)
def _named_plan(topology):
    """The parts of `infer`'s map that names decide for ``topology`` (legs, pelvis, head, neck,
    spine, arms and their sources), or None when names do not decide the legs or the head."""
    names, parents, esp = topology.names, topology.parents, topology.end_site_parents
    legs = {s: _match_chain(names, parents, s, "leg") for s in ("left", "right")}
    if not all(legs.values()) or set(_present(legs["left"])) & set(_present(legs["right"])):
        return None
    pelvis0 = common_ancestor(parents, legs["left"]["hip"], legs["right"]["hip"])
    if pelvis0 < 0:
        return None
    pelvis = trunk_pelvis(parents, pelvis0, (legs["left"]["hip"], legs["right"]["hip"]))
    sources = {"legs": "names", "up": "geometry",
               "pelvis": "names" if pelvis in _match_centre(names, "pelvis") else "geometry"}
    leg_joints = set(_present(legs["left"])) | set(_present(legs["right"]))
    below = [j for j in range(len(names)) if j != pelvis and _path(parents, pelvis, j) and j not in leg_joints]
    if not [j for j in _match_centre(names, "head") if j in below]:
        return None  # the head from geometry: `infer` per clip
    head, neck = _head_and_neck({}, names, parents, esp, None, None, pelvis, leg_joints, sources)
    stop = neck if neck >= 0 else head
    spine = tuple(_path(parents, pelvis, stop)[1:-1]) if stop >= 0 else ()
    arms = _arms({}, names, parents, sources)
    return {"left": legs["left"], "right": legs["right"], "pelvis0": pelvis0, "pelvis": pelvis,
            "left_leg": _leg(legs["left"], names, esp, {}, "left"),
            "right_leg": _leg(legs["right"], names, esp, {}, "right"),
            "head": head, "neck": neck, "spine": spine, "arms": arms, "sources": sources}

