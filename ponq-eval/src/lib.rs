//! # ponq-eval
//!
//! Evaluation of PoNQ-rs with the paper's protocol (SPEC section 8), by module:
//!
//! - [`mod@inputs`]: the shapes of a data folder (meshes, `ponq-prep` records, the authors' HDF5
//!   files), restricted to a split, and their ground truth and SDF grids;
//! - [`mod@evaluate`]: one shape at one resolution reconstructed by PoNQ / PoNQ-lite
//!   (`ponq_infer`) and marching cubes on the same grid, scored with `ponq_mesh::metrics`
//!   (CD, F1, NC, ECD, EF1, validity, #V, #F, time);
//! - [`report`]: the rows of a run, resumable on disk, and the report (`per_shape.csv`,
//!   `summary.md`, `report.md` with renders and charts);
//! - [`render`]: a small software rasteriser for the side-by-side renders;
//! - [`chart`]: line charts with `plotters` and an embedded font (also used by `ponq-train`
//!   for its loss curves).
//!
//! The `ponq-eval` program (`run`, `compare`, `check`, `mc`) is a thin command line over these.
//!
//! ```no_run
//! use ponq_eval::{EvalOptions, Method, evaluate, inputs};
//! let device = ponq_model::backend::cpu();
//! let (net, cfg) = ponq_infer::shipped::load(&device).unwrap();
//! let (shapes, _missing) = inputs("meshes/".as_ref(), None).unwrap();
//! let opts = EvalOptions {
//!     resolutions: vec![32],
//!     methods: vec![Method::Ponq, Method::Mc],
//!     coarsen: 0,
//!     merge_smooth: Some(15.0),
//!     small_tet_rule: Default::default(),
//!     samples: 100_000,
//!     renders: 0,
//!     tile: 0,
//!     name: "PoNQ".into(),
//! };
//! for (id, path) in &shapes {
//!     let (rows, _image) =
//!         evaluate(id, path, 32, &net, cfg.encoder_layers, &opts, &device, false).unwrap();
//!     println!("{rows:?}");
//! }
//! ```

pub mod broken;
pub mod chart;
pub mod evaluate;
pub mod fields;
pub mod inputs;
pub mod logs;
pub mod render;
pub mod report;

pub use evaluate::{EvalOptions, Method, evaluate};
pub use inputs::{Shape, group_of, inputs};
pub use report::{
    Row, read_rows, rows_path, summary_by_group, summary_markdown, write_report, write_rows,
};
