//! Grids in people's conventions side by side with the exact grid (`ponq-eval fields`): each
//! mesh's exact signed distance grid is rewritten in every convention of
//! [`ponq_data::conventions`] (other units, TSDFs, inside positive, occupancy-like fields,
//! squared, noise), and each copy goes through `ponq-infer`'s path (conditioning, the network,
//! meshing, refinement) and through marching cubes at the copy's own level and sign; both are
//! compared with the mesh.

use std::time::Instant;

use burn::prelude::*;
use ponq_data::condition::{ConditionOptions, Kind};
use ponq_data::conventions::Convention;
use ponq_infer::{InferOptions, infer};
use ponq_mesh::io::npy::Grid3;
use ponq_mesh::marching_cubes::marching_cubes;
use ponq_mesh::metrics::{MetricOptions, compare};
use ponq_mesh::{TriMesh, validity};
use ponq_model::PonqNet;

/// One copy of one shape at one resolution.
#[derive(Debug, Clone, PartialEq)]
pub struct FieldRow {
    /// Shape id and group (first folder below the data folder).
    pub shape: String,
    pub group: String,
    /// Cells per side.
    pub res: usize,
    /// The convention ([`Convention`]'s name).
    pub convention: String,
    /// What the conditioning found: `distance`, `scaled`, `mapped`.
    pub kind: String,
    /// `ponq-infer`'s output: valid, and its metrics against the mesh.
    pub valid: bool,
    pub f1: f64,
    pub nc: f64,
    pub ef1: f64,
    /// Marching cubes on the same copy (at its level, with its sign).
    pub mc_f1: f64,
    pub mc_nc: f64,
    pub mc_ef1: f64,
    /// The whole path, and the conditioning alone (ms).
    pub seconds: f64,
    pub condition_ms: f64,
    /// Error text when the copy could not be reconstructed (empty otherwise).
    pub error: String,
}

impl FieldRow {
    /// The CSV header of [`FieldRow::csv`].
    pub const HEADER: &'static str = "shape,group,res,convention,kind,valid,f1,nc,ef1,mc_f1,mc_nc,mc_ef1,seconds,condition_ms,error";

    /// One CSV line (the error text with commas, quotes and newlines replaced).
    pub fn csv(&self) -> String {
        format!(
            "{},{},{},{},{},{},{},{},{},{},{},{},{:.4},{:.3},{}",
            self.shape,
            self.group,
            self.res,
            self.convention,
            self.kind,
            self.valid,
            self.f1,
            self.nc,
            self.ef1,
            self.mc_f1,
            self.mc_nc,
            self.mc_ef1,
            self.seconds,
            self.condition_ms,
            self.error.replace([',', '"', '\n'], " ")
        )
    }

    /// Parses [`FieldRow::csv`].
    pub fn parse(line: &str) -> Option<Self> {
        let f: Vec<&str> = line.splitn(15, ',').collect();
        if f.len() != 15 {
            return None;
        }
        Some(Self {
            shape: f[0].to_string(),
            group: f[1].to_string(),
            res: f[2].parse().ok()?,
            convention: f[3].to_string(),
            kind: f[4].to_string(),
            valid: f[5].parse().ok()?,
            f1: f[6].parse().ok()?,
            nc: f[7].parse().ok()?,
            ef1: f[8].parse().ok()?,
            mc_f1: f[9].parse().ok()?,
            mc_nc: f[10].parse().ok()?,
            mc_ef1: f[11].parse().ok()?,
            seconds: f[12].parse().ok()?,
            condition_ms: f[13].parse().ok()?,
            error: f[14].to_string(),
        })
    }
}

/// Evaluates one copy: `exact` is the shape's exact grid (`res + 1` nodes per side over
/// `[-1,1]^3`), `truth` the normalised mesh.
#[allow(clippy::too_many_arguments)]
pub fn evaluate_copy(
    shape: &str,
    group: &str,
    exact: &Grid3,
    truth: &TriMesh,
    convention: Convention,
    seed: u64,
    samples: usize,
    net: &PonqNet,
    encoder_layers: usize,
    device: &Device,
) -> FieldRow {
    let res = exact.dims[0] - 1;
    let h = 2.0 / res as f64;
    let mut row = FieldRow {
        shape: shape.to_string(),
        group: group.to_string(),
        res,
        convention: convention.to_string(),
        kind: String::new(),
        valid: false,
        f1: 0.0,
        nc: 0.0,
        ef1: 0.0,
        mc_f1: 0.0,
        mc_nc: 0.0,
        mc_ef1: 0.0,
        seconds: 0.0,
        condition_ms: 0.0,
        error: String::new(),
    };
    let opts = MetricOptions {
        surface_samples: samples,
        edge_samples: samples,
        check_validity: false,
        ..Default::default()
    };
    let values = convention.apply(&exact.data, h, seed);
    let copy = match Grid3::new(exact.dims, values) {
        Ok(g) => g,
        Err(e) => {
            row.error = e.to_string();
            return row;
        }
    };
    // Marching cubes at the copy's own level and sign.
    let (level, inside_above) = convention.surface();
    let signed: Vec<f64> = copy
        .data
        .iter()
        .map(|&v| if inside_above { level - v } else { v - level })
        .collect();
    if let Ok(mc) = marching_cubes(&signed, copy.dims, [-1.0; 3], [1.0; 3])
        && !mc.faces.is_empty()
    {
        let m = compare(&mc, truth, &opts);
        (row.mc_f1, row.mc_nc, row.mc_ef1) = (m.f1, m.nc, m.ef1);
    }
    // ponq-infer's path, told only what a user must tell it (an offset surface's level).
    let iopts = InferOptions {
        condition: ConditionOptions {
            level: convention.level(),
            ..Default::default()
        },
        ..Default::default()
    };
    let t = Instant::now();
    let out = infer(net, encoder_layers, &copy, &iopts, device, |_, _| {});
    row.seconds = t.elapsed().as_secs_f64();
    match out {
        Ok(r) => {
            if let Some(c) = &r.conditioning {
                row.condition_ms = c.time.as_secs_f64() * 1e3;
                row.kind = match c.kind {
                    Kind::Distance => "distance",
                    Kind::Scaled { .. } => "scaled",
                    Kind::Mapped { .. } => "mapped",
                    Kind::Redistanced { .. } => "redistanced",
                }
                .to_string();
            }
            if r.mesh.faces.is_empty() {
                row.error = "empty mesh".into();
                return row;
            }
            row.valid = validity::check(&r.mesh).is_valid();
            let m = compare(&r.mesh, truth, &opts);
            (row.f1, row.nc, row.ef1) = (m.f1, m.nc, m.ef1);
        }
        Err(e) => row.error = format!("{e:#}"),
    }
    row
}

/// The table per resolution and convention: copies, valid outputs, mean F1 / NC / EF1 beside
/// the exact grid's (same shapes) and marching cubes' on the same copies, the worst F1 loss
/// against the exact grid, copies below marching cubes, the conditioning's mean time and its
/// share of the path.
pub fn summary_markdown(rows: &[FieldRow]) -> String {
    let mut out = String::from(
        "| grid | convention | kind | copies | valid | F1 | exact F1 | worst dF1 | MC F1 | below MC | NC | MC NC | EF1 | MC EF1 | conditioning ms | share of path |\n|---|---|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|\n",
    );
    let mut resolutions: Vec<usize> = rows.iter().map(|r| r.res).collect();
    resolutions.sort_unstable();
    resolutions.dedup();
    let mut names: Vec<String> = Vec::new();
    for r in rows {
        if !names.contains(&r.convention) {
            names.push(r.convention.clone());
        }
    }
    let order: Vec<String> = Convention::BENCHMARK
        .iter()
        .map(|c| c.to_string())
        .collect();
    names.sort_by_key(|n| order.iter().position(|o| o == n).unwrap_or(usize::MAX));
    let exact_f1 = |shape: &str, res: usize| {
        rows.iter()
            .find(|r| r.shape == shape && r.res == res && r.convention == "exact")
            .map(|r| r.f1)
    };
    for &res in &resolutions {
        for name in &names {
            let sel: Vec<&FieldRow> = rows
                .iter()
                .filter(|r| r.res == res && &r.convention == name)
                .collect();
            if sel.is_empty() {
                continue;
            }
            let n = sel.len() as f64;
            let mean = |f: &dyn Fn(&FieldRow) -> f64| sel.iter().map(|r| f(r)).sum::<f64>() / n;
            let paired: Vec<(f64, f64)> = sel
                .iter()
                .filter_map(|r| exact_f1(&r.shape, res).map(|e| (r.f1, e)))
                .collect();
            let exact_mean = paired.iter().map(|p| p.1).sum::<f64>() / paired.len().max(1) as f64;
            let worst = paired
                .iter()
                .map(|(f, e)| e - f)
                .fold(f64::NEG_INFINITY, f64::max);
            let below = sel.iter().filter(|r| r.f1 < r.mc_f1).count();
            let mut kinds: Vec<&str> = sel.iter().map(|r| r.kind.as_str()).collect();
            kinds.sort_unstable();
            kinds.dedup();
            let cond = mean(&|r| r.condition_ms);
            let share = sel
                .iter()
                .map(|r| r.condition_ms / 1e3 / r.seconds.max(1e-9))
                .sum::<f64>()
                / n;
            out.push_str(&format!(
                "| {}^3 | {name} | {} | {} | {} | {:.3} | {:.3} | {:.3} | {:.3} | {below} | {:.3} | {:.3} | {:.3} | {:.3} | {:.1} | {:.1}% |\n",
                res + 1,
                kinds.join("/"),
                sel.len(),
                sel.iter().filter(|r| r.valid).count(),
                mean(&|r| r.f1),
                exact_mean,
                worst,
                mean(&|r| r.mc_f1),
                mean(&|r| r.nc),
                mean(&|r| r.mc_nc),
                mean(&|r| r.ef1),
                mean(&|r| r.mc_ef1),
                cond,
                100.0 * share
            ));
        }
    }
    out
}
