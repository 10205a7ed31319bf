"""`fourierjax explore`: Unuma's interactive gait editor and Neff & Fiume's stance panel in the browser (viser)."""

from fourierjax.explore._engine import (
    DEFAULT_CHARACTERISTICS,
    DEFAULT_GAITS,
    Gait,
    Library,
    check_pair,
    default_library,
    edited_ground,
    edited_model,
    fit_clips,
    ground_path,
    load_sources,
    render,
    result_motion,
    synthesize_motion,
    synthesize_result,
    transition_motion,
    view_positions,
)
from fourierjax.explore._params import (
    CONFIG_FORMAT,
    CONFIG_VERSION,
    HIP_RULES,
    MIN_PATH_RADIUS_M,
    Params,
    config_text,
)

__all__ = [
    "CONFIG_FORMAT", "CONFIG_VERSION", "DEFAULT_CHARACTERISTICS", "DEFAULT_GAITS", "HIP_RULES", "Explorer",
    "MIN_PATH_RADIUS_M",
    "Gait", "Library", "Params", "check_pair", "config_text", "default_library", "edited_ground", "edited_model",
    "fit_clips", "ground_path", "load_sources", "render", "result_motion", "synthesize_motion",
    "synthesize_result", "transition_motion", "view_positions",
]  # fmt: skip


def __getattr__(name: str):
    # The server needs viser (the `explore` extra): imported only when asked for.
    if name == "Explorer":
        from fourierjax.explore._server import Explorer

        return Explorer
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
