//! Axis-aligned bounding-box hierarchy over triangles.
