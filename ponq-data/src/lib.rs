//! # ponq-data
//!
//! From meshes to PoNQ inputs:
//! - [`normalize`]: the `[-1,1]` convention and its inverse;
//! - [`sampling`]: surface samples, and boundary samples for open surfaces;
//! - [`sdf`] + [`occupancy`]: exact signed distance grids (the network's input) and the
//!   ground-truth occupancy / "close" masks; [`repair`] of broken meshes before them, and
//!   [`fast_winding`], the sign of soups whose faces do not meet;
//! - [`condition`]: grids in other conventions (units, sign, iso-level, occupancy, tanh) read
//!   as signed distances; [`colour_transfer`]: colours from the input to the output;
//! - [`synth`]: seeded procedural CAD-like training shapes;
//! - [`dataset`] (the project's one-`.npz`-per-shape format, split files) and [`hdf5`] (the
//!   authors' preprocessed files); [`prep`] builds datasets (`ponq-prep`);
//! - [`fit`]: the optimisation-based PoNQ of the paper (points fitted to a sampled mesh with
//!   Adam on the Chamfer distance, then normals and quadrics per Voronoi cell; `ponq-fit`).
//!
//! ```no_run
//! use ponq_data::fit::{FitOptions, fit_mesh};
//! let mesh = ponq_mesh::io::read_mesh("part.obj")?;
//! let fitted = fit_mesh(&mesh, &FitOptions { grid: 32, ..Default::default() }, |_| {})?;
//! println!("{} points", fitted.ponq.len());
//! # Ok::<(), anyhow::Error>(())
//! ```

pub mod broken;
pub mod colour_transfer;
pub mod condition;
pub mod conventions;
pub mod dataset;
pub mod error;
pub mod fast_winding;
pub mod fit;
pub mod hdf5;
pub mod names;
pub mod normalize;
pub mod occupancy;
pub mod outputs;
pub mod prep;
pub mod records;
pub mod refine;
pub mod repair;
pub mod sampling;
pub mod sdf;
pub mod synth;

pub use error::{DataError, Result};
