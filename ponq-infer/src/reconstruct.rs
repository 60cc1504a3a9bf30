//! Reconstruction: SDF grid -> network (in [`tiles`](crate::tiles)) -> prediction -> PoNQ
//! (kept cells, optional PoNQ-lite / hierarchy) -> `ponq_mesh::mesher` -> mesh, in the user's
//! frame (see [`frame`](crate::frame)).

use std::time::{Duration, Instant};

use anyhow::{Context, Result, bail};
use burn::prelude::*;
use ponq_mesh::io::npy::Grid3;
use ponq_mesh::mesher::{MeshingOptions, MeshingStats, mesh_ponq};
use ponq_mesh::tagging::SmallTetRule;
use ponq_mesh::{Ponq, TriMesh};
use ponq_model::{PonqNet, network_input_scale};

use crate::frame::{Frame, ponq_to_user};
use crate::tiles::predict_tiled;

/// The default of [`InferOptions::merge_smooth`]: cells whose predicted normals agree within
/// 15 degrees get one point. Chosen on the shared meshes (models/README.md): the four noisy
/// points of a smooth cell make small creases (free-form ECD at 33^3 0.41 without, 0.13 with,
/// marching cubes 0.16); 10 degrees removes too few of them, 20 and more cost CD / F1 on CAD.
pub const DEFAULT_MERGE_SMOOTH_DEG: f64 = 15.0;

/// Options of [`infer`].
#[derive(Debug, Clone)]
pub struct InferOptions {
    /// The box spanned by the grid nodes (default `[-1,1]^3`).
    pub bounds: ([f64; 3], [f64; 3]),
    /// Cells per side of a tile's kept core (a tile adds the encoder's margin on each side);
    /// 0 picks [`auto_tile`].
    pub tile: usize,
    /// PoNQ-lite: one point per cell.
    pub lite: bool,
    /// Hierarchy: merge 2x2x2 blocks this many more times (implies lite).
    pub coarsen: u32,
    /// Adaptive PoNQ-lite: merge the points of each cell whose normals agree within this many
    /// degrees (`ponq_mesh::lite::merge_smooth_cells`); `None` keeps every point. Ignored with
    /// `lite` / `coarsen`. Default [`DEFAULT_MERGE_SMOOTH_DEG`].
    pub merge_smooth: Option<f64>,
    /// Open-surface culling threshold.
    pub open: Option<f64>,
    /// Flip quadrilateral diagonals onto sharp edges (`ponq_mesh::flips`; default true).
    pub align_creases: bool,
    /// Which labels the tagging's small-tet rule adds (`ponq_mesh::tagging::SmallTetRule`;
    /// default inside only, as the authors' code).
    pub small_tet_rule: SmallTetRule,
    /// Cells are kept when their occupancy exceeds this (0.5).
    pub occupancy_threshold: f32,
    /// Use the authors' cell bases (only for their pretrained weights).
    pub authors_cell_base: bool,
}

impl Default for InferOptions {
    fn default() -> Self {
        Self {
            bounds: ([-1.0; 3], [1.0; 3]),
            tile: 0,
            lite: false,
            coarsen: 0,
            merge_smooth: Some(DEFAULT_MERGE_SMOOTH_DEG),
            open: None,
            align_creases: true,
            small_tet_rule: SmallTetRule::InsideOnly,
            occupancy_threshold: 0.5,
            authors_cell_base: false,
        }
    }
}

/// The tile size [`InferOptions`] uses when given 0: 128 cells where the encoder runs at the
/// needed cells only ([`PonqNet::uses_sparse_encoder`]: memory follows the surface, and
/// fewer tiles repeat fewer margins), 48 where it runs on whole tiles (memory follows the
/// tile's volume).
pub fn auto_tile(net: &PonqNet, device: &Device) -> usize {
    if net.uses_sparse_encoder(device) {
        128
    } else {
        48
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
    // Close mask over the cells.
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
    let t0 = Instant::now();
    let (pred, tiles) = predict_tiled(
        net,
        &input,
        &frame,
        encoder_layers,
        if opts.tile == 0 {
            auto_tile(net, device)
        } else {
            opts.tile
        },
        opts.authors_cell_base,
        Some(&close),
        device,
        progress,
    )?;
    let network = t0.elapsed();
    let t1 = Instant::now();
    let kept = pred.kept_cells(opts.occupancy_threshold, Some(&close))?;
    let (mut ponq, cells) = pred.to_ponq(&kept)?;
    let mut grid_scale = frame.n as f64;
    if opts.lite || opts.coarsen > 0 {
        ponq = ponq_mesh::lite::coarsen(&ponq, &cells, opts.coarsen)?;
        grid_scale /= f64::from(1u32 << opts.coarsen.min(20));
    } else if let Some(angle) = opts.merge_smooth {
        ponq = ponq_mesh::lite::merge_smooth_cells(&ponq, &cells, angle)?;
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
        align_creases: opts.align_creases,
        small_tet_rule: opts.small_tet_rule,
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
