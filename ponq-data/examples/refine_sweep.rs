//! Measures the refinement (`ponq_data::refine`) on saved network predictions, without the
//! network: per shape, the unrefined mesh (smooth cells merged, as `ponq-infer`) and the
//! refined one against the ground truth, then group means.
//!
//! `cargo run --release -p ponq-data --example refine_sweep -- PRED_DIR DATA_DIR [KEY=VALUE...]`
//!
//! `PRED_DIR/<id>_<res>.npz` come from `ponq-infer`'s `save_prediction` example run on
//! `DATA_DIR/<id>_<res>.npy` (SDF grids written by `ponq-prep sdf`); `DATA_DIR/<id>.{obj,off,
//! ply,stl}` is the ground truth (normalised here as `ponq-prep sdf` does). The
//! group of a shape is the part of its id before `__` (e.g. `cad__part`). KEY=VALUE set
//! `RefineOptions` fields (band, radius, max_shift, ball_tolerance, prior, normals,
//! min_samples, rounds, around_vstar, share, cutoff, clear), `merge` (degrees, default 15), `samples`
//! (metric samples, default 100000) and `only` (a comma-separated list of ids).

use std::collections::BTreeMap;
use std::path::PathBuf;
use std::time::Instant;

use anyhow::{Context, Result, bail};
use ponq_data::refine::{DistanceGrid, RefineOptions, check_distance, refine};
use ponq_mesh::io::npz::read_arrays;
use ponq_mesh::mesher::{MeshingOptions, mesh_ponq};
use ponq_mesh::metrics::{MetricOptions, compare};
use ponq_mesh::{Ponq, Quadric, TriMesh, io, validity};

fn read_prediction(path: &PathBuf) -> Result<(Ponq, Vec<[u32; 3]>)> {
    let arrays: BTreeMap<String, Vec<f64>> = read_arrays(path)?
        .into_iter()
        .map(|(n, a)| (n, a.data))
        .collect();
    let get = |n: &str| {
        arrays
            .get(n)
            .with_context(|| format!("{} lacks {n}", path.display()))
    };
    let v3 = |d: &Vec<f64>| d.chunks(3).map(|c| [c[0], c[1], c[2]]).collect::<Vec<_>>();
    let quadrics = get("quadrics")?
        .chunks(16)
        .map(|c| Quadric::from_matrix4(&nalgebra::Matrix4::from_row_slice(c)))
        .collect();
    let cells = get("cells")?
        .chunks(3)
        .map(|c| [c[0] as u32, c[1] as u32, c[2] as u32])
        .collect();
    let p = Ponq::new(
        v3(get("points")?),
        v3(get("normals")?),
        quadrics,
        Some(v3(get("vstars")?)),
    )?;
    Ok((p, cells))
}

#[derive(Default, Clone, Copy)]
struct Sum {
    n: usize,
    m: [f64; 5],
    valid: usize,
    secs: f64,
}

fn main() -> Result<()> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    if args.len() < 2 {
        bail!("usage: refine_sweep PRED_DIR DATA_DIR [KEY=VALUE...]");
    }
    let (pred_dir, data_dir) = (PathBuf::from(&args[0]), PathBuf::from(&args[1]));
    let mut o = RefineOptions::default();
    let mut merge = 15.0;
    let mut samples = 100_000;
    let mut only: Option<Vec<String>> = None;
    let mut all_share = false;

    for kv in &args[2..] {
        let (k, v) = kv.split_once('=').context("KEY=VALUE expected")?;
        let f = || v.parse::<f64>().with_context(|| format!("{k}={v}"));
        match k {
            "band" => o.band = f()?,
            "radius" => o.radius = f()?,
            "max_shift" => o.max_shift = f()?,
            "ball_tolerance" => o.ball_tolerance = f()?,
            "prior" => o.prior = f()?,
            "normals" => o.normals = v == "1" || v == "true",
            "around_vstar" => o.around_vstar = v == "1" || v == "true",
            "min_samples" => o.min_samples = f()? as usize,
            "iterations" | "rounds" => o.rounds = Some(f()? as usize),
            "merge" => merge = f()?,
            "share" => o.share = Some(f()?),
            "cutoff" => o.cutoff = f()?,
            "max_move" => o.max_move = f()?,
            "max_angle" => o.max_angle = f()?,
            "all_share" => all_share = v == "1",
            "clear" => o.clear = v == "1",
            "samples" => samples = f()? as usize,
            "only" => only = Some(v.split(',').map(String::from).collect()),
            _ => bail!("unknown key {k}"),
        }
    }
    let mut ids: Vec<String> = std::fs::read_dir(&pred_dir)?
        .filter_map(|e| e.ok())
        .filter_map(|e| {
            let p = e.path();
            (p.extension()? == "npz").then(|| p.file_stem()?.to_str().map(String::from))?
        })
        .collect();
    ids.sort();
    if let Some(only) = &only {
        ids.retain(|i| only.contains(i));
    }
    let mopt = MetricOptions {
        surface_samples: samples,
        edge_samples: samples,
        check_validity: false,
        ..Default::default()
    };
    let mut sums: BTreeMap<(String, usize), Sum> = BTreeMap::new();
    println!(
        "{:40} {:>4} | {:>7} {:>6} {:>6} {:>7} {:>6} | {:>7} {:>6} {:>6} {:>7} {:>6} | residuals",
        "shape", "res", "CD", "F1", "NC", "ECD", "EF1", "CD", "F1", "NC", "ECD", "EF1"
    );
    for id in &ids {
        let (raw, cells) = read_prediction(&pred_dir.join(format!("{id}.npz")))?;
        let (shape, _) = id.rsplit_once('_').context("ids are <shape>_<res>")?;
        let gt_path = ["obj", "off", "ply", "stl"]
            .iter()
            .map(|e| data_dir.join(format!("{shape}.{e}")))
            .find(|p| p.exists())
            .with_context(|| format!("no mesh {shape}.* in {}", data_dir.display()))?;
        let gt = io::read_mesh(&gt_path)?;
        let gt = ponq_data::normalize::Normalization::of(&gt)?.apply_mesh(&gt);
        let g = io::npy::read_npy_grid(data_dir.join(format!("{id}.npy")))?;
        let n = g.dims[0] - 1;
        let grid = DistanceGrid::new(g.dims, [-1.0; 3], 2.0 / n as f64, &g.data)?;
        let mopts = MeshingOptions {
            grid_scale: n as f64,
            ..Default::default()
        };
        let mesh_of = |p: &Ponq| -> Result<TriMesh> {
            let q = if merge > 0.0 {
                ponq_mesh::lite::merge_smooth_cells(p, &cells, merge)?
            } else {
                p.clone()
            };
            Ok(mesh_ponq(&q, &mopts)?.mesh)
        };
        let base = mesh_of(&raw)?;
        let t = Instant::now();
        let check = check_distance(&grid);
        let sharing = if merge > 0.0 && !all_share {
            Some(
                ponq_mesh::lite::smooth_points(&raw, &cells, merge)?
                    .iter()
                    .map(|&s| !s)
                    .collect::<Vec<bool>>(),
            )
        } else {
            None
        };
        let r = refine(&raw, &base, &grid, &o, sharing.as_deref(), |p| {
            let mut q = if merge > 0.0 {
                ponq_mesh::lite::merge_smooth_cells(p, &cells, merge)?
            } else {
                p.clone()
            };
            if o.clear {
                ponq_data::refine::clear_balls(&grid, &mut q, o.max_move);
            }
            Ok(mesh_ponq(&q, &mopts)?.mesh)
        })?;
        let secs = t.elapsed().as_secs_f64();
        let mb = compare(&base, &gt, &mopt);
        let mr = compare(&r.mesh, &gt, &mopt);
        let valid = validity::check(&r.mesh).is_valid();
        if std::env::var_os("SWEEP_INTRUSIONS").is_some() {
            for d in [0.1, 0.25, 0.5] {
                eprintln!(
                    "{id}: intrusions at {d}: network {} refined {}",
                    ponq_data::refine::intrusions(&grid, &base, d),
                    ponq_data::refine::intrusions(&grid, &r.mesh, d)
                );
            }
        }
        let group = id.split("__").next().unwrap_or("").to_string();
        let res: Vec<String> = r.residuals.iter().map(|x| format!("{x:.3}")).collect();
        println!(
            "{:40} {:>4} | {:7.3} {:6.3} {:6.3} {:7.3} {:6.3} | {:7.3} {:6.3} {:6.3} {:7.3} {:6.3} | {} kept {} {}{}",
            id,
            n,
            mb.cd_x1e5,
            mb.f1,
            mb.nc,
            mb.ecd_x1e2,
            mb.ef1,
            mr.cd_x1e5,
            mr.f1,
            mr.nc,
            mr.ecd_x1e2,
            mr.ef1,
            res.join(" "),
            r.rounds_kept,
            if check.is_distance() {
                String::new()
            } else {
                format!("NOT-DISTANCE ({check}) ")
            },
            if valid { "" } else { "INVALID" }
        );
        for (k, m) in [(0usize, mb), (1, mr)] {
            let s = sums.entry((group.clone(), k)).or_default();
            s.n += 1;
            for (a, x) in [m.cd_x1e5, m.f1, m.nc, m.ecd_x1e2, m.ef1]
                .into_iter()
                .enumerate()
            {
                s.m[a] += x;
            }
            if k == 1 {
                s.valid += usize::from(valid);
                s.secs += secs;
            }
        }
    }
    println!(
        "\ngroup      rows      n      CD     F1     NC     ECD    EF1  valid  refine s/shape"
    );
    for ((g, k), s) in &sums {
        let n = s.n as f64;
        println!(
            "{:10} {:9} {:3} {:7.3} {:6.3} {:6.3} {:7.3} {:6.3}  {}",
            g,
            if *k == 0 { "network" } else { "refined" },
            s.n,
            s.m[0] / n,
            s.m[1] / n,
            s.m[2] / n,
            s.m[3] / n,
            s.m[4] / n,
            if *k == 1 {
                format!("{}/{}  {:.3}", s.valid, s.n, s.secs / n)
            } else {
                String::new()
            }
        );
    }
    Ok(())
}
