//! Flat caps: edge flips that remove the triangles with an angle near 180 degrees ("caps")
//! lying in a flat part of the surface, whose normals are noise.
//!
//! The v* of a flat region form a near-lattice on its plane (exactly on it after the
//! refinement against exact distances), and the minimum cut's surface has caps there: three
//! nearly collinear vertices. Across the cap's short height, hundredths of a cell of
//! position noise tilt its normal by tens of degrees, so it makes "sharp" edges in the middle
//! of a face (on the evaluation shape `gmsh_object` at 129^3, three 42 degree edges on a flat
//! face: ECD x1e2 0.147, against marching cubes' 0.005).
//!
//! For two triangles `(u, v, a)` and `(v, u, b)` sharing the edge `u v`, where `(u, v, a)` is
//! the cap (its angle at `a` above 150 degrees; the same with the roles swapped), the flip to
//! `(b, v, a)`, `(a, u, b)` is made when:
//!
//! - the other triangle is no cap itself (no angle above 150 degrees: its normal `n` is
//!   well defined) and `a` lies within a tenth of a cell of its plane;
//! - the triangles across the cap's two other edges have normals within 30 degrees of `n`:
//!   the cap lies in a flat neighbourhood (a cap along a crease, whose apex is on the crease,
//!   is left to the crease flips, [`crate::flips`]);
//! - both new triangles face the way `n` does and their largest angle is smaller than the
//!   cap's, `a b` is not an edge yet and `u`, `v` keep at least three neighbours.
//!
//! The new triangles then lie on the other triangle's plane, with the normal it has, to a
//! tenth of a cell. Measured with the shipped model and the refinement (`docs/meshing.md`):
//! on the 105 evaluation meshes the group means of CD, NC and EF1 move by at most 0.006, and
//! `gmsh_object` at 129^3 goes from ECD 0.147 to 0.0002; on 32 other meshes, free-form EF1 at
//! 129^3 rises from 0.628 to 0.706.
//!
//! Guarantees (as the crease flips'): the surface stays closed, oriented and a 2-manifold,
//! and the exact self-intersection test runs on the flipped faces afterwards; if any of them
//! intersects another face, all flips are undone and the pass runs again without the
//! quadrilaterals involved ([`crate::flips::without_intersections`]). The pass is sequential
//! and deterministic. Any input other than a closed, oriented 2-manifold is left as it is.

use crate::TriMesh;
use crate::halfedge::HalfEdges;
use crate::vec3::{cross, dot, sub};

/// What [`flatten_caps`] did.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct CapStats {
    /// Flips kept.
    pub flips: usize,
    /// Passes over the edges in the last attempt.
    pub passes: usize,
    /// Attempts (1 unless flips had to be undone because of self-intersections).
    pub attempts: usize,
    /// Edges excluded after a self-intersection.
    pub excluded: usize,
}

/// The cosine of the angle above which a triangle is a cap (150 degrees).
const CAP_COS: f64 = -0.866_025_403_784_438_6;
/// The cap's apex must lie this close to the other triangle's plane, in cells.
const PLANE_TOLERANCE: f64 = 0.1;
/// The cosine of the largest angle between the other triangle's normal and those of the
/// triangles around the cap (30 degrees).
const FLAT_COS: f64 = 0.866_025_403_784_438_6;
/// Passes over all edges at most (each pass flips only what passes the tests).
const MAX_PASSES: usize = 8;

/// Flips the flat caps of the closed, oriented 2-manifold `mesh` away (see the
/// [module docs](self)); `cell` is the PoNQ's cell size in the mesh's units. Any other mesh,
/// or a `cell` that is not positive and finite, is left unchanged. The result is as valid as
/// the input (closed, oriented, manifold, free of self-intersections).
///
/// ```
/// use ponq_mesh::caps::flatten_caps;
/// use ponq_mesh::TriMesh;
/// // A box whose top face (z = 0.5) has a vertex 0.01 off its diagonal c0-c2: the triangle
/// // (c0, c2, m) is a flat cap with an angle of about 178 degrees at m.
/// let mut m = TriMesh {
///     vertices: vec![
///         [0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [1.0, 1.0, 0.0], [0.0, 1.0, 0.0],
///         [0.0, 0.0, 0.5], [1.0, 0.0, 0.5], [1.0, 1.0, 0.5], [0.0, 1.0, 0.5],
///         [0.5, 0.51, 0.5],
///     ],
///     faces: vec![
///         [0, 2, 1], [0, 3, 2], // bottom
///         [0, 1, 5], [0, 5, 4], [1, 2, 6], [1, 6, 5], // sides
///         [2, 3, 7], [2, 7, 6], [3, 0, 4], [3, 4, 7],
///         [4, 6, 8], [4, 5, 6], [6, 7, 8], [7, 4, 8], // top, the cap first
///     ],
/// };
/// assert_eq!(flatten_caps(&mut m, 0.1).flips, 1);
/// // The diagonal 4-6 is gone; the cap's apex 8 now joins corner 5.
/// assert!(m.faces.iter().any(|f| f.contains(&8) && f.contains(&5)));
/// assert!(ponq_mesh::validity::check(&m).is_valid());
/// ```
pub fn flatten_caps(mesh: &mut TriMesh, cell: f64) -> CapStats {
    if !(cell > 0.0 && cell.is_finite()) {
        return CapStats::default();
    }
    let tolerance = PLANE_TOLERANCE * cell;
    let mut passes = 0;
    let (flips, attempts, excluded) = crate::flips::without_intersections(mesh, |mesh, banned| {
        passes = 0;
        let Some(mut he) = HalfEdges::new(&mesh.faces, mesh.vertices.len()) else {
            return Vec::new();
        };
        let mut flipped = Vec::new();
        for _ in 0..MAX_PASSES {
            passes += 1;
            let before = flipped.len();
            let edges: Vec<(u32, u32)> = he
                .sorted_edges(&mesh.faces)
                .into_iter()
                .map(|h| {
                    (
                        HalfEdges::origin(&mesh.faces, h),
                        HalfEdges::target(&mesh.faces, h),
                    )
                })
                .collect();
            for (u, v) in edges {
                if !banned.is_empty() && banned.contains(&(u, v)) {
                    continue;
                }
                // The edge may be gone after an earlier flip of this pass.
                let Some(h) = he.find(&mesh.faces, u, v) else {
                    continue;
                };
                if flips_cap(mesh, &he, h, tolerance) {
                    let g = he.opposite(h);
                    he.flip(&mut mesh.faces, h);
                    flipped.push((h / 3, g / 3));
                }
            }
            if flipped.len() == before {
                break;
            }
        }
        flipped
    });
    CapStats {
        flips,
        passes,
        attempts,
        excluded,
    }
}

/// Whether the edge of `h = u -> v` is the long edge of a flat cap to flip (see the
/// [module docs](self)).
fn flips_cap(mesh: &TriMesh, he: &HalfEdges, h: u32, tolerance: f64) -> bool {
    let faces = &mesh.faces;
    let p = |w: u32| mesh.vertices[w as usize];
    let next = |x: u32| x - x % 3 + (x % 3 + 1) % 3;
    let g = he.opposite(h);
    let (u, v) = (HalfEdges::origin(faces, h), HalfEdges::target(faces, h));
    let a = HalfEdges::target(faces, next(h));
    let b = HalfEdges::target(faces, next(g));
    if a == b || he.degree(u) <= 3 || he.degree(v) <= 3 {
        return false;
    }
    let (f1, f2) = ([u, v, a], [v, u, b]);
    let (c1, c2) = (smallest_cos(mesh, f1), smallest_cos(mesh, f2));
    // The cap, its apex, its two other half-edges, and the other face.
    let (cap_cos, apex, sides, other) = match (c1 < CAP_COS, c2 < CAP_COS) {
        (true, false) => (c1, a, [next(h), HalfEdges::prev(h)], f2),
        (false, true) => (c2, b, [next(g), HalfEdges::prev(g)], f1),
        _ => return false,
    };
    let Some(n) = unit_normal(mesh, other) else {
        return false;
    };
    if dot(sub(p(apex), p(u)), n).abs() > tolerance {
        return false;
    }
    let flat = sides.iter().all(|&s| {
        let across = faces[(he.opposite(s) / 3) as usize];
        unit_normal(mesh, across).is_some_and(|m| dot(m, n) >= FLAT_COS)
    });
    if !flat {
        return false;
    }
    let new = [[b, v, a], [a, u, b]];
    let faces_n = new
        .iter()
        .all(|&f| unit_normal(mesh, f).is_some_and(|m| dot(m, n) > 0.0));
    faces_n
        && new.iter().all(|&f| smallest_cos(mesh, f) > cap_cos)
        && he.find(faces, a, b).is_none()
}

/// The cosine of the largest angle of triangle `f` (1 for a degenerate one with a zero-length
/// side, which then counts as no cap).
fn smallest_cos(mesh: &TriMesh, f: [u32; 3]) -> f64 {
    let p = f.map(|w| mesh.vertices[w as usize]);
    (0..3)
        .map(|i| {
            let (x, y) = (sub(p[(i + 1) % 3], p[i]), sub(p[(i + 2) % 3], p[i]));
            let l = (dot(x, x) * dot(y, y)).sqrt();
            if l > 0.0 { dot(x, y) / l } else { 1.0 }
        })
        .fold(1.0, f64::min)
}

/// The unit normal of triangle `f` (oriented by its vertex order), `None` if degenerate.
fn unit_normal(mesh: &TriMesh, f: [u32; 3]) -> Option<[f64; 3]> {
    let [a, b, c] = f.map(|w| mesh.vertices[w as usize]);
    let n = cross(sub(b, a), sub(c, a));
    let l = dot(n, n).sqrt();
    (l > 0.0 && l.is_finite()).then(|| n.map(|x| x / l))
}
