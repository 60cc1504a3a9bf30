//! Saving and loading weights: our own burnpack files (`.bpk` with the config beside it as
//! `.json`) and the authors' PyTorch state dict (`pretrained_PoNQ_ABC.pt`).

use std::path::{Path, PathBuf};

use burn::module::Module;
use burn::prelude::*;
use burn::store::{ModuleSnapshot, PytorchStore};

use crate::error::{ModelError, Result};
use crate::model::{PonqNet, PonqNetConfig};

fn werr(path: &Path, message: impl ToString) -> ModelError {
    ModelError::Weights {
        path: path.display().to_string(),
        message: message.to_string(),
    }
}

/// The config file that goes with a weights file: same name, extension `.json`.
pub fn config_path(weights: &Path) -> PathBuf {
    weights.with_extension("json")
}

/// Writes `model` to `path` (burnpack) and its config to [`config_path`]`(path)`; both are
/// written to temporary names and renamed, so a crash never leaves a torn pair behind.
pub fn save(model: &PonqNet, config: &PonqNetConfig, path: &Path) -> Result<()> {
    let tmp = path.with_extension("bpk.tmp");
    model
        .clone()
        .save_file(&tmp)
        .map_err(|e| werr(path, format!("{e:?}")))?;
    // burnpack may append its own extension.
    let written = if tmp.exists() {
        tmp.clone()
    } else {
        tmp.with_extension("tmp.bpk")
    };
    let cfg_tmp = path.with_extension("json.tmp");
    config.save(&cfg_tmp).map_err(|e| werr(&cfg_tmp, e))?;
    std::fs::rename(&written, path).map_err(|e| werr(path, e))?;
    std::fs::rename(&cfg_tmp, config_path(path)).map_err(|e| werr(path, e))?;
    Ok(())
}

/// Reads a network saved by [`save`]: the config from [`config_path`]`(path)`, the weights
/// from `path`.
pub fn load(path: &Path, device: &Device) -> Result<(PonqNet, PonqNetConfig)> {
    if !path.is_file() {
        return Err(werr(path, "no such file"));
    }
    let cfg_path = config_path(path);
    let config = PonqNetConfig::load(&cfg_path)
        .map_err(|e| werr(&cfg_path, format!("cannot read the model config: {e}")))?;
    let model = config
        .init(device)
        .try_load_file(path)
        .map_err(|e| werr(path, format!("{e:?}")))?;
    Ok((model, config))
}

/// Key renames from the authors' `CNN_3d_multiple_split` state dict to [`PonqNet`]:
/// `encoder.0` is the kernel-2 input conv, `encoder.2k+2` the k-th kernel-3 conv (odd
/// indices are the LeakyReLUs); each decoder is `decoder.{0,1,2}` residual blocks and
/// `decoder.3` the head.
pub fn authors_key_remapping(
    encoder_layers: usize,
    decoder_blocks: usize,
) -> Vec<(String, String)> {
    let mut m = vec![(r"^encoder\.0\.".to_string(), "input.".to_string())];
    for k in 0..encoder_layers {
        m.push((
            format!(r"^encoder\.{}\.", 2 * k + 2),
            format!("encoder.{k}."),
        ));
    }
    m.push((
        format!(r"^(decoder_\w+)\.decoder\.{decoder_blocks}\."),
        "$1.head.".to_string(),
    ));
    m.push((
        r"^(decoder_\w+)\.decoder\.(\d+)\.".to_string(),
        "$1.blocks.$2.".to_string(),
    ));
    for (from, to) in [
        ("decoder_As", "decoder_cholesky"),
        ("decoder_mean_normals", "decoder_normals"),
        ("decoder_bools", "decoder_occupancy"),
    ] {
        m.push((format!(r"^{from}\."), format!("{to}.")));
    }
    m
}

/// Loads the authors' PyTorch weights (`torch.save(model.state_dict())`, optionally nested
/// under `state_dict`) into a network of `config` (the paper's config for their file).
/// Every parameter must be present with the right shape.
pub fn load_authors_state_dict(
    path: &Path,
    config: &PonqNetConfig,
    device: &Device,
) -> Result<PonqNet> {
    if !path.is_file() {
        return Err(werr(path, "no such file"));
    }
    let mut store = PytorchStore::from_file(path)
        .allow_partial(false)
        .validate(true);
    for (from, to) in authors_key_remapping(config.encoder_layers, config.decoder_blocks) {
        store = store.with_key_remapping(from, to);
    }
    let mut model = config.init(device);
    let result = model
        .load_from(&mut store)
        .map_err(|e| werr(path, format!("{e:?}")))?;
    if !result.missing.is_empty() {
        return Err(werr(path, format!("missing tensors: {:?}", result.missing)));
    }
    if !result.errors.is_empty() {
        return Err(werr(path, format!("{:?}", result.errors)));
    }
    Ok(model)
}

/// Reads a network from the bytes of a burnpack file and the JSON text of its config (for
/// a model embedded in a binary).
pub fn load_bytes(
    weights: &[u8],
    config_json: &str,
    device: &Device,
) -> Result<(PonqNet, PonqNetConfig)> {
    let here = Path::new("<embedded model>");
    let config: PonqNetConfig =
        serde_json::from_str(config_json).map_err(|e| werr(here, format!("config: {e}")))?;
    let record = burn::store::ModuleRecord::from_bytes(burn::tensor::Bytes::from_bytes_vec(
        weights.to_vec(),
    ))
    .map_err(|e| werr(here, format!("{e:?}")))?;
    let model = config
        .init(device)
        .try_load_record(record)
        .map_err(|e| werr(here, format!("{e:?}")))?;
    Ok((model, config))
}
