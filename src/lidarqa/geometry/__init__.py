"""Planes, plane segmentation, edges (plane-pair segments) and corners (ALGORITHMS.md §1.2, §4)."""

from .segmentation import surface_growing

__all__ = ["surface_growing"]
