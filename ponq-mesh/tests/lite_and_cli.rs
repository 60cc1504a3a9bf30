//! PoNQ-lite / hierarchy, and the `ponq-mesh` command line end to end.

mod common;

use std::process::Command;

use common::*;
use ponq_mesh::lite::{cell_of, coarsen, merge_smooth_cells};
use ponq_mesh::mesher::{MeshingOptions, mesh_ponq};
use ponq_mesh::{Ponq, Quadric, io, validity};

fn grid_ponq(n: usize) -> (Ponq, Vec<[u32; 3]>) {
    // Four points per cell, like the network's P = 4: split each cell's samples in 4 groups.
    let s = box_samples(
        [-0.47, -0.41, -0.29],
        [0.53, 0.39, 0.31],
        80_000,
        &mut rng(5),
    );
    let dom = ([-1.0; 3], [1.0; 3]);
    let ids: Vec<u32> = s
        .points
        .iter()
        .enumerate()
        .map(|(i, p)| {
            let c = cell_of(*p, n, dom);
            ((((c[0] as usize * n) + c[1] as usize) * n + c[2] as usize) * 4 + i % 4) as u32
        })
        .collect();
    let (ponq, clusters) = Ponq::from_clusters(&s.points, &s.normals, &ids, n * n * n * 4).unwrap();
    let cells = clusters
        .iter()
        .map(|&c| {
            let cell = c as usize / 4;
            [
                (cell / (n * n)) as u32,
                ((cell / n) % n) as u32,
                (cell % n) as u32,
            ]
        })
        .collect();
    (ponq, cells)
}

#[test]
fn lite_sums_quadrics_per_cell_and_meshes_validly() {
    let n = 16;
    let (ponq, cells) = grid_ponq(n);
    let lite = coarsen(&ponq, &cells, 0).unwrap();
    let mut distinct = cells.clone();
    distinct.sort_unstable();
    distinct.dedup();
    assert_eq!(lite.len(), distinct.len(), "one point per occupied cell");
    // The quadrics are sums: the total is preserved.
    let total = |p: &Ponq| p.quadrics.iter().fold(Quadric::zero(), |a, q| a + *q);
    let (a, b) = (total(&ponq), total(&lite));
    assert!((a.to_matrix4() - b.to_matrix4()).norm() < 1e-9 * a.to_matrix4().norm());
    let out = mesh_ponq(
        &lite,
        &MeshingOptions {
            grid_scale: n as f64,
            ..Default::default()
        },
    )
    .unwrap();
    assert!(validity::check(&out.mesh).is_valid());
    assert!(out.mesh.vertices.len() <= lite.len());
    // The hierarchy: each level has fewer points and still meshes validly.
    let mut last = lite.len();
    for k in 1..=2 {
        let c = coarsen(&ponq, &cells, k).unwrap();
        assert!(c.len() < last, "level {k}: {} !< {last}", c.len());
        last = c.len();
        let out = mesh_ponq(
            &c,
            &MeshingOptions {
                grid_scale: (n >> k) as f64,
                ..Default::default()
            },
        )
        .unwrap();
        let r = validity::check(&out.mesh);
        assert!(r.is_valid() || out.mesh.faces.is_empty(), "level {k}: {r}");
    }
    assert!(coarsen(&ponq, &cells[1..], 0).is_err());
}

/// Adaptive lite merges exactly the cells whose normals agree within the angle: on a box,
/// the face cells (one normal) merge, the edge and corner cells (two or three normals) keep
/// their points; 0 degrees merges nothing here, 180 is PoNQ-lite; the result meshes validly.
#[test]
fn merge_smooth_cells_merges_flat_cells_and_keeps_creases() {
    let n = 16;
    let (ponq, cells) = grid_ponq(n);
    let mut by_cell: std::collections::BTreeMap<[u32; 3], Vec<usize>> = Default::default();
    for (i, &c) in cells.iter().enumerate() {
        by_cell.entry(c).or_default().push(i);
    }
    let unit = |n: [f64; 3]| {
        let l = (n[0] * n[0] + n[1] * n[1] + n[2] * n[2]).sqrt();
        n.map(|x| x / l)
    };
    // The expected outcome, cell by cell, from the normals' largest pairwise angle.
    let max_angle = |m: &[usize]| {
        let mut worst: f64 = 0.0;
        for &i in m {
            for &j in m {
                let (a, b) = (unit(ponq.normals[i]), unit(ponq.normals[j]));
                let c = (a[0] * b[0] + a[1] * b[1] + a[2] * b[2]).clamp(-1.0, 1.0);
                worst = worst.max(c.acos().to_degrees());
            }
        }
        worst
    };
    let flat = by_cell
        .values()
        .filter(|m| m.len() > 1 && max_angle(m) <= 20.0)
        .count();
    let crease: usize = by_cell
        .values()
        .filter(|m| m.len() == 1 || max_angle(m) > 20.0)
        .map(Vec::len)
        .sum();
    assert!(flat > 0 && crease > 0, "the box has both kinds of cells");
    let merged = merge_smooth_cells(&ponq, &cells, 20.0).unwrap();
    assert_eq!(merged.len(), flat + crease);
    // Quadric sums are preserved, so is the total.
    let total = |p: &Ponq| p.quadrics.iter().fold(Quadric::zero(), |a, q| a + *q);
    let (a, b) = (total(&ponq), total(&merged));
    assert!((a.to_matrix4() - b.to_matrix4()).norm() < 1e-9 * a.to_matrix4().norm());
    // Every point of a crease cell is still there.
    for m in by_cell.values().filter(|m| max_angle(m) > 20.0) {
        for &i in m {
            assert!(
                merged.points.contains(&ponq.points[i]),
                "crease point {i} kept"
            );
        }
    }
    let out = mesh_ponq(
        &merged,
        &MeshingOptions {
            grid_scale: n as f64,
            ..Default::default()
        },
    )
    .unwrap();
    assert!(validity::check(&out.mesh).is_valid());
    // 180 degrees is PoNQ-lite, point for point.
    let all = merge_smooth_cells(&ponq, &cells, 180.0).unwrap();
    let lite = coarsen(&ponq, &cells, 0).unwrap();
    assert_eq!(all.points, lite.points);
    assert_eq!(all.vstars(), lite.vstars());
    // Errors: lengths, angles.
    assert!(merge_smooth_cells(&ponq, &cells[1..], 20.0).is_err());
    assert!(merge_smooth_cells(&ponq, &cells, -1.0).is_err());
    assert!(merge_smooth_cells(&ponq, &cells, f64::NAN).is_err());
}

fn bin() -> Command {
    Command::new(env!("CARGO_BIN_EXE_ponq-mesh"))
}

fn example(name: &str) -> std::path::PathBuf {
    std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../examples")
        .join(name)
}

#[test]
fn cli_meshes_the_shipped_example() {
    let dir = std::env::temp_dir().join(format!("ponq-cli-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    for (args, file) in [
        (vec!["--grid-scale", "32"], "a.obj"),
        (vec!["--grid-scale", "32", "--lite"], "b.ply"),
        (
            vec!["--grid-scale", "32", "--lite", "--coarsen", "1"],
            "c.obj",
        ),
        (
            vec!["--grid-scale", "32", "--bounds", "-1,-1,-1,1,1,1"],
            "d.obj",
        ),
        (vec!["--grid-scale", "32", "--merge-smooth", "15"], "e.obj"),
    ] {
        let out = dir.join(file);
        let o = bin()
            .arg(example("csg_ponq_32.npz"))
            .arg("-o")
            .arg(&out)
            .args(&args)
            .output()
            .unwrap();
        assert!(
            o.status.success(),
            "{args:?}: {}",
            String::from_utf8_lossy(&o.stderr)
        );
        let stdout = String::from_utf8_lossy(&o.stdout);
        assert!(stdout.contains("validity: valid"), "{stdout}");
        let m = io::read_mesh(&out).unwrap();
        assert!(validity::check(&m).is_valid());
    }
    std::fs::remove_dir_all(&dir).ok();
}

/// The same file, byte for byte, with the AVX2 paths (where the CPU has them) and with the
/// portable code everywhere (`PONQ_NO_AVX2`, see `ponq_mesh::cpu`): the Delaunay's walk and
/// conflict lanes, the Hilbert keys, the tagging's and the flips' lanes, on both example
/// PoNQs, PoNQ-lite included.
#[test]
fn cli_output_does_not_depend_on_the_avx2_paths() {
    #[cfg(target_arch = "x86_64")]
    let avx2_cpu = std::arch::is_x86_feature_detected!("avx2");
    #[cfg(not(target_arch = "x86_64"))]
    let avx2_cpu = false;
    let dir = std::env::temp_dir().join(format!("ponq-cli-avx2-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    for (file, grid, extra) in [
        ("example001_ponq_64.npz", "64", &[][..]),
        ("example001_ponq_64.npz", "64", &["--lite"][..]),
        ("csg_ponq_32.npz", "32", &[][..]),
    ] {
        let mut files = Vec::new();
        for portable in ["0", "1"] {
            let out = dir.join(format!("p{portable}.obj"));
            let o = bin()
                .env("PONQ_NO_AVX2", portable)
                .arg(example(file))
                .arg("-o")
                .arg(&out)
                .args(["--grid-scale", grid, "--no-check"])
                .args(extra)
                .output()
                .unwrap();
            assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
            // The portable run says so; the other takes the AVX2 paths where the CPU has them.
            let stdout = String::from_utf8_lossy(&o.stdout);
            let avx2 = portable == "0" && avx2_cpu;
            assert!(
                stdout.contains(if avx2 { "AVX2 paths" } else { "portable code" }),
                "{stdout}"
            );
            files.push(std::fs::read(&out).unwrap());
        }
        assert!(files[0].len() > 1000);
        assert!(
            files[0] == files[1],
            "{file} {extra:?}: the meshes differ with PONQ_NO_AVX2"
        );
    }
    std::fs::remove_dir_all(&dir).ok();
}

/// The same file, byte for byte, with one worker thread and with three (the Delaunay's
/// canonical order and deterministic later stages), crease flips on and off.
#[test]
fn cli_output_does_not_depend_on_the_thread_count() {
    let dir = std::env::temp_dir().join(format!("ponq-cli-threads-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    for extra in [&[][..], &["--no-crease-flips"][..]] {
        let mut files = Vec::new();
        for threads in ["1", "3"] {
            let out = dir.join(format!("t{threads}.obj"));
            let o = bin()
                .arg(example("example001_ponq_64.npz"))
                .arg("-o")
                .arg(&out)
                .args(["--grid-scale", "64", "--threads", threads, "--no-check"])
                .args(extra)
                .output()
                .unwrap();
            assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
            let stdout = String::from_utf8_lossy(&o.stdout);
            assert!(
                stdout.contains(&format!("; {threads} worker threads")),
                "{stdout}"
            );
            files.push(std::fs::read(&out).unwrap());
        }
        assert!(files[0].len() > 1000);
        assert!(files[0] == files[1], "{extra:?}: the meshes differ");
    }
    let o = bin()
        .arg(example("csg_ponq_32.npz"))
        .args(["-o", dir.join("z.obj").to_str().unwrap(), "--threads", "0"])
        .output()
        .unwrap();
    assert_eq!(o.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&o.stderr).contains("--threads"));
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn cli_bad_input_is_a_clear_error() {
    let dir = std::env::temp_dir().join(format!("ponq-cli-bad-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let garbage = dir.join("garbage.npz");
    std::fs::write(&garbage, b"this is not a zip file").unwrap();
    let nan = dir.join("nan.npz");
    let mut p = io::npz::read_ponq(example("csg_ponq_32.npz")).unwrap();
    p.points[3][1] = f64::NAN;
    // Ponq::new refuses NaN, so write the file through the raw struct.
    io::npz::write_ponq(&nan, &p).ok();
    let cases: Vec<(Vec<std::ffi::OsString>, &str)> = vec![
        (
            vec![
                dir.join("missing.npz").into(),
                "-o".into(),
                dir.join("x.obj").into(),
            ],
            "missing.npz",
        ),
        (
            vec![
                garbage.clone().into(),
                "-o".into(),
                dir.join("x.obj").into(),
            ],
            "zip",
        ),
        (
            vec![
                example("csg_ponq_32.npz").into(),
                "-o".into(),
                dir.join("x.xyz").into(),
            ],
            "unsupported",
        ),
        (
            vec![
                example("csg_ponq_32.npz").into(),
                "-o".into(),
                dir.join("x.obj").into(),
                "--grid-scale".into(),
                "0".into(),
            ],
            "grid-scale",
        ),
        (
            vec![
                example("csg_ponq_32.npz").into(),
                "-o".into(),
                dir.join("x.obj").into(),
                "--bounds".into(),
                "-1,-1,-1,1,1".into(),
            ],
            "6 comma-separated",
        ),
        (
            vec![
                example("csg_ponq_32.npz").into(),
                "-o".into(),
                dir.join("x.obj").into(),
                "--coarsen".into(),
                "2".into(),
            ],
            "--lite",
        ),
        (
            vec![
                example("csg_ponq_32.npz").into(),
                "-o".into(),
                dir.join("x.obj").into(),
                "--merge-smooth".into(),
                "15".into(),
                "--lite".into(),
            ],
            "exclude each other",
        ),
        (
            vec![
                example("csg_ponq_32.npz").into(),
                "-o".into(),
                dir.join("x.obj").into(),
                "--merge-smooth".into(),
                "200".into(),
            ],
            "[0, 180]",
        ),
    ];
    for (args, needle) in cases {
        let o = bin().args(&args).output().unwrap();
        assert_eq!(o.status.code(), Some(2), "{args:?}");
        let err = String::from_utf8_lossy(&o.stderr).to_lowercase();
        assert!(err.contains(&needle.to_lowercase()), "{args:?}: {err}");
    }
    if nan.exists() {
        let o = bin()
            .arg(&nan)
            .arg("-o")
            .arg(dir.join("x.obj"))
            .output()
            .unwrap();
        assert_eq!(o.status.code(), Some(2));
        assert!(String::from_utf8_lossy(&o.stderr).contains("not finite"));
    }
    std::fs::remove_dir_all(&dir).ok();
}

/// Runs `ponq-mesh` on the shipped CSG example at 32^3 with `extra` flags, writing
/// `dir/name.obj`: the process output and the file's path.
fn mesh_example_into(
    dir: &std::path::Path,
    name: &str,
    extra: &[&str],
) -> (std::process::Output, std::path::PathBuf) {
    let out = dir.join(format!("{name}.obj"));
    let o = bin()
        .arg(example("csg_ponq_32.npz"))
        .arg("-o")
        .arg(&out)
        .args(["--grid-scale", "32"])
        .args(extra)
        .output()
        .unwrap();
    (o, out)
}

#[test]
fn cli_small_tet_rules_by_name() {
    let dir = std::env::temp_dir().join(format!("ponq-cli-rules-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let run = |name: &str, extra: &[&str]| mesh_example_into(&dir, name, extra);
    let mut files = Vec::new();
    for (name, extra) in [
        ("both", vec!["--small-tets", "both"]),
        ("both_old_flag", vec!["--small-tets-both-ways"]),
        ("authors", vec!["--small-tets", "authors"]),
        ("inside", vec!["--small-tets", "inside"]),
        ("default", vec![]),
    ] {
        let (o, out) = run(name, &extra);
        assert!(
            o.status.success(),
            "{name}: {}",
            String::from_utf8_lossy(&o.stderr)
        );
        let m = io::read_mesh(&out).unwrap();
        let r = validity::check(&m);
        assert!(r.is_valid(), "{name}: {r}");
        files.push(std::fs::read(&out).unwrap());
    }
    // The old flag is the `both` rule; the default is `inside`.
    assert!(files[0] == files[1]);
    assert!(files[3] == files[4]);
    // Unknown names and both spellings at once are usage errors that name the choices.
    let (o, _) = run("bad", &["--small-tets", "outside"]);
    assert_eq!(o.status.code(), Some(2));
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(err.contains("inside, both, authors"), "{err}");
    let (o, _) = run("twice", &["--small-tets", "both", "--small-tets-both-ways"]);
    assert_eq!(o.status.code(), Some(2));
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn cli_authors_mesher_is_its_three_flags() {
    let dir = std::env::temp_dir().join(format!("ponq-cli-authors-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let run = |name: &str, extra: &[&str]| mesh_example_into(&dir, name, extra);
    let (a, fa) = run("preset", &["--authors-mesher"]);
    let flags = [
        "--small-tets",
        "authors",
        "--no-crease-flips",
        "--no-manifold",
    ];
    let (b, fb) = run("flags", &flags);
    assert!(a.status.success(), "{}", String::from_utf8_lossy(&a.stderr));
    assert!(b.status.success(), "{}", String::from_utf8_lossy(&b.stderr));
    assert!(std::fs::read(&fa).unwrap() == std::fs::read(&fb).unwrap());
    // It differs from the default (flips, manifold repair) on this CAD part.
    let (c, fc) = run("default", &[]);
    assert!(c.status.success());
    assert!(std::fs::read(&fa).unwrap() != std::fs::read(&fc).unwrap());
    // It fixes the small-tet rule: another one with it is a usage error.
    let (o, _) = run("both", &["--authors-mesher", "--small-tets", "both"]);
    assert_eq!(o.status.code(), Some(2));
    // A negative or non-finite weld tolerance is a clear error.
    for bad in ["-1e-10", "nan", "inf"] {
        let (o, _) = run("weld", &["--weld", bad]);
        assert_eq!(o.status.code(), Some(2), "--weld {bad}");
        let err = String::from_utf8_lossy(&o.stderr);
        assert!(err.contains("weld"), "--weld {bad}: {err}");
    }
    std::fs::remove_dir_all(&dir).ok();
}
