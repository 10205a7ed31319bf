"""The joint-speed limit of `synth --add` (no limb flips from a characteristic's weight).

`fourierjax characteristic A B` records how fast the fastest joint of A and of B moves over a
cycle (`style.peak_joint_speed`, pelvis-relative, per second and per radian of phase), in body
heights so that it carries over to a base of another size. `synth MODEL --add C=W` then
superposes with `style.superpose(speed_limit=)` at the fastest of the base and the clips the
characteristics came from: a weight that would move a joint faster than any of them (a swing
extrapolated past a body's, a channel sent onto another branch) is scaled down along its own
line until it does not. `--no-speed-limit` keeps the weights as given.
"""

from __future__ import annotations

import math

#: The characteristic file's header key (`model_io.save_characteristic(joint_speed=)`).
HEADER_KEY = "joint_speed"


def _peaks(model, skeleton, body_map) -> tuple[float, float]:
    """(per second, per radian) peak joint speed of one model's cycle, in file units."""
    from fourierjax import style

    per_s = float(style.peak_joint_speed(model, skeleton, per="second", body_map=body_map))
    per_rad = float(style.peak_joint_speed(model, skeleton, per="radian", body_map=body_map))
    return per_s, per_rad


def _height(gait) -> float | None:
    h = getattr(getattr(gait, "body_map", None), "height", None)
    return float(h) if h is not None and math.isfinite(h) and h > 0 else None


def characteristic_speeds(a, b) -> dict | None:
    """The header entry of a characteristic A − B: the larger of A's and B's peak joint speeds
    per second and per radian of phase, in body heights; None when either gait has no skeleton
    or no body map to measure it on (a model file written without them)."""
    from fourierjax.body import BodyMapError
    from fourierjax.errors import UserError

    rows = []
    for g in (a, b):
        height = _height(g)
        if g.template is None or height is None:
            return None
        try:
            per_s, per_rad = _peaks(g.model, g.template.skeleton(), g.body_map)
        except (UserError, BodyMapError):  # a body map made for another skeleton
            return None
        if not (math.isfinite(per_s) and math.isfinite(per_rad)):
            return None
        rows.append((per_s / height, per_rad / height))
    return {"per_second": max(r[0] for r in rows), "per_radian": max(r[1] for r in rows),
            "unit": "body heights"}


def _stored(header: dict) -> tuple[float, float] | None:
    entry = (header or {}).get(HEADER_KEY)
    if not isinstance(entry, dict):
        return None
    try:
        per_s, per_rad = float(entry["per_second"]), float(entry["per_radian"])
    except (KeyError, TypeError, ValueError):
        return None
    ok = all(math.isfinite(v) and v > 0 for v in (per_s, per_rad))
    return (per_s, per_rad) if ok else None


def synth_limit(model, skeleton, body_map, headers: list[dict]):
    """`(style.SpeedLimit, None)` for `synth --add`, or `(None, why)` when one cannot be made.

    The limit is the fastest of the base (`model`, measured here) and every characteristic's
    recorded clips, scaled from body heights to the base's file units by its body map's height.
    """
    if body_map is None or not (getattr(body_map, "height", 0) or 0) > 0:
        return None, "the model file has no body map to size the clips' joint speeds with"
    stored = [_stored(h) for h in headers]
    if any(s is None for s in stored):
        return None, ("a characteristic file does not record its clips' joint speeds (written before "
                      "`fourierjax characteristic` stored them, or from model files without a skeleton)")
    from fourierjax import style
    from fourierjax.errors import UserError

    height = float(body_map.height)
    try:
        base_s, base_rad = _peaks(model, skeleton, body_map)
    except UserError as err:  # a stored body map that does not fit the model file's skeleton
        return None, f"the base's joint speeds cannot be measured ({err})"
    per_s = max(base_s, *(s[0] * height for s in stored))
    per_rad = max(base_rad, *(s[1] * height for s in stored))
    return style.SpeedLimit(skeleton, max_speed=per_s, max_phase_speed=per_rad, body_map=body_map), None


def excess(model, skeleton, body_map, limit) -> float:
    """How far `model`'s fastest joint is over `limit` (the larger of the two ratios; <= 1: within)."""
    per_s, per_rad = _peaks(model, skeleton, body_map)
    return max(per_s / float(limit.max_speed), per_rad / float(limit.max_phase_speed))
