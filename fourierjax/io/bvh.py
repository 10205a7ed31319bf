"""Fast NumPy reader and writer for BVH motion files, with errors that name the file and line."""

from fourierjax.io._bvh_motion import MAX_ABS_VALUE, MAX_FRAME_TIME_S, MIN_FRAME_TIME_S, BVHError, Motion
from fourierjax.io._bvh_parse import parse_bvh, read_bvh
from fourierjax.io._bvh_write import format_bvh, write_bvh

__all__ = ["BVHError", "MAX_ABS_VALUE", "MAX_FRAME_TIME_S", "MIN_FRAME_TIME_S", "Motion", "format_bvh",
           "parse_bvh", "read_bvh", "write_bvh"]
