//! Vertex fans that are graphs over an axis plane: an exact certificate that the faces around a
//! vertex meet each other only at that vertex and along their shared edges.
//!
//! The faces of a closed mesh around a vertex `v` are its *fan*. [`graph_fans`] certifies `v`
//! when, for one of the three axis projections `P` (dropping x, y or z; tried in decreasing
//! order of the fan's summed normal's components):
//! * the corners of `v`, faces `(v, r, r')`, form a single cycle `r_0 -> r_1 -> ... -> r_0`
//!   of `n >= 3` distinct vertices (every face holding `v` is one of them: each occurrence of
//!   `v` in a face is a corner);
//! * every projected face `(P v, P r, P r')` has the same orientation `s != 0` (exact
//!   `orient2d`): the faces are non-degenerate, and each projects one-to-one into the sector of
//!   the plane between the rays from `P v` through `P r` and `P r'`, a sector of less than a
//!   half-turn;
//! * the sectors go around `P v` exactly once: the winding number of the projected edges
//!   `P r -> P r'` around `P v` is `s` (Sunday's count of their crossings with the ray from
//!   `P v` towards +x: exact coordinate comparisons, and the side of `P v` of a crossing edge
//!   is its sector's orientation, so no further predicate).
//!
//! Seen from `P v`, each edge `P r -> P r'` sweeps its sector's angle (in `(0, pi)`, signed by
//! `s`), so a winding number of `s` means that the cycle makes one turn: the rays through the
//! `P r_i` follow each other in strictly increasing angle over exactly one turn. Two sectors
//! that are not consecutive then meet only at `P v`, and two consecutive ones only along their
//! common ray, with their far corners strictly on opposite sides of it. Hence, for two faces of
//! a certified fan (a projection one-to-one on each face maps any common point to a common
//! point of the projections):
//! * sharing only `v`, they meet only at `v`;
//! * sharing an edge `v r_i`, they are not folded onto each other (coplanar with their third
//!   corners on the same side of the edge: the projection is one-to-one on their common plane
//!   and keeps the sides).
//!
//! These are exactly the pairs that [`crate::validity`] would otherwise decide one by one with
//! exact orientation tests (on a 217k-face mesh 1.3 million of its 1.43 million candidate
//! pairs); the certificate costs one 2D orientation test per corner. A vertex that
//! is not certified (a fold, a fan winding twice, a degree above [`MAX_DEGREE`], a
//! non-manifold vertex, a degenerate face, a non-finite coordinate, a fan over no axis plane)
//! only leaves its pairs to the exact pair test.

use rayon::prelude::*;

use crate::corners::{corner_rows, one_cycle};
use crate::predicates::{o2, proj};
use crate::vec3::{cross, sub};

/// Vertices of higher degree are not certified (their pairs are tested one by one): the
/// certificate's cost stays linear in the corners.
pub const MAX_DEGREE: usize = 64;

/// `certified[v]` for every vertex of the mesh `(vertices, faces)`: whether the fan of `v` is a
/// graph over an axis plane as the [module docs](self) define it. All `false` when a face
/// refers to a vertex out of range.
///
/// ```
/// use ponq_mesh::fan::graph_fans;
/// // An octahedron: the four faces around each vertex project one-to-one onto the plane
/// // across that vertex's axis.
/// let (x, y, z) = ([1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]);
/// let neg = |p: [f64; 3]| p.map(|c| -c);
/// let v = [x, neg(x), y, neg(y), z, neg(z)];
/// let f = [
///     [0, 2, 4], [1, 4, 2], [0, 4, 3], [1, 3, 4],
///     [0, 5, 2], [1, 2, 5], [0, 3, 5], [1, 5, 3],
/// ];
/// assert_eq!(graph_fans(&v, &f), vec![true; 6]);
/// // The corner of a tetrahedron with three right angles is a graph over no axis plane
/// // (each projection collapses one of its edges): its pairs are left to the exact tests.
/// let v = [[0.0, 0.0, 0.0], x, y, z];
/// let f = [[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]];
/// assert!(!graph_fans(&v, &f)[0]);
/// ```
pub fn graph_fans(vertices: &[[f64; 3]], faces: &[[u32; 3]]) -> Vec<bool> {
    vertex_fans(vertices, faces, true).certified
}

/// What one pass over the corners of every vertex finds (see [`vertex_fans`]).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct VertexFans {
    /// Whether each vertex's fan is certified ([`graph_fans`]); all `false` when not asked
    /// for.
    pub certified: Vec<bool>,
    /// Whether the corners of every vertex that has any form a single cycle of at least 3:
    /// faces `(v, r_0, r_1)`, `(v, r_1, r_2)`, ..., `(v, r_{n-1}, r_0)` with distinct `r_i`.
    /// Then no face repeats an index (a face `(v, v, x)` gives `v` the corners `(v, x)` and
    /// `(x, v)`, which lead to each other: a cycle of two, or, with another corner ending at
    /// `x`, a corner reached from two), every edge `v r` is
    /// in exactly two faces, one going `v -> r` and one `r -> v` (the corners starting and
    /// ending at `r`), and the faces around each vertex are one fan: the mesh is a closed,
    /// oriented 2-manifold. `false` when a face refers to a vertex out of range.
    pub single_cycles: bool,
}

/// The fans of every vertex of the mesh `(vertices, faces)`, in one parallel pass over the
/// corners grouped by vertex: whether each forms a single cycle and, if `certify`, whether
/// it is certified ([module docs](self)).
pub fn vertex_fans(vertices: &[[f64; 3]], faces: &[[u32; 3]], certify: bool) -> VertexFans {
    let nv = vertices.len();
    if faces.iter().flatten().any(|&v| v as usize >= nv) {
        return VertexFans {
            certified: vec![false; nv],
            single_cycles: false,
        };
    }
    // The corners of each vertex `v` as (next, previous) vertex of its face, grouped by `v`.
    let (start, corners) = corner_rows(faces, nv, |_, f, k| (f[(k + 1) % 3], f[(k + 2) % 3]));
    let per_vertex: Vec<(bool, bool)> = (0..nv)
        .into_par_iter()
        .with_min_len(1024)
        .map(|v| {
            let c = &corners[start[v] as usize..start[v + 1] as usize];
            let cycle = c.len() >= 3 && one_cycle(c);
            (
                c.is_empty() || cycle,
                certify && cycle && certify_cycle(vertices, v, c),
            )
        })
        .collect();
    VertexFans {
        single_cycles: per_vertex.iter().all(|x| x.0),
        certified: per_vertex.into_iter().map(|x| x.1).collect(),
    }
}

/// Whether the fan of `v`, given by its corners `(r, r')` (face `(v, r, r')`) forming a single
/// cycle ([`one_cycle`]), is certified.
fn certify_cycle(vertices: &[[f64; 3]], v: usize, corners: &[(u32, u32)]) -> bool {
    if corners.len() > MAX_DEGREE {
        return false;
    }
    let p = vertices[v];
    let mut finite = p.iter().all(|x| x.is_finite());
    let mut normal = [0.0f64; 3];
    for &(a, b) in corners {
        let (qa, qb) = (vertices[a as usize], vertices[b as usize]);
        finite &= qa.iter().chain(&qb).all(|x| x.is_finite());
        let c = cross(sub(qa, p), sub(qb, p));
        for k in 0..3 {
            normal[k] += c[k];
        }
    }
    if !finite {
        return false;
    }
    // The projection: the axis along which the fan's summed normal is largest first (any
    // axis would do for correctness; this one is the likeliest to pass), the others if it
    // fails (a fan edge along that axis, say).
    let mut axes = [0u8, 1, 2];
    axes.sort_by(|&i, &j| {
        normal[j as usize]
            .abs()
            .total_cmp(&normal[i as usize].abs())
    });
    axes.iter()
        .any(|&axis| graph_over(vertices, p, corners, axis))
}

/// Whether the fan of the point `p` with the corners `corners` (one cycle, see
/// [`one_cycle`]) projects one-to-one onto the plane dropping coordinate `axis`: sectors of one
/// orientation, and one turn in all.
fn graph_over(vertices: &[[f64; 3]], p: [f64; 3], corners: &[(u32, u32)], axis: u8) -> bool {
    let o = proj(&p, axis);
    // Every sector turns the same way `s`, by less than a half-turn; and the winding number
    // of the corners' edges around `o` is `s`. Each edge sweeps (seen from `o`) the angle of
    // its sector, so the winding number is the number of turns, signed by `s`. It is counted
    // as crossings of the ray from `o` in the +x direction (Sunday's rule, exact: coordinate
    // comparisons, and the side of `o` of a crossing edge is its sector's orientation,
    // `orient2d(r, r', o) = orient2d(o, r, r')`).
    let mut s = 0;
    let mut winding = 0i32;
    for &(a, b) in corners {
        let (ra, rb) = (
            proj(&vertices[a as usize], axis),
            proj(&vertices[b as usize], axis),
        );
        let t = o2(o, ra, rb);
        if t == 0 || (s != 0 && t != s) {
            return false;
        }
        s = t;
        if ra.y <= o.y {
            winding += (rb.y > o.y && t > 0) as i32;
        } else {
            winding -= (rb.y <= o.y && t < 0) as i32;
        }
    }
    winding == i32::from(s)
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;

    /// A ring whose fan turns twice, every sector the same way by less than a half-turn, the
    /// second turn exactly through the ray of `r_0` (`r_3` lies on it).
    pub(crate) const SECOND_TURN_THROUGH_A_RAY: [[f64; 3]; 6] = [
        [1.0, 0.0, 0.0],
        [-1.0, 1.0, 0.0],
        [-1.0, -1.0, 0.0],
        [2.0, 0.0, 0.0],
        [-2.0, 2.0, 0.0],
        [-2.0, -2.0, 0.0],
    ];

    /// A fan around the origin through `ring` (closed by `apex` below, so every ring vertex
    /// has a closed fan too).
    pub(crate) fn fan(ring: &[[f64; 3]]) -> (Vec<[f64; 3]>, Vec<[u32; 3]>) {
        let n = ring.len() as u32;
        let mut v = vec![[0.0, 0.0, 0.0]];
        v.extend_from_slice(ring);
        v.push([0.0, 0.0, -1.0]);
        let apex = n + 1;
        let mut f = Vec::new();
        for i in 0..n {
            let (a, b) = (1 + i, 1 + (i + 1) % n);
            f.push([0, a, b]);
            f.push([apex, b, a]);
        }
        (v, f)
    }

    pub(crate) fn circle(n: usize, turns: usize, z: impl Fn(usize) -> f64) -> Vec<[f64; 3]> {
        (0..n)
            .map(|i| {
                let t = std::f64::consts::TAU * (turns * i) as f64 / n as f64;
                [t.cos(), t.sin(), z(i)]
            })
            .collect()
    }

    /// [`fan`] of `n` faces, and a second fan of `n` faces at the centre (its ring raised):
    /// a vertex with two fans.
    fn two_fans(n: u32) -> (Vec<[f64; 3]>, Vec<[u32; 3]>) {
        let (mut v, mut f) = fan(&circle(n as usize, 1, |_| 0.0));
        let base = v.len() as u32;
        let ring = circle(n as usize, 1, |_| 0.0);
        v.extend(ring.iter().map(|p| [p[0], p[1], p[2] + 2.0]));
        for i in 0..n {
            f.push([0, base + i, base + (i + 1) % n]);
        }
        (v, f)
    }

    #[test]
    fn a_vertex_of_high_degree_is_one_cycle_but_not_certified() {
        let (v, f) = fan(&circle(200, 1, |_| 0.0));
        let fans = vertex_fans(&v, &f, true);
        assert!(fans.single_cycles);
        assert!(!fans.certified[0]);
        // Two such fans at one vertex: not one cycle.
        let (v, f) = two_fans(100);
        assert!(!vertex_fans(&v, &f, false).single_cycles);
    }

    #[test]
    fn a_flat_or_wavy_fan_is_certified() {
        for z in [|_| 0.0, |i: usize| 0.3 * (i % 2) as f64] {
            let (v, f) = fan(&circle(7, 1, z));
            assert!(graph_fans(&v, &f)[0]);
        }
    }

    #[test]
    fn a_fan_winding_twice_is_not() {
        // Seven faces going round twice: each sector is less than a half-turn and all turn
        // the same way, but the projections overlap.
        let (v, f) = fan(&circle(7, 2, |i| 0.1 * i as f64));
        assert!(!graph_fans(&v, &f)[0]);
        // Its faces do cross each other (`validity`'s tests: certifying it would hide these
        // pairs).
    }

    #[test]
    fn a_fold_a_repeated_face_or_a_second_fan_is_not() {
        // A ring vertex pulled across: one sector turns the other way.
        let mut ring = circle(6, 1, |_| 0.0);
        ring[2] = [-0.2, -0.9, 0.0];
        let (v, f) = fan(&ring);
        assert!(!graph_fans(&v, &f)[0]);
        // A face repeated.
        let (v, mut f) = fan(&circle(6, 1, |_| 0.0));
        f.push(f[0]);
        assert!(!graph_fans(&v, &f)[0]);
        // Two fans glued at the centre.
        let (v, f) = two_fans(5);
        assert!(!graph_fans(&v, &f)[0]);
    }

    #[test]
    fn a_second_turn_through_a_ray_is_caught() {
        // Every sector turns the same way by less than a half-turn, and the second turn
        // passes exactly through the ray of r_0 (r_3 lies on it): the crossing count must
        // handle a vertex on the counted ray.
        let (v, f) = fan(&SECOND_TURN_THROUGH_A_RAY);
        assert!(!graph_fans(&v, &f)[0]);
        // Its faces do cross each other (`validity`'s tests).
    }

    #[test]
    fn out_of_range_or_non_finite_input_certifies_nothing() {
        let (v, mut f) = fan(&circle(6, 1, |_| 0.0));
        f.push([0, 1, 99]);
        assert!(graph_fans(&v, &f).iter().all(|&c| !c));
        let (mut v, f) = fan(&circle(6, 1, |_| 0.0));
        v[2][0] = f64::NAN;
        let c = graph_fans(&v, &f);
        assert!(!c[0] && !c[2]);
    }
}
