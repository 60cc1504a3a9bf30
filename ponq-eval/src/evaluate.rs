//! Evaluation of one shape at one resolution with the paper's protocol (SPEC section 8): the
//! shape is reconstructed from its SDF grid by PoNQ (and PoNQ-lite) and by marching cubes on
//! the same grid and compared with the ground truth at unit bounding-box diagonal.

use std::path::Path;
use std::time::Instant;

use anyhow::{Context, Result};
use burn::prelude::*;
use ponq_infer::{InferOptions, RefineMode, finish, infer, predict};
use ponq_mesh::metrics::{MetricOptions, compare};
use ponq_mesh::tagging::SmallTetRule;
use ponq_mesh::{TriMesh, validity};
use ponq_model::PonqNet;

use crate::inputs::{Truth, grid_of, truth};
use crate::render::{Image, render};
use crate::report::Row;

/// A reconstruction method.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord)]
pub enum Method {
    /// PoNQ (all points), the network alone.
    Ponq,
    /// PoNQ refined against the grid's exact distances (`ponq_infer::RefineMode::Auto`).
    Refined,
    /// PoNQ-lite (one point per cell, `coarsen` more levels).
    Lite,
    /// Marching cubes on the same grid.
    Mc,
}

impl Method {
    /// Name in tables.
    pub fn name(&self) -> &'static str {
        match self {
            Method::Ponq => "PoNQ",
            Method::Refined => "PoNQ+refine",
            Method::Lite => "PoNQ-lite",
            Method::Mc => "MC",
        }
    }
}

/// Options of an evaluation.
#[derive(Debug, Clone)]
pub struct EvalOptions {
    /// Grid resolutions (cells per side).
    pub resolutions: Vec<usize>,
    /// Methods.
    pub methods: Vec<Method>,
    /// Hierarchy level of PoNQ-lite.
    pub coarsen: u32,
    /// Adaptive PoNQ-lite angle of the PoNQ rows (`ponq_infer::InferOptions::merge_smooth`).
    pub merge_smooth: Option<f64>,
    /// Which labels the mesher's small-tet rule adds (`ponq_mesh::tagging::SmallTetRule`).
    pub small_tet_rule: SmallTetRule,
    /// Surface / edge samples per mesh for the metrics.
    pub samples: usize,
    /// Shapes (the first ones) rendered side by side.
    pub renders: usize,
    /// Network tile size (0: `ponq_infer::reconstruct::auto_tile`).
    pub tile: usize,
    /// Name of the PoNQ rows (`PoNQ` by default; the lite rows are `<name>-lite`), so that
    /// several models can share one report.
    pub name: String,
}

/// Metrics of `pred` against the truth (both in the `[-1,1]` frame).
fn metrics(pred: &TriMesh, t: &Truth, samples: usize) -> (f64, f64, f64, f64, f64, bool) {
    let watertight = !pred.faces.is_empty() && validity::check(pred).is_valid();
    let opts = MetricOptions {
        surface_samples: samples,
        edge_samples: samples,
        check_validity: false,
        ..Default::default()
    };
    if let Some(gt) = &t.mesh {
        let m = compare(pred, gt, &opts);
        return (m.cd_x1e5, m.f1, m.nc, m.ecd_x1e2, m.ef1, watertight);
    }
    // Samples only: CD / F1 / NC at unit diagonal (the [-1,1] frame has diagonal 2).
    let s = ponq_mesh::sampling::sample_surface(pred, samples, 1);
    if s.points.is_empty() || t.samples.is_empty() {
        return (f64::INFINITY, 0.0, 0.0, f64::NAN, f64::NAN, watertight);
    }
    let stride = (t.samples.len() / samples).max(1);
    let gt: Vec<[f64; 3]> = t.samples.iter().step_by(stride).copied().collect();
    let gtn: Vec<[f64; 3]> = t.normals.iter().step_by(stride).copied().collect();
    let half = |v: &[[f64; 3]]| v.iter().map(|p| p.map(|x| 0.5 * x)).collect::<Vec<_>>();
    let (cd, f1, (ab, ba)) =
        ponq_mesh::metrics::chamfer_f1(&half(&gt), &half(&s.points), opts.f1_threshold);
    let dot = |a: [f64; 3], b: [f64; 3]| (a[0] * b[0] + a[1] * b[1] + a[2] * b[2]).abs();
    let nc1 = ab
        .iter()
        .enumerate()
        .map(|(i, &(j, _))| dot(gtn[i], s.normals[j as usize]))
        .sum::<f64>()
        / ab.len() as f64;
    let nc2 = ba
        .iter()
        .enumerate()
        .map(|(i, &(j, _))| dot(s.normals[i], gtn[j as usize]))
        .sum::<f64>()
        / ba.len() as f64;
    (
        cd * 1e5,
        f1,
        0.5 * (nc1 + nc2),
        f64::NAN,
        f64::NAN,
        watertight,
    )
}

/// Evaluates one shape at one resolution; returns its rows and, when `render` is set, the
/// side-by-side image (ground truth or nothing, marching cubes, PoNQ).
// The arguments are independent inputs of one evaluation (shape, grid, network, options).
#[allow(clippy::too_many_arguments)]
pub fn evaluate(
    id: &str,
    path: &Path,
    res: usize,
    net: &PonqNet,
    encoder_layers: usize,
    opts: &EvalOptions,
    device: &Device,
    render_it: bool,
) -> Result<(Vec<Row>, Option<Image>)> {
    let t = truth(path).with_context(|| format!("reading {}", path.display()))?;
    let grid = grid_of(&t, res)?;
    let mut rows = Vec::new();
    let mut meshes = Vec::new();
    // The network's PoNQ, shared by the PoNQ and refined rows (and its time).
    let mut predicted: Option<(Option<ponq_infer::Predicted>, f64)> = None;
    for &m in &opts.methods {
        let start = Instant::now();
        let mut network_secs = 0.0;
        let mesh = match m {
            Method::Mc => ponq_mesh::marching_cubes::marching_cubes(
                &grid.data, grid.dims, [-1.0; 3], [1.0; 3],
            )?,
            Method::Ponq | Method::Refined => {
                let io = InferOptions {
                    tile: opts.tile,
                    merge_smooth: opts.merge_smooth,
                    small_tet_rule: opts.small_tet_rule,
                    refine: if m == Method::Refined {
                        RefineMode::Auto
                    } else {
                        RefineMode::Off
                    },
                    ..Default::default()
                };
                let mut ran_network = false;
                if predicted.is_none() {
                    ran_network = true;
                    let t = Instant::now();
                    let p = match predict(net, encoder_layers, &grid, &io, device, |_, _| {}) {
                        Ok(p) => Some(p),
                        Err(e) if e.to_string().contains("no sign change") => None,
                        Err(e) => return Err(e),
                    };
                    predicted = Some((p, t.elapsed().as_secs_f64()));
                }
                let (p, secs) = predicted
                    .as_ref()
                    .map_or((None, 0.0), |(p, s)| (p.as_ref(), *s));
                if !ran_network {
                    network_secs = secs;
                }
                match p {
                    Some(p) => finish(p, &io)?.mesh,
                    None => TriMesh::default(),
                }
            }
            Method::Lite => {
                let io = InferOptions {
                    tile: opts.tile,
                    lite: true,
                    coarsen: opts.coarsen,
                    merge_smooth: opts.merge_smooth,
                    small_tet_rule: opts.small_tet_rule,
                    refine: RefineMode::Off,
                    ..Default::default()
                };
                match infer(net, encoder_layers, &grid, &io, device, |_, _| {}) {
                    Ok(r) => r.mesh,
                    Err(e) if e.to_string().contains("no sign change") => TriMesh::default(),
                    Err(e) => return Err(e),
                }
            }
        };
        // The network's time counts in both PoNQ rows (it ran once, inside the first).
        let seconds = start.elapsed().as_secs_f64() + network_secs;
        let (cd, f1, nc, ecd, ef1, watertight) = metrics(&mesh, &t, opts.samples);
        rows.push(Row {
            shape: id.to_string(),
            method: match m {
                Method::Ponq => opts.name.clone(),
                Method::Refined => format!("{}+refine", opts.name),
                Method::Lite => format!("{}-lite", opts.name),
                Method::Mc => m.name().to_string(),
            },
            res,
            cd,
            f1,
            nc,
            ecd,
            ef1,
            watertight,
            vertices: mesh.vertices.len(),
            faces: mesh.faces.len(),
            seconds,
        });
        meshes.push((m, mesh));
    }
    let image = render_it.then(|| {
        let view = ([0.0; 3], 1.0 / 3f64.sqrt());
        let mut ims = Vec::new();
        if let Some(gt) = &t.mesh {
            ims.push(render(gt, view, 256, [0.75, 0.75, 0.75]));
        }
        for (m, mesh) in &meshes {
            let c = match m {
                Method::Mc => [0.95, 0.6, 0.4],
                Method::Ponq => [0.45, 0.65, 0.95],
                Method::Refined => [0.35, 0.55, 0.9],
                Method::Lite => [0.5, 0.85, 0.55],
            };
            ims.push(render(mesh, view, 256, c));
        }
        Image::hstack(&ims)
    });
    Ok((rows, image))
}
