//! The network: parameter count, output shapes and parameterisation, conversion to a PoNQ,
//! tiling paste, and the weights round trip.

use burn::module::Module;
use burn::prelude::*;
use ponq_model::{GridFrame, PonqNetConfig, Prediction, backend};

fn tiny() -> PonqNetConfig {
    PonqNetConfig::new()
        .with_width(8)
        .with_points_per_cell(2)
        .with_encoder_layers(1)
        .with_decoder_blocks(1)
}

fn ramp(n: usize, device: &Device) -> Tensor<5> {
    let m = n + 1;
    let data: Vec<f32> = (0..m * m * m)
        .map(|i| {
            let (x, y, z) = (i / (m * m), (i / m) % m, i % m);
            let p = [x, y, z].map(|c| -1.0 + 2.0 * c as f32 / n as f32);
            (p[0] * p[0] + p[1] * p[1] + p[2] * p[2]).sqrt() - 0.6
        })
        .collect();
    Tensor::<1>::from_data(TensorData::new(data, [m * m * m]), device).reshape([1, 1, m, m, m])
}

#[test]
fn paper_config_has_the_papers_parameter_count() {
    let device = backend::cpu();
    let net = PonqNetConfig::new().init(&device);
    assert_eq!(net.num_params(), 2_716_861);
    assert_eq!(net.points_per_cell(), 4);
}

#[test]
fn output_shapes_and_parameterisation() {
    let device = backend::cpu();
    let net = tiny().init(&device);
    let n = 6;
    let frame = GridFrame::whole(n);
    let out = net.forward(ramp(n, &device), &frame);
    assert_eq!(out.cells, [n, n, n]);
    assert_eq!(out.points.dims(), [1, n * n * n, 2, 3]);
    assert_eq!(out.vstars.dims(), [1, n * n * n, 2, 3]);
    assert_eq!(out.normals.dims(), [1, n * n * n, 2, 3]);
    assert_eq!(out.cholesky.dims(), [1, n * n * n, 2, 6]);
    assert_eq!(out.occupancy.dims(), [1, n * n * n]);
    let pred = Prediction::from_output(&out, 0).expect("read back");
    // Occupancy is a probability.
    assert!(pred.occupancy.iter().all(|&o| o > 0.0 && o < 1.0));
    // Points are offsets of at most a few cells from their cell centre (fresh weights give
    // small heads); the cell centre of cell (i,j,k) is -1 + (i + 0.5) * 2/n.
    for c in 0..pred.num_cells() {
        let cc = pred.cell_coords(c);
        for k in 0..2 {
            for a in 0..3 {
                let centre = -1.0 + (cc[a] as f64 + 0.5) * 2.0 / n as f64;
                let p = f64::from(pred.points[(c * 2 + k) * 3 + a]);
                assert!(
                    (p - centre).abs() < 3.0 * 2.0 / n as f64,
                    "cell {c} point {k}: {p} vs {centre}"
                );
            }
        }
    }
    // Converting every cell gives 2 points per cell whose quadric vanishes at v*.
    let all: Vec<usize> = (0..pred.num_cells()).collect();
    let (ponq, cell_of) = pred.to_ponq(&all).expect("finite");
    assert_eq!(ponq.len(), 2 * n * n * n);
    assert_eq!(cell_of.len(), ponq.len());
    let vs = ponq.vstars.as_ref().expect("stored v*");
    for (q, v) in ponq.quadrics.iter().zip(vs) {
        assert!(q.eval(*v).abs() < 1e-9);
        // A = U U^T is positive semi-definite.
        let e = q.a.symmetric_eigenvalues();
        assert!(e.iter().all(|&l| l > -1e-9), "{e:?}");
    }
}

#[test]
fn crop_frame_shifts_points_by_the_crop_origin() {
    let device = backend::cpu();
    let net = tiny().init(&device);
    let n = 4;
    let input = ramp(n, &device);
    let a = Prediction::from_output(
        &net.forward(input.clone(), &GridFrame::crop(8, [0, 0, 0])),
        0,
    )
    .unwrap();
    let b =
        Prediction::from_output(&net.forward(input, &GridFrame::crop(8, [2, 0, 1])), 0).unwrap();
    let cell = 2.0 / 8.0;
    for i in 0..a.points.len() / 3 {
        assert!((b.points[3 * i] - a.points[3 * i] - 2.0 * cell).abs() < 1e-5);
        assert!((b.points[3 * i + 1] - a.points[3 * i + 1]).abs() < 1e-5);
        assert!((b.points[3 * i + 2] - a.points[3 * i + 2] - cell).abs() < 1e-5);
    }
}

#[test]
fn paste_copies_tiles_to_their_place() {
    let device = backend::cpu();
    let net = tiny().init(&device);
    let tile =
        Prediction::from_output(&net.forward(ramp(4, &device), &GridFrame::whole(4)), 0).unwrap();
    let mut whole = Prediction::zeros([6, 6, 6], 2);
    whole
        .paste(&tile, [1, 1, 1], [3, 4, 4], [2, 1, 0])
        .expect("inside");
    for i in 0..6 {
        for j in 0..6 {
            for k in 0..6 {
                let dst = (i * 6 + j) * 6 + k;
                let inside = (3..5).contains(&i) && (2..5).contains(&j) && (1..4).contains(&k);
                if inside {
                    let src = ((i - 2) * 4 + (j - 1)) * 4 + k;
                    assert_eq!(whole.occupancy[dst], tile.occupancy[src]);
                    assert_eq!(
                        whole.cholesky[dst * 12..dst * 12 + 12],
                        tile.cholesky[src * 12..src * 12 + 12]
                    );
                } else {
                    assert_eq!(whole.occupancy[dst], 0.0);
                }
            }
        }
    }
    assert!(whole.paste(&tile, [0, 0, 0], [4, 4, 4], [3, 3, 3]).is_err());
}

#[test]
fn kept_cells_respects_threshold_and_close_mask() {
    let mut p = Prediction::zeros([2, 1, 1], 1);
    p.occupancy = vec![0.9, 0.7];
    assert_eq!(p.kept_cells(0.5, None).unwrap(), vec![0, 1]);
    assert_eq!(p.kept_cells(0.8, None).unwrap(), vec![0]);
    assert_eq!(p.kept_cells(0.5, Some(&[false, true])).unwrap(), vec![1]);
    assert!(p.kept_cells(0.5, Some(&[true])).is_err());
}

#[test]
fn weights_round_trip_exactly() {
    let device = backend::cpu();
    let cfg = tiny();
    let net = cfg.init(&device);
    let dir = std::env::temp_dir().join(format!("ponq-model-weights-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let path = dir.join("net.bpk");
    ponq_model::weights::save(&net, &cfg, &path).expect("save");
    let (back, cfg2) = ponq_model::weights::load(&path, &device).expect("load");
    assert_eq!(cfg2, cfg);
    let x = ramp(4, &device);
    let a = Prediction::from_output(&net.forward(x.clone(), &GridFrame::whole(4)), 0).unwrap();
    let b = Prediction::from_output(&back.forward(x, &GridFrame::whole(4)), 0).unwrap();
    assert_eq!(a, b);
    // Errors, not panics, on missing or corrupt files.
    assert!(ponq_model::weights::load(&dir.join("missing.bpk"), &device).is_err());
    std::fs::write(dir.join("bad.bpk"), b"not a burnpack").unwrap();
    std::fs::copy(dir.join("net.json"), dir.join("bad.json")).unwrap();
    assert!(ponq_model::weights::load(&dir.join("bad.bpk"), &device).is_err());
    std::fs::remove_dir_all(&dir).ok();
}

fn host(t: Tensor<4>) -> Vec<f32> {
    t.into_data()
        .convert::<f32>()
        .try_to_vec::<f32>()
        .expect("f32")
}

/// Max |a - b| over max |b|.
fn rel(a: &[f32], b: &[f32]) -> f32 {
    assert_eq!(a.len(), b.len());
    let scale = b.iter().fold(1e-12f32, |m, v| m.max(v.abs()));
    a.iter()
        .zip(b)
        .map(|(x, y)| (x - y).abs())
        .fold(0.0, f32::max)
        / scale
}

#[test]
fn widened_network_computes_the_same_function() {
    let device = backend::cpu();
    let config = PonqNetConfig::new()
        .with_width(8)
        .with_points_per_cell(2)
        .with_encoder_layers(2)
        .with_decoder_blocks(2);
    let n = 7;
    let frame = GridFrame::whole(n);
    for kernels in [ponq_model::Kernels::Stock, ponq_model::Kernels::Fast] {
        let net = config.init(&device).with_kernels(kernels);
        let (wide, wide_config) = ponq_model::widen::widen(&net, &config, 13, 5).expect("widen");
        assert_eq!(wide_config.width, 13);
        assert_eq!(wide.kernels(), kernels);
        assert_eq!(wide.num_params(), wide_config.init(&device).num_params());
        assert!(wide.num_params() > net.num_params());
        let a = net.forward(ramp(n, &device), &frame);
        let b = wide.forward(ramp(n, &device), &frame);
        for (name, x, y) in [
            ("points", a.points, b.points),
            ("normals", a.normals, b.normals),
            ("cholesky", a.cholesky, b.cholesky),
            ("vstars", a.vstars, b.vstars),
        ] {
            let e = rel(&host(y), &host(x));
            assert!(e < 1e-5, "{kernels:?}: {name} differs by {e}");
        }
        let e = rel(
            &host(b.occupancy.reshape([1, 1, 1, n * n * n])),
            &host(a.occupancy.reshape([1, 1, 1, n * n * n])),
        );
        assert!(e < 1e-5, "{kernels:?}: occupancy differs by {e}");
    }
    // Same width: the same network; narrower: an error.
    let net = config.init(&device);
    let (same, _) = ponq_model::widen::widen(&net, &config, 8, 1).expect("same width");
    let a = host(net.forward(ramp(n, &device), &frame).points);
    let b = host(same.forward(ramp(n, &device), &frame).points);
    assert_eq!(a, b);
    assert!(ponq_model::widen::widen(&net, &config, 7, 1).is_err());
}
