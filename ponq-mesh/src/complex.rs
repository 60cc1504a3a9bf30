//! The tetrahedral complex the mesher works on: the Delaunay tetrahedralisation of the v*
//! plus the eight protective corners, with the PoNQ data (unit normal, the normal the tagging
//! uses, normalised quadric) attached to each vertex, and the inside / outside labels of the
//! tets.

use crate::delaunay::{Delaunay, NONE};
use crate::predicates::orient3d;
use crate::quadric::Quadric;

/// Label of a tetrahedron.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Label {
    /// Not decided yet (decided by the minimum cut).
    Unknown,
    /// Inside the shape.
    Inside,
    /// Outside the shape.
    Outside,
}

/// The outward faces of a positively oriented tet: `FACES[k]` is the face opposite vertex `k`,
/// ordered so that its right-hand normal points out of the tet.
pub const FACES: [[usize; 3]; 4] = [[1, 2, 3], [0, 3, 2], [0, 1, 3], [0, 2, 1]];

/// Delaunay tets with per-vertex PoNQ data.
///
/// Invariants: `normals`, `tag_normals`, `quadrics`, `protective` and `vertex_tet` have one
/// entry per Delaunay vertex; normals are unit length or zero; each tag normal is its normal
/// times a finite factor >= 0; quadrics are normalised (largest
/// eigenvalue of `A` is 1, or `A = 0`); `vertex_tet[v]` is a tet containing `v` ([`NONE`] when
/// no tet does).
#[derive(Debug, Clone)]
pub struct TetComplex {
    /// The triangulation.
    pub dt: Delaunay,
    /// Unit normal per vertex (zero when unknown).
    pub normals: Vec<[f64; 3]>,
    /// Each vertex's unit normal scaled to the length of its raw normal (the PoNQ's normal,
    /// not normalised: a mean of unit normals, short where they disagree; for merged points,
    /// the mean of their raw normals' length): the tagging's tests use it, so that the
    /// barycentre test weighs each vertex's plane by that length, as the authors' mesher does
    /// ([`crate::tagging::tag_tet`]). One array for both tests keeps the tagging's memory
    /// traffic what it was with unit normals.
    pub tag_normals: Vec<[f64; 3]>,
    /// Normalised quadric per vertex.
    pub quadrics: Vec<Quadric>,
    /// True for the protective corner points.
    pub protective: Vec<bool>,
    /// One tet containing each vertex (the start of [`TetComplex::incident`]).
    pub vertex_tet: Vec<u32>,
    /// Edge length of a grid cell in the frame of the points.
    pub cell_size: f64,
    /// `h` of the face score (`grid_scale^2` for the `[-1,1]` box).
    pub h: f64,
}

/// Barycentre of the four points, summed in their order (one function, so that the tagging's
/// lanes compute [`TetComplex::barycenter`]'s bits).
#[inline(always)]
pub fn barycenter_of(p: [[f64; 3]; 4]) -> [f64; 3] {
    let mut b = [0.0; 3];
    for q in p {
        for k in 0..3 {
            b[k] += 0.25 * q[k];
        }
    }
    b
}

impl TetComplex {
    /// Stores the per-vertex data and one tet per vertex. Full incidence lists are not built:
    /// the mesher needs the star of a few hundred vertices at most (the small-tet rule, the
    /// manifold repair), which [`TetComplex::incident`] finds from `vertex_tet` (building the
    /// lists took 15-20 ms at 100k points).
    pub fn new(
        dt: Delaunay,
        normals: Vec<[f64; 3]>,
        tag_normals: Vec<[f64; 3]>,
        quadrics: Vec<Quadric>,
        protective: Vec<bool>,
        cell_size: f64,
        h: f64,
    ) -> Self {
        let vertex_tet = dt.vertex_to_tet();
        Self {
            dt,
            normals,
            tag_normals,
            quadrics,
            protective,
            vertex_tet,
            cell_size,
            h,
        }
    }

    /// Number of tets.
    pub fn n_tets(&self) -> usize {
        self.dt.tets.len()
    }

    /// The tets incident to vertex `v`, ascending: the star of `v`, found by crossing the
    /// faces that contain `v` from [`TetComplex::vertex_tet`] (the star of a vertex of a
    /// triangulation is connected through them).
    pub fn incident(&self, v: u32) -> Vec<u32> {
        let start = self.vertex_tet.get(v as usize).copied().unwrap_or(NONE);
        if start == NONE {
            return Vec::new();
        }
        let mut star = vec![start];
        let mut seen = std::collections::HashSet::from([start]);
        let mut i = 0;
        while i < star.len() {
            let t = star[i];
            i += 1;
            let tv = self.dt.tets[t as usize];
            for k in 0..4 {
                // The face opposite vertex k contains v unless v is vertex k.
                let nb = self.dt.neighbors[t as usize][k];
                if tv[k] != v && nb != NONE && seen.insert(nb) {
                    star.push(nb);
                }
            }
        }
        star.sort_unstable();
        star
    }

    /// Position of vertex `v`.
    #[inline]
    pub fn pos(&self, v: u32) -> &[f64; 3] {
        &self.dt.vertices[v as usize]
    }

    /// True when tet `t` has a protective vertex.
    pub fn touches_protective(&self, t: u32) -> bool {
        self.dt.tets[t as usize]
            .iter()
            .any(|&v| self.protective[v as usize])
    }

    /// The three vertices of face `k` of tet `t`, ordered with the normal pointing out of `t`.
    #[inline]
    pub fn outward_face(&self, t: u32, k: usize) -> [u32; 3] {
        let tv = self.dt.tets[t as usize];
        FACES[k].map(|i| tv[i])
    }

    /// Barycentre of tet `t`.
    pub fn barycenter(&self, t: u32) -> [f64; 3] {
        barycenter_of(self.dt.tets[t as usize].map(|v| *self.pos(v)))
    }

    /// Volume of tet `t` (positive).
    pub fn volume(&self, t: u32) -> f64 {
        let [a, b, c, d] = self.dt.tets[t as usize].map(|v| *self.pos(v));
        let u = [b[0] - a[0], b[1] - a[1], b[2] - a[2]];
        let v = [c[0] - a[0], c[1] - a[1], c[2] - a[2]];
        let w = [d[0] - a[0], d[1] - a[1], d[2] - a[2]];
        (u[0] * (v[1] * w[2] - v[2] * w[1]) - u[1] * (v[0] * w[2] - v[2] * w[0])
            + u[2] * (v[0] * w[1] - v[1] * w[0]))
            .abs()
            / 6.0
    }

    /// Size of tet `t`: the mean squared distance of its vertices to its barycentre.
    pub fn size(&self, t: u32) -> f64 {
        let b = self.barycenter(t);
        self.dt.tets[t as usize]
            .iter()
            .map(|&v| {
                let p = self.pos(v);
                (p[0] - b[0]).powi(2) + (p[1] - b[1]).powi(2) + (p[2] - b[2]).powi(2)
            })
            .sum::<f64>()
            / 4.0
    }

    /// Neighbour of `t` across face `k` ([`NONE`] on the hull, which counts as outside).
    #[inline]
    pub fn neighbor(&self, t: u32, k: usize) -> u32 {
        self.dt.neighbors[t as usize][k]
    }

    /// Debug helper: true when every tet is positively oriented.
    pub fn all_positive(&self) -> bool {
        self.dt.tets.iter().all(|tv| {
            orient3d(
                self.pos(tv[0]),
                self.pos(tv[1]),
                self.pos(tv[2]),
                self.pos(tv[3]),
            ) > 0
        })
    }
}

/// True when `nb` counts as outside under `labels` (hull faces border the outside).
#[inline]
pub fn is_outside(labels: &[Label], nb: u32) -> bool {
    nb == NONE || labels[nb as usize] == Label::Outside
}

#[cfg(test)]
mod tests {
    use super::*;

    /// `incident` finds exactly the tets containing each vertex, ascending, for interior and
    /// hull vertices, on random points and on a co-spherical lattice.
    #[test]
    fn incident_is_the_star_of_each_vertex() {
        use rand::{Rng, SeedableRng};
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(7);
        let random: Vec<[f64; 3]> = (0..400)
            .map(|_| std::array::from_fn(|_| rng.random_range(0.0..1.0)))
            .collect();
        let lattice: Vec<[f64; 3]> = (0..125)
            .map(|i| [(i % 5) as f64, (i / 5 % 5) as f64, (i / 25) as f64])
            .collect();
        for pts in [random, lattice] {
            let dt = Delaunay::new(&pts).expect("finite points");
            let nv = dt.vertices.len();
            let cx = TetComplex::new(
                dt,
                vec![[0.0; 3]; nv],
                vec![[0.0; 3]; nv],
                vec![Quadric::zero(); nv],
                vec![false; nv],
                0.1,
                1.0,
            );
            let mut brute = vec![Vec::new(); nv];
            for (t, tv) in cx.dt.tets.iter().enumerate() {
                for &v in tv {
                    brute[v as usize].push(t as u32);
                }
            }
            for (v, expected) in brute.iter().enumerate() {
                assert!(!expected.is_empty());
                assert_eq!(&cx.incident(v as u32), expected, "star of vertex {v}");
            }
        }
    }
}
