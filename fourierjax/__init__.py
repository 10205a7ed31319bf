"""Differentiable JAX library for stylized human motion: Fourier gait models and expressive stance."""

import importlib as _importlib

__version__ = "0.1.0"

# Everything loads on first use (PEP 562), so that `import fourierjax` (and `fourierjax --help`)
# does not import JAX, and optimistix, TOML parsing, the bundled data index and matplotlib stay
# out until asked for. `viz` (matplotlib) is not in `__all__`, so `from fourierjax import *`
# never imports matplotlib.
_MODULES = ("anthropometry", "body", "config", "contacts", "crowd", "data", "errors", "features",
            "fourier", "gait", "io", "kinematics", "model_io", "motion", "parallel", "rotations",
            "skeleton", "spectrum", "stance", "style", "viz")
_NAMES = {
    "enable_compile_cache": "fourierjax._compile_cache",
    "Crowd": "fourierjax.crowd", "crowd_positions": "fourierjax.crowd", "make_crowd": "fourierjax.crowd",
    "FourierJaxError": "fourierjax.errors", "UserError": "fourierjax.errors",
    "FourierModel": "fourierjax.fourier", "fit": "fourierjax.fourier", "fit_batch": "fourierjax.fourier",
    "synthesize": "fourierjax.fourier", "synthesize_batch": "fourierjax.fourier",
    "synthesize_phase": "fourierjax.fourier",
    "BVHError": "fourierjax.io.bvh", "Motion": "fourierjax.io.bvh", "parse_bvh": "fourierjax.io.bvh",
    "read_bvh": "fourierjax.io.bvh", "write_bvh": "fourierjax.io.bvh",
    "FKResult": "fourierjax.kinematics", "forward_kinematics": "fourierjax.kinematics",
    "joint_positions": "fourierjax.kinematics",
    "Skeleton": "fourierjax.skeleton", "Topology": "fourierjax.skeleton",
    "BodyMap": "fourierjax.body", "infer_body_map": "fourierjax.body",
}


def __getattr__(name: str):
    if name in _MODULES:
        value = _importlib.import_module(f"fourierjax.{name}")
    elif name in _NAMES:
        value = getattr(_importlib.import_module(_NAMES[name]), name)
    else:
        raise AttributeError(f"module 'fourierjax' has no attribute {name!r}")
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(_MODULES) | set(_NAMES))


__all__ = [
    # modules
    "anthropometry",
    "body",
    "config",
    "contacts",
    "crowd",
    "data",
    "errors",
    "features",
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
    "BodyMap",
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
    "infer_body_map",
    "joint_positions",
    "make_crowd",
    "parse_bvh",
    "read_bvh",
    "synthesize",
    "synthesize_batch",
    "synthesize_phase",
    "write_bvh",
]
