//! `ponq-infer`: an SDF grid (`.npy`) or a mesh in, a sharp watertight mesh out, with the
//! trained PoNQ network.

use std::path::{Path, PathBuf};
use std::process::ExitCode;
use std::time::{Duration, Instant};

use anyhow::{Context, Result, bail};
use clap::Parser;
use indicatif::{ProgressBar, ProgressStyle};
use ponq_data::records::{Record, RecordLog, Status};
use ponq_infer::mesh_input::{MeshInput, mesh_band};
use ponq_infer::{InferOptions, RefineMode, finish, predict_band, shipped};
use ponq_mesh::cli::MesherFlags;
use ponq_mesh::mesher::MeshingOptions;
use ponq_mesh::{io, validity};
use ponq_model::backend::{BackendKind, device};

/// Reconstruct a mesh from a signed distance grid (negative inside) or from a mesh with the
/// PoNQ network: SDF grid -> network -> PoNQ -> [refinement] -> Delaunay -> tags -> min cut
/// -> mesh.
///
/// The output is closed, oriented, manifold and free of self-intersections (checked; exit
/// code 3 if not). Exit codes: 0 success, 2 bad input or flags, 3 invalid output, 4 no
/// surface (the field has no sign change at its level, or one but no surface came out;
/// nothing is written). With a folder or list: 0 only
/// when every input is written (valid) or already there, 2 when any failed (each failure
/// printed and in the log), else 3 when an output failed the validity check.
///
/// Only the part of the grid near the surface is kept (read plane by plane; for a mesh,
/// distances are computed there only), so time and memory follow the surface: a 513^3 grid
/// of a part takes 15-20 s and about 1.3 GB, 1025^3 about 90 s and 5 GB (two cores). A run that would not fit in the
/// available memory (or in $PONQ_MEMORY_LIMIT, e.g. 8G) stops before the work with what it
/// needs.
#[derive(Parser, Debug, Clone)]
#[command(version, about, long_about)]
struct Args {
    /// Input: an SDF grid (`.npy` array of rank 3, float32 or float64, C or Fortran order;
    /// signed distances in the units of --bounds, negative inside; cells must be cubes), or a
    /// closed triangle mesh (`.obj`, `.ply`, `.off`, `.stl`), which is normalised into
    /// [-1,1]^3 and sampled on a grid of --res cells per side with exact signed distances
    /// (as `ponq-prep sdf` does); the output is then in the mesh's coordinates. A folder
    /// (searched recursively) or a `.txt` list of such files (one path per line, relative to
    /// the list) runs them all into the folder -o, one OUT/NAME.<--format> each (see
    /// --shard, --log). NAME is the input's path below the folder (or the list's folder)
    /// without its extension (a/model.obj -> OUT/a/model.obj); two inputs that differ only by
    /// their extension or letter case are refused before any work. Outputs already in OUT,
    /// whole, are not redone (a killed run resumes).
    input: PathBuf,
    /// Output mesh (`.obj`, `.ply` or `.off`); with a folder or list as input, the output
    /// folder.
    #[arg(short, long)]
    output: PathBuf,
    /// Folder / list input: the output format of each mesh.
    #[arg(long, value_name = "EXT", default_value = "obj", value_parser = ["obj", "ply", "off"])]
    format: String,
    /// Folder / list input: only shard I of N (e.g. 0/4), a split by the inputs' names
    /// (their hash modulo N) so that N machines or Slurm array tasks cover the inputs exactly
    /// once into one folder; outputs already there are skipped, so a run can be repeated
    /// after a failure.
    #[arg(long, value_name = "I/N")]
    shard: Option<ponq_data::records::Shard>,
    /// Folder / list input: the log, one JSON line per input (name, status done / already /
    /// error, the error, seconds per stage, peak memory, validity, vertex and face counts,
    /// the repair's report), appended [default: OUT/log.jsonl, or
    /// OUT/log-shard-I-of-N.jsonl]; `ponq-eval log` summarises logs.
    #[arg(long, value_name = "LOG.jsonl")]
    log: Option<PathBuf>,
    /// Grid input: the iso-level of the surface [default: 0; a field whose values lie in
    /// [0, 1] without a sign change at 0, an occupancy, is taken at 0.5 with a note].
    #[arg(long, value_name = "L", allow_hyphen_values = true)]
    level: Option<f64>,
    /// Grid input: which side of the level is inside. auto: the side the grid's boundary
    /// lies on is outside (a note when that flips the sign; an error when the boundary lies
    /// on both sides); negative: signed distances as this project writes them; positive:
    /// occupancies, densities, inside-positive SDFs.
    #[arg(long, value_name = "SIDE", default_value = "auto")]
    inside: ponq_data::condition::Inside,
    /// Grid input: what the values are. auto: measured from the slopes at the surface, so
    /// that a distance in other units (voxels, millimetres, a normalised TSDF) is rescaled and
    /// a monotone function of a distance (occupancy, tanh, sigmoid) is mapped back to one,
    /// while a true signed distance in the units of --bounds is used as it is; distance: take
    /// the values as such distances without measuring; redistance: take exact distances to
    /// the field's zero set as marching cubes places it (any field; the surface is then
    /// marching cubes', sharpened by the network). auto falls back to redistance when the
    /// mesh strays from the field's zero set.
    #[arg(long, value_name = "KIND", default_value = "auto")]
    field: ponq_data::condition::FieldKind,
    /// Do not carry colours. By default a coloured input gives each output vertex its colour:
    /// a mesh's (PLY vertex or face `red green blue`, OBJ `v x y z r g b`, OBJ materials and
    /// `map_Kd` textures) at the vertex's closest point on it, a grid's (`.npz` with `sdf`
    /// and `rgb` of shape (nx, ny, nz, 3)) trilinearly; PLY outputs get `uchar red green
    /// blue`, OBJ `v x y z r g b`, OFF `COFF`. An uncoloured input gives the same file as
    /// before colours existed.
    #[arg(long)]
    no_colours: bool,
    /// Mesh input only: cells per side of the SDF grid (RES+1 nodes per side): 32 is coarse
    /// (the network's training resolution), 128 fine [default: 64].
    #[arg(long, value_name = "RES")]
    res: Option<usize>,
    /// Mesh input only: write the output in the normalised [-1,1] frame of the grid (as
    /// `ponq-prep sdf` + `ponq-infer` on its grid would) instead of the input's coordinates.
    #[arg(long)]
    normalized: bool,
    /// Mesh input only: use the mesh as it is, without the repair (the behaviour before it
    /// existed: a mesh that is not closed and consistently oriented is an error unless
    /// --open). By default a mesh is repaired first: vertices within 1e-4 of the diagonal
    /// welded, degenerate and duplicate faces dropped, faces and parts oriented, holes
    /// closed, faces that separate no inside from an outside (internal faces, nested shells,
    /// fins, overlaps) removed; a clean mesh is used unchanged. The defect report says what
    /// was found and done.
    #[arg(long)]
    no_repair: bool,
    /// Mesh input only: also write the defect report as a JSON object to this file.
    #[arg(long, value_name = "REPORT.json")]
    json: Option<PathBuf>,
    /// Refine the network's PoNQ against the grid's exact distances (each node near the
    /// surface gives a surface sample along the first mesh's directions; the quadrics are
    /// refitted to them and the PoNQ meshed again, a few rounds, a round kept only if its
    /// mesh fits the distances better). `auto` refines when the grid passes a check of a true
    /// signed distance (near the surface it falls at rate 1 and never faster), so that scaled,
    /// smoothed or approximate fields are left as the network reads them; `on` always; `off`
    /// never. Not with --open, --lite or --coarsen.
    #[arg(long, value_name = "MODE", default_value = "auto")]
    refine: RefineMode,
    /// Rounds of refinement, each one sampling, refit and meshing; a round is kept only if
    /// its mesh fits the distances better [default: 2 up to 48 cells per side, 1 above: a
    /// second round sharpens a little more and about doubles the refinement's time].
    #[arg(long, value_name = "N", value_parser = clap::value_parser!(u8).range(1..=8))]
    refine_rounds: Option<u8>,
    /// PoNQ-lite: one point per cell (quadrics of the cell summed).
    #[arg(long)]
    lite: bool,
    /// Coarser hierarchy level: merge 2x2x2 blocks of cells K times (implies --lite).
    #[arg(long, value_name = "K", default_value_t = 0)]
    coarsen: u32,
    /// Adaptive PoNQ-lite: merge the points of each cell whose predicted normals agree
    /// within DEG degrees into one (smooth surfaces come out without the small creases that
    /// four noisy points per cell make there, with about half the vertices), keep every point
    /// of the other cells (sharp edges and corners). 0 keeps every point of every cell (plain
    /// PoNQ). Ignored with --lite / --coarsen.
    #[arg(long, value_name = "DEG", default_value_t = ponq_infer::reconstruct::DEFAULT_MERGE_SMOOTH_DEG)]
    merge_smooth: f64,
    /// Open surface: drop triangles away from sharp, planar-like quadrics (threshold T on
    /// the anisotropy lambda2/lambda1, in [0, 1], default 0.35). The output then has a
    /// boundary.
    #[arg(long, value_name = "T", num_args = 0..=1, default_missing_value = "0.35")]
    open: Option<f64>,
    /// Network weights (`.bpk` with its `.json` config beside it) [default: the model
    /// shipped in models/ and built into this program].
    #[arg(long)]
    model: Option<PathBuf>,
    /// The authors' PyTorch weights (`pretrained_PoNQ_ABC.pt`) instead of --model.
    #[arg(long, conflicts_with = "model")]
    authors_weights: Option<PathBuf>,
    /// Compute backend: flex (CPU, default), wgpu (GPU or a software Vulkan driver; needs the
    /// `wgpu` cargo feature) or cuda (NVIDIA; needs the `cuda` cargo feature and a driver).
    #[arg(long, default_value = "flex")]
    backend: BackendKind,
    /// Also write the predicted PoNQ (points, normals, quadrics, v*) as `.npz`.
    #[arg(long, value_name = "P.npz")]
    save_ponq: Option<PathBuf>,
    #[command(flatten)]
    mesher: MesherFlags,
    /// Layer implementation on the CPU: fast (custom kernels, default), fast-bf16 (the same
    /// with bf16 GEMM inputs and f32 sums: AMX tiles or AVX-512 BF16, an error on CPUs
    /// without) or stock (Burn's Conv3d layers). fast and stock give the same numbers up to
    /// float rounding; GPU backends use the stock layers.
    #[arg(long, default_value = "fast")]
    kernels: ponq_model::Kernels,
    /// Worker threads [default: all cores].
    #[arg(long)]
    threads: Option<usize>,
    /// Cells per side of a network tile (the kept core; tiles overlap by the encoder's
    /// reach so the result equals one pass over the whole grid). Bounds peak memory.
    /// [default: 128 with the fast CPU kernels (the encoder runs near the surface only),
    /// 48 otherwise]
    #[arg(long)]
    tile: Option<usize>,
    /// Skip the validity check of the output.
    #[arg(long)]
    no_check: bool,
    /// Print nothing but errors (no progress bars, no summary).
    #[arg(short, long)]
    quiet: bool,
}

/// A spinner for a stage without steps of its own (hidden with --quiet or off a terminal).
fn spinner(quiet: bool, msg: &'static str) -> ProgressBar {
    if quiet {
        return ProgressBar::hidden();
    }
    let pb = ProgressBar::new_spinner();
    pb.set_style(
        ProgressStyle::with_template("{spinner} {msg} [{elapsed}]")
            .unwrap_or_else(|_| ProgressStyle::default_spinner()),
    );
    pb.set_message(msg);
    pb.enable_steady_tick(Duration::from_millis(120));
    pb
}

fn bar(quiet: bool, template: &str) -> ProgressBar {
    if quiet {
        return ProgressBar::hidden();
    }
    let pb = ProgressBar::new(1);
    pb.set_style(
        ProgressStyle::with_template(template).unwrap_or_else(|_| ProgressStyle::default_bar()),
    );
    pb
}

/// Where the output's colours come from.
enum ColourFrom {
    None,
    /// The input mesh (in its coordinates) and its colours.
    Mesh(ponq_mesh::TriMesh, ponq_mesh::colour::Colours),
    /// A colour per node of the grid of these dims.
    Grid(Vec<ponq_mesh::colour::Rgb>, [usize; 3]),
}

/// The colour of each vertex of `mesh` (the output, in the input's coordinates, or the grid's
/// normalised frame with --normalized).
fn vertex_colours(
    source: &ColourFrom,
    mesh: &ponq_mesh::TriMesh,
    normalization: Option<&ponq_data::normalize::Normalization>,
    normalized: bool,
    opts: &InferOptions,
) -> Result<Option<Vec<ponq_mesh::colour::Rgb>>> {
    Ok(match source {
        ColourFrom::None => None,
        ColourFrom::Mesh(input, c) => {
            let points: Vec<[f64; 3]> = match (normalization, normalized) {
                (Some(n), true) => n.invert_mesh(mesh).vertices,
                _ => mesh.vertices.clone(),
            };
            let src = ponq_data::colour_transfer::ColourSource::new(input, c)
                .context("the input mesh's colours")?;
            Some(src.colours(&points))
        }
        ColourFrom::Grid(rgb, dims) => {
            let frame = ponq_infer::Frame::of_dims(*dims, opts.bounds)?;
            Some(ponq_data::colour_transfer::grid_colours(
                rgb,
                *dims,
                frame.lo,
                frame.h,
                &mesh.vertices,
            ))
        }
    })
}

fn is_npz(p: &Path) -> bool {
    p.extension().is_some_and(|e| e.eq_ignore_ascii_case("npz"))
}

fn is_mesh_path(p: &Path) -> bool {
    ponq_mesh::io::MeshFormat::from_path(p).is_some()
}

enum Outcome {
    Valid,
    Invalid,
    Empty,
}

/// What a run measured, for the batch log.
#[derive(Default)]
struct Measured {
    stages: Vec<(String, f64)>,
    vertices: usize,
    faces: usize,
    valid: Option<bool>,
    report: Option<String>,
}

fn run(args: &Args) -> Result<Outcome> {
    run_measured(args, &mut Measured::default())
}

fn run_measured(args: &Args, measured: &mut Measured) -> Result<Outcome> {
    if let Some(e) = args.kernels.unsupported_here() {
        bail!(e);
    }
    if let Some(t) = args.open {
        MeshingOptions::check_open_threshold(t).context("--open")?;
    }
    if !(0.0..=180.0).contains(&args.merge_smooth) {
        bail!(
            "--merge-smooth takes an angle in [0, 180] degrees, got {}",
            args.merge_smooth
        );
    }
    let ext = args
        .output
        .extension()
        .and_then(|e| e.to_str())
        .map(str::to_ascii_lowercase);
    if !matches!(ext.as_deref(), Some("obj" | "ply" | "off")) {
        bail!(
            "the output must end in .obj, .ply or .off: {}",
            args.output.display()
        );
    }
    let bounds = args.mesher.domain().context("--bounds")?;
    let mesh_input = is_mesh_path(&args.input);
    if mesh_input && args.mesher.bounds.is_some() {
        bail!("--bounds is for SDF grids: a mesh input is normalised into [-1,1]^3");
    }
    if mesh_input
        && (args.level.is_some()
            || args.inside != ponq_data::condition::Inside::Auto
            || args.field != ponq_data::condition::FieldKind::Auto)
    {
        bail!(
            "--level, --inside and --field are for grids: a mesh input gives its own exact \
             signed distance"
        );
    }
    if let Some(l) = args.level
        && !l.is_finite()
    {
        bail!("--level takes a finite number, got {l}");
    }
    if !mesh_input
        && (args.res.is_some() || args.normalized || args.no_repair || args.json.is_some())
    {
        bail!(
            "--res, --normalized, --no-repair and --json are for a mesh input (.obj, .ply, .off, \
             .stl)"
        );
    }
    if !args.input.exists() {
        bail!(
            "cannot read the input {}: it does not exist",
            args.input.display()
        );
    }
    let dev = device(args.backend).map_err(anyhow::Error::msg)?;
    let (net, net_cfg, authors) = match (&args.model, &args.authors_weights) {
        (_, Some(pt)) => {
            let cfg = ponq_model::PonqNetConfig::new();
            (
                ponq_model::weights::load_authors_state_dict(pt, &cfg, &dev)?,
                cfg,
                true,
            )
        }
        (Some(p), None) => {
            let (n, c) = ponq_model::weights::load(p, &dev)?;
            (n, c, false)
        }
        (None, None) => {
            let (n, c) = shipped::load(&dev)?;
            (n, c, false)
        }
    };
    let net = net.with_kernels(args.kernels);
    let opts = InferOptions {
        bounds,
        tile: args.tile.unwrap_or(0),
        lite: args.lite,
        coarsen: args.coarsen,
        merge_smooth: (args.merge_smooth > 0.0).then_some(args.merge_smooth),
        open: args.open,
        authors_cell_base: authors,
        align_creases: !args.mesher.no_crease_flips,
        small_tet_rule: args.mesher.small_tet_rule(),
        refine: if args.lite || args.coarsen > 0 {
            RefineMode::Off
        } else {
            args.refine
        },
        refine_options: ponq_data::refine::RefineOptions {
            rounds: args.refine_rounds.map(usize::from),
            ..Default::default()
        },
        condition: ponq_data::condition::ConditionOptions {
            level: args.level,
            // An open surface's boundary lies on both sides: signed distances, unless told.
            inside: match (args.inside, args.open) {
                (ponq_data::condition::Inside::Auto, Some(_)) => {
                    ponq_data::condition::Inside::Negative
                }
                (i, _) => i,
            },
            field: args.field,
        },
        ..Default::default()
    };
    let t = Instant::now();
    let mut conditioning = None;
    let mut source = ColourFrom::None;
    let (grid, normalization) = if mesh_input {
        let (mesh, colours) = if args.no_colours {
            (io::read_mesh(&args.input), None)
        } else {
            match io::read_mesh_coloured_noted(&args.input) {
                Ok((m, c, notes)) => {
                    // Colours never cost the geometry: what could not be read is said.
                    if !args.quiet {
                        for n in notes {
                            eprintln!("note: colours: {n}");
                        }
                    }
                    (Ok(m), c)
                }
                Err(e) => (Err(e), None),
            }
        };
        let mesh =
            mesh.with_context(|| format!("cannot read the mesh {}", args.input.display()))?;
        let res = args.res.unwrap_or(64);
        let pb = bar(
            args.quiet,
            "sdf near the surface {bar:30} {pos}/{len} bricks [{elapsed} < {eta}]",
        );
        let input = MeshInput {
            open_surface: args.open.is_some(),
            repair: !args.no_repair,
        };
        let g = mesh_band(
            &mesh,
            res,
            input,
            net_cfg.encoder_layers,
            &opts,
            |done, total| {
                pb.set_length(total as u64);
                pb.set_position(done as u64);
            },
        )
        .with_context(|| format!("the input mesh {}", args.input.display()))?;
        pb.finish_and_clear();
        if let Some(r) = &g.report {
            if !args.quiet && (r.found_defects() || r.ambiguous_node_share.is_some()) {
                eprintln!("{r}");
            }
            if let Some(path) = &args.json {
                std::fs::write(path, r.to_json() + "\n")
                    .with_context(|| format!("writing the defect report {}", path.display()))?;
            }
            measured.report = Some(r.to_json());
        }
        if g.open && !args.quiet {
            eprintln!(
                "note: the input mesh is open; the grid's sign follows its generalised winding \
                 number (--open culls the triangles away from the surface)"
            );
        }
        if let Some(c) = colours {
            source = ColourFrom::Mesh(mesh, c);
        }
        (g.grid, Some(g.normalization))
    } else {
        let pb = bar(
            args.quiet,
            "{msg} {bar:30} {pos}/{len} planes [{elapsed} < {eta}]",
        );
        let g = if is_npz(&args.input) {
            ponq_infer::grid_input::read_grid_npz(
                &args.input,
                net_cfg.encoder_layers,
                &opts,
                !args.no_colours,
            )
        } else {
            ponq_infer::grid_input::read_grid(
                &args.input,
                net_cfg.encoder_layers,
                &opts,
                |stage, done, total| {
                    pb.set_message(stage.to_string());
                    pb.set_length(total as u64);
                    pb.set_position(done as u64);
                },
            )
        };
        pb.finish_and_clear();
        let g = match g {
            Err(e) if format!("{e:#}").contains("no sign change") => {
                eprintln!("error: {e:#}");
                return Ok(Outcome::Empty);
            }
            g => g?,
        };
        conditioning = Some(g.conditioning);
        if let (Some(c), false) = (g.colours, args.no_colours) {
            source = ColourFrom::Grid(c, g.band.dims());
        }
        (g.band, None)
    };
    let read_time = t.elapsed();
    if (args.lite || args.coarsen > 0) && args.refine == RefineMode::On {
        bail!("--refine on works on the full PoNQ: not with --lite or --coarsen");
    }
    let pb = bar(args.quiet, "network {bar:30} {pos}/{len} tiles [{elapsed}]");
    let dims = grid.dims();
    let tick = |done: usize, total: usize| {
        pb.set_length(total as u64);
        pb.set_position(done as u64);
    };
    let predicted = predict_band(&net, net_cfg.encoder_layers, grid, &opts, &dev, tick);
    let predicted = match predicted {
        Ok(mut r) => {
            r.conditioning = conditioning.clone();
            r
        }
        Err(e) if e.to_string().contains("no sign change") => {
            pb.finish_and_clear();
            eprintln!("error: {e:#}");
            return Ok(Outcome::Empty);
        }
        Err(e) => return Err(e),
    };
    pb.finish_and_clear();
    let sp = spinner(
        args.quiet,
        if opts.refine == RefineMode::Off {
            "meshing"
        } else {
            "meshing and refining"
        },
    );
    let band_mb = predicted.normalised.memory_bytes() as f64 / (1 << 20) as f64;
    let band_share = predicted.normalised.stored_bricks() as f64
        / predicted.normalised.brick_dims().iter().product::<usize>() as f64;
    let close_cells = predicted.close_cells;
    let res = finish(&predicted, &opts);
    drop(predicted);
    sp.finish_and_clear();
    let mut res = res?;
    if !mesh_input && ponq_infer::retry_redistanced(&res, &opts) {
        // The mesh strayed from the field's zero set: read the grid again as exact distances
        // to it, and keep the mesh that keeps closer.
        let mut o2 = opts.clone();
        o2.condition.field = ponq_data::condition::FieldKind::Redistance;
        let sp = spinner(args.quiet, "re-distancing and meshing again");
        let again = if is_npz(&args.input) {
            ponq_infer::grid_input::read_grid_npz(&args.input, net_cfg.encoder_layers, &o2, false)
        } else {
            ponq_infer::grid_input::read_grid(
                &args.input,
                net_cfg.encoder_layers,
                &o2,
                |_, _, _| {},
            )
        };
        let second = again.and_then(|g2| {
            let mut p2 = predict_band(&net, net_cfg.encoder_layers, g2.band, &o2, &dev, |_, _| {})?;
            p2.conditioning = Some(g2.conditioning);
            finish(&p2, &o2)
        });
        res = match second {
            Ok(r2) => ponq_infer::keep_closer(res, r2),
            // A failed second reading leaves the first mesh, with a note.
            Err(e) => {
                ponq_infer::with_note(res, format!("reading it again re-distanced failed: {e:#}"))
            }
        };
        conditioning = res.conditioning.clone();
        sp.finish_and_clear();
    }
    if res.mesh.faces.is_empty() {
        // The field has a sign change, yet nothing came out: never a silent empty file.
        eprintln!(
            "error: the grid has a sign change but no surface came out ({}); nothing is \
             written. Check how its values are read{}: --level (the iso-level), --inside \
             (which side is inside), --field distance (take the values as distances); or mesh \
             a finer grid",
            res.message.as_deref().unwrap_or("the network kept no cell"),
            conditioning
                .as_ref()
                .map(|c: &ponq_data::condition::Conditioning| format!(" ({})", c.summary()))
                .unwrap_or_default()
        );
        return Ok(Outcome::Empty);
    }
    if let Some(norm) = &normalization
        && !args.normalized
    {
        res.mesh = norm.invert_mesh(&res.mesh);
    }
    let t_colours = Instant::now();
    let colours = vertex_colours(
        &source,
        &res.mesh,
        normalization.as_ref(),
        args.normalized,
        &opts,
    )?;
    let colour_time = t_colours.elapsed();
    let t = Instant::now();
    io::write_mesh_coloured(&args.output, &res.mesh, colours.as_deref())
        .context("writing the mesh")?;
    if let Some(p) = &args.save_ponq {
        io::npz::write_ponq(p, &res.ponq).context("writing the PoNQ")?;
    }
    let write_time = t.elapsed();
    let report = (!args.no_check && !res.mesh.faces.is_empty()).then(|| validity::check(&res.mesh));
    let secs = |d: Duration| d.as_secs_f64();
    measured.stages = vec![
        (
            if normalization.is_some() {
                "read + sdf"
            } else {
                "read"
            }
            .to_string(),
            secs(read_time),
        ),
        ("network".into(), secs(res.times.network)),
        ("to PoNQ".into(), secs(res.times.convert)),
        ("meshing".into(), secs(res.times.meshing)),
        ("refinement".into(), secs(res.times.refine)),
        ("write".into(), secs(write_time)),
    ];
    measured.vertices = res.mesh.vertices.len();
    measured.faces = res.mesh.faces.len();
    if !args.quiet {
        let ms = |d: std::time::Duration| d.as_secs_f64() * 1e3;
        let s = &res.meshing;
        if let Some(n) = &normalization {
            println!(
                "{}: normalised by centre {:?}, scale {:.6e}; output in {} coordinates",
                args.input.display(),
                n.centre,
                n.scale,
                if args.normalized {
                    "the grid's [-1,1]"
                } else {
                    "the input's"
                }
            );
        }
        println!(
            "{}: grid {:?} (stored near the surface: {band_mb:.0} MB, {:.1}% of the grid) -> {close_cells} cells near the surface -> {} cells kept, {} points -> {} V, {} F",
            args.output.display(),
            dims,
            100.0 * band_share,
            res.kept_cells,
            res.ponq.len(),
            res.mesh.vertices.len(),
            res.mesh.faces.len()
        );
        if colours.is_some() {
            println!(
                "colours: {} of the output's {} vertices, {} ({:.1} ms)",
                match &source {
                    ColourFrom::Mesh(..) => "at the closest points of the input mesh",
                    ColourFrom::Grid(..) => "trilinear in the grid's 'rgb'",
                    ColourFrom::None => "",
                },
                res.mesh.vertices.len(),
                if args
                    .output
                    .extension()
                    .is_some_and(|e| e.eq_ignore_ascii_case("ply"))
                {
                    "uchar red green blue"
                } else {
                    "written per vertex"
                },
                colour_time.as_secs_f64() * 1e3
            );
        }
        if let Some(c) = &conditioning {
            match res.surface_agreement {
                Some(a) => println!(
                    "{}; the mesh and the field's zero set cover each other to {:.1}%",
                    c.summary(),
                    100.0 * a
                ),
                None => println!("{}", c.summary()),
            }
        }
        if let Some(m) = &res.message {
            println!("note: {m}");
        }
        if s.welded > 0 {
            println!(
                "note: {} points welded onto others a rounding away{} (see ponq-mesh --weld)",
                s.welded,
                if s.meshed_twice { ", meshed twice" } else { "" }
            );
        }
        if opts.refine != RefineMode::Off {
            println!("{}", res.refinement.summary());
        }
        println!(
            "time (ms): {} {:.1}, network {:.1} ({} tiles), to PoNQ {:.1}, meshing {:.1} (delaunay {:.1}, tagging {:.1}, cut {:.1}, manifold {:.1}, extraction {:.1}, flips {:.1}), refinement {:.1}, write {:.1}",
            if normalization.is_some() {
                "read + sdf"
            } else {
                "read"
            },
            ms(read_time),
            ms(res.times.network),
            res.tiles,
            ms(res.times.convert),
            ms(res.times.meshing),
            ms(s.times.delaunay),
            ms(s.times.tagging),
            ms(s.times.cut),
            ms(s.times.manifold),
            ms(s.times.extraction),
            ms(s.times.flips),
            ms(res.times.refine),
            ms(write_time)
        );
        if let Some(r) = &report {
            if args.open.is_some() {
                // An open surface passes with boundary edges (and the vertices on them).
                println!(
                    "validity (open surface: boundary edges expected; needs no self-intersection, no non-manifold edge or vertex): {r}"
                );
            } else {
                println!("validity: {r}");
            }
        }
    }
    Ok(match &report {
        None => Outcome::Valid,
        Some(r) => {
            let ok = if args.open.is_some() {
                r.is_valid_open_surface()
            } else {
                r.is_valid()
            };
            measured.valid = Some(ok);
            if ok { Outcome::Valid } else { Outcome::Invalid }
        }
    })
}

/// Whether the input names many inputs: a folder, or a `.txt` / `.lst` list.
fn is_batch(p: &Path) -> bool {
    p.is_dir()
        || p.extension()
            .and_then(|e| e.to_str())
            .is_some_and(|e| matches!(e.to_ascii_lowercase().as_str(), "txt" | "lst"))
}

/// The inputs of a folder (meshes and `.npy` grids, recursively, sorted) or a list.
fn batch_inputs(p: &Path) -> Result<Vec<PathBuf>> {
    ponq_data::prep::input_files(p, |f| {
        is_mesh_path(f) || f.extension().is_some_and(|e| e.eq_ignore_ascii_case("npy"))
    })
    .with_context(|| format!("listing the inputs of {}", p.display()))
}

/// What a folder or list run did.
#[derive(Default)]
struct BatchCounts {
    done: usize,
    already: usize,
    failed: usize,
    invalid: usize,
}

/// `ponq-infer DIR -o OUT`: every input into OUT/NAME.EXT (names: `ponq_data::names`), one
/// log record each.
fn run_batch(args: &Args) -> Result<BatchCounts> {
    if args.json.is_some() || args.save_ponq.is_some() {
        bail!(
            "--json and --save-ponq name one file: not with a folder or list input (the log holds each input's report)"
        );
    }
    let inputs = batch_inputs(&args.input)?;
    if inputs.is_empty() {
        bail!(
            "no input (.npy, .obj, .ply, .off, .stl) in {}",
            args.input.display()
        );
    }
    // Distinct names (paths below the input folder), or a refusal before any work.
    let root = ponq_data::prep::input_root(&args.input);
    let names = ponq_data::names::output_names(&inputs, &root).context("naming the outputs")?;
    let mine: Vec<(&PathBuf, &String)> = inputs
        .iter()
        .zip(&names)
        .filter(|(_, n)| args.shard.is_none_or(|s| s.contains(n)))
        .collect();
    std::fs::create_dir_all(&args.output)
        .with_context(|| format!("creating the output folder {}", args.output.display()))?;
    let log_path = args
        .log
        .clone()
        .unwrap_or_else(|| ponq_data::records::default_log(&args.output, args.shard));
    let log = RecordLog::append(&log_path).context("opening the log")?;
    let stale = ponq_data::outputs::StalePartials::find(&args.output);
    let pb = bar(
        args.quiet,
        "shapes {bar:30} {pos}/{len} [{elapsed} < {eta}] {msg}",
    );
    pb.set_length(mine.len() as u64);
    let mut counts = BatchCounts::default();
    let mut stale_removed = 0;
    for (input, n) in mine {
        pb.set_message(n.clone());
        let output = ponq_data::names::output_path(&args.output, n, &args.format);
        let started = Instant::now();
        stale_removed += stale.remove_for(&output);
        // An output there counts as done only when whole (a run that crashed may have left
        // a cut file under older versions, or a full disk).
        let cut = output.exists() && !ponq_data::outputs::is_whole(&output);
        let record = if !cut && output.is_file() {
            counts.already += 1;
            Record::new(n, input, Status::Already)
        } else {
            let mut one = args.clone();
            one.input = input.clone();
            if let Some(dir) = output.parent() {
                std::fs::create_dir_all(dir)
                    .with_context(|| format!("creating the folder {}", dir.display()))?;
            }
            // Written under a temporary name, committed (flushed, renamed) when whole and
            // checked: a killed run leaves nothing the next run would take as done.
            let partial = ponq_data::outputs::partial_path(&output);
            one.output = partial.clone();
            one.quiet = true;
            if !is_mesh_path(input) {
                // The mesh-only flags apply to the meshes of a mixed folder.
                one.res = None;
                one.normalized = false;
                one.no_repair = false;
            }
            let mut m = Measured::default();
            let outcome = run_measured(&one, &mut m);
            let mut r = match &outcome {
                Ok(Outcome::Valid | Outcome::Invalid) => Record::new(n, input, Status::Done),
                Ok(Outcome::Empty) => {
                    let mut r = Record::new(n, input, Status::Error);
                    r.error = Some(
                        "no surface: the field has no sign change at its level, or none came \
                         out (see --level, --inside, --field)"
                            .into(),
                    );
                    r
                }
                Err(e) => {
                    let mut r = Record::new(n, input, Status::Error);
                    r.error = Some(format!("{e:#}"));
                    r
                }
            };
            if r.status == Status::Done
                && let Err(e) = ponq_data::outputs::commit(&partial, &output)
            {
                r.status = Status::Error;
                r.error = Some(format!("{e:#}"));
            }
            if r.status == Status::Done {
                counts.done += 1;
                if matches!(outcome, Ok(Outcome::Invalid)) {
                    counts.invalid += 1;
                }
                if cut {
                    r.warning = Some("its output was cut (a run that crashed): redone".into());
                }
                r.vertices = Some(m.vertices);
                r.faces = Some(m.faces);
            } else {
                counts.failed += 1;
                let _ = std::fs::remove_file(&partial);
                if let Some(e) = &r.error {
                    pb.suspend(|| eprintln!("failed {n}: {e}"));
                }
            }
            r.stages = m.stages;
            r.valid = m.valid;
            r.report = m.report;
            r
        };
        let mut record = record;
        record.shards = args.shard.map_or(1, |s| s.count());
        record.seconds = started.elapsed().as_secs_f64();
        log.write(&record).context("writing the log")?;
        // The next shape's memory budget is measured afresh: give back what this one freed.
        ponq_mesh::memory::release_freed();
        pb.inc(1);
    }
    pb.finish_and_clear();
    if !args.quiet {
        println!(
            "{}: {} meshes written, {} already there, {} failed{}; log {}",
            args.output.display(),
            counts.done,
            counts.already,
            counts.failed,
            args.shard
                .map(|s| format!(" (shard {s})"))
                .unwrap_or_default(),
            log_path.display()
        );
        if stale_removed > 0 {
            println!("note: removed {stale_removed} temporary file(s) of runs that crashed");
        }
    }
    if counts.failed > 0 {
        eprintln!(
            "error: {} input(s) failed (see the log {})",
            counts.failed,
            log_path.display()
        );
    }
    if counts.invalid > 0 {
        eprintln!(
            "error: {} output(s) failed the validity check (written; `valid: false` in the log {})",
            counts.invalid,
            log_path.display()
        );
    }
    Ok(counts)
}

fn main() -> ExitCode {
    ponq_mesh::memory::keep_freed_memory();
    let args = Args::parse();
    if let Some(t) = args.threads
        && let Err(e) = rayon::ThreadPoolBuilder::new()
            .num_threads(t.max(1))
            .build_global()
    {
        eprintln!("error: cannot set the thread count: {e}");
        return ExitCode::from(2);
    }
    // A memory setting that cannot be read is an error before any work.
    if let Err(e) = ponq_mesh::memory::budget() {
        eprintln!("error: {e}");
        return ExitCode::from(2);
    }
    if is_batch(&args.input) {
        return match run_batch(&args) {
            Ok(c) if c.failed > 0 => ExitCode::from(2),
            Ok(c) if c.invalid > 0 => ExitCode::from(3),
            Ok(_) => ExitCode::SUCCESS,
            Err(e) => {
                eprintln!("error: {e:#}");
                ExitCode::from(2)
            }
        };
    }
    if args.shard.is_some() || args.log.is_some() {
        eprintln!("error: --shard and --log are for a folder or list input");
        return ExitCode::from(2);
    }
    match run(&args) {
        Ok(Outcome::Valid) => ExitCode::SUCCESS,
        Ok(Outcome::Invalid) => {
            eprintln!("error: the output mesh failed the validity check (see above)");
            ExitCode::from(3)
        }
        Ok(Outcome::Empty) => ExitCode::from(4),
        Err(e) => {
            eprintln!("error: {e:#}");
            ExitCode::from(2)
        }
    }
}
