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

use ponq_data::condition::{ConditionOptions, Conditioning, FieldScan};
use ponq_data::refine::{
    BAND_REACH, DistanceCheck, DistanceGrid, RefineOptions, check_distance, clear_balls, refine,
};
use ponq_mesh::band::BandGrid;

use crate::frame::{Frame, ponq_to_user};
use crate::tiles::predict_cells;

/// The default of [`InferOptions::merge_smooth`]: cells whose predicted normals agree within
/// 15 degrees get one point. Chosen on the shared meshes (docs/evaluation.md): the four noisy
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
    /// Flip quadrilateral diagonals onto sharp edges (`ponq_mesh::flips`) and flat caps away
    /// (`ponq_mesh::caps`); default true.
    pub align_creases: bool,
    /// Which labels the tagging's small-tet rule adds (`ponq_mesh::tagging::SmallTetRule`;
    /// default inside only, as the authors' code).
    pub small_tet_rule: SmallTetRule,
    /// Cells are kept when their occupancy exceeds this (0.5).
    pub occupancy_threshold: f32,
    /// Use the authors' cell bases (only for their pretrained weights).
    pub authors_cell_base: bool,
    /// Refinement against the grid's exact distances ([`RefineMode`]).
    pub refine: RefineMode,
    /// Parameters of the refinement.
    pub refine_options: RefineOptions,
    /// How the grid's values are read (iso-level, sign, kind of field:
    /// `ponq_data::condition`); by default measured.
    pub condition: ConditionOptions,
}

/// When [`finish`] refines the network's PoNQ against the grid's distances
/// (`ponq_data::refine`).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub enum RefineMode {
    /// When the grid passes [`check_distance`] (a true signed distance).
    #[default]
    Auto,
    /// Always (on a grid that is not a true distance the result may be worse).
    On,
    /// Never.
    Off,
}

impl std::str::FromStr for RefineMode {
    type Err = String;
    fn from_str(s: &str) -> std::result::Result<Self, String> {
        match s {
            "auto" => Ok(Self::Auto),
            "on" => Ok(Self::On),
            "off" => Ok(Self::Off),
            _ => Err(format!("expected auto, on or off, got {s:?}")),
        }
    }
}

impl std::fmt::Display for RefineMode {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            Self::Auto => "auto",
            Self::On => "on",
            Self::Off => "off",
        })
    }
}

/// What the refinement did in [`finish`].
#[derive(Debug, Clone, Default)]
pub struct RefineReport {
    /// The mode asked for.
    pub mode: RefineMode,
    /// The grid check (in `auto` mode).
    pub check: Option<DistanceCheck>,
    /// Whether it ran.
    pub ran: bool,
    /// Fit of each round's mesh to the grid's distances (RMS of `dist(x, mesh) - |d(x)|` over
    /// the band, in cells), the network's mesh first.
    pub residuals: Vec<f64>,
    /// Rounds whose mesh was kept (0: the network's mesh).
    pub rounds_kept: usize,
    /// Band nodes and dropped samples of the last round.
    pub samples: (usize, usize),
    /// Time of the whole refinement (sampling, refits and meshings).
    pub time: Duration,
    /// Why it did not run, where that needs saying.
    pub note: Option<String>,
}

impl RefineReport {
    /// One line for a summary.
    pub fn summary(&self) -> String {
        if self.ran {
            let res: Vec<String> = self.residuals.iter().map(|r| format!("{r:.3}")).collect();
            format!(
                "refinement ({}): {} round(s) kept, fit to the distances (RMS, cells) {}",
                self.mode,
                self.rounds_kept,
                res.join(" -> ")
            )
        } else if let Some(n) = &self.note {
            format!("refinement ({}): off, {n}", self.mode)
        } else if let Some(c) = &self.check {
            format!(
                "refinement ({}): off, the grid is not a true signed distance ({c})",
                self.mode
            )
        } else {
            format!("refinement ({}): off", self.mode)
        }
    }
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
            refine: RefineMode::Auto,
            refine_options: RefineOptions::default(),
            condition: ConditionOptions::default(),
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
    /// Refinement (sampling, refits and their meshings; zero when it did not run).
    pub refine: Duration,
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
    /// What the refinement did.
    pub refinement: RefineReport,
    /// How the grid's values were read (when [`predict`] conditioned them).
    pub conditioning: Option<Conditioning>,
    /// For a grid whose values were conditioned (not used as they are): how well the mesh and
    /// the field's zero set cover each other, the smaller of the share of the mesh's vertices
    /// within a cell of the zero set (trilinear in the conditioned grid) and the share of the
    /// zero set's crossings along grid edges within a cell and a half of a vertex. A reading
    /// gone wrong puts the mesh elsewhere, or on a part of the surface only:
    /// [`Inference::strays`] says so.
    pub surface_agreement: Option<f64>,
}

impl Inference {
    /// Whether the mesh strays from the field's zero set ([`Inference::surface_agreement`]
    /// below 90%): the conditioning misread the field, and exact distances to its zero set
    /// (`FieldKind::Redistance`) are the safer reading.
    pub fn strays(&self) -> bool {
        self.surface_agreement.is_some_and(|a| a < 0.9)
    }
}

/// The network's PoNQ on a grid, before any merging: what [`predict`] returns and
/// [`finish`] meshes. Everything is in the normalised frame of [`Frame`].
#[derive(Debug, Clone)]
pub struct Predicted {
    /// The grid's frame.
    pub frame: Frame,
    /// How the grid's values were read into distances (set by [`predict`] and
    /// [`crate::grid_input`]; `None` from [`predict_band`] alone).
    pub conditioning: Option<Conditioning>,
    /// The grid's values in the normalised frame (distances times [`Frame::scale`]), stored
    /// near the surface ([`band_parameters`]).
    pub normalised: BandGrid,
    /// Every point of the kept cells.
    pub ponq: Ponq,
    /// The grid cell of each point.
    pub cells: Vec<[u32; 3]>,
    /// Tiles the network ran on.
    pub tiles: usize,
    /// Cells near the surface (the network ran on these).
    pub close_cells: usize,
    /// Cells kept (occupied and close).
    pub kept_cells: usize,
    /// Time of the network.
    pub network: Duration,
}

/// The band of a grid that inference reads, for a frame of `n` cells along its longest
/// axis and the network's `encoder_layers`: the threshold (in the normalised frame) and
/// the reach (nodes) of a [`BandGrid`] holding every node any stage reads (the cells that
/// can be kept, the encoder's margin around them, the refinement's band and the nodes
/// around it).
pub fn band_parameters(n: usize, encoder_layers: usize, opts: &InferOptions) -> (f64, usize) {
    let h = 2.0 / n as f64;
    let t = close_threshold(n).max(DistanceGrid::band_threshold(h, opts.refine_options.band));
    (t * (1.0 + 1e-9), encoder_layers.max(BAND_REACH) + 1)
}

/// Memory one cell near the surface takes from the network to the end of the refinement,
/// measured with `ponq-infer` on the shared bunny at 513^3 (peak resident memory 1.32 GB for
/// 484k cells of 4 points, a band of 71 MB: 570 bytes a point), with a margin.
const BYTES_PER_CLOSE_POINT: u64 = 700;

/// Refuses a run whose cells near the surface would take more memory than is left
/// (`ponq_mesh::memory::budget`), before any work. The band is already resident, so the
/// budget (which counts what the process holds) already has it: only the new work is priced.
fn check_memory(close: usize, points_per_cell: usize) -> Result<()> {
    let need = close as u64 * points_per_cell as u64 * BYTES_PER_CLOSE_POINT;
    ponq_mesh::memory::check(
        need,
        &format!("the network and the meshing of {close} cells near the surface"),
        "mesh a coarser grid, or --coarsen 1 (PoNQ-lite at half the resolution)",
    )?;
    Ok(())
}

/// The most bytes a grid's band may take while it is built: half of what is left
/// (`ponq_mesh::memory::budget`); the rest is for the network and the meshing (checked again
/// before the network runs).
///
/// # Errors
/// An unreadable `PONQ_MEMORY_LIMIT`.
pub fn band_memory_limit() -> Result<Option<usize>> {
    Ok(ponq_mesh::memory::available_bytes()?.map(|b| usize::try_from(b / 2).unwrap_or(usize::MAX)))
}

/// [`Inference::surface_agreement`] of `mesh` (normalised frame) and the band (cell `h`).
fn agreement(mesh: &TriMesh, band: &BandGrid, h: f64) -> f64 {
    if mesh.vertices.is_empty() {
        return 0.0;
    }
    let dims = band.dims();
    let near = mesh
        .vertices
        .iter()
        .filter(|v| {
            let x: [f64; 3] =
                std::array::from_fn(|a| ((v[a] + 1.0) / h).clamp(0.0, (dims[a] - 1) as f64));
            let i: [usize; 3] =
                std::array::from_fn(|a| (x[a].floor() as usize).min(dims[a].saturating_sub(2)));
            let t: [f64; 3] = std::array::from_fn(|a| x[a] - i[a] as f64);
            let mut val = 0.0;
            for c in 0..8 {
                let o = [c >> 2, (c >> 1) & 1, c & 1];
                let w: f64 = (0..3)
                    .map(|a| if o[a] == 1 { t[a] } else { 1.0 - t[a] })
                    .product();
                let idx: [usize; 3] = std::array::from_fn(|a| (i[a] + o[a]).min(dims[a] - 1));
                val += w * band.get(idx[0], idx[1], idx[2]);
            }
            val.abs() < h
        })
        .count();
    let precision = near as f64 / mesh.vertices.len() as f64;
    // And the other way: the zero set's crossings along grid edges with a vertex of the mesh
    // within a cell and a half (a mesh that keeps close to a part of the surface only).
    let Some(index) = ponq_mesh::nn::PointIndex::new(&mesh.vertices) else {
        return 0.0;
    };
    let mut crossings: Vec<[f64; 3]> = Vec::new();
    band.for_each_stored(|i, j, k, v| {
        for (a, (x, y, z)) in [(i + 1, j, k), (i, j + 1, k), (i, j, k + 1)]
            .into_iter()
            .enumerate()
        {
            if x >= dims[0] || y >= dims[1] || z >= dims[2] {
                continue;
            }
            let w = band.get(x, y, z);
            if (v < 0.0) != (w < 0.0) {
                let t = v / (v - w);
                let mut p = [i, j, k].map(|c| -1.0 + c as f64 * h);
                p[a] += t * h;
                crossings.push(p);
            }
        }
    });
    if crossings.is_empty() {
        return precision;
    }
    let step = crossings.len().div_ceil(50_000);
    let reach = (1.5 * h) * (1.5 * h);
    let (mut hit, mut all) = (0usize, 0usize);
    for p in crossings.iter().step_by(step) {
        all += 1;
        hit += usize::from(index.nearest(p).1 <= reach);
    }
    precision.min(hit as f64 / all as f64)
}

/// A cell can be kept when all its corners are closer than this (normalised frame) to the
/// surface.
fn close_threshold(n: usize) -> f64 {
    2.0 * 3f64.sqrt() / (n as f64 + 1.0)
}

/// Runs the network on an SDF grid (negative inside) and returns its PoNQ over the kept
/// cells ([`Predicted`]); [`infer`] is this followed by [`finish`]. The values are read as
/// `opts.condition` says (`ponq_data::condition`: a signed distance in the grid's frame is
/// used as it is; other units, signs, levels and monotone functions of a distance are
/// conditioned into one first).
///
/// # Errors
/// A grid that [`Frame::of`] rejects, a field without a sign change ("no sign change") or
/// whose inside cannot be told, the network's errors.
pub fn predict(
    net: &PonqNet,
    encoder_layers: usize,
    grid: &Grid3,
    opts: &InferOptions,
    device: &Device,
    progress: impl FnMut(usize, usize),
) -> Result<Predicted> {
    let (band, conditioning) = conditioned_band(grid, encoder_layers, opts)?;
    let mut out = predict_band(net, encoder_layers, band, opts, device, progress)?;
    out.conditioning = Some(conditioning);
    Ok(out)
}

/// A grid in memory read as [`predict`] reads it: its values conditioned (`opts.condition`)
/// and stored near the surface, for a network of `encoder_layers`.
///
/// # Errors
/// As [`predict`], but the network's.
pub fn conditioned_band(
    grid: &Grid3,
    encoder_layers: usize,
    opts: &InferOptions,
) -> Result<(BandGrid, Conditioning)> {
    let frame = Frame::of(grid, opts.bounds)?;
    let plane = grid.dims[1] * grid.dims[2];
    if grid.data.len() != grid.dims.iter().product::<usize>() {
        bail!(
            "{} values for a grid of {:?} nodes",
            grid.data.len(),
            grid.dims
        );
    }
    // What the values are (a pass over the planes), then the band of the distances.
    let mut scan = FieldScan::new(grid.dims, &opts.condition);
    for p in grid.data.chunks(plane.max(1)) {
        scan.push_plane(p)?;
    }
    let mut conditioning = scan.finish(frame.scale())?;
    conditioning.fit_whole_grid(grid.data.len());
    let (t, reach) = band_parameters(frame.n, encoder_layers, opts);
    // Priced plane by plane as it is built (a grid whose surface fills it stores it all).
    let identity = conditioning.is_identity();
    let mut b = ponq_mesh::band::BandBuilder::new(
        grid.dims,
        if identity { frame.scale() } else { 1.0 },
        t,
        reach,
    )?
    .with_limit(band_memory_limit()?);
    if conditioning.needs_whole_grid() {
        // Re-distanced: the whole grid at once (two copies of it, and its marching cubes).
        ponq_mesh::memory::check(
            grid.data.len() as u64 * 24,
            "re-distancing the whole grid",
            "give the field's convention (--field distance) or mesh a coarser grid",
        )?;
        let values = conditioning.condition_dense(&grid.data, grid.dims)?;
        for p in values.chunks(plane.max(1)) {
            b.push_plane(p)?;
        }
    } else {
        let mut mapped = Vec::new();
        for p in grid.data.chunks(plane.max(1)) {
            if identity {
                b.push_plane(p)?;
            } else {
                mapped.clear();
                mapped.extend(p.iter().map(|&v| conditioning.apply(v)));
                b.push_plane(&mapped)?;
            }
        }
    }
    Ok((b.finish()?, conditioning))
}

/// [`predict`] on a grid already stored near its surface, in the normalised frame (read with
/// `ponq_mesh::io::npy::read_npy_band` and [`band_parameters`]; `opts.bounds` give the
/// frame). Nothing here allocates per node or per cell of the whole grid.
///
/// # Errors
/// As [`predict`]; a band narrower than [`band_parameters`].
pub fn predict_band(
    net: &PonqNet,
    encoder_layers: usize,
    band: BandGrid,
    opts: &InferOptions,
    device: &Device,
    progress: impl FnMut(usize, usize),
) -> Result<Predicted> {
    let frame = Frame::of_dims(band.dims(), opts.bounds)?;
    let (t, reach) = band_parameters(frame.n, encoder_layers, opts);
    if band.threshold() < t || band.reach() < reach {
        bail!(
            "the grid's stored band (|d| < {}, reach {}) is narrower than inference reads (|d| < {t}, reach {reach})",
            band.threshold(),
            band.reach()
        );
    }
    let stats = band.stats();
    if !(stats.min < 0.0 && stats.max > 0.0) {
        let s = frame.scale();
        bail!(
            "the SDF has no sign change (values in [{}, {}]): the surface is empty; nothing to mesh",
            stats.min / s,
            stats.max / s
        );
    }
    let k = network_input_scale(frame.n);
    // The cells near the surface: all 8 corners closer than the threshold (such corners are
    // stored).
    let [c0, c1, c2] = frame.cells;
    let thr = close_threshold(frame.n);
    let mut close = Vec::new();
    band.for_each_stored(|i, j, kk, v| {
        if i < c0
            && j < c1
            && kk < c2
            && v.abs() < thr
            && (1..8).all(|d| {
                band.get(i + (d >> 2), j + ((d >> 1) & 1), kk + (d & 1))
                    .abs()
                    < thr
            })
        {
            close.push((i * c1 + j) * c2 + kk);
        }
    });
    close.sort_unstable();
    check_memory(close.len(), net.points_per_cell())?;
    let t0 = Instant::now();
    let (pred, tiles) = predict_cells(
        net,
        |lo, hi| {
            band.block(lo, hi)
                .into_iter()
                .map(|v| v as f32 * k)
                .collect()
        },
        &frame,
        encoder_layers,
        if opts.tile == 0 {
            auto_tile(net, device)
        } else {
            opts.tile
        },
        opts.authors_cell_base,
        &close,
        device,
        progress,
    )?;
    let network = t0.elapsed();
    let kept = pred.kept_cells(opts.occupancy_threshold, None)?;
    let (ponq, _) = pred.to_ponq(&kept)?;
    let p = net.points_per_cell();
    let cells = kept
        .iter()
        .flat_map(|&r| {
            let c = close[r];
            let at = [
                (c / (c1 * c2)) as u32,
                ((c / c2) % c1) as u32,
                (c % c2) as u32,
            ];
            std::iter::repeat_n(at, p)
        })
        .collect();
    Ok(Predicted {
        frame,
        conditioning: None,
        normalised: band,
        ponq,
        cells,
        tiles,
        close_cells: close.len(),
        kept_cells: kept.len(),
        network,
    })
}

/// Reconstructs a mesh from an SDF grid (negative inside) with a trained network:
/// [`predict`], then [`finish`].
///
/// When the grid's values were conditioned and the mesh strays from their zero set
/// ([`Inference::strays`]), the grid is read again as exact distances to its zero set
/// (`FieldKind::Redistance`) and the mesh that keeps closer to it is returned (a note in its
/// conditioning says so).
pub fn infer(
    net: &PonqNet,
    encoder_layers: usize,
    grid: &Grid3,
    opts: &InferOptions,
    device: &Device,
    mut progress: impl FnMut(usize, usize),
) -> Result<Inference> {
    let p = predict(net, encoder_layers, grid, opts, device, &mut progress)?;
    let first = finish(&p, opts)?;
    if !retry_redistanced(&first, opts) {
        return Ok(first);
    }
    drop(p);
    let mut o2 = opts.clone();
    o2.condition.field = ponq_data::condition::FieldKind::Redistance;
    let second = predict(net, encoder_layers, grid, &o2, device, &mut progress)
        .and_then(|p2| finish(&p2, &o2));
    Ok(match second {
        Ok(s) => keep_closer(first, s),
        Err(e) => with_note(
            first,
            format!("reading it again re-distanced failed: {e:#}"),
        ),
    })
}

/// `res` with a note in its conditioning.
pub fn with_note(mut res: Inference, note: String) -> Inference {
    if let Some(c) = res.conditioning.as_mut() {
        c.notes.push(note);
    }
    res
}

/// Whether a result is worth a second reading as exact distances to the zero set: its mesh
/// strays from the zero set, its field was measured (not given as a distance), and not
/// already re-distanced.
pub fn retry_redistanced(res: &Inference, opts: &InferOptions) -> bool {
    res.strays()
        && opts.condition.field == ponq_data::condition::FieldKind::Auto
        && !res
            .conditioning
            .as_ref()
            .is_some_and(|c| c.needs_whole_grid())
}

/// Of a first result that strayed and a second, re-distanced one, the one whose mesh keeps
/// closer to the field's zero set, with a note.
pub fn keep_closer(first: Inference, mut second: Inference) -> Inference {
    let (a, b) = (
        first.surface_agreement.unwrap_or(0.0),
        second.surface_agreement.unwrap_or(0.0),
    );
    if b >= a && !second.mesh.faces.is_empty() {
        if let Some(c) = second.conditioning.as_mut() {
            c.notes.push(format!(
                "read value by value, the mesh strayed from the field's zero set ({:.0}% of \
                 its vertices within a cell of it; re-distanced: {:.0}%)",
                100.0 * a,
                100.0 * b
            ));
        }
        second
    } else {
        first
    }
}

/// The PoNQ that is meshed: PoNQ-lite / hierarchy / merged smooth cells, per `opts`, and
/// the grid scale to mesh it with.
fn convert(ponq: &Ponq, cells: &[[u32; 3]], n: usize, opts: &InferOptions) -> Result<(Ponq, f64)> {
    let mut grid_scale = n as f64;
    let out = if opts.lite || opts.coarsen > 0 {
        grid_scale /= f64::from(1u32 << opts.coarsen.min(20));
        ponq_mesh::lite::coarsen(ponq, cells, opts.coarsen)?
    } else if let Some(angle) = opts.merge_smooth {
        ponq_mesh::lite::merge_smooth_cells(ponq, cells, angle)?
    } else {
        ponq.clone()
    };
    Ok((out, grid_scale))
}

/// Merges (per `opts`) and meshes the network's PoNQ, refines it against the grid's
/// distances when `opts.refine` says so, and maps the result to the user's frame.
///
/// # Errors
/// Meshing errors.
pub fn finish(p: &Predicted, opts: &InferOptions) -> Result<Inference> {
    let frame = &p.frame;
    let t1 = Instant::now();
    let (ponq, grid_scale) = convert(&p.ponq, &p.cells, frame.n, opts)?;
    let convert_time = t1.elapsed();
    let t2 = Instant::now();
    let mopts = MeshingOptions {
        grid_scale,
        domain: (
            [-1.0; 3],
            frame.cells.map(|c| -1.0 + c as f64 * 2.0 / frame.n as f64),
        ),
        open_threshold: opts.open,
        align_creases: opts.align_creases,
        flat_caps: opts.align_creases,
        small_tet_rule: opts.small_tet_rule,
        ..Default::default()
    };
    let (mut mesh, mut meshing, message) = if ponq.is_empty() {
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
    let mut ponq = ponq;
    // Refinement against the grid's distances.
    let t3 = Instant::now();
    let mut refinement = RefineReport {
        mode: opts.refine,
        ..Default::default()
    };
    // The grid's distances in the normalised frame; not needed when refinement is off.
    let grid = match opts.refine {
        RefineMode::Off => None,
        _ => Some(DistanceGrid::from_band(
            &p.normalised,
            [-1.0; 3],
            2.0 / frame.n as f64,
            opts.refine_options.band,
        )?),
    };
    let wanted = match (&grid, opts.refine) {
        (Some(g), RefineMode::Auto) => {
            let c = check_distance(g);
            refinement.check = Some(c);
            // Distances mapped from another field are a little off everywhere (the map's
            // error), so some nodes look steeper than 1: the rest of the check still holds.
            match p.conditioning.as_ref().and_then(|k| k.mapped_refinable()) {
                Some(true) => c.steepest_median >= 0.92 && c.steepest_unit_fraction >= 0.6,
                Some(false) => {
                    refinement.note = Some(
                        "the field's distances are mapped from its values, too loosely to \
                         refine against"
                            .into(),
                    );
                    false
                }
                None => c.is_distance(),
            }
        }
        (Some(_), _) => true,
        (None, _) => false,
    };
    if let Some(grid) = grid.as_ref().filter(|_| wanted)
        && !mesh.faces.is_empty()
        && opts.open.is_none()
    {
        // Every round's merged PoNQ and meshing statistics, to report the kept one's.
        let mut rounds: Vec<(Ponq, MeshingStats)> = Vec::new();
        // Points of cells merged into one need no shared samples (see `refit`).
        let sharing: Option<Vec<bool>> = match opts.merge_smooth {
            Some(angle) => Some(
                ponq_mesh::lite::smooth_points(&p.ponq, &p.cells, angle)?
                    .into_iter()
                    .map(|s| !s)
                    .collect(),
            ),
            None => None,
        };
        let ro = &opts.refine_options;
        let r = refine(&p.ponq, &mesh, grid, ro, sharing.as_deref(), |raw| {
            let (mut q, _) = convert(raw, &p.cells, frame.n, opts)
                .map_err(|e| ponq_data::DataError::Invalid(format!("{e:#}")))?;
            if ro.clear {
                clear_balls(grid, &mut q, ro.max_move);
            }
            let out = mesh_ponq(&q, &mopts)?;
            rounds.push((q, out.stats));
            Ok(out.mesh)
        })
        .context("refining the PoNQ against the grid's distances")?;
        refinement.ran = true;
        refinement.residuals = r.residuals;
        refinement.rounds_kept = r.rounds_kept;
        refinement.samples = r.samples;
        if r.rounds_kept > 0 && r.rounds_kept <= rounds.len() {
            let (q, st) = rounds.swap_remove(r.rounds_kept - 1);
            ponq = q;
            meshing = st;
            mesh = r.mesh;
        }
        refinement.time = t3.elapsed();
    } else if wanted && opts.open.is_some() {
        refinement.note = Some("refinement is for closed surfaces: not run with --open".into());
    }
    let surface_agreement = p
        .conditioning
        .as_ref()
        .filter(|c| !c.is_identity())
        .map(|_| agreement(&mesh, &p.normalised, 2.0 / frame.n as f64));
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
        ponq: ponq_to_user(&ponq, frame)?,
        meshing,
        times: InferTimes {
            network: p.network,
            convert: convert_time,
            meshing: meshing_time,
            refine: refinement.time,
        },
        tiles: p.tiles,
        kept_cells: p.kept_cells,
        conditioning: p.conditioning.clone(),
        surface_agreement,
        message,
        refinement,
    })
}
