//! Validity-check benchmark: time of each part of [`validity::check`] on large meshes, and the
//! two face hierarchies (binned SAH [`Bvh::build`] vs Morton order [`Bvh::build_morton`]) side
//! by side in the same run.
//!
//! `cargo bench -p ponq-mesh --bench validity_bench` meshes the synthetic PoNQs of
//! `mesh_bench` at grids 145 and 230 (~40k and ~100k points) and prints a table; mesh files
//! (`.obj`, `.ply`, `.off`, `.stl`) given after `--` are checked too. `--repeat N` (default 5)
//! keeps the best of N runs of each column.

#[path = "util/args.rs"]
mod args;
#[path = "../tests/common/mod.rs"]
mod common;

use std::time::{Duration, Instant};

use common::*;
use ponq_mesh::bvh::{Aabb, Bvh};
use ponq_mesh::mesher::{MeshingOptions, mesh_ponq};
use ponq_mesh::{TriMesh, io, validity};

fn best<T>(repeat: usize, mut f: impl FnMut() -> T) -> (Duration, T) {
    let mut out = None;
    let mut time = Duration::MAX;
    for _ in 0..repeat {
        let t = Instant::now();
        let r = f();
        time = time.min(t.elapsed());
        out = Some(r);
    }
    (time, out.expect("repeat >= 1"))
}

/// Face pairs whose boxes overlap, counted in parallel.
fn pairs(t: &Bvh) -> usize {
    t.par_fold_overlapping_pairs(|| 0usize, |c, _, _| *c += 1, |a, b| a + b)
}

fn row(name: &str, mesh: &TriMesh, repeat: usize) {
    let ms = |d: Duration| d.as_secs_f64() * 1e3;
    let (t_check, report) = best(repeat, || validity::check(mesh));
    let (t_topo, _) = best(repeat, || validity::check_topology(mesh));
    let (t_self, n_self) = best(repeat, || validity::count_self_intersections(mesh));
    let boxes: Vec<Aabb> = (0..mesh.faces.len())
        .map(|f| Aabb::from_points(&mesh.triangle(f)))
        .collect();
    let (t_sah, sah) = best(repeat, || Bvh::build(&boxes));
    let (t_morton, morton) = best(repeat, || Bvh::build_morton(&boxes));
    let (t_sah_pairs, n_sah) = best(repeat, || pairs(&sah));
    let (t_morton_pairs, n_morton) = best(repeat, || pairs(&morton));
    assert_eq!(
        n_sah, n_morton,
        "both hierarchies report the same box pairs"
    );
    println!(
        "| {name} | {} | {} | **{:.1}** | {:.1} | {:.1} ({n_self}) | {:.1} / {:.1} | {:.1} / {:.1} | {n_sah} |",
        mesh.faces.len(),
        if report.is_valid() { "yes" } else { "NO" },
        ms(t_check),
        ms(t_topo),
        ms(t_self),
        ms(t_sah),
        ms(t_morton),
        ms(t_sah_pairs),
        ms(t_morton_pairs),
    );
}

const USAGE: &str = "\
Validity-check benchmark: each part of the check on the meshes of mesh_bench's synthetic
PoNQs at grids 145 and 230, and the two face hierarchies (SAH, Morton) side by side.

usage: cargo bench -p ponq-mesh --bench validity_bench -- [--repeat N] [MESH ...]

  --repeat N   best of N runs of each column (default 5)
  MESH         .obj / .ply / .off / .stl files checked too
  -h, --help   this text";

fn main() {
    let args = args::parse(USAGE, &["--repeat"]);
    let repeat = args
        .windows(2)
        .find(|w| w[0] == "--repeat")
        .map(|w| w[1].parse::<usize>().expect("a number after --repeat"))
        .unwrap_or(5)
        .max(1);
    println!(
        "| input | faces | valid | check ms | topology ms | self-intersection ms (count) | BVH build ms, SAH / Morton | box pairs ms, SAH / Morton | box pairs |"
    );
    println!("|---|---:|---|---:|---:|---:|---:|---:|---:|");
    for (grid, samples) in [(145usize, 1_000_000usize), (230, 2_500_000)] {
        let ponq = ponq_by_grid(&cad_union_samples(samples), grid);
        let opts = MeshingOptions {
            grid_scale: grid as f64,
            ..Default::default()
        };
        let out = mesh_ponq(&ponq, &opts).expect("meshing");
        row(&format!("synthetic grid {grid}"), &out.mesh, repeat);
    }
    for arg in args.iter().filter(|a| {
        [".obj", ".ply", ".off", ".stl"]
            .iter()
            .any(|e| a.to_lowercase().ends_with(e))
    }) {
        match io::read_mesh(arg) {
            Ok(m) => row(arg, &m, repeat),
            Err(e) => eprintln!("{arg}: {e}"),
        }
    }
}
