//! Meshing benchmark: PoNQs of ~2k, ~10k, ~40k and ~100k points, time per stage.
//!
//! `cargo bench -p ponq-mesh --bench mesh_bench` prints a table. Extra `.npz` PoNQ files given
//! as arguments after `--` are meshed too (grid scale from a `_32`/`_64`/`_128` suffix, else 32).

#[path = "../tests/common/mod.rs"]
mod common;

use std::time::Instant;

use common::*;
use ponq_mesh::mesher::{MeshingOptions, mesh_ponq};
use ponq_mesh::{Ponq, io, validity};

/// A CAD-like closed surface: the boundary of the union of a box, a sphere and a cylinder
/// (samples of each part kept where they are outside the other two).
fn shape(n_samples: usize) -> Samples {
    let mut r = rng(42);
    let (blo, bhi) = ([-0.7, -0.5, -0.3], [0.6, 0.5, 0.35]);
    let (sc, sr) = ([0.3, 0.1, 0.2], 0.45);
    let (cr, cz0, cz1) = (0.3, -0.8, 0.8);
    let in_box = |p: &[f64; 3]| (0..3).all(|k| p[k] > blo[k] && p[k] < bhi[k]);
    let in_sphere = |p: &[f64; 3]| {
        (p[0] - sc[0]).powi(2) + (p[1] - sc[1]).powi(2) + (p[2] - sc[2]).powi(2) < sr * sr
    };
    let in_cyl = |p: &[f64; 3]| p[0] * p[0] + p[1] * p[1] < cr * cr && p[2] > cz0 && p[2] < cz1;
    let parts = [
        box_samples(blo, bhi, n_samples / 2, &mut r),
        sphere_samples(sc, sr, n_samples / 4, &mut r),
        cylinder_samples(cr, cz0, cz1, n_samples / 4, &mut r),
    ];
    let mut s = Samples {
        points: Vec::new(),
        normals: Vec::new(),
    };
    for (i, part) in parts.into_iter().enumerate() {
        for (p, n) in part.points.into_iter().zip(part.normals) {
            let covered =
                (i != 0 && in_box(&p)) || (i != 1 && in_sphere(&p)) || (i != 2 && in_cyl(&p));
            if !covered {
                s.points.push(p);
                s.normals.push(n);
            }
        }
    }
    s
}

fn row(name: &str, ponq: &Ponq, grid: f64, repeat: usize) {
    let opts = MeshingOptions {
        grid_scale: grid,
        ..Default::default()
    };
    // Warm-up run, then the best of `repeat` (3 unless `--repeat N`).
    let _ = mesh_ponq(ponq, &opts);
    let mut best = None;
    for _ in 0..repeat {
        let t = Instant::now();
        let out = mesh_ponq(ponq, &opts).expect("meshing");
        let wall = t.elapsed();
        if best.as_ref().is_none_or(|(w, _)| wall < *w) {
            best = Some((wall, out));
        }
    }
    let (wall, out) = best.expect("ran");
    let t = Instant::now();
    let valid = validity::check(&out.mesh);
    let check = t.elapsed();
    let ms = |d: std::time::Duration| d.as_secs_f64() * 1e3;
    let s = &out.stats;
    println!(
        "| {name} | {} | {} | {:.1} | {:.1} | {:.1} | {:.1} | {:.1} | {:.1} | {:.1} | **{:.1}** | {} / {} | {} | {:.1} |",
        s.points,
        s.tets,
        ms(s.times.prepare),
        ms(s.times.delaunay),
        ms(s.times.tagging),
        ms(s.times.cut),
        ms(s.times.manifold),
        ms(s.times.extraction),
        ms(s.times.flips),
        ms(wall),
        out.mesh.vertices.len(),
        out.mesh.faces.len(),
        if valid.is_valid() { "yes" } else { "NO" },
        ms(check)
    );
}

fn main() {
    // `--grid G` (repeatable) keeps only those synthetic grids, `--repeat N` times each: a
    // run for a profiler that is mostly meshing.
    let args: Vec<String> = std::env::args().skip(1).collect();
    let value_of = |flag: &str| {
        args.windows(2)
            .filter(|w| w[0] == flag)
            .map(|w| w[1].parse::<usize>().expect("a number after the flag"))
            .collect::<Vec<_>>()
    };
    let only = value_of("--grid");
    // `--save DIR`: also write each synthetic PoNQ as `DIR/synthetic_G.npz` (for `ponq-mesh`
    // of another build, `--grid-scale G`).
    let save = args
        .windows(2)
        .find(|w| w[0] == "--save")
        .map(|w| std::path::PathBuf::from(&w[1]));
    let repeat = value_of("--repeat").last().copied().unwrap_or(3).max(1);
    println!(
        "| input | points | tets | prepare ms | delaunay ms | tagging ms | cut ms | manifold ms | extraction ms | flips ms | total ms | V / F | valid | check ms |"
    );
    println!("|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---|---|---:|");
    for (grid, samples) in [
        (32usize, 80_000usize),
        (72, 300_000),
        (145, 1_000_000),
        (230, 2_500_000),
    ] {
        if !only.is_empty() && !only.contains(&grid) {
            continue;
        }
        let ponq = ponq_by_grid(&shape(samples), grid);
        if let Some(dir) = &save {
            let path = dir.join(format!("synthetic_{grid}.npz"));
            io::npz::write_ponq(&path, &ponq).expect("writing the PoNQ");
        }
        row(
            &format!("synthetic grid {grid}"),
            &ponq,
            grid as f64,
            repeat,
        );
    }
    for arg in args.iter().filter(|a| a.ends_with(".npz")) {
        let grid = if arg.contains("_128") {
            128.0
        } else if arg.contains("_64") {
            64.0
        } else {
            32.0
        };
        match io::npz::read_ponq(arg) {
            Ok(p) => row(arg, &p, grid, repeat),
            Err(e) => eprintln!("{arg}: {e}"),
        }
    }
}
