//! # ponq-train
//!
//! Training the PoNQ network and the command-line programs that use it.
//!
//! The pipeline of a step: [`data`] cuts random crops of SDF grids (with 90-degree rotations
//! and flips) and stacks them ([`data::Batcher`]); `ponq_model::PonqNet` predicts per-cell
//! PoNQ points; [`loss`] assigns samples to predicted points with a kd-tree and evaluates the
//! six losses; [`train`] runs AdamW with gradient clipping, validation, checkpoints and
//! `metrics.csv` / [`plot`]. [`config`] is the TOML file of a run (`configs/*.toml`).
//!
//! ```no_run
//! use ponq_train::{config::TrainConfig, train};
//! let cfg = TrainConfig::load("configs/smoke.toml".as_ref()).unwrap();
//! let opts = train::RunOptions {
//!     out: "runs/smoke".into(),
//!     resume: false,
//!     device: ponq_model::backend::cpu(),
//!     quiet: false,
//! };
//! let summary = train::run(&cfg, &opts).unwrap();
//! println!("{} epochs", summary.epochs_done);
//! ```

pub mod config;
pub mod data;
pub mod dataset;
pub mod eval;
pub mod infer;
pub mod loss;
pub mod models;
pub mod plot;
pub mod render;
pub mod train;
