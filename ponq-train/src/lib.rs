//! # ponq-train
//!
//! Training the PoNQ network (`ponq_model`) on SDF grids and surface samples (`ponq_data`), and
//! the `ponq-train` program. Inference lives in `ponq-infer`, evaluation in `ponq-eval`.
//!
//! The pipeline of a step: [`data`] cuts random crops of SDF grids (with 90-degree rotations
//! and flips) and stacks them ([`data::Batcher`]); `ponq_model::PonqNet` predicts per-cell
//! PoNQ points; [`loss`] assigns samples to predicted points with a kd-tree and evaluates the
//! six losses; [`train`] runs AdamW with gradient clipping, validation, checkpoints and
//! `metrics.csv` / [`plot`] (loss curves drawn by `ponq_eval::chart`). [`config`] is the TOML file of a run (`configs/*.toml`).
//!
//! Training:
//!
//! ```no_run
//! use ponq_train::{config::TrainConfig, train};
//! let cfg = TrainConfig::load("configs/smoke.toml".as_ref()).unwrap();
//! let opts = train::RunOptions {
//!     out: "runs/smoke".into(),
//!     resume: false,
//!     device: ponq_model::backend::cpu(),
//!     quiet: false,
//!     kernels: ponq_model::Kernels::Fast,
//!     extra_devices: Vec::new(),
//! };
//! let summary = train::run(&cfg, &opts).unwrap();
//! println!("{} epochs", summary.epochs_done);
//! ```

pub mod config;
pub mod data;
pub mod dataset;
pub mod loss;
pub mod parallel;
pub mod plot;
pub mod train;
