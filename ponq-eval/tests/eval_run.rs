//! `ponq-eval run` on a tiny split against direct metric calls, with the refined rows; how its
//! inputs are found;
//! `ponq-eval compare`'s sharp-edge angle.

use std::path::PathBuf;
use std::process::Command;

use ponq_model::{PonqNetConfig, backend};

fn tmp(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("ponq-eval-{name}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    d
}

#[test]
fn eval_run_matches_direct_metric_calls() {
    let d = tmp("eval");
    let data = d.join("data");
    // Shapes in sub-folders are found too.
    std::fs::create_dir_all(data.join("cad")).unwrap();
    let root = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("..");
    std::fs::copy(root.join("examples/csg.obj"), data.join("cad/csg.obj")).unwrap();
    std::fs::write(d.join("split.txt"), "csg\nnot_here\n").unwrap();
    // A tiny network keeps the test fast; the numbers checked are MC's and the summary's.
    let dev = backend::cpu();
    let cfg = PonqNetConfig::new()
        .with_width(8)
        .with_points_per_cell(2)
        .with_encoder_layers(1)
        .with_decoder_blocks(1);
    ponq_model::weights::save(&cfg.init(&dev), &cfg, &d.join("net.bpk")).unwrap();
    let report = d.join("report");
    let run = || {
        Command::new(env!("CARGO_BIN_EXE_ponq-eval"))
            .args([
                "run",
                "--res",
                "8",
                "--samples",
                "3000",
                "--renders",
                "1",
                "--jobs",
                "1",
                "-q",
                "--data",
            ])
            .arg(&data)
            .arg("--split")
            .arg(d.join("split.txt"))
            .arg("--model")
            .arg(d.join("net.bpk"))
            .arg("-o")
            .arg(&report)
            .output()
            .unwrap()
    };
    let o = run();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let csv = std::fs::read_to_string(report.join("per_shape.csv")).unwrap();
    let rows: Vec<ponq_eval::Row> = csv
        .lines()
        .skip(1)
        .map(|l| ponq_eval::Row::parse(l).unwrap())
        .collect();
    assert_eq!(rows.len(), 2, "PoNQ and MC for one shape");
    let mc = rows.iter().find(|r| r.method == "MC").unwrap();
    // Direct calls: normalise, SDF grid, marching cubes, metrics with the same samples.
    let gt = ponq_mesh::io::read_mesh(data.join("cad/csg.obj")).unwrap();
    let gt = ponq_data::normalize::Normalization::of(&gt)
        .unwrap()
        .apply_mesh(&gt);
    let g = ponq_data::sdf::MeshSdf::new(&gt)
        .unwrap()
        .grid(8, |_| {})
        .unwrap();
    let v: Vec<f64> = g.values.iter().map(|&x| f64::from(x)).collect();
    let m = ponq_mesh::marching_cubes::marching_cubes(&v, [9; 3], [-1.0; 3], [1.0; 3]).unwrap();
    let opts = ponq_mesh::metrics::MetricOptions {
        surface_samples: 3000,
        edge_samples: 3000,
        check_validity: false,
        ..Default::default()
    };
    let want = ponq_mesh::metrics::compare(&m, &gt, &opts);
    let close = |a: f64, b: f64| (a - b).abs() <= 1e-9 * (1.0 + b.abs());
    assert!(
        close(mc.cd, want.cd_x1e5) && close(mc.f1, want.f1) && close(mc.nc, want.nc),
        "{mc:?} vs {want:?}"
    );
    assert!(
        close(mc.ecd, want.ecd_x1e2) && close(mc.ef1, want.ef1),
        "{mc:?} vs {want:?}"
    );
    assert_eq!((mc.vertices, mc.faces), (m.vertices.len(), m.faces.len()));
    assert_eq!(mc.watertight, ponq_mesh::validity::check(&m).is_valid());
    let ponq = rows.iter().find(|r| r.method == "PoNQ").unwrap();
    assert!(ponq.faces == 0 || ponq.watertight, "{ponq:?}");
    // The summary's MC line shows the same numbers (one shape: mean = value).
    let summary = std::fs::read_to_string(report.join("summary.md")).unwrap();
    let line = summary.lines().find(|l| l.starts_with("| MC |")).unwrap();
    assert!(
        line.contains(&format!("| {:.3} | {:.3} | {:.3} |", mc.cd, mc.f1, mc.nc)),
        "{line}"
    );
    let rep = std::fs::read_to_string(report.join("report.md")).unwrap();
    assert!(rep.contains("not_here"), "missing ids are listed");
    assert!(report.join("renders/csg_9.png").is_file());
    // The metric charts (one resolution: one point per method) are drawn and linked.
    assert!(std::fs::metadata(report.join("charts.png")).unwrap().len() > 1000);
    assert!(rep.contains("](charts.png)"), "{rep}");
    // Resumable: a second run reuses the rows (same file content).
    let o = run();
    assert!(o.status.success());
    assert_eq!(
        std::fs::read_to_string(report.join("per_shape.csv")).unwrap(),
        csv
    );
    std::fs::remove_dir_all(&d).ok();
}

#[test]
fn eval_inputs_are_found_recursively_and_ids_must_be_unique() {
    let d = tmp("inputs");
    std::fs::create_dir_all(d.join("a/b")).unwrap();
    std::fs::create_dir_all(d.join("c")).unwrap();
    for f in ["a/one.obj", "a/b/two.ply", "c/three.npz", "c/notes.txt"] {
        std::fs::write(d.join(f), "").unwrap();
    }
    std::fs::write(d.join("split.txt"), "one\nthree\nfour\n").unwrap();
    let (files, missing) = ponq_eval::inputs(&d, Some(&d.join("split.txt"))).unwrap();
    let ids: Vec<&str> = files.iter().map(|f| f.0.as_str()).collect();
    assert_eq!(ids, ["one", "three"]);
    assert_eq!(missing, ["four"]);
    let (all, _) = ponq_eval::inputs(&d, None).unwrap();
    assert_eq!(all.len(), 3);
    std::fs::write(d.join("c/one.stl"), "").unwrap();
    let err = ponq_eval::inputs(&d, None).unwrap_err().to_string();
    assert!(err.contains("two shapes with the id \"one\""), "{err}");
    std::fs::remove_dir_all(&d).ok();
}

/// Two models in one report (`--name`, `--no-mc` for the second), and per-group tables (CAD /
/// free-form sub-folders) with means and medians.
#[test]
fn eval_run_compares_models_and_groups() {
    let d = tmp("groups");
    let data = d.join("data");
    std::fs::create_dir_all(data.join("cad")).unwrap();
    std::fs::create_dir_all(data.join("freeform")).unwrap();
    let root = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("..");
    std::fs::copy(root.join("examples/csg.obj"), data.join("cad/csg.obj")).unwrap();
    std::fs::copy(
        root.join("examples/example001.obj"),
        data.join("freeform/e1.obj"),
    )
    .unwrap();
    let dev = backend::cpu();
    let cfg = PonqNetConfig::new()
        .with_width(8)
        .with_points_per_cell(2)
        .with_encoder_layers(1)
        .with_decoder_blocks(1);
    ponq_model::weights::save(&cfg.init(&dev), &cfg, &d.join("a.bpk")).unwrap();
    ponq_model::weights::save(&cfg.init(&dev), &cfg, &d.join("b.bpk")).unwrap();
    let report = d.join("report");
    let run = |model: &str, extra: &[&str]| {
        let o = Command::new(env!("CARGO_BIN_EXE_ponq-eval"))
            .args([
                "run",
                "--res",
                "8",
                "--samples",
                "2000",
                "--renders",
                "0",
                "-q",
            ])
            .arg("--data")
            .arg(&data)
            .arg("--model")
            .arg(d.join(model))
            .arg("-o")
            .arg(&report)
            .args(extra)
            .output()
            .unwrap();
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    };
    run("a.bpk", &[]);
    run("b.bpk", &["--name", "other", "--no-mc"]);
    let rows = ponq_eval::read_rows(&report).unwrap();
    let methods: std::collections::BTreeSet<&str> =
        rows.iter().map(|r| r.method.as_str()).collect();
    assert_eq!(
        methods.into_iter().collect::<Vec<_>>(),
        ["MC", "PoNQ", "other"]
    );
    assert_eq!(rows.len(), 6, "three methods for two shapes");
    let summary = std::fs::read_to_string(report.join("summary.md")).unwrap();
    assert!(summary.contains("### cad (mean / median)"), "{summary}");
    assert!(
        summary.contains("### freeform (mean / median)"),
        "{summary}"
    );
    assert!(summary.contains("| other | 9^3 | 1 |"), "{summary}");
    // A name that is not a file-name component is refused.
    let o = Command::new(env!("CARGO_BIN_EXE_ponq-eval"))
        .args(["run", "--res", "8", "--name", "a/b", "--data"])
        .arg(&data)
        .arg("-o")
        .arg(&report)
        .output()
        .unwrap();
    assert!(!o.status.success());
    assert!(String::from_utf8_lossy(&o.stderr).contains("--name"));
    std::fs::remove_dir_all(&d).ok();
}

/// A closed prism over the polygon of the given angles (degrees) on the unit circle, z in
/// [-0.5, 0.5], outward-oriented, as OBJ text.
fn prism_obj(angles: &[f64]) -> String {
    let n = angles.len();
    let mut s = String::new();
    for z in [-0.5, 0.5] {
        for a in angles {
            let r = a.to_radians();
            s += &format!("v {} {} {z}\n", r.cos(), r.sin());
        }
    }
    // OBJ indices are 1-based: bottom ring 1..=n, top ring n+1..=2n.
    let (b, t) = (|i: usize| i % n + 1, |i: usize| i % n + 1 + n);
    for i in 1..n - 1 {
        s += &format!("f {} {} {}\n", b(0), b(i + 1), b(i));
        s += &format!("f {} {} {}\n", t(0), t(i), t(i + 1));
    }
    for i in 0..n {
        s += &format!("f {} {} {}\n", b(i), b(i + 1), t(i + 1));
        s += &format!("f {} {} {}\n", b(i), t(i + 1), t(i));
    }
    s
}

/// `compare --sharp-angle` decides which edges count: a hexagonal prism (vertical edges of 60
/// degrees) against the rectangle prism on four of its corners (all edges 90 degrees). Below
/// 60 degrees the truth has six vertical sharp edges and the prediction four of them; above,
/// the truth has none and the prediction's four are extra, so the edge metrics differ. Bad
/// angles are errors.
#[test]
fn compare_sharp_angle_sets_the_edges_that_count() {
    let d = tmp("sharp-angle");
    let (gt, pred) = (d.join("hexagon.obj"), d.join("rectangle.obj"));
    std::fs::write(&gt, prism_obj(&[0.0, 60.0, 120.0, 180.0, 240.0, 300.0])).unwrap();
    std::fs::write(&pred, prism_obj(&[0.0, 60.0, 180.0, 240.0])).unwrap();
    let compare = |extra: &[&str]| {
        Command::new(env!("CARGO_BIN_EXE_ponq-eval"))
            .args([
                "compare",
                "--pred-frame",
                "gt",
                "--samples",
                "20000",
                "--json",
            ])
            .arg(&pred)
            .arg(&gt)
            .args(extra)
            .output()
            .unwrap()
    };
    let edge_metrics = |extra: &[&str]| -> (f64, f64) {
        let o = compare(extra);
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
        let out = String::from_utf8_lossy(&o.stdout).to_string();
        let field = |k: &str| -> f64 {
            let rest = &out[out.find(&format!("\"{k}\":")).unwrap() + k.len() + 3..];
            rest[..rest.find([',', '}']).unwrap()].parse().unwrap()
        };
        (field("ecd_x1e2"), field("ef1"))
    };
    let default = edge_metrics(&[]);
    assert_eq!(default, edge_metrics(&["--sharp-angle", "30"]));
    assert_eq!(default, edge_metrics(&["--sharp-angle", "45"]));
    let above = edge_metrics(&["--sharp-angle", "75"]);
    assert_ne!(default, above);
    // Above 60 degrees the prediction's vertical edges have no counterpart: more of its
    // edge samples are far from the truth's.
    assert!(above.0 > default.0, "ECD {} -> {}", default.0, above.0);
    for bad in ["0", "180", "-5", "nan"] {
        let o = compare(&[&format!("--sharp-angle={bad}")]);
        assert_eq!(o.status.code(), Some(2), "--sharp-angle {bad}");
        assert!(String::from_utf8_lossy(&o.stderr).contains("--sharp-angle"));
    }
    let _ = std::fs::remove_dir_all(&d);
}

#[test]
fn eval_run_reports_refined_rows_beside_the_network() {
    let d = tmp("refine");
    let data = d.join("data");
    std::fs::create_dir_all(&data).unwrap();
    let root = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("..");
    std::fs::copy(root.join("examples/csg.obj"), data.join("csg.obj")).unwrap();
    let report = d.join("report");
    let o = Command::new(env!("CARGO_BIN_EXE_ponq-eval"))
        .args([
            "run",
            "--res",
            "24",
            "--samples",
            "20000",
            "--renders",
            "0",
            "--refine",
            "-q",
            "--data",
        ])
        .arg(&data)
        .arg("-o")
        .arg(&report)
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let csv = std::fs::read_to_string(report.join("per_shape.csv")).unwrap();
    let header: Vec<&str> = csv.lines().next().unwrap().split(',').collect();
    let col = |name: &str| header.iter().position(|h| *h == name).unwrap();
    let row = |method: &str| -> Vec<String> {
        csv.lines()
            .map(|l| l.split(',').map(String::from).collect::<Vec<_>>())
            .find(|r| r[col("method")] == method)
            .unwrap_or_else(|| panic!("no {method} row in {csv}"))
    };
    let (net, refined) = (row("PoNQ"), row("PoNQ+refine"));
    let _ = row("MC");
    let num = |r: &[String], c: &str| r[col(c)].parse::<f64>().unwrap();
    // The exact grid of a CAD part: the refined mesh is valid, closer to the part and its
    // edges sharper; its time includes the network's run, which both rows share.
    assert_eq!(refined[col("watertight")], "true");
    assert!(num(&refined, "cd_x1e5") < num(&net, "cd_x1e5"), "{csv}");
    assert!(num(&refined, "ef1") > num(&net, "ef1"), "{csv}");
    assert!(num(&refined, "seconds") > 0.0 && num(&net, "seconds") > 0.0);
    let summary = std::fs::read_to_string(report.join("summary.md")).unwrap();
    assert!(summary.contains("| PoNQ+refine |"), "{summary}");
}
