"""Joint-name conventions: tokenising rig names and matching body parts by a table of names."""

from __future__ import annotations

import itertools
import re

# Tokens a rig puts in front of every joint name (after any `ns:` namespace is dropped):
# Mixamo's `mixamorig`, MotionBuilder's `Character1_`, 3ds Max's `Bip01 `, Rigify's `DEF-`.
_PREFIX_TOKENS = frozenset({"mixamorig", "character", "bip", "biped", "def", "mch", "org", "rig", "skel", "ch"})
_LEFT = frozenset({"left", "l", "lft"})
_RIGHT = frozenset({"right", "r", "rt", "rgt"})
_TOKEN_RE = re.compile(r"[A-Z]+(?=[A-Z][a-z])|[A-Z]?[a-z]+|[A-Z]+|[0-9]+")

# Role -> {part key: rank}; a lower rank wins when two joints of a chain could take the role.
# Keys are the lower-case part tokens joined without digits (`LeftUpLeg` -> side "left", key
# "upleg"; `Bip01 L Toe0` -> "l", "toe"; `lShldrBend` -> "l", "shldrbend").
LEG_ROLES: dict[str, dict[str, int]] = {
    # CMU/Mixamo/LAFAN UpLeg, Bandai UpperLeg, Daz Thigh(Bend), 3ds Max/SMPL Hip, CMU's LHipJoint.
    "hip": {"upleg": 0, "upperleg": 0, "thigh": 0, "thighbend": 0, "femur": 0, "legupper": 0,
            "hip": 1, "hipjoint": 2},
    "knee": {"leg": 0, "lowerleg": 0, "shin": 0, "shinbend": 0, "calf": 0, "knee": 0, "loleg": 0,
             "lowleg": 0, "leglower": 0, "tibia": 0},
    # SMPL's `L_Foot` is the toe and `L_Ankle` the ankle; CMU's `LeftFoot` is the ankle.
    "ankle": {"foot": 0, "ankle": 0},
    "toe": {"toebase": 0, "toe": 0, "toes": 0, "ball": 0, "footend": 1, "foot": 1, "metatarsals": 1},
}
ARM_ROLES: dict[str, dict[str, int]] = {
    # CMU/Mixamo/Bandai `Shoulder` is the collar; SMPL's and 3ds Max-style `Shoulder` the shoulder.
    "collar": {"shoulder": 0, "collar": 0, "clavicle": 0, "clav": 0},
    "shoulder": {"arm": 0, "upperarm": 0, "uparm": 0, "shldr": 0, "shldrbend": 0, "humerus": 0,
                 "armupper": 0, "shoulder": 1},
    "elbow": {"forearm": 0, "lowerarm": 0, "loarm": 0, "elbow": 0, "forearmbend": 0, "armlower": 0},
    "wrist": {"hand": 0, "wrist": 0},
}
CENTRE_ROLES: dict[str, dict[str, int]] = {
    "pelvis": {"hips": 0, "hip": 0, "pelvis": 0},
    "neck": {"neck": 0, "necklower": 0, "neckupper": 1},
    "head": {"head": 0},
}
# Cost of leaving an optional role empty, against the ranks above.
_MISSING_COST = 2


def tokens(name: str) -> list[str]:
    """Lower-case tokens of a joint name, without a `ns:` namespace and without rig prefixes."""
    name = name.rsplit(":", 1)[-1].rsplit("|", 1)[-1]
    toks = []
    for t in _TOKEN_RE.findall(name):
        t = t.lower()
        # One-word spellings ("LEFTUPLEG", "leftfoot", "footleft") keep their side apart.
        for s in ("left", "right"):
            if len(t) > len(s) and t.startswith(s):
                toks.append(s)
                t = t[len(s):]
            elif len(t) > len(s) and t.endswith(s):
                toks.append(t[: -len(s)])
                t = s
        toks.append(t)
    while toks and (toks[0] in _PREFIX_TOKENS or toks[0].isdigit()):
        toks = toks[1:]
    return toks


def side_and_key(name: str) -> tuple[str | None, str]:
    """`("left" | "right" | None, part key)` of a joint name, e.g. `"thigh.L"` -> `("left", "thigh")`."""
    toks = tokens(name)
    side = None
    if len(toks) > 1 and (toks[-1] in _LEFT or toks[-1] in _RIGHT):
        side, toks = ("left" if toks[-1] in _LEFT else "right"), toks[:-1]
    else:
        for k, t in enumerate(toks):
            if t in _LEFT or t in _RIGHT:
                side, toks = ("left" if t in _LEFT else "right"), toks[k + 1:]
                break
    return side, "".join(t for t in toks if not t.isdigit())


def _is_ancestor(parents: tuple[int, ...], a: int, b: int) -> bool:
    """Whether joint `a` is a strict ancestor of joint `b`."""
    b = parents[b]
    while b >= 0:
        if b == a:
            return True
        b = parents[b]
    return False


def match_chain(
    names: tuple[str, ...], parents: tuple[int, ...], side: str | None,
    roles: dict[str, dict[str, int]], optional: tuple[str, ...],
) -> dict[str, int | None] | None:
    """The joints of one chain (roles listed root to tip) by name, or None when names do not decide.

    Every role takes a joint of `side` whose part key is in the role's table; consecutive
    roles must be strict ancestors of each other. Of all consistent assignments the one with
    the lowest total rank wins (an empty optional role costs `_MISSING_COST`); ties go to the
    assignment whose joints are closest together in the hierarchy.
    """
    keyed = [side_and_key(n) for n in names]
    cands: list[list[int | None]] = []
    for role, table in roles.items():
        c: list[int | None] = [j for j, (s, k) in enumerate(keyed) if s == side and k in table]
        if role in optional:
            c.append(None)
        if not c:
            return None
        cands.append(c)
    best, best_score = None, None
    depth = depths(parents)
    for combo in itertools.product(*cands):
        present = [j for j in combo if j is not None]
        if any(not _is_ancestor(parents, a, b) for a, b in itertools.pairwise(present)):
            continue
        rank = sum(_MISSING_COST if j is None else table[keyed[j][1]]
                   for j, table in zip(combo, roles.values()))
        spread = depth[present[-1]] - depth[present[0]] if present else 0
        score = (rank, spread)
        if best_score is None or score < best_score:
            best, best_score = combo, score
    if best is None:
        return None
    return dict(zip(roles, best))


def match_centre(names: tuple[str, ...], role: str) -> list[int]:
    """Joints without a side whose key names `role` ("pelvis", "neck", "head"), best rank first."""
    table = CENTRE_ROLES[role]
    hits = []
    for j, n in enumerate(names):
        s, k = side_and_key(n)
        if s is None and k in table:
            hits.append((table[k], j))
    return [j for _, j in sorted(hits)]


def depths(parents: tuple[int, ...]) -> list[int]:
    d: list[int] = []
    for p in parents:
        d.append(0 if p < 0 else d[p] + 1)
    return d


def leg_roles_found(names: tuple[str, ...]) -> str:
    """What the name table finds of each leg, and which role no joint's name gives, for messages:
    e.g. "left leg: hip 'thigh_l', no knee (no joint named like leg, lowerleg, shin, calf, knee)"."""
    keyed = [side_and_key(n) for n in names]
    parts = []
    for side in ("left", "right"):
        found = []
        for role, table in LEG_ROLES.items():
            hits = sorted((table[k], j) for j, (s, k) in enumerate(keyed) if s == side and k in table)
            if hits:
                found.append(f"{role} {names[hits[0][1]]!r}")
            elif role != "toe":
                found.append(f"no {role} (no joint named like {', '.join(list(table)[:5])})")
        parts.append(f"{side} leg: " + ", ".join(found))
    return "; ".join(parts)
