//! Broken copies side by side with the clean input (`ponq-eval broken`): each mesh of a folder
//! goes through `ponq-infer MESH`'s path (repair, exact SDF, the network, meshing and
//! refinement) as it is and as broken copies of every defect class
//! ([`ponq_data::broken`]), and each output is compared with the clean mesh (for overlaps,
//! with the union of the two copies).

use std::path::Path;
use std::time::Instant;

use anyhow::{Context, Result};
use burn::prelude::*;
use ponq_data::broken::{Defect, break_mesh, union_surface};
use ponq_data::normalize::Normalization;
use ponq_infer::mesh_input::{MeshInput, mesh_band};
use ponq_infer::{InferOptions, finish, predict_band};
use ponq_mesh::metrics::{MetricOptions, compare};
use ponq_mesh::{TriMesh, io, validity};
use ponq_model::PonqNet;

/// One reconstruction of one copy.
#[derive(Debug, Clone, PartialEq)]
pub struct CopyRow {
    /// Shape id (file stem) and group (first folder below the data folder).
    pub shape: String,
    pub group: String,
    /// `clean` or a defect class name.
    pub copy: String,
    /// The output is closed, oriented, manifold and free of self-intersections.
    pub valid: bool,
    /// Metrics against the clean mesh (the union for overlaps), at unit diagonal; ECD / EF1
    /// are NaN for overlaps (the union's surface is a set of pieces without sharp edges).
    pub cd_x1e5: f64,
    pub f1: f64,
    pub nc: f64,
    pub ef1: f64,
    /// Whole path: repair, SDF, network, meshing, refinement.
    pub seconds: f64,
    /// The repair changed the mesh.
    pub repaired: bool,
    /// Error text when the copy could not be reconstructed (empty otherwise).
    pub error: String,
}

impl CopyRow {
    /// The CSV header of [`CopyRow::csv`].
    pub const HEADER: &'static str =
        "shape,group,copy,valid,cd_x1e5,f1,nc,ef1,seconds,repaired,error";

    /// One CSV line (the error text with commas and quotes replaced).
    pub fn csv(&self) -> String {
        format!(
            "{},{},{},{},{},{},{},{},{:.3},{},{}",
            self.shape,
            self.group,
            self.copy,
            self.valid,
            self.cd_x1e5,
            self.f1,
            self.nc,
            self.ef1,
            self.seconds,
            self.repaired,
            self.error.replace([',', '"', '\n'], " ")
        )
    }

    /// The row of a copy that could not be evaluated at all, with its error.
    pub fn failed(shape: &str, group: &str, copy: &str, error: String) -> Self {
        Self {
            shape: shape.to_string(),
            group: group.to_string(),
            copy: copy.to_string(),
            valid: false,
            cd_x1e5: f64::INFINITY,
            f1: 0.0,
            nc: 0.0,
            ef1: 0.0,
            seconds: 0.0,
            repaired: false,
            error,
        }
    }

    /// Parses [`CopyRow::csv`].
    pub fn parse(line: &str) -> Option<Self> {
        let f: Vec<&str> = line.splitn(11, ',').collect();
        if f.len() != 11 {
            return None;
        }
        Some(Self {
            shape: f[0].to_string(),
            group: f[1].to_string(),
            copy: f[2].to_string(),
            valid: f[3].parse().ok()?,
            cd_x1e5: f[4].parse().ok()?,
            f1: f[5].parse().ok()?,
            nc: f[6].parse().ok()?,
            ef1: f[7].parse().ok()?,
            seconds: f[8].parse().ok()?,
            repaired: f[9].parse().ok()?,
            error: f[10].to_string(),
        })
    }
}

/// Reconstructs `input` (in its own coordinates) as `ponq-infer MESH --res RES` does and
/// returns the output in the coordinates of the input, and whether the repair changed it.
fn reconstruct(
    input: &TriMesh,
    res: usize,
    net: &PonqNet,
    encoder_layers: usize,
    device: &Device,
) -> Result<(TriMesh, bool)> {
    let opts = InferOptions::default();
    let g = mesh_band(
        input,
        res,
        MeshInput::default(),
        encoder_layers,
        &opts,
        |_, _| {},
    )?;
    let p = predict_band(net, encoder_layers, g.grid, &opts, device, |_, _| {})?;
    let r = finish(&p, &opts)?;
    Ok((
        g.normalization.invert_mesh(&r.mesh),
        g.report.is_some_and(|r| r.repaired),
    ))
}

/// Every copy of one shape: the clean mesh and one broken copy per class of `defects`, each
/// reconstructed at `res` cells per side and compared with the clean mesh. A copy that fails
/// is a row with its error; only a shape that cannot be read at all is an `Err` (the caller
/// writes its rows, [`CopyRow::failed`]).
#[allow(clippy::too_many_arguments)]
pub fn evaluate_copies(
    shape: &str,
    group: &str,
    path: &Path,
    res: usize,
    defects: &[Defect],
    seed: u64,
    samples: usize,
    net: &PonqNet,
    encoder_layers: usize,
    device: &Device,
    done: &dyn Fn(&str) -> bool,
    mut emit: impl FnMut(CopyRow) -> Result<()>,
) -> Result<()> {
    let clean = io::read_mesh(path).with_context(|| format!("reading {}", path.display()))?;
    let norm = Normalization::of(&clean).context("normalising the clean mesh")?;
    let truth = norm.apply_mesh(&clean);
    let (lo, hi) = clean.bounding_box().context("the mesh has no vertex")?;
    let diag = (0..3).map(|k| (hi[k] - lo[k]).powi(2)).sum::<f64>().sqrt();
    let cell = diag / res as f64;
    let opts = MetricOptions {
        surface_samples: samples,
        edge_samples: samples,
        check_validity: false,
        ..Default::default()
    };
    let mut copies: Vec<Option<Defect>> = vec![None];
    copies.extend(defects.iter().copied().map(Some));
    for d in copies {
        let name = d.map_or("clean", Defect::name);
        if done(name) {
            continue;
        }
        let mut row = CopyRow {
            shape: shape.to_string(),
            group: group.to_string(),
            copy: name.to_string(),
            valid: false,
            cd_x1e5: f64::INFINITY,
            f1: 0.0,
            nc: 0.0,
            ef1: 0.0,
            seconds: 0.0,
            repaired: false,
            error: String::new(),
        };
        let input = match d {
            None => Ok(clean.clone()),
            Some(d) => break_mesh(&clean, d, seed, cell).map_err(anyhow::Error::from),
        };
        let t = Instant::now();
        match input.and_then(|m| reconstruct(&m, res, net, encoder_layers, device)) {
            Ok((out, repaired)) => {
                row.seconds = t.elapsed().as_secs_f64();
                row.repaired = repaired;
                row.valid = !out.faces.is_empty() && validity::check(&out).is_valid();
                let out_n = norm.apply_mesh(&out);
                if d == Some(Defect::Overlap) {
                    // The reference of an overlap is the union's surface; a failure to build
                    // it is this copy's error row, not the end of the evaluation.
                    match union_surface(&truth, 0.25 * 2.0 / res as f64) {
                        Ok(union) => {
                            let m = compare(&out_n, &union, &opts);
                            (row.cd_x1e5, row.f1, row.nc, row.ef1) =
                                (m.cd_x1e5, m.f1, m.nc, f64::NAN);
                        }
                        Err(e) => row.error = format!("the union's surface: {e:#}"),
                    }
                } else {
                    let m = compare(&out_n, &truth, &opts);
                    (row.cd_x1e5, row.f1, row.nc, row.ef1) = (m.cd_x1e5, m.f1, m.nc, m.ef1);
                }
            }
            Err(e) => {
                row.seconds = t.elapsed().as_secs_f64();
                row.error = format!("{e:#}");
            }
        }
        emit(row)?;
    }
    Ok(())
}

/// The table per copy class: shapes, valid outputs, means of F1 / NC / EF1 beside the clean
/// copies' of the same shapes, the largest F1 loss, the mean time (clean first).
pub fn summary_markdown(rows: &[CopyRow]) -> String {
    let mut names: Vec<String> = vec!["clean".into()];
    names.extend(Defect::ALL.iter().map(|d| d.name().to_string()));
    let clean = |shape: &str| rows.iter().find(|r| r.shape == shape && r.copy == "clean");
    let mut out = String::from(
        "| copy | shapes | valid | F1 | F1 clean | mean dF1 | worst dF1 | NC | NC clean | EF1 | EF1 clean | time (s) | time clean (s) | errors |\n|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|\n",
    );
    for name in names {
        let rs: Vec<&CopyRow> = rows.iter().filter(|r| r.copy == name).collect();
        if rs.is_empty() {
            continue;
        }
        let pairs: Vec<(&CopyRow, &CopyRow)> = rs
            .iter()
            .filter_map(|r| clean(&r.shape).map(|c| (*r, c)))
            .collect();
        let n = pairs.len().max(1) as f64;
        let mean = |f: &dyn Fn(&CopyRow) -> f64, c: bool| {
            let v: Vec<f64> = pairs
                .iter()
                .map(|(r, k)| f(if c { k } else { r }))
                .filter(|x| x.is_finite())
                .collect();
            if v.is_empty() {
                f64::NAN
            } else {
                v.iter().sum::<f64>() / v.len() as f64
            }
        };
        let worst = pairs
            .iter()
            .map(|(r, c)| c.f1 - r.f1)
            .fold(f64::NEG_INFINITY, f64::max);
        let d_mean = pairs.iter().map(|(r, c)| c.f1 - r.f1).sum::<f64>() / n;
        let fmt = |x: f64| {
            if x.is_finite() {
                format!("{x:.3}")
            } else {
                "-".to_string()
            }
        };
        out += &format!(
            "| {name} | {} | {} | {} | {} | {} | {} | {} | {} | {} | {} | {} | {} | {} |\n",
            rs.len(),
            rs.iter().filter(|r| r.valid).count(),
            fmt(mean(&|r| r.f1, false)),
            fmt(mean(&|r| r.f1, true)),
            fmt(d_mean),
            fmt(worst),
            fmt(mean(&|r| r.nc, false)),
            fmt(mean(&|r| r.nc, true)),
            fmt(mean(&|r| r.ef1, false)),
            fmt(mean(&|r| r.ef1, true)),
            fmt(mean(&|r| r.seconds, false)),
            fmt(mean(&|r| r.seconds, true)),
            rs.iter().filter(|r| !r.error.is_empty()).count(),
        );
    }
    out
}
