//! Refinement of a PoNQ against the exact distances of its input grid.
//!
//! A grid of exact signed distances says, at every node `x`, that the surface touches the
//! sphere of radius `|d(x)|` around `x` and enters none of the nodes' open balls. Once a
//! first mesh gives each node a direction `u` towards its nearest surface point,
//! `s = x + |d(x)| u` is a point of the true surface up to second order in the direction's
//! error, with the normal `-sign(d(x)) u`. Nodes in the normal cone of a convex edge (from
//! inside: a concave one) all land on that edge, so sharp edges and corners get dense,
//! accurate samples that a coarse grid otherwise hides.
//!
//! The stages, each a function:
//! - [`check_distance`]: is the grid a true distance (1-Lipschitz, falling at rate one
//!   towards the surface)? Refinement is only meaningful on one.
//! - [`grid_samples`]: one sample per node of the band `|d| < band` cells, its direction
//!   from the closest point of a mesh; samples that enter a neighbour's ball are pushed out
//!   along their sphere, and dropped when they cannot be (a node whose sphere touches two
//!   sides of a thin part, a direction from a wrong mesh).
//! - [`refit`]: each PoNQ point gets the mean plane quadric of the samples in its Voronoi
//!   cell (within `radius` cells), scaled to the network's quadric's trace, and its v* again.
//! - [`refine`]: mesh -> samples -> refit -> mesh, a few times, keeping a new mesh only while
//!   it fits the grid's distances better (RMS of `dist(x, mesh) - |d(x)|` over the band).
//!
//! ```
//! use ponq_data::refine::{DistanceGrid, check_distance};
//! // The exact distance to the plane z = 0.1 on a 9^3 grid over [-1,1]^3.
//! let h = 0.25;
//! let values: Vec<f64> = (0..729).map(|i| -1.0 + h * (i % 9) as f64 - 0.1).collect();
//! let grid = DistanceGrid::new([9; 3], [-1.0; 3], h, &values).unwrap();
//! assert!(check_distance(&grid).is_distance());
//! ```

use std::time::{Duration, Instant};

use std::borrow::Cow;

use ponq_mesh::band::BandGrid;
use ponq_mesh::nn::PointIndex;
use ponq_mesh::{Ponq, Quadric, TriMesh};
use rayon::prelude::*;

use crate::error::{DataError, Result};
use crate::sdf::{ClosestQueries, MeshSdf};

/// A grid of signed distances, negative inside: node `(i, j, k)` at `lo + h (i, j, k)`.
/// The values live in a [`BandGrid`]: every stage here reads the nodes near the surface
/// only (the band `|d| < 3` cells and two nodes around it), so a grid stored near its surface
/// gives the same results as the dense one ([`DistanceGrid::band_threshold`] says how wide
/// the band must be).
///
/// Invariants (checked by the constructors): every dimension is at least 2, `h` is positive
/// and finite, every value finite.
#[derive(Debug, Clone)]
pub struct DistanceGrid<'a> {
    /// Nodes per axis.
    pub dims: [usize; 3],
    /// Position of node `(0, 0, 0)`.
    pub lo: [f64; 3],
    /// Node spacing (the same along every axis).
    pub h: f64,
    /// Signed distances.
    values: Cow<'a, BandGrid>,
}

impl<'a> DistanceGrid<'a> {
    /// Checks and wraps a dense grid (`values` in C order, `k` fastest).
    ///
    /// # Errors
    /// [`DataError::Invalid`] for a size mismatch, fewer than 2 nodes along an axis, a
    /// spacing that is not positive and finite, or a non-finite value.
    pub fn new(dims: [usize; 3], lo: [f64; 3], h: f64, values: &[f64]) -> Result<Self> {
        if values.len() != dims.iter().product::<usize>() {
            return Err(DataError::Invalid(format!(
                "{} values for a grid of {dims:?} nodes",
                values.len()
            )));
        }
        if let Some(i) = values.iter().position(|v| !v.is_finite()) {
            return Err(DataError::Invalid(format!(
                "the grid holds a non-finite value at flat index {i}"
            )));
        }
        Self::check_frame(dims, lo, h)?;
        let band = BandGrid::from_dense(dims, values, 1.0, f64::INFINITY, 0)
            .map_err(|e| DataError::Invalid(e.to_string()))?;
        Ok(Self {
            dims,
            lo,
            h,
            values: Cow::Owned(band),
        })
    }

    /// Wraps a grid stored near its surface; its band must hold every node with
    /// `|d| < band_threshold(h, band)` and [`BAND_REACH`] nodes around each.
    ///
    /// # Errors
    /// [`DataError::Invalid`] for an invalid frame, or a band narrower than the stages need.
    pub fn from_band(grid: &'a BandGrid, lo: [f64; 3], h: f64, band: f64) -> Result<Self> {
        let dims = grid.dims();
        Self::check_frame(dims, lo, h)?;
        if grid.threshold() < Self::band_threshold(h, band) || grid.reach() < BAND_REACH {
            return Err(DataError::Invalid(format!(
                "the stored band (|d| < {}, reach {}) is narrower than the refinement reads \
                 (|d| < {}, reach {BAND_REACH})",
                grid.threshold(),
                grid.reach(),
                Self::band_threshold(h, band)
            )));
        }
        Ok(Self {
            dims,
            lo,
            h,
            values: Cow::Borrowed(grid),
        })
    }

    /// The smallest band threshold [`DistanceGrid::from_band`] accepts for cells of size `h`
    /// and a sampling band of `band` cells ([`RefineOptions::band`]): the distance check
    /// reads the nodes below 3 cells, the sampling those below `band`.
    pub fn band_threshold(h: f64, band: f64) -> f64 {
        h * band.max(3.0)
    }

    fn check_frame(dims: [usize; 3], lo: [f64; 3], h: f64) -> Result<()> {
        if dims.iter().any(|&d| d < 2) {
            return Err(DataError::Invalid(format!(
                "a distance grid needs at least 2 nodes per axis, got {dims:?}"
            )));
        }
        if !(h > 0.0 && h.is_finite()) || lo.iter().any(|x| !x.is_finite()) {
            return Err(DataError::Invalid(format!(
                "invalid grid frame: origin {lo:?}, spacing {h}"
            )));
        }
        Ok(())
    }

    /// The values.
    pub fn values(&self) -> &BandGrid {
        &self.values
    }

    #[inline]
    fn value(&self, i: usize, j: usize, k: usize) -> f64 {
        self.values.get(i, j, k)
    }

    #[inline]
    fn node(&self, i: usize, j: usize, k: usize) -> [f64; 3] {
        [
            self.lo[0] + self.h * i as f64,
            self.lo[1] + self.h * j as f64,
            self.lo[2] + self.h * k as f64,
        ]
    }

    /// Flat indices, ascending, of the nodes with `|d| < band` (in grid units).
    fn band_nodes(&self, band: f64) -> Vec<usize> {
        self.values.stored_where(|v| v.abs() < band)
    }
}

/// Nodes around a band node that the stages read (the 5x5x5 blocks of [`check_distance`]
/// and [`grid_samples`]).
pub const BAND_REACH: usize = 2;

/// Options of [`grid_samples`], [`refit`] and [`refine`]. Lengths are in grid cells.
#[derive(Debug, Clone)]
pub struct RefineOptions {
    /// Nodes with `|d| < band` give a sample.
    pub band: f64,
    /// A sample goes to its nearest PoNQ point if that is within `radius`.
    pub radius: f64,
    /// Samples farther than this from the mesh that gave their direction are dropped.
    pub max_shift: f64,
    /// A sample that still enters a neighbour node's ball this deep after being pushed out
    /// is dropped.
    pub ball_tolerance: f64,
    /// Weight of the network's own quadric in the refitted one (0: the samples' alone).
    pub prior: f64,
    /// Also replace each point's normal by its samples' mean normal (its length kept).
    pub normals: bool,
    /// Points need this many samples to be refitted (the others keep the network's values).
    pub min_samples: usize,
    /// Rounds of mesh -> samples -> refit -> mesh; `None`: [`RefineOptions::rounds_for`].
    pub rounds: Option<usize>,
    /// Solve the refitted v* around the network's v* (true) or around its point (false).
    pub around_vstar: bool,
    /// 0: each sample goes to its nearest point only (Voronoi cells). Otherwise a sample
    /// counts for every sharing point (of its 8 nearest) within this many cells, weighted by
    /// `exp(-(dist / (share / 2))^2)` (see [`refit`]'s `sharing`). `None`:
    /// [`RefineOptions::share_for`] the grid ([`refit`] alone, which does not see the grid:
    /// 0.5).
    pub share: Option<f64>,
    /// Relative singular-value cut-off of the refitted v* solve (the mesher's default is
    /// `ponq_mesh::quadric::SVD_CUTOFF`, 0.05).
    pub cutoff: f64,
    /// Move the refitted PoNQ's v* out of the nodes' balls before meshing ([`clear_balls`]).
    pub clear: bool,
    /// A refitted v* farther than this from its point is solved again with fewer directions
    /// (see [`refit`]).
    pub max_move: f64,
    /// A sample counts for a point only if its normal is within this many degrees of the
    /// point's (samples of the far side of a thin part do not).
    pub max_angle: f64,
}

impl RefineOptions {
    /// The default number of rounds on a grid of `cells` per side: 2 up to 48 cells, 1 above
    /// (a second round gains less on finer grids and doubles the time).
    pub fn rounds_for(cells: usize) -> usize {
        if cells <= 48 { 2 } else { 1 }
    }

    /// The default sharing radius on a grid of `cells` per side: 0.75 cells from 49 to 96
    /// cells, 0.5 otherwise. Measured at 33^3, 65^3 and 129^3 (`docs/refinement.md`): at 65^3
    /// the wider radius finds more edges (CAD EF1 0.797 -> 0.803 on the evaluation meshes,
    /// 0.884 -> 0.897 on the development set); at 33^3 it merges thin parts' samples (F1
    /// falls) and at 129^3 it finds fewer edges (EF1 falls on both sets and both groups).
    pub fn share_for(cells: usize) -> f64 {
        if (49..=96).contains(&cells) {
            0.75
        } else {
            0.5
        }
    }
}

impl Default for RefineOptions {
    fn default() -> Self {
        Self {
            band: 1.75,
            radius: 1.0,
            max_shift: 1.0,
            ball_tolerance: 0.05,
            prior: 0.1,
            normals: false,
            min_samples: 1,
            rounds: None,
            around_vstar: false,
            share: None,
            cutoff: ponq_mesh::quadric::SVD_CUTOFF,
            clear: true,
            max_move: 1.0,
            max_angle: 100.0,
        }
    }
}

/// What [`check_distance`] measured on the nodes near the surface.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DistanceCheck {
    /// Nodes with `1 < |d| < 3` cells (two nodes or more from the grid's sides, not on a
    /// truncated plateau) that were tested.
    pub band_nodes: usize,
    /// Median over them of the steepest descent rate of `|d|` towards the surface: the
    /// largest `sign(d(x)) (d(x) - d(y)) / |x - y|` over the nodes `y` of the 5x5x5 block
    /// around `x`. A true distance gives nearly 1 (exactly 1 along the gradient; the block's
    /// directions miss it by at most a few degrees).
    pub steepest_median: f64,
    /// Fraction of them with a steepest rate above 0.9.
    pub steepest_unit_fraction: f64,
    /// Nodes with a rate above 1 (+0.1%): the field changes faster than a distance can.
    pub steeper_than_one: usize,
}

impl DistanceCheck {
    /// Whether the grid looks like a true signed distance near its surface: at most 1% of
    /// the tested nodes steeper than 1, a median steepest rate of at least 0.92 and at least
    /// 60% of the nodes above 0.9. Scaled, smoothed or noisy fields fail (measured on grids
    /// made so from exact ones: `docs/refinement.md`); a truncated one passes (its band is
    /// exact). Nodes closer than one cell are left out: next to a part thinner than a cell
    /// the descent crosses to the other side, so exact grids of thin parts look smoothed there.
    pub fn is_distance(&self) -> bool {
        self.band_nodes > 0
            && self.steeper_than_one as f64 <= 0.01 * self.band_nodes as f64
            && self.steepest_median >= 0.92
            && self.steepest_unit_fraction >= 0.6
    }
}

impl std::fmt::Display for DistanceCheck {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "{} nodes near the surface: steepest rate median {:.3}, {:.1}% above 0.9, {:.1}% above 1",
            self.band_nodes,
            self.steepest_median,
            100.0 * self.steepest_unit_fraction,
            100.0 * self.steeper_than_one as f64 / self.band_nodes.max(1) as f64
        )
    }
}

/// Tests whether a grid holds a true signed distance near its zero level set (see
/// [`DistanceCheck`]): a distance is 1-Lipschitz, and from every node off the medial axis
/// it falls towards the surface at rate 1.
pub fn check_distance(grid: &DistanceGrid) -> DistanceCheck {
    let h = grid.h;
    let [n0, n1, n2] = grid.dims;
    const R: usize = 2;
    let offsets: Vec<([isize; 3], f64)> = (-2isize..=2)
        .flat_map(|a| (-2isize..=2).flat_map(move |b| (-2isize..=2).map(move |c| [a, b, c])))
        .filter(|o| *o != [0, 0, 0])
        .map(|o| {
            let l = ((o[0] * o[0] + o[1] * o[1] + o[2] * o[2]) as f64).sqrt();
            (o, 1.0 / (l * h))
        })
        .collect();
    // A truncated field clamps many nodes to its extreme values: leave those out.
    let stats = grid.values.stats();
    let (vmin, vmax) = (stats.min.min(0.0), stats.max.max(0.0));
    let count_at = |x: f64| stats.count_of_extreme(x).unwrap_or(0) as usize;
    let many = grid.values.len() / 100;
    let clamp_hi = (vmax > 0.0 && count_at(vmax) > many).then_some(vmax);
    let clamp_lo = (vmin < 0.0 && count_at(vmin) > many).then_some(vmin);
    let clamped = |v: f64| Some(v) == clamp_hi || Some(v) == clamp_lo;
    let tested = grid
        .values
        .stored_where(|v| v.abs() > h && v.abs() < 3.0 * h && !clamped(v));
    let rates: Vec<f64> = tested
        .par_iter()
        .filter_map(|&f| {
            let [i, j, k] = grid.values.coords(f);
            if i < R || j < R || k < R || i + R >= n0 || j + R >= n1 || k + R >= n2 {
                return None;
            }
            let v = grid.value(i, j, k);
            let sign = v.signum();
            let mut best = f64::NEG_INFINITY;
            for &(o, inv) in &offsets {
                let y = grid.value(
                    (i as isize + o[0]) as usize,
                    (j as isize + o[1]) as usize,
                    (k as isize + o[2]) as usize,
                );
                best = best.max(sign * (v - y) * inv);
            }
            Some(best)
        })
        .collect();
    let n = rates.len();
    let steeper = rates.iter().filter(|&&r| r > 1.0 + 1e-3).count();
    let unit = rates.iter().filter(|&&r| r > 0.9).count();
    let mut rates = rates;
    let median = if n == 0 {
        f64::NAN
    } else {
        *rates.select_nth_unstable_by(n / 2, f64::total_cmp).1
    };
    DistanceCheck {
        band_nodes: n,
        steepest_median: median,
        steepest_unit_fraction: if n == 0 { 0.0 } else { unit as f64 / n as f64 },
        steeper_than_one: steeper,
    }
}

/// Surface samples read off a distance grid along the directions of a mesh.
#[derive(Debug, Clone, Default)]
pub struct GridSamples {
    /// Sample positions (on the true surface up to the directions' error).
    pub points: Vec<[f64; 3]>,
    /// Unit outward normals.
    pub normals: Vec<[f64; 3]>,
    /// Nodes of the band.
    pub band_nodes: usize,
    /// Band nodes whose sample was dropped.
    pub dropped: usize,
    /// RMS over the band nodes of `dist(x, mesh) - |d(x)|`, in cells: how well the mesh fits
    /// the grid's distances.
    pub residual: f64,
}

/// Depth, in cells, at which a face inside a node's ball counts as an intrusion.
const INTRUSION_DEPTH: f64 = 0.25;

/// Band nodes per run of closest-point queries (consecutive nodes are neighbours, so each
/// query starts from its predecessor's triangle).
const QUERY_CHUNK: usize = 256;

/// Offsets of the neighbour nodes whose balls a sample is tested against.
const REACH: isize = 2;

/// One sample per band node (`|d| < band` cells): `s = x + |d| u` with `u` the direction
/// from `x` to its closest point on `mesh`, pushed out of the neighbour nodes' balls along
/// the sphere of `x`; dropped when it still enters one by more than `ball_tolerance` or is
/// farther than `max_shift` from the mesh. Also measures how well `mesh` fits the distances.
///
/// # Errors
/// [`DataError::Invalid`] for a mesh without faces or with non-finite vertices.
pub fn grid_samples(
    grid: &DistanceGrid,
    mesh: &TriMesh,
    opts: &RefineOptions,
) -> Result<GridSamples> {
    let sdf = MeshSdf::for_distances(mesh)?;
    let h = grid.h;
    let nodes = grid.band_nodes(opts.band * h);
    let tol = opts.ball_tolerance * h;
    let max_shift = opts.max_shift * h;
    type Out = (Option<([f64; 3], [f64; 3])>, f64);
    let out: Vec<Out> = nodes
        .par_chunks(QUERY_CHUNK)
        .flat_map_iter(|chunk| {
            let sdf = &sdf;
            let mut queries = ClosestQueries::default();
            chunk.iter().map(move |&f| {
                let [i, j, k] = grid.values.coords(f);
                let x = grid.node(i, j, k);
                let d = grid.value(i, j, k);
                let r = d.abs();
                let (y, nf) = sdf.closest_point_and_normal_with(x, &mut queries);
                let yx = sub(y, x);
                let dist = norm(yx);
                let res = (dist - r) / h;
                let sign = if d < 0.0 { -1.0 } else { 1.0 };
                let u = if dist > 1e-12 * h {
                    yx.map(|c| c / dist)
                } else if norm(nf) > 0.0 {
                    nf.map(|c| -sign * c)
                } else {
                    return (None, res);
                };
                let s0 = add(x, u.map(|c| c * r));
                let mut s = s0;
                if r > 0.0 {
                    // The balls that could hold the sample while it moves less than `slack`.
                    let slack = 0.5 * h;
                    let mut balls: Vec<([f64; 3], f64)> = Vec::with_capacity(32);
                    for_each_neighbour(grid, [i, j, k], |c, rc| {
                        if norm(sub(s0, c)) < rc + slack {
                            balls.push((c, rc));
                        }
                    });
                    let deepest = |s: [f64; 3]| {
                        balls.iter().fold((([0.0; 3], 0.0), 0.0), |best, &(c, rc)| {
                            let pen = rc - norm(sub(s, c));
                            if pen > best.1 { ((c, rc), pen) } else { best }
                        })
                    };
                    // Push the sample out of the neighbours' balls, back onto x's sphere.
                    for _ in 0..4 {
                        let ((c, rc), pen) = deepest(s);
                        if pen <= 1e-3 * h {
                            break;
                        }
                        let cs = sub(s, c);
                        let l = norm(cs);
                        if l == 0.0 {
                            break;
                        }
                        let pushed = add(c, cs.map(|v| v * rc / l));
                        let xs = sub(pushed, x);
                        let lx = norm(xs);
                        if lx == 0.0 {
                            break;
                        }
                        s = add(x, xs.map(|v| v * r / lx));
                    }
                    let pen = if norm(sub(s, s0)) < slack {
                        deepest(s).1
                    } else {
                        let mut worst = 0.0f64;
                        for_each_neighbour(grid, [i, j, k], |c, rc| {
                            worst = worst.max(rc - norm(sub(s, c)));
                        });
                        worst
                    };
                    if pen > tol {
                        return (None, res);
                    }
                }
                if norm(sub(s, y)) > max_shift {
                    return (None, res);
                }
                let n = if r > 0.0 {
                    sub(s, x).map(|c| -sign * c / r)
                } else {
                    nf
                };
                (Some((s, n)), res)
            })
        })
        .collect();
    let mut g = GridSamples {
        band_nodes: nodes.len(),
        ..Default::default()
    };
    let mut sq = 0.0;
    for (s, res) in out {
        sq += res * res;
        match s {
            Some((p, n)) => {
                g.points.push(p);
                g.normals.push(n);
            }
            None => g.dropped += 1,
        }
    }
    g.residual = if nodes.is_empty() {
        0.0
    } else {
        (sq / nodes.len() as f64).sqrt()
    };
    Ok(g)
}

/// How well `mesh` fits the grid's distances: [`GridSamples::residual`] alone (no samples).
///
/// # Errors
/// As [`grid_samples`].
pub fn fit_residual(grid: &DistanceGrid, mesh: &TriMesh, opts: &RefineOptions) -> Result<f64> {
    let sdf = MeshSdf::for_distances(mesh)?;
    let nodes = grid.band_nodes(opts.band * grid.h);
    let (sq, n) = nodes
        .par_chunks(QUERY_CHUNK)
        .map(|chunk| {
            let mut queries = ClosestQueries::default();
            chunk.iter().fold((0.0, 0usize), |(sq, n), &f| {
                let [i, j, k] = grid.values.coords(f);
                let x = grid.node(i, j, k);
                let (y, _) = sdf.closest_point_and_normal_with(x, &mut queries);
                let res = (norm(sub(y, x)) - grid.value(i, j, k).abs()) / grid.h;
                (sq + res * res, n + 1)
            })
        })
        .reduce(|| (0.0, 0), |a, b| (a.0 + b.0, a.1 + b.1));
    Ok(if n == 0 { 0.0 } else { (sq / n as f64).sqrt() })
}

/// Moves every v* of `ponq` out of the nodes' open balls (the surface enters none of them,
/// so neither should a vertex): up to four times, the v* goes radially to the sphere of the
/// ball it enters deepest; a v* that would move farther than `max_move` cells stays. Returns
/// how many v* moved.
pub fn clear_balls(grid: &DistanceGrid, ponq: &mut Ponq, max_move: f64) -> usize {
    let mut vstars = ponq.vstars();
    let h = grid.h;
    let max_move = max_move * h;
    let moved: Vec<Option<[f64; 3]>> = vstars
        .par_iter()
        .map(|&v| {
            let c: [isize; 3] = std::array::from_fn(|a| ((v[a] - grid.lo[a]) / h).round() as isize);
            if (0..3).any(|a| c[a] < 0 || c[a] >= grid.dims[a] as isize) {
                return None;
            }
            let at = c.map(|x| x as usize);
            let mut p = v;
            let mut changed = false;
            for _ in 0..4 {
                // The ball `p` enters deepest (one centred at `p` gives no direction).
                let mut worst = (([0.0; 3], 0.0), 1e-3 * h);
                let mut consider = |c: [f64; 3], rc: f64| {
                    let l = norm(sub(p, c));
                    if l > 1e-9 * h && rc - l > worst.1 {
                        worst = ((c, rc), rc - l);
                    }
                };
                for_each_neighbour(grid, at, &mut consider);
                consider(
                    grid.node(at[0], at[1], at[2]),
                    grid.value(at[0], at[1], at[2]).abs(),
                );
                if worst.1 <= 1e-3 * h {
                    break;
                }
                let ((c, rc), _) = worst;
                let cp = sub(p, c);
                p = add(c, cp.map(|x| x * rc / norm(cp)));
                changed = true;
            }
            // A v* deeper than `max_move` in the balls is not near this surface (a point of a
            // thin part meshed on the wrong side): pushing it out could take it anywhere.
            (changed && norm(sub(p, v)) <= max_move).then_some(p)
        })
        .collect();
    let mut count = 0;
    for (v, m) in vstars.iter_mut().zip(moved) {
        if let Some(p) = m {
            *v = p;
            count += 1;
        }
    }
    ponq.vstars = Some(vstars);
    count
}

/// Faces of `mesh` that cross space a node's ball shows empty: their centroid lies more than
/// `depth` cells inside the open ball of one of the 8 nodes around it (a triangle bridging a
/// gap, a spike out of a thin part). A mesh of the true surface has none.
pub fn intrusions(grid: &DistanceGrid, mesh: &TriMesh, depth: f64) -> usize {
    let h = grid.h;
    let depth = depth * h;
    mesh.faces
        .par_iter()
        .filter(|f| {
            let [a, b, c] = f.map(|v| mesh.vertices[v as usize]);
            let p: [f64; 3] = std::array::from_fn(|k| (a[k] + b[k] + c[k]) / 3.0);
            let base: [isize; 3] =
                std::array::from_fn(|k| ((p[k] - grid.lo[k]) / h).floor() as isize);
            (0..8).any(|corner| {
                let n: [isize; 3] = std::array::from_fn(|k| base[k] + ((corner >> k) & 1));
                if (0..3).any(|k| n[k] < 0 || n[k] >= grid.dims[k] as isize) {
                    return false;
                }
                let [i, j, k] = n.map(|x| x as usize);
                let r = grid.value(i, j, k).abs();
                r - norm(sub(p, grid.node(i, j, k))) > depth
            })
        })
        .count()
}

/// Calls `f(centre, radius)` for the balls of the nodes within [`REACH`] nodes of `at`
/// (itself excluded).
#[inline]
fn for_each_neighbour(grid: &DistanceGrid, at: [usize; 3], mut f: impl FnMut([f64; 3], f64)) {
    let range = |a: usize| {
        let lo = at[a].saturating_sub(REACH as usize);
        let hi = (at[a] + REACH as usize).min(grid.dims[a] - 1);
        lo..=hi
    };
    for i in range(0) {
        for j in range(1) {
            for k in range(2) {
                if [i, j, k] == at {
                    continue;
                }
                f(grid.node(i, j, k), grid.value(i, j, k).abs());
            }
        }
    }
}

/// One refitted point: its quadric, v* and normal.
type Refitted = (Quadric, [f64; 3], [f64; 3]);

/// What [`refit`] changed.
#[derive(Debug, Clone, Copy, Default)]
pub struct RefitStats {
    /// Points whose quadric was refitted.
    pub refitted: usize,
    /// Samples assigned to a point.
    pub assigned: usize,
}

/// Refits a PoNQ to grid samples: each sample goes to its nearest point (by v*) within
/// `radius` cells, and with a sharing radius above 0 also to the sharing points near it (`sharing`:
/// one flag per point, `None` for all; the points of cells that will be merged into one need
/// no sharing: their cell already gathers the samples of all its points); a point with at
/// least `min_samples` samples gets the weighted mean of their plane quadrics, scaled to the
/// trace of its own quadric's `A` (and mixed with it by `prior`), and its v* solved again
/// within `max_move` cells of its point; the others are unchanged. Points, and normals unless `opts.normals`, are kept.
///
/// # Errors
/// [`DataError::Invalid`] for a non-positive `h` or a `sharing` of the wrong length; errors
/// of [`Ponq::new`].
pub fn refit(
    ponq: &Ponq,
    samples: &GridSamples,
    h: f64,
    opts: &RefineOptions,
    sharing: Option<&[bool]>,
) -> Result<(Ponq, RefitStats)> {
    if let Some(f) = sharing
        && f.len() != ponq.len()
    {
        return Err(DataError::Invalid(format!(
            "{} sharing flags for {} points",
            f.len(),
            ponq.len()
        )));
    }
    let shares = |i: usize| sharing.is_none_or(|f| f[i]);
    if !(h > 0.0 && h.is_finite()) {
        return Err(DataError::Invalid(format!("invalid cell size {h}")));
    }
    let vstars = ponq.vstars();
    let mut stats = RefitStats::default();
    let Some(index) = PointIndex::new(&vstars) else {
        return Ok((ponq.clone(), stats));
    };
    let r2 = (opts.radius * h).powi(2);
    let m = ponq.len();
    let mut quad = vec![Quadric::zero(); m];
    let mut nsum = vec![[0.0f64; 3]; m];
    let mut count = vec![0usize; m];
    let mut weight = vec![0.0f64; m];
    // A sample only counts for a point on its side of the surface: on a part thinner than
    // the sharing radius, samples of the other side (opposite normals) would pull the point's
    // v* to the middle and the part would vanish. Normals of the two faces of an edge make up
    // to about 90 degrees; only those beyond `max_angle` are the other side.
    let unit: Vec<[f64; 3]> = ponq
        .normals
        .iter()
        .map(|n| {
            let l = norm(*n);
            if l > 0.0 { n.map(|c| c / l) } else { [0.0; 3] }
        })
        .collect();
    let min_cos = opts.max_angle.to_radians().cos();
    let same_side = |i: usize, s: usize| {
        let (a, b) = (unit[i], samples.normals[s]);
        a == [0.0; 3] || a[0] * b[0] + a[1] * b[1] + a[2] * b[2] >= min_cos
    };
    let mut add = |i: usize, s: usize, w: f64| {
        if !same_side(i, s) {
            return false;
        }
        quad[i] += Quadric::from_plane(samples.points[s], samples.normals[s]) * w;
        for a in 0..3 {
            nsum[i][a] += w * samples.normals[s][a];
        }
        count[i] += 1;
        weight[i] += w;
        true
    };
    let share = opts.share.unwrap_or(0.5);
    if share > 0.0 {
        let share2 = (share * h).powi(2);
        let sigma2 = (0.5 * share * h).powi(2);
        let near: Vec<Vec<(u32, f64)>> = samples
            .points
            .par_iter()
            .map(|p| index.nearest_k_within(p, 8, share2.max(r2)))
            .collect();
        for (s, list) in near.iter().enumerate() {
            let mut any = false;
            if let Some(&(i0, d0)) = list.first()
                && !shares(i0 as usize)
                && d0 <= r2
            {
                any |= add(i0 as usize, s, 1.0);
            }
            for &(i, d2) in list {
                if shares(i as usize) && d2 <= share2 {
                    any |= add(i as usize, s, (-d2 / sigma2).exp());
                }
            }
            stats.assigned += usize::from(any);
        }
    } else {
        let nearest = index.nearest_many(&samples.points);
        for (s, &(i, d2)) in nearest.iter().enumerate() {
            if d2 <= r2 && add(i as usize, s, 1.0) {
                stats.assigned += 1;
            }
        }
    }
    // Per point: the refitted (quadric, v*, normal), or None to keep the network's.
    let refitted: Vec<Option<Refitted>> = (0..m)
        .into_par_iter()
        .map(|i| {
            if count[i] < opts.min_samples.max(1) {
                return None;
            }
            let qs = quad[i] * (1.0 / weight[i]);
            let net = ponq.quadrics[i];
            let (tn, ts) = (net.a.trace(), qs.a.trace());
            if !(ts > 0.0) {
                return None;
            }
            let scale = if tn > 0.0 { tn / ts } else { 1.0 };
            let q = qs * (scale * (1.0 - opts.prior)) + net * opts.prior;
            let reference = if opts.around_vstar {
                vstars[i]
            } else {
                ponq.points[i]
            };
            // A v* stays within `max_move` of its point (the network's are within a few
            // hundredths of a cell): where the samples' planes meet farther away (nearly
            // parallel planes at a thin tip), fewer of their directions are kept, down to the
            // main plane alone; failing that the point keeps the network's values.
            let max_move = opts.max_move * h;
            let v = q
                .optimal_points(reference, [opts.cutoff, 0.2, 1.0])
                .into_iter()
                .find(|v| {
                    v.iter().all(|c| c.is_finite()) && norm(sub(*v, reference)) <= max_move
                })?;
            let mut n = ponq.normals[i];
            if opts.normals {
                let l = norm(nsum[i]);
                let keep = norm(n);
                if l > 0.0 && keep > 0.0 {
                    n = nsum[i].map(|c| c / l * keep);
                }
            }
            Some((q, v, n))
        })
        .collect();
    let mut quadrics = ponq.quadrics.clone();
    let mut normals = ponq.normals.clone();
    let mut new_vstars = vstars;
    for (i, r) in refitted.into_iter().enumerate() {
        if let Some((q, v, n)) = r {
            quadrics[i] = q;
            new_vstars[i] = v;
            normals[i] = n;
            stats.refitted += 1;
        }
    }
    let out = Ponq::new(ponq.points.clone(), normals, quadrics, Some(new_vstars))?;
    Ok((out, stats))
}

/// What [`refine`] did.
#[derive(Debug, Clone, Default)]
pub struct Refinement {
    /// The mesh kept (the input mesh when no round improved the fit).
    pub mesh: TriMesh,
    /// The refitted PoNQ that gave it (`None` when the input mesh was kept).
    pub ponq: Option<Ponq>,
    /// Fit of each mesh to the distances (see [`GridSamples::residual`]): the input's first.
    pub residuals: Vec<f64>,
    /// Rounds whose mesh was kept (0: the input).
    pub rounds_kept: usize,
    /// Samples of the last round (band nodes, dropped).
    pub samples: (usize, usize),
    /// Time spent sampling and refitting (meshing excluded).
    pub time: Duration,
}

/// Refines a PoNQ against a distance grid: starting from `mesh` (the mesh of `ponq`),
/// `opts.rounds` times take samples along the current mesh's directions, refit `ponq`
/// (always the original, so errors do not compound; `sharing` as in [`refit`]) and mesh it
/// with `mesh_fn`; a round's mesh is kept only if it fits the distances better than the best
/// so far and has no more faces through empty space ([`intrusions`]) than `mesh`.
///
/// # Errors
/// Errors of [`grid_samples`], [`refit`] and `mesh_fn`.
pub fn refine(
    ponq: &Ponq,
    mesh: &TriMesh,
    grid: &DistanceGrid,
    opts: &RefineOptions,
    sharing: Option<&[bool]>,
    mut mesh_fn: impl FnMut(&Ponq) -> Result<TriMesh>,
) -> Result<Refinement> {
    let mut out = Refinement {
        mesh: mesh.clone(),
        ..Default::default()
    };
    let mut spent = Duration::ZERO;
    if mesh.faces.is_empty() {
        return Ok(out);
    }
    let mut current = mesh.clone();
    let mut current_ponq: Option<Ponq> = None;
    let mut best = f64::INFINITY;
    // A round may not add faces through empty space (see [`intrusions`]); the fit of a few
    // such faces barely changes.
    let allowed = intrusions(grid, mesh, INTRUSION_DEPTH);
    let cells = grid.dims.iter().max().map_or(1, |&d| d - 1);
    let rounds = opts
        .rounds
        .unwrap_or_else(|| RefineOptions::rounds_for(cells));
    let opts = &RefineOptions {
        share: Some(
            opts.share
                .unwrap_or_else(|| RefineOptions::share_for(cells)),
        ),
        ..opts.clone()
    };
    for round in 0..=rounds {
        let t = Instant::now();
        if round == rounds {
            // The last mesh only needs its fit.
            let r = fit_residual(grid, &current, opts)?;
            let clean = round == 0 || intrusions(grid, &current, INTRUSION_DEPTH) <= allowed;
            spent += t.elapsed();
            out.residuals.push(r);
            if r < best && clean {
                out.mesh = current.clone();
                out.ponq = current_ponq.clone();
                out.rounds_kept = round;
            }
            break;
        }
        let s = grid_samples(grid, &current, opts)?;
        spent += t.elapsed();
        out.residuals.push(s.residual);
        let clean = round == 0 || intrusions(grid, &current, INTRUSION_DEPTH) <= allowed;
        if s.residual < best && clean {
            best = s.residual;
            out.mesh = current.clone();
            out.ponq = current_ponq.clone();
            out.rounds_kept = round;
        } else {
            break;
        }
        out.samples = (s.band_nodes, s.dropped);
        if s.points.is_empty() {
            break;
        }
        let t = Instant::now();
        let (p, _) = refit(ponq, &s, grid.h, opts, sharing)?;
        spent += t.elapsed();
        current = mesh_fn(&p)?;
        if current.faces.is_empty() {
            break;
        }
        current_ponq = Some(p);
    }
    out.time = spent;
    Ok(out)
}

#[inline]
fn sub(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}

#[inline]
fn add(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [a[0] + b[0], a[1] + b[1], a[2] + b[2]]
}

#[inline]
fn norm(a: [f64; 3]) -> f64 {
    (a[0] * a[0] + a[1] * a[1] + a[2] * a[2]).sqrt()
}
