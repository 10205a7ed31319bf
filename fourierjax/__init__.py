"""Differentiable JAX library for stylized human motion: Fourier gait models and expressive stance."""

import importlib as _importlib

from fourierjax import (
    anthropometry,
    contacts,
    crowd,
    errors,
    fourier,
    gait,
    io,
    kinematics,
    motion,
    rotations,
    skeleton,
    spectrum,
    style,
)
from fourierjax._compile_cache import enable_compile_cache
from fourierjax.crowd import Crowd, crowd_positions, make_crowd
from fourierjax.errors import FourierJaxError, UserError
from fourierjax.fourier import FourierModel, fit, fit_batch, synthesize, synthesize_batch, synthesize_phase
from fourierjax.io.bvh import BVHError, Motion, parse_bvh, read_bvh, write_bvh
from fourierjax.kinematics import FKResult, forward_kinematics, joint_positions
from fourierjax.skeleton import Skeleton, Topology

__version__ = "0.1.0"

# Public modules imported on first use (PEP 562): optimistix, TOML parsing, the bundled data
# index and the device mesh helpers stay out of `import fourierjax`. `viz` (matplotlib) loads the
# same way but is not in `__all__`, so that `from fourierjax import *` never imports matplotlib.
_LAZY_MODULES = ("config", "data", "model_io", "parallel", "stance", "viz")


def __getattr__(name: str):
    if name in _LAZY_MODULES:
        module = _importlib.import_module(f"fourierjax.{name}")
        globals()[name] = module
        return module
    raise AttributeError(f"module 'fourierjax' has no attribute {name!r}")


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(_LAZY_MODULES))


__all__ = [
    # modules
    "anthropometry",
    "config",
    "contacts",
    "crowd",
    "data",
    "errors",
    "fourier",
    "gait",
    "io",
    "kinematics",
    "model_io",
    "motion",
    "parallel",
    "rotations",
    "skeleton",
    "spectrum",
    "stance",
    "style",
    # the most used names
    "BVHError",
    "Crowd",
    "FKResult",
    "FourierJaxError",
    "FourierModel",
    "Motion",
    "Skeleton",
    "Topology",
    "UserError",
    "crowd_positions",
    "enable_compile_cache",
    "fit",
    "fit_batch",
    "forward_kinematics",
    "joint_positions",
    "make_crowd",
    "parse_bvh",
    "read_bvh",
    "synthesize",
    "synthesize_batch",
    "synthesize_phase",
    "write_bvh",
]
