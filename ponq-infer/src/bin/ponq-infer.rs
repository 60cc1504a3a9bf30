//! `ponq-infer`: an SDF grid (`.npy`) or a mesh in, a sharp watertight mesh out, with the
//! trained PoNQ network.

use std::path::{Path, PathBuf};
use std::process::ExitCode;
use std::time::{Duration, Instant};

use anyhow::{Context, Result, bail};
use clap::Parser;
use indicatif::{ProgressBar, ProgressStyle};
use ponq_infer::mesh_input::{MeshInput, mesh_band};
use ponq_infer::reconstruct::band_parameters;
use ponq_infer::{Frame, InferOptions, RefineMode, finish, predict_band, shipped};
use ponq_mesh::cli::MesherFlags;
use ponq_mesh::mesher::MeshingOptions;
use ponq_mesh::{io, validity};
use ponq_model::backend::{BackendKind, device};

/// Reconstruct a mesh from a signed distance grid (negative inside) or from a mesh with the
/// PoNQ network: SDF grid -> network -> PoNQ -> [refinement] -> Delaunay -> tags -> min cut
/// -> mesh.
///
/// The output is closed, oriented, manifold and free of self-intersections (checked; exit
/// code 3 if not). Exit codes: 0 success, 2 bad input or flags, 3 invalid output, 4 empty
/// surface (the SDF has no sign change; nothing is written).
#[derive(Parser, Debug)]
#[command(version, about, long_about)]
struct Args {
    /// Input: an SDF grid (`.npy` array of rank 3, float32 or float64, C or Fortran order;
    /// signed distances in the units of --bounds, negative inside; cells must be cubes), or a
    /// closed triangle mesh (`.obj`, `.ply`, `.off`, `.stl`), which is normalised into
    /// [-1,1]^3 and sampled on a grid of --res cells per side with exact signed distances
    /// (as `ponq-prep sdf` does); the output is then in the mesh's coordinates.
    input: PathBuf,
    /// Output mesh (`.obj`, `.ply` or `.off`).
    #[arg(short, long)]
    output: PathBuf,
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

fn is_mesh_path(p: &Path) -> bool {
    ponq_mesh::io::MeshFormat::from_path(p).is_some()
}

enum Outcome {
    Valid,
    Invalid,
    Empty,
}

fn run(args: &Args) -> Result<Outcome> {
    if let Some(e) = args.kernels.unsupported_here() {
        bail!(e);
    }
    if let Some(t) = args.threads {
        rayon::ThreadPoolBuilder::new()
            .num_threads(t.max(1))
            .build_global()
            .context("cannot set the thread count")?;
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
        ..Default::default()
    };
    let t = Instant::now();
    let (grid, normalization) = if mesh_input {
        let mesh = io::read_mesh(&args.input)
            .with_context(|| format!("cannot read the mesh {}", args.input.display()))?;
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
        }
        if g.open && !args.quiet {
            eprintln!(
                "note: the input mesh is open; the grid's sign follows its generalised winding \
                 number (--open culls the triangles away from the surface)"
            );
        }
        (g.grid, Some(g.normalization))
    } else {
        let pb = bar(
            args.quiet,
            "read {bar:30} {pos}/{len} planes [{elapsed} < {eta}]",
        );
        let band = io::npy::read_npy_band(
            &args.input,
            |dims| {
                let frame = Frame::of_dims(dims, bounds)
                    .map_err(|e| ponq_mesh::Error::InvalidInput(format!("{e:#}")))?;
                let (t, reach) = band_parameters(frame.n, net_cfg.encoder_layers, &opts);
                // The band may take half of what is free; the rest is for the network and
                // the meshing (checked again before the network runs).
                let limit = ponq_mesh::memory::available_bytes().map(|b| b as usize / 2);
                Ok((frame.scale(), t, reach, limit))
            },
            |done, total| {
                pb.set_length(total as u64);
                pb.set_position(done as u64);
            },
        )
        .with_context(|| format!("cannot read the SDF grid {}", args.input.display()))?;
        pb.finish_and_clear();
        (band, None)
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
        Ok(r) => r,
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
    if let Some(norm) = &normalization
        && !args.normalized
    {
        res.mesh = norm.invert_mesh(&res.mesh);
    }
    let t = Instant::now();
    io::write_mesh(&args.output, &res.mesh).context("writing the mesh")?;
    if let Some(p) = &args.save_ponq {
        io::npz::write_ponq(p, &res.ponq).context("writing the PoNQ")?;
    }
    let write_time = t.elapsed();
    let report = (!args.no_check && !res.mesh.faces.is_empty()).then(|| validity::check(&res.mesh));
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
            if ok { Outcome::Valid } else { Outcome::Invalid }
        }
    })
}

fn main() -> ExitCode {
    ponq_mesh::memory::keep_freed_memory();
    let args = Args::parse();
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
