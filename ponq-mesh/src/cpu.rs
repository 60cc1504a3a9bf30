//! Runtime CPU features: the one place the hand-vectorised paths ask whether they may run.
//!
//! The AVX2 paths (the Delaunay's walk and conflict lanes, the Hilbert keys, the tagging's
//! lanes, the flips' quadric lanes) are compiled with `#[target_feature(enable = "avx2")]`
//! next to a portable version of the same code, and chosen at run time: never with
//! `-C target-cpu=native`. Each gives the same results as its portable version (tested
//! lane by lane; the meshes are the same byte for byte).

use std::sync::OnceLock;

/// Whether the AVX2 paths run: on x86-64 CPUs with AVX2, unless the environment variable
/// `PONQ_NO_AVX2` is set (to anything but `0` or an empty value), which forces the portable
/// code everywhere (to test it, or to compare with it, on an AVX2 machine). Read once per
/// process.
///
/// ```
/// // Where this is true, the CPU has AVX2 (the `unsafe` AVX2 paths rely on it).
/// #[cfg(target_arch = "x86_64")]
/// assert!(!ponq_mesh::cpu::has_avx2() || std::arch::is_x86_feature_detected!("avx2"));
/// ```
pub fn has_avx2() -> bool {
    static AVX2: OnceLock<bool> = OnceLock::new();
    *AVX2.get_or_init(|| {
        let off = std::env::var_os("PONQ_NO_AVX2").is_some_and(|v| !v.is_empty() && v != "0");
        #[cfg(target_arch = "x86_64")]
        let cpu = std::arch::is_x86_feature_detected!("avx2");
        #[cfg(not(target_arch = "x86_64"))]
        let cpu = false;
        cpu && !off
    })
}
