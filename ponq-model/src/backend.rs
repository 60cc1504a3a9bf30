//! Devices: the pure-Rust `flex` CPU backend (default), and with cargo features of the same
//! names the GPU through `wgpu` (Vulkan / Metal / DX12, or a software Vulkan driver such as
//! Mesa's lavapipe) and NVIDIA GPUs through `cuda` (the driver is loaded at run time: the
//! build needs no CUDA toolkit).
//!
//! [`device`] checks that the device actually works (one tiny tensor round trip) and turns a
//! missing driver or adapter into an error message instead of a panic deep inside a backend.

use burn::prelude::*;

/// Which backend to run on.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum BackendKind {
    /// Burn's `flex` CPU backend.
    Flex,
    /// wgpu (Vulkan / Metal / DX12); needs the `wgpu` cargo feature.
    Wgpu,
    /// CUDA; needs the `cuda` cargo feature and an NVIDIA driver at run time.
    Cuda,
}

impl std::str::FromStr for BackendKind {
    type Err = String;
    fn from_str(s: &str) -> std::result::Result<Self, String> {
        match s.to_ascii_lowercase().as_str() {
            "flex" | "cpu" => Ok(Self::Flex),
            "wgpu" | "gpu" => Ok(Self::Wgpu),
            "cuda" => Ok(Self::Cuda),
            _ => Err(format!(
                "unknown backend '{s}' (expected flex, wgpu or cuda)"
            )),
        }
    }
}

impl std::fmt::Display for BackendKind {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            Self::Flex => "flex",
            Self::Wgpu => "wgpu",
            Self::Cuda => "cuda",
        })
    }
}

/// The CPU device.
pub fn cpu() -> Device {
    Device::flex()
}

/// The device of `kind` (GPU index 0), checked to work: an error when its cargo feature is not
/// compiled in or when no driver / adapter answers.
pub fn device(kind: BackendKind) -> Result<Device, String> {
    device_at(kind, 0)
}

/// The device of `kind` with GPU index `index` (ignored for `flex`; for `wgpu` the index-th
/// discrete GPU when there is one, else the default adapter), checked to work.
pub fn device_at(kind: BackendKind, index: usize) -> Result<Device, String> {
    let dev = match kind {
        BackendKind::Flex => return Ok(cpu()),
        BackendKind::Wgpu => wgpu_device(index)?,
        BackendKind::Cuda => cuda_device(index)?,
    };
    probe(&dev).map_err(|e| format!("the {kind} device {index} does not work: {e}"))?;
    Ok(dev)
}

#[cfg(feature = "wgpu")]
fn wgpu_device(index: usize) -> Result<Device, String> {
    Ok(if index == 0 {
        Device::wgpu(Default::default())
    } else {
        Device::wgpu(burn::tensor::DeviceKind::DiscreteGpu(index))
    })
}

#[cfg(not(feature = "wgpu"))]
fn wgpu_device(_index: usize) -> Result<Device, String> {
    Err("this build has no wgpu backend: rebuild with `--features wgpu`".to_string())
}

#[cfg(feature = "cuda")]
fn cuda_device(index: usize) -> Result<Device, String> {
    Ok(Device::cuda(index))
}

#[cfg(not(feature = "cuda"))]
fn cuda_device(_index: usize) -> Result<Device, String> {
    Err("this build has no CUDA backend: rebuild with `--features cuda`".to_string())
}

/// One small tensor to the device and back. Backends panic when their driver is missing
/// (e.g. no `libcuda.so`, no Vulkan adapter); the panic is caught and becomes the error.
pub fn probe(dev: &Device) -> Result<(), String> {
    let dev = dev.clone();
    let hook = std::panic::take_hook();
    std::panic::set_hook(Box::new(|_| {}));
    let r = std::panic::catch_unwind(move || {
        let t = Tensor::<1>::from_floats([1.0f32, 2.0, 3.0], &dev);
        (t * 2.0).into_data().try_to_vec::<f32>()
    });
    std::panic::set_hook(hook);
    match r {
        Ok(Ok(v)) if v == [2.0, 4.0, 6.0] => Ok(()),
        Ok(Ok(v)) => Err(format!(
            "a test computation gave {v:?} instead of [2, 4, 6]"
        )),
        Ok(Err(e)) => Err(format!("{e:?}")),
        Err(p) => Err(p
            .downcast_ref::<String>()
            .cloned()
            .or_else(|| p.downcast_ref::<&str>().map(|s| s.to_string()))
            .unwrap_or_else(|| "the backend panicked".to_string())),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn backends_parse_and_missing_features_are_errors() {
        assert_eq!("flex".parse::<BackendKind>(), Ok(BackendKind::Flex));
        assert_eq!("CUDA".parse::<BackendKind>(), Ok(BackendKind::Cuda));
        assert!("metal".parse::<BackendKind>().is_err());
        assert!(device(BackendKind::Flex).is_ok());
        #[cfg(not(feature = "cuda"))]
        assert!(
            device(BackendKind::Cuda)
                .unwrap_err()
                .contains("--features cuda")
        );
        #[cfg(not(feature = "wgpu"))]
        assert!(
            device(BackendKind::Wgpu)
                .unwrap_err()
                .contains("--features wgpu")
        );
    }
}
