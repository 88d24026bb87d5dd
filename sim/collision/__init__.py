"""Collision detection between the needle's segments and the tissue's exterior triangles."""

from sim.collision.segments import CollisionInputError, SegmentHits, intersect_segments_triangles

__all__ = ["CollisionInputError", "SegmentHits", "intersect_segments_triangles"]
