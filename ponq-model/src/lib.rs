//! # ponq-model
//!
//! The PoNQ network on Burn: an SDF grid goes in, per cell `P` points with normals, quadrics
//! (`A = U U^T` and v*) and an occupancy come out ([`model`]); [`prediction`] turns that into
//! the [`ponq_mesh::Ponq`] that `ponq-mesh` meshes; [`weights`] saves / loads our burnpack
//! files and the authors' PyTorch state dict; [`backend`] picks the device (`flex` CPU by
//! default, `wgpu` with the cargo feature of that name); [`fast`] holds the fast CPU kernels
//! the network runs on by default on the CPU (custom Burn operations with their own backward).
//!
//! ```no_run
//! use burn::prelude::*;
//! use ponq_model::{GridFrame, PonqNetConfig, Prediction};
//! let device = ponq_model::backend::cpu();
//! let net = PonqNetConfig::new().with_width(32).init(&device);
//! let n = 8; // cells per side
//! let sdf = Tensor::<5>::zeros([1, 1, n + 1, n + 1, n + 1], &device);
//! let out = net.forward(sdf, &GridFrame::whole(n));
//! let pred = Prediction::from_output(&out, 0).unwrap();
//! let cells = pred.kept_cells(0.5, None).unwrap();
//! let (ponq, _cell_of_point) = pred.to_ponq(&cells).unwrap();
//! # let _ = ponq;
//! ```

pub mod activation;
pub mod backend;
pub mod error;
pub mod fast;
pub mod model;
pub mod prediction;
pub mod weights;
pub mod widen;

pub use error::{ModelError, Result};
pub use fast::Kernels;
pub use model::{GridFrame, PonqNet, PonqNetConfig, PonqOutput};
pub use prediction::Prediction;

/// Factor applied to an SDF (in `[-1,1]` units) of an `n`-cell grid before it enters the
/// network: `n / 32`, so the network always sees distances in the units it was trained on
/// (SPEC section 3).
pub fn network_input_scale(n: usize) -> f32 {
    n as f32 / 32.0
}
