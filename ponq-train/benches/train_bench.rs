//! The network on the CPU, side by side in one process: Burn's stock layers against the fast
//! CPU kernels (`ponq_model::fast`, f32, and bf16 where the CPU has AMX or AVX-512 BF16),
//! forward and training step, with their GFLOP/s, peak memory, and the machine's f32 GEMM
//! rate (one large `gemm` call) as the ceiling.
//!
//! `cargo bench -p ponq-train --bench train_bench [REPS] [paper|cpu|w48|w64]` (default 3
//! repetitions, medians, all cases; the stock and fast runs alternate so that the machine's drift hits
//! both alike).
//! `ponq-train/benches/side_by_side.sh` also runs the same network in PyTorch.
//!
//! Cases: the paper's network (width 128, P = 4) on a 33^3 grid, batch 1 (`paper16`: batch
//! 16, the paper's phase-1 step, `configs/phase1.toml`); the CPU recipes' networks
//! (`configs/cpu.toml`, width 32, `configs/cpu-w48.toml`, width 48, and the shipped
//! `configs/cpu-w64.toml`, width 64) on 17^3-node crops, batch 1 and 8 (widths 48 / 64: 8).
//!
//! `--backend wgpu` (or `cuda`; built with `--features ponq-train/wgpu` / `cuda`) runs the
//! same cases on the GPU with Burn's stock layers (the only ones there), waiting for the device
//! after every timed call; `paper16` is then among the default cases. The peak-memory column
//! counts host memory only.

use std::alloc::{GlobalAlloc, Layout, System};
use std::sync::atomic::{AtomicUsize, Ordering};
use std::time::Instant;

use burn::optim::GradientsParams;
use burn::prelude::*;
use ponq_model::backend::{self, BackendKind};
use ponq_model::{Kernels, PonqNet};
use ponq_train::config::{LossWeights, ModelSection, TrainConfig};
use ponq_train::data::{Batcher, Item, ItemOptions, item_frame, make_item, sphere_shape};
use ponq_train::{loss, train};
use rand::SeedableRng;

/// The system allocator, counting live bytes and their peak.
struct Counting;

static LIVE: AtomicUsize = AtomicUsize::new(0);
static PEAK: AtomicUsize = AtomicUsize::new(0);

// SAFETY: forwards to `System`; the counters do not affect allocation.
unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, l: Layout) -> *mut u8 {
        let p = unsafe { System.alloc(l) };
        if !p.is_null() {
            let now = LIVE.fetch_add(l.size(), Ordering::Relaxed) + l.size();
            PEAK.fetch_max(now, Ordering::Relaxed);
        }
        p
    }
    unsafe fn dealloc(&self, p: *mut u8, l: Layout) {
        unsafe { System.dealloc(p, l) };
        LIVE.fetch_sub(l.size(), Ordering::Relaxed);
    }
    unsafe fn realloc(&self, p: *mut u8, l: Layout, new: usize) -> *mut u8 {
        let q = unsafe { System.realloc(p, l, new) };
        if !q.is_null() {
            if new > l.size() {
                let now = LIVE.fetch_add(new - l.size(), Ordering::Relaxed) + new - l.size();
                PEAK.fetch_max(now, Ordering::Relaxed);
            } else {
                LIVE.fetch_sub(l.size() - new, Ordering::Relaxed);
            }
        }
        q
    }
}

#[global_allocator]
static ALLOC: Counting = Counting;

/// Runs `f`, returning its result, seconds and the peak of live heap bytes above the start.
fn measure<T>(f: impl FnOnce() -> T) -> (T, f64, usize) {
    let base = LIVE.load(Ordering::Relaxed);
    PEAK.store(base, Ordering::Relaxed);
    let t = Instant::now();
    let r = f();
    let s = t.elapsed().as_secs_f64();
    (r, s, PEAK.load(Ordering::Relaxed).saturating_sub(base))
}

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

/// Multiply-adds x 2 of one forward over `cells` output cells.
fn forward_flops(m: &ModelSection, cells: usize) -> f64 {
    let w = m.width as f64;
    let p = m.points_per_cell as f64;
    let enc = 8.0 * w + m.encoder_layers as f64 * 27.0 * w * w;
    let heads = (3.0 + 3.0 + 6.0 + 3.0) * p + 1.0;
    let dec = 5.0 * m.decoder_blocks as f64 * 2.0 * w * w + w * heads;
    2.0 * cells as f64 * (enc + dec)
}

/// GFLOP/s of one large `gemm` call on all threads (the shape of the paper's k3 convolution as
/// an im2col GEMM: 32,768 x 3,456 x 128), best of 3.
fn gemm_ceiling() -> f64 {
    let (m, k, n) = (32768usize, 3456usize, 128usize);
    let a: Vec<f32> = (0..m * k).map(|i| (i % 17) as f32 * 0.01).collect();
    let b: Vec<f32> = (0..k * n).map(|i| (i % 13) as f32 * 0.01).collect();
    let mut c = vec![0.0f32; m * n];
    let mut best = f64::MAX;
    for _ in 0..3 {
        let t = Instant::now();
        // SAFETY: row-major a [m, k], b [k, n], c [m, n], all of those sizes.
        unsafe {
            gemm::gemm(
                m,
                n,
                k,
                c.as_mut_ptr(),
                1,
                n as isize,
                false,
                a.as_ptr(),
                1,
                k as isize,
                b.as_ptr(),
                1,
                n as isize,
                1.0,
                1.0,
                false,
                false,
                false,
                gemm::Parallelism::Rayon(0),
            )
        };
        best = best.min(t.elapsed().as_secs_f64());
    }
    2.0 * (m * k * n) as f64 / best / 1e9
}

struct Row {
    fwd: Vec<f64>,
    step: Vec<f64>,
    fwd_mem: usize,
    step_mem: usize,
}

/// One case: `batch` items of `crop` cells (0: the whole 33^3 grid) on `dev`, `reps` timed
/// repetitions after one warm-up; on the CPU every kernel implementation, elsewhere the stock
/// layers.
fn bench(
    dev: &Device,
    name: &str,
    model: ModelSection,
    batch: usize,
    crop: usize,
    samples: usize,
    reps: usize,
) {
    let cfg = TrainConfig {
        model: model.clone(),
        ..Default::default()
    };
    let on_cpu = *dev == ponq_model::backend::cpu();
    let its = items(batch, crop, samples);
    let frame = item_frame(32);
    let cells = batch
        * if crop == 0 {
            32 * 32 * 32
        } else {
            crop * crop * crop
        };
    let flops = forward_flops(&model, cells);
    let net: PonqNet = cfg.model.net().init(dev);
    let x = Batcher {
        device: dev.clone(),
    }
    .batch(&its)
    .expect("batch");
    let ad = dev.clone().autodiff();
    let xa = Batcher { device: ad.clone() }.batch(&its).expect("batch");
    let mut kinds = vec![Kernels::Stock];
    if on_cpu {
        kinds.push(Kernels::Fast);
        if ponq_model::fast::bf16::available() {
            kinds.push(Kernels::FastBf16);
        }
    }
    let mut rows: Vec<Row> = kinds
        .iter()
        .map(|_| Row {
            fwd: vec![],
            step: vec![],
            fwd_mem: 0,
            step_mem: 0,
        })
        .collect();
    // One model and optimizer per path, the same initial weights.
    let init: PonqNet = cfg.model.net().init(&ad);
    let mut models: Vec<PonqNet> = kinds
        .iter()
        .map(|&k| init.clone().with_kernels(k))
        .collect();
    let mut optims: Vec<_> = kinds
        .iter()
        .map(|_| burn::optim::AdamWConfig::new().with_amsgrad(true).init())
        .collect();
    for rep in 0..=reps {
        for (i, &k) in kinds.iter().enumerate() {
            let n = net.clone().with_kernels(k);
            let (_, s, mem) = measure(|| {
                let out = n.forward(x.clone(), &frame);
                let _ = out.occupancy.into_data();
                // The other decoders' outputs too: a lazy (fused) GPU backend would otherwise
                // run them inside the next timed call.
                dev.sync().expect("device sync");
            });
            let model = models[i].clone();
            let ((), st, smem) = measure(|| {
                let out = model.forward(xa.clone(), &frame);
                let l = loss::compute(&out, &its, &LossWeights::default()).expect("loss");
                let mut g = GradientsParams::from_grads(l.total.backward(), &model);
                train::clip_global_norm(&model, &mut g, 1.0);
                models[i] = optims[i].step(1e-4, model.clone(), g);
                dev.sync().expect("device sync");
            });
            if rep > 0 {
                rows[i].fwd.push(s);
                rows[i].step.push(st);
            }
            rows[i].fwd_mem = rows[i].fwd_mem.max(mem);
            rows[i].step_mem = rows[i].step_mem.max(smem);
        }
    }
    let input = if crop == 0 {
        "33^3".to_string()
    } else {
        format!("{}^3", crop + 1)
    };
    let stock = (median(rows[0].fwd.clone()), median(rows[0].step.clone()));
    for (k, r) in kinds.iter().zip(&rows) {
        let (f, s) = (median(r.fwd.clone()), median(r.step.clone()));
        println!(
            "| {name} | {} | {input} | {batch} | {k} | {f:.3} | {:.0} | {s:.3} | {:.0} | {:.2}x / {:.2}x | {:.0} / {:.0} |",
            net.num_params(),
            flops / f / 1e9,
            3.0 * flops / s / 1e9,
            stock.0 / f,
            stock.1 / s,
            r.fwd_mem as f64 / 1e6,
            r.step_mem as f64 / 1e6,
        );
    }
}

fn main() {
    let mut args: Vec<String> = std::env::args().skip(1).collect();
    // `--backend B` (taken out of the arguments, so that `cpu`, a name of flex, is no case).
    let kind: BackendKind = match args.iter().position(|a| a == "--backend") {
        Some(i) if i + 1 < args.len() => {
            let b: Vec<String> = args.drain(i..i + 2).collect();
            b[1].parse().unwrap_or_else(|e: String| fail(&e))
        }
        Some(_) => fail("--backend needs a value: flex, wgpu or cuda"),
        None => BackendKind::Flex,
    };
    let dev = backend::device(kind).unwrap_or_else(|e| fail(&e));
    let reps = args
        .iter()
        .find_map(|a| a.parse::<usize>().ok())
        .unwrap_or(3)
        .max(1);
    // Case filter: `paper`, `paper16`, `cpu`, `w48` or `w64` (default all; `paper16` only on a
    // GPU by default).
    let cases = ["paper", "paper16", "cpu", "w48", "w64"];
    let want = |case: &str| {
        if args.iter().any(|a| cases.contains(&a.as_str())) {
            args.iter().any(|a| a == case)
        } else {
            case != "paper16" || kind != BackendKind::Flex
        }
    };
    if kind == BackendKind::Flex {
        println!(
            "GEMM ceiling (one 32768 x 3456 x 128 gemm call, {} threads): {:.0} GFLOP/s\n",
            rayon::current_num_threads(),
            gemm_ceiling()
        );
    } else {
        println!("backend: {kind} (Burn's stock layers)\n");
    }
    println!(
        "| network | parameters | input | batch | kernels | forward (s) | forward GFLOP/s | training step (s) | step GFLOP/s (3x forward FLOPs) | speed-up vs stock (forward / step) | peak MB (forward / step) |"
    );
    println!("|---|---:|---|---:|---|---:|---:|---:|---:|---:|---:|");
    let paper = "paper (width 128, P 4)";
    if want("paper") {
        bench(&dev, paper, ModelSection::default(), 1, 0, 100_000, reps);
    }
    if want("paper16") {
        bench(&dev, paper, ModelSection::default(), 16, 0, 100_000, reps);
    }
    let cpu = ModelSection {
        width: 32,
        points_per_cell: 4,
        encoder_layers: 4,
        decoder_blocks: 3,
    };
    if want("cpu") {
        for batch in [1, 8] {
            let name = "cpu.toml (width 32)";
            bench(&dev, name, cpu.clone(), batch, 16, 16_000, reps);
        }
    }
    if want("w48") {
        let w48 = ModelSection {
            width: 48,
            ..cpu.clone()
        };
        bench(&dev, "cpu-w48.toml (width 48)", w48, 8, 16, 16_000, reps);
    }
    if want("w64") {
        let w64 = ModelSection { width: 64, ..cpu };
        bench(&dev, "cpu-w64.toml (width 64)", w64, 8, 16, 16_000, reps);
    }
}

fn fail(msg: &str) -> ! {
    eprintln!("train_bench: {msg}");
    std::process::exit(2)
}
