//! Training configuration: a TOML file with `[model]`, `[data]`, `[train]` and `[loss]`
//! tables (see `configs/*.toml`). Every field has a default, so a config only states what
//! differs from the paper's phase 1.

use std::path::{Path, PathBuf};

use anyhow::{Context, Result, bail};
use ponq_model::PonqNetConfig;
use serde::{Deserialize, Serialize};

/// The whole configuration of a run.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct TrainConfig {
    /// Network shape.
    pub model: ModelSection,
    /// Training data.
    pub data: DataSection,
    /// Optimisation.
    pub train: TrainSection,
    /// Loss weights.
    pub loss: LossWeights,
}

/// `[model]`: the network (see [`PonqNetConfig`]).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct ModelSection {
    /// Feature channels (paper 128).
    pub width: usize,
    /// Points per cell (paper 4).
    pub points_per_cell: usize,
    /// Kernel-3 encoder convolutions (paper 5).
    pub encoder_layers: usize,
    /// Residual blocks per decoder (paper 3).
    pub decoder_blocks: usize,
}

impl Default for ModelSection {
    fn default() -> Self {
        Self {
            width: 128,
            points_per_cell: 4,
            encoder_layers: 5,
            decoder_blocks: 3,
        }
    }
}

impl ModelSection {
    /// The network config.
    pub fn net(&self) -> PonqNetConfig {
        PonqNetConfig::new()
            .with_width(self.width)
            .with_points_per_cell(self.points_per_cell)
            .with_encoder_layers(self.encoder_layers)
            .with_decoder_blocks(self.decoder_blocks)
    }
}

/// `[data]`: where shapes come from.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct DataSection {
    /// Folder of shape files: our `.npz` records (`ponq-prep`) or the authors' `.hdf5`.
    /// Relative paths are relative to the config file.
    pub dir: PathBuf,
    /// Optional split file (one id per line) selecting the training shapes in `dir`.
    pub split: Option<PathBuf>,
    /// Exclusion split: a file of ids (one per line) this run must never train or validate
    /// on, e.g. the evaluation shapes; a run whose data holds one of them stops with an error
    /// naming it. Relative to the config file.
    pub exclude: Option<PathBuf>,
    /// When `dir` holds no shape: generate this many procedural shapes into it first.
    pub synth_count: usize,
    /// Relative frequencies of the generated shape families (see `ponq_data::synth::SynthMix`):
    /// `synth_mix = { csg = 0.4, filleted = 0.25, lathe = 0.15, freeform = 0.2 }`; CSG parts
    /// only by default.
    pub synth_mix: SynthMixSection,
    /// First seed of the generated shapes.
    pub synth_seed: u64,
    /// Surface samples stored per generated shape.
    pub synth_samples: usize,
    /// Grid resolution (cells per side) trained and validated on.
    pub resolution: usize,
    /// More resolutions trained on (the records must hold these grids; generated shapes get
    /// them): a batch is cut from one of them with probability `extra_weight`, so the
    /// network sees the cell sizes it is used at.
    pub extra_resolutions: Vec<usize>,
    /// Share of batches cut from the `extra_resolutions` grids (0.5).
    pub extra_weight: f64,
    /// Shapes held aside for validation (the last ones in sorted order).
    pub validation_shapes: usize,
    /// Use at most this many training shapes (0: all).
    pub max_shapes: usize,
}

impl Default for DataSection {
    fn default() -> Self {
        Self {
            dir: PathBuf::from("data/synth32"),
            split: None,
            exclude: None,
            synth_count: 0,
            synth_mix: SynthMixSection::default(),
            synth_seed: 1000,
            synth_samples: 200_000,
            resolution: 32,
            extra_resolutions: Vec::new(),
            extra_weight: 0.5,
            validation_shapes: 16,
            max_shapes: 0,
        }
    }
}

/// `data.synth_mix`: relative frequencies of the generated shape families.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct SynthMixSection {
    /// Sharp-edged CSG parts.
    pub csg: f64,
    /// CSG features on filleted bases.
    pub filleted: f64,
    /// Turned parts.
    pub lathe: f64,
    /// Free-form bodies.
    pub freeform: f64,
}

impl Default for SynthMixSection {
    fn default() -> Self {
        let m = ponq_data::synth::SynthMix::default();
        Self {
            csg: m.csg,
            filleted: m.filleted,
            lathe: m.lathe,
            freeform: m.freeform,
        }
    }
}

impl SynthMixSection {
    /// The generator's form.
    pub fn mix(&self) -> ponq_data::synth::SynthMix {
        ponq_data::synth::SynthMix {
            csg: self.csg,
            filleted: self.filleted,
            lathe: self.lathe,
            freeform: self.freeform,
        }
    }
}

/// `[train]`: the optimisation.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct TrainSection {
    /// Epochs (passes over the training shapes).
    pub epochs: usize,
    /// Shapes per step.
    pub batch_size: usize,
    /// Split each batch into this many micro-batches, run one after the other on one device
    /// with their gradients summed (same step as the whole batch, less memory; 1: none).
    pub micro_batches: usize,
    /// Learning rate.
    pub lr: f64,
    /// Step decay of the learning rate: `[[epoch, factor], ...]`, from epoch `epoch` on
    /// (counted from 0, as in `metrics.csv`'s epoch - 1) the rate is `lr * factor` (the
    /// last step reached applies). Empty: constant.
    pub lr_steps: Vec<(usize, f64)>,
    /// AdamW decoupled weight decay.
    pub weight_decay: f64,
    /// AMSGrad variant of AdamW.
    pub amsgrad: bool,
    /// Global gradient-norm clipping (0: none).
    pub grad_clip: f64,
    /// Surface samples per shape (per crop) and step.
    pub samples_per_shape: usize,
    /// Cells per side of the random crops (0: the whole grid).
    pub crop: usize,
    /// Random 90-degree rotations and flips.
    pub augment: bool,
    /// Seed of everything random in the run (initial weights aside: Burn seeds those).
    pub seed: u64,
    /// Start from this checkpoint's weights (the previous phase); relative to the config. A
    /// network that differs from `[model]` only by a smaller width is widened to it
    /// (Net2Wider: it starts with the same outputs; `ponq_model::widen`).
    pub init_from: Option<PathBuf>,
    /// Validation losses every this many epochs (0: never).
    pub validate_every: usize,
    /// Meshed validation (CD / NC / EF1) every this many epochs (0: never).
    pub mesh_validate_every: usize,
    /// Shapes meshed in a meshed validation.
    pub mesh_validate_shapes: usize,
    /// Stop after this many minutes (0: no limit); the checkpoint of the last finished epoch
    /// stays.
    pub time_limit_minutes: f64,
}

impl TrainSection {
    /// The learning rate of epoch `epoch` (from 0): `lr` times the factor of the last step of
    /// `lr_steps` at or before it.
    pub fn lr_at(&self, epoch: usize) -> f64 {
        self.lr
            * self
                .lr_steps
                .iter()
                .rev()
                .find(|&&(e, _)| e <= epoch)
                .map_or(1.0, |&(_, f)| f)
    }
}

impl Default for TrainSection {
    fn default() -> Self {
        Self {
            epochs: 200,
            batch_size: 16,
            micro_batches: 1,
            lr_steps: Vec::new(),
            lr: 6.4e-5,
            weight_decay: 0.01,
            amsgrad: true,
            grad_clip: 1.0,
            samples_per_shape: 500_000,
            crop: 0,
            augment: false,
            seed: 0,
            init_from: None,
            validate_every: 1,
            mesh_validate_every: 10,
            mesh_validate_shapes: 4,
            time_limit_minutes: 0.0,
        }
    }
}

/// `[loss]`: weights of the six terms (SPEC section 5).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct LossWeights {
    /// Squared Chamfer distance.
    pub cd: f64,
    /// Normals.
    pub normals: f64,
    /// Quadric matrices `A`.
    pub a: f64,
    /// v* along the sample normal.
    pub vstar: f64,
    /// v* regularisation.
    pub reg: f64,
    /// Occupancy.
    pub occ: f64,
    /// Occupancy margin: the authors' `relu((o - gt)^2 - margin)` (0: plain squared error).
    pub occ_margin: f64,
}

impl Default for LossWeights {
    fn default() -> Self {
        Self {
            cd: 100.0,
            normals: 0.1,
            a: 0.1,
            vstar: 100.0,
            reg: 100.0,
            occ: 0.1,
            occ_margin: 0.01,
        }
    }
}

impl TrainConfig {
    /// Reads and checks a config; relative paths become relative to the file's folder.
    pub fn load(path: &Path) -> Result<Self> {
        let text = std::fs::read_to_string(path)
            .with_context(|| format!("cannot read config {}", path.display()))?;
        let mut c: TrainConfig =
            toml::from_str(&text).with_context(|| format!("invalid config {}", path.display()))?;
        let base = path.parent().unwrap_or(Path::new("."));
        let rel = |p: &Path| base.join(p); // `join` keeps absolute paths as they are
        c.data.dir = base.join(&c.data.dir);
        c.data.split = c.data.split.as_deref().map(rel);
        c.data.exclude = c.data.exclude.as_deref().map(rel);
        c.train.init_from = c.train.init_from.as_deref().map(rel);
        c.check()?;
        Ok(c)
    }

    /// The ids of the exclusion split (`data.exclude`), empty without one.
    pub fn excluded_ids(&self) -> Result<std::collections::HashSet<String>> {
        match &self.data.exclude {
            None => Ok(Default::default()),
            Some(p) => Ok(ponq_data::dataset::read_split(p)
                .with_context(|| format!("cannot read the exclusion split {}", p.display()))?
                .into_iter()
                .collect()),
        }
    }

    /// Checks value ranges.
    pub fn check(&self) -> Result<()> {
        let t = &self.train;
        if t.epochs == 0 || t.batch_size == 0 || t.samples_per_shape == 0 {
            bail!("train.epochs, train.batch_size and train.samples_per_shape must be positive");
        }
        if t.micro_batches == 0 || t.micro_batches > t.batch_size {
            bail!(
                "train.micro_batches must be between 1 and train.batch_size ({}), got {}",
                t.batch_size,
                t.micro_batches
            );
        }
        if !(t.lr > 0.0 && t.lr.is_finite()) {
            bail!("train.lr must be positive, got {}", t.lr);
        }
        if t.lr_steps.windows(2).any(|w| w[0].0 >= w[1].0)
            || t.lr_steps.iter().any(|&(_, f)| !(f > 0.0 && f.is_finite()))
        {
            bail!(
                "train.lr_steps must list increasing epochs with positive factors, got {:?}",
                t.lr_steps
            );
        }
        if self.data.resolution < 2 {
            bail!("data.resolution must be at least 2");
        }
        if t.crop > self.data.resolution {
            bail!(
                "train.crop ({}) exceeds data.resolution ({})",
                t.crop,
                self.data.resolution
            );
        }
        if let Some(&r) = self
            .data
            .extra_resolutions
            .iter()
            .find(|&&r| r < 2 || r < t.crop)
        {
            bail!(
                "data.extra_resolutions: {r} is below 2 or below train.crop ({})",
                t.crop
            );
        }
        self.data
            .synth_mix
            .mix()
            .check()
            .map_err(|e| anyhow::anyhow!("data.synth_mix: {e}"))?;
        if !(0.0..=1.0).contains(&self.data.extra_weight) {
            bail!(
                "data.extra_weight must be in [0, 1], got {}",
                self.data.extra_weight
            );
        }
        let m = &self.model;
        if m.width == 0 || m.points_per_cell == 0 {
            bail!("model.width and model.points_per_cell must be positive");
        }
        let w = &self.loss;
        for (name, v) in [
            ("cd", w.cd),
            ("normals", w.normals),
            ("a", w.a),
            ("vstar", w.vstar),
            ("reg", w.reg),
            ("occ", w.occ),
            ("occ_margin", w.occ_margin),
        ] {
            if !(v >= 0.0 && v.is_finite()) {
                bail!("loss.{name} must be a non-negative number, got {v}");
            }
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn lr_steps_parse_apply_and_are_checked() {
        let mut cfg: TrainConfig =
            toml::from_str("[train]\nlr = 1e-3\nlr_steps = [[10, 0.3], [20, 0.1]]\n").unwrap();
        let t = &cfg.train;
        assert_eq!(t.lr_steps, vec![(10, 0.3), (20, 0.1)]);
        assert_eq!(t.lr_at(0), 1e-3);
        assert_eq!(t.lr_at(9), 1e-3);
        assert!((t.lr_at(10) - 3e-4).abs() < 1e-12);
        assert!((t.lr_at(19) - 3e-4).abs() < 1e-12);
        assert!((t.lr_at(500) - 1e-4).abs() < 1e-12);
        assert!(cfg.check().is_ok());
        cfg.train.lr_steps = vec![(20, 0.3), (10, 0.1)];
        assert!(cfg.check().unwrap_err().to_string().contains("lr_steps"));
        cfg.train.lr_steps = vec![(10, 0.0)];
        assert!(cfg.check().is_err());
    }
}
