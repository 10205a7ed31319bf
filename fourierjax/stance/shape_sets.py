"""Shape sets (Neff & Fiume 2004, sec. 6): one intensity knob over a shape vector, as TOML data."""

import dataclasses
import os
import tomllib
from pathlib import Path

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float

from fourierjax.errors import UserError
from fourierjax.stance import _util as u
from fourierjax.stance.ik import Feet
from fourierjax.stance.problem import (
    SHAPE_PARAMS,
    StanceProblem,
    as_finite,
    check_bends,
    make_problem,
    negate_directions,
)
from fourierjax.stance.skeleton48 import Body
from fourierjax.stance.torso import COLLAR_STATES, SHAPE_CLASSES, class_weights, collar_sign

BUILTIN_DIR = Path(__file__).with_name("shape_sets")
_OBJECT_MODES = ("none", "optional", "required")
_SIDE_KEYS = {"sagittal_class", "coronal_class", "collar_y", "collar_z", "gaze",
              "abdomen_offset", "vector", "away", "curves"}  # fmt: skip
_CURVE_KINDS = ("linear", "late")


@dataclasses.dataclass(frozen=True)
class _Side:
    sagittal_class: str
    coronal_class: str
    collar_y: str
    collar_z: str
    gaze_object: bool
    abdomen_offset: bool
    vector: tuple[float, ...]  # [20]
    forward: tuple[float, ...]  # [20] object-directed, per u_z
    lateral: tuple[float, ...]  # [20] per u_x
    late_start: tuple[float, ...]  # [20] -1 = linear, else the "late" start


@dataclasses.dataclass(frozen=True)
class ShapeSet:
    """A loaded shape set (immutable; see the module docstring for the file format)."""

    name: str
    description: str
    object_mode: str
    positive: _Side
    negative: _Side | None
    source: str

    @property
    def needs_object(self) -> bool:
        return self.object_mode == "required"

    def evaluate(
        self, intensity: Float[Array, ""], object_xyz: Float[Array, "3"] | None = None
    ) -> dict[str, Array]:
        """The shape vector and states at `intensity` (jnp; traceable).

        Returns:
            dict with `shape` [20], `sagittal_weights` [4], `coronal_weights` [4],
            `collar_signs` [2], `gaze_object` (0/1 scalar).
        """
        i = jnp.asarray(intensity, float)
        if i.shape != ():
            raise UserError(f"shape set {self.name!r}: intensity must be a single number, got "
                            f"shape {i.shape} (vmap over intensities for a sweep)")
        if object_xyz is None:
            ux, uz = jnp.asarray(0.0), jnp.asarray(1.0)
        else:
            o = jnp.asarray(object_xyz, float)
            d = u.safe_normalize(jnp.stack([o[0], o[2]]), jnp.array([0.0, 1.0]))
            ux, uz = d[0], d[1]

        def side_values(side: _Side, t):
            late = jnp.asarray(side.late_start)
            is_late = late >= 0.0
            s = jnp.where(is_late, late, 0.0)
            ramp = jnp.maximum(t - s, 0.0) / jnp.where(is_late, 1.0 - s, 1.0)
            curve = jnp.where(is_late, ramp * ramp, t)
            base = jnp.asarray(side.vector) + uz * jnp.asarray(side.forward)
            base = base + ux * jnp.asarray(side.lateral)
            return curve * base, _states(side)

        pos, pos_states = side_values(self.positive, jnp.abs(i))
        if self.negative is None:
            # No negative side: the positive one pointing the other way (directions negated,
            # bends and the gaze weight kept: `problem.negate_directions`).
            neg, neg_states = negate_directions(pos), pos_states
        else:
            neg, neg_states = side_values(self.negative, jnp.abs(i))
        use_pos = i >= 0.0
        out = {"shape": jnp.where(use_pos, pos, neg)}
        for k in pos_states:
            out[k] = jnp.where(use_pos, pos_states[k], neg_states[k])
        return out

    def check_shape(self, shape: Float[Array, "20"], intensity, object_xyz=None) -> None:
        """Refuse a known shape vector of this set that `problem` could not solve (traced: no
        check here; the solvers flag it as `invalid_input`).

        Arguments:
            shape: `[20]` the shape vector at `intensity` (`evaluate(...)["shape"]`).
            intensity, object_xyz: the values it was evaluated at (for the message).

        Raises:
            UserError: NaN or infinite values (a huge intensity overflows the "late" curves,
                which square it), or a knee or elbow bend out of range (`check_bends`).
        """
        if isinstance(shape, jax.core.Tracer):
            return
        if not np.isfinite(shape).all():
            bad = [n for n, v in zip(SHAPE_PARAMS, np.asarray(shape)) if not np.isfinite(v)]
            with_object = "" if object_xyz is None else f" (object_xyz {np.asarray(object_xyz).tolist()})"
            raise UserError(
                f"shape set {self.name!r}: intensity {float(intensity):.6g}{with_object} gives a shape "
                f"vector with infinite or NaN values in {bad}; use a smaller intensity"
            )
        check_bends(shape, f"shape set {self.name!r}: intensity {float(intensity):.6g}")

    def problem(
        self,
        body: Body,
        intensity: Float[Array, ""],
        object_xyz=None,
        *,
        target_right=None,
        target_left=None,
        feet: Feet | None = None,
        dominant: str = "right",
    ) -> StanceProblem:
        """The `StanceProblem` of this shape set at `intensity` (traceable in intensity,
        object and targets; vmap it over intensities for a sweep).

        Arguments:
            body: the character.
            intensity: the knob (0 = neutral; 1 = the shape vector; beyond extrapolates).
            object_xyz: `[3]` world object (m), required by sets with `object = "required"`.
            target_right, target_left: `[3]` wrist targets (m) or None.
            feet: planted feet (default: at the origin, facing +Z).
            dominant: "right" or "left".
        """
        if object_xyz is None and self.needs_object:
            raise UserError(f"shape set {self.name!r} needs an object position (--object x,y,z)")
        intensity = as_finite(intensity, f"shape set {self.name!r}: intensity")
        if object_xyz is not None:
            object_xyz = as_finite(object_xyz, f"shape set {self.name!r}: object_xyz")
            if object_xyz.shape != (3,):
                raise UserError(f"shape set {self.name!r}: object_xyz must be 3 coordinates, "
                                f"got shape {object_xyz.shape}")
        base = make_problem(
            body,
            feet=feet,
            target_right=target_right,
            target_left=target_left,
            abdomen_offset=self.positive.abdomen_offset,
            dominant=dominant,
        )
        ev = self.evaluate(intensity, object_xyz)
        self.check_shape(ev["shape"], intensity, object_xyz)
        gaze = base.gaze_point
        if object_xyz is not None:
            gaze = jnp.where(ev["gaze_object"] > 0.5, jnp.asarray(object_xyz, gaze.dtype), gaze)
        dt = base.shape.dtype
        return eqx.tree_at(
            lambda p: (p.shape, p.sagittal_weights, p.coronal_weights, p.collar_signs,
                       p.gaze_point),  # fmt: skip
            base,
            (ev["shape"].astype(dt), ev["sagittal_weights"].astype(dt),
             ev["coronal_weights"].astype(dt), ev["collar_signs"].astype(dt),
             gaze.astype(dt)),  # fmt: skip
        )


def _states(side: _Side) -> dict[str, Array]:
    return {
        "sagittal_weights": class_weights("sagittal", side.sagittal_class),
        "coronal_weights": class_weights("coronal", side.coronal_class),
        "collar_signs": jnp.array([collar_sign(side.collar_y), collar_sign(side.collar_z)]),
        "gaze_object": jnp.asarray(1.0 if side.gaze_object else 0.0),
    }


def _err(source: str, key: str, msg: str) -> UserError:
    return UserError(f"{source}: {key}: {msg}")


def _number(source, key, v) -> float:
    if isinstance(v, bool) or not isinstance(v, int | float) or not np.isfinite(v):
        raise _err(source, key, f"must be a finite number, got {v!r}")
    return float(v)


def _parse_side(source: str, prefix: str, t) -> _Side:
    if not isinstance(t, dict):
        raise _err(source, prefix, "must be a table")
    unknown = sorted(set(t) - _SIDE_KEYS)
    if unknown:
        raise _err(source, f"{prefix}.{unknown[0]}", f"unknown key; known: {sorted(_SIDE_KEYS)}")
    states = {}
    for key, choices, default in (
        ("sagittal_class", SHAPE_CLASSES, "straight"),
        ("coronal_class", SHAPE_CLASSES, "straight"),
        ("collar_y", tuple(COLLAR_STATES), "aligned"),
        ("collar_z", tuple(COLLAR_STATES), "aligned"),
    ):
        v = t.get(key, default)
        if v not in choices:
            raise _err(source, f"{prefix}.{key}", f"must be one of {list(choices)}, got {v!r}")
        states[key] = v
    gaze = t.get("gaze", "none")
    if gaze not in ("none", "object"):
        raise _err(source, f"{prefix}.gaze", f"must be 'none' or 'object', got {gaze!r}")
    abd = t.get("abdomen_offset", False)
    if not isinstance(abd, bool):
        raise _err(source, f"{prefix}.abdomen_offset", f"must be true or false, got {abd!r}")
    n = len(SHAPE_PARAMS)
    vec, fwd, lat, late = [0.0] * n, [0.0] * n, [0.0] * n, [-1.0] * n

    def index(table, name):
        if name not in SHAPE_PARAMS:
            raise _err(source, f"{prefix}.{table}.{name}",
                       f"unknown shape parameter; known: {list(SHAPE_PARAMS)}")  # fmt: skip
        return SHAPE_PARAMS.index(name)

    for name, v in _table(source, f"{prefix}.vector", t.get("vector", {})).items():
        vec[index("vector", name)] = _number(source, f"{prefix}.vector.{name}", v)
    for name, v in _table(source, f"{prefix}.away", t.get("away", {})).items():
        k = index("away", name)
        v = _table(source, f"{prefix}.away.{name}", v)
        bad = sorted(set(v) - {"forward", "lateral"})
        if bad:
            raise _err(source, f"{prefix}.away.{name}.{bad[0]}", "use 'forward' and 'lateral'")
        fwd[k] = _number(source, f"{prefix}.away.{name}.forward", v.get("forward", 0.0))
        lat[k] = _number(source, f"{prefix}.away.{name}.lateral", v.get("lateral", 0.0))
    for name, v in _table(source, f"{prefix}.curves", t.get("curves", {})).items():
        k = index("curves", name)
        v = _table(source, f"{prefix}.curves.{name}", v)
        kind = v.get("kind", "linear")
        if kind not in _CURVE_KINDS:
            raise _err(source, f"{prefix}.curves.{name}.kind", f"must be one of {list(_CURVE_KINDS)}")
        if kind == "late":
            s = _number(source, f"{prefix}.curves.{name}.start", v.get("start", 0.5))
            if not 0.0 <= s < 1.0:
                raise _err(source, f"{prefix}.curves.{name}.start", "must be in [0, 1)")
            late[k] = s
    return _Side(
        sagittal_class=states["sagittal_class"],
        coronal_class=states["coronal_class"],
        collar_y=states["collar_y"],
        collar_z=states["collar_z"],
        gaze_object=gaze == "object",
        abdomen_offset=abd,
        vector=tuple(vec),
        forward=tuple(fwd),
        lateral=tuple(lat),
        late_start=tuple(late),
    )


def _table(source, key, v) -> dict:
    if not isinstance(v, dict):
        raise _err(source, key, "must be a table")
    return v


def parse_shape_set(text: str, source: str = "<string>") -> ShapeSet:
    """Parse and validate a shape set from TOML text (errors name the source and the key).

    Format (see `fourierjax/stance/shape_sets/*.toml`; `configs/shape_sets/slouch.toml` is a user
    example loaded by path). Top level: `name`, `description`, `object` ("none", "optional" or
    "required"). Then a `[positive]` table (used for intensity >= 0) and an optional
    `[negative]` table (intensity < 0; without it negative intensities point the positive side
    the other way: its directions negated, its knee and elbow bends and gaze weight kept, see
    `problem.MAGNITUDE_PARAMS`). Each side has:

    - states: `sagittal_class`, `coronal_class` (`torso.SHAPE_CLASSES`), `collar_y`, `collar_z`
      ("aligned"/"opposed"), optional `gaze = "object"` (look at the object) and
      `abdomen_offset = true` (let the solver move the abdomen X offset);
    - `[side.vector]`: shape-vector values (`problem.SHAPE_PARAMS`) at |intensity| = 1;
    - `[side.away]`: object-directed values, `name = { forward = a, lateral = b }` adds
      `a * u_z + b * u_x` where `u` is the horizontal unit direction from the character (at the
      origin, facing +Z) to the object; "away" because the recoil sets lean against `u`;
    - `[side.curves]`: per-parameter interpolation, `{ kind = "linear" }` (default) or
      `{ kind = "late", start = s }`: zero until |intensity| = s, then ((t - s) / (1 - s))^2
      (the knee bend that only comes near the hunched end of the posture scale).

    Values scale with the intensity from the neutral origin (all zeros) and extrapolate beyond
    |intensity| = 1 (a weight or forward shift past +-1 can put the balance point off the feet:
    `problem.balance_margin_m` says how far). The class states switch with the sign of the
    intensity, where all desired amplitudes are zero, so poses stay continuous in the intensity when no reach target is
    active. With an active target the solver moves the amplitudes off their desired values, so
    they are not zero at intensity 0 and the class switch shows as a jump in the pose there
    (measured, posture set, right-hand target (-0.35, 1.05, 0.55): objective 25.21 and
    sagittal amplitude 0.215 at intensity -1e-5, 21.13 and 0.366 at +1e-5). Neff & Fiume switch
    the sagittal class "as the sagittal amplitude passes through zero" (sec. 6); switching on
    the solved amplitudes inside the solver is not implemented. Everything after loading is jnp:
    the intensity and the object can be traced (vmap over intensities; differentiate through
    the solver).

    Arguments:
        text: the TOML text.
        source: where it came from, for error messages (a path or "<string>").

    Returns:
        The `ShapeSet`.

    Raises:
        UserError: invalid TOML or an invalid shape set, naming `source` and the key.
    """
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as err:
        raise UserError(f"{source}: not valid TOML: {err}") from None
    known = {"name", "description", "object", "positive", "negative"}
    unknown = sorted(set(data) - known)
    if unknown:
        raise _err(source, unknown[0], f"unknown key; known: {sorted(known)}")
    name = data.get("name")
    if not isinstance(name, str) or not name or any(c.isspace() for c in name):
        raise _err(source, "name", f"must be a non-empty word, got {name!r}")
    desc = data.get("description", "")
    if not isinstance(desc, str):
        raise _err(source, "description", "must be a string")
    mode = data.get("object", "none")
    if mode not in _OBJECT_MODES:
        raise _err(source, "object", f"must be one of {list(_OBJECT_MODES)}, got {mode!r}")
    if "positive" not in data:
        raise _err(source, "positive", "missing (the shape vector at intensity +1)")
    pos = _parse_side(source, "positive", data["positive"])
    neg = _parse_side(source, "negative", data["negative"]) if "negative" in data else None
    return ShapeSet(name, desc, mode, pos, neg, source)


def load_shape_set(path: str | os.PathLike) -> ShapeSet:
    """Load a shape set from a TOML file.

    Arguments:
        path: the `.toml` file (UTF-8 text).

    Returns:
        The `ShapeSet`.

    Raises:
        UserError: the file cannot be read, is not UTF-8 text (e.g. a binary `.npz` given by
            mistake), or is not a valid shape set.
    """
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8")
    except OSError as err:
        raise UserError(f"{path}: cannot read shape set: {err.strerror}") from None
    except UnicodeDecodeError as err:
        raise UserError(
            f"{path}: not a shape set: a shape set is a UTF-8 TOML text file, and byte "
            f"{err.start} is not UTF-8 (a binary file?)"
        ) from None
    return parse_shape_set(text, str(path))


def builtin_shape_sets() -> dict[str, ShapeSet]:
    """The shape sets shipped with the package, by name (sorted)."""
    sets = {}
    for p in sorted(BUILTIN_DIR.glob("*.toml")):
        s = load_shape_set(p)
        sets[s.name] = s
    return dict(sorted(sets.items()))


def get_shape_set(name_or_path: str) -> ShapeSet:
    """A built-in shape set by name, or a shape set file by path (ends with .toml, holds a
    directory separator, or names an existing file that is not a built-in name)."""
    if name_or_path.endswith(".toml") or os.sep in name_or_path:
        return load_shape_set(name_or_path)
    sets = builtin_shape_sets()
    if name_or_path not in sets and os.path.isfile(name_or_path):
        return load_shape_set(name_or_path)
    if name_or_path not in sets:
        raise UserError(
            f"unknown shape set {name_or_path!r}; choose one of {', '.join(sets)} "
            "or give a .toml file"
        )
    return sets[name_or_path]


def perturb(shape: Float[Array, "20"], key, scale: float = 0.03) -> Float[Array, "20"]:
    """A small random variation of a shape vector (sec. 6: same pose family, not the same
    pose): Gaussian noise of `scale` (rad, or fraction for the shifts) on nonzero entries."""
    noise = scale * jax.random.normal(key, shape.shape, shape.dtype)
    return shape + jnp.where(shape != 0.0, noise, 0.0)


def anticipation(shape: Float[Array, "20"], fraction: float = 0.3) -> Float[Array, "20"]:
    """The wind-up before a move (sec. 6: "negating and reducing the amplitude of a shape
    vector allows a character to move backwards"): the shape vector times `fraction`, its
    directions negated and its bends and gaze weight kept (`problem.negate_directions`)."""
    return fraction * negate_directions(shape)
