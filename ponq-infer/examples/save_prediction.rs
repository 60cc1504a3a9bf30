//! Saves the network's PoNQ on SDF grids before any merging (every point of the kept cells,
//! in the grid's normalised frame, with each point's cell), for experiments with the stages
//! after the network (`ponq-data/examples/refine_sweep.rs`) that need no network run.
//!
//! `cargo run --release -p ponq-infer --example save_prediction -- OUT_DIR SDF.npy...`
//! writes `OUT_DIR/<stem>.npz` with float64 arrays `points`, `normals` (M, 3), `quadrics`
//! (M, 4, 4), `vstars` (M, 3) and `cells` (M, 3), using the shipped model.

use std::path::PathBuf;

use anyhow::{Context, Result, bail};
use ponq_infer::{InferOptions, predict, shipped};
use ponq_mesh::io::npz::{NamedArray, write_arrays};

fn main() -> Result<()> {
    let args: Vec<PathBuf> = std::env::args_os().skip(1).map(PathBuf::from).collect();
    if args.len() < 2 {
        bail!("usage: save_prediction OUT_DIR SDF.npy...");
    }
    let out = &args[0];
    std::fs::create_dir_all(out).with_context(|| format!("creating {}", out.display()))?;
    let dev = ponq_model::backend::cpu();
    let (net, cfg) = shipped::load(&dev)?;
    for sdf in &args[1..] {
        let grid = ponq_mesh::io::npy::read_npy_grid(sdf)
            .with_context(|| format!("reading {}", sdf.display()))?;
        let p = match predict(
            &net,
            cfg.encoder_layers,
            &grid,
            &InferOptions::default(),
            &dev,
            |_, _| {},
        ) {
            Ok(p) => p,
            Err(e) => {
                eprintln!("{}: skipped: {e:#}", sdf.display());
                continue;
            }
        };
        let m = p.ponq.len();
        let flat = |v: &[[f64; 3]]| v.iter().flatten().copied().collect::<Vec<f64>>();
        let arr = |name: &str, shape: Vec<usize>, data: Vec<f64>| NamedArray {
            name: name.into(),
            shape,
            data,
            f32_storage: false,
        };
        let quadrics: Vec<f64> = p
            .ponq
            .quadrics
            .iter()
            .flat_map(|q| {
                let mat = q.to_matrix4();
                (0..16).map(move |k| mat[(k / 4, k % 4)])
            })
            .collect();
        let stem = sdf
            .file_stem()
            .and_then(|s| s.to_str())
            .context("file name")?;
        let path = out.join(format!("{stem}.npz"));
        write_arrays(
            &path,
            &[
                arr("points", vec![m, 3], flat(&p.ponq.points)),
                arr("normals", vec![m, 3], flat(&p.ponq.normals)),
                arr("quadrics", vec![m, 4, 4], quadrics),
                arr("vstars", vec![m, 3], flat(&p.ponq.vstars())),
                arr(
                    "cells",
                    vec![m, 3],
                    p.cells.iter().flatten().map(|&c| f64::from(c)).collect(),
                ),
            ],
        )?;
        println!(
            "{}: {m} points, {:.0} ms network",
            path.display(),
            p.network.as_secs_f64() * 1e3
        );
    }
    Ok(())
}
