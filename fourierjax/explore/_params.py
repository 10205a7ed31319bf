"""The explorer's parameter set (what the sliders show) and its TOML form for `synth --config`."""

from __future__ import annotations

import dataclasses
import math

from fourierjax.errors import UserError

#: `format` of an explore config file; `fourierjax synth --config` refuses any other.
CONFIG_FORMAT = "fourierjax.explore_config"
CONFIG_VERSION = 1
#: Hip rules of `gait.synthesize_gait`, repeated so that the parameter set does not import JAX.
HIP_RULES = ("unuma1995", "continuous", "smooth")
#: The tightest circle a path may have (m): a quarter of a stride; tighter, the walker spins.
MIN_PATH_RADIUS_M = 0.25


@dataclasses.dataclass(frozen=True)
class Params:
    """One state of the gait panel: every number `synth --config` needs to redo the synthesis.

    - `a`, `b`: names of the two gaits of the library (Unuma eq. 3 at `s`; `s` in [-1, 2]).
    - `weights`: `(name, weight)` per loaded characteristic (Unuma eq. 8).
    - `step`, `speed`, `gait`, `jump`, `hip_rule`, `root_motion`: the step constraints (§3.1).
    - `noise_deg`, `noise_harmonics`, `seed`: Unuma §3.3 noise on the rotation channels.
    - `foot_lock`: plant the feet (`synthesize_gait(foot_lock=)`, the library's locking; on by
      default, as in `synth`).
    - `path_radius_m`: 0 walks straight on; otherwise the walk follows a circle of that radius
      in metres, turning left (> 0) or right (< 0), as `synth --path circle:R`.
    - `seconds`, `fps`: length and frame rate of the synthesized (and exported) motion.
    """

    a: str
    b: str
    s: float = 0.0
    weights: tuple[tuple[str, float], ...] = ()
    step: float = 1.0
    speed: float = 1.0
    gait: float = 1.0
    jump: float = 0.0
    hip_rule: str = "unuma1995"
    root_motion: bool = True
    noise_deg: float = 0.0
    noise_harmonics: int = 3
    seed: int = 0
    foot_lock: bool = True
    path_radius_m: float = 0.0
    seconds: float = 4.0
    fps: float = 60.0

    def __post_init__(self):
        check_params(self)

    @property
    def num_frames(self) -> int:
        """Frames of the synthesized motion (at least 2)."""
        return max(2, int(round(self.seconds * self.fps)))

    @property
    def frame_time_s(self) -> float:
        """Seconds per frame."""
        return 1.0 / self.fps


_RANGES = {  # name: (low, high), inclusive; None = unbounded
    "s": (-1.0, 2.0),
    "step": (0.0, None),
    "speed": (0.0, None),
    "gait": (0.0, 1.0),
    "jump": (0.0, None),
    "noise_deg": (0.0, 90.0),
    "path_radius_m": (-1000.0, 1000.0),
    "seconds": (1e-3, 600.0),
    "fps": (1.0, 1000.0),
}


def check_params(p: Params) -> None:
    """Raise `UserError` naming the first value out of range (each with its range)."""
    for name, (lo, hi) in _RANGES.items():
        v = getattr(p, name)
        if isinstance(v, bool) or not isinstance(v, int | float) or not math.isfinite(v):
            raise UserError(f"{name}: must be a finite number, got {v!r}")
        if v < lo or (hi is not None and v > hi):
            raise UserError(f"{name}: must be in [{lo:g}, {'inf' if hi is None else f'{hi:g}'}], got {v!r}")
    for name, w in p.weights:
        if isinstance(w, bool) or not isinstance(w, int | float) or not math.isfinite(w):
            raise UserError(f"characteristic {name!r}: weight must be a finite number, got {w!r}")
    if 0.0 < abs(p.path_radius_m) < MIN_PATH_RADIUS_M:
        raise UserError(f"path_radius_m: 0 (straight) or a radius of at least {MIN_PATH_RADIUS_M:g} m "
                        f"(negative turns right), got {p.path_radius_m!r}")
    if p.hip_rule not in HIP_RULES:
        raise UserError(f"hip_rule: expected one of {', '.join(HIP_RULES)}, got {p.hip_rule!r}")
    if isinstance(p.noise_harmonics, bool) or not isinstance(p.noise_harmonics, int) or p.noise_harmonics < 1:
        raise UserError(f"noise_harmonics: must be an integer >= 1, got {p.noise_harmonics!r}")
    if isinstance(p.seed, bool) or not isinstance(p.seed, int):
        raise UserError(f"seed: must be an integer, got {p.seed!r}")


def _toml_value(v) -> str:
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, int):
        return str(v)
    if isinstance(v, float):
        return repr(v)  # shortest round-trip form: the file reproduces the float exactly
    return '"' + str(v).replace("\\", "\\\\").replace('"', '\\"') + '"'


def config_text(p: Params, files: dict[str, str]) -> str:
    """The TOML config of a parameter set.

    Arguments:
        p: the parameter set.
        files: gait and characteristic name -> model or characteristic file (relative to the
            config's folder), for `p.a`, `p.b` and every name of `p.weights`.

    Returns:
        The text of a file that `fourierjax synth --config FILE --out OUT.bvh` reproduces.
    """
    lines = [
        "# Written by `fourierjax explore`. Reproduce it with",
        "#   fourierjax synth --config THIS_FILE --out OUT.bvh",
        f'format = "{CONFIG_FORMAT}"',
        f"version = {CONFIG_VERSION}",
        "",
        "[models]  # model files (fourierjax fit), relative to this file",
        f"a = {_toml_value(files[p.a])}",
        f"b = {_toml_value(files[p.b])}",
        "",
        "[gait]",
    ]
    for key in ("s", "step", "speed", "gait", "jump", "hip_rule", "root_motion", "foot_lock", "path_radius_m",
                "seconds", "fps"):
        lines.append(f"{key} = {_toml_value(getattr(p, key))}")
    lines += ["", "[noise]", f"degrees = {_toml_value(p.noise_deg)}",
              f"harmonics = {p.noise_harmonics}", f"seed = {p.seed}"]
    for name, w in p.weights:
        lines += ["", f"[characteristics.{_toml_value(name)}]", f"file = {_toml_value(files[name])}",
                  f"weight = {_toml_value(float(w))}"]
    return "\n".join(lines) + "\n"
