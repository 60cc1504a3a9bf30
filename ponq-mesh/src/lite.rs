//! PoNQ-lite and the hierarchy (SPEC section 2): merge the points of each grid cell, or of each
//! 2^K block of cells, by summing their quadrics, and solve one v* per group; and adaptive
//! PoNQ-lite ([`merge_smooth_cells`]), which merges only the cells whose normals agree.
//!
//! ```
//! use ponq_mesh::lite::{coarsen, merge_smooth_cells};
//! use ponq_mesh::{Ponq, Quadric};
//!
//! // Two cells: one on a flat face (two points, same normal), one on a crease (two normals).
//! let pts = vec![[0.1, 0.1, 0.0], [0.3, 0.2, 0.0], [1.1, 0.2, 0.0], [1.2, 0.1, 0.1]];
//! let nrm = vec![[0.0, 0.0, 1.0], [0.0, 0.0, 1.0], [0.0, 0.0, 1.0], [1.0, 0.0, 0.0]];
//! let quadrics = pts.iter().zip(&nrm).map(|(p, n)| Quadric::from_plane(*p, *n)).collect();
//! let ponq = Ponq::new(pts, nrm, quadrics, None).unwrap();
//! let cells = [[0, 0, 0], [0, 0, 0], [1, 0, 0], [1, 0, 0]];
//! assert_eq!(coarsen(&ponq, &cells, 0).unwrap().len(), 2); // PoNQ-lite: one per cell
//! assert_eq!(merge_smooth_cells(&ponq, &cells, 15.0).unwrap().len(), 3); // the crease keeps two
//! ```

use std::collections::HashMap;

use crate::error::{Error, Result};
use crate::ponq::Ponq;
use crate::quadric::{Quadric, SVD_CUTOFF};

/// Cell of a point `p` in a grid of `n` cells per side over `domain` (clamped to the grid).
pub fn cell_of(p: [f64; 3], n: usize, domain: ([f64; 3], [f64; 3])) -> [u32; 3] {
    let (lo, hi) = domain;
    std::array::from_fn(|k| {
        let t = (p[k] - lo[k]) / (hi[k] - lo[k]) * n as f64;
        (t.floor().max(0.0) as usize).min(n.saturating_sub(1)) as u32
    })
}

/// PoNQ-lite (with `coarsen` more levels) when `lite`, else adaptive PoNQ-lite at
/// `merge_smooth` degrees when given, else the PoNQ unchanged, for a PoNQ whose points' grid
/// cells are not known: each point's cell is the one its position falls in (a grid of
/// `grid_scale` cells per side over `domain`, [`cell_of`]). Returns the PoNQ and the grid scale
/// to mesh it with (divided by `2^coarsen` for the hierarchy). What `ponq-mesh` does with an
/// `.npz`.
///
/// # Errors
/// As [`coarsen`] and [`merge_smooth_cells`].
pub fn simplify_by_position(
    ponq: &Ponq,
    grid_scale: f64,
    domain: ([f64; 3], [f64; 3]),
    lite: bool,
    coarsen_levels: u32,
    merge_smooth: Option<f64>,
) -> Result<(Ponq, f64)> {
    let cells = || -> Vec<[u32; 3]> {
        let n = grid_scale.round() as usize;
        ponq.points.iter().map(|&p| cell_of(p, n, domain)).collect()
    };
    if lite {
        let out = coarsen(ponq, &cells(), coarsen_levels)?;
        Ok((out, grid_scale / f64::from(1u32 << coarsen_levels.min(20))))
    } else if let Some(angle) = merge_smooth {
        Ok((merge_smooth_cells(ponq, &cells(), angle)?, grid_scale))
    } else {
        Ok((ponq.clone(), grid_scale))
    }
}

/// Merges the points of each group of `2^coarsen` x `2^coarsen` x `2^coarsen` cells
/// (`coarsen = 0` is PoNQ-lite: one point per cell). `cells[i]` is the grid cell of point `i`.
/// Quadrics (with their `b` and `c` parts) are summed, normals averaged, and the new v* is the
/// pseudo-inverse solution around the mean of the group's v*. Groups come out in increasing
/// cell order (deterministic).
///
/// # Errors
/// [`Error::InvalidInput`] when `cells` and the PoNQ differ in length.
pub fn coarsen(ponq: &Ponq, cells: &[[u32; 3]], coarsen: u32) -> Result<Ponq> {
    check_one_cell_per_point(ponq, cells)?;
    if coarsen > 20 {
        return Err(Error::InvalidInput(format!(
            "coarsening {coarsen} times is more than any grid supports"
        )));
    }
    let groups = group_by_cell(cells, |c| c.map(|x| x >> coarsen));
    let vstars = ponq.vstars();
    let mut out = Merged::default();
    for (_, members) in groups {
        out.push_merged(ponq, &vstars, &members);
    }
    out.into_ponq()
}

/// Adaptive PoNQ-lite: merges the points of each grid cell into one (as [`coarsen`] with
/// `coarsen = 0`) where the cell's surface is smooth, i.e. all its points' normals lie within
/// `max_angle_deg` degrees of each other, and keeps every point of the other cells (creases and
/// corners, where the points carry the different planes). `cells[i]` is the grid cell of point
/// `i`. Groups come out in increasing cell order; a kept cell's points keep their order.
///
/// With `max_angle_deg = 0` only cells whose normals are identical are merged; with 180 every
/// cell is (PoNQ-lite). A point with a zero normal never merges.
///
/// # Errors
/// [`Error::InvalidInput`] when `cells` and the PoNQ differ in length or the angle is not in
/// `[0, 180]`.
pub fn merge_smooth_cells(ponq: &Ponq, cells: &[[u32; 3]], max_angle_deg: f64) -> Result<Ponq> {
    check_one_cell_per_point(ponq, cells)?;
    if !(0.0..=180.0).contains(&max_angle_deg) {
        return Err(Error::InvalidInput(format!(
            "the normal angle for merging must be in [0, 180] degrees, got {max_angle_deg}"
        )));
    }
    let smooth = smooth_test(ponq, max_angle_deg);
    let groups = group_by_cell(cells, |c| c);
    let vstars = ponq.vstars();
    let mut out = Merged::default();
    for (_, members) in groups {
        if members.len() > 1 && smooth(&members) {
            out.push_merged(ponq, &vstars, &members);
        } else {
            for &i in &members {
                out.points.push(ponq.points[i]);
                out.normals.push(ponq.normals[i]);
                out.quadrics.push(ponq.quadrics[i]);
                out.vstars.push(vstars[i]);
            }
        }
    }
    out.into_ponq()
}

/// Which points [`merge_smooth_cells`] merges with the other points of their cell (a cell of
/// two points or more whose normals agree within `max_angle_deg` degrees): `true` for each
/// point of a smooth cell.
///
/// # Errors
/// As [`merge_smooth_cells`].
pub fn smooth_points(ponq: &Ponq, cells: &[[u32; 3]], max_angle_deg: f64) -> Result<Vec<bool>> {
    check_one_cell_per_point(ponq, cells)?;
    if !(0.0..=180.0).contains(&max_angle_deg) {
        return Err(Error::InvalidInput(format!(
            "the normal angle for merging must be in [0, 180] degrees, got {max_angle_deg}"
        )));
    }
    let smooth = smooth_test(ponq, max_angle_deg);
    let mut out = vec![false; ponq.len()];
    for (_, members) in group_by_cell(cells, |c| c) {
        if members.len() > 1 && smooth(&members) {
            for i in members {
                out[i] = true;
            }
        }
    }
    Ok(out)
}

/// Whether the points `members` have pairwise normals within `max_angle_deg` degrees (a
/// zero normal agrees with nothing).
fn smooth_test(ponq: &Ponq, max_angle_deg: f64) -> impl Fn(&[usize]) -> bool {
    let min_cos = max_angle_deg.to_radians().cos();
    let unit: Vec<Option<[f64; 3]>> = ponq
        .normals
        .iter()
        .map(|n| {
            let l = (n[0] * n[0] + n[1] * n[1] + n[2] * n[2]).sqrt();
            (l > 0.0 && l.is_finite()).then(|| n.map(|x| x / l))
        })
        .collect();
    move |members: &[usize]| {
        members.iter().enumerate().all(|(k, &i)| {
            members[k + 1..].iter().all(|&j| match (unit[i], unit[j]) {
                (Some(a), Some(b)) => a[0] * b[0] + a[1] * b[1] + a[2] * b[2] >= min_cos,
                _ => false,
            })
        })
    }
}

/// [`Error::InvalidInput`] unless `cells` gives one cell per point of `ponq`.
fn check_one_cell_per_point(ponq: &Ponq, cells: &[[u32; 3]]) -> Result<()> {
    if cells.len() != ponq.len() {
        return Err(Error::InvalidInput(format!(
            "{} cells for {} points",
            cells.len(),
            ponq.len()
        )));
    }
    Ok(())
}

/// The point indices of each group (`key` of the point's cell), groups in increasing key
/// order, members in point order.
fn group_by_cell(
    cells: &[[u32; 3]],
    key: impl Fn([u32; 3]) -> [u32; 3],
) -> Vec<([u32; 3], Vec<usize>)> {
    let mut groups: HashMap<[u32; 3], Vec<usize>> = HashMap::new();
    for (i, &c) in cells.iter().enumerate() {
        groups.entry(key(c)).or_default().push(i);
    }
    let mut groups: Vec<_> = groups.into_iter().collect();
    groups.sort_unstable_by_key(|g| g.0);
    groups
}

/// A PoNQ under construction.
#[derive(Default)]
struct Merged {
    points: Vec<[f64; 3]>,
    normals: Vec<[f64; 3]>,
    quadrics: Vec<Quadric>,
    vstars: Vec<[f64; 3]>,
}

impl Merged {
    /// One point for `members`: quadrics (with their `b` and `c` parts) summed, normals
    /// averaged, the point at the mean of their v*, its v* the pseudo-inverse solution
    /// around that mean.
    fn push_merged(&mut self, ponq: &Ponq, vstars: &[[f64; 3]], members: &[usize]) {
        let mut q = Quadric::zero();
        let (mut n, mut v) = ([0.0; 3], [0.0; 3]);
        for &i in members {
            q += ponq.quadrics[i];
            for k in 0..3 {
                n[k] += ponq.normals[i][k];
                v[k] += vstars[i][k];
            }
        }
        let count = members.len() as f64;
        let mean = v.map(|x| x / count);
        self.points.push(mean);
        self.normals.push(n.map(|x| x / count));
        self.quadrics.push(q);
        self.vstars.push(q.optimal_point(mean, SVD_CUTOFF));
    }

    fn into_ponq(self) -> Result<Ponq> {
        Ponq::new(self.points, self.normals, self.quadrics, Some(self.vstars))
    }
}
