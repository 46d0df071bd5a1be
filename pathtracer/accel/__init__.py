"""Acceleration structure: binned-SAH BVH built on the host, traversed in kernels."""
from .bvh import BVH, build_bvh, sah_cost

__all__ = ["BVH", "build_bvh", "sah_cost"]
