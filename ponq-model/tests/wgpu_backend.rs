//! The network on the `wgpu` backend against the CPU (`flex`): the same weights (saved on one
//! backend, loaded on the other) give the same outputs and the same gradient for every
//! parameter. Runs on any Vulkan / Metal / DX12 adapter; CI runs it on Mesa's software Vulkan
//! driver (lavapipe). Without an adapter the tests say so and pass, unless
//! `PONQ_REQUIRE_WGPU` is set (CI sets it).
#![cfg(feature = "wgpu")]

use burn::module::{Module, ModuleVisitor, Param};
use burn::optim::GradientsParams;
use burn::prelude::*;
use ponq_model::backend::{BackendKind, cpu, device};
use ponq_model::{GridFrame, PonqNet, PonqNetConfig, PonqOutput, weights};

/// The wgpu device, or `None` (and a message) when no adapter answers.
fn gpu() -> Option<Device> {
    match device(BackendKind::Wgpu) {
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

fn values<const D: usize>(t: Tensor<D>) -> Vec<f32> {
    t.into_data().try_to_vec::<f32>().expect("f32")
}

fn input(n: usize, d: &Device) -> Tensor<5> {
    let m = n + 1;
    let v: Vec<f32> = (0..m * m * m)
        .map(|i| ((i * 7919) % 1013) as f32 / 1013.0 - 0.45)
        .collect();
    Tensor::<1>::from_data(TensorData::new(v, [m * m * m]), d).reshape([1, 1, m, m, m])
}

fn outputs(o: &PonqOutput) -> Vec<Vec<f32>> {
    vec![
        values(o.points.clone()),
        values(o.vstars.clone()),
        values(o.normals.clone()),
        values(o.cholesky.clone()),
        values(o.occupancy.clone()),
    ]
}

fn loss(o: &PonqOutput) -> Tensor<1> {
    o.points.clone().sin().sum()
        + (o.normals.clone() * o.normals.clone()).sum() * 0.3
        + o.cholesky.clone().cos().sum() * 0.2
        + o.occupancy.clone().sum()
        + o.vstars.clone().sum() * 0.1
}

struct Grads<'a> {
    grads: &'a GradientsParams,
    out: Vec<Vec<f32>>,
}

impl ModuleVisitor for Grads<'_> {
    fn visit_float<const D: usize>(&mut self, p: &Param<Tensor<D>>) {
        self.out
            .push(self.grads.get::<D>(p.id).map(values).unwrap_or_default());
    }
}

fn gradients(net: &PonqNet, x: Tensor<5>, frame: &GridFrame) -> Vec<Vec<f32>> {
    let g = loss(&net.forward(x, frame)).backward();
    let gp = GradientsParams::from_grads(g, net);
    let mut v = Grads {
        grads: &gp,
        out: Vec::new(),
    };
    net.visit(&mut v);
    v.out
}

fn close(a: &[f32], b: &[f32], what: &str) {
    assert_eq!(a.len(), b.len(), "{what}");
    let scale = b.iter().fold(1e-6f32, |m, v| m.max(v.abs()));
    let worst = a
        .iter()
        .zip(b)
        .map(|(x, y)| (x - y).abs())
        .fold(0.0f32, f32::max);
    assert!(
        worst <= 1e-4 * scale,
        "{what}: differs by {worst} (scale {scale})"
    );
}

#[test]
fn wgpu_matches_flex_forward_and_gradients() {
    let Some(gpu) = gpu() else { return };
    let cfg = PonqNetConfig::new()
        .with_width(8)
        .with_points_per_cell(2)
        .with_encoder_layers(2)
        .with_decoder_blocks(1);
    let dir = std::env::temp_dir().join(format!("ponq-wgpu-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    // Weights made on the CPU, loaded on both backends (a checkpoint crosses backends).
    weights::save(&cfg.init(&cpu()), &cfg, &dir.join("net.bpk")).unwrap();
    let (flex_net, _) = weights::load(&dir.join("net.bpk"), &cpu()).unwrap();
    let (gpu_net, _) = weights::load(&dir.join("net.bpk"), &gpu).unwrap();
    let frame = GridFrame::crop(12, [1, 2, 0]);
    let a = outputs(&flex_net.forward(input(6, &cpu()), &frame));
    let b = outputs(&gpu_net.forward(input(6, &gpu), &frame));
    for (i, (x, y)) in b.iter().zip(&a).enumerate() {
        close(x, y, &format!("output {i}"));
    }
    // Gradients of every parameter, with autodiff on both.
    let (flex_ad, _) = weights::load(&dir.join("net.bpk"), &cpu().autodiff()).unwrap();
    let (gpu_ad, _) = weights::load(&dir.join("net.bpk"), &gpu.clone().autodiff()).unwrap();
    let ga = gradients(&flex_ad, input(6, &cpu().autodiff()), &frame);
    let gb = gradients(&gpu_ad, input(6, &gpu.autodiff()), &frame);
    assert_eq!(ga.len(), gb.len());
    for (i, (x, y)) in gb.iter().zip(&ga).enumerate() {
        assert!(!y.is_empty(), "parameter {i} has no gradient");
        close(x, y, &format!("gradient of parameter {i}"));
    }
    // Weights saved on the GPU load on the CPU unchanged.
    weights::save(&gpu_net, &cfg, &dir.join("back.bpk")).unwrap();
    let (back, _) = weights::load(&dir.join("back.bpk"), &cpu()).unwrap();
    let c = outputs(&back.forward(input(6, &cpu()), &frame));
    assert_eq!(c, a, "a round trip through the GPU changes no weight");
    std::fs::remove_dir_all(&dir).ok();
}
