//! `ponq-fit`: optimisation-based PoNQ of a mesh (no network).

use std::path::PathBuf;
use std::process::ExitCode;

use anyhow::{Context, Result, bail};
use clap::Parser;
use indicatif::{ProgressBar, ProgressStyle};
use ponq_data::fit::{FitOptions, fit_mesh};
use ponq_mesh::{io, validity};

/// Fit a PoNQ to a mesh (points optimised with Adam on the Chamfer distance to surface
/// samples, then normals and quadrics per Voronoi cell) and mesh it: a closed, manifold,
/// self-intersection-free approximation with sharp features.
#[derive(Parser, Debug)]
#[command(version, about, long_about)]
struct Args {
    /// Input mesh (.obj, .ply, .off, .stl).
    input: PathBuf,
    /// Output mesh (.obj, .ply, .off).
    #[arg(short, long)]
    output: PathBuf,
    /// Grid resolution: initial points at the corners of the occupied cells of a GRID^3 grid
    /// over the normalised shape; also the meshing scale. The paper uses 32, 64 and 128.
    #[arg(long, default_value_t = 32)]
    grid: usize,
    /// Also save the fitted PoNQ (.npz, [-1,1] frame).
    #[arg(long, value_name = "P.npz")]
    save_ponq: Option<PathBuf>,
    /// Open surface: add boundary samples with rotated normals and drop the triangles whose
    /// vertices are all anisotropic (threshold T, default 0.35).
    #[arg(long, value_name = "T", num_args = 0..=1, default_missing_value = "0.35")]
    open: Option<f64>,
    /// PoNQ-lite: one point per grid cell (fewer vertices, same sharp features).
    #[arg(long)]
    lite: bool,
    /// Write the output in the input's coordinates instead of the [-1,1] frame.
    #[arg(long)]
    original_frame: bool,
    /// Surface samples (default 100,000 * (grid/32)^2).
    #[arg(long)]
    samples: Option<usize>,
    /// Adam iterations.
    #[arg(long, default_value_t = 400)]
    iterations: usize,
    /// Seed of the sampling and mini-batches.
    #[arg(long, default_value_t = 0)]
    seed: u64,
    /// Use the mesh as it is, without the repair (by default it is repaired first: vertices
    /// within 1e-4 of the diagonal welded, degenerate and duplicate faces dropped, faces and
    /// parts oriented, holes closed and faces that separate no inside from an outside removed
    /// (with --open: nothing closed or removed); a clean mesh is used unchanged).
    #[arg(long)]
    no_repair: bool,
    /// Print nothing but errors (no progress bar).
    #[arg(short, long)]
    quiet: bool,
}

fn run(a: &Args) -> Result<bool> {
    if let Some(t) = a.open
        && !(0.0..=1.0).contains(&t)
    {
        bail!("--open threshold must be in [0, 1], got {t}");
    }
    let mesh = io::read_mesh(&a.input).context("reading the input mesh")?;
    let bar = if a.quiet {
        ProgressBar::hidden()
    } else {
        ProgressBar::new(a.iterations as u64)
    };
    bar.set_style(
        ProgressStyle::with_template("fit {bar:40} {pos}/{len} iterations [{elapsed} < {eta}]")
            .unwrap_or_else(|_| ProgressStyle::default_bar()),
    );
    let opts = FitOptions {
        grid: a.grid,
        samples: a.samples,
        iterations: a.iterations,
        open: a.open,
        lite: a.lite,
        seed: a.seed,
        repair: !a.no_repair,
        ..Default::default()
    };
    let fitted = fit_mesh(&mesh, &opts, |i| bar.set_position(i as u64))?;
    bar.finish_and_clear();
    if let Some(r) = &fitted.report
        && !a.quiet
        && r.found_defects()
    {
        eprintln!("{r}");
    }
    if let Some(p) = &a.save_ponq {
        io::npz::write_ponq(p, &fitted.ponq).context("writing the PoNQ file")?;
    }
    let out = if a.original_frame {
        fitted.normalization.invert_mesh(&fitted.meshing.mesh)
    } else {
        fitted.meshing.mesh.clone()
    };
    io::write_mesh(&a.output, &out).context("writing the output mesh")?;
    let report = validity::check(&fitted.meshing.mesh);
    let ok = if a.open.is_some() {
        report.is_valid_open_surface()
    } else {
        report.is_valid()
    };
    if !a.quiet {
        let ms = |d: std::time::Duration| d.as_secs_f64() * 1e3;
        println!(
            "{}: {} points -> {} V, {} F; final Chamfer loss {:.3e}",
            a.output.display(),
            fitted.ponq.len(),
            out.vertices.len(),
            out.faces.len(),
            fitted.final_loss
        );
        if let Some(m) = &fitted.meshing.message {
            println!("note: {m}");
        }
        let [s, f, p, m] = fitted.times;
        println!(
            "time (ms): sampling {:.0}, fit {:.0}, ponq {:.0}, meshing {:.0}",
            ms(s),
            ms(f),
            ms(p),
            ms(m)
        );
        println!("validity: {report}");
    }
    Ok(ok)
}

fn main() -> ExitCode {
    let a = Args::parse();
    match run(&a) {
        Ok(true) => ExitCode::SUCCESS,
        Ok(false) => {
            eprintln!("error: the output mesh failed the validity check");
            ExitCode::from(3)
        }
        Err(e) => {
            eprintln!("error: {e:#}");
            ExitCode::from(2)
        }
    }
}
