//! Training on the `wgpu` backend: a few epochs of `configs/smoke.toml` give the same losses as
//! on the CPU, and a checkpoint written on the CPU resumes on the GPU. See
//! `ponq-model/tests/wgpu_backend.rs` for how the adapter is found (lavapipe in CI).
#![cfg(feature = "wgpu")]

use std::path::PathBuf;

use ponq_model::backend::{self, BackendKind};
use ponq_train::config::TrainConfig;
use ponq_train::data::sphere_shape;
use ponq_train::train::{RunOptions, run_with_shapes};

fn gpu() -> Option<burn::prelude::Device> {
    match backend::device(BackendKind::Wgpu) {
        Ok(d) => Some(d),
        Err(e) => {
            assert!(
                std::env::var_os("PONQ_REQUIRE_WGPU").is_none(),
                "PONQ_REQUIRE_WGPU is set but the wgpu device does not work: {e}"
            );
            eprintln!("skipped: {e}");
            None
        }
    }
}

fn tmp(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("ponq-wgpu-train-{name}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    d
}

#[test]
fn wgpu_training_matches_flex_and_checkpoints_cross_backends() {
    let Some(gpu) = gpu() else { return };
    let path = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../configs/smoke.toml");
    let mut cfg = TrainConfig::load(&path).unwrap();
    cfg.train.mesh_validate_every = 0;
    cfg.train.epochs = 3;
    let train = vec![
        sphere_shape("a", 8, [0.1, 0.0, -0.1], 0.5, 3000),
        sphere_shape("b", 8, [-0.2, 0.1, 0.0], 0.6, 3000),
    ];
    let val = vec![sphere_shape("v", 8, [0.0, 0.1, 0.0], 0.55, 3000)];
    let dir = tmp("runs");
    let net = cfg.model.net();
    let init = dir.join("init.bpk");
    ponq_model::weights::save(&net.init(&backend::cpu()), &net, &init).unwrap();
    cfg.train.init_from = Some(init);
    let opts = |out: &str, device: burn::prelude::Device, resume: bool| RunOptions {
        out: dir.join(out),
        resume,
        device,
        quiet: true,
        kernels: ponq_model::Kernels::default(),
        extra_devices: Vec::new(),
    };
    let flex = run_with_shapes(&cfg, &train, &val, &opts("flex", backend::cpu(), false)).unwrap();
    let wgpu = run_with_shapes(&cfg, &train, &val, &opts("wgpu", gpu.clone(), false)).unwrap();
    assert_eq!(flex.step_losses.len(), wgpu.step_losses.len());
    for (i, (a, b)) in wgpu.step_losses.iter().zip(&flex.step_losses).enumerate() {
        assert!(
            (a - b).abs() <= 1e-3 * b.abs(),
            "step {i}: wgpu {a} vs flex {b}"
        );
    }
    // Two epochs on the CPU, the third resumed on the GPU: the same as all on the CPU.
    cfg.train.epochs = 2;
    run_with_shapes(&cfg, &train, &val, &opts("mixed", backend::cpu(), false)).unwrap();
    cfg.train.epochs = 3;
    let rest = run_with_shapes(&cfg, &train, &val, &opts("mixed", gpu, true)).unwrap();
    assert_eq!(rest.epochs_done, 3);
    let tail = &flex.step_losses[flex.step_losses.len() - rest.step_losses.len()..];
    for (i, (a, b)) in rest.step_losses.iter().zip(tail).enumerate() {
        assert!(
            (a - b).abs() <= 1e-3 * b.abs(),
            "resumed step {i}: {a} vs {b}"
        );
    }
    std::fs::remove_dir_all(&dir).ok();
}
