//! Evaluation on a split with the paper's protocol (SPEC section 8): every shape is
//! reconstructed from its SDF grid by PoNQ (and PoNQ-lite) and by marching cubes on the same
//! grid, compared with the ground truth at unit bounding-box diagonal, and summarised.
//!
//! Resumable: the rows of each (shape, resolution) go to `OUT/rows/<shape>@<res>.csv`
//! (written atomically); a rerun skips the pairs already there.

use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::{Context, Result, bail};
use burn::prelude::*;
use ponq_data::normalize::Normalization;
use ponq_data::sdf::MeshSdf;
use ponq_mesh::io::npy::Grid3;
use ponq_mesh::metrics::{MetricOptions, compare};
use ponq_mesh::{TriMesh, io, validity};
use ponq_model::PonqNet;

use crate::infer::{InferOptions, infer};
use crate::render::{Image, render};

/// A reconstruction method.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord)]
pub enum Method {
    /// PoNQ (all points).
    Ponq,
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
    /// Surface / edge samples per mesh for the metrics.
    pub samples: usize,
    /// Shapes (the first ones) rendered side by side.
    pub renders: usize,
    /// Network tile size.
    pub tile: usize,
}

/// One result line.
#[derive(Debug, Clone, PartialEq)]
pub struct Row {
    /// Shape id.
    pub shape: String,
    /// Method name.
    pub method: String,
    /// Resolution.
    pub res: usize,
    /// CD x 1e5.
    pub cd: f64,
    /// F1.
    pub f1: f64,
    /// Normal consistency.
    pub nc: f64,
    /// Edge CD x 1e2 (NaN without a ground-truth mesh).
    pub ecd: f64,
    /// Edge F1 (NaN without a ground-truth mesh).
    pub ef1: f64,
    /// Closed, oriented, manifold, free of self-intersections.
    pub watertight: bool,
    /// Vertices.
    pub vertices: usize,
    /// Faces.
    pub faces: usize,
    /// Reconstruction time from the grid (seconds).
    pub seconds: f64,
}

/// CSV header of [`Row`].
pub const CSV_HEADER: &str =
    "shape,method,res,cd_x1e5,f1,nc,ecd_x1e2,ef1,watertight,vertices,faces,seconds";

impl Row {
    /// One CSV line.
    pub fn csv(&self) -> String {
        format!(
            "{},{},{},{},{},{},{},{},{},{},{},{}",
            self.shape,
            self.method,
            self.res,
            self.cd,
            self.f1,
            self.nc,
            self.ecd,
            self.ef1,
            self.watertight,
            self.vertices,
            self.faces,
            self.seconds
        )
    }

    /// Parses a line written by [`Row::csv`].
    pub fn parse(line: &str) -> Result<Self> {
        let f: Vec<&str> = line.split(',').collect();
        if f.len() != 12 {
            bail!("a result row needs 12 fields: {line}");
        }
        let num = |i: usize| -> Result<f64> {
            f[i].parse().with_context(|| format!("field {i} of {line}"))
        };
        Ok(Self {
            shape: f[0].to_string(),
            method: f[1].to_string(),
            res: f[2].parse()?,
            cd: num(3)?,
            f1: num(4)?,
            nc: num(5)?,
            ecd: num(6)?,
            ef1: num(7)?,
            watertight: f[8].parse()?,
            vertices: f[9].parse()?,
            faces: f[10].parse()?,
            seconds: num(11)?,
        })
    }
}

const MESH_EXT: [&str; 4] = ["obj", "ply", "off", "stl"];

/// The shapes to evaluate: files of `data` (meshes, or `.npz` / `.hdf5` records) sorted by
/// name, restricted to a split's ids when given; also returns the split ids with no file.
pub fn inputs(data: &Path, split: Option<&Path>) -> Result<(Vec<Shape>, Vec<String>)> {
    let is_shape = |p: &Path| {
        p.extension()
            .and_then(|e| e.to_str())
            .map(|e| e.to_ascii_lowercase())
            .is_some_and(|e| {
                MESH_EXT.contains(&e.as_str()) || matches!(e.as_str(), "npz" | "hdf5" | "h5")
            })
    };
    // The folder is searched recursively (data sets are often grouped in sub-folders).
    let mut files: Vec<(String, PathBuf)> = Vec::new();
    let mut stack = vec![data.to_path_buf()];
    while let Some(dir) = stack.pop() {
        for e in
            std::fs::read_dir(&dir).with_context(|| format!("cannot list {}", dir.display()))?
        {
            let p = e
                .with_context(|| format!("cannot list {}", dir.display()))?
                .path();
            if p.is_dir() {
                stack.push(p);
            } else if is_shape(&p)
                && let Some(stem) = p.file_stem().and_then(|s| s.to_str())
            {
                files.push((stem.to_string(), p));
            }
        }
    }
    files.sort();
    // The id of a shape is its file stem: two files with one stem would be ambiguous.
    if let Some(w) = files.windows(2).find(|w| w[0].0 == w[1].0) {
        bail!(
            "two shapes with the id {:?} ({} and {}); ids are file stems and must be unique",
            w[0].0,
            w[0].1.display(),
            w[1].1.display()
        );
    }
    let mut missing = Vec::new();
    if let Some(split) = split {
        let ids = ponq_data::dataset::read_split(split)
            .with_context(|| format!("cannot read the split {}", split.display()))?;
        let have: std::collections::HashSet<&str> = files.iter().map(|f| f.0.as_str()).collect();
        missing = ids
            .iter()
            .filter(|id| !have.contains(id.as_str()))
            .cloned()
            .collect();
        let want: std::collections::HashSet<&str> = ids.iter().map(String::as_str).collect();
        files.retain(|f| want.contains(f.0.as_str()));
    }
    Ok((files, missing))
}

/// Ground truth of a shape in the `[-1,1]` frame: the normalised mesh when the input is a
/// mesh, else the record's samples and normals, plus its SDF grids.
struct Truth {
    mesh: Option<TriMesh>,
    samples: Vec<[f64; 3]>,
    normals: Vec<[f64; 3]>,
    sdf: MeshOrRecord,
}

enum MeshOrRecord {
    Mesh(Box<MeshSdf>),
    Record(std::collections::BTreeMap<usize, Vec<f32>>),
}

fn truth(path: &Path) -> Result<Truth> {
    let ext = path
        .extension()
        .and_then(|e| e.to_str())
        .map(|e| e.to_ascii_lowercase())
        .unwrap_or_default();
    if MESH_EXT.contains(&ext.as_str()) {
        let m = io::read_mesh(path)?;
        let m = Normalization::of(&m)?.apply_mesh(&m);
        let sdf = MeshSdf::new(&m)?;
        Ok(Truth {
            mesh: Some(m),
            samples: vec![],
            normals: vec![],
            sdf: MeshOrRecord::Mesh(Box::new(sdf)),
        })
    } else {
        let rec = if ext == "npz" {
            ponq_data::dataset::ShapeRecord::read(path)?
        } else {
            ponq_data::hdf5::read_authors_h5(path)?
        };
        let f = |v: &[[f32; 3]]| v.iter().map(|p| p.map(f64::from)).collect();
        Ok(Truth {
            mesh: None,
            samples: f(&rec.samples),
            normals: f(&rec.normals),
            sdf: MeshOrRecord::Record(rec.sdf),
        })
    }
}

fn grid_of(t: &Truth, res: usize) -> Result<Grid3> {
    let values: Vec<f64> = match &t.sdf {
        MeshOrRecord::Mesh(s) => s
            .grid(res, |_| {})?
            .values
            .iter()
            .map(|&v| f64::from(v))
            .collect(),
        MeshOrRecord::Record(g) => g
            .get(&res)
            .with_context(|| format!("the record has no SDF grid at resolution {res}"))?
            .iter()
            .map(|&v| f64::from(v))
            .collect(),
    };
    Ok(Grid3::new([res + 1; 3], values)?)
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

/// A shape to evaluate: its id (the file stem) and its file.
pub type Shape = (String, PathBuf);

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
    for &m in &opts.methods {
        let start = Instant::now();
        let mesh = match m {
            Method::Mc => ponq_mesh::marching_cubes::marching_cubes(
                &grid.data, grid.dims, [-1.0; 3], [1.0; 3],
            )?,
            Method::Ponq | Method::Lite => {
                let io = InferOptions {
                    tile: opts.tile,
                    lite: m == Method::Lite,
                    coarsen: if m == Method::Lite { opts.coarsen } else { 0 },
                    ..Default::default()
                };
                match infer(net, encoder_layers, &grid, &io, device, |_, _| {}) {
                    Ok(r) => r.mesh,
                    Err(e) if e.to_string().contains("no sign change") => TriMesh::default(),
                    Err(e) => return Err(e),
                }
            }
        };
        let seconds = start.elapsed().as_secs_f64();
        let (cd, f1, nc, ecd, ef1, watertight) = metrics(&mesh, &t, opts.samples);
        rows.push(Row {
            shape: id.to_string(),
            method: m.name().to_string(),
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
                Method::Lite => [0.5, 0.85, 0.55],
            };
            ims.push(render(mesh, view, 256, c));
        }
        Image::hstack(&ims)
    });
    Ok((rows, image))
}

/// Means per (method, resolution) in the paper's layout, as a Markdown table.
pub fn summary_markdown(rows: &[Row]) -> String {
    let mut keys: Vec<(usize, String)> = rows.iter().map(|r| (r.res, r.method.clone())).collect();
    keys.sort();
    keys.dedup();
    let mut s = String::from(
        "| method | grid | shapes | CD x1e5 | F1 | NC | ECD x1e2 | EF1 | watertight % | #V | #F | time (s) |\n\
         |---|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|\n",
    );
    for (res, method) in keys {
        let g: Vec<&Row> = rows
            .iter()
            .filter(|r| r.res == res && r.method == method)
            .collect();
        let n = g.len() as f64;
        let mean = |f: &dyn Fn(&Row) -> f64| {
            let v: Vec<f64> = g.iter().map(|r| f(r)).filter(|x| x.is_finite()).collect();
            if v.is_empty() {
                f64::NAN
            } else {
                v.iter().sum::<f64>() / v.len() as f64
            }
        };
        let fmt = |x: f64, d: usize| {
            if x.is_nan() {
                "-".to_string()
            } else {
                format!("{x:.d$}")
            }
        };
        s += &format!(
            "| {method} | {}^3 | {} | {} | {} | {} | {} | {} | {:.1} | {:.0} | {:.0} | {} |\n",
            res + 1,
            g.len(),
            fmt(mean(&|r| r.cd), 3),
            fmt(mean(&|r| r.f1), 3),
            fmt(mean(&|r| r.nc), 3),
            fmt(mean(&|r| r.ecd), 3),
            fmt(mean(&|r| r.ef1), 3),
            100.0 * g.iter().filter(|r| r.watertight).count() as f64 / n,
            mean(&|r| r.vertices as f64),
            mean(&|r| r.faces as f64),
            fmt(mean(&|r| r.seconds), 3),
        );
    }
    s
}

/// Reads all rows of `out/rows`.
pub fn read_rows(out: &Path) -> Result<Vec<Row>> {
    let dir = out.join("rows");
    let mut rows = Vec::new();
    if !dir.is_dir() {
        return Ok(rows);
    }
    let mut files: Vec<PathBuf> = std::fs::read_dir(&dir)?
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.extension().is_some_and(|e| e == "csv"))
        .collect();
    files.sort();
    for f in files {
        for line in std::fs::read_to_string(&f)?.lines().skip(1) {
            rows.push(Row::parse(line).with_context(|| format!("in {}", f.display()))?);
        }
    }
    Ok(rows)
}

/// Path of the rows of one (shape, resolution).
pub fn rows_path(out: &Path, id: &str, res: usize) -> PathBuf {
    out.join("rows").join(format!("{id}@{res}.csv"))
}

/// Writes rows atomically.
pub fn write_rows(path: &Path, rows: &[Row]) -> Result<()> {
    let tmp = path.with_extension("csv.tmp");
    let mut text = String::from(CSV_HEADER);
    text.push('\n');
    for r in rows {
        text += &r.csv();
        text.push('\n');
    }
    std::fs::write(&tmp, text)?;
    std::fs::rename(&tmp, path)?;
    Ok(())
}

/// Writes `per_shape.csv`, `summary.md` and `report.md` of `out` from its rows.
pub fn write_report(
    out: &Path,
    missing: &[String],
    failed: &[(String, String)],
) -> Result<Vec<Row>> {
    let mut rows = read_rows(out)?;
    rows.sort_by(|a, b| (a.res, &a.method, &a.shape).cmp(&(b.res, &b.method, &b.shape)));
    let mut csv = String::from(CSV_HEADER);
    csv.push('\n');
    for r in &rows {
        csv += &r.csv();
        csv.push('\n');
    }
    std::fs::write(out.join("per_shape.csv"), csv)?;
    let summary = summary_markdown(&rows);
    std::fs::write(out.join("summary.md"), &summary)?;
    let mut rep = String::from(
        "# PoNQ-rs evaluation\n\nMeans over shapes; metrics at unit bounding-box diagonal (SPEC section 8); time is the reconstruction from the grid (network + meshing, or marching cubes).\n\n",
    );
    rep += &summary;
    if !missing.is_empty() {
        rep += &format!(
            "\n{} shapes of the split have no file here: {}\n",
            missing.len(),
            missing.join(", ")
        );
    }
    if !failed.is_empty() {
        rep += "\nFailed shapes:\n\n";
        for (id, e) in failed {
            rep += &format!("- {id}: {e}\n");
        }
    }
    let rdir = out.join("renders");
    if rdir.is_dir() {
        let mut imgs: Vec<PathBuf> = std::fs::read_dir(&rdir)?
            .filter_map(|e| e.ok().map(|e| e.path()))
            .collect();
        imgs.sort();
        if !imgs.is_empty() {
            rep += "\n## Renders (ground truth, then the methods in the table's order)\n\n";
            for p in imgs {
                if let Some(name) = p.file_name().and_then(|n| n.to_str()) {
                    rep += &format!("{name}\n\n![{name}](renders/{name})\n\n");
                }
            }
        }
    }
    std::fs::write(out.join("report.md"), rep)?;
    Ok(rows)
}
