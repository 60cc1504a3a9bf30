//! Loading the training shapes of a config (and generating procedural ones first when the
//! data folder is empty and `data.synth_count > 0`).

use anyhow::{Context, Result, bail};
use indicatif::ProgressBar;
use rayon::prelude::*;

use crate::config::TrainConfig;
use crate::data::{Shape, read_shape_with, shape_files};

/// Samples kept in memory per shape (crops draw their loss samples from these).
pub const MAX_SAMPLES_IN_MEMORY: usize = 200_000;

/// Generates `data.synth_count` procedural shapes into `data.dir` (skipping finished ones).
pub fn generate(cfg: &TrainConfig, quiet: bool) -> Result<()> {
    let d = &cfg.data;
    let jobs: Vec<ponq_data::prep::SynthJob> = (0..d.synth_count as u64)
        .map(|i| ponq_data::prep::SynthJob {
            seed: d.synth_seed + i,
            synth: ponq_data::synth::SynthOptions {
                mix: d.synth_mix.mix(),
                ..Default::default()
            },
        })
        .collect();
    let mut resolutions = vec![d.resolution];
    resolutions.extend(d.extra_resolutions.iter().filter(|&&r| r != d.resolution));
    let opts = ponq_data::prep::PrepOptions {
        resolutions,
        samples: d.synth_samples,
        ..Default::default()
    };
    if !quiet {
        eprintln!(
            "generating {} procedural shapes into {}",
            jobs.len(),
            d.dir.display()
        );
    }
    let pb = if quiet {
        ProgressBar::hidden()
    } else {
        ProgressBar::new(jobs.len() as u64)
    };
    let s = ponq_data::prep::run_batch(&jobs, &d.dir, &opts, || pb.inc(1))?;
    pb.finish_and_clear();
    if !quiet && !s.skipped.is_empty() {
        eprintln!(
            "{} generated shapes skipped: {:?}",
            s.skipped.len(),
            s.skipped
        );
    }
    Ok(())
}

/// `(training, validation)` shapes: sorted files of the folder; the last
/// `validation_shapes` are held aside.
pub fn load(cfg: &TrainConfig, quiet: bool) -> Result<(Vec<Shape>, Vec<Shape>)> {
    let d = &cfg.data;
    let empty = shape_files(&d.dir, None)
        .map(|f| f.is_empty())
        .unwrap_or(true);
    if empty {
        if d.synth_count == 0 {
            bail!(
                "no shape files (.npz / .hdf5) in {}; prepare some with `ponq-prep` or set data.synth_count",
                d.dir.display()
            );
        }
        generate(cfg, quiet)?;
    }
    let mut files = shape_files(&d.dir, d.split.as_deref())?;
    if files.len() < 2 && d.validation_shapes > 0 {
        bail!(
            "{} holds {} shapes: too few to hold some aside for validation",
            d.dir.display(),
            files.len()
        );
    }
    let nval = d.validation_shapes.min(files.len() / 2);
    let val_files = files.split_off(files.len() - nval);
    if d.max_shapes > 0 {
        files.truncate(d.max_shapes);
    }
    let pb = if quiet {
        ProgressBar::hidden()
    } else {
        ProgressBar::new((files.len() + val_files.len()) as u64)
    };
    pb.set_message("reading shapes");
    let read = |v: &[std::path::PathBuf]| -> Result<Vec<Shape>> {
        v.par_iter()
            .map(|p| {
                let s =
                    read_shape_with(p, d.resolution, &d.extra_resolutions, MAX_SAMPLES_IN_MEMORY);
                pb.inc(1);
                s
            })
            .collect::<Result<Vec<_>>>()
    };
    let train = read(&files).context("loading training shapes")?;
    let val = read(&val_files).context("loading validation shapes")?;
    pb.finish_and_clear();
    Ok((train, val))
}
