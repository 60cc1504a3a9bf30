//! Time per phase of a training step (forward, losses, backward, clipping, AdamW):
//! `cargo run --release -p ponq-train --example step_profile -- [fast|stock] [paper|cpu]`.
//! `paper`: the paper's network on a 33^3 grid, batch 1; `cpu`: `configs/cpu.toml`'s network
//! on 17^3 crops, batch 8.

use std::time::Instant;

use anyhow::{Context, Result};
use burn::optim::GradientsParams;
use ponq_model::{Kernels, PonqNet};
use ponq_train::config::{LossWeights, ModelSection, TrainConfig};
use ponq_train::data::{Batcher, ItemOptions, item_frame, make_item, sphere_shape};
use ponq_train::{loss, train};
use rand::SeedableRng;

fn main() -> Result<()> {
    let args: Vec<String> = std::env::args().collect();
    let kernels: Kernels = match args.get(1) {
        Some(s) => s.parse().map_err(anyhow::Error::msg)?,
        None => Kernels::Fast,
    };
    let paper = args.get(2).is_none_or(|s| s == "paper");
    let (model, batch, crop, samples) = if paper {
        (ModelSection::default(), 1, 0, 100_000)
    } else {
        let m = ModelSection {
            width: 32,
            points_per_cell: 4,
            encoder_layers: 4,
            decoder_blocks: 3,
        };
        (m, 8, 16, 16_000)
    };
    let cfg = TrainConfig {
        model,
        ..Default::default()
    };
    let shape = sphere_shape("bench", 32, [0.05, -0.03, 0.02], 0.6, 200_000);
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(0);
    let opts = ItemOptions {
        crop,
        samples,
        augment: true,
    };
    let its: Vec<_> = (0..batch)
        .map(|_| make_item(&shape, &opts, &mut rng))
        .collect();
    let frame = item_frame(32);
    let ad = ponq_model::backend::cpu().autodiff();
    let mut model: PonqNet = cfg.model.net().init(&ad).with_kernels(kernels);
    let mut optim = burn::optim::AdamWConfig::new().with_amsgrad(true).init();
    let xa = Batcher { device: ad.clone() }
        .batch(&its)
        .context("batch")?;
    for _ in 0..4 {
        let t0 = Instant::now();
        let out = model.forward(xa.clone(), &frame);
        let t1 = Instant::now();
        let l = loss::compute(&out, &its, &LossWeights::default())?;
        let t2 = Instant::now();
        let grads = l.total.backward();
        let t3 = Instant::now();
        let mut g = GradientsParams::from_grads(grads, &model);
        train::clip_global_norm(&model, &mut g, 1.0);
        let t4 = Instant::now();
        model = optim.step(1e-4, model, g);
        let t5 = Instant::now();
        let s = |a: Instant, b: Instant| (b - a).as_secs_f64();
        println!(
            "{kernels}: forward {:.3} loss {:.3} backward {:.3} clip {:.3} optim {:.3} total {:.3} s",
            s(t0, t1),
            s(t1, t2),
            s(t2, t3),
            s(t3, t4),
            s(t4, t5),
            s(t0, t5)
        );
    }
    Ok(())
}
