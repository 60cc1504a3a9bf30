//! `ponq-mesh`: mesh a stored PoNQ file (`.npz`) into a watertight manifold triangle mesh.

use std::path::PathBuf;
use std::process::ExitCode;
use std::time::Instant;

use anyhow::{Context, Result, bail};
use clap::Parser;
use ponq_mesh::cli::MesherFlags;
use ponq_mesh::io;
use ponq_mesh::lite::simplify_by_position;
use ponq_mesh::mesher::{MeshingOptions, mesh_ponq};
use ponq_mesh::tagging::SmallTetRule;
use ponq_mesh::validity;

/// Mesh a PoNQ file (points, normals, quadrics) into a closed, oriented, manifold,
/// self-intersection-free triangle mesh.
///
/// The input is an `.npz` with arrays `points` (M,3), `normals` (M,3), `quadrics` (M,4,4)
/// (float32 or float64) and optionally `vstars` (M,3), in the frame of the grid domain
/// (the [-1,1]^3 box unless --bounds says otherwise).
#[derive(Parser, Debug)]
#[command(
    version,
    about,
    long_about,
    after_help = "Environment: PONQ_NO_AVX2=1 runs the portable code instead of the AVX2 \
                  paths (the same mesh, slower); RAYON_NUM_THREADS sets the worker threads where \
                  --threads is not given."
)]
struct Args {
    /// Input PoNQ file (.npz).
    input: PathBuf,
    /// Output mesh (.obj, .ply or .off).
    #[arg(short, long)]
    output: PathBuf,
    /// Resolution N of the grid the PoNQ was made on (N cells per side): sets the face-score
    /// weight h = N^2, the small-tet threshold and the cells of --lite.
    #[arg(long, default_value_t = 32.0)]
    grid_scale: f64,
    /// PoNQ-lite: merge the points of each grid cell into one (quadrics summed). Cells are
    /// found from the point positions.
    #[arg(long)]
    lite: bool,
    /// Hierarchy: with --lite, merge 2x2x2 blocks of cells K more times (grid N / 2^K).
    #[arg(long, value_name = "K", default_value_t = 0)]
    coarsen: u32,
    /// Adaptive PoNQ-lite: merge the points of each grid cell (found from the point
    /// positions) whose normals agree within DEG degrees into one; keep the other cells'
    /// points (sharp edges and corners). Not with --lite.
    #[arg(long, value_name = "DEG")]
    merge_smooth: Option<f64>,
    /// Open surface: drop the triangles whose three vertices all have quadric anisotropy
    /// (lambda2/lambda1) above T, in [0, 1]. Without a value T = 0.35.
    #[arg(long, value_name = "T", num_args = 0..=1, default_missing_value = "0.35")]
    open: Option<f64>,
    /// Skip the manifold repair (output is still closed and free of self-intersections,
    /// but may have non-manifold edges or vertices, as the authors' mesher).
    #[arg(long)]
    no_manifold: bool,
    #[command(flatten)]
    mesher: MesherFlags,
    /// The authors' mesher to the letter: `--small-tets authors --no-crease-flips
    /// --no-manifold`. With an exact minimum cut in their code its output is ours face for
    /// face (docs/meshing.md); like theirs it may have non-manifold edges or vertices.
    #[arg(long, conflicts_with_all = ["small_tets", "small_tets_both_ways", "lite", "open"])]
    authors_mesher: bool,
    /// Weld tolerance relative to the domain size: v* this close (two v* a rounding apart)
    /// become one vertex, quadrics summed, so that no near-zero-area triangle is left (if the
    /// Delaunay's merge misses a pair, the PoNQ is meshed again). 0 turns it off.
    #[arg(long, value_name = "REL", allow_hyphen_values = true, default_value_t = ponq_mesh::mesher::DEFAULT_WELD)]
    weld: f64,
    /// Skip the exact validity check of the output (it is cheap; on by default).
    #[arg(long)]
    no_check: bool,
    /// Worker threads [default: all cores]. The mesh is the same for any count (the
    /// Delaunay output is put in a canonical order; the later stages are deterministic).
    #[arg(long)]
    threads: Option<usize>,
    /// Print nothing but errors.
    #[arg(short, long)]
    quiet: bool,
}

fn run(args: &Args) -> Result<bool> {
    if let Some(t) = args.threads {
        if t == 0 {
            bail!("--threads must be at least 1");
        }
        rayon::ThreadPoolBuilder::new()
            .num_threads(t)
            .build_global()
            .context("cannot set the thread count")?;
    }
    if let Some(t) = args.open {
        MeshingOptions::check_open_threshold(t).context("--open")?;
    }
    if args.coarsen > 0 && !args.lite {
        bail!("--coarsen needs --lite");
    }
    if args.merge_smooth.is_some() && args.lite {
        bail!("--merge-smooth and --lite exclude each other (--lite merges every cell)");
    }
    let domain = args.mesher.domain().context("--bounds")?;
    let t0 = Instant::now();
    let ponq = io::npz::read_ponq(&args.input).context("reading the PoNQ file")?;
    let read_time = t0.elapsed();
    let grid_scale = args.grid_scale;
    if !(grid_scale >= 1.0 && grid_scale.is_finite()) {
        bail!("--grid-scale must be >= 1, got {grid_scale}");
    }
    let (ponq, grid_scale) = simplify_by_position(
        &ponq,
        grid_scale,
        domain,
        args.lite,
        args.coarsen,
        args.merge_smooth,
    )?;
    let opts = MeshingOptions {
        grid_scale,
        domain,
        manifold: !(args.no_manifold || args.authors_mesher),
        open_threshold: args.open,
        align_creases: !(args.mesher.no_crease_flips || args.authors_mesher),
        flat_caps: !(args.mesher.no_crease_flips || args.authors_mesher),
        small_tet_rule: if args.authors_mesher {
            SmallTetRule::Authors
        } else {
            args.mesher.small_tet_rule()
        },
        weld: args.weld,
        ..Default::default()
    };
    let out = mesh_ponq(&ponq, &opts)?;
    let t1 = Instant::now();
    io::write_mesh(&args.output, &out.mesh).context("writing the mesh")?;
    let write_time = t1.elapsed();
    let report = (!args.no_check).then(|| {
        let t = Instant::now();
        (validity::check(&out.mesh), t.elapsed())
    });
    if !args.quiet {
        let s = &out.stats;
        let ms = |d: std::time::Duration| d.as_secs_f64() * 1e3;
        println!(
            "{}: {} points -> {} V, {} F",
            args.output.display(),
            s.points,
            out.mesh.vertices.len(),
            out.mesh.faces.len()
        );
        if let Some(msg) = &out.message {
            println!("note: {msg}");
        }
        println!(
            "tets {} (tagged in {}, out {}, unknown {}), cut graph {} nodes / {} edges, manifold repair flipped {} tets, {} crease flips, {} flat caps flipped ({} attempts); {} worker threads, {}",
            s.tets,
            s.tagged[0],
            s.tagged[1],
            s.tagged[2],
            s.cut.nodes,
            s.cut.edges,
            s.manifold.flipped_tets,
            s.flips.flips,
            s.caps.flips,
            s.caps.attempts,
            rayon::current_num_threads(),
            if ponq_mesh::cpu::has_avx2() {
                "AVX2 paths"
            } else {
                "portable code (no AVX2, or PONQ_NO_AVX2 set)"
            }
        );
        if s.welded > 0 {
            println!(
                "welded {} points onto others within {:e} of the domain size{}",
                s.welded,
                args.weld,
                if s.meshed_twice {
                    " (meshed twice)"
                } else {
                    ""
                }
            );
        }
        println!(
            "time (ms): read {:.1}, prepare {:.1}, delaunay {:.1}, tagging {:.1}, cut {:.1}, manifold {:.1}, extraction {:.1}, flips {:.1}, write {:.1}; meshing total {:.1}",
            ms(read_time),
            ms(s.times.prepare),
            ms(s.times.delaunay),
            ms(s.times.tagging),
            ms(s.times.cut),
            ms(s.times.manifold),
            ms(s.times.extraction),
            ms(s.times.flips),
            ms(write_time),
            ms(s.times.total())
        );
        if let Some((r, d)) = &report {
            if args.open.is_some() {
                // An open surface passes with boundary edges (and the vertices on them).
                println!(
                    "validity (open surface: boundary edges expected; needs no self-intersection, no non-manifold edge or vertex): {r} (checked in {:.1} ms)",
                    ms(*d)
                );
            } else {
                println!("validity: {r} (checked in {:.1} ms)", ms(*d));
            }
        }
    }
    let ok = match &report {
        None => true,
        Some((r, _)) => {
            if args.open.is_some() {
                // Open meshes have boundary edges by design.
                r.is_valid_open_surface()
            } else if args.no_manifold || args.authors_mesher {
                // Without the repair, non-manifold edges/vertices are expected (as in the
                // authors' mesher); the surface must still be embedded.
                r.self_intersections == 0 && r.boundary_edges == 0
            } else {
                r.is_valid()
            }
        }
    };
    Ok(ok)
}

fn main() -> ExitCode {
    ponq_mesh::memory::keep_freed_memory();
    let args = Args::parse();
    match run(&args) {
        Ok(true) => ExitCode::SUCCESS,
        Ok(false) => {
            eprintln!("error: the output mesh failed the validity check (see above)");
            ExitCode::from(3)
        }
        Err(e) => {
            eprintln!("error: {e:#}");
            ExitCode::from(2)
        }
    }
}
