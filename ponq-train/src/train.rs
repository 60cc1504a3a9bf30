//! The training loop: AdamW (AMSGrad) with global gradient-norm clipping over batches of
//! random crops, validation, atomic per-epoch checkpoints with exact resume, `metrics.csv`
//! and a loss plot.
//!
//! Randomness: epoch `e` draws everything (shape order, crops, rotations, samples) from a
//! ChaCha8 stream seeded by `(seed, e)`, so the RNG state of a checkpoint is its epoch
//! number and a resumed run repeats the uninterrupted one.

use std::io::Write;
use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::{Context, Result, bail};
use burn::module::{Module, ModuleVisitor, Param};
use burn::optim::{AdamWConfig, GradientsParams, ModuleOptimizer};
use burn::prelude::*;
use indicatif::{ProgressBar, ProgressStyle};
use ponq_model::{PonqNet, PonqNetConfig, Prediction};
use rand::seq::SliceRandom;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};

use crate::config::TrainConfig;
use crate::data::{Batcher, Item, ItemOptions, Shape, item_frame, make_item, make_item_at};
use crate::loss::{self, LossTerms};
use crate::parallel::{BatchGradients, DeviceGroup, Parallel};

/// How to run.
#[derive(Debug, Clone)]
pub struct RunOptions {
    /// Output folder (checkpoint, metrics.csv, loss plot, final model).
    pub out: PathBuf,
    /// Continue from `out/checkpoint` if present.
    pub resume: bool,
    /// Device (autodiff is enabled on it).
    pub device: Device,
    /// No progress bars or messages.
    pub quiet: bool,
    /// Layer implementation on the CPU (the fast kernels by default; the weights and the
    /// numbers are the same up to float rounding).
    pub kernels: ponq_model::Kernels,
    /// More devices for data-parallel training: each batch is split across `device` and
    /// these (see [`crate::parallel`]; needs a backend with collective operations: CUDA).
    /// Empty: one device.
    pub extra_devices: Vec<Device>,
}

/// What a run did.
#[derive(Debug, Clone, Default)]
pub struct RunSummary {
    /// Epochs finished in total (including resumed ones).
    pub epochs_done: usize,
    /// Total loss of every step of this invocation, in order.
    pub step_losses: Vec<f64>,
    /// Mean training terms of the last epoch.
    pub last_train: LossTerms,
    /// Validation terms of every validation: (epoch, terms).
    pub validation: Vec<(usize, LossTerms)>,
    /// Whether the time limit stopped the run early.
    pub stopped_by_time: bool,
    /// Optimizer steps in total, across every run continued with `--resume`.
    pub total_steps: usize,
    /// Training wall-clock seconds in total, across every run continued with `--resume`.
    pub total_seconds: f64,
}

/// Saved with every checkpoint.
#[derive(Debug, Clone, Serialize, Deserialize)]
struct State {
    epochs_done: usize,
    steps_done: usize,
    seconds: f64,
}

/// Sums the squares of all gradients (for the global norm).
struct GradNorm<'a> {
    grads: &'a GradientsParams,
    sum: f64,
}

impl ModuleVisitor for GradNorm<'_> {
    fn visit_float<const D: usize>(&mut self, param: &Param<Tensor<D>>) {
        if let Some(g) = self.grads.get::<D>(param.id) {
            self.sum += f64::from((g.clone() * g).sum().into_scalar::<f32>());
        }
    }
}

/// Multiplies all gradients by `factor`.
struct GradScale<'a> {
    grads: &'a mut GradientsParams,
    factor: f32,
}

impl ModuleVisitor for GradScale<'_> {
    fn visit_float<const D: usize>(&mut self, param: &Param<Tensor<D>>) {
        if let Some(g) = self.grads.remove::<D>(param.id) {
            self.grads.register(param.id, g.mul_scalar(self.factor));
        }
    }
}

/// Clips the global gradient norm to `max_norm` (as PyTorch's `clip_grad_norm_`); returns
/// the norm before clipping.
pub fn clip_global_norm(model: &PonqNet, grads: &mut GradientsParams, max_norm: f64) -> f64 {
    let mut n = GradNorm { grads, sum: 0.0 };
    model.visit(&mut n);
    let norm = n.sum.sqrt();
    if max_norm > 0.0 && norm > max_norm {
        let mut s = GradScale {
            grads,
            factor: (max_norm / (norm + 1e-6)) as f32,
        };
        model.visit(&mut s);
    }
    norm
}

fn epoch_rng(seed: u64, epoch: usize) -> ChaCha8Rng {
    ChaCha8Rng::seed_from_u64(seed ^ (epoch as u64).wrapping_mul(0x9E37_79B9_7F4A_7C15))
}

fn optimizer(cfg: &TrainConfig) -> ModuleOptimizer {
    AdamWConfig::new()
        .with_weight_decay(cfg.train.weight_decay as f32)
        .with_amsgrad(cfg.train.amsgrad)
        .with_epsilon(1e-8)
        .init()
}

/// Checkpoint files of `dir`.
fn ck_paths(dir: &Path) -> (PathBuf, PathBuf, PathBuf) {
    (
        dir.join("model.bpk"),
        dir.join("optim.bpk"),
        dir.join("state.json"),
    )
}

/// Writes a checkpoint folder atomically: into `checkpoint.tmp`, then swapped in.
fn save_checkpoint(
    out: &Path,
    model: &PonqNet,
    cfg: &TrainConfig,
    optim: &ModuleOptimizer,
    state: &State,
) -> Result<()> {
    let tmp = out.join("checkpoint.tmp");
    let fin = out.join("checkpoint");
    let old = out.join("checkpoint.old");
    if tmp.exists() {
        std::fs::remove_dir_all(&tmp)?;
    }
    std::fs::create_dir_all(&tmp)?;
    let (m, o, s) = ck_paths(&tmp);
    ponq_model::weights::save(model, &cfg.model.net(), &m)?;
    optim
        .save(&o)
        .map_err(|e| anyhow::anyhow!("saving the optimizer state: {e:?}"))?;
    std::fs::write(&s, serde_json::to_string_pretty(state)?)?;
    std::fs::write(tmp.join("config.toml"), toml::to_string(cfg)?)?;
    if fin.exists() {
        if old.exists() {
            std::fs::remove_dir_all(&old)?;
        }
        std::fs::rename(&fin, &old)?;
    }
    std::fs::rename(&tmp, &fin)?;
    if old.exists() {
        std::fs::remove_dir_all(&old)?;
    }
    Ok(())
}

/// The checkpoint folder to resume from (`checkpoint`, or `checkpoint.old` when a crash
/// happened between the two renames).
fn checkpoint_dir(out: &Path) -> Option<PathBuf> {
    [out.join("checkpoint"), out.join("checkpoint.old")]
        .into_iter()
        .find(|d| d.join("state.json").is_file())
}

/// Loads weights saved by [`ponq_model::weights::save`] (a checkpoint folder or a `.bpk`).
pub fn load_weights(path: &Path, cfg: &TrainConfig, device: &Device) -> Result<PonqNet> {
    let (model, net, file) = read_weights(path, device)?;
    if net != cfg.model.net() {
        bail!(
            "{} holds a network {net:?}, the config asks for {:?}",
            file.display(),
            cfg.model.net()
        );
    }
    Ok(model)
}

/// The network `train.init_from` names, as [`load_weights`] does; where the config asks for
/// the same network wider (only `model.width` larger), that network widened to it
/// (`ponq_model::widen`: the same function, new channels copying old ones, seeded by
/// `train.seed`).
pub fn init_weights(
    path: &Path,
    cfg: &TrainConfig,
    device: &Device,
    quiet: bool,
) -> Result<PonqNet> {
    let (model, net, file) = read_weights(path, device)?;
    let want = cfg.model.net();
    if net == want {
        return Ok(model);
    }
    let same_but_width = PonqNetConfig {
        width: want.width,
        ..net.clone()
    } == want;
    if !same_but_width || want.width < net.width {
        bail!(
            "{} holds a network {net:?}, the config asks for {want:?} (only a wider network \
             can start from it)",
            file.display()
        );
    }
    if !quiet {
        eprintln!(
            "widening {} from width {} to {} (Net2Wider: the same outputs to start with)",
            file.display(),
            net.width,
            want.width
        );
    }
    let (wide, _) = ponq_model::widen::widen(&model, &net, want.width, cfg.train.seed)
        .with_context(|| format!("widening {}", file.display()))?;
    Ok(wide)
}

/// The network saved at `path` (a `.bpk` file or a directory holding `model.bpk`), its
/// config and the file read.
fn read_weights(path: &Path, device: &Device) -> Result<(PonqNet, PonqNetConfig, PathBuf)> {
    let file = if path.is_dir() {
        path.join("model.bpk")
    } else {
        path.to_path_buf()
    };
    let (model, net) = ponq_model::weights::load(&file, device)
        .with_context(|| format!("cannot load weights {}", file.display()))?;
    Ok((model, net, file))
}

fn bar(quiet: bool, len: u64, msg: &str) -> ProgressBar {
    if quiet {
        return ProgressBar::hidden();
    }
    let pb = ProgressBar::new(len);
    pb.set_style(
        ProgressStyle::with_template(
            "{msg} [{elapsed_precise}] {wide_bar} {pos}/{len} steps, ETA {eta} {prefix}",
        )
        .unwrap_or_else(|_| ProgressStyle::default_bar()),
    );
    pb.set_message(msg.to_string());
    pb
}

/// Validation items: fixed crops (seeded by shape index), no augmentation.
pub fn validation_items(shapes: &[Shape], opts: &ItemOptions, seed: u64) -> Vec<Item> {
    shapes
        .iter()
        .enumerate()
        .map(|(i, s)| {
            let mut rng = ChaCha8Rng::seed_from_u64(seed.wrapping_add(0xA5A5 + i as u64));
            make_item(
                s,
                &ItemOptions {
                    augment: false,
                    ..*opts
                },
                &mut rng,
            )
        })
        .collect()
}

/// Mean validation losses of `items` (batches of `batch`).
pub fn validate(
    model: &PonqNet,
    items: &[Item],
    cfg: &TrainConfig,
    device: &Device,
) -> Result<LossTerms> {
    let batcher = Batcher {
        device: device.clone(),
    };
    let frame = item_frame(cfg.data.resolution);
    let mut sum = LossTerms::default();
    let b = cfg.train.batch_size.max(1);
    for chunk in items.chunks(b) {
        let out = model.forward(batcher.batch(chunk)?, &frame);
        let l = loss::compute(&out, chunk, &cfg.loss)?;
        sum.add(&l.terms, chunk.len() as f64 / items.len() as f64);
    }
    Ok(sum)
}

/// Meshed validation of one shape: the whole grid through the network and `ponq-mesh`;
/// `(cd x 1e5, f1, nc, valid)` against the shape's samples at unit diagonal.
pub fn mesh_validate(
    model: &PonqNet,
    shape: &Shape,
    device: &Device,
) -> Result<(f64, f64, f64, bool)> {
    let mut rng = ChaCha8Rng::seed_from_u64(0);
    let item = make_item(
        shape,
        &ItemOptions {
            crop: 0,
            samples: 1,
            augment: false,
        },
        &mut rng,
    );
    let batcher = Batcher {
        device: device.clone(),
    };
    let out = model.forward(
        batcher.batch(std::slice::from_ref(&item))?,
        &item_frame(shape.res),
    );
    let pred = Prediction::from_output(&out, 0)?;
    let cells = pred.kept_cells(0.5, Some(&item.close))?;
    let (ponq, _) = pred.to_ponq(&cells)?;
    let opts = ponq_mesh::mesher::MeshingOptions {
        grid_scale: shape.res as f64,
        ..Default::default()
    };
    let mesh = ponq_mesh::mesher::mesh_ponq(&ponq, &opts)?.mesh;
    if mesh.faces.is_empty() {
        return Ok((f64::INFINITY, 0.0, 0.0, false));
    }
    let valid = ponq_mesh::validity::check(&mesh).is_valid();
    let s = ponq_mesh::sampling::sample_surface(&mesh, 20_000, 1);
    let stride = (shape.samples.len() / 20_000).max(1);
    let gt: Vec<[f64; 3]> = shape
        .samples
        .iter()
        .step_by(stride)
        .map(|p| p.map(f64::from))
        .collect();
    let gtn: Vec<[f64; 3]> = shape
        .normals
        .iter()
        .step_by(stride)
        .map(|p| p.map(f64::from))
        .collect();
    // [-1,1] frame (diagonal ~2) -> unit diagonal: distances / 2.
    let (cd, f1, (_, ba)) = ponq_mesh::metrics::chamfer_f1(&s.points, &gt, 0.006);
    let nc = ba
        .iter()
        .zip(&gtn)
        .map(|(&(i, _), n)| {
            let m = s.normals[i as usize];
            (m[0] * n[0] + m[1] * n[1] + m[2] * n[2]).abs()
        })
        .sum::<f64>()
        / ba.len().max(1) as f64;
    Ok((cd / 4.0 * 1e5, f1, nc, valid))
}

fn csv_header() -> String {
    let mut h = vec![
        "epoch".to_string(),
        "steps".into(),
        "seconds".into(),
        "lr".into(),
    ];
    for n in LossTerms::NAMES {
        h.push(format!("train_{n}"));
    }
    for n in LossTerms::NAMES {
        h.push(format!("val_{n}"));
    }
    h.extend([
        "val_mesh_cd".into(),
        "val_mesh_f1".into(),
        "val_mesh_nc".into(),
        "val_mesh_valid".into(),
    ]);
    h.join(",")
}

/// Trains on in-memory shapes.
pub fn run_with_shapes(
    cfg: &TrainConfig,
    train: &[Shape],
    val: &[Shape],
    opts: &RunOptions,
) -> Result<RunSummary> {
    if train.is_empty() {
        bail!("no training shapes");
    }
    if let Some(s) = train
        .iter()
        .chain(val)
        .find(|s| s.res != cfg.data.resolution)
    {
        bail!(
            "shape {} has resolution {}, the config {}",
            s.id,
            s.res,
            cfg.data.resolution
        );
    }
    let excluded = cfg.excluded_ids()?;
    if let Some(s) = train.iter().chain(val).find(|s| excluded.contains(&s.id)) {
        bail!(
            "the data holds shape {}, which the exclusion split {} says this run must never train \
             or validate on; remove it from {} (or use data.split)",
            s.id,
            cfg.data
                .exclude
                .as_deref()
                .map(|p| p.display().to_string())
                .unwrap_or_default(),
            cfg.data.dir.display()
        );
    }
    std::fs::create_dir_all(&opts.out)
        .with_context(|| format!("cannot create {}", opts.out.display()))?;
    let device = opts.device.clone().autodiff();
    let mut parallel = if opts.extra_devices.is_empty() {
        Parallel::MicroBatches(cfg.train.micro_batches)
    } else {
        if cfg.train.batch_size < 1 + opts.extra_devices.len() {
            bail!(
                "{} devices for a batch of {} shapes: each device needs at least one shape \
                 (raise train.batch_size or use fewer devices)",
                1 + opts.extra_devices.len(),
                cfg.train.batch_size
            );
        }
        let mut devices = vec![device.clone()];
        devices.extend(opts.extra_devices.iter().map(|d| d.clone().autodiff()));
        Parallel::Devices(DeviceGroup::new(devices)?)
    };
    let net = cfg.model.net();
    let mut state = State {
        epochs_done: 0,
        steps_done: 0,
        seconds: 0.0,
    };
    let mut optim = optimizer(cfg);
    let ck = if opts.resume {
        checkpoint_dir(&opts.out)
    } else {
        None
    };
    if let Some(e) = opts.kernels.unsupported_here() {
        bail!(e);
    }
    let mut model = if let Some(dir) = &ck {
        let (m, o, s) = ck_paths(dir);
        state = serde_json::from_str(&std::fs::read_to_string(&s)?)
            .with_context(|| format!("invalid {}", s.display()))?;
        optim = optim
            .load(&o)
            .map_err(|e| anyhow::anyhow!("loading {}: {e:?}", o.display()))?;
        if !opts.quiet {
            eprintln!(
                "resuming after epoch {} from {}",
                state.epochs_done,
                dir.display()
            );
        }
        load_weights(&m, cfg, &device)?
    } else if let Some(init) = &cfg.train.init_from {
        if !opts.quiet {
            eprintln!("starting from the weights of {}", init.display());
        }
        init_weights(init, cfg, &device, opts.quiet)?
    } else {
        // Seeded initial weights (the seed may be global to the backend).
        device.seed(cfg.train.seed);
        net.init(&device)
    }
    .with_kernels(opts.kernels);
    let csv_path = opts.out.join("metrics.csv");
    if ck.is_none() || !csv_path.is_file() {
        std::fs::write(&csv_path, csv_header() + "\n")?;
    }
    let item_opts = ItemOptions {
        crop: cfg.train.crop,
        samples: cfg.train.samples_per_shape,
        augment: cfg.train.augment,
    };
    let val_items = validation_items(val, &item_opts, cfg.train.seed);
    let frame = item_frame(cfg.data.resolution);
    let steps_per_epoch = train.len().div_ceil(cfg.train.batch_size);
    let mut summary = RunSummary {
        epochs_done: state.epochs_done,
        ..Default::default()
    };
    let start = Instant::now();
    let seconds_before = state.seconds;
    let pb = bar(
        opts.quiet,
        ((cfg.train.epochs.saturating_sub(state.epochs_done)) * steps_per_epoch) as u64,
        "training",
    );
    for epoch in state.epochs_done..cfg.train.epochs {
        let mut rng = epoch_rng(cfg.train.seed, epoch);
        let mut order: Vec<usize> = (0..train.len()).collect();
        order.shuffle(&mut rng);
        let mut mean = LossTerms::default();
        for chunk in order.chunks(cfg.train.batch_size) {
            // The resolution of this batch (no draw without extra resolutions).
            let extra = &cfg.data.extra_resolutions;
            let res = if !extra.is_empty() && rng.random_bool(cfg.data.extra_weight) {
                extra[rng.random_range(0..extra.len())]
            } else {
                cfg.data.resolution
            };
            let items: Vec<Item> = chunk
                .iter()
                .map(|&i| {
                    let shape = &train[i];
                    let grid = shape.grid(res).with_context(|| {
                        format!("shape {} has no grid at resolution {res}", shape.id)
                    })?;
                    Ok(make_item_at(shape, res, grid, &item_opts, &mut rng))
                })
                .collect::<Result<_>>()?;
            let batch_frame = if res == cfg.data.resolution {
                frame
            } else {
                item_frame(res)
            };
            model = parallel.prepare(model);
            let BatchGradients { mut grads, terms } =
                parallel.gradients(&model, &items, &batch_frame, &cfg.loss)?;
            clip_global_norm(&model, &mut grads, cfg.train.grad_clip);
            model = optim.step(cfg.train.lr_at(epoch), model, grads);
            mean.add(&terms, 1.0 / steps_per_epoch as f64);
            summary.step_losses.push(terms.total);
            state.steps_done += 1;
            pb.set_prefix(format!("epoch {} loss {:.4}", epoch + 1, terms.total));
            pb.inc(1);
        }
        state.epochs_done = epoch + 1;
        state.seconds = seconds_before + start.elapsed().as_secs_f64();
        summary.last_train = mean;
        let every = |k: usize| {
            k > 0 && (state.epochs_done.is_multiple_of(k) || state.epochs_done == cfg.train.epochs)
        };
        let val_terms = if every(cfg.train.validate_every) && !val_items.is_empty() {
            let v = validate(&model, &val_items, cfg, &device)?;
            summary.validation.push((state.epochs_done, v));
            Some(v)
        } else {
            None
        };
        let mesh_val = if every(cfg.train.mesh_validate_every) && !val.is_empty() {
            let k = cfg.train.mesh_validate_shapes.clamp(1, val.len());
            let mut acc = (0.0, 0.0, 0.0, 0usize);
            for s in &val[..k] {
                let (cd, f1, nc, ok) = mesh_validate(&model, s, &device)?;
                acc = (
                    acc.0 + cd / k as f64,
                    acc.1 + f1 / k as f64,
                    acc.2 + nc / k as f64,
                    acc.3 + ok as usize,
                );
            }
            Some(acc)
        } else {
            None
        };
        // metrics.csv row.
        let mut row = vec![
            state.epochs_done.to_string(),
            state.steps_done.to_string(),
            format!("{:.1}", state.seconds),
            format!("{:e}", cfg.train.lr_at(epoch)),
        ];
        row.extend(mean.values().iter().map(|v| format!("{v:.6e}")));
        match val_terms {
            Some(v) => row.extend(v.values().iter().map(|v| format!("{v:.6e}"))),
            None => row.extend(std::iter::repeat_n(String::new(), 7)),
        }
        match mesh_val {
            Some((cd, f1, nc, ok)) => row.extend([
                format!("{cd:.4}"),
                format!("{f1:.4}"),
                format!("{nc:.4}"),
                ok.to_string(),
            ]),
            None => row.extend(std::iter::repeat_n(String::new(), 4)),
        }
        save_checkpoint(&opts.out, &model, cfg, &optim, &state)?;
        let mut f = std::fs::OpenOptions::new().append(true).open(&csv_path)?;
        writeln!(f, "{}", row.join(","))?;
        drop(f);
        if let Err(e) = crate::plot::plot_losses(&csv_path, &opts.out.join("losses.png")) {
            pb.println(format!("warning: no loss plot: {e:#}"));
        }
        if !opts.quiet {
            let v = val_terms
                .map(|v| format!(", val {:.4}", v.total))
                .unwrap_or_default();
            let m = mesh_val
                .map(|(cd, _, nc, ok)| format!(", meshed CD {cd:.2} NC {nc:.3} valid {ok}"))
                .unwrap_or_default();
            pb.println(format!(
                "epoch {}: train {:.4}{v}{m}",
                state.epochs_done, mean.total
            ));
        }
        summary.epochs_done = state.epochs_done;
        summary.total_steps = state.steps_done;
        summary.total_seconds = state.seconds;
        let limit = cfg.train.time_limit_minutes;
        if limit > 0.0
            && start.elapsed().as_secs_f64() > limit * 60.0
            && state.epochs_done < cfg.train.epochs
        {
            summary.stopped_by_time = true;
            break;
        }
    }
    pb.finish_and_clear();
    ponq_model::weights::save(&model, &net, &opts.out.join("model.bpk"))?;
    Ok(summary)
}

/// Loads the shapes of `cfg.data` (generating procedural shapes first when asked and the
/// folder is empty), holds the last `validation_shapes` aside and trains.
pub fn run(cfg: &TrainConfig, opts: &RunOptions) -> Result<RunSummary> {
    let (train, val) = crate::dataset::load(cfg, opts.quiet)?;
    run_with_shapes(cfg, &train, &val, opts)
}
