//! The fast CPU path of the network: custom Burn operations with hand-written backward passes
//! for the layers that cost the time, on channels-last activations from the encoder's first
//! layer to the decoder heads (no layout conversion per layer).
//!
//! - [`kernels`]: the `f32` kernels on slices (im2col GEMM convolutions and 1x1x1 GEMMs with
//!   bias, LeakyReLU and the residual add fused; their backward passes);
//! - [`ops`]: those kernels as a Burn backend extension for `flex` and `Autodiff<flex>`, and
//!   the `Tensor` wrappers the network calls;
//! - [`sparse`]: the encoder at the cells near the surface only (inference).
//!
//! [`Kernels`] selects the path; `PonqNet` uses the fast one on the CPU (`flex`) device unless
//! told otherwise, and Burn's stock `Conv3d` layers on any other device (GPU backends). Both
//! give the same numbers within float rounding (tested).

pub mod kernels;
pub mod ops;
pub mod sparse;

use burn::prelude::*;

/// Which implementation of the network's layers runs on the CPU.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Kernels {
    /// The fast CPU kernels ([`ops`]) on the `flex` device; stock layers elsewhere.
    #[default]
    Fast,
    /// Burn's stock `Conv3d` layers everywhere.
    Stock,
}

impl std::str::FromStr for Kernels {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        match s.to_ascii_lowercase().as_str() {
            "fast" => Ok(Self::Fast),
            "stock" => Ok(Self::Stock),
            _ => Err(format!("unknown kernels '{s}' (expected fast or stock)")),
        }
    }
}

impl std::fmt::Display for Kernels {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            Self::Fast => "fast",
            Self::Stock => "stock",
        })
    }
}

/// Whether the fast kernels can run on `device`: the `flex` CPU device, with or without
/// autodiff.
pub fn supports(device: &Device) -> bool {
    matches!(
        device.clone().inner().as_dispatch(),
        burn::backend::DispatchDevice::Flex(_)
    )
}
