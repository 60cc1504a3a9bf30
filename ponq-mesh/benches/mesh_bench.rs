//! Meshing benchmark: PoNQs of ~2k, ~10k, ~40k and ~100k points, time per stage.
//!
//! `cargo bench -p ponq-mesh --bench mesh_bench` prints a table. Extra `.npz` PoNQ files given
//! as arguments after `--` are meshed too (grid scale from a `_32`/`_64`/`_128` suffix, else 32).

#[path = "util/args.rs"]
mod args;
#[path = "../tests/common/mod.rs"]
mod common;

use std::time::{Duration, Instant};

use common::*;
use ponq_mesh::mesher::{MeshingOptions, StageTimes, mesh_ponq};
use ponq_mesh::{Ponq, io, validity};

/// The stage times in the table's column order.
fn stage_columns(s: &StageTimes) -> [Duration; 7] {
    [
        s.prepare,
        s.delaunay,
        s.tagging,
        s.cut,
        s.manifold,
        s.extraction,
        s.flips,
    ]
}

/// Prints the table row of `ponq`: the stage times of the run with the best total, or with
/// `stage_best` each stage's best over the runs (the total stays the best total).
fn row(name: &str, ponq: &Ponq, grid: f64, repeat: usize, stage_best: bool) {
    let opts = MeshingOptions {
        grid_scale: grid,
        ..Default::default()
    };
    // Warm-up run, then the best of `repeat` (3 unless `--repeat N`).
    let _ = mesh_ponq(ponq, &opts);
    let mut best = None;
    let mut stages_best: Option<[Duration; 7]> = None;
    for _ in 0..repeat {
        let t = Instant::now();
        let out = match mesh_ponq(ponq, &opts) {
            Ok(out) => out,
            Err(e) => {
                eprintln!("error: {name}: {e}");
                std::process::exit(2);
            }
        };
        let wall = t.elapsed();
        let stages = stage_columns(&out.stats.times);
        stages_best = Some(match stages_best {
            None => stages,
            Some(b) => std::array::from_fn(|k| b[k].min(stages[k])),
        });
        if best.as_ref().is_none_or(|(w, _)| wall < *w) {
            best = Some((wall, out));
        }
    }
    let (wall, out) = best.expect("ran");
    let stages = match stages_best {
        Some(b) if stage_best => b,
        _ => stage_columns(&out.stats.times),
    };
    let t = Instant::now();
    let valid = validity::check(&out.mesh);
    let check = t.elapsed();
    let ms = |d: Duration| d.as_secs_f64() * 1e3;
    println!(
        "| {name} | {} | {} | {:.1} | {:.1} | {:.1} | {:.1} | {:.1} | {:.1} | {:.1} | **{:.1}** | {} / {} | {} | {:.1} |",
        out.stats.points,
        out.stats.tets,
        ms(stages[0]),
        ms(stages[1]),
        ms(stages[2]),
        ms(stages[3]),
        ms(stages[4]),
        ms(stages[5]),
        ms(stages[6]),
        ms(wall),
        out.mesh.vertices.len(),
        out.mesh.faces.len(),
        if valid.is_valid() { "yes" } else { "NO" },
        ms(check)
    );
}

const USAGE: &str = "\
Meshing benchmark: synthetic CAD-like PoNQs (grids 32, 72, 145, 230: ~2k to ~109k points),
the time of each meshing stage (best of N after a warm-up run) and of the validity check.

usage: cargo bench -p ponq-mesh --bench mesh_bench -- [--grid G]... [--repeat N] [--stage-best] [--save DIR] [FILE.npz ...]

  --grid G      only this synthetic grid (repeatable); another grid than the four (16 to
                1024) gets about 47 G^2 surface samples, like grid 230 (221: ~100k points)
  --repeat N    best of N runs (default 3): a long run for a profiler
  --stage-best  each stage column: that stage's best over the N runs, instead of its time
                in the run with the best total (steadier for comparing one stage between
                builds on a noisy machine; the total column stays the best total)
  --save DIR    also write each synthetic PoNQ as DIR/synthetic_G.npz (for another build's
                ponq-mesh: benches/mesh_side_by_side.sh)
  FILE.npz      PoNQ files meshed too (grid scale from a _32 / _64 / _128 suffix, else 32)
  -h, --help    this text";

fn main() {
    // `--grid G` (repeatable) keeps only those synthetic grids, `--repeat N` times each: a
    // run for a profiler that is mostly meshing.
    let args = args::parse(USAGE, &["--grid", "--repeat", "--save", "--stage-best"]);
    let stage_best = args.iter().any(|a| a == "--stage-best");
    let value_of = |flag: &str| {
        args.windows(2)
            .filter(|w| w[0] == flag)
            .map(|w| {
                w[1].parse::<usize>().unwrap_or_else(|_| {
                    eprintln!("error: {flag} takes a number, got {}\n\n{USAGE}", w[1]);
                    std::process::exit(2);
                })
            })
            .collect::<Vec<_>>()
    };
    let only = value_of("--grid");
    // `--save DIR`: also write each synthetic PoNQ as `DIR/synthetic_G.npz` (for `ponq-mesh`
    // of another build, `--grid-scale G`).
    let save = args
        .windows(2)
        .find(|w| w[0] == "--save")
        .map(|w| std::path::PathBuf::from(&w[1]));
    if let Some(dir) = &save
        && let Err(e) = std::fs::create_dir_all(dir)
    {
        eprintln!("error: --save {}: {e}", dir.display());
        std::process::exit(2);
    }
    let repeat = value_of("--repeat").last().copied().unwrap_or(3).max(1);
    const STANDARD: [(usize, usize); 4] = [
        (32, 80_000),
        (72, 300_000),
        (145, 1_000_000),
        (230, 2_500_000),
    ];
    let grids: Vec<(usize, usize)> = if only.is_empty() {
        STANDARD.to_vec()
    } else {
        only.iter()
            .map(|&g| {
                if !(16..=1024).contains(&g) {
                    eprintln!("error: --grid {g}: give a grid from 16 to 1024\n\n{USAGE}");
                    std::process::exit(2);
                }
                let samples = STANDARD
                    .iter()
                    .find(|s| s.0 == g)
                    .map_or(2_500_000 * g * g / (230 * 230), |s| s.1);
                (g, samples)
            })
            .collect()
    };
    println!(
        "| input | points | tets | prepare ms | delaunay ms | tagging ms | cut ms | manifold ms | extraction ms | flips ms | total ms | V / F | valid | check ms |"
    );
    println!("|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---|---|---:|");
    for (grid, samples) in grids {
        let ponq = ponq_by_grid(&cad_union_samples(samples), grid);
        if let Some(dir) = &save {
            let path = dir.join(format!("synthetic_{grid}.npz"));
            if let Err(e) = io::npz::write_ponq(&path, &ponq) {
                eprintln!("error: --save {}: {e}", path.display());
                std::process::exit(2);
            }
        }
        row(
            &format!("synthetic grid {grid}"),
            &ponq,
            grid as f64,
            repeat,
            stage_best,
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
            Ok(p) => row(arg, &p, grid, repeat, stage_best),
            Err(e) => eprintln!("{arg}: {e}"),
        }
    }
}
