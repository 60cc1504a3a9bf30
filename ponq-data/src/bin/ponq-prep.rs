//! `ponq-prep`: turn meshes into PoNQ training / evaluation data.
//!
//! Subcommands: `sdf` (an exact signed distance grid as a `.npy` file), `meshes` and `synth`
//! (dataset records, see `ponq_data::dataset`), `break` (a broken copy of a mesh, to test the
//! repair on), `field` (a grid in another convention, to test how grids are read).

use std::path::{Path, PathBuf};
use std::process::ExitCode;
use std::time::Instant;

use anyhow::{Context, Result, bail};
use clap::{Args, Parser, Subcommand};
use indicatif::{ProgressBar, ProgressStyle};
use ponq_data::normalize::Normalization;
use ponq_data::prep::{
    BatchRun, Job, PrepOptions, SynthJob, input_root, mesh_inputs, mesh_jobs, run_batch_with,
};
use ponq_data::records::RecordLog;
use ponq_data::repair::{RepairOptions, repair_with_solid};
use ponq_data::sdf::signed_distance_grid;
use ponq_data::synth::SynthOptions;
use ponq_mesh::io;
use ponq_mesh::validity::check_topology;

/// Prepare PoNQ data from meshes (.obj, .ply, .off, .stl).
#[derive(Parser, Debug)]
#[command(version, about, long_about)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand, Debug)]
enum Command {
    /// Exact signed distance grid of a mesh, written as a float32 .npy array.
    ///
    /// The mesh is normalised to the [-1,1] convention (bounding-box centre at the origin,
    /// bounding-box diagonal 2) unless --no-normalize is given. The grid has (RES+1)^3 nodes
    /// spanning [-1,1]^3, node (i,j,k) at -1 + 2i/RES (C order: x slowest, z fastest); values
    /// are exact distances to the triangles, negative inside. The sign is the generalised
    /// winding number's, exact on every node of a closed mesh; open meshes get a warning.
    Sdf(SdfArgs),
    /// Prepare a folder (searched recursively) or a list file of meshes as dataset records:
    /// one OUT/NAME.npz per mesh with `pointcloud`, `normals`, `<res>_sdf` and
    /// `<res>_occupancy` in the [-1,1] frame.
    ///
    /// NAME is the mesh's path below the input folder (or the list's folder) without its
    /// extension: a flat folder gives OUT/STEM.npz, a layout such as ShapeNet's
    /// (a/model.obj, b/model.obj) OUT/a/model.npz, OUT/b/model.npz; two files that differ
    /// only by their extension or letter case are refused before any work. Runs in parallel. Outputs are written whole or not at all
    /// (a temporary file, flushed to the disk, then renamed); shapes whose output is already
    /// in OUT, whole, are not redone (a killed run resumes; a cut file is redone). A bad mesh
    /// is an error record in the log and the others go on.
    ///
    /// Exit codes: 0 when every shape is written or already there; 2 when any failed (the
    /// summary says how many, each error is printed and in the log) or on bad arguments.
    Meshes(MeshesArgs),
    /// Generate procedural CAD-like shapes (seeds S..S+N) and prepare them like `meshes`,
    /// with their exact analytic surface samples: OUT/synth_SEED.npz.
    Synth(SynthArgs),
    /// Write a broken copy of a mesh, one class of defect, seeded: what real collections are
    /// full of (triangle soups, cracks, flipped faces and parts, duplicates, holes, nested
    /// shells, overlapping copies, fins), to test and measure the repair on.
    Break(BreakArgs),
    /// Write a copy of an SDF grid in another convention, as people's grids come: other units
    /// (scale:F, voxel), TSDFs (tsdf:N normalised over N cells, tsdf-world:N truncated at N
    /// cells), inside positive, occupancy-like fields (tanh, sigmoid: inside near 1, its
    /// surface at 0.5), squared (d|d|), noise:S (S cells), offset:L (the surface at level L),
    /// to test and measure how `ponq-infer` reads them.
    Field(FieldArgs),
}

#[derive(Args, Debug)]
struct FieldArgs {
    /// Input grid (.npy): a signed distance, negative inside, in the [-1,1] frame as
    /// `ponq-prep sdf` writes it (the cell is 2 / (nodes - 1) of its longest axis).
    grid: PathBuf,
    /// Output grid (.npy, float32).
    #[arg(short, long, value_name = "OUT.npy")]
    output: PathBuf,
    /// The convention: exact, scale:F, voxel, tsdf:N, tsdf-world:N, tanh, sigmoid,
    /// inside-positive, squared, noise:S, offset:L.
    #[arg(long, value_name = "NAME")]
    convention: ponq_data::conventions::Convention,
    /// Seed of the noise.
    #[arg(long, default_value_t = 0)]
    seed: u64,
}

#[derive(Args, Debug)]
struct BreakArgs {
    /// Input mesh (.obj, .ply, .off, .stl): a closed solid.
    mesh: PathBuf,
    /// Output mesh (.obj, .ply, .off).
    #[arg(short, long, value_name = "BROKEN.obj")]
    output: PathBuf,
    /// The defect: soup (one vertex triple per face), cracks (a soup with its vertices moved
    /// apart by up to 1e-5 of the diagonal), flip10 / flip50 (10% / 50% of the faces flipped),
    /// flip-part (the largest part flipped whole), duplicates (5% of the faces duplicated with
    /// the opposite orientation), holes (faces no longer than a grid cell removed, one per
    /// hole), nested-shell (a sphere inside the solid, facing out), overlap (a copy moved by a
    /// quarter of the bounding box), fins (triangles half a cell tall on edges).
    #[arg(long, value_name = "CLASS")]
    defect: ponq_data::broken::Defect,
    /// Cells per side of the grid the copy is meant for: a cell is the diagonal / RES (the
    /// size of holes and fins).
    #[arg(long, value_name = "RES", default_value_t = 64)]
    res: usize,
    /// Seed of the random choices.
    #[arg(long, default_value_t = 0)]
    seed: u64,
}

#[derive(Args, Debug)]
struct BatchArgs {
    /// Output folder (created if missing).
    #[arg(short, long, value_name = "OUT")]
    output: PathBuf,
    /// Grid resolutions, comma-separated (cells per side).
    #[arg(long, value_delimiter = ',', default_value = "32,64")]
    res: Vec<usize>,
    /// Surface samples per shape.
    #[arg(long, default_value_t = 1_000_000)]
    samples: usize,
    /// Sampling seed.
    #[arg(long, default_value_t = 0)]
    sample_seed: u64,
    /// Worker threads (default: all cores).
    #[arg(long)]
    jobs: Option<usize>,
    /// Use the meshes as they are, without the repair (see `ponq-prep sdf --help`).
    #[arg(long)]
    no_repair: bool,
    /// Only shard I of N (e.g. 0/4): the shapes whose name hashes to I modulo N, a split
    /// that depends on the names only, so N machines or Slurm array tasks
    /// (`--shard $SLURM_ARRAY_TASK_ID/$SLURM_ARRAY_TASK_COUNT`) cover a dataset exactly once
    /// into one output folder; each skips what is done and can be re-run after a failure.
    #[arg(long, value_name = "I/N")]
    shard: Option<ponq_data::records::Shard>,
    /// The log: one JSON line per shape (name, input, status done / already / error, the
    /// error, seconds per stage, peak memory, warning, the repair's report), appended
    /// [default: OUT/log.jsonl, or OUT/log-shard-I-of-N.jsonl with --shard]. `ponq-eval log`
    /// summarises logs.
    #[arg(long, value_name = "LOG.jsonl")]
    log: Option<PathBuf>,
    /// Print nothing but errors (no progress bar, no summary).
    #[arg(short, long)]
    quiet: bool,
}

#[derive(Args, Debug)]
struct MeshesArgs {
    /// A folder of meshes (.obj, .ply, .off, .stl) or a text file listing mesh paths.
    input: PathBuf,
    #[command(flatten)]
    batch: BatchArgs,
}

#[derive(Args, Debug)]
struct SynthArgs {
    /// Number of shapes.
    #[arg(long)]
    count: u64,
    /// First seed; shape i uses seed S + i.
    #[arg(long, default_value_t = 0)]
    seed: u64,
    /// Resolution of the generator's meshing grid (higher: sharper ground truth, slower).
    #[arg(long, default_value_t = 96)]
    mesh_resolution: usize,
    #[command(flatten)]
    batch: BatchArgs,
}

#[derive(Args, Debug)]
struct SdfArgs {
    /// Input mesh (.obj, .ply, .off, .stl).
    mesh: PathBuf,
    /// Output grid (.npy, float32, shape (RES+1, RES+1, RES+1)).
    #[arg(short, long, value_name = "SDF.npy")]
    output: PathBuf,
    /// Cells per axis (2..=1024): 32 for training (33^3 nodes), the authors also used 64
    /// and 128.
    #[arg(long, value_name = "RES", default_value_t = 32)]
    res: usize,
    /// Use the mesh's coordinates as they are (they should already lie in [-1,1]^3); by
    /// default the mesh is normalised to bounding-box centre 0 and diagonal 2.
    #[arg(long)]
    no_normalize: bool,
    /// Use the mesh as it is (the behaviour before the repair existed: an open mesh is signed
    /// by its winding number with a warning). By default a mesh is repaired first: vertices
    /// within 1e-4 of the diagonal welded, degenerate and duplicate faces dropped, faces and
    /// parts oriented, holes closed, faces that separate no inside from an outside removed;
    /// a clean mesh is used unchanged.
    #[arg(long)]
    no_repair: bool,
    /// Also write the defect report as a JSON object to this file.
    #[arg(long, value_name = "REPORT.json")]
    json: Option<PathBuf>,
    /// Compute exact distances only within CELLS cells of the surface and write a truncated
    /// signed distance (values clamped to +-CELLS cells, the sign everywhere): work and
    /// memory follow the surface, not the grid's volume (a 1025^3 grid in seconds). 10 cells
    /// (the default of the flag) cover everything `ponq-infer` reads (the cells it can keep,
    /// 1.7 cells from the surface, and the encoder's 4 nodes along each axis around them:
    /// up to 8.7 cells), so it gives the same mesh as on the dense grid. The file is still a
    /// dense float32 array.
    #[arg(long, value_name = "CELLS", num_args = 0..=1, default_missing_value = "10")]
    band: Option<f64>,
    /// Print nothing but errors and warnings (no progress bar, no summary, no defect report).
    #[arg(short, long)]
    quiet: bool,
}

/// Smallest and largest accepted `--res`.
const RES_RANGE: std::ops::RangeInclusive<usize> = 2..=1024;

/// Reads a mesh; the errors of [`io::read_mesh`] already name the file.
fn read_input_mesh(path: &Path) -> Result<ponq_mesh::TriMesh> {
    if !path.exists() {
        bail!("input mesh {} does not exist", path.display());
    }
    let mesh = io::read_mesh(path).context("cannot read the input mesh")?;
    if mesh.faces.is_empty() {
        bail!("{} has no triangle", path.display());
    }
    Ok(mesh)
}

/// Fails early (before any long computation) when the output's directory does not exist.
fn check_output_dir(output: &Path) -> Result<()> {
    let dir = output.parent().filter(|d| !d.as_os_str().is_empty());
    if let Some(d) = dir
        && !d.is_dir()
    {
        bail!(
            "the directory {} of the output {} does not exist",
            d.display(),
            output.display()
        );
    }
    Ok(())
}

/// `ponq-prep sdf --band`: the distances near the surface, written as a truncated grid.
fn write_band(
    a: &SdfArgs,
    repaired: &Option<ponq_data::repair::Repaired>,
    mesh: &ponq_mesh::TriMesh,
    norm: &Normalization,
    cells: f64,
    bar: &ProgressBar,
    t0: Instant,
) -> Result<()> {
    if !(cells.is_finite() && (1.0..=1e6).contains(&cells)) {
        bail!("--band takes a width of at least 1 cell, got {cells}");
    }
    let t = cells * 2.0 / a.res as f64;
    bar.set_style(
        ProgressStyle::with_template(
            "sdf near the surface {bar:40} {pos}/{len} bricks [{elapsed} < {eta}]",
        )
        .unwrap_or_else(|_| ProgressStyle::default_bar()),
    );
    let tick = |done: usize, total: usize| {
        bar.set_length(total as u64);
        bar.set_position(done as u64);
    };
    let t1 = Instant::now();
    let band = match repaired {
        Some(r) => r.band(|m| norm.apply_mesh(m), a.res, 1.0, t, 1, tick),
        None => {
            let sdf = ponq_data::sdf::MeshSdf::new(mesh)?;
            sdf.band_signed_by(&sdf, a.res, 1.0, t, 1, tick)
        }
    }
    .with_context(|| format!("computing the SDF of {}", a.mesh.display()))?;
    let secs = t1.elapsed().as_secs_f64();
    bar.finish_and_clear();
    io::npy::write_npy_band_f32(&a.output, &band.grid, Some(t))
        .context("cannot write the SDF grid")?;
    if band.open {
        eprintln!(
            "warning: {} is not a closed, consistently oriented surface; the sign follows the \
             generalised winding number (inside where |w| > 1/2), away from the surface one \
             value per brick of 8^3 nodes",
            a.mesh.display()
        );
    }
    if !a.quiet {
        let n1 = a.res + 1;
        println!(
            "{}: {n1}^3 nodes, exact within {cells} cells of the surface ({} bricks of 8^3 \
             nodes stored, {:.1}% of the grid), truncated to +-{t:.6} elsewhere; {secs:.2} s, \
             total {:.2} s",
            a.output.display(),
            band.grid.stored_bricks(),
            100.0 * band.grid.stored_bricks() as f64
                / band.grid.brick_dims().iter().product::<usize>() as f64,
            t0.elapsed().as_secs_f64()
        );
    }
    Ok(())
}

fn run_sdf(a: &SdfArgs) -> Result<()> {
    if !RES_RANGE.contains(&a.res) {
        bail!(
            "--res must be in {}..={}, got {}",
            RES_RANGE.start(),
            RES_RANGE.end(),
            a.res
        );
    }
    check_output_dir(&a.output)?;
    let t0 = Instant::now();
    let mesh = read_input_mesh(&a.mesh)?;
    if a.no_repair && a.json.is_some() {
        bail!("--json writes the repair's report: not with --no-repair");
    }
    let repaired = if a.no_repair {
        None
    } else {
        let r = repair_with_solid(&mesh, &RepairOptions::default())
            .with_context(|| format!("repairing {}", a.mesh.display()))?;
        if !a.quiet && r.report.found_defects() {
            eprintln!("{}", r.report);
        }
        if let Some(path) = &a.json {
            std::fs::write(path, r.report.to_json() + "\n")
                .with_context(|| format!("writing the defect report {}", path.display()))?;
        }
        Some(r)
    };
    let mesh = repaired.as_ref().map_or(&mesh, |r| &r.mesh);
    let norm = if a.no_normalize {
        Normalization {
            centre: [0.0; 3],
            scale: 1.0,
        }
    } else {
        let norm =
            Normalization::of(mesh).with_context(|| format!("normalising {}", a.mesh.display()))?;
        if !a.quiet {
            println!(
                "normalised: centre {:?}, scale {:.6e} (x -> (x - centre) * scale)",
                norm.centre, norm.scale
            );
        }
        norm
    };
    let mesh = norm.apply_mesh(mesh);
    let n1 = a.res + 1;
    let total = (n1 * n1 * n1) as u64;
    let bar = if a.quiet {
        ProgressBar::hidden()
    } else {
        ProgressBar::new(total)
    };
    bar.set_style(
        ProgressStyle::with_template(
            "sdf {bar:40} {percent:>3}% {pos}/{len} nodes [{elapsed} < {eta}]",
        )
        .unwrap_or_else(|_| ProgressStyle::default_bar()),
    );
    if let Some(cells) = a.band {
        return write_band(a, &repaired, &mesh, &norm, cells, &bar, t0);
    }
    let t1 = Instant::now();
    let grid = match &repaired {
        Some(r) => r.grid(
            |m| norm.apply_mesh(m),
            a.res,
            |n| bar.set_position(n as u64),
        ),
        None => signed_distance_grid(&mesh, a.res, |n| bar.set_position(n as u64)),
    }
    .with_context(|| format!("computing the SDF of {}", a.mesh.display()))?;
    let secs = t1.elapsed().as_secs_f64();
    bar.finish_and_clear();
    io::npy::write_npy_grid_f32(&a.output, &grid.to_grid3())
        .context("cannot write the SDF grid")?;
    if grid.open {
        let report = check_topology(&mesh);
        eprintln!(
            "warning: {} is not a closed, consistently oriented surface ({report}); the sign \
             follows the generalised winding number (inside where |w| > 1/2) and may be \
             meaningless away from the surface",
            a.mesh.display()
        );
    }
    if !a.quiet {
        let (lo, hi) = grid.min_max();
        let h = 2.0 / a.res as f64;
        println!(
            "{}: {n1}^3 = {total} nodes from {} faces in {secs:.2} s ({:.2} M nodes/s), \
             total {:.2} s",
            a.output.display(),
            mesh.faces.len(),
            total as f64 / secs.max(1e-9) / 1e6,
            t0.elapsed().as_secs_f64()
        );
        println!(
            "sdf min {lo:.6} max {hi:.6} (node spacing {h:.6}); {} nodes inside",
            grid.inside_count()
        );
        if lo > 0.0 {
            eprintln!(
                "note: no node is inside the surface (a shape thinner than a cell, an open \
                 surface, or a mesh outside [-1,1]^3 with --no-normalize)"
            );
        }
    }
    Ok(())
}

/// A batch's outcome: every shape done or already there, or how many failed.
enum BatchOutcome {
    AllDone,
    Failed,
}

fn run_batch_cmd<J: Job>(jobs: &[J], b: &BatchArgs) -> Result<BatchOutcome> {
    if b.res.is_empty() || b.res.iter().any(|r| !RES_RANGE.contains(r)) {
        bail!(
            "--res values must be in {}..={}, got {:?}",
            RES_RANGE.start(),
            RES_RANGE.end(),
            b.res
        );
    }
    if b.samples == 0 {
        bail!("--samples must be positive");
    }
    if let Some(n) = b.jobs {
        rayon::ThreadPoolBuilder::new()
            .num_threads(n.max(1))
            .build_global()
            .context("setting the number of worker threads")?;
    }
    let opts = PrepOptions {
        resolutions: b.res.clone(),
        samples: b.samples,
        seed: b.sample_seed,
        repair: !b.no_repair,
    };
    let bar = if b.quiet {
        ProgressBar::hidden()
    } else {
        ProgressBar::new(jobs.len() as u64)
    };
    bar.set_style(
        ProgressStyle::with_template("prep {bar:40} {pos}/{len} shapes [{elapsed} < {eta}]")
            .unwrap_or_else(|_| ProgressStyle::default_bar()),
    );
    std::fs::create_dir_all(&b.output)
        .with_context(|| format!("creating the output folder {}", b.output.display()))?;
    let log_path = b
        .log
        .clone()
        .unwrap_or_else(|| ponq_data::records::default_log(&b.output, b.shard));
    let log = RecordLog::append(&log_path).context("opening the log")?;
    if let Some(sh) = &b.shard {
        let n = jobs.iter().filter(|j| sh.contains(&j.id())).count();
        bar.set_length(n as u64);
    }
    let run = BatchRun {
        shard: b.shard,
        log: Some(&log),
    };
    let s = run_batch_with(jobs, &b.output, &opts, &run, || bar.inc(1))?;
    bar.finish_and_clear();
    for (id, why) in &s.skipped {
        eprintln!("failed {id}: {why}");
    }
    for (id, w) in &s.warnings {
        eprintln!("warning {id}: {w}");
    }
    if !b.quiet {
        println!(
            "{}: {} shapes written, {} already there, {} failed, in {:.1} s{}; log {}",
            b.output.display(),
            s.done.len(),
            s.already.len(),
            s.skipped.len(),
            s.time.as_secs_f64(),
            b.shard.map(|x| format!(" (shard {x})")).unwrap_or_default(),
            log_path.display()
        );
        if s.stale_removed > 0 {
            println!(
                "note: removed {} temporary file(s) of runs that crashed",
                s.stale_removed
            );
        }
    }
    if s.all_done() {
        return Ok(BatchOutcome::AllDone);
    }
    eprintln!(
        "error: {} of {} shapes failed (each one's error is above and in the log {})",
        s.skipped.len(),
        s.records.len(),
        log_path.display()
    );
    Ok(BatchOutcome::Failed)
}

fn run_field(a: &FieldArgs) -> Result<()> {
    check_output_dir(&a.output)?;
    let g = io::npy::read_npy_grid(&a.grid).context("cannot read the grid")?;
    let n = g.dims.iter().max().copied().unwrap_or(2).max(2) - 1;
    let h = 2.0 / n as f64;
    let values = a.convention.apply(&g.data, h, a.seed);
    let out = io::npy::Grid3::new(g.dims, values).context("the converted grid")?;
    io::npy::write_npy_grid_f32(&a.output, &out).context("writing the grid")?;
    println!(
        "{}: {} copy of {} ({:?} nodes){}",
        a.output.display(),
        a.convention,
        a.grid.display(),
        g.dims,
        a.convention
            .level()
            .map(|l| format!("; its surface is at --level {l}"))
            .unwrap_or_default()
    );
    Ok(())
}

fn run_break(a: &BreakArgs) -> Result<()> {
    if !RES_RANGE.contains(&a.res) {
        bail!(
            "--res must be in {}..={}, got {}",
            RES_RANGE.start(),
            RES_RANGE.end(),
            a.res
        );
    }
    check_output_dir(&a.output)?;
    let mesh = read_input_mesh(&a.mesh)?;
    let (lo, hi) = mesh.bounding_box().context("the mesh has no vertex")?;
    let diag = (0..3).map(|k| (hi[k] - lo[k]).powi(2)).sum::<f64>().sqrt();
    let broken = ponq_data::broken::break_mesh(&mesh, a.defect, a.seed, diag / a.res as f64)
        .with_context(|| format!("breaking {}", a.mesh.display()))?;
    io::write_mesh(&a.output, &broken).context("writing the broken copy")?;
    println!(
        "{}: {} ({} vertices, {} faces; the input had {}, {})",
        a.output.display(),
        a.defect,
        broken.vertices.len(),
        broken.faces.len(),
        mesh.vertices.len(),
        mesh.faces.len()
    );
    Ok(())
}

fn main() -> ExitCode {
    let cli = Cli::parse();
    // A memory setting that cannot be read is an error before any work.
    if let Err(e) = ponq_mesh::memory::budget() {
        eprintln!("error: {e}");
        return ExitCode::from(2);
    }
    let result = match &cli.command {
        Command::Sdf(a) => run_sdf(a).map(|()| BatchOutcome::AllDone),
        Command::Meshes(a) => mesh_inputs(&a.input)
            .context("listing the input meshes")
            .and_then(|files| {
                if files.is_empty() {
                    bail!(
                        "no mesh (.obj, .ply, .off, .stl) found in {}",
                        a.input.display()
                    );
                }
                let jobs = mesh_jobs(files, &input_root(&a.input)).context("naming the outputs")?;
                run_batch_cmd(&jobs, &a.batch)
            }),
        Command::Break(a) => run_break(a).map(|()| BatchOutcome::AllDone),
        Command::Field(a) => run_field(a).map(|()| BatchOutcome::AllDone),
        Command::Synth(a) => {
            let synth = SynthOptions {
                mesh_resolution: a.mesh_resolution,
                ..Default::default()
            };
            let jobs: Vec<SynthJob> = (0..a.count)
                .map(|i| SynthJob {
                    seed: a.seed + i,
                    synth: synth.clone(),
                })
                .collect();
            run_batch_cmd(&jobs, &a.batch)
        }
    };
    match result {
        Ok(BatchOutcome::AllDone) => ExitCode::SUCCESS,
        Ok(BatchOutcome::Failed) => ExitCode::from(2),
        Err(e) => {
            eprintln!("error: {e:#}");
            ExitCode::from(2)
        }
    }
}
