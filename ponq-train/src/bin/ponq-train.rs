//! `ponq-train`: trains the PoNQ network from a TOML config (see `configs/`).

use std::path::PathBuf;
use std::process::ExitCode;

use anyhow::{Context, Result};
use clap::Parser;
use ponq_model::backend::{BackendKind, device_at};
use ponq_train::config::TrainConfig;
use ponq_train::parallel::{check_devices, parse_devices};
use ponq_train::train::{RunOptions, run};

/// Train the PoNQ network (SDF grid -> per-cell points, normals, quadrics, occupancy).
///
/// Writes OUT/checkpoint/ (model, optimizer, epoch; replaced atomically after every epoch),
/// OUT/metrics.csv (losses per epoch), OUT/losses.png (their plot) and OUT/model.bpk +
/// OUT/model.json (the final network, usable by `ponq-infer --model`).
#[derive(Parser, Debug)]
#[command(version, about, long_about)]
struct Args {
    /// Run configuration (TOML): configs/phase1.toml, phase2.toml, phase3.toml, cpu.toml,
    /// smoke.toml.
    #[arg(long)]
    config: PathBuf,
    /// Output folder [default: runs/<config name>].
    #[arg(long)]
    out: Option<PathBuf>,
    /// Continue from OUT/checkpoint (exactly: same shapes, crops and optimizer state).
    #[arg(long)]
    resume: bool,
    /// Compute backend: flex (CPU, default), wgpu (GPU or a software Vulkan driver; needs the
    /// `wgpu` cargo feature) or cuda (NVIDIA; needs the `cuda` cargo feature and a driver).
    #[arg(long, default_value = "flex")]
    backend: BackendKind,
    /// GPUs to train on together, as indices (`0,1,2,3`): each batch (train.batch_size
    /// shapes) is split across them and their gradients are summed (Burn's distributed data
    /// parallelism, NCCL); the learning rate and the checkpoints are those of one device, so a
    /// run may resume with another device count. Several devices need `--backend cuda`.
    #[arg(long, default_value = "0")]
    devices: String,
    /// Layer implementation on the CPU: fast (custom kernels, default), fast-bf16 (the same
    /// with bf16 GEMM inputs and f32 sums: AMX tiles or AVX-512 BF16, an error on CPUs
    /// without) or stock (Burn's Conv3d layers). Same weights; fast and stock give the same
    /// numbers up to float rounding, fast-bf16 within bf16 rounding. GPU backends always use
    /// the stock layers. A resumed run repeats the interrupted one exactly only with the same
    /// kernels.
    #[arg(long, default_value = "fast")]
    kernels: ponq_model::Kernels,
    /// Worker threads for the CPU backend and the data pipeline [default: all cores].
    #[arg(long)]
    threads: Option<usize>,
    /// Override the number of epochs of the config.
    #[arg(long)]
    epochs: Option<usize>,
    /// Override the time limit of the config (minutes; 0: none).
    #[arg(long)]
    time_limit: Option<f64>,
    /// Print nothing but errors.
    #[arg(short, long)]
    quiet: bool,
}

fn main() -> ExitCode {
    match real_main() {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {e:#}");
            ExitCode::from(2)
        }
    }
}

fn real_main() -> Result<()> {
    let args = Args::parse();
    if let Some(t) = args.threads {
        rayon::ThreadPoolBuilder::new()
            .num_threads(t.max(1))
            .build_global()
            .context("cannot set the thread count")?;
    }
    let mut cfg = TrainConfig::load(&args.config)?;
    if let Some(e) = args.epochs {
        cfg.train.epochs = e;
    }
    if let Some(t) = args.time_limit {
        cfg.train.time_limit_minutes = t;
    }
    cfg.check()?;
    let out = args.out.unwrap_or_else(|| {
        let stem = args
            .config
            .file_stem()
            .map(|s| s.to_string_lossy().into_owned())
            .unwrap_or_else(|| "run".into());
        PathBuf::from("runs").join(stem)
    });
    let indices = parse_devices(&args.devices)?;
    check_devices(args.backend, &indices, cfg.train.batch_size)?;
    let mut devices = indices
        .iter()
        .map(|&i| device_at(args.backend, i).map_err(anyhow::Error::msg))
        .collect::<Result<Vec<_>>>()?;
    let device = devices.remove(0);
    let opts = RunOptions {
        out: out.clone(),
        resume: args.resume,
        device,
        quiet: args.quiet,
        kernels: args.kernels,
        extra_devices: devices,
    };
    let s = run(&cfg, &opts)?;
    if !args.quiet {
        let v = s
            .validation
            .last()
            .map(|(e, v)| format!("; validation loss {:.4} (epoch {e})", v.total))
            .unwrap_or_default();
        println!(
            "{} epochs{}; last training loss {:.4}{v}; model: {}",
            s.epochs_done,
            if s.stopped_by_time {
                " (stopped by the time limit)"
            } else {
                ""
            },
            s.last_train.total,
            out.join("model.bpk").display()
        );
        println!(
            "in total (across runs continued with --resume): {} steps, {:.1} minutes of training",
            s.total_steps,
            s.total_seconds / 60.0
        );
    }
    Ok(())
}
