//! Repair benchmark: the time of the mesh path before the network (normalisation and the exact
//! SDF grid), clean against each class of broken copy, side by side in one run. For each mesh
//! of a folder (default: the shared evaluation meshes), `clean` is the path without the repair
//! (`--no-repair`), `clean+check` the default path on the clean mesh (the repair only looks),
//! and each defect class the default path on a broken copy (`ponq_data::broken`).
//!
//! ```sh
//! cargo bench -p ponq-data --bench repair_bench                       # 64 cells, 20 meshes
//! cargo bench -p ponq-data --bench repair_bench -- DIR --res 64 --limit 105
//! ```
//!
//! Prints, per class, the median and the mean over the meshes of (time / clean time), and the
//! total seconds.

use std::path::{Path, PathBuf};
use std::time::Instant;

use ponq_data::broken::{Defect, break_mesh};
use ponq_data::normalize::Normalization;
use ponq_data::repair::{RepairOptions, repair_with_solid};
use ponq_data::sdf::MeshSdf;
use ponq_mesh::{TriMesh, io};

fn meshes(dir: &Path) -> Vec<PathBuf> {
    let mut out = Vec::new();
    let mut stack = vec![dir.to_path_buf()];
    while let Some(d) = stack.pop() {
        let Ok(rd) = std::fs::read_dir(&d) else {
            continue;
        };
        for e in rd.flatten() {
            let p = e.path();
            if p.is_dir() {
                stack.push(p);
            } else if io::MeshFormat::from_path(&p).is_some() {
                out.push(p);
            }
        }
    }
    out.sort();
    out
}

/// The default path: repair, normalise, grid; seconds.
fn repaired_path(m: &TriMesh, res: usize) -> f64 {
    let t = Instant::now();
    let r = repair_with_solid(m, &RepairOptions::default()).expect("repair");
    let n = Normalization::of(&r.mesh).expect("normalise");
    let g = r.grid(|x| n.apply_mesh(x), res, |_| {}).expect("grid");
    std::hint::black_box(g);
    t.elapsed().as_secs_f64()
}

/// The path without the repair; seconds.
fn plain_path(m: &TriMesh, res: usize) -> f64 {
    let t = Instant::now();
    let n = Normalization::of(m).expect("normalise");
    let g = MeshSdf::new(&n.apply_mesh(m))
        .expect("sdf")
        .grid(res, |_| {})
        .expect("grid");
    std::hint::black_box(g);
    t.elapsed().as_secs_f64()
}

fn main() {
    let args: Vec<String> = std::env::args()
        .skip(1)
        .filter(|a| a != "--bench")
        .collect();
    let mut dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../shared/data/meshes");
    let (mut res, mut limit) = (64usize, 20usize);
    let mut i = 0;
    while i < args.len() {
        match args[i].as_str() {
            "--res" => {
                res = args[i + 1].parse().expect("--res N");
                i += 1;
            }
            "--limit" => {
                limit = args[i + 1].parse().expect("--limit N");
                i += 1;
            }
            a => dir = PathBuf::from(a),
        }
        i += 1;
    }
    let files: Vec<PathBuf> = meshes(&dir).into_iter().take(limit).collect();
    if files.is_empty() {
        eprintln!("no mesh in {} (give a folder of meshes)", dir.display());
        return;
    }
    let mut names = vec!["clean".to_string(), "clean+check".to_string()];
    names.extend(Defect::ALL.iter().map(|d| d.name().to_string()));
    let mut ratios: Vec<Vec<f64>> = vec![Vec::new(); names.len()];
    let mut totals = vec![0.0f64; names.len()];
    for f in &files {
        let Ok(m) = io::read_mesh(f) else {
            continue;
        };
        let (lo, hi) = m.bounding_box().expect("vertices");
        let diag = (0..3).map(|k| (hi[k] - lo[k]).powi(2)).sum::<f64>().sqrt();
        let base = plain_path(&m, res);
        let mut times = vec![base, repaired_path(&m, res)];
        for d in Defect::ALL {
            let b = break_mesh(&m, d, 1, diag / res as f64).expect("break");
            times.push(repaired_path(&b, res));
        }
        for (k, t) in times.iter().enumerate() {
            ratios[k].push(t / base);
            totals[k] += t;
        }
    }
    println!(
        "{} meshes of {} at {}^3 nodes; time of normalisation + (repair +) exact SDF grid",
        ratios[0].len(),
        dir.display(),
        res + 1
    );
    println!("| input | median x clean | mean x clean | total (s) |");
    println!("|---|---:|---:|---:|");
    for (k, n) in names.iter().enumerate() {
        let mut r = ratios[k].clone();
        r.sort_by(f64::total_cmp);
        let med = r.get(r.len() / 2).copied().unwrap_or(f64::NAN);
        let mean = r.iter().sum::<f64>() / r.len().max(1) as f64;
        println!("| {n} | {med:.2} | {mean:.2} | {:.2} |", totals[k]);
    }
}
