//! Turning meshes (or procedural shapes) into dataset records: normalise, sample, exact SDF
//! grids and occupancy at every requested resolution ([`prepare_mesh`]); and the resumable,
//! parallel batch driver behind `ponq-prep meshes` / `ponq-prep synth` ([`run_batch`]).

use std::path::{Path, PathBuf};
use std::sync::Mutex;
use std::time::{Duration, Instant};

use ponq_mesh::TriMesh;
use ponq_mesh::sampling::sample_surface;
use rayon::prelude::*;

use crate::dataset::ShapeRecord;
use crate::error::{DataError, Result};
use crate::normalize::Normalization;
use crate::occupancy::occupancy_from_samples;
use crate::records::{Record, RecordLog, Shard, Status};
use crate::sdf::MeshSdf;

/// Options of [`prepare_mesh`].
#[derive(Debug, Clone)]
pub struct PrepOptions {
    /// Grid resolutions (cells per side), e.g. `[32, 64, 128]`.
    pub resolutions: Vec<usize>,
    /// Surface samples per shape (the authors stored 1,000,000).
    pub samples: usize,
    /// Sampling seed.
    pub seed: u64,
    /// Repair meshes first ([`crate::repair`]; a clean mesh is used unchanged). `false`: the
    /// mesh as it is, an open one signed by its winding number with a warning.
    pub repair: bool,
}

impl Default for PrepOptions {
    fn default() -> Self {
        Self {
            resolutions: vec![32, 64],
            samples: 1_000_000,
            seed: 0,
            repair: true,
        }
    }
}

/// A prepared shape and a warning when its mesh is open (its SDF sign then comes from the
/// generalised winding number).
pub struct Prepared {
    /// The record.
    pub record: ShapeRecord,
    /// `Some(message)` for open or non-manifold input meshes, and for repaired ones.
    pub warning: Option<String>,
    /// What the repair found and did (meshes, with [`PrepOptions::repair`]).
    pub report: Option<crate::repair::DefectReport>,
    /// Seconds per stage, in order (`read`, `repair`, `sample`, `sdf <res>`, ...).
    pub times: Vec<(String, f64)>,
}

/// Exact analytic samples and their normals, in the `[-1,1]` frame.
pub type Analytic<'a> = (&'a [[f64; 3]], &'a [[f64; 3]]);

/// Prepares one mesh (in any frame): normalisation to `[-1,1]`, samples with normals, SDF
/// grids and occupancy at every resolution. `samples` / `normals` given (e.g. exact analytic
/// samples of a procedural shape, already in the `[-1,1]` frame) replace the mesh sampling.
pub fn prepare_mesh(
    mesh: &TriMesh,
    analytic: Option<Analytic<'_>>,
    opts: &PrepOptions,
) -> Result<Prepared> {
    if mesh.faces.is_empty() {
        return Err(DataError::Invalid("the mesh has no face".into()));
    }
    if opts.resolutions.is_empty() {
        return Err(DataError::Invalid("no grid resolution requested".into()));
    }
    let mut times = Vec::new();
    let mut clock = Instant::now();
    let mut lap = |name: String, times: &mut Vec<(String, f64)>| {
        times.push((name, clock.elapsed().as_secs_f64()));
        clock = Instant::now();
    };
    let repaired = if opts.repair && analytic.is_none() {
        Some(crate::repair::repair_with_solid(
            mesh,
            &crate::repair::RepairOptions::default(),
        )?)
    } else {
        None
    };
    let mesh = repaired.as_ref().map_or(mesh, |r| &r.mesh);
    let norm = Normalization::of(mesh)?;
    let m = norm.apply_mesh(mesh);
    lap("repair".into(), &mut times);
    let (points, normals) = match analytic {
        Some((p, n)) => (p.to_vec(), n.to_vec()),
        None => {
            let s = sample_surface(&m, opts.samples, opts.seed);
            (s.points, s.normals)
        }
    };
    lap("sample".into(), &mut times);
    if points.is_empty() {
        return Err(DataError::Invalid("the mesh has no area to sample".into()));
    }
    // Signed by the fast winding number where the repair could not prove a closed surface.
    let sdf = match &repaired {
        Some(r) => r.distances(&m)?,
        None => MeshSdf::new(&m)?,
    };
    // Where the repair removed faces, the closed surface they came from gives the sign.
    let solid = match repaired.as_ref().and_then(|r| r.solid.as_ref()) {
        Some(s) => Some(MeshSdf::new(&norm.apply_mesh(s))?),
        None => None,
    };
    let report = repaired.map(|r| r.report);
    let mut warning: Option<String> = sdf.is_open().then(|| {
        "the mesh is not closed: the SDF sign comes from the generalised winding number".into()
    });
    if let Some(r) = report.as_ref().filter(|r| r.found_defects()) {
        let line = r.to_string().replace('\n', "; ");
        warning = Some(match warning {
            Some(w) => format!("{line}; {w}"),
            None => line,
        });
    }
    let mut record = ShapeRecord {
        samples: points.iter().map(|p| p.map(|x| x as f32)).collect(),
        normals: normals.iter().map(|p| p.map(|x| x as f32)).collect(),
        ..Default::default()
    };
    for &res in &opts.resolutions {
        let g = sdf.grid_signed_by(solid.as_ref().unwrap_or(&sdf), res, |_| {})?;
        record.sdf.insert(res, g.values);
        record
            .occupancy
            .insert(res, occupancy_from_samples(&points, res)?);
        lap(format!("sdf {res}"), &mut times);
    }
    Ok(Prepared {
        record,
        warning,
        report,
        times,
    })
}

/// Exact boundary samples drawn for the exact distances of a generated shape (about 0.3 s;
/// their mean spacing on a typical part is 0.002).
pub const EXACT_DISTANCE_SAMPLES: usize = 1_000_000;

/// Prepares a generated shape: its exact samples (already in the `[-1,1]` frame) and SDF grids
/// of exact distances to its analytic boundary ([`crate::synth::distance`]), so that the grids
/// agree with the samples the losses use, not with the intermediate mesh.
pub fn prepare_synth(
    shape: &crate::synth::SynthShape,
    seed: u64,
    opts: &PrepOptions,
) -> Result<Prepared> {
    if opts.resolutions.is_empty() {
        return Err(DataError::Invalid("no grid resolution requested".into()));
    }
    if shape.samples.is_empty() {
        return Err(DataError::Invalid("the shape has no samples".into()));
    }
    let exact = crate::synth::distance::ExactDistance::new(
        &shape.solid,
        &shape.mesh,
        EXACT_DISTANCE_SAMPLES,
        seed ^ 0x5eed_d157,
    )
    .ok_or_else(|| DataError::Invalid("the shape's boundary cannot be sampled".into()))?;
    let mut record = ShapeRecord {
        samples: shape.samples.iter().map(|p| p.map(|x| x as f32)).collect(),
        normals: shape.normals.iter().map(|p| p.map(|x| x as f32)).collect(),
        ..Default::default()
    };
    for &res in &opts.resolutions {
        if !(1..=crate::sdf::MAX_RES).contains(&res) {
            return Err(DataError::Invalid(format!(
                "grid resolution {res} is outside 1..={}",
                crate::sdf::MAX_RES
            )));
        }
        record.sdf.insert(res, exact.grid(res));
        record
            .occupancy
            .insert(res, occupancy_from_samples(&shape.samples, res)?);
    }
    Ok(Prepared {
        record,
        warning: None,
        report: None,
        times: Vec::new(),
    })
}

/// One unit of work of a batch: an id (the output's name, [`crate::names`]) and how to make
/// its shape.
pub trait Job: Sync {
    /// The output's name: `OUT/<id>.npz` (it may hold `/`: sub-folders of the output).
    fn id(&self) -> String;
    /// Makes the record.
    fn run(&self, opts: &PrepOptions) -> Result<Prepared>;
    /// The input file, for the log ([`crate::records`]); empty when generated.
    fn input(&self) -> PathBuf {
        PathBuf::new()
    }
}

/// Where a batch logs and which part of it runs here.
#[derive(Default)]
pub struct BatchRun<'a> {
    /// Only the shapes of this shard ([`Shard::contains`] on the id).
    pub shard: Option<Shard>,
    /// One JSON line per shape (done, already there, or failed with its error).
    pub log: Option<&'a RecordLog>,
}

/// What a batch did.
#[derive(Debug, Default)]
pub struct BatchSummary {
    /// Shapes written in this run.
    pub done: Vec<String>,
    /// Shapes already present (resumed run).
    pub already: Vec<String>,
    /// Shapes skipped with the reason.
    pub skipped: Vec<(String, String)>,
    /// Warnings (written shapes with a remark).
    pub warnings: Vec<(String, String)>,
    /// Temporary files of crashed runs removed.
    pub stale_removed: usize,
    /// Wall time.
    pub time: Duration,
    /// Every shape's record, in the order they finished (as logged).
    pub records: Vec<Record>,
}

impl BatchSummary {
    /// Whether every shape of the run is done or was already there.
    pub fn all_done(&self) -> bool {
        self.skipped.is_empty()
    }
}

/// Runs `jobs` in parallel into `out_dir/<id>.npz`, skipping finished shapes (so a killed run
/// resumes), recording failures instead of stopping; `tick` is called after every job.
pub fn run_batch<J: Job>(
    jobs: &[J],
    out_dir: &Path,
    opts: &PrepOptions,
    tick: impl Fn() + Sync,
) -> Result<BatchSummary> {
    run_batch_with(jobs, out_dir, opts, &BatchRun::default(), tick)
}

/// [`run_batch`] on the jobs of `run.shard` only, each shape's [`Record`] appended to
/// `run.log` (a failure of the log itself stops the batch).
///
/// Outputs are written whole or not at all ([`crate::outputs`]); an output already there
/// counts as done only when it is whole (a cut one is redone, with a warning); temporary
/// files of crashed runs are removed as their shapes come up.
///
/// # Errors
/// Two jobs with one id (before any work), the output folder or the log cannot be written.
pub fn run_batch_with<J: Job>(
    jobs: &[J],
    out_dir: &Path,
    opts: &PrepOptions,
    run: &BatchRun<'_>,
    tick: impl Fn() + Sync,
) -> Result<BatchSummary> {
    let mut ids: Vec<String> = jobs.iter().map(Job::id).collect();
    ids.sort_unstable();
    if let Some(w) = ids.windows(2).find(|w| w[0] == w[1]) {
        return Err(DataError::Invalid(format!(
            "two shapes of the batch are named {:?}: their outputs would be one file",
            w[0]
        )));
    }
    std::fs::create_dir_all(out_dir).map_err(|e| ponq_mesh::Error::io(out_dir, e))?;
    let t = Instant::now();
    let stale = crate::outputs::StalePartials::find(out_dir);
    let summary = Mutex::new(BatchSummary::default());
    let log_error: Mutex<Option<DataError>> = Mutex::new(None);
    let push = |f: &dyn Fn(&mut BatchSummary)| {
        if let Ok(mut s) = summary.lock() {
            f(&mut s);
        }
    };
    let shards = run.shard.map_or(1, |s| s.count());
    let mine: Vec<&J> = jobs
        .iter()
        .filter(|j| run.shard.is_none_or(|s| s.contains(&j.id())))
        .collect();
    mine.par_iter().for_each(|job| {
        let id = job.id();
        let path = crate::names::output_path(out_dir, &id, "npz");
        let started = Instant::now();
        let removed = stale.remove_for(&path);
        if removed > 0 {
            push(&|s| s.stale_removed += removed);
        }
        let cut = path.exists() && !crate::outputs::is_whole(&path);
        let record = if !cut && path.is_file() {
            push(&|s| s.already.push(id.clone()));
            Record::new(&id, job.input(), Status::Already)
        } else {
            match job.run(opts).and_then(|p| {
                let w = Instant::now();
                if let Some(dir) = path.parent() {
                    std::fs::create_dir_all(dir).map_err(|e| ponq_mesh::Error::io(dir, e))?;
                }
                // Written under a temporary name and committed when whole: a killed run (or a
                // crashed machine) leaves no partial record that the next run would take as
                // done.
                let partial = crate::outputs::partial_path(&path);
                let written = p
                    .record
                    .write(&partial)
                    .and_then(|()| crate::outputs::commit(&partial, &path));
                if written.is_err() {
                    let _ = std::fs::remove_file(&partial);
                }
                written?;
                Ok((p, w.elapsed().as_secs_f64()))
            }) {
                Ok((mut p, write)) => {
                    if cut {
                        let w = "its output was cut (a run that crashed): redone".to_string();
                        p.warning = Some(match p.warning {
                            Some(x) => format!("{w}; {x}"),
                            None => w,
                        });
                    }
                    push(&|s| {
                        s.done.push(id.clone());
                        if let Some(w) = &p.warning {
                            s.warnings.push((id.clone(), w.clone()));
                        }
                    });
                    let mut r = Record::new(&id, job.input(), Status::Done);
                    r.stages = p.times;
                    r.stages.push(("write".into(), write));
                    r.warning = p.warning;
                    r.report = p.report.map(|x| x.to_json());
                    r
                }
                Err(e) => {
                    push(&|s| s.skipped.push((id.clone(), e.to_string())));
                    let mut r = Record::new(&id, job.input(), Status::Error);
                    r.error = Some(e.to_string());
                    r
                }
            }
        };
        let mut record = record;
        record.shards = shards;
        record.seconds = started.elapsed().as_secs_f64();
        if let Some(log) = run.log
            && let Err(e) = log.write(&record)
            && let Ok(mut slot) = log_error.lock()
        {
            *slot = Some(e);
        }
        push(&|s| s.records.push(record.clone()));
        tick();
    });
    if let Some(e) = log_error.into_inner().ok().flatten() {
        return Err(e);
    }
    let mut s = summary
        .into_inner()
        .map_err(|_| DataError::Invalid("a worker panicked".into()))?;
    s.done.sort();
    s.already.sort();
    s.skipped.sort();
    s.warnings.sort();
    s.time = t.elapsed();
    Ok(s)
}

/// A mesh file to prepare, and its output's name ([`mesh_jobs`] names a whole batch).
pub struct MeshJob {
    /// The mesh file.
    pub path: PathBuf,
    /// The output's name ([`crate::names::output_names`] of the batch's files).
    pub name: String,
}

/// The jobs of a batch of mesh files below the dataset's folder `root`, named by
/// [`crate::names::output_names`].
///
/// # Errors
/// Two files that would share an output (they differ by their extension or letter case
/// only).
pub fn mesh_jobs(files: Vec<PathBuf>, root: &Path) -> Result<Vec<MeshJob>> {
    let names = crate::names::output_names(&files, root)?;
    Ok(files
        .into_iter()
        .zip(names)
        .map(|(path, name)| MeshJob { path, name })
        .collect())
}

impl Job for MeshJob {
    fn id(&self) -> String {
        self.name.clone()
    }
    fn run(&self, opts: &PrepOptions) -> Result<Prepared> {
        let t = Instant::now();
        let mesh = ponq_mesh::io::read_mesh(&self.path)?;
        let read = t.elapsed().as_secs_f64();
        let mut p = prepare_mesh(&mesh, None, opts)?;
        p.times.insert(0, ("read".into(), read));
        Ok(p)
    }
    fn input(&self) -> PathBuf {
        self.path.clone()
    }
}

/// A procedural shape (seed) to generate and prepare, with its exact analytic samples.
pub struct SynthJob {
    /// Seed of the shape.
    pub seed: u64,
    /// Generator options.
    pub synth: crate::synth::SynthOptions,
}

impl Job for SynthJob {
    fn id(&self) -> String {
        format!("synth_{:08}", self.seed)
    }
    fn run(&self, opts: &PrepOptions) -> Result<Prepared> {
        let mut so = self.synth.clone();
        so.samples = opts.samples;
        let s = crate::synth::generate(self.seed, &so)?;
        prepare_synth(&s, self.seed, opts)
    }
}

/// The root of a batch's inputs (their names are their paths below it,
/// [`crate::names`]): the folder itself, or the folder of a list file.
pub fn input_root(dir_or_list: &Path) -> PathBuf {
    if dir_or_list.is_dir() {
        dir_or_list.to_path_buf()
    } else {
        dir_or_list.parent().unwrap_or(Path::new("")).to_path_buf()
    }
}

/// Mesh files of a folder (obj/ply/off/stl, sorted) or listed in a text file (one path per
/// line, relative to the list's folder).
pub fn mesh_inputs(dir_or_list: &Path) -> Result<Vec<PathBuf>> {
    input_files(dir_or_list, |p| {
        p.extension().and_then(|e| e.to_str()).is_some_and(|e| {
            matches!(
                e.to_ascii_lowercase().as_str(),
                "obj" | "ply" | "off" | "stl"
            )
        })
    })
}

/// The files of a folder (searched recursively) that `accept` takes, or the paths listed in a
/// text file (one per line, relative to the list's folder; `#` starts a comment line), sorted.
///
/// # Errors
/// A folder or list that cannot be read.
pub fn input_files(dir_or_list: &Path, accept: impl Fn(&Path) -> bool) -> Result<Vec<PathBuf>> {
    let io = |e| ponq_mesh::Error::io(dir_or_list, e);
    let mut out = Vec::new();
    if dir_or_list.is_dir() {
        let mut stack = vec![dir_or_list.to_path_buf()];
        while let Some(d) = stack.pop() {
            for e in std::fs::read_dir(&d).map_err(io)? {
                let p = e.map_err(io)?.path();
                if p.is_dir() {
                    stack.push(p);
                } else if accept(&p) {
                    out.push(p);
                }
            }
        }
    } else {
        let text = std::fs::read_to_string(dir_or_list).map_err(io)?;
        let base = dir_or_list.parent().unwrap_or(Path::new("."));
        for l in text
            .lines()
            .map(str::trim)
            .filter(|l| !l.is_empty() && !l.starts_with('#'))
        {
            out.push(base.join(l));
        }
    }
    out.sort();
    Ok(out)
}
