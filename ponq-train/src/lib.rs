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
//! Inference (`ponq-infer`): [`infer`] runs the network over an SDF grid in exact tiles and
//! meshes the prediction (SDF grid -> network -> PoNQ -> Delaunay -> tags -> min cut -> mesh);
//! [`models`] is the shipped model. Evaluation (`ponq-eval run`): [`eval`] reconstructs shapes
//! with PoNQ and marching cubes, scores them and writes the report ([`render`] draws it).
//!
//! ```no_run
//! use ponq_train::{infer, models};
//! let device = ponq_model::backend::cpu();
//! let (net, cfg) = models::shipped(&device).unwrap();
//! let grid = ponq_mesh::io::npy::read_npy_grid("examples/csg_sdf_33.npy").unwrap();
//! let opts = infer::InferOptions::default();
//! let out = infer::infer(&net, cfg.encoder_layers, &grid, &opts, &device, |_, _| {}).unwrap();
//! println!("{} faces", out.mesh.faces.len());
//! ```
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
