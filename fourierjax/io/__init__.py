"""File formats at the edge of the library (NumPy, no JAX tracing): BVH motion files here, model
and characteristic files in `fourierjax.io.model_io`."""

from fourierjax.io.bvh import BVHError, Motion, format_bvh, parse_bvh, read_bvh, write_bvh

__all__ = ["BVHError", "Motion", "format_bvh", "parse_bvh", "read_bvh", "write_bvh"]
