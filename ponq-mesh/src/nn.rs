//! Nearest-neighbour queries on point clouds (a thin wrapper over `kiddo`'s immutable k-d tree).

use kiddo::{ImmutableKdTree, SquaredEuclidean};

/// A static point cloud answering exact nearest-neighbour queries.
///
/// Invariant: holds at least one point (construction of an empty index returns `None`).
pub struct PointIndex {
    tree: ImmutableKdTree<f64, 3>,
}

impl PointIndex {
    /// Builds the index; `None` for an empty slice or a slice kiddo rejects.
    pub fn new(points: &[[f64; 3]]) -> Option<Self> {
        if points.is_empty() {
            return None;
        }
        ImmutableKdTree::new_from_slice(points)
            .ok()
            .map(|tree| Self { tree })
    }

    /// `(index, squared distance)` of the point nearest to `q`.
    #[inline]
    pub fn nearest(&self, q: &[f64; 3]) -> (u32, f64) {
        let r = self
            .tree
            .query(q)
            .nearest_one::<SquaredEuclidean<f64>>()
            .execute();
        (r.item, r.distance)
    }

    /// `(index, squared distance)` of the `k` points nearest to `q` (all of them when there
    /// are fewer), nearest first.
    pub fn nearest_k(&self, q: &[f64; 3], k: usize) -> Vec<(u32, f64)> {
        let Some(k) = std::num::NonZeroUsize::new(k) else {
            return Vec::new();
        };
        let mut v: Vec<(u32, f64)> = self
            .tree
            .query(q)
            .nearest_n::<SquaredEuclidean<f64>>(k)
            .execute()
            .into_iter()
            .map(|r| (r.item, r.distance))
            .collect();
        v.sort_by(|a, b| a.1.total_cmp(&b.1).then(a.0.cmp(&b.0)));
        v
    }

    /// `(index, squared distance)` of at most `k` points nearest to `q` among those within
    /// squared distance `r2`, nearest first (a bounded search: cheaper than
    /// [`PointIndex::nearest_k`] when few points are that close).
    pub fn nearest_k_within(&self, q: &[f64; 3], k: usize, r2: f64) -> Vec<(u32, f64)> {
        let Some(k) = std::num::NonZeroUsize::new(k) else {
            return Vec::new();
        };
        let mut v: Vec<(u32, f64)> = self
            .tree
            .query(q)
            .nearest_n::<SquaredEuclidean<f64>>(k)
            .within(r2)
            .execute()
            .into_iter()
            .map(|r| (r.item, r.distance))
            .filter(|r| r.1 <= r2)
            .collect();
        v.sort_by(|a, b| a.1.total_cmp(&b.1).then(a.0.cmp(&b.0)));
        v
    }

    /// Nearest points of many queries, in parallel: `(index, squared distance)` per query.
    pub fn nearest_many(&self, queries: &[[f64; 3]]) -> Vec<(u32, f64)> {
        use rayon::prelude::*;
        queries.par_iter().map(|q| self.nearest(q)).collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn matches_brute_force() {
        let pts: Vec<[f64; 3]> = (0..500)
            .map(|i| {
                let t = i as f64 * 0.37;
                [t.sin(), (1.3 * t).cos(), (0.7 * t).sin() * t.cos()]
            })
            .collect();
        let idx = PointIndex::new(&pts).expect("non-empty");
        for j in 0..100 {
            let q = [(j as f64 * 0.11).cos(), (j as f64 * 0.23).sin(), 0.3];
            let (i, d) = idx.nearest(&q);
            let k = idx.nearest_k(&q, 5);
            assert_eq!(k.len(), 5);
            assert_eq!(k[0].1, d);
            assert!(k.windows(2).all(|w| w[0].1 <= w[1].1));
            let mut all: Vec<f64> = pts
                .iter()
                .map(|p| (p[0] - q[0]).powi(2) + (p[1] - q[1]).powi(2) + (p[2] - q[2]).powi(2))
                .collect();
            all.sort_by(f64::total_cmp);
            for (j, (_, dk)) in k.iter().enumerate() {
                assert!((dk - all[j]).abs() < 1e-12);
            }
            let r2 = all[3] * 1.0000001;
            let w = idx.nearest_k_within(&q, 8, r2);
            assert_eq!(w.len(), all.iter().filter(|&&d| d <= r2).count().min(8));
            for (j, (_, dk)) in w.iter().enumerate() {
                assert!((dk - all[j]).abs() < 1e-12);
            }
            let best = pts
                .iter()
                .map(|p| (p[0] - q[0]).powi(2) + (p[1] - q[1]).powi(2) + (p[2] - q[2]).powi(2))
                .fold(f64::MAX, f64::min);
            assert!((d - best).abs() < 1e-12, "{d} vs {best}");
            let p = pts[i as usize];
            let di = (p[0] - q[0]).powi(2) + (p[1] - q[1]).powi(2) + (p[2] - q[2]).powi(2);
            assert!((di - d).abs() < 1e-12);
        }
        assert!(PointIndex::new(&[]).is_none());
    }
}
