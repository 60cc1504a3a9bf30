//! # ponq-infer
//!
//! Inference with a trained PoNQ network: an SDF grid goes in, a watertight, manifold,
//! self-intersection-free mesh comes out. The pipeline, by module:
//!
//! - [`frame`]: the user's grid and bounds -> the network's normalised frame (and back);
//! - [`tiles`]: the network (`ponq_model::PonqNet`) over the grid in overlapping tiles whose
//!   margins make the result equal to one pass over the whole grid;
//! - [`reconstruct`]: prediction -> PoNQ (kept cells, PoNQ-lite / hierarchy) -> `ponq_mesh`
//!   (Delaunay -> tags -> min cut -> mesh) -> refinement against the grid's exact distances
//!   (`ponq_data::refine`, when the grid is a true signed distance) -> mesh;
//! - [`grid_input`]: a grid file in, read near its surface, its values conditioned into
//!   distances first (`ponq_data::condition`: units, sign, iso-level, monotone fields);
//! - [`field`]: a signed distance function (a neural field) evaluated near its surface only;
//! - [`mesh_input`]: a mesh as the input (normalised, its exact SDF grid computed);
//! - [`shipped`]: the model in the repository's `models/` folder, also built into the program.
//!
//! The `ponq-infer` program is a thin command line over [`infer`].
//!
//! ```no_run
//! use ponq_infer::{InferOptions, infer, shipped};
//! let device = ponq_model::backend::cpu();
//! let (net, cfg) = shipped::load(&device).unwrap();
//! let grid = ponq_mesh::io::npy::read_npy_grid("examples/csg_sdf_33.npy").unwrap();
//! let out = infer(&net, cfg.encoder_layers, &grid, &InferOptions::default(), &device, |_, _| {})
//!     .unwrap();
//! println!("{} faces", out.mesh.faces.len());
//! ```

pub mod field;
pub mod frame;
pub mod grid_input;
pub mod mesh_input;
pub mod reconstruct;
pub mod shipped;
pub mod tiles;

pub use frame::Frame;
pub use reconstruct::{
    InferOptions, InferTimes, Inference, Predicted, RefineMode, RefineReport, band_parameters,
    finish, infer, keep_closer, predict, predict_band, retry_redistanced, with_note,
};
pub use tiles::{predict_cells, predict_tiled};
