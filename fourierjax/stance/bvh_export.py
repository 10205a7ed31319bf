"""Deprecated: moved to `fourierjax.io.stance_bvh` (the stance core does not import io)."""

import importlib
import warnings

_NAMES = ("animate", "ease_in_out", "pose_to_motion", "write_stance_bvh")


def __getattr__(name):
    # Lazy: importing this module imports neither io nor motion; each name warns once per use.
    if name in _NAMES:
        warnings.warn(
            f"fourierjax.stance.bvh_export is deprecated; import {name} from fourierjax.io.stance_bvh",
            DeprecationWarning,
            stacklevel=2,
        )
        return getattr(importlib.import_module("fourierjax.io.stance_bvh"), name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
