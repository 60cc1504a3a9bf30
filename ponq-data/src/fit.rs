//! Optimisation-based PoNQ (SPEC section 7, the paper's "Optimization-based 3D
//! Reconstruction"): fit points to a sampled mesh by minimising the squared Chamfer distance
//! with Adam, then build per point the mean normal and the mean quadric of the samples of its
//! Voronoi cell, and mesh the result.
//!
//! Gradients are analytic: for `L = mean_p |p - s(p)|^2 + mean_s |p(s) - s|^2` (nearest
//! neighbours by k-d tree, held fixed within a step), `dL/dp = 2 (p - s(p)) / |P|
//! + sum_{s: p(s) = p} 2 (p - s) / |S|`.

use std::time::{Duration, Instant};

use ponq_mesh::lite::{cell_of, coarsen};
use ponq_mesh::mesher::{MeshingOptions, MeshingOutput, mesh_ponq};
use ponq_mesh::nn::PointIndex;
use ponq_mesh::open_surface::DEFAULT_OPEN_THRESHOLD;
use ponq_mesh::{Ponq, TriMesh};
use rand::SeedableRng;
use rand::seq::index::sample;
use rand_chacha::ChaCha8Rng;

use crate::error::{DataError, Result};
use crate::normalize::Normalization;
use crate::sampling::{SurfaceSamples, sample_boundary, sample_surface};

/// Options of [`fit_mesh`].
#[derive(Debug, Clone)]
pub struct FitOptions {
    /// Grid resolution (32, 64, 128): initial points and meshing scale.
    pub grid: usize,
    /// Surface samples; default `100,000 * (grid / 32)^2`.
    pub samples: Option<usize>,
    /// Adam iterations (400).
    pub iterations: usize,
    /// Fraction of the samples used per iteration (0.1).
    pub batch_fraction: f64,
    /// Learning rate; default `1e-3 * 32 / grid`.
    pub lr: Option<f64>,
    /// Open surface: add boundary samples and cull with this anisotropy threshold.
    pub open: Option<f64>,
    /// PoNQ-lite: one point per grid cell after fitting.
    pub lite: bool,
    /// Seed of the sampling and batches.
    pub seed: u64,
    /// Repair the mesh first ([`crate::repair`]: a clean mesh is used unchanged; with
    /// `open`, nothing is closed or removed).
    pub repair: bool,
}

impl Default for FitOptions {
    fn default() -> Self {
        Self {
            grid: 32,
            samples: None,
            iterations: 400,
            batch_fraction: 0.1,
            lr: None,
            open: None,
            lite: false,
            seed: 0,
            repair: true,
        }
    }
}

impl FitOptions {
    /// The open-surface option with the default threshold.
    pub fn open_default() -> Option<f64> {
        Some(DEFAULT_OPEN_THRESHOLD)
    }
}

/// Result of [`fit_mesh`]: everything in the `[-1,1]` frame of the input.
#[derive(Debug, Clone)]
pub struct Fitted {
    /// The normalisation that maps the input into the `[-1,1]` frame.
    pub normalization: Normalization,
    /// The fitted PoNQ.
    pub ponq: Ponq,
    /// The meshing result (mesh in the `[-1,1]` frame).
    pub meshing: MeshingOutput,
    /// Final squared Chamfer loss on the last batch.
    pub final_loss: f64,
    /// Time spent sampling, fitting (Adam), building the PoNQ, meshing.
    pub times: [Duration; 4],
    /// What the repair found and did (with [`FitOptions::repair`]).
    pub report: Option<crate::repair::DefectReport>,
}

/// Corners of the `grid^3` cells of `[-1,1]^3` that hold at least one sample (unique).
pub fn initial_points(samples: &[[f64; 3]], grid: usize) -> Vec<[f64; 3]> {
    let n = grid as u64 + 1;
    let mut keys: Vec<u64> = Vec::with_capacity(samples.len());
    for p in samples {
        let c = cell_of(*p, grid, ([-1.0; 3], [1.0; 3]));
        for corner in 0..8u32 {
            let i = c[0] as u64 + u64::from(corner & 1);
            let j = c[1] as u64 + u64::from((corner >> 1) & 1);
            let k = c[2] as u64 + u64::from((corner >> 2) & 1);
            keys.push((i * n + j) * n + k);
        }
    }
    keys.sort_unstable();
    keys.dedup();
    let h = 2.0 / grid as f64;
    keys.iter()
        .map(|&key| {
            let (ij, k) = (key / n, key % n);
            let (i, j) = (ij / n, ij % n);
            [
                -1.0 + h * i as f64,
                -1.0 + h * j as f64,
                -1.0 + h * k as f64,
            ]
        })
        .collect()
}

/// Minimises the squared Chamfer distance between `points` and `samples` with Adam;
/// `progress(i)` is called after each iteration. Returns the loss of the last batch.
pub fn optimise_points(
    points: &mut [[f64; 3]],
    samples: &[[f64; 3]],
    iterations: usize,
    batch_fraction: f64,
    lr: f64,
    seed: u64,
    mut progress: impl FnMut(usize),
) -> f64 {
    use rayon::prelude::*;
    let np = points.len();
    if np == 0 || samples.is_empty() {
        return 0.0;
    }
    let batch = ((samples.len() as f64 * batch_fraction).round() as usize).clamp(1, samples.len());
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let (b1, b2, eps) = (0.9f64, 0.999f64, 1e-8f64);
    let mut m = vec![[0.0f64; 3]; np];
    let mut v = vec![[0.0f64; 3]; np];
    let mut last = 0.0;
    let mut bs: Vec<[f64; 3]> = Vec::with_capacity(batch);
    for it in 0..iterations {
        bs.clear();
        bs.extend(
            sample(&mut rng, samples.len(), batch)
                .iter()
                .map(|i| samples[i]),
        );
        let (Some(si), Some(pi)) = (PointIndex::new(&bs), PointIndex::new(points)) else {
            break;
        };
        let p2s = si.nearest_many(points);
        let s2p = pi.nearest_many(&bs);
        let mut grad: Vec<[f64; 3]> = points
            .par_iter()
            .zip(&p2s)
            .map(|(p, &(j, _))| {
                let s = bs[j as usize];
                std::array::from_fn(|k| 2.0 * (p[k] - s[k]) / np as f64)
            })
            .collect();
        for (s, &(j, _)) in bs.iter().zip(&s2p) {
            let p = points[j as usize];
            for k in 0..3 {
                grad[j as usize][k] += 2.0 * (p[k] - s[k]) / batch as f64;
            }
        }
        last = p2s.iter().map(|x| x.1).sum::<f64>() / np as f64
            + s2p.iter().map(|x| x.1).sum::<f64>() / batch as f64;
        let t = (it + 1) as i32;
        let (c1, c2) = (1.0 - b1.powi(t), 1.0 - b2.powi(t));
        for i in 0..np {
            for k in 0..3 {
                let g = grad[i][k];
                m[i][k] = b1 * m[i][k] + (1.0 - b1) * g;
                v[i][k] = b2 * v[i][k] + (1.0 - b2) * g * g;
                points[i][k] -= lr * (m[i][k] / c1) / ((v[i][k] / c2).sqrt() + eps);
            }
        }
        progress(it + 1);
    }
    last
}

/// PoNQ of `points` from the samples of their Voronoi cells: mean normal, mean plane quadric,
/// mean sample position as the point; points without sample are dropped.
pub fn ponq_from_voronoi(points: &[[f64; 3]], s: &SurfaceSamples) -> Result<Ponq> {
    let idx = PointIndex::new(points)
        .ok_or_else(|| DataError::Invalid("no point to build the PoNQ from".into()))?;
    let nearest: Vec<u32> = idx
        .nearest_many(&s.points)
        .into_iter()
        .map(|x| x.0)
        .collect();
    let (mut ponq, ids) = Ponq::from_clusters(&s.points, &s.normals, &nearest, points.len())?;
    // Keep the fitted positions as the points (v* is solved around them).
    ponq.points = ids.iter().map(|&i| points[i as usize]).collect();
    Ok(ponq)
}

/// The whole optimisation-based PoNQ of a mesh; `progress(iteration)` reports the fit.
///
/// # Errors
/// A mesh without faces or area, a grid below 2, or a meshing error.
pub fn fit_mesh(mesh: &TriMesh, opts: &FitOptions, progress: impl FnMut(usize)) -> Result<Fitted> {
    if opts.grid < 2 || opts.grid > 1024 {
        return Err(DataError::Invalid(format!(
            "grid must be between 2 and 1024, got {}",
            opts.grid
        )));
    }
    if mesh.faces.is_empty() {
        return Err(DataError::Invalid("the mesh has no face".into()));
    }
    if !(opts.batch_fraction > 0.0 && opts.batch_fraction <= 1.0) {
        return Err(DataError::Invalid(format!(
            "batch fraction must be in (0, 1], got {}",
            opts.batch_fraction
        )));
    }
    let t0 = Instant::now();
    let (repaired, report) = if opts.repair {
        let ro = if opts.open.is_some() {
            crate::repair::RepairOptions::open_surface()
        } else {
            crate::repair::RepairOptions::default()
        };
        let (m, r) = crate::repair::repair(mesh, &ro)?;
        (Some(m), Some(r))
    } else {
        (None, None)
    };
    let mesh = repaired.as_ref().unwrap_or(mesh);
    let norm = Normalization::of(mesh)?;
    let m = norm.apply_mesh(mesh);
    let scale = opts.grid as f64 / 32.0;
    let n = opts
        .samples
        .unwrap_or((100_000.0 * scale * scale).round() as usize)
        .max(1);
    let mut s = sample_surface(&m, n, opts.seed);
    if s.points.is_empty() {
        return Err(DataError::Invalid("the mesh has no area to sample".into()));
    }
    if opts.open.is_some() {
        // As many boundary samples per boundary cell as surface samples in a cell (density
        // n / area times the cell size per unit length): the rotated copies then make the
        // quadrics of boundary points clearly anisotropic (lambda2 / lambda1 near 1/2 or more).
        let area: f64 = (0..m.faces.len())
            .map(|f| {
                let c = ponq_mesh::sampling::face_cross(&m, f);
                0.5 * (c[0] * c[0] + c[1] * c[1] + c[2] * c[2]).sqrt()
            })
            .sum();
        let length: f64 = crate::sampling::boundary_edges(&m)
            .iter()
            .map(|&(a, b, _)| {
                let (p, q) = (m.vertices[a as usize], m.vertices[b as usize]);
                ((p[0] - q[0]).powi(2) + (p[1] - q[1]).powi(2) + (p[2] - q[2]).powi(2)).sqrt()
            })
            .sum();
        let cell = 2.0 / opts.grid as f64;
        let nb = (n as f64 / area.max(1e-12) * cell * length).round() as usize;
        let b = sample_boundary(&m, nb, opts.seed.wrapping_add(17));
        s.points.extend(b.points);
        s.normals.extend(b.normals);
        s.faces.extend(b.faces);
    }
    let t_sample = t0.elapsed();

    let t1 = Instant::now();
    let mut points = initial_points(&s.points, opts.grid);
    let lr = opts.lr.unwrap_or(1e-3 * 32.0 / opts.grid as f64);
    let final_loss = optimise_points(
        &mut points,
        &s.points,
        opts.iterations,
        opts.batch_fraction,
        lr,
        opts.seed.wrapping_add(1),
        progress,
    );
    let t_fit = t1.elapsed();

    let t2 = Instant::now();
    let mut ponq = ponq_from_voronoi(&points, &s)?;
    let mut grid_scale = opts.grid as f64;
    if opts.lite {
        let cells: Vec<[u32; 3]> = ponq
            .points
            .iter()
            .map(|&p| cell_of(p, opts.grid, ([-1.0; 3], [1.0; 3])))
            .collect();
        ponq = coarsen(&ponq, &cells, 0)?;
        grid_scale = opts.grid as f64;
    }
    let t_ponq = t2.elapsed();

    let t3 = Instant::now();
    let meshing = mesh_ponq(
        &ponq,
        &MeshingOptions {
            grid_scale,
            open_threshold: opts.open,
            ..Default::default()
        },
    )?;
    let t_mesh = t3.elapsed();
    Ok(Fitted {
        normalization: norm,
        ponq,
        meshing,
        final_loss,
        times: [t_sample, t_fit, t_ponq, t_mesh],
        report,
    })
}
