//! `ponq-infer`: an SDF grid (`.npy`) in, a sharp watertight mesh out, with the trained
//! PoNQ network.

use std::path::PathBuf;
use std::process::ExitCode;
use std::time::Instant;

use anyhow::{Context, Result, bail};
use clap::Parser;
use indicatif::{ProgressBar, ProgressStyle};
use ponq_infer::{InferOptions, infer, shipped};
use ponq_mesh::mesher::MeshingOptions;
use ponq_mesh::tagging::SmallTetRule;
use ponq_mesh::{io, validity};
use ponq_model::backend::{BackendKind, device};

/// Reconstruct a mesh from a signed distance grid (negative inside) with the PoNQ network:
/// SDF grid -> network -> PoNQ -> Delaunay -> tags -> min cut -> mesh.
///
/// The output is closed, oriented, manifold and free of self-intersections (checked; exit
/// code 3 if not). Exit codes: 0 success, 2 bad input or flags, 3 invalid output, 4 empty
/// surface (the SDF has no sign change; nothing is written).
#[derive(Parser, Debug)]
#[command(version, about, long_about)]
struct Args {
    /// SDF grid: a `.npy` array of rank 3, float32 or float64, C or Fortran order. Values are
    /// signed distances in the units of --bounds, negative inside; cells must be cubes.
    sdf: PathBuf,
    /// Output mesh (`.obj`, `.ply` or `.off`).
    #[arg(short, long)]
    output: PathBuf,
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
    /// Box spanned by the grid nodes: xmin,ymin,zmin,xmax,ymax,zmax [default: -1,-1,-1,1,1,1].
    #[arg(
        long,
        value_delimiter = ',',
        allow_hyphen_values = true,
        value_name = "X0,Y0,Z0,X1,Y1,Z1"
    )]
    bounds: Option<Vec<f64>>,
    /// Also write the predicted PoNQ (points, normals, quadrics, v*) as `.npz`.
    #[arg(long, value_name = "P.npz")]
    save_ponq: Option<PathBuf>,
    /// Keep the triangles of the minimum cut as they are: no flips of quadrilateral diagonals
    /// onto the sharp edges the quadrics describe.
    #[arg(long)]
    no_crease_flips: bool,
    /// The small-tet rule of the tagging: `inside` (default: a vertex with an outside tet but no
    /// inside tet gets its smallest unknown tet tagged inside, if small; the authors' intent),
    /// `authors` (their code to the letter: the smallest of all the vertex's tets, whatever its
    /// label, flags read once), `both` (the paper's text: inside and outside tets; the rule
    /// before 2026-12-03). See README, mesher section.
    #[arg(long, value_name = "RULE", default_value = "inside")]
    small_tets: SmallTetRule,
    /// Same as `--small-tets both` (kept for earlier scripts).
    #[arg(long, conflicts_with = "small_tets")]
    small_tets_both_ways: bool,
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
    /// Print nothing but errors.
    #[arg(short, long)]
    quiet: bool,
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
    let bounds = match &args.bounds {
        None => ([-1.0; 3], [1.0; 3]),
        Some(b) => MeshingOptions::domain_from(b).context("--bounds")?,
    };
    let dev = device(args.backend).map_err(anyhow::Error::msg)?;
    let t = Instant::now();
    let grid = io::npy::read_npy_grid(&args.sdf)
        .with_context(|| format!("cannot read the SDF grid {}", args.sdf.display()))?;
    let read_time = t.elapsed();
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
        align_creases: !args.no_crease_flips,
        small_tet_rule: if args.small_tets_both_ways {
            SmallTetRule::BothWays
        } else {
            args.small_tets
        },
        ..Default::default()
    };
    let pb = if args.quiet {
        ProgressBar::hidden()
    } else {
        let pb = ProgressBar::new(1);
        pb.set_style(
            ProgressStyle::with_template("network {bar:30} {pos}/{len} tiles [{elapsed}]")
                .unwrap_or_else(|_| ProgressStyle::default_bar()),
        );
        pb
    };
    let res = match infer(
        &net,
        net_cfg.encoder_layers,
        &grid,
        &opts,
        &dev,
        |done, total| {
            pb.set_length(total as u64);
            pb.set_position(done as u64);
        },
    ) {
        Ok(r) => r,
        Err(e) if e.to_string().contains("no sign change") => {
            pb.finish_and_clear();
            eprintln!("error: {e:#}");
            return Ok(Outcome::Empty);
        }
        Err(e) => return Err(e),
    };
    pb.finish_and_clear();
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
        println!(
            "{}: grid {:?} -> {} cells kept, {} points -> {} V, {} F",
            args.output.display(),
            grid.dims,
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
        println!(
            "time (ms): read {:.1}, network {:.1} ({} tiles), to PoNQ {:.1}, meshing {:.1} (delaunay {:.1}, tagging {:.1}, cut {:.1}, manifold {:.1}, extraction {:.1}, flips {:.1}), write {:.1}",
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
            ms(write_time)
        );
        if let Some(r) = &report {
            if args.open.is_some() {
                // An open surface passes with boundary edges (and the vertices on them).
                println!(
                    "validity (open surface: boundary edges expected; needs no self-intersection, no non-manifold edge): {r}"
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
                r.self_intersections == 0 && r.nonmanifold_edges == 0
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
