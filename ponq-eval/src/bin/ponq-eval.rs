//! `ponq-eval`: reconstruction metrics with the paper's protocol.

use ponq_mesh::tagging::SmallTetRule;
use std::path::PathBuf;
use std::process::ExitCode;

use anyhow::{Context, Result, bail};
use clap::{Parser, Subcommand, ValueEnum};
use ponq_mesh::metrics::{MetricOptions, compare, grid_frame_to_gt};
use ponq_mesh::{io, validity};

/// Evaluate reconstructions: CD (x1e5), F1, NC, ECD (x1e2), EF1, watertightness, #V, #F,
/// with both meshes at the ground truth's unit bounding-box diagonal (SPEC section 8).
#[derive(Parser, Debug)]
#[command(version, about, long_about)]
struct Cli {
    #[command(subcommand)]
    cmd: Cmd,
}

#[derive(Clone, Copy, Debug, ValueEnum)]
enum Frame {
    /// PRED is in the [-1,1] frame of GT (bounding-box centre 0, diagonal 2), as written by
    /// ponq-fit and ponq-infer by default.
    Grid,
    /// PRED is in GT's own coordinates.
    Gt,
}

#[derive(Subcommand, Debug)]
enum Cmd {
    /// Evaluate a split: every shape through PoNQ (and PoNQ-lite) and marching cubes at each
    /// resolution; writes OUT/per_shape.csv, OUT/summary.md (the paper's table layout),
    /// OUT/report.md with renders in OUT/renders/. Resumable: rerun the same command.
    Run(RunArgs),
    /// Broken copies side by side with the clean meshes: every mesh of DATA through
    /// `ponq-infer MESH --res RES`'s path (repair, SDF, network, meshing, refinement) as it
    /// is and as one broken copy per defect class (`ponq-prep break --help`), each output
    /// compared with the clean mesh (with the union of the two copies for `overlap`).
    /// Writes OUT/per_copy.csv (resumable: rerun the same command) and OUT/summary.md (per
    /// class: valid outputs, F1 / NC / EF1 beside the clean copies' of the same shapes, the
    /// mean and worst F1 loss, time).
    Broken(BrokenArgs),
    /// Grids in people's conventions side by side with the exact grid: every mesh of DATA's
    /// exact SDF grid at each --res rewritten in each convention (`ponq-prep field --help`),
    /// each copy through `ponq-infer`'s path (its values conditioned into distances) and
    /// through marching cubes at the copy's level and sign, both compared with the mesh.
    /// Writes OUT/per_copy.csv (resumable: rerun the same command) and OUT/summary.md (per
    /// grid and convention: valid outputs, F1 / NC / EF1 beside the exact grid's and marching
    /// cubes', the worst F1 loss, copies below marching cubes, the conditioning's time).
    Fields(FieldsArgs),
    /// Summarise batch logs (the JSON lines `ponq-prep meshes` and `ponq-infer DIR` write
    /// beside their outputs; several logs, e.g. one per shard, are merged): shapes by status,
    /// errors by reason, seconds per shape (percentiles), peak memory, invalid outputs.
    Log {
        /// Log files (`.jsonl`), or folders whose `*.jsonl` files are read.
        logs: Vec<PathBuf>,
    },
    /// Marching cubes baseline: the zero level set of an SDF grid (.npy, nodes spanning the
    /// [-1,1]^3 box, negative inside, as written by `ponq-prep sdf`).
    Mc {
        /// SDF grid (.npy, float32 or float64, rank 3).
        sdf: PathBuf,
        /// Output mesh (.obj, .ply, .off).
        #[arg(short, long)]
        output: PathBuf,
    },
    /// Check a mesh: closed, oriented, manifold, free of self-intersections (exact
    /// predicates). Exit status 0 when valid, 1 when not.
    Check {
        /// Mesh file (.obj, .ply, .off, .stl).
        mesh: PathBuf,
    },
    /// Compare one predicted mesh with its ground truth.
    Compare {
        /// Predicted mesh (.obj, .ply, .off, .stl).
        pred: PathBuf,
        /// Ground-truth mesh.
        gt: PathBuf,
        /// Frame of PRED.
        #[arg(long, value_enum, default_value_t = Frame::Grid)]
        pred_frame: Frame,
        /// Surface and sharp-edge samples per mesh.
        #[arg(long, default_value_t = 100_000)]
        samples: usize,
        /// Sampling seed.
        #[arg(long, default_value_t = 0)]
        seed: u64,
        /// Dihedral angle in degrees above which an edge counts as sharp for ECD / EF1 (the
        /// papers' 30; other values show how much a result hangs on edges near the threshold).
        #[arg(long, default_value_t = 30.0, value_name = "DEG")]
        sharp_angle: f64,
        /// Print one JSON object instead of a table.
        #[arg(long)]
        json: bool,
    },
}

fn main() -> ExitCode {
    match run(Cli::parse()) {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {e:#}");
            ExitCode::from(2)
        }
    }
}

fn run(cli: Cli) -> Result<()> {
    match cli.cmd {
        Cmd::Run(a) => run_split(a),
        Cmd::Broken(a) => run_broken(a),
        Cmd::Fields(a) => run_fields(a),
        Cmd::Log { logs } => {
            let mut files = Vec::new();
            for p in logs {
                if p.is_dir() {
                    let mut found: Vec<PathBuf> = std::fs::read_dir(&p)
                        .with_context(|| format!("reading {}", p.display()))?
                        .filter_map(|e| e.ok().map(|e| e.path()))
                        .filter(|f| f.extension().is_some_and(|e| e == "jsonl"))
                        .collect();
                    found.sort();
                    files.extend(found);
                } else {
                    files.push(p);
                }
            }
            if files.is_empty() {
                anyhow::bail!("no log given (files .jsonl, or folders holding them)");
            }
            print!("{}", ponq_eval::logs::summarise(&files)?);
            Ok(())
        }
        Cmd::Mc { sdf, output } => {
            let g = io::npy::read_npy_grid(&sdf).context("reading the SDF grid")?;
            let t = std::time::Instant::now();
            let m =
                ponq_mesh::marching_cubes::marching_cubes(&g.data, g.dims, [-1.0; 3], [1.0; 3])?;
            let secs = t.elapsed().as_secs_f64();
            io::write_mesh(&output, &m).context("writing the mesh")?;
            println!(
                "{}: {} V, {} F in {:.1} ms; {}",
                output.display(),
                m.vertices.len(),
                m.faces.len(),
                secs * 1e3,
                validity::check(&m)
            );
            Ok(())
        }
        Cmd::Check { mesh } => {
            let m = io::read_mesh(&mesh).context("reading the mesh")?;
            let r = validity::check(&m);
            println!(
                "{}: {} V, {} F: {r}",
                mesh.display(),
                m.vertices.len(),
                m.faces.len()
            );
            if !r.is_valid() {
                std::process::exit(1);
            }
            Ok(())
        }
        Cmd::Compare {
            pred,
            gt,
            pred_frame,
            samples,
            seed,
            sharp_angle,
            json,
        } => {
            if samples == 0 {
                bail!("--samples must be positive");
            }
            if !(sharp_angle > 0.0 && sharp_angle < 180.0) {
                bail!("--sharp-angle must be in (0, 180) degrees, got {sharp_angle}");
            }
            let p = io::read_mesh(&pred).context("reading the predicted mesh")?;
            // Validity is checked on the file as written: mapping it to another frame rounds
            // coordinates, which can create or remove exact contacts.
            let watertight = validity::check(&p).is_valid();
            let g = io::read_mesh(&gt).context("reading the ground-truth mesh")?;
            if g.faces.is_empty() {
                bail!("the ground truth {} has no face", gt.display());
            }
            let p = match pred_frame {
                Frame::Gt => p,
                Frame::Grid => grid_frame_to_gt(&p, &g)
                    .context("the ground truth has a degenerate bounding box")?,
            };
            let m = compare(
                &p,
                &g,
                &MetricOptions {
                    surface_samples: samples,
                    edge_samples: samples,
                    seed,
                    sharp_angle_deg: sharp_angle,
                    check_validity: false,
                    ..Default::default()
                },
            );
            let m = ponq_mesh::metrics::Metrics {
                watertight: Some(watertight),
                ..m
            };
            let wt = match m.watertight {
                Some(true) => "yes",
                Some(false) => "no",
                None => "unchecked",
            };
            if json {
                let f = |x: f64| {
                    if x.is_finite() {
                        format!("{x}")
                    } else {
                        "null".to_string()
                    }
                };
                println!(
                    "{{\"pred\":{:?},\"gt\":{:?},\"cd_x1e5\":{},\"f1\":{},\"nc\":{},\"ecd_x1e2\":{},\"ef1\":{},\"watertight\":{},\"vertices\":{},\"faces\":{}}}",
                    pred.display().to_string(),
                    gt.display().to_string(),
                    f(m.cd_x1e5),
                    f(m.f1),
                    f(m.nc),
                    f(m.ecd_x1e2),
                    f(m.ef1),
                    m.watertight.unwrap_or(false),
                    m.n_vertices,
                    m.n_faces
                );
            } else {
                println!("| CD x1e5 | F1 | NC | ECD x1e2 | EF1 | watertight | #V | #F |");
                println!("|---:|---:|---:|---:|---:|---|---:|---:|");
                println!(
                    "| {:.3} | {:.3} | {:.3} | {:.3} | {:.3} | {wt} | {} | {} |",
                    m.cd_x1e5, m.f1, m.nc, m.ecd_x1e2, m.ef1, m.n_vertices, m.n_faces
                );
            }
            Ok(())
        }
    }
}

/// Flags of `ponq-eval run`.
#[derive(clap::Args, Debug)]
struct RunArgs {
    /// Folder of shapes, searched recursively: meshes (.obj/.ply/.off/.stl; their SDF grids are made here),
    /// our .npz records or the authors' .hdf5 files (metrics from their samples; no
    /// edge metrics without a mesh).
    #[arg(long)]
    data: PathBuf,
    /// Split file (one id = file stem per line), e.g. configs/splits/abc_test.txt;
    /// ids without a file are listed in the report, not fatal.
    #[arg(long)]
    split: Option<PathBuf>,
    /// Grid resolutions (cells per side), comma-separated.
    #[arg(long, value_delimiter = ',', default_value = "32")]
    res: Vec<usize>,
    /// Also evaluate PoNQ-lite.
    #[arg(long)]
    lite: bool,
    /// Hierarchy level for PoNQ-lite (implies --lite).
    #[arg(long, default_value_t = 0)]
    coarsen: u32,
    /// Adaptive PoNQ-lite in the PoNQ rows, as `ponq-infer --merge-smooth`: merge each
    /// cell's points whose normals agree within DEG degrees; 0 keeps every point.
    #[arg(long, value_name = "DEG", default_value_t = ponq_infer::reconstruct::DEFAULT_MERGE_SMOOTH_DEG)]
    merge_smooth: f64,
    /// The small-tet rule of the tagging: `inside` (default: a vertex with an outside tet but no
    /// inside tet gets its smallest unknown tet tagged inside, if small; the authors' intent),
    /// `authors` (their code to the letter: the smallest of all the vertex's tets, whatever its
    /// label, flags read once), `both` (the paper's text: inside and outside tets; the rule
    /// before 2026-12-03). See docs/meshing.md.
    #[arg(long, value_name = "RULE", default_value = "inside")]
    small_tets: SmallTetRule,
    /// Same as `--small-tets both` (kept for earlier scripts).
    #[arg(long, conflicts_with = "small_tets")]
    small_tets_both_ways: bool,
    /// Skip the marching cubes baseline.
    #[arg(long)]
    no_mc: bool,
    /// Also report the PoNQ rows refined against the grid's exact distances (`ponq-infer
    /// --refine auto`, the default output), named `<name>+refine`, beside the network's
    /// alone (`<name>`), from the same network run; their time column includes the network.
    #[arg(long)]
    refine: bool,
    /// Network weights [default: the shipped model].
    #[arg(long)]
    model: Option<PathBuf>,
    /// Compute backend of the network: flex (CPU, default), wgpu or cuda (with the cargo
    /// feature of that name).
    #[arg(long, default_value = "flex")]
    backend: ponq_model::backend::BackendKind,
    /// Layer implementation of the network on the CPU: fast (custom kernels, default),
    /// fast-bf16 (bf16 GEMM inputs, f32 sums; AMX or AVX-512 BF16, an error on CPUs without)
    /// or stock (Burn's Conv3d layers); fast and stock give the same numbers up to float
    /// rounding.
    #[arg(long, default_value = "fast")]
    kernels: ponq_model::Kernels,
    /// Surface and sharp-edge samples per mesh for the metrics.
    #[arg(long, default_value_t = 100_000)]
    samples: usize,
    /// Render the first K shapes side by side (ground truth, MC, PoNQ).
    #[arg(long, default_value_t = 4)]
    renders: usize,
    /// Shapes evaluated in parallel [default: all cores].
    #[arg(long)]
    jobs: Option<usize>,
    /// Name of this model's rows in the report (`PoNQ`; `<name>-lite` for PoNQ-lite): run
    /// again into the same folder with another `--model`, `--name` and `--no-mc` to compare
    /// models in one report.
    #[arg(long, default_value = "PoNQ")]
    name: String,
    /// Report folder.
    #[arg(short, long)]
    output: PathBuf,
    /// No progress bar.
    #[arg(short, long)]
    quiet: bool,
}

#[derive(clap::Args, Debug)]
struct BrokenArgs {
    /// A folder of clean meshes (searched recursively; the first folder below it is a
    /// shape's group in the CSV).
    data: PathBuf,
    /// Cells per side of the SDF grid (also the size of holes and fins: a cell).
    #[arg(long, default_value_t = 64)]
    res: usize,
    /// Defect classes, comma-separated, or `all`.
    #[arg(long, value_delimiter = ',', default_value = "all")]
    defects: Vec<String>,
    /// Seed of the broken copies.
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// Surface and sharp-edge samples per mesh for the metrics.
    #[arg(long, default_value_t = 100_000)]
    samples: usize,
    /// Only the first N meshes (sorted by name).
    #[arg(long)]
    limit: Option<usize>,
    /// Network weights [default: the shipped model].
    #[arg(long)]
    model: Option<PathBuf>,
    /// Report folder.
    #[arg(short, long)]
    output: PathBuf,
    /// No progress bar.
    #[arg(short, long)]
    quiet: bool,
}

#[derive(clap::Args, Debug)]
struct FieldsArgs {
    /// A folder of meshes (searched recursively; the first folder below it is a shape's
    /// group in the CSV).
    data: PathBuf,
    /// Cells per side of the grids, comma-separated.
    #[arg(long, value_delimiter = ',', default_value = "32,64")]
    res: Vec<usize>,
    /// Conventions, comma-separated (`ponq-prep field --help`), or `all` (the 17 of the
    /// benchmark).
    #[arg(long, value_delimiter = ',', default_value = "all")]
    conventions: Vec<String>,
    /// Seed of the noise.
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// Surface and sharp-edge samples per mesh for the metrics.
    #[arg(long, default_value_t = 100_000)]
    samples: usize,
    /// Only the first N meshes (sorted by name).
    #[arg(long)]
    limit: Option<usize>,
    /// Network weights [default: the shipped model].
    #[arg(long)]
    model: Option<PathBuf>,
    /// Report folder.
    #[arg(short, long)]
    output: PathBuf,
    /// No progress bar.
    #[arg(short, long)]
    quiet: bool,
}

fn run_fields(a: FieldsArgs) -> Result<()> {
    use indicatif::{ProgressBar, ProgressStyle};
    use ponq_data::conventions::Convention;
    use ponq_eval::fields::{FieldRow, evaluate_copy, summary_markdown};
    use std::io::Write;
    if a.res.is_empty() || a.res.iter().any(|r| !(2..=256).contains(r)) {
        bail!("--res takes resolutions in 2..=256, got {:?}", a.res);
    }
    if a.samples == 0 {
        bail!("--samples must be positive");
    }
    let conventions: Vec<Convention> = if a.conventions.iter().any(|c| c == "all") {
        Convention::BENCHMARK.to_vec()
    } else {
        a.conventions
            .iter()
            .map(|c| c.parse::<Convention>().map_err(anyhow::Error::msg))
            .collect::<Result<_>>()?
    };
    let (mut shapes, _) = ponq_eval::inputs::inputs(&a.data, None)?;
    shapes.retain(|(_, p)| ponq_mesh::io::MeshFormat::from_path(p).is_some());
    if let Some(n) = a.limit {
        shapes.truncate(n);
    }
    if shapes.is_empty() {
        bail!("no mesh (.obj, .ply, .off, .stl) in {}", a.data.display());
    }
    std::fs::create_dir_all(&a.output)
        .with_context(|| format!("creating {}", a.output.display()))?;
    let csv = a.output.join("per_copy.csv");
    let mut rows: Vec<FieldRow> = match std::fs::read_to_string(&csv) {
        Ok(text) => text.lines().skip(1).filter_map(FieldRow::parse).collect(),
        Err(_) => Vec::new(),
    };
    let mut file = std::fs::OpenOptions::new()
        .create(true)
        .append(true)
        .open(&csv)
        .with_context(|| format!("opening {}", csv.display()))?;
    if rows.is_empty() {
        writeln!(file, "{}", FieldRow::HEADER)?;
    }
    let device = ponq_model::backend::cpu();
    let (net, cfg) = match &a.model {
        Some(p) => ponq_model::weights::load(p, &device)?,
        None => ponq_infer::shipped::load(&device)?,
    };
    let bar = if a.quiet {
        ProgressBar::hidden()
    } else {
        ProgressBar::new((shapes.len() * a.res.len() * conventions.len()) as u64)
    };
    bar.set_style(
        ProgressStyle::with_template("copies {bar:40} {pos}/{len} [{elapsed} < {eta}] {msg}")
            .unwrap_or_else(|_| ProgressStyle::default_bar()),
    );
    let mut failed = 0;
    for (id, path) in &shapes {
        let group = ponq_eval::inputs::group_of(&a.data, path);
        bar.set_message(id.clone());
        let truth = match ponq_eval::inputs::truth(path) {
            Ok(t) => t,
            Err(e) => {
                bar.suspend(|| eprintln!("failed {id}: {e:#}"));
                failed += 1;
                bar.inc((a.res.len() * conventions.len()) as u64);
                continue;
            }
        };
        let Some(mesh) = truth.mesh.as_ref() else {
            continue;
        };
        for &res in &a.res {
            let todo: Vec<Convention> = conventions
                .iter()
                .copied()
                .filter(|c| {
                    let name = c.to_string();
                    !rows
                        .iter()
                        .any(|r| &r.shape == id && r.res == res && r.convention == name)
                })
                .collect();
            bar.inc((conventions.len() - todo.len()) as u64);
            if todo.is_empty() {
                continue;
            }
            let exact = match ponq_eval::inputs::grid_of(&truth, res) {
                Ok(g) => g,
                Err(e) => {
                    bar.suspend(|| eprintln!("failed {id} at {res}: {e:#}"));
                    failed += 1;
                    bar.inc(todo.len() as u64);
                    continue;
                }
            };
            for c in todo {
                let row = evaluate_copy(
                    id,
                    &group,
                    &exact,
                    mesh,
                    c,
                    a.seed,
                    a.samples,
                    &net,
                    cfg.encoder_layers,
                    &device,
                );
                writeln!(file, "{}", row.csv())?;
                file.flush()?;
                rows.push(row);
                bar.inc(1);
            }
        }
    }
    bar.finish_and_clear();
    let table = summary_markdown(&rows);
    let md = a.output.join("summary.md");
    std::fs::write(
        &md,
        format!(
            "# Grids in other conventions (seed {})\n\n{} meshes of {}.\n\n{table}",
            a.seed,
            shapes.len(),
            a.data.display()
        ),
    )
    .with_context(|| format!("writing {}", md.display()))?;
    if !a.quiet {
        print!("{table}");
        println!("{}: per copy; {}: this table", csv.display(), md.display());
    }
    let errors = rows.iter().filter(|r| !r.error.is_empty()).count();
    if errors > 0 {
        eprintln!(
            "note: {errors} copies could not be reconstructed (their rows in {} hold the error)",
            csv.display()
        );
    }
    if failed > 0 {
        bail!("{failed} shape(s) or grids could not be read (see above)");
    }
    Ok(())
}

fn run_broken(a: BrokenArgs) -> Result<()> {
    use indicatif::{ProgressBar, ProgressStyle};
    use ponq_data::broken::Defect;
    use ponq_eval::broken::{CopyRow, evaluate_copies, summary_markdown};
    use std::io::Write;
    if !(2..=512).contains(&a.res) {
        bail!("--res takes a resolution in 2..=512, got {}", a.res);
    }
    if a.samples == 0 {
        bail!("--samples must be positive");
    }
    let defects: Vec<Defect> = if a.defects.iter().any(|d| d == "all") {
        Defect::ALL.to_vec()
    } else {
        a.defects
            .iter()
            .map(|d| d.parse::<Defect>().map_err(anyhow::Error::msg))
            .collect::<Result<_>>()?
    };
    let (mut shapes, _) = ponq_eval::inputs::inputs(&a.data, None)?;
    shapes.retain(|(_, p)| ponq_mesh::io::MeshFormat::from_path(p).is_some());
    if let Some(n) = a.limit {
        shapes.truncate(n);
    }
    if shapes.is_empty() {
        bail!("no mesh (.obj, .ply, .off, .stl) in {}", a.data.display());
    }
    std::fs::create_dir_all(&a.output)
        .with_context(|| format!("creating {}", a.output.display()))?;
    let csv = a.output.join("per_copy.csv");
    let mut rows: Vec<CopyRow> = match std::fs::read_to_string(&csv) {
        Ok(text) => text.lines().skip(1).filter_map(CopyRow::parse).collect(),
        Err(_) => Vec::new(),
    };
    let mut file = std::fs::OpenOptions::new()
        .create(true)
        .append(true)
        .open(&csv)
        .with_context(|| format!("opening {}", csv.display()))?;
    if rows.is_empty() {
        writeln!(file, "{}", CopyRow::HEADER)?;
    }
    let device = ponq_model::backend::cpu();
    let (net, cfg) = match &a.model {
        Some(p) => ponq_model::weights::load(p, &device)?,
        None => ponq_infer::shipped::load(&device)?,
    };
    let bar = if a.quiet {
        ProgressBar::hidden()
    } else {
        ProgressBar::new((shapes.len() * (defects.len() + 1)) as u64)
    };
    bar.set_style(
        ProgressStyle::with_template("copies {bar:40} {pos}/{len} [{elapsed} < {eta}] {msg}")
            .unwrap_or_else(|_| ProgressStyle::default_bar()),
    );
    for (id, path) in &shapes {
        let group = ponq_eval::inputs::group_of(&a.data, path);
        bar.set_message(id.clone());
        let have: Vec<String> = rows
            .iter()
            .filter(|r| &r.shape == id)
            .map(|r| r.copy.clone())
            .collect();
        bar.inc(have.len() as u64);
        let result = evaluate_copies(
            id,
            &group,
            path,
            a.res,
            &defects,
            a.seed,
            a.samples,
            &net,
            cfg.encoder_layers,
            &device,
            &|copy| have.iter().any(|h| h == copy),
            |row| {
                writeln!(file, "{}", row.csv())?;
                file.flush()?;
                rows.push(row);
                bar.inc(1);
                Ok(())
            },
        );
        if let Err(e) = result {
            // The shape itself cannot be evaluated: an error row for each copy it lacks (the
            // evaluation goes on; a re-run does not try it again).
            bar.suspend(|| eprintln!("failed {id}: {e:#}"));
            let mut copies = vec!["clean"];
            copies.extend(defects.iter().map(|d| d.name()));
            for copy in copies {
                if rows.iter().any(|r| &r.shape == id && r.copy == copy) {
                    continue;
                }
                let row = CopyRow::failed(id, &group, copy, format!("{e:#}"));
                writeln!(file, "{}", row.csv())?;
                file.flush()?;
                rows.push(row);
                bar.inc(1);
            }
        }
    }
    bar.finish_and_clear();
    let failed = rows.iter().filter(|r| !r.error.is_empty()).count();
    let table = summary_markdown(&rows);
    let md = a.output.join("summary.md");
    std::fs::write(
        &md,
        format!(
            "# Broken copies at {}^3 (seed {})\n\n{} meshes of {}.\n\n{table}",
            a.res + 1,
            a.seed,
            shapes.len(),
            a.data.display()
        ),
    )
    .with_context(|| format!("writing {}", md.display()))?;
    if !a.quiet {
        print!("{table}");
        println!("{}: per copy; {}: this table", csv.display(), md.display());
    }
    if failed > 0 {
        eprintln!(
            "note: {failed} copies could not be reconstructed (their rows in {} hold the error)",
            csv.display()
        );
    }
    Ok(())
}

fn run_split(a: RunArgs) -> Result<()> {
    use indicatif::{ProgressBar, ProgressStyle};
    use ponq_eval::{self as eval, EvalOptions, Method};
    use rayon::prelude::*;
    if let Some(e) = a.kernels.unsupported_here() {
        bail!(e);
    }
    if let Some(j) = a.jobs {
        rayon::ThreadPoolBuilder::new()
            .num_threads(j.max(1))
            .build_global()
            .context("cannot set the thread count")?;
    }
    if a.res.is_empty() || a.res.iter().any(|&r| !(2..=512).contains(&r)) {
        bail!("--res takes resolutions in 2..=512, got {:?}", a.res);
    }
    if a.samples == 0 {
        bail!("--samples must be positive");
    }
    if a.name.is_empty()
        || !a
            .name
            .chars()
            .all(|c| c.is_ascii_alphanumeric() || matches!(c, '-' | '_' | '.'))
    {
        bail!(
            "--name takes letters, digits, '-', '_' and '.', got {:?}",
            a.name
        );
    }
    let device = ponq_model::backend::device(a.backend).map_err(anyhow::Error::msg)?;
    let (net, cfg) = match &a.model {
        Some(p) => ponq_model::weights::load(p, &device)?,
        None => ponq_infer::shipped::load(&device)?,
    };
    let net = net.with_kernels(a.kernels);
    let (shapes, missing) = eval::inputs(&a.data, a.split.as_deref())?;
    if shapes.is_empty() {
        bail!("no shape of {} to evaluate", a.data.display());
    }
    let mut methods = vec![Method::Ponq];
    if a.refine {
        methods.push(Method::Refined);
    }
    if !(0.0..=180.0).contains(&a.merge_smooth) {
        bail!(
            "--merge-smooth takes an angle in [0, 180] degrees, got {}",
            a.merge_smooth
        );
    }
    if a.lite || a.coarsen > 0 {
        methods.push(Method::Lite);
    }
    if !a.no_mc {
        methods.push(Method::Mc);
    }
    let opts = EvalOptions {
        resolutions: a.res.clone(),
        methods,
        coarsen: a.coarsen,
        merge_smooth: (a.merge_smooth > 0.0).then_some(a.merge_smooth),
        small_tet_rule: if a.small_tets_both_ways {
            SmallTetRule::BothWays
        } else {
            a.small_tets
        },
        samples: a.samples,
        renders: a.renders,
        tile: 0,
        name: a.name.clone(),
    };
    std::fs::create_dir_all(a.output.join("rows"))
        .with_context(|| format!("cannot create {}", a.output.display()))?;
    std::fs::create_dir_all(a.output.join("renders"))?;
    let jobs: Vec<(usize, usize)> = (0..shapes.len())
        .flat_map(|i| a.res.iter().map(move |&r| (i, r)))
        .collect();
    let pb = if a.quiet {
        ProgressBar::hidden()
    } else {
        let pb = ProgressBar::new(jobs.len() as u64);
        pb.set_style(
            ProgressStyle::with_template(
                "{bar:40} {pos}/{len} (shape, grid) pairs [{elapsed} / ETA {eta}]",
            )
            .unwrap_or_else(|_| ProgressStyle::default_bar()),
        );
        pb
    };
    let failed: Vec<(String, String)> = jobs
        .par_iter()
        .filter_map(|&(i, r)| {
            let (id, path) = &shapes[i];
            let rows_path = eval::rows_path(&a.output, id, r, &a.name);
            let result = if rows_path.is_file() {
                Ok(())
            } else {
                let render = i < a.renders;
                eval::evaluate(
                    id,
                    path,
                    r,
                    &net,
                    cfg.encoder_layers,
                    &opts,
                    &device,
                    render,
                )
                .and_then(|(rows, image)| {
                    if let Some(im) = image {
                        let suffix = if a.name == "PoNQ" {
                            String::new()
                        } else {
                            format!("_{}", a.name)
                        };
                        im.save_png(
                            &a.output
                                .join("renders")
                                .join(format!("{id}_{}{suffix}.png", r + 1)),
                        )?;
                    }
                    eval::write_rows(&rows_path, &rows)
                })
            };
            pb.inc(1);
            result
                .err()
                .map(|e| (format!("{id}@{}", r + 1), format!("{e:#}")))
        })
        .collect();
    pb.finish_and_clear();
    let groups: std::collections::BTreeMap<String, String> = shapes
        .iter()
        .map(|(id, path)| (id.clone(), eval::group_of(&a.data, path)))
        .collect();
    let rows = eval::write_report(&a.output, &missing, &failed, &groups)?;
    if !a.quiet {
        print!("{}", eval::summary_markdown(&rows));
        if !missing.is_empty() {
            println!(
                "{} shapes of the split are missing (listed in report.md)",
                missing.len()
            );
        }
        for (id, e) in &failed {
            println!("failed: {id}: {e}");
        }
        println!("report: {}", a.output.join("report.md").display());
    }
    Ok(())
}
