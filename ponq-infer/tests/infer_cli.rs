//! `ponq-infer` end to end (shipped model), tiling exactness, bad inputs, the built-in model.

use std::path::{Path, PathBuf};
use std::process::Command;

use ponq_infer::{Frame, predict_tiled};
use ponq_mesh::io::npy::{Grid3, write_npy_grid_f32};
use ponq_model::{PonqNetConfig, backend};

fn tmp(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("ponq-infer-{name}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    d
}

/// SDF of a box of half-sizes `h` rotated about z by `angle`, on `n` cells over `[-1,1]^3`.
fn box_grid(n: usize, h: [f64; 3], angle: f64) -> Grid3 {
    let m = n + 1;
    let (c, s) = (angle.cos(), angle.sin());
    let mut v = Vec::with_capacity(m * m * m);
    for i in 0..m {
        for j in 0..m {
            for k in 0..m {
                let p = [i, j, k].map(|t| -1.0 + 2.0 * t as f64 / n as f64);
                let q = [c * p[0] + s * p[1], -s * p[0] + c * p[1], p[2]];
                let d: [f64; 3] = std::array::from_fn(|a| q[a].abs() - h[a]);
                let out = d.iter().map(|x| x.max(0.0).powi(2)).sum::<f64>().sqrt();
                let inside = d.iter().cloned().fold(f64::MIN, f64::max).min(0.0);
                v.push(out + inside);
            }
        }
    }
    Grid3::new([m; 3], v).unwrap()
}

fn infer_exe() -> &'static str {
    env!("CARGO_BIN_EXE_ponq-infer")
}

#[test]
fn infer_reconstructs_a_valid_box_with_the_shipped_model() {
    let d = tmp("box");
    let g = box_grid(16, [0.5, 0.35, 0.4], 0.3);
    write_npy_grid_f32(d.join("box.npy"), &g).unwrap();
    let mut vertices = Vec::new();
    for extra in [
        vec![],
        vec!["--lite"],
        vec!["--tile", "5"],
        vec!["--merge-smooth", "0"],
        vec!["--small-tets-both-ways"],
        vec!["--small-tets", "authors"],
    ] {
        let o = Command::new(infer_exe())
            .arg(d.join("box.npy"))
            .arg("-o")
            .arg(d.join("box.obj"))
            .args(&extra)
            .output()
            .unwrap();
        assert!(
            o.status.success(),
            "{extra:?}: {}{}",
            String::from_utf8_lossy(&o.stdout),
            String::from_utf8_lossy(&o.stderr)
        );
        let m = ponq_mesh::io::read_mesh(d.join("box.obj")).unwrap();
        let r = ponq_mesh::validity::check(&m);
        assert!(r.is_valid(), "{extra:?}: {r}");
        vertices.push(m.vertices.len());
        // The surface lies near the box: every vertex within 1.5 cells of it.
        let cell = 2.0 / 16.0;
        let (c, s) = (0.3f64.cos(), 0.3f64.sin());
        for v in &m.vertices {
            let q = [c * v[0] + s * v[1], -s * v[0] + c * v[1], v[2]];
            let h = [0.5, 0.35, 0.4];
            let dd: [f64; 3] = std::array::from_fn(|a| q[a].abs() - h[a]);
            let out = dd.iter().map(|x| x.max(0.0).powi(2)).sum::<f64>().sqrt();
            let inside = dd.iter().cloned().fold(f64::MIN, f64::max).min(0.0);
            assert!(
                (out + inside).abs() < 1.5 * cell,
                "{extra:?}: vertex {v:?} at distance {}",
                out + inside
            );
        }
    }
    // By default the flat cells' points are merged: fewer vertices than full PoNQ
    // (`--merge-smooth 0`), more than PoNQ-lite (the box's edge and corner cells keep theirs).
    assert!(
        vertices[1] < vertices[0] && vertices[0] < vertices[3],
        "vertices: default, lite, tiled, full {vertices:?}"
    );
    // --open: boundary edges are allowed, self-intersections and non-manifold edges are not.
    let o = Command::new(infer_exe())
        .arg(d.join("box.npy"))
        .arg("-o")
        .arg(d.join("open.obj"))
        .args(["--open", "0.35"])
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let m = ponq_mesh::io::read_mesh(d.join("open.obj")).unwrap();
    let r = ponq_mesh::validity::check(&m);
    assert!(r.self_intersections == 0 && r.nonmanifold_edges == 0, "{r}");
    std::fs::remove_dir_all(&d).ok();
}

#[test]
fn tiles_give_the_same_prediction_as_one_pass() {
    let dev = backend::cpu();
    let net = PonqNetConfig::new()
        .with_width(8)
        .with_points_per_cell(2)
        .with_encoder_layers(2)
        .with_decoder_blocks(1)
        .init(&dev);
    let g = box_grid(11, [0.5, 0.4, 0.3], 0.2);
    let frame = Frame::of(&g, ([-1.0; 3], [1.0; 3])).unwrap();
    let input: Vec<f32> = g.data.iter().map(|&v| v as f32 * 11.0 / 32.0).collect();
    let (whole, t1) =
        predict_tiled(&net, &input, &frame, 2, 64, false, None, &dev, |_, _| {}).unwrap();
    let (tiled, t2) =
        predict_tiled(&net, &input, &frame, 2, 4, false, None, &dev, |_, _| {}).unwrap();
    assert_eq!(t1, 1);
    assert_eq!(t2, 27);
    for (name, a, b) in [
        ("points", &whole.points, &tiled.points),
        ("cholesky", &whole.cholesky, &tiled.cholesky),
        ("occupancy", &whole.occupancy, &tiled.occupancy),
    ] {
        let worst = a
            .iter()
            .zip(b)
            .map(|(x, y)| (x - y).abs())
            .fold(0f32, f32::max);
        assert!(worst < 1e-4, "{name}: tiles differ by {worst}");
    }
    // Tiles without a needed cell are skipped, the decoders run on needed cells only:
    // needed cells keep their prediction (up to float rounding), the others are zero.
    let cells = 11 * 11 * 11;
    let needed: Vec<bool> = (0..cells).map(|c| c % 11 < 3 && c / 121 < 4).collect();
    let (part, t3) = predict_tiled(
        &net,
        &input,
        &frame,
        2,
        4,
        false,
        Some(&needed),
        &dev,
        |_, _| {},
    )
    .unwrap();
    assert!(t3 < 27 && t3 > 0, "{t3} tiles");
    let p = net.points_per_cell();
    let close = |a: &[f32], b: &[f32]| a.iter().zip(b).all(|(x, y)| (x - y).abs() < 1e-5);
    for (c, &n) in needed.iter().enumerate() {
        let r3 = c * p * 3..(c + 1) * p * 3;
        let r6 = c * p * 6..(c + 1) * p * 6;
        if n {
            assert!(
                close(&part.occupancy[c..c + 1], &tiled.occupancy[c..c + 1]),
                "cell {c}"
            );
            assert!(
                close(&part.points[r3.clone()], &tiled.points[r3.clone()]),
                "cell {c}"
            );
            assert!(
                close(&part.vstars[r3.clone()], &tiled.vstars[r3.clone()]),
                "cell {c}"
            );
            assert!(
                close(&part.normals[r3.clone()], &tiled.normals[r3]),
                "cell {c}"
            );
            assert!(
                close(&part.cholesky[r6.clone()], &tiled.cholesky[r6]),
                "cell {c}"
            );
        } else {
            assert_eq!(part.occupancy[c], 0.0, "cell {c} is not needed");
            assert!(part.points[r3].iter().all(|&v| v == 0.0));
        }
    }
    assert!(
        predict_tiled(
            &net,
            &input,
            &frame,
            2,
            4,
            false,
            Some(&needed[1..]),
            &dev,
            |_, _| {}
        )
        .is_err(),
        "a mask of the wrong size is an error"
    );
    // A margin smaller than the encoder's reach changes the border cells of tiles.
    let (short, _) =
        predict_tiled(&net, &input, &frame, 0, 4, false, None, &dev, |_, _| {}).unwrap();
    assert!(
        whole
            .occupancy
            .iter()
            .zip(&short.occupancy)
            .any(|(x, y)| (x - y).abs() > 1e-4)
    );
}

fn run_infer(args: &[&std::ffi::OsStr]) -> (Option<i32>, String) {
    let o = Command::new(infer_exe()).args(args).output().unwrap();
    (
        o.status.code(),
        String::from_utf8_lossy(&o.stderr).into_owned(),
    )
}

#[test]
fn infer_rejects_bad_input_with_clear_errors() {
    let d = tmp("bad");
    let out = d.join("o.obj");
    let os = |p: &Path| p.as_os_str().to_owned();
    let o = os(&out);
    // Not a .npy file; truncated; wrong rank.
    std::fs::write(d.join("text.npy"), "hello").unwrap();
    let good = box_grid(8, [0.5; 3], 0.0);
    write_npy_grid_f32(d.join("good.npy"), &good).unwrap();
    let bytes = std::fs::read(d.join("good.npy")).unwrap();
    std::fs::write(d.join("trunc.npy"), &bytes[..bytes.len() / 2]).unwrap();
    let cases: Vec<(PathBuf, &str)> = vec![
        (d.join("missing.npy"), "cannot read"),
        (d.join("text.npy"), "cannot read"),
        (d.join("trunc.npy"), "cannot read"),
    ];
    for (p, msg) in &cases {
        let (code, err) = run_infer(&[&os(p), "-o".as_ref(), &o]);
        assert_eq!(code, Some(2), "{p:?}: {err}");
        assert!(err.contains(msg), "{p:?}: {err}");
    }
    // NaN, a grid too small, no sign change, non-cubic cells.
    // The writer refuses NaN, so patch one f32 of the data block (little-endian) by hand.
    let mut nan_bytes = bytes.clone();
    let data_start = nan_bytes.len() - 4 * good.data.len();
    nan_bytes[data_start + 400..data_start + 404].copy_from_slice(&f32::NAN.to_le_bytes());
    std::fs::write(d.join("nan.npy"), &nan_bytes).unwrap();
    nan_bytes[data_start + 400..data_start + 404].copy_from_slice(&f32::NEG_INFINITY.to_le_bytes());
    std::fs::write(d.join("inf.npy"), &nan_bytes).unwrap();
    write_npy_grid_f32(
        d.join("tiny.npy"),
        &Grid3::new([1, 2, 2], vec![-1.0, 1.0, 1.0, 1.0]).unwrap(),
    )
    .unwrap();
    let mut pos = good.clone();
    pos.data.iter_mut().for_each(|v| *v = v.abs() + 0.1);
    write_npy_grid_f32(d.join("pos.npy"), &pos).unwrap();
    for (name, code_want, msg) in [
        ("nan.npy", 2, "is NaN"),
        ("inf.npy", 2, "is -inf"),
        ("tiny.npy", 2, "at least 2 nodes"),
        ("pos.npy", 4, "no sign change"),
    ] {
        let (code, err) = run_infer(&[&os(&d.join(name)), "-o".as_ref(), &o]);
        assert_eq!(code, Some(code_want), "{name}: {err}");
        assert!(err.contains(msg), "{name}: {err}");
    }
    assert!(!out.exists(), "nothing is written on errors");
    let (code, err) = run_infer(&[
        &os(&d.join("good.npy")),
        "-o".as_ref(),
        &o,
        "--bounds".as_ref(),
        "-1,-1,-1,1,1,3".as_ref(),
    ]);
    assert_eq!(code, Some(2));
    assert!(err.contains("not cubes"), "{err}");
    let (code, err) = run_infer(&[
        &os(&d.join("good.npy")),
        "-o".as_ref(),
        &o,
        "--bounds".as_ref(),
        "-1,-1,-1,1,1".as_ref(),
    ]);
    assert_eq!(code, Some(2));
    assert!(err.contains("6 comma-separated"), "{err}");
    let (code, err) = run_infer(&[
        &os(&d.join("good.npy")),
        "-o".as_ref(),
        &o,
        "--merge-smooth".as_ref(),
        "200".as_ref(),
    ]);
    assert_eq!(code, Some(2));
    assert!(err.contains("[0, 180]"), "{err}");
    assert!(!out.exists(), "nothing is written on errors");
    let (code, _) = run_infer(&[
        &os(&d.join("good.npy")),
        "-o".as_ref(),
        &os(&d.join("o.xyz")),
    ]);
    assert_eq!(code, Some(2));
    std::fs::remove_dir_all(&d).ok();
}

#[test]
fn built_in_model_equals_the_shipped_file() {
    let dev = backend::cpu();
    let here = Path::new(env!("CARGO_MANIFEST_DIR")).join("../models/ponq-cpu.bpk");
    let (file_net, file_cfg) = ponq_model::weights::load(&here, &dev).unwrap();
    let (emb_net, emb_cfg) = ponq_infer::shipped::embedded(&dev).unwrap();
    assert_eq!(file_cfg.width, emb_cfg.width);
    assert_eq!(file_cfg.encoder_layers, emb_cfg.encoder_layers);
    let g = box_grid(6, [0.5, 0.4, 0.3], 0.1);
    let frame = Frame::of(&g, ([-1.0; 3], [1.0; 3])).unwrap();
    let input: Vec<f32> = g.data.iter().map(|&v| v as f32 * 6.0 / 32.0).collect();
    let (a, _) = predict_tiled(
        &file_net,
        &input,
        &frame,
        file_cfg.encoder_layers,
        64,
        false,
        None,
        &dev,
        |_, _| {},
    )
    .unwrap();
    let (b, _) = predict_tiled(
        &emb_net,
        &input,
        &frame,
        emb_cfg.encoder_layers,
        64,
        false,
        None,
        &dev,
        |_, _| {},
    )
    .unwrap();
    assert_eq!(a.points, b.points);
    assert_eq!(a.occupancy, b.occupancy);
}

/// `ponq-infer --backend wgpu` on a shipped example: a valid mesh with the vertex count of the
/// CPU run (the floats may differ in the last bits). Skipped without an adapter unless
/// `PONQ_REQUIRE_WGPU` is set.
#[cfg(feature = "wgpu")]
#[test]
fn infer_on_wgpu_gives_the_cpu_mesh() {
    if let Err(e) = ponq_model::backend::device(ponq_model::backend::BackendKind::Wgpu) {
        assert!(
            std::env::var_os("PONQ_REQUIRE_WGPU").is_none(),
            "PONQ_REQUIRE_WGPU is set but the wgpu device does not work: {e}"
        );
        eprintln!("skipped: {e}");
        return;
    }
    let d = tmp("wgpu");
    let example = Path::new(env!("CARGO_MANIFEST_DIR")).join("../examples/csg_sdf_33.npy");
    let mut counts = Vec::new();
    for backend in ["flex", "wgpu"] {
        let out = d.join(format!("{backend}.obj"));
        let o = Command::new(infer_exe())
            .arg(&example)
            .arg("-o")
            .arg(&out)
            .args(["--backend", backend])
            .output()
            .unwrap();
        assert!(
            o.status.success(),
            "{backend}: {}",
            String::from_utf8_lossy(&o.stderr)
        );
        let m = ponq_mesh::io::read_mesh(&out).unwrap();
        assert!(ponq_mesh::validity::check(&m).is_valid(), "{backend}");
        counts.push((m.vertices.len(), m.faces.len()));
    }
    assert_eq!(counts[0], counts[1], "flex vs wgpu");
    std::fs::remove_dir_all(&d).ok();
}

/// `--backend cuda` without the feature (or without a driver) is a clear error, not a panic.
#[test]
fn missing_backends_are_clear_errors() {
    let d = tmp("backend");
    let example = Path::new(env!("CARGO_MANIFEST_DIR")).join("../examples/csg_sdf_33.npy");
    let o = Command::new(infer_exe())
        .arg(&example)
        .arg("-o")
        .arg(d.join("o.obj"))
        .args(["--backend", "cuda"])
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(2), "{err}");
    assert!(err.contains("cuda") || err.contains("CUDA"), "{err}");
    assert!(!err.contains("panicked"), "{err}");
    std::fs::remove_dir_all(&d).ok();
}

#[test]
fn bf16_kernels_give_a_valid_mesh_or_a_clear_error() {
    let d = tmp("bf16");
    let g = box_grid(16, [0.5, 0.35, 0.4], 0.3);
    write_npy_grid_f32(d.join("box.npy"), &g).unwrap();
    let run = |kernels: &str, out: &str| {
        Command::new(infer_exe())
            .arg(d.join("box.npy"))
            .arg("-o")
            .arg(d.join(out))
            .args(["--kernels", kernels])
            .output()
            .unwrap()
    };
    let o = run("fast-bf16", "bf16.obj");
    if !ponq_model::fast::bf16::available() {
        assert_eq!(o.status.code(), Some(2));
        let err = String::from_utf8_lossy(&o.stderr);
        assert!(err.contains("AVX-512 BF16"), "{err}");
        return;
    }
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let f = run("fast", "f32.obj");
    assert!(f.status.success(), "{}", String::from_utf8_lossy(&f.stderr));
    let mb = ponq_mesh::io::read_mesh(d.join("bf16.obj")).unwrap();
    let mf = ponq_mesh::io::read_mesh(d.join("f32.obj")).unwrap();
    let r = ponq_mesh::validity::check(&mb);
    assert!(r.is_valid(), "{r}");
    // The same surface up to bf16 rounding of the network: vertex counts within 10%, and
    // every bf16 vertex within a quarter cell of the f32 mesh's nearest vertex.
    let (nb, nf) = (mb.vertices.len() as f64, mf.vertices.len() as f64);
    assert!((nb - nf).abs() <= 0.1 * nf, "{nb} vs {nf} vertices");
    let cell = 2.0 / 16.0;
    for v in &mb.vertices {
        let near = mf
            .vertices
            .iter()
            .map(|w| (0..3).map(|a| (v[a] - w[a]).powi(2)).sum::<f64>().sqrt())
            .fold(f64::MAX, f64::min);
        assert!(near < 0.25 * cell, "vertex {v:?}: {near} from the f32 mesh");
    }
    std::fs::remove_dir_all(&d).ok();
}
