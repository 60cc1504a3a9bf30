//! The normalised frame of a user's grid: the user's grid spans `bounds` with equal cell size
//! `h` along all axes. Work is done in a normalised frame where node `(0,0,0)` is at `-1` and
//! the cell size is `2 / N` with `N` the largest number of cells along an axis (so a cubic grid
//! over `[-1,1]^3` is its own normalised frame); the mesh and PoNQ are mapped back at the end.

use anyhow::{Result, bail};
use ponq_mesh::Ponq;
use ponq_mesh::io::npy::Grid3;
use ponq_mesh::quadric::Quadric;

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
        if let Some(i) = grid.data.iter().position(|v| !v.is_finite()) {
            bail!(
                "the grid holds a non-finite value ({}) at flat index {i}",
                grid.data[i]
            );
        }
        Self::of_dims(grid.dims, bounds)
    }

    /// The frame of a grid of `d` nodes over `bounds` (the checks of [`Frame::of`] but the
    /// values').
    ///
    /// The default bounds `[-1,1]^3` with unequal node counts are taken as cubic cells: the
    /// longest axis over `[-1, 1]`, the others centred on 0 ([`cubic_bounds`]).
    pub fn of_dims(d: [usize; 3], bounds: ([f64; 3], [f64; 3])) -> Result<Self> {
        if d.iter().any(|&x| x < 2) {
            bail!("the grid must have at least 2 nodes along every axis, it has {d:?}");
        }
        let (lo, hi) = if bounds == ([-1.0; 3], [1.0; 3]) && !(d[0] == d[1] && d[1] == d[2]) {
            cubic_bounds(d)
        } else {
            bounds
        };
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

/// Bounds with cubic cells for a grid of `d` nodes: the longest axis over `[-1, 1]`, the
/// others centred on 0 with the same spacing.
pub fn cubic_bounds(d: [usize; 3]) -> ([f64; 3], [f64; 3]) {
    let n = d.iter().max().copied().unwrap_or(2).max(2) - 1;
    let h = 2.0 / n as f64;
    let half = d.map(|x| x.saturating_sub(1) as f64 * h / 2.0);
    (half.map(|x| -x), half)
}

/// Maps a PoNQ from the normalised frame to the user's: positions, and quadrics
/// `Q_user(x) = Q(s (x - lo) - 1)`, i.e. `A * s^2` around the mapped v*.
pub fn ponq_to_user(p: &Ponq, f: &Frame) -> Result<Ponq> {
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
