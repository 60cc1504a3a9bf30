//! The model shipped in the repository's `models/` folder (`ponq-cpu.bpk` + `.json`, trained
//! with `configs/cpu-w64.toml` from the width-48 model of `configs/cpu-w48.toml`; see
//! `models/README.md`). It is also built into the programs, so an
//! installed `ponq-infer` needs no file beside it.

use std::path::PathBuf;

use anyhow::{Context, Result};
use burn::prelude::*;
use ponq_model::{PonqNet, PonqNetConfig};

/// File name of the shipped model.
pub const SHIPPED: &str = "ponq-cpu.bpk";

/// The shipped weights and config, built into the program.
const EMBEDDED_WEIGHTS: &[u8] = include_bytes!("../../models/ponq-cpu.bpk");
const EMBEDDED_CONFIG: &str = include_str!("../../models/ponq-cpu.json");

/// Files that replace the built-in model when present: `$PONQ_MODEL`, then `models/` of the
/// source tree this program was built from (so a retrained model is picked up without a
/// rebuild).
pub fn candidates() -> Vec<PathBuf> {
    let mut v = Vec::new();
    if let Some(p) = std::env::var_os("PONQ_MODEL") {
        v.push(PathBuf::from(p));
    }
    v.push(
        PathBuf::from(env!("CARGO_MANIFEST_DIR"))
            .join("../models")
            .join(SHIPPED),
    );
    v
}

/// Loads the shipped model: `$PONQ_MODEL` if set (an error if it cannot be read), else the
/// source tree's `models/ponq-cpu.bpk` if present, else the built-in copy.
pub fn load(device: &Device) -> Result<(PonqNet, PonqNetConfig)> {
    if let Some(p) = std::env::var_os("PONQ_MODEL") {
        let p = PathBuf::from(p);
        return ponq_model::weights::load(&p, device)
            .with_context(|| format!("PONQ_MODEL={}", p.display()));
    }
    for p in candidates() {
        if p.is_file() {
            return Ok(ponq_model::weights::load(&p, device)?);
        }
    }
    embedded(device)
}

/// Loads the copy of the shipped model built into the program.
pub fn embedded(device: &Device) -> Result<(PonqNet, PonqNetConfig)> {
    Ok(ponq_model::weights::load_bytes(
        EMBEDDED_WEIGHTS,
        EMBEDDED_CONFIG,
        device,
    )?)
}
