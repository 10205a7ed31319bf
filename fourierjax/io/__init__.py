"""File formats at the edge of the library: BVH motion files (NumPy, no JAX tracing)."""

from fourierjax.io.bvh import BVHError, Motion, format_bvh, parse_bvh, read_bvh, write_bvh

__all__ = ["BVHError", "Motion", "format_bvh", "parse_bvh", "read_bvh", "write_bvh"]
