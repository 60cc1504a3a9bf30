//! The PoNQ representation: points, normals and quadrics.

use crate::error::{Error, Result};
use crate::quadric::{Quadric, SVD_CUTOFF};

/// A PoNQ: per point a position `p`, a normal `n` and a quadric `Q`, optionally with its
/// QEM-optimal vertex `v*` already solved.
///
/// Invariants (checked by [`Ponq::new`]): all vectors have the same length, every value is
/// finite. Coordinates are in the frame of the grid domain (the `[-1,1]^3` box by default).
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Ponq {
    /// Point positions `p` (the reference points of the v* solve).
    pub points: Vec<[f64; 3]>,
    /// Normals (not necessarily unit length; a zero normal means "unknown").
    pub normals: Vec<[f64; 3]>,
    /// Quadrics.
    pub quadrics: Vec<Quadric>,
    /// Optional stored QEM-optimal vertices; solved from the quadrics when absent.
    pub vstars: Option<Vec<[f64; 3]>>,
}

fn check_finite3(name: &str, v: &[[f64; 3]]) -> Result<()> {
    if let Some(i) = v.iter().position(|p| p.iter().any(|c| !c.is_finite())) {
        return Err(Error::InvalidInput(format!(
            "{name}[{i}] = {:?} is not finite",
            v[i]
        )));
    }
    Ok(())
}

impl Ponq {
    /// Builds a PoNQ, checking sizes and finiteness.
    pub fn new(
        points: Vec<[f64; 3]>,
        normals: Vec<[f64; 3]>,
        quadrics: Vec<Quadric>,
        vstars: Option<Vec<[f64; 3]>>,
    ) -> Result<Self> {
        let m = points.len();
        if normals.len() != m || quadrics.len() != m {
            return Err(Error::InvalidInput(format!(
                "{m} points but {} normals and {} quadrics",
                normals.len(),
                quadrics.len()
            )));
        }
        check_finite3("points", &points)?;
        check_finite3("normals", &normals)?;
        if let Some(i) = quadrics.iter().position(|q| {
            q.a.iter().any(|x| !x.is_finite())
                || q.b.iter().any(|x| !x.is_finite())
                || !q.c.is_finite()
        }) {
            return Err(Error::InvalidInput(format!("quadrics[{i}] is not finite")));
        }
        if let Some(v) = &vstars {
            if v.len() != m {
                return Err(Error::InvalidInput(format!(
                    "{m} points but {} vstars",
                    v.len()
                )));
            }
            check_finite3("vstars", v)?;
        }
        Ok(Self {
            points,
            normals,
            quadrics,
            vstars,
        })
    }

    /// Number of points.
    pub fn len(&self) -> usize {
        self.points.len()
    }

    /// True when there is no point.
    pub fn is_empty(&self) -> bool {
        self.points.is_empty()
    }

    /// The QEM-optimal vertices: the stored ones, or solved from each quadric around its point
    /// with the 0.05 relative SVD cut-off.
    pub fn vstars(&self) -> Vec<[f64; 3]> {
        match &self.vstars {
            Some(v) => v.clone(),
            None => {
                use rayon::prelude::*;
                self.quadrics
                    .par_iter()
                    .zip(&self.points)
                    .map(|(q, p)| q.optimal_point(*p, SVD_CUTOFF))
                    .collect()
            }
        }
    }
}

impl Ponq {
    /// Builds a PoNQ from oriented surface samples grouped into clusters (e.g. the Voronoi cells
    /// of fitted points, or grid cells): per non-empty cluster, the mean sample position, the
    /// mean normal and the mean of the samples' plane quadrics (SPEC section 7). Empty clusters
    /// are dropped. `cluster[i] < n_clusters` is the cluster of sample `i`. Returns the PoNQ and,
    /// for each of its points, its cluster index.
    ///
    /// # Errors
    /// [`Error::InvalidInput`] for mismatched lengths, an out-of-range cluster or NaN.
    pub fn from_clusters(
        samples: &[[f64; 3]],
        normals: &[[f64; 3]],
        cluster: &[u32],
        n_clusters: usize,
    ) -> Result<(Self, Vec<u32>)> {
        if samples.len() != normals.len() || samples.len() != cluster.len() {
            return Err(Error::InvalidInput(format!(
                "{} samples, {} normals, {} cluster ids",
                samples.len(),
                normals.len(),
                cluster.len()
            )));
        }
        let mut count = vec![0u32; n_clusters];
        let mut pos = vec![[0.0f64; 3]; n_clusters];
        let mut nor = vec![[0.0f64; 3]; n_clusters];
        let mut quad = vec![Quadric::zero(); n_clusters];
        for i in 0..samples.len() {
            let c = cluster[i] as usize;
            if c >= n_clusters {
                return Err(Error::InvalidInput(format!(
                    "sample {i} is in cluster {c} >= {n_clusters}"
                )));
            }
            count[c] += 1;
            for k in 0..3 {
                pos[c][k] += samples[i][k];
                nor[c][k] += normals[i][k];
            }
            quad[c] += Quadric::from_plane(samples[i], normals[i]);
        }
        let mut ids = Vec::new();
        let (mut p, mut n, mut q) = (Vec::new(), Vec::new(), Vec::new());
        for c in 0..n_clusters {
            if count[c] == 0 {
                continue;
            }
            let w = 1.0 / f64::from(count[c]);
            ids.push(c as u32);
            p.push(pos[c].map(|x| x * w));
            n.push(nor[c].map(|x| x * w));
            q.push(quad[c] * w);
        }
        Ok((Ponq::new(p, n, q, None)?, ids))
    }
}
