//! The tetrahedral complex the mesher works on: the Delaunay tetrahedralisation of the v*
//! plus the eight protective corners, with the PoNQ data (unit normal, normalised quadric)
//! attached to each vertex, and the inside / outside labels of the tets.

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
/// Invariants: `normals`, `quadrics`, `protective` have one entry per Delaunay vertex;
/// normals are unit length or zero; quadrics are normalised (largest eigenvalue of `A` is 1,
/// or `A = 0`); `incident` lists, for every vertex, the tets that contain it.
#[derive(Debug, Clone)]
pub struct TetComplex {
    /// The triangulation.
    pub dt: Delaunay,
    /// Unit normal per vertex (zero when unknown).
    pub normals: Vec<[f64; 3]>,
    /// Normalised quadric per vertex.
    pub quadrics: Vec<Quadric>,
    /// True for the protective corner points.
    pub protective: Vec<bool>,
    /// CSR offsets into `incident_tets`, one range per vertex.
    pub incident_offsets: Vec<u32>,
    /// Tets incident to each vertex.
    pub incident_tets: Vec<u32>,
    /// Edge length of a grid cell in the frame of the points.
    pub cell_size: f64,
    /// `h` of the face score (`grid_scale^2` for the `[-1,1]` box).
    pub h: f64,
}

impl TetComplex {
    /// Builds the incidence lists of `dt` and stores the per-vertex data.
    pub fn new(
        dt: Delaunay,
        normals: Vec<[f64; 3]>,
        quadrics: Vec<Quadric>,
        protective: Vec<bool>,
        cell_size: f64,
        h: f64,
    ) -> Self {
        use rayon::prelude::*;
        // Counting sort of (vertex, tet) by vertex, one vertex range per thread: each thread
        // reads all tets but writes only its own part, so lists stay sorted by tet.
        let nv = dt.vertices.len();
        let parts = rayon::current_num_threads().clamp(1, 16);
        let bounds: Vec<usize> = (0..=parts).map(|i| nv * i / parts).collect();
        let tets = &dt.tets;
        let counts: Vec<Vec<u32>> = (0..parts)
            .into_par_iter()
            .map(|c| {
                let (lo, hi) = (bounds[c], bounds[c + 1]);
                let mut cnt = vec![0u32; hi - lo];
                for t in tets {
                    for &v in t {
                        let v = v as usize;
                        if v >= lo && v < hi {
                            cnt[v - lo] += 1;
                        }
                    }
                }
                cnt
            })
            .collect();
        let mut offsets = Vec::with_capacity(nv + 1);
        offsets.push(0u32);
        for &c in counts.iter().flatten() {
            offsets.push(offsets[offsets.len() - 1] + c);
        }
        let mut incident = vec![0u32; offsets[nv] as usize];
        let mut slices = Vec::with_capacity(parts);
        let mut rest = &mut incident[..];
        for c in 0..parts {
            let len = (offsets[bounds[c + 1]] - offsets[bounds[c]]) as usize;
            let (a, b) = rest.split_at_mut(len);
            slices.push(a);
            rest = b;
        }
        slices.into_par_iter().enumerate().for_each(|(c, slice)| {
            let (lo, hi) = (bounds[c], bounds[c + 1]);
            let base = offsets[lo];
            let mut fill: Vec<u32> = offsets[lo..hi].iter().map(|o| o - base).collect();
            for (ti, t) in tets.iter().enumerate() {
                for &v in t {
                    let v = v as usize;
                    if v >= lo && v < hi {
                        slice[fill[v - lo] as usize] = ti as u32;
                        fill[v - lo] += 1;
                    }
                }
            }
        });
        let counts = offsets;
        Self {
            dt,
            normals,
            quadrics,
            protective,
            incident_offsets: counts,
            incident_tets: incident,
            cell_size,
            h,
        }
    }

    /// Number of tets.
    pub fn n_tets(&self) -> usize {
        self.dt.tets.len()
    }

    /// The tets incident to vertex `v`.
    pub fn incident(&self, v: u32) -> &[u32] {
        let a = self.incident_offsets[v as usize] as usize;
        let b = self.incident_offsets[v as usize + 1] as usize;
        &self.incident_tets[a..b]
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
        let tv = self.dt.tets[t as usize];
        let mut b = [0.0; 3];
        for &v in &tv {
            let p = self.pos(v);
            for k in 0..3 {
                b[k] += 0.25 * p[k];
            }
        }
        b
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
