//! Inference: an SDF grid of any size through the network (in tiles whose margins make the
//! result identical to one pass over the whole grid), to a PoNQ, to a mesh.
//!
//! Frames: the user's grid spans `bounds` with equal cell size `h` along all axes. Work is
//! done in a normalised frame where node `(0,0,0)` is at `-1` and the cell size is
//! `2 / N` with `N` the largest number of cells along an axis (so a cubic grid over
//! `[-1,1]^3` is its own normalised frame); the mesh and PoNQ are mapped back at the end.

use std::time::{Duration, Instant};

use anyhow::{Context, Result, bail};
use burn::prelude::*;
use ponq_mesh::io::npy::Grid3;
use ponq_mesh::mesher::{MeshingOptions, MeshingStats, mesh_ponq};
use ponq_mesh::quadric::Quadric;
use ponq_mesh::{Ponq, TriMesh};
use ponq_model::{GridFrame, PonqNet, Prediction, network_input_scale};

/// Options of [`infer`].
#[derive(Debug, Clone)]
pub struct InferOptions {
    /// The box spanned by the grid nodes (default `[-1,1]^3`).
    pub bounds: ([f64; 3], [f64; 3]),
    /// Cells per side of a tile's kept core (a tile adds the encoder's margin on each side).
    pub tile: usize,
    /// PoNQ-lite: one point per cell.
    pub lite: bool,
    /// Hierarchy: merge 2x2x2 blocks this many more times (implies lite).
    pub coarsen: u32,
    /// Open-surface culling threshold.
    pub open: Option<f64>,
    /// Cells are kept when their occupancy exceeds this (0.5).
    pub occupancy_threshold: f32,
    /// Use the authors' cell bases (only for their pretrained weights).
    pub authors_cell_base: bool,
}

impl Default for InferOptions {
    fn default() -> Self {
        Self {
            bounds: ([-1.0; 3], [1.0; 3]),
            tile: 48,
            lite: false,
            coarsen: 0,
            open: None,
            occupancy_threshold: 0.5,
            authors_cell_base: false,
        }
    }
}

/// Time per stage.
#[derive(Debug, Clone, Copy, Default)]
pub struct InferTimes {
    /// Network (all tiles).
    pub network: Duration,
    /// Prediction to PoNQ (and lite / coarsening).
    pub convert: Duration,
    /// Meshing (the stages are in [`Inference::meshing`]).
    pub meshing: Duration,
}

/// What [`infer`] produced.
#[derive(Debug, Clone)]
pub struct Inference {
    /// The mesh in the user's coordinates (empty when no cell was kept; see `message`).
    pub mesh: TriMesh,
    /// The PoNQ that was meshed, in the user's coordinates.
    pub ponq: Ponq,
    /// Meshing statistics.
    pub meshing: MeshingStats,
    /// Time per stage.
    pub times: InferTimes,
    /// Tiles the network ran on.
    pub tiles: usize,
    /// Cells kept (occupied and close).
    pub kept_cells: usize,
    /// A note when the result is empty or degenerate.
    pub message: Option<String>,
}

/// The normalised frame of a grid.
#[derive(Debug, Clone, Copy)]
pub struct Frame {
    /// Cells per axis.
    pub cells: [usize; 3],
    /// Largest of `cells`.
    pub n: usize,
    /// User coordinate of node `(0,0,0)`.
    pub lo: [f64; 3],
    /// User cell size.
    pub h: f64,
}

impl Frame {
    /// Checks a grid against its bounds: at least 2 nodes per axis, finite values, equal
    /// cell sizes along the axes (relative tolerance 1e-6).
    pub fn of(grid: &Grid3, bounds: ([f64; 3], [f64; 3])) -> Result<Self> {
        let d = grid.dims;
        if d.iter().any(|&x| x < 2) {
            bail!("the grid must have at least 2 nodes along every axis, it has {d:?}");
        }
        if let Some(i) = grid.data.iter().position(|v| !v.is_finite()) {
            bail!(
                "the grid holds a non-finite value ({}) at flat index {i}",
                grid.data[i]
            );
        }
        let (lo, hi) = bounds;
        let mut hs = [0.0; 3];
        for a in 0..3 {
            if !(hi[a] > lo[a]) || !lo[a].is_finite() || !hi[a].is_finite() {
                bail!("invalid bounds along axis {a}: {} .. {}", lo[a], hi[a]);
            }
            hs[a] = (hi[a] - lo[a]) / (d[a] - 1) as f64;
        }
        let h = hs[0];
        if hs.iter().any(|&x| (x - h).abs() > 1e-6 * h) {
            bail!(
                "the grid's cells are not cubes: cell sizes {hs:?} for {d:?} nodes over {lo:?}..{hi:?}; \
                 resample the grid to equal spacing or give --bounds that make the cells cubic"
            );
        }
        let cells = d.map(|x| x - 1);
        Ok(Self {
            cells,
            n: *cells.iter().max().unwrap_or(&1),
            lo,
            h,
        })
    }

    /// Normalised coordinates per user unit.
    pub fn scale(&self) -> f64 {
        2.0 / (self.n as f64 * self.h)
    }

    /// User point of a normalised point.
    pub fn to_user(&self, p: [f64; 3]) -> [f64; 3] {
        std::array::from_fn(|a| self.lo[a] + (p[a] + 1.0) / self.scale())
    }

    /// Whether the normalised frame is the user's frame.
    pub fn is_identity(&self) -> bool {
        self.lo == [-1.0; 3] && (self.scale() - 1.0).abs() < 1e-15
    }
}

/// Maps a PoNQ from the normalised frame to the user's: positions, and quadrics
/// `Q_user(x) = Q(s (x - lo) - 1)`, i.e. `A * s^2` around the mapped v*.
fn ponq_to_user(p: &Ponq, f: &Frame) -> Result<Ponq> {
    if f.is_identity() {
        return Ok(p.clone());
    }
    let s2 = f.scale() * f.scale();
    let vs = p.vstars();
    let points = p.points.iter().map(|&x| f.to_user(x)).collect();
    let vstars: Vec<[f64; 3]> = vs.iter().map(|&x| f.to_user(x)).collect();
    let quadrics = p
        .quadrics
        .iter()
        .zip(&vstars)
        .map(|(q, &v)| Quadric::from_a_vstar(q.a * s2, v))
        .collect();
    Ok(Ponq::new(
        points,
        p.normals.clone(),
        quadrics,
        Some(vstars),
    )?)
}

/// Runs the network over `grid` (normalised values, already scaled for the network) in
/// tiles; returns the prediction over all cells and the number of tiles.
// Grid, network, tiling and device are independent inputs; a struct would only rename them.
#[allow(clippy::too_many_arguments)]
pub fn predict_tiled(
    net: &PonqNet,
    input: &[f32],
    frame: &Frame,
    margin: usize,
    tile: usize,
    authors_cell_base: bool,
    device: &Device,
    mut progress: impl FnMut(usize, usize),
) -> Result<(Prediction, usize)> {
    let cells = frame.cells;
    let nodes = cells.map(|c| c + 1);
    let tile = tile.max(1);
    let mut pred = Prediction::zeros(cells, net.points_per_cell());
    let starts = |n: usize| -> Vec<(usize, usize)> {
        (0..n)
            .step_by(tile)
            .map(|a| (a, (a + tile).min(n)))
            .collect()
    };
    let (sx, sy, sz) = (starts(cells[0]), starts(cells[1]), starts(cells[2]));
    let total = sx.len() * sy.len() * sz.len();
    let mut done = 0;
    for &(ax, bx) in &sx {
        for &(ay, by) in &sy {
            for &(az, bz) in &sz {
                let core = [(ax, bx), (ay, by), (az, bz)];
                let lo: [usize; 3] = std::array::from_fn(|a| core[a].0.saturating_sub(margin));
                let hi: [usize; 3] = std::array::from_fn(|a| (core[a].1 + margin).min(cells[a]));
                let m: [usize; 3] = std::array::from_fn(|a| hi[a] - lo[a] + 1);
                let mut data = Vec::with_capacity(m[0] * m[1] * m[2]);
                for i in lo[0]..=hi[0] {
                    for j in lo[1]..=hi[1] {
                        let row = (i * nodes[1] + j) * nodes[2];
                        data.extend_from_slice(&input[row + lo[2]..=row + hi[2]]);
                    }
                }
                let x = Tensor::<1>::from_data(TensorData::new(data, [m[0] * m[1] * m[2]]), device)
                    .reshape([1, 1, m[0], m[1], m[2]]);
                let mut gf = GridFrame::crop(frame.n, lo);
                gf.authors_cell_base = authors_cell_base;
                let out = net.forward(x, &gf);
                let t = Prediction::from_output(&out, 0)?;
                pred.paste(
                    &t,
                    std::array::from_fn(|a| core[a].0 - lo[a]),
                    std::array::from_fn(|a| core[a].1 - lo[a]),
                    lo,
                )?;
                done += 1;
                progress(done, total);
            }
        }
    }
    Ok((pred, total))
}

/// Reconstructs a mesh from an SDF grid (negative inside) with a trained network.
pub fn infer(
    net: &PonqNet,
    encoder_layers: usize,
    grid: &Grid3,
    opts: &InferOptions,
    device: &Device,
    progress: impl FnMut(usize, usize),
) -> Result<Inference> {
    let frame = Frame::of(grid, opts.bounds)?;
    let (min, max) = grid
        .data
        .iter()
        .fold((f64::MAX, f64::MIN), |(a, b), &v| (a.min(v), b.max(v)));
    if !(min < 0.0 && max > 0.0) {
        bail!(
            "the SDF has no sign change (values in [{min}, {max}]): the surface is empty; nothing to mesh"
        );
    }
    let s = frame.scale();
    let normalised: Vec<f64> = grid.data.iter().map(|v| v * s).collect();
    let k = network_input_scale(frame.n);
    let input: Vec<f32> = normalised.iter().map(|&v| v as f32 * k).collect();
    let t0 = Instant::now();
    let (pred, tiles) = predict_tiled(
        net,
        &input,
        &frame,
        encoder_layers,
        opts.tile,
        opts.authors_cell_base,
        device,
        progress,
    )?;
    let network = t0.elapsed();
    // Close mask over the cells.
    let t1 = Instant::now();
    let [c0, c1, c2] = frame.cells;
    let thr = 2.0 * 3f64.sqrt() / (frame.n as f64 + 1.0);
    let node = |i: usize, j: usize, k: usize| normalised[(i * (c1 + 1) + j) * (c2 + 1) + k];
    let mut close = Vec::with_capacity(c0 * c1 * c2);
    for i in 0..c0 {
        for j in 0..c1 {
            for k in 0..c2 {
                close.push(
                    (0..8).all(|d| node(i + (d >> 2), j + ((d >> 1) & 1), k + (d & 1)).abs() < thr),
                );
            }
        }
    }
    let kept = pred.kept_cells(opts.occupancy_threshold, Some(&close))?;
    let (mut ponq, cells) = pred.to_ponq(&kept)?;
    let mut grid_scale = frame.n as f64;
    if opts.lite || opts.coarsen > 0 {
        ponq = ponq_mesh::lite::coarsen(&ponq, &cells, opts.coarsen)?;
        grid_scale /= f64::from(1u32 << opts.coarsen.min(20));
    }
    let convert = t1.elapsed();
    let t2 = Instant::now();
    let mopts = MeshingOptions {
        grid_scale,
        domain: (
            [-1.0; 3],
            frame.cells.map(|c| -1.0 + c as f64 * 2.0 / frame.n as f64),
        ),
        open_threshold: opts.open,
        ..Default::default()
    };
    let (mesh, meshing, message) = if ponq.is_empty() {
        (
            TriMesh::default(),
            MeshingStats::default(),
            Some(
                "the network kept no cell (no occupied cell near the surface): empty mesh"
                    .to_string(),
            ),
        )
    } else {
        let out = mesh_ponq(&ponq, &mopts).context("meshing the predicted PoNQ")?;
        (out.mesh, out.stats, out.message)
    };
    let meshing_time = t2.elapsed();
    let mesh = if frame.is_identity() {
        mesh
    } else {
        TriMesh {
            vertices: mesh.vertices.iter().map(|&v| frame.to_user(v)).collect(),
            faces: mesh.faces,
        }
    };
    Ok(Inference {
        mesh,
        ponq: ponq_to_user(&ponq, &frame)?,
        meshing,
        times: InferTimes {
            network,
            convert,
            meshing: meshing_time,
        },
        tiles,
        kept_cells: kept.len(),
        message,
    })
}
