//! Mesh validity: closed, oriented, manifold, free of self-intersections (exact).
