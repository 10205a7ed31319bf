"""Differentiable JAX library for stylized human motion."""

from fourierjax import anthropometry, contacts, fourier, gait, kinematics, motion, rotations, skeleton, spectrum, style
from fourierjax.crowd import Crowd, crowd_positions, make_crowd
from fourierjax.errors import FourierJaxError, UserError
from fourierjax.fourier import FourierModel, synthesize, synthesize_batch, synthesize_phase
from fourierjax.io.bvh import BVHError, Motion, read_bvh, write_bvh
from fourierjax.kinematics import FKResult, forward_kinematics, joint_positions
from fourierjax.skeleton import Skeleton, Topology

__version__ = "0.1.0"

__all__ = [
    "BVHError",
    "Crowd",
    "FKResult",
    "FourierJaxError",
    "FourierModel",
    "Motion",
    "Skeleton",
    "Topology",
    "UserError",
    "anthropometry",
    "contacts",
    "crowd_positions",
    "forward_kinematics",
    "fourier",
    "gait",
    "joint_positions",
    "kinematics",
    "make_crowd",
    "motion",
    "read_bvh",
    "rotations",
    "skeleton",
    "spectrum",
    "style",
    "synthesize",
    "synthesize_batch",
    "synthesize_phase",
    "write_bvh",
]
