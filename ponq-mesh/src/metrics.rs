//! Reconstruction metrics with the paper's protocol (SPEC section 8).
//!
//! Both meshes are put at the ground truth's unit bounding-box diagonal (centred on its box),
//! then 100,000 area-weighted samples with face normals are drawn on each and matched to their
//! nearest neighbour in the other set:
//! CD = mean d^2 (gt -> pred) + mean d^2 (pred -> gt) (reported x1e5), F1 at 0.003,
//! NC = mean |n_a . n_b| both ways. Sharp edges (dihedral angle > 30 degrees) get 100,000
//! length-weighted samples on each mesh: ECD (squared, x1e2) and EF1 at 0.005. As in the
//! evaluation code of NDC / VoroMesh / PoNQ, a mesh without sharp edge stands for one edge
//! point at the origin, so a ground truth without sharp edges scores ECD 0 and EF1 1 against a
//! prediction without sharp edges.

use crate::nn::PointIndex;
use crate::sampling::{sample_edges, sample_surface, sharp_edges};
use crate::trimesh::TriMesh;
use crate::validity;

/// Settings of [`compare`].
#[derive(Debug, Clone)]
pub struct MetricOptions {
    /// Surface samples per mesh (100,000).
    pub surface_samples: usize,
    /// Sharp-edge samples per mesh (100,000).
    pub edge_samples: usize,
    /// F1 distance threshold at unit diagonal (0.003).
    pub f1_threshold: f64,
    /// Edge F1 distance threshold (0.005).
    pub ef1_threshold: f64,
    /// Dihedral angle above which an edge is sharp, degrees (30).
    pub sharp_angle_deg: f64,
    /// Seed of all sampling.
    pub seed: u64,
    /// Run the exact validity check (watertight, manifold, no self-intersection) on `pred`.
    pub check_validity: bool,
}

impl Default for MetricOptions {
    fn default() -> Self {
        Self {
            surface_samples: 100_000,
            edge_samples: 100_000,
            f1_threshold: 0.003,
            ef1_threshold: 0.005,
            sharp_angle_deg: 30.0,
            seed: 0,
            check_validity: true,
        }
    }
}

/// Metrics of a prediction against a ground truth, in the units the paper reports.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Metrics {
    /// Chamfer distance (squared, both directions summed) x 1e5.
    pub cd_x1e5: f64,
    /// F-score at the F1 threshold.
    pub f1: f64,
    /// Normal consistency.
    pub nc: f64,
    /// Edge Chamfer distance (squared) x 1e2.
    pub ecd_x1e2: f64,
    /// Edge F-score at the EF1 threshold.
    pub ef1: f64,
    /// Vertices of the prediction.
    pub n_vertices: usize,
    /// Faces of the prediction.
    pub n_faces: usize,
    /// Closed, oriented, manifold and free of self-intersections (`None` when not checked).
    pub watertight: Option<bool>,
}

/// The transform `x -> (x - centre) * scale` that puts `gt` at unit bounding-box diagonal.
/// `None` for a mesh without vertices or with a zero diagonal.
pub fn unit_diagonal_transform(gt: &TriMesh) -> Option<([f64; 3], f64)> {
    let (lo, hi) = gt.bounding_box()?;
    let d = ((hi[0] - lo[0]).powi(2) + (hi[1] - lo[1]).powi(2) + (hi[2] - lo[2]).powi(2)).sqrt();
    if !(d > 0.0) || !d.is_finite() {
        return None;
    }
    let c = [
        0.5 * (lo[0] + hi[0]),
        0.5 * (lo[1] + hi[1]),
        0.5 * (lo[2] + hi[2]),
    ];
    Some((c, 1.0 / d))
}

/// Applies `x -> (x - centre) * scale` to every vertex.
pub fn transformed(mesh: &TriMesh, centre: [f64; 3], scale: f64) -> TriMesh {
    TriMesh {
        vertices: mesh
            .vertices
            .iter()
            .map(|p| std::array::from_fn(|k| (p[k] - centre[k]) * scale))
            .collect(),
        faces: mesh.faces.clone(),
    }
}

/// Maps a prediction made in the `[-1,1]` frame of `gt` (bounding-box centre 0, diagonal 2)
/// back to the coordinates of `gt`.
pub fn grid_frame_to_gt(pred: &TriMesh, gt: &TriMesh) -> Option<TriMesh> {
    let (c, s) = unit_diagonal_transform(gt)?;
    // grid frame = 2 * unit-diagonal frame.
    Some(transformed(pred, [0.0; 3], 0.5 / s).translated(c))
}

impl TriMesh {
    /// The mesh moved by `t`.
    pub fn translated(mut self, t: [f64; 3]) -> TriMesh {
        for p in &mut self.vertices {
            for k in 0..3 {
                p[k] += t[k];
            }
        }
        self
    }
}

/// One-sided nearest distances (squared) from `from` to `to`, with the matched indices.
fn one_sided(from: &[[f64; 3]], to: &PointIndex) -> Vec<(u32, f64)> {
    to.nearest_many(from)
}

/// Nearest matches `a -> b` and `b -> a` (index, squared distance).
type Matches = (Vec<(u32, f64)>, Vec<(u32, f64)>);

/// `(cd, f1, matches)` of two point sets with a distance threshold (unsquared): `cd` is the
/// sum of both mean squared nearest distances (not scaled), `f1` the harmonic mean of the
/// fractions of each set within `tau` of the other. Empty sets give `(inf, 0)`.
pub fn chamfer_f1(a: &[[f64; 3]], b: &[[f64; 3]], tau: f64) -> (f64, f64, Matches) {
    let (Some(ia), Some(ib)) = (PointIndex::new(a), PointIndex::new(b)) else {
        return (f64::INFINITY, 0.0, (Vec::new(), Vec::new()));
    };
    let ab = one_sided(a, &ib);
    let ba = one_sided(b, &ia);
    let mean = |v: &[(u32, f64)]| v.iter().map(|x| x.1).sum::<f64>() / v.len() as f64;
    let cd = mean(&ab) + mean(&ba);
    let t2 = tau * tau;
    let frac = |v: &[(u32, f64)]| v.iter().filter(|x| x.1 < t2).count() as f64 / v.len() as f64;
    let (recall, precision) = (frac(&ab), frac(&ba));
    let f1 = if recall + precision > 0.0 {
        2.0 * recall * precision / (recall + precision)
    } else {
        0.0
    };
    (cd, f1, (ab, ba))
}

/// Compares `pred` with `gt`, both in the coordinates of `gt`.
pub fn compare(pred: &TriMesh, gt: &TriMesh, opts: &MetricOptions) -> Metrics {
    let watertight = opts
        .check_validity
        .then(|| validity::check(pred).is_valid());
    let mut m = Metrics {
        cd_x1e5: f64::INFINITY,
        f1: 0.0,
        nc: 0.0,
        ecd_x1e2: f64::INFINITY,
        ef1: 0.0,
        n_vertices: pred.vertices.len(),
        n_faces: pred.faces.len(),
        watertight,
    };
    let Some((c, s)) = unit_diagonal_transform(gt) else {
        return m;
    };
    let gt = transformed(gt, c, s);
    let pred = transformed(pred, c, s);
    let sg = sample_surface(&gt, opts.surface_samples, opts.seed);
    let sp = sample_surface(&pred, opts.surface_samples, opts.seed.wrapping_add(1));
    if sg.points.is_empty() || sp.points.is_empty() {
        return m;
    }
    let (cd, f1, (gp, pg)) = chamfer_f1(&sg.points, &sp.points, opts.f1_threshold);
    let dot = |a: &[f64; 3], b: &[f64; 3]| (a[0] * b[0] + a[1] * b[1] + a[2] * b[2]).abs();
    let nc_gp: f64 = gp
        .iter()
        .enumerate()
        .map(|(i, &(j, _))| dot(&sg.normals[i], &sp.normals[j as usize]))
        .sum::<f64>()
        / gp.len() as f64;
    let nc_pg: f64 = pg
        .iter()
        .enumerate()
        .map(|(i, &(j, _))| dot(&sp.normals[i], &sg.normals[j as usize]))
        .sum::<f64>()
        / pg.len() as f64;
    m.cd_x1e5 = cd * 1e5;
    m.f1 = f1;
    m.nc = 0.5 * (nc_gp + nc_pg);
    let edge_points = |mesh: &TriMesh, seed: u64| {
        let e = sharp_edges(mesh, opts.sharp_angle_deg);
        let pts = sample_edges(mesh, &e, opts.edge_samples, seed);
        if pts.is_empty() { vec![[0.0; 3]] } else { pts }
    };
    let eg = edge_points(&gt, opts.seed.wrapping_add(2));
    let ep = edge_points(&pred, opts.seed.wrapping_add(3));
    let (ecd, ef1, _) = chamfer_f1(&eg, &ep, opts.ef1_threshold);
    m.ecd_x1e2 = ecd * 1e2;
    m.ef1 = ef1;
    m
}
