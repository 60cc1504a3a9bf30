//! `ponq-eval`: reconstruction metrics with the paper's protocol.

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
            json,
        } => {
            if samples == 0 {
                bail!("--samples must be positive");
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
