//! Colours through `ponq-infer MESH`, side by side with the same meshes without colours.
//!
//! Each mesh of a folder (default the shared evaluation meshes) is written as a PLY with a
//! colour per vertex given by a smooth function of the position (each channel affine in one
//! coordinate of the mesh's box: red x, green y, blue z, so that colours interpolated on the
//! input's faces are the function itself), then remeshed by the `ponq-infer` program twice,
//! with and without its colours (`--no-colours`, the path before colours existed), in
//! alternating order. It prints, per mesh and overall: the mean and largest colour error at
//! the output's vertices against the function there (in % of the range), and the time of both
//! runs. The coloured run's mesh is checked to be the `--no-colours` run's, vertex for vertex.
//!
//! `cargo bench -p ponq-infer --bench colours_bench -- [--data DIR] [--res 64] [--limit N]`

use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::Instant;

use ponq_mesh::colour::{Colours, Rgb};
use ponq_mesh::io;

fn arg(name: &str) -> Option<String> {
    let args: Vec<String> = std::env::args().collect();
    args.iter()
        .position(|a| a == name)
        .and_then(|i| args.get(i + 1).cloned())
}

fn binary() -> PathBuf {
    let exe = std::env::current_exe().expect("the bench's path");
    exe.parent()
        .and_then(|d| d.parent())
        .map(|d| d.join("ponq-infer"))
        .expect("target/release")
}

fn meshes(dir: &Path) -> Vec<PathBuf> {
    let mut out = Vec::new();
    let mut stack = vec![dir.to_path_buf()];
    while let Some(d) = stack.pop() {
        for e in std::fs::read_dir(&d).expect("the data folder").flatten() {
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

/// The colour function of a mesh with box `lo..hi`.
fn colour_of(p: [f64; 3], lo: [f64; 3], hi: [f64; 3]) -> Rgb {
    std::array::from_fn(|k| (((p[k] - lo[k]) / (hi[k] - lo[k]).max(1e-12)) as f32).clamp(0.0, 1.0))
}

fn run(input: &Path, output: &Path, res: &str, colours: bool) -> f64 {
    let mut c = Command::new(binary());
    c.arg(input)
        .arg("-o")
        .arg(output)
        .args(["--res", res, "-q"]);
    if !colours {
        c.arg("--no-colours");
    }
    let t = Instant::now();
    let o = c.output().expect("ponq-infer runs");
    assert!(
        o.status.success(),
        "{}: {}",
        input.display(),
        String::from_utf8_lossy(&o.stderr)
    );
    t.elapsed().as_secs_f64()
}

fn main() {
    let data = arg("--data").map_or_else(
        || Path::new(env!("CARGO_MANIFEST_DIR")).join("../../shared/data/meshes"),
        PathBuf::from,
    );
    let res = arg("--res").unwrap_or_else(|| "64".into());
    let limit: usize = arg("--limit").map_or(usize::MAX, |s| s.parse().expect("--limit N"));
    let work = std::env::temp_dir().join(format!("ponq-colours-bench-{}", std::process::id()));
    std::fs::create_dir_all(&work).expect("a work folder");
    println!("| mesh | mean error % | max error % | with colours s | without s |");
    println!("|---|---:|---:|---:|---:|");
    let (mut errs, mut ratios) = (Vec::new(), Vec::new());
    let mut worst = 0.0f64;
    for (i, path) in meshes(&data).into_iter().take(limit).enumerate() {
        let Ok(mesh) = io::read_mesh(&path) else {
            continue;
        };
        let Some((lo, hi)) = mesh.bounding_box() else {
            continue;
        };
        let colours: Vec<Rgb> = mesh
            .vertices
            .iter()
            .map(|&p| colour_of(p, lo, hi))
            .collect();
        let input = work.join("in.ply");
        io::write_mesh_coloured(&input, &mesh, Some(&colours)).expect("write the coloured copy");
        let (with, without) = (work.join("with.ply"), work.join("without.ply"));
        // Alternate the order, so that neither run always comes first.
        let (tw, to) = if i % 2 == 0 {
            let a = run(&input, &with, &res, true);
            (a, run(&input, &without, &res, false))
        } else {
            let b = run(&input, &without, &res, false);
            (run(&input, &with, &res, true), b)
        };
        let (out, c) = io::read_mesh_coloured(&with).expect("the coloured output");
        let Some(Colours::Vertex(c)) = c else {
            panic!("{}: no colours in the output", path.display())
        };
        let plain = io::read_mesh(&without).expect("the plain output");
        assert_eq!(
            plain,
            out,
            "{}: another mesh without colours",
            path.display()
        );
        let e: Vec<f64> = out
            .vertices
            .iter()
            .zip(&c)
            .map(|(&p, col)| {
                let want = colour_of(p, lo, hi);
                (0..3)
                    .map(|k| f64::from((col[k] - want[k]).abs()))
                    .fold(0.0, f64::max)
            })
            .collect();
        let mean = 100.0 * e.iter().sum::<f64>() / e.len().max(1) as f64;
        let max = 100.0 * e.iter().copied().fold(0.0, f64::max);
        worst = worst.max(max);
        errs.push(mean);
        ratios.push(tw / to);
        println!(
            "| {} | {mean:.3} | {max:.2} | {tw:.3} | {to:.3} |",
            path.file_stem()
                .map(|s| s.to_string_lossy())
                .unwrap_or_default()
        );
    }
    ratios.sort_by(f64::total_cmp);
    let median = ratios.get(ratios.len() / 2).copied().unwrap_or(f64::NAN);
    println!(
        "\n{} meshes at --res {res}: mean colour error {:.3}% of the range (the largest at a \
         vertex {worst:.2}%); time with colours / without, median {median:.3} (min {:.3}, max \
         {:.3})",
        errs.len(),
        errs.iter().sum::<f64>() / errs.len().max(1) as f64,
        ratios.first().copied().unwrap_or(f64::NAN),
        ratios.last().copied().unwrap_or(f64::NAN)
    );
    std::fs::remove_dir_all(&work).ok();
}
