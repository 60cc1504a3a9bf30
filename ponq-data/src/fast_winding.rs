//! The fast winding number of a triangle soup (Barill et al. 2018, "Fast Winding Numbers for
//! Soups and Clouds"): the generalised winding number `w(q)` (Jacobson et al. 2013) of the
//! faces as they are, with no weld, orientation or closedness asked of them.
//!
//! `w(q) = sum_t Omega_t(q) / (4 pi)`, `Omega_t` the signed solid angle of triangle `t` seen
//! from `q`. Each triangle is a dipole layer: `Omega_t(q) / (4 pi) = int_t n . grad G(y - q)
//! dA(y)` with `grad G(x) = x / (4 pi |x|^3)`. A tree over the triangles stores, per node, the
//! moments of its layer about its centre `c`: `M0 = sum a n`, `M1 = sum a n (x - c)^T` and
//! `M2 = sum a n (x - c) (x - c)^T` (the exact integrals over each triangle). Far from a node
//! (`|q - c| > beta r`, `r` the node's radius about `c`) its sum is the order-2 Taylor
//! expansion of `grad G` about `c`; near it, the children's, and at a leaf the exact solid
//! angles. Order 2 with `beta = 2`, Barill et al.'s choice: the expansion's error is a small
//! fraction of the node's own contribution, far below the `1/2` threshold the sign takes,
//! while every query near the surface (where `w` jumps) is summed exactly.
//!
//! Written here because no maintained Rust crate computes winding numbers of soups (libigl's is
//! C++); the exact solid angle is [`solid_angle`], the one the exact hierarchy of
//! [`crate::sdf::MeshSdf`] uses for closed meshes too.
//!
//! ```
//! use ponq_data::fast_winding::FastWinding;
//! // A unit cube as a soup: 12 triangles, 36 corners, no vertex shared.
//! let c = |i: usize| [(i & 1) as f64, ((i >> 1) & 1) as f64, ((i >> 2) & 1) as f64];
//! let quads = [[0, 2, 3, 1], [4, 5, 7, 6], [0, 1, 5, 4], [2, 6, 7, 3], [0, 4, 6, 2], [1, 3, 7, 5]];
//! let tris: Vec<[[f64; 3]; 3]> = quads
//!     .iter()
//!     .flat_map(|q| [[c(q[0]), c(q[1]), c(q[2])], [c(q[0]), c(q[2]), c(q[3])]])
//!     .collect();
//! let w = FastWinding::new(&tris);
//! assert!((w.winding_number([0.5, 0.5, 0.5]).abs() - 1.0).abs() < 1e-9);
//! assert!(w.winding_number([2.0, 0.5, 0.5]).abs() < 1e-3);
//! ```

use std::f64::consts::PI;

use ponq_mesh::vec3::{add, cross, dot, norm, scale, sub};
use rayon::prelude::*;

/// Signed solid angle of triangle `(a, b, c)` seen from `p` (Van Oosterom and Strackee),
/// positive when `p` is on the side the normal `(b-a) x (c-a)` points away from, in
/// `[-2 pi, 2 pi]`.
pub fn solid_angle(p: [f64; 3], a: [f64; 3], b: [f64; 3], c: [f64; 3]) -> f64 {
    let a = sub(a, p);
    let b = sub(b, p);
    let c = sub(c, p);
    let (la, lb, lc) = (norm(a), norm(b), norm(c));
    let det = dot(a, cross(b, c));
    let den = la * lb * lc + dot(a, b) * lc + dot(b, c) * la + dot(c, a) * lb;
    2.0 * det.atan2(den)
}

/// Triangles per leaf.
const LEAF: usize = 8;

/// Barill et al.'s accuracy parameter: a node's expansion is used when the query is farther
/// than `BETA` times its radius from its centre.
pub const BETA: f64 = 2.0;

/// One node of the tree: its triangles `start..end` (leaf order), children, and its layer's
/// moments about `centre`.
#[derive(Debug, Clone)]
struct Node {
    start: u32,
    end: u32,
    /// Children (`u32::MAX` at a leaf).
    left: u32,
    right: u32,
    centre: [f64; 3],
    /// The largest distance from `centre` to a corner of the node's triangles.
    radius: f64,
    /// `sum a n`.
    m0: [f64; 3],
    /// `sum int n_i (x - c)_j dA`, row `i`.
    m1: [[f64; 3]; 3],
    /// `sum int n_i (x - c)_j (x - c)_k dA`, `[i][j][k]` (symmetric in `j, k`).
    m2: [[[f64; 3]; 3]; 3],
}

/// The fast winding number of a set of triangles (see the [module docs](self)).
///
/// Invariants: every triangle is in exactly one leaf; a node's moments are the sums of its
/// triangles' exact moments about its centre, and its radius bounds their corners.
#[derive(Debug, Clone)]
pub struct FastWinding {
    /// Triangles in leaf order, `[a, b, c]` corners.
    tris: Vec<[[f64; 3]; 3]>,
    nodes: Vec<Node>,
    beta: f64,
}

/// Area times unit normal (`(b - a) x (c - a) / 2`).
fn area_normal(t: &[[f64; 3]; 3]) -> [f64; 3] {
    scale(cross(sub(t[1], t[0]), sub(t[2], t[0])), 0.5)
}

impl FastWinding {
    /// The tree over `tris` (triangles as corner triples, `(F, 3, 3)`), with [`BETA`].
    pub fn new(tris: &[[[f64; 3]; 3]]) -> Self {
        Self::with_beta(tris, BETA)
    }

    /// The tree over `tris` with accuracy `beta` (> 1; larger is more exact and slower).
    pub fn with_beta(tris: &[[[f64; 3]; 3]], beta: f64) -> Self {
        let mut tris: Vec<[[f64; 3]; 3]> = tris.to_vec();
        let mut nodes = Vec::with_capacity(2 * tris.len() / LEAF + 1);
        if !tris.is_empty() {
            let n = tris.len();
            build(&mut tris, 0, n, &mut nodes);
        }
        Self {
            tris,
            nodes,
            beta: beta.max(1.0 + 1e-9),
        }
    }

    /// The tree over the faces of a mesh as they are (`vertices (V, 3)`, `faces (F, 3)`
    /// indices into them; faces naming a vertex out of range are skipped).
    pub fn of_mesh(vertices: &[[f64; 3]], faces: &[[u32; 3]]) -> Self {
        let tris: Vec<[[f64; 3]; 3]> = faces
            .iter()
            .filter(|f| f.iter().all(|&v| (v as usize) < vertices.len()))
            .map(|f| f.map(|v| vertices[v as usize]))
            .collect();
        Self::new(&tris)
    }

    /// The number of triangles.
    pub fn len(&self) -> usize {
        self.tris.len()
    }

    /// No triangle.
    pub fn is_empty(&self) -> bool {
        self.tris.is_empty()
    }

    /// The winding number at `q` (`1` inside and `0` outside a closed outward surface; near
    /// those values for a soup of one with gaps; undefined on a triangle).
    pub fn winding_number(&self, q: [f64; 3]) -> f64 {
        if self.nodes.is_empty() {
            return 0.0;
        }
        let mut sum = 0.0;
        // A fixed stack: median splits keep the depth at log2(F / LEAF) (25 for 2^28 faces),
        // and the stack holds at most one pending child per level.
        let mut stack = [0u32; 128];
        let mut sp = 1;
        while sp > 0 {
            sp -= 1;
            let n = stack[sp];
            let node = &self.nodes[n as usize];
            let x = sub(node.centre, q);
            let d = norm(x);
            if d > self.beta * node.radius {
                sum += far_field(node, x, d);
            } else if node.left == u32::MAX {
                for t in &self.tris[node.start as usize..node.end as usize] {
                    sum += solid_angle(q, t[0], t[1], t[2]) / (4.0 * PI);
                }
            } else {
                stack[sp] = node.right;
                stack[sp + 1] = node.left;
                sp += 2;
            }
        }
        sum
    }

    /// [`FastWinding::winding_number`] at many points (`(N, 3)`), in parallel.
    pub fn winding_numbers(&self, qs: &[[f64; 3]]) -> Vec<f64> {
        qs.par_iter().map(|&q| self.winding_number(q)).collect()
    }
}

/// The order-2 expansion of a node's layer at `q`, `x = centre - q`, `d = |x|`.
fn far_field(node: &Node, x: [f64; 3], d: f64) -> f64 {
    let d2 = d * d;
    let d3 = d2 * d;
    let d5 = d3 * d2;
    let d7 = d5 * d2;
    // Order 0: grad G(x) . M0.
    let mut w = dot(x, node.m0) / d3;
    // Order 1: sum_ij H_ij M1_ij, H_ij = (delta_ij d^2 - 3 x_i x_j) / d^5.
    let mut h = 0.0;
    for i in 0..3 {
        for j in 0..3 {
            let delta = if i == j { d2 } else { 0.0 };
            h += (delta - 3.0 * x[i] * x[j]) * node.m1[i][j];
        }
    }
    w += h / d5;
    // Order 2: 1/2 sum_ijk T_ijk M2_ijk,
    // T_ijk = (15 x_i x_j x_k - 3 d^2 (delta_ij x_k + delta_ik x_j + delta_jk x_i)) / d^7.
    let mut t = 0.0;
    for i in 0..3 {
        for j in 0..3 {
            for k in 0..3 {
                let mut term = 15.0 * x[i] * x[j] * x[k];
                if i == j {
                    term -= 3.0 * d2 * x[k];
                }
                if i == k {
                    term -= 3.0 * d2 * x[j];
                }
                if j == k {
                    term -= 3.0 * d2 * x[i];
                }
                t += term * node.m2[i][j][k];
            }
        }
    }
    w += 0.5 * t / d7;
    w / (4.0 * PI)
}

/// Builds the subtree of `tris[start..end]` (reordered), appending its nodes; returns its index.
fn build(tris: &mut [[[f64; 3]; 3]], start: usize, end: usize, nodes: &mut Vec<Node>) -> u32 {
    let slice = &tris[start..end];
    // The centre: the area-weighted centroid (the centroids' mean when every area is zero).
    let mut area = 0.0;
    let mut acc = [0.0; 3];
    let mut mean = [0.0; 3];
    for t in slice {
        let a = norm(area_normal(t));
        let c = scale(add(add(t[0], t[1]), t[2]), 1.0 / 3.0);
        area += a;
        acc = add(acc, scale(c, a));
        mean = add(mean, c);
    }
    let centre = if area > 0.0 {
        scale(acc, 1.0 / area)
    } else {
        scale(mean, 1.0 / slice.len() as f64)
    };
    let mut radius: f64 = 0.0;
    let (mut m0, mut m1, mut m2) = ([0.0; 3], [[0.0; 3]; 3], [[[0.0; 3]; 3]; 3]);
    for t in slice {
        let an = area_normal(t);
        let p = t.map(|v| sub(v, centre));
        for v in &p {
            radius = radius.max(norm(*v));
        }
        // The triangle's exact moments about the centre (per unit area):
        // int d dA / a = (p0 + p1 + p2) / 3, int d d^T dA / a = (sum p p^T + s s^T) / 12.
        let s = add(add(p[0], p[1]), p[2]);
        for i in 0..3 {
            m0[i] += an[i];
            for j in 0..3 {
                m1[i][j] += an[i] * s[j] / 3.0;
                for k in 0..3 {
                    let second =
                        (p[0][j] * p[0][k] + p[1][j] * p[1][k] + p[2][j] * p[2][k] + s[j] * s[k])
                            / 12.0;
                    m2[i][j][k] += an[i] * second;
                }
            }
        }
    }
    let index = nodes.len() as u32;
    nodes.push(Node {
        start: start as u32,
        end: end as u32,
        left: u32::MAX,
        right: u32::MAX,
        centre,
        radius,
        m0,
        m1,
        m2,
    });
    if end - start > LEAF {
        // Split at the median centroid along the widest axis of the centroids' box.
        let (mut lo, mut hi) = ([f64::INFINITY; 3], [f64::NEG_INFINITY; 3]);
        for t in &tris[start..end] {
            for k in 0..3 {
                let c = t[0][k] + t[1][k] + t[2][k];
                lo[k] = lo[k].min(c);
                hi[k] = hi[k].max(c);
            }
        }
        let axis = (0..3)
            .max_by(|&a, &b| (hi[a] - lo[a]).total_cmp(&(hi[b] - lo[b])))
            .unwrap_or(0);
        let mid = (start + end) / 2;
        let key = |t: &[[f64; 3]; 3]| t[0][axis] + t[1][axis] + t[2][axis];
        tris[start..end].select_nth_unstable_by(mid - start, |a, b| key(a).total_cmp(&key(b)));
        let left = build(tris, start, mid, nodes);
        let right = build(tris, mid, end, nodes);
        nodes[index as usize].left = left;
        nodes[index as usize].right = right;
    }
    index
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{Rng, SeedableRng};

    /// A sphere of `n x 2n` quads (as triangles), radius 1, centre 0, outward.
    fn sphere(n: usize) -> Vec<[[f64; 3]; 3]> {
        let p = |i: usize, j: usize| {
            let th = PI * i as f64 / n as f64;
            let ph = 2.0 * PI * j as f64 / (2 * n) as f64;
            [th.sin() * ph.cos(), th.sin() * ph.sin(), th.cos()]
        };
        let mut out = Vec::new();
        for i in 0..n {
            for j in 0..2 * n {
                let (a, b, c, d) = (p(i, j), p(i + 1, j), p(i + 1, j + 1), p(i, j + 1));
                out.push([a, b, c]);
                out.push([a, c, d]);
            }
        }
        out
    }

    /// Against the exact sum of solid angles at random points near and far: within 1e-2
    /// with beta 2 (order 2), to rounding when every node is summed exactly.
    #[test]
    fn matches_the_exact_sum() {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(3);
        let mut tris = sphere(24);
        // A second, smaller sphere with jittered corners: a soup with gaps.
        for t in sphere(12) {
            tris.push(t.map(|v| {
                [
                    0.3 * v[0] + 1.5 + rng.random_range(-1e-3..1e-3),
                    0.3 * v[1] + rng.random_range(-1e-3..1e-3),
                    0.3 * v[2],
                ]
            }));
        }
        let fast = FastWinding::new(&tris);
        let exact = |q: [f64; 3]| {
            tris.iter()
                .map(|t| solid_angle(q, t[0], t[1], t[2]))
                .sum::<f64>()
                / (4.0 * PI)
        };
        let qs: Vec<[f64; 3]> = (0..500)
            .map(|_| {
                [
                    rng.random_range(-3.0..3.0),
                    rng.random_range(-3.0..3.0),
                    rng.random_range(-3.0..3.0),
                ]
            })
            .collect();
        let worst = |f: &FastWinding| {
            qs.iter()
                .map(|&q| (f.winding_number(q) - exact(q)).abs())
                .fold(0.0, f64::max)
        };
        // Far below the threshold of 1/2; and an order-2 expansion: its error falls by more
        // than 2^3 when beta doubles.
        let (w2, w4) = (worst(&fast), worst(&FastWinding::with_beta(&tris, 4.0)));
        assert!(w2 < 1e-2, "worst error {w2}");
        assert!(w4 < w2 / 8.0, "beta 2: {w2}, beta 4: {w4}");
        let all_exact = FastWinding::with_beta(&tris, 1e9);
        let q = [0.2, -0.1, 0.3];
        assert!((all_exact.winding_number(q) - exact(q)).abs() < 1e-9);
        // Inside the big sphere, inside the small one, outside both.
        let w = fast.winding_numbers(&[[0.0; 3], [1.5, 0.0, 0.0], [0.0, 2.5, 0.0]]);
        assert!((w[0].abs() - 1.0).abs() < 1e-2, "{w:?}");
        assert!((w[1].abs() - 1.0).abs() < 2e-2, "{w:?}");
        assert!(w[2].abs() < 1e-2, "{w:?}");
    }

    #[test]
    fn empty_and_degenerate() {
        assert_eq!(FastWinding::new(&[]).winding_number([0.0; 3]), 0.0);
        let flat = [[[0.0; 3], [1.0, 0.0, 0.0], [2.0, 0.0, 0.0]]; 20];
        let w = FastWinding::new(&flat);
        assert_eq!(w.len(), 20);
        assert!(w.winding_number([0.5, 1.0, 0.0]).abs() < 1e-12);
    }
}
