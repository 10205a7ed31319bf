"""`BodyMap`: which joints of a skeleton are the legs, feet, trunk and arms, and its up axis and units."""

from __future__ import annotations

import dataclasses
import json
import math
import os
import pathlib
import tomllib

from fourierjax.errors import UserError

#: Version of the dictionary / TOML layout written by `BodyMap.to_dict` and `to_toml`.
BODY_MAP_VERSION = 1
#: Metres per file unit of the units a map can name.
UNITS: dict[str, float] = {"m": 1.0, "cm": 0.01, "mm": 0.001, "in": 0.0254, "cmu": 0.0564}
_UNIT_ALIASES = {"metres": "m", "meters": "m", "metre": "m", "meter": "m", "centimetres": "cm",
                 "centimeters": "cm", "millimetres": "mm", "millimeters": "mm", "inches": "in",
                 "inch": "in"}
AXES = "xyz"
END_SITE = "/End Site"  # an End Site is named "<parent joint>/End Site", as in `contacts.FootPoints`

_MINIMAL_TOML = """\
[legs.left]
hip = "thigh_l"     # the thigh joint (Unuma's groin)
knee = "calf_l"
ankle = "foot_l"
toe = "ball_l"      # optional
[legs.right]
hip = "thigh_r"
knee = "calf_r"
ankle = "foot_r"
toe = "ball_r"
# optional: trajectory = "Hips", up = "y" (or "z", "-z"), units = "cm" (m, cm, mm, in, cmu)"""


class BodyMapError(UserError):
    """A skeleton whose legs (or another required part) cannot be found or a map that does not fit it."""


@dataclasses.dataclass(frozen=True)
class Leg:
    """One leg: joint indices into the topology (`toe` is -1 when the rig has none).

    `foot_points` index the concatenation of joints and End Sites (`J + e` is End Site `e`),
    ankle first and toe tip last, as `fourierjax.contacts.FootPoints` does; `names` are the
    names of `(hip, knee, ankle, toe)` ("" for no toe) and `foot_point_names` those of the points.
    """

    hip: int
    knee: int
    ankle: int
    toe: int
    foot_points: tuple[int, ...]
    names: tuple[str, str, str, str]
    foot_point_names: tuple[str, ...]


@dataclasses.dataclass(frozen=True)
class Arm:
    """One arm: joint indices (`collar` is -1 when the rig has none) and their names."""

    collar: int
    shoulder: int
    elbow: int
    wrist: int
    names: tuple[str, str, str, str]


@dataclasses.dataclass(frozen=True)
class BodyMap:
    """A skeleton's body parts, up axis, facing and scale: immutable and hashable (a jit static argument).

    Joint fields are indices into the topology the map was made for; `joint_names` holds that
    topology's names, for messages and to check that a stored map fits a skeleton.

    Attributes:
        joint_names: the topology's joint names, in file order.
        left, right: the legs (`Leg`).
        trajectory: the joint whose position channels carry the travel.
        pelvis: the joint the legs and the spine hang from.
        spine: the joints from the pelvis (exclusive) to the neck or head (exclusive).
        neck, head: joint indices, -1 when not found.
        left_arm, right_arm: `Arm`, or None when not found.
        up_axis: 0, 1 or 2 (x, y, z); up_sign: +1 or -1.
        forward: unit vector in the ground plane (file axes): the direction of travel when the
            clip travels, the facing otherwise.
        facing: unit vector in the ground plane: where the toes (or the knees) point.
        leg_length: hip to ankle through the knee, in file units (median over frames).
        height: head top above the feet in the mean pose, file units.
        units: a key of `UNITS`; metres_per_unit: its value (or a user-given scale).
        sources: `(field, how)` pairs, how in "names", "geometry", "file" (an override),
            "argument" (a keyword argument) or "stored" (`from_dict`).
    """

    joint_names: tuple[str, ...]
    left: Leg
    right: Leg
    trajectory: int
    pelvis: int
    spine: tuple[int, ...]
    neck: int
    head: int
    left_arm: Arm | None
    right_arm: Arm | None
    up_axis: int
    up_sign: int
    forward: tuple[float, float, float]
    facing: tuple[float, float, float]
    leg_length: float
    height: float
    units: str
    metres_per_unit: float
    sources: tuple[tuple[str, str], ...] = ()

    # -- what consumers ask for ---------------------------------------------------------
    @property
    def groins(self) -> tuple[int, int]:
        """`(left hip, right hip)` joint indices: Unuma's groins, for the hip-height rule."""
        return self.left.hip, self.right.hip

    @property
    def feet(self) -> tuple[tuple[int, ...], tuple[int, ...]]:
        """`(left, right)` foot point indices into joints + End Sites, ankle first, toe tip last."""
        return self.left.foot_points, self.right.foot_points

    @property
    def up(self) -> tuple[float, float, float]:
        """The up direction as a unit vector in file axes."""
        v = [0.0, 0.0, 0.0]
        v[self.up_axis] = float(self.up_sign)
        return tuple(v)  # type: ignore[return-value]

    @property
    def left_direction(self) -> tuple[float, float, float]:
        """`up × forward`: the body's left in the ground plane (right-handed axes)."""
        u, f = self.up, self.forward
        return (u[1] * f[2] - u[2] * f[1], u[2] * f[0] - u[0] * f[2], u[0] * f[1] - u[1] * f[0])

    def source(self, field: str) -> str:
        """How `field` was found ("names", "geometry", "file", "argument", "stored")."""
        return dict(self.sources).get(field, "geometry")

    def name(self, joint: int) -> str:
        """The name of joint `joint`, "" for -1 (a part the rig does not have)."""
        return self.joint_names[joint] if joint >= 0 else ""

    # -- storage ------------------------------------------------------------------------
    def to_dict(self) -> dict:
        """A JSON-ready dictionary naming every joint (for a model file's header); see `from_dict`."""
        def leg(g: Leg) -> dict:
            d = dict(zip(("hip", "knee", "ankle", "toe"), g.names))
            if not d["toe"]:
                del d["toe"]
            d["foot_points"] = list(g.foot_point_names)
            return d

        def arm(a: Arm) -> dict:
            d = dict(zip(("collar", "shoulder", "elbow", "wrist"), a.names))
            if not d["collar"]:
                del d["collar"]
            return d

        out: dict = {
            "version": BODY_MAP_VERSION,
            "up": ("-" if self.up_sign < 0 else "") + AXES[self.up_axis],
            "forward": list(self.forward),
            "facing": list(self.facing),
            "units": self.units,
            "metres_per_unit": self.metres_per_unit,
            "leg_length": self.leg_length,
            "height": self.height,
            "trajectory": self.name(self.trajectory),
            "pelvis": self.name(self.pelvis),
            "spine": [self.name(j) for j in self.spine],
            "legs": {"left": leg(self.left), "right": leg(self.right)},
        }
        if self.neck >= 0:
            out["neck"] = self.name(self.neck)
        if self.head >= 0:
            out["head"] = self.name(self.head)
        if self.left_arm is not None and self.right_arm is not None:
            out["arms"] = {"left": arm(self.left_arm), "right": arm(self.right_arm)}
        out["sources"] = dict(self.sources)
        return out

    def to_toml(self) -> str:
        """The map as a TOML override file (every field by joint name); `infer_body_map` reads it back."""
        d = self.to_dict()
        lines = ["# fourierjax body map: joints by name; edit and pass as overrides"]
        tables = {k: d.pop(k) for k in ("legs", "arms", "sources") if k in d}
        lines += [f"{k} = {_toml_value(v)}" for k, v in d.items()]
        for group in ("legs", "arms"):
            for side, fields in tables.get(group, {}).items():
                lines.append(f"\n[{group}.{side}]")
                lines += [f"{k} = {_toml_value(v)}" for k, v in fields.items()]
        lines.append("\n[sources]")
        lines += [f"{json.dumps(k)} = {_toml_value(v)}" for k, v in tables["sources"].items()]
        return "\n".join(lines) + "\n"

    def describe(self) -> str:
        """A few human-readable lines (for `fourierjax info`)."""
        s = self.source

        def leg(g: Leg) -> str:
            return " > ".join(n for n in g.names if n)

        lines = [
            f"legs ({s('legs')}): left {leg(self.left)}; right {leg(self.right)}",
            f"feet: left {', '.join(self.left.foot_point_names)}; right {', '.join(self.right.foot_point_names)}",
            f"trajectory ({s('trajectory')}): {self.name(self.trajectory)}; pelvis: {self.name(self.pelvis)}",
            f"spine: {', '.join(self.name(j) for j in self.spine) or '-'}; neck: {self.name(self.neck) or '-'};"
            f" head: {self.name(self.head) or '-'}",
        ]
        if self.left_arm is not None and self.right_arm is not None:
            lines.append(f"arms ({s('arms')}): left {' > '.join(n for n in self.left_arm.names if n)};"
                         f" right {' > '.join(n for n in self.right_arm.names if n)}")
        f = ", ".join(f"{x:+.2f}" for x in self.forward)
        lines += [
            f"up ({s('up')}): {'-' if self.up_sign < 0 else '+'}{AXES[self.up_axis]}; forward ({s('forward')}): ({f})",
            f"units ({s('units')}): {self.units} ({self.metres_per_unit:g} m per unit); leg length "
            f"{self.leg_length:.4g} units ({self.leg_length * self.metres_per_unit:.2f} m), height "
            f"{self.height:.4g} units ({self.height * self.metres_per_unit:.2f} m)",
        ]
        return "\n".join(lines)


def _toml_value(v) -> str:
    if isinstance(v, str):
        return json.dumps(v)  # a JSON string is a TOML basic string
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, int | float):
        return repr(float(v)) if isinstance(v, float) else str(v)
    if isinstance(v, list | tuple):
        return "[" + ", ".join(_toml_value(x) for x in v) + "]"
    raise TypeError(f"no TOML spelling for {v!r}")


def parse_overrides(overrides) -> dict:
    """An override mapping from a dict, TOML text, or a path to a TOML file (`str` ending in .toml or a Path)."""
    if overrides is None:
        return {}
    if isinstance(overrides, dict):
        d = dict(overrides)
    elif isinstance(overrides, pathlib.Path) or (isinstance(overrides, str) and overrides.endswith(".toml")
                                                 and "\n" not in overrides):
        path = os.fspath(overrides)
        try:
            with open(path, "rb") as f:
                d = tomllib.load(f)
        except OSError as err:
            raise BodyMapError(f"{path}: cannot read the body map: {err.strerror or err}") from None
        except tomllib.TOMLDecodeError as err:
            raise BodyMapError(f"{path}: not a valid TOML body map: {err}") from None
    elif isinstance(overrides, str):
        try:
            d = tomllib.loads(overrides)
        except tomllib.TOMLDecodeError as err:
            raise BodyMapError(f"body map: not valid TOML: {err}") from None
    else:
        raise TypeError(f"overrides must be a dict, TOML text or a path, got {type(overrides).__name__}")
    version = d.get("version", BODY_MAP_VERSION)
    if version != BODY_MAP_VERSION:
        raise BodyMapError(f"body map: version {version!r} is not supported (this fourierjax reads "
                           f"version {BODY_MAP_VERSION})")
    known = {"version", "up", "forward", "facing", "units", "metres_per_unit", "leg_length", "height",
             "trajectory", "pelvis", "spine", "neck", "head", "legs", "arms", "sources"}
    unknown = sorted(set(d) - known)
    if unknown:
        raise BodyMapError(f"body map: unknown field(s) {unknown}; known fields are {sorted(known)}")
    return d


def parse_up(up) -> tuple[int, int]:
    """`(axis, sign)` from "y", "-z", "+x", 1, or `(axis, sign)`."""
    if isinstance(up, tuple | list) and len(up) == 2:
        axis, sign = int(up[0]), int(up[1])
    elif isinstance(up, int) and not isinstance(up, bool):
        axis, sign = up, 1
    elif isinstance(up, str) and up.strip().lower().lstrip("+-") in ("x", "y", "z"):
        t = up.strip().lower()
        axis, sign = AXES.index(t.lstrip("+-")), (-1 if t.startswith("-") else 1)
    else:
        raise BodyMapError(f"up must be 'x', 'y', 'z' (optionally signed, e.g. '-z') or 0/1/2, got {up!r}")
    if axis not in (0, 1, 2) or sign not in (1, -1):
        raise BodyMapError(f"up: axis must be 0, 1 or 2 and sign ±1, got {up!r}")
    return axis, sign


def parse_units(units) -> tuple[str, float]:
    """`(units key, metres per unit)` from a name in `UNITS` (or an alias) or a number of metres per unit."""
    if isinstance(units, int | float) and not isinstance(units, bool):
        if not (math.isfinite(units) and units > 0):
            raise BodyMapError(f"units: metres per unit must be a positive number, got {units!r}")
        return "custom", float(units)
    key = str(units).strip().lower()
    key = _UNIT_ALIASES.get(key, key)
    if key not in UNITS:
        raise BodyMapError(f"units: unknown unit {units!r}; use one of {sorted(UNITS)} or metres per unit")
    return key, UNITS[key]


def resolve_point(names: tuple[str, ...], end_site_parents: tuple[int, ...], spec: str, what: str) -> int:
    """Index of a joint name, or of `"<joint>/End Site"` (the first End Site of that joint) as `J + e`."""
    if spec.endswith(END_SITE):
        parent = resolve_joint(names, spec[: -len(END_SITE)], what)
        for e, p in enumerate(end_site_parents):
            if p == parent:
                return len(names) + e
        raise BodyMapError(f"body map: {what}: joint {names[parent]!r} has no End Site")
    return resolve_joint(names, spec, what)


def resolve_joint(names: tuple[str, ...], spec, what: str) -> int:
    """Index of joint `spec` (a name; an int index is accepted too), with a message naming the joints."""
    if isinstance(spec, int) and not isinstance(spec, bool):
        if 0 <= spec < len(names):
            return spec
    elif spec in names:
        return names.index(spec)
    shown = ", ".join(names[:40]) + (", ..." if len(names) > 40 else "")
    raise BodyMapError(f"body map: {what} = {spec!r} is not a joint of this skeleton; its joints are: {shown}")


def point_name(names: tuple[str, ...], end_site_parents: tuple[int, ...], point: int) -> str:
    """The name of a joint or End Site point index (see `resolve_point`)."""
    if point < len(names):
        return names[point]
    return names[end_site_parents[point - len(names)]] + END_SITE


def missing_legs_message(what: str, names: tuple[str, ...]) -> str:
    from fourierjax._body._names import leg_roles_found

    shown = ", ".join(names[:40]) + (", ..." if len(names) > 40 else "")
    return (f"cannot find the legs of this skeleton: {what}. By name, {leg_roles_found(names)}. Its joints "
            f"are: {shown}. Name them in a body map file (TOML): pass it as `--body-map FILE` on the command "
            f"line, or in Python as `infer_body_map(motion, overrides=FILE)` and give that map as `body_map=` "
            f"(fit_motions, synthesize_gait, ...). For example:\n{_MINIMAL_TOML}")
