//! Forward and training-step times of the paper's network on a 33^3 grid and of the CPU
//! variant (`configs/cpu.toml`) on its 17^3-node crops, on the CPU (`flex`) backend.
//!
//! `cargo bench -p ponq-train --bench train_bench` (optional argument: repetitions, default 3).
//! Reference (SPEC 9): PyTorch on these two cores, forward 2.85 s, step ~9.5 s per 33^3 grid.

use std::time::Instant;

use burn::optim::GradientsParams;
use burn::prelude::*;
use ponq_model::PonqNet;
use ponq_train::config::{LossWeights, ModelSection, TrainConfig};
use ponq_train::data::{Batcher, Item, ItemOptions, item_frame, make_item, sphere_shape};
use ponq_train::{loss, train};
use rand::SeedableRng;

fn items(batch: usize, crop: usize, samples: usize) -> Vec<Item> {
    let shape = sphere_shape("bench", 32, [0.05, -0.03, 0.02], 0.6, 200_000);
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(0);
    (0..batch)
        .map(|_| {
            make_item(
                &shape,
                &ItemOptions {
                    crop,
                    samples,
                    augment: true,
                },
                &mut rng,
            )
        })
        .collect()
}

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

fn bench(name: &str, model: ModelSection, batch: usize, crop: usize, samples: usize, reps: usize) {
    let cfg = TrainConfig {
        model,
        ..Default::default()
    };
    let dev = ponq_model::backend::cpu();
    let its = items(batch, crop, samples);
    let frame = item_frame(32);
    // Forward without autodiff.
    let net: PonqNet = cfg.model.net().init(&dev);
    let x = Batcher {
        device: dev.clone(),
    }
    .batch(&its)
    .expect("batch");
    let mut fwd = Vec::new();
    for _ in 0..reps + 1 {
        let t = Instant::now();
        let out = net.forward(x.clone(), &frame);
        let _ = out.occupancy.into_data();
        fwd.push(t.elapsed().as_secs_f64());
    }
    fwd.remove(0);
    // Training step: forward, losses (kd-tree assignment), backward, clipping, AdamW.
    let ad = dev.autodiff();
    let mut model: PonqNet = cfg.model.net().init(&ad);
    let mut optim = burn::optim::AdamWConfig::new().with_amsgrad(true).init();
    let xa = Batcher { device: ad.clone() }.batch(&its).expect("batch");
    let mut step = Vec::new();
    for _ in 0..reps + 1 {
        let t = Instant::now();
        let out = model.forward(xa.clone(), &frame);
        let l = loss::compute(&out, &its, &LossWeights::default()).expect("loss");
        let mut g = GradientsParams::from_grads(l.total.backward(), &model);
        train::clip_global_norm(&model, &mut g, 1.0);
        model = optim.step(1e-4, model, g);
        step.push(t.elapsed().as_secs_f64());
    }
    step.remove(0);
    let (f, s) = (median(fwd), median(step));
    println!(
        "| {name} | {} | {} | {batch} | {f:.3} | {s:.3} | {:.3} |",
        net.num_params(),
        if crop == 0 {
            "33^3".to_string()
        } else {
            format!("{}^3", crop + 1)
        },
        s / batch as f64
    );
}

fn main() {
    let reps = std::env::args()
        .skip(1)
        .find_map(|a| a.parse::<usize>().ok())
        .unwrap_or(3)
        .max(1);
    println!(
        "| network | parameters | input | batch | forward (s) | training step (s) | step per grid (s) |"
    );
    println!("|---|---|---|---|---|---|---|");
    bench(
        "paper (width 128)",
        ModelSection::default(),
        1,
        0,
        100_000,
        reps,
    );
    let cpu = ModelSection {
        width: 32,
        points_per_cell: 4,
        encoder_layers: 4,
        decoder_blocks: 3,
    };
    bench("cpu.toml (width 32)", cpu.clone(), 1, 16, 16_000, reps);
    bench("cpu.toml (width 32)", cpu, 8, 16, 16_000, reps);
}
