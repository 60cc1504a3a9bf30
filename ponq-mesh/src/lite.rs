//! PoNQ-lite and the hierarchy (SPEC section 2): merge the points of each grid cell, or of each
//! 2^K block of cells, by summing their quadrics, and solve one v* per group.

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

/// Merges the points of each group of `2^coarsen` x `2^coarsen` x `2^coarsen` cells
/// (`coarsen = 0` is PoNQ-lite: one point per cell). `cells[i]` is the grid cell of point `i`.
/// Quadrics (with their `b` and `c` parts) are summed, normals averaged, and the new v* is the
/// pseudo-inverse solution around the mean of the group's v*. Groups come out in increasing
/// cell order (deterministic).
///
/// # Errors
/// [`Error::InvalidInput`] when `cells` and the PoNQ differ in length.
pub fn coarsen(ponq: &Ponq, cells: &[[u32; 3]], coarsen: u32) -> Result<Ponq> {
    if cells.len() != ponq.len() {
        return Err(Error::InvalidInput(format!(
            "{} cells for {} points",
            cells.len(),
            ponq.len()
        )));
    }
    if coarsen > 20 {
        return Err(Error::InvalidInput(format!(
            "coarsening {coarsen} times is more than any grid supports"
        )));
    }
    let vstars = ponq.vstars();
    struct Acc {
        q: Quadric,
        n: [f64; 3],
        v: [f64; 3],
        count: f64,
    }
    let mut groups: HashMap<[u32; 3], Acc> = HashMap::new();
    for i in 0..ponq.len() {
        let key = cells[i].map(|c| c >> coarsen);
        let a = groups.entry(key).or_insert(Acc {
            q: Quadric::zero(),
            n: [0.0; 3],
            v: [0.0; 3],
            count: 0.0,
        });
        a.q += ponq.quadrics[i];
        for k in 0..3 {
            a.n[k] += ponq.normals[i][k];
            a.v[k] += vstars[i][k];
        }
        a.count += 1.0;
    }
    let mut keys: Vec<[u32; 3]> = groups.keys().copied().collect();
    keys.sort_unstable();
    let mut points = Vec::with_capacity(keys.len());
    let mut normals = Vec::with_capacity(keys.len());
    let mut quadrics = Vec::with_capacity(keys.len());
    let mut vs = Vec::with_capacity(keys.len());
    for key in keys {
        let a = &groups[&key];
        let mean = a.v.map(|x| x / a.count);
        points.push(mean);
        normals.push(a.n.map(|x| x / a.count));
        quadrics.push(a.q);
        vs.push(a.q.optimal_point(mean, SVD_CUTOFF));
    }
    Ponq::new(points, normals, quadrics, Some(vs))
}
