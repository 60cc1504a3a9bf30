//! The fast CPU path of the network: custom Burn operations with hand-written backward passes
//! for the layers that cost the time, on channels-last activations from the encoder's first
//! layer to the decoder heads (no layout conversion per layer).
//!
//! - [`kernels`]: the kernels on slices (im2col GEMM convolutions and their backward passes;
//!   1x1x1 layers one at a time, the baseline `kernel_bench` times the fused decoders
//!   against), f32 or bf16 GEMMs;
//! - [`decoders`]: the five decoders fused per row tile of the shared features (their first
//!   layers as one GEMM; the backward pass recomputes a tile's activations in cache);
//! - [`bf16`]: the bf16 GEMM with f32 sums (AMX or AVX-512 BF16, runtime detected);
//! - [`ops`]: those kernels as a Burn backend extension for `flex` and `Autodiff<flex>`, and
//!   the `Tensor` wrappers the network calls;
//! - [`sparse`]: the encoder at the cells near the surface only (inference).
//!
//! [`Kernels`] selects the path; `PonqNet` uses the fast one on the CPU (`flex`) device unless
//! told otherwise, and Burn's stock `Conv3d` layers on any other device (GPU backends). Both
//! give the same numbers within float rounding (tested).

pub mod bf16;
pub mod decoders;
pub mod kernels;
pub mod ops;
pub mod sparse;
#[cfg(test)]
mod testing;
pub mod winograd;

use burn::prelude::*;

/// Which implementation of the network's layers runs on the CPU.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Kernels {
    /// The fast CPU kernels ([`ops`]) on the `flex` device; stock layers elsewhere.
    #[default]
    Fast,
    /// Burn's stock `Conv3d` layers everywhere.
    Stock,
    /// The fast CPU kernels with bf16 GEMM inputs and f32 sums
    /// ([`kernels::Precision::Bf16`]); needs AVX-512 BF16 ([`bf16::available`]), else the f32
    /// kernels run. Stock layers off the CPU.
    FastBf16,
}

impl Kernels {
    /// Whether this selects the fast CPU kernels (in either precision).
    pub fn is_fast(self) -> bool {
        matches!(self, Self::Fast | Self::FastBf16)
    }

    /// The GEMM precision of the fast kernels.
    pub fn precision(self) -> kernels::Precision {
        match self {
            Self::FastBf16 => kernels::Precision::Bf16,
            _ => kernels::Precision::F32,
        }
    }

    /// An error naming the missing CPU feature when this selection cannot run as asked here
    /// (`fast-bf16` without AVX-512 BF16); `None` when it can.
    pub fn unsupported_here(self) -> Option<String> {
        (self == Self::FastBf16 && !bf16::available()).then(|| {
            "--kernels fast-bf16 needs a CPU with AMX-BF16 or AVX-512 BF16 (avx512_bf16); this \
             one has neither: use fast"
                .to_string()
        })
    }
}

impl std::str::FromStr for Kernels {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        match s.to_ascii_lowercase().as_str() {
            "fast" => Ok(Self::Fast),
            "stock" => Ok(Self::Stock),
            "fast-bf16" | "bf16" => Ok(Self::FastBf16),
            _ => Err(format!(
                "unknown kernels '{s}' (expected fast, fast-bf16 or stock)"
            )),
        }
    }
}

impl std::fmt::Display for Kernels {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            Self::Fast => "fast",
            Self::Stock => "stock",
            Self::FastBf16 => "fast-bf16",
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
