//! Devices: the pure-Rust `flex` CPU backend (default) and, with the `wgpu` cargo feature,
//! the GPU through wgpu.

use burn::prelude::*;

/// Which backend to run on.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum BackendKind {
    /// Burn's `flex` CPU backend.
    Flex,
    /// wgpu (Vulkan / Metal / DX12); needs the `wgpu` cargo feature.
    Wgpu,
}

impl std::str::FromStr for BackendKind {
    type Err = String;
    fn from_str(s: &str) -> std::result::Result<Self, String> {
        match s.to_ascii_lowercase().as_str() {
            "flex" | "cpu" => Ok(Self::Flex),
            "wgpu" | "gpu" => Ok(Self::Wgpu),
            _ => Err(format!("unknown backend '{s}' (expected flex or wgpu)")),
        }
    }
}

/// The CPU device.
pub fn cpu() -> Device {
    Device::flex()
}

/// The device of `kind`; an error when `wgpu` was asked for but not compiled in.
pub fn device(kind: BackendKind) -> Result<Device, String> {
    match kind {
        BackendKind::Flex => Ok(cpu()),
        #[cfg(feature = "wgpu")]
        BackendKind::Wgpu => Ok(Device::wgpu(Default::default())),
        #[cfg(not(feature = "wgpu"))]
        BackendKind::Wgpu => {
            Err("this build has no GPU backend: rebuild with `--features wgpu`".to_string())
        }
    }
}
