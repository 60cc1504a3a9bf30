//! `ponq-infer` time per stage (network, conversion to PoNQ, Delaunay, tagging, cut, manifold
//! repair, extraction, refinement against the grid's distances) with the shipped model on the
//! CPU (`flex`) backend, for SDF grids of the shipped example meshes at 33^3, 65^3 and 129^3
//! nodes. Each shape runs three times; the table has the fastest run's stages, and the
//! refinement's time beside the network's (its goal: at most the network's at 65^3).
//!
//! `cargo bench -p ponq-infer --bench infer_bench` (optional arguments: resolutions, e.g.
//! `-- 32 64`; default 32 64 128).

use std::time::Instant;

use ponq_data::normalize::Normalization;
use ponq_data::sdf::MeshSdf;
use ponq_infer::{InferOptions, infer};
use ponq_mesh::io::npy::Grid3;

fn main() {
    let res: Vec<usize> = std::env::args()
        .skip(1)
        .filter_map(|a| a.parse().ok())
        .collect();
    let res = if res.is_empty() {
        vec![32, 64, 128]
    } else {
        res
    };
    let dev = ponq_model::backend::cpu();
    let (net, cfg) = ponq_infer::shipped::load(&dev).expect("shipped model");
    let root = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("..");
    println!(
        "threads: {}; model width {}, {} encoder layers, P = {}",
        rayon::current_num_threads(),
        cfg.width,
        cfg.encoder_layers,
        cfg.points_per_cell
    );
    println!();
    println!(
        "| shape | grid | points | V | F | network | to PoNQ | Delaunay | tagging | cut | manifold | extraction | refinement | refinement / network | total (s) |"
    );
    println!("|---|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|");
    for name in ["csg", "example001"] {
        let mesh = ponq_mesh::io::read_mesh(root.join(format!("examples/{name}.obj")))
            .expect("example mesh");
        let mesh = Normalization::of(&mesh)
            .expect("normalise")
            .apply_mesh(&mesh);
        let sdf = MeshSdf::new(&mesh).expect("sdf");
        for &n in &res {
            let g = sdf.grid(n, |_| {}).expect("grid");
            let grid = Grid3::new([n + 1; 3], g.values.iter().map(|&v| f64::from(v)).collect())
                .expect("grid");
            let opts = InferOptions::default();
            let (r, total) = (0..3)
                .map(|_| {
                    let t = Instant::now();
                    let r = infer(&net, cfg.encoder_layers, &grid, &opts, &dev, |_, _| {})
                        .expect("infer");
                    (r, t.elapsed().as_secs_f64())
                })
                .min_by(|a, b| a.1.total_cmp(&b.1))
                .expect("three runs");
            let s = |d: std::time::Duration| format!("{:.3}", d.as_secs_f64());
            let st = &r.meshing.times;
            println!(
                "| {name} | {}^3 | {} | {} | {} | {} | {} | {} | {} | {} | {} | {} | {} | {:.2} | {total:.3} |",
                n + 1,
                r.ponq.len(),
                r.mesh.vertices.len(),
                r.mesh.faces.len(),
                s(r.times.network),
                s(r.times.convert),
                s(st.delaunay),
                s(st.tagging),
                s(st.cut),
                s(st.manifold),
                s(st.extraction),
                s(r.times.refine),
                r.times.refine.as_secs_f64() / r.times.network.as_secs_f64(),
            );
        }
    }
}
