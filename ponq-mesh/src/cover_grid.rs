//! The cells of a uniform grid that a set of boxes covers, as a bitmap: an exact, conservative
//! pre-test before a [`Bvh`](crate::bvh::Bvh) query with many query boxes and few boxes in
//! the hierarchy.
//!
//! The crease flips test every face of a mesh (~200k) against the few hundred faces they
//! changed (see [`crate::validity::intersecting_face_pairs_among`]). Almost every face is far
//! from all of them, yet its query descends several levels of the hierarchy, whose top boxes
//! span the whole shape. A look at one bit of a small bitmap rejects such a face instead: on
//! the 217k-face mesh of `mesh_bench` the test took 4.4-4.5 ms without the bitmap and
//! 3.7-3.9 ms with it. Written here because no maintained crate offers a covered-cells bitmap
//! over `f64` boxes with this exactness argument.
//!
//! Exactness: the cell of a coordinate `x` on an axis is `(x - origin) * inv` clamped to the
//! grid and truncated, a monotone function of `x` (rounded subtraction, multiplication by
//! `inv >= 0`, clamp and truncation are all monotone). Each stored box marks its cells
//! widened by one cell downwards on each axis. If a query box `q` shares a point with a stored
//! box `B`, then on every axis `cell(q.min) <= cell(B.max)` (as `q.min <= B.max`) and
//! `cell(q.max) >= cell(B.min)` (as `q.max >= B.min`); when `q` spans at most two cells
//! (`cell(q.max) <= cell(q.min) + 1`, an integer test), `cell(q.min) >= cell(B.min) - 1`, so
//! the one cell of `q.min` is marked: [`CoverGrid::may_overlap`] looks at that single bit, and
//! answers true for a wider box without looking. It never answers false for a box that
//! overlaps a stored one.
//!
//! ```
//! use ponq_mesh::bvh::Aabb;
//! use ponq_mesh::cover_grid::CoverGrid;
//! let stored = [Aabb::new([0.0; 3], [0.1; 3]), Aabb::new([0.9; 3], [1.0; 3])];
//! let grid = CoverGrid::new(&stored, 1 << 12).expect("finite boxes");
//! assert!(grid.may_overlap(&Aabb::new([0.1; 3], [0.2; 3]))); // touches the first box
//! assert!(!grid.may_overlap(&Aabb::new([0.4; 3], [0.5; 3]))); // between the two
//! ```

use crate::bvh::Aabb;

/// Bits per axis of a [`CoverGrid::point_key`]'s cell.
const KEY_BITS: u32 = 19;

/// The covered cells of a grid over the union of some boxes.
///
/// Invariants: `n[k] >= 1` and `n[0] * n[1] * n[2] <= bits.len() * 64`; the bit of every cell
/// of a stored box, or one cell below one on any axes, is set (cells in the sense of the
/// [module docs](self)).
#[derive(Debug, Clone)]
pub struct CoverGrid {
    bounds: Aabb,
    inv: [f64; 3],
    n: [usize; 3],
    bits: Vec<u64>,
}

impl CoverGrid {
    /// The grid of `boxes` with at most `max_cells` cells (at least one), sized so that a cell
    /// is twice the boxes' mean extent on each axis (query boxes of about that size then span
    /// at most two cells). `None` when there is no non-empty box, when a coordinate is not
    /// finite, or when marking the boxes' cells would take more than `4 * max_cells` steps
    /// (boxes much larger than their mean): a caller then queries without the pre-test.
    pub fn new(boxes: &[Aabb], max_cells: usize) -> Option<Self> {
        let boxes: Vec<&Aabb> = boxes.iter().filter(|b| !b.is_empty()).collect();
        if boxes.is_empty() {
            return None;
        }
        let bounds = boxes.iter().fold(Aabb::EMPTY, |u, b| u.union(b));
        if !(0..3).all(|k| bounds.min[k].is_finite() && bounds.max[k].is_finite()) {
            return None;
        }
        let extent: [f64; 3] = std::array::from_fn(|k| bounds.max[k] - bounds.min[k]);
        let mean: [f64; 3] = std::array::from_fn(|k| {
            boxes.iter().map(|b| b.max[k] - b.min[k]).sum::<f64>() / boxes.len() as f64
        });
        let max_cells = max_cells.max(1);
        // Cells per axis: the extent in mean box sizes, then all axes scaled down together
        // until the grid fits in `max_cells`.
        let want: [f64; 3] = std::array::from_fn(|k| {
            if extent[k] > 0.0 {
                (extent[k] / (2.0 * mean[k]).max(extent[k] * 1e-6)).max(1.0)
            } else {
                1.0
            }
        });
        let total = want[0] * want[1] * want[2];
        let shrink = if total > max_cells as f64 {
            (max_cells as f64 / total).cbrt()
        } else {
            1.0
        };
        let mut n = want.map(|w| ((w * shrink).floor() as usize).max(1));
        while n[0] * n[1] * n[2] > max_cells {
            let k = (0..3).max_by_key(|&k| n[k]).unwrap_or(0);
            n[k] = (n[k] / 2).max(1);
        }
        let inv: [f64; 3] = std::array::from_fn(|k| {
            if extent[k] > 0.0 {
                n[k] as f64 / extent[k]
            } else {
                0.0
            }
        });
        let cells = n[0] * n[1] * n[2];
        let mut grid = Self {
            bounds,
            inv,
            n,
            bits: vec![0u64; cells.div_ceil(64)],
        };
        let mut steps = 0usize;
        for b in boxes {
            let (mut lo, hi) = grid.range(b);
            lo = lo.map(|c| c.saturating_sub(1));
            steps += (hi[0] - lo[0] + 1) * (hi[1] - lo[1] + 1) * (hi[2] - lo[2] + 1);
            if steps > 4 * max_cells {
                return None;
            }
            for z in lo[2]..=hi[2] {
                for y in lo[1]..=hi[1] {
                    for x in lo[0]..=hi[0] {
                        let c = grid.index([x, y, z]);
                        grid.bits[c / 64] |= 1 << (c % 64);
                    }
                }
            }
        }
        Some(grid)
    }

    /// False only when `b` overlaps no stored box (closed boxes, as [`Aabb::overlaps`]); true
    /// without a look at the bitmap for a box that spans more than two cells on an axis.
    #[inline]
    pub fn may_overlap(&self, b: &Aabb) -> bool {
        if !self.bounds.overlaps(b) {
            return false;
        }
        let (lo, hi) = self.range(b);
        if (0..3).any(|k| hi[k] > lo[k] + 1) {
            return true;
        }
        let c = self.index(lo);
        self.bits[c / 64] & (1 << (c % 64)) != 0
    }

    /// Whether [`CoverGrid::point_key`] can hold this grid's cells (at most `2^19` per axis;
    /// a grid of `2^20` cells has more only when it is flat).
    pub fn has_point_keys(&self) -> bool {
        self.n.iter().all(|&n| n <= 1 << KEY_BITS)
    }

    /// What [`CoverGrid::may_overlap_points`] needs of a finite point `p`, packed in 64 bits:
    /// its cell on each axis and on which sides of the grid's bounds it lies. Only meaningful
    /// when [`CoverGrid::has_point_keys`].
    ///
    /// A mesh's faces share vertices: the keys of the vertices, once, then three per face,
    /// read 8 bytes per vertex where the face's box reads 24 (on the 217k-face mesh of
    /// `mesh_bench` the vertices' keys fit in the second-level cache, their positions do not).
    #[inline]
    pub fn point_key(&self, p: [f64; 3]) -> u64 {
        let mut key = 0u64;
        for (k, &x) in p.iter().enumerate() {
            let cell = self.cell(k, x) as u64;
            let sides = (x <= self.bounds.max[k]) as u64 | ((x >= self.bounds.min[k]) as u64) << 1;
            key |= cell << (KEY_BITS * k as u32) | sides << (3 * KEY_BITS + 2 * k as u32);
        }
        key
    }

    /// [`CoverGrid::may_overlap`] of the box of three finite points, from their
    /// [`CoverGrid::point_key`]s: the same answer. The box reaches the bounds on an axis when
    /// one point is at most the upper bound and one at least the lower; its first and last
    /// cells are the smallest and largest of the points' (`cell` is monotone).
    #[inline]
    pub fn may_overlap_points(&self, keys: [u64; 3]) -> bool {
        let sides = (keys[0] | keys[1] | keys[2]) >> (3 * KEY_BITS);
        if sides != 0b11_1111 {
            return false;
        }
        let mask = (1u64 << KEY_BITS) - 1;
        let cells = |k: usize| keys.map(|key| ((key >> (KEY_BITS * k as u32)) & mask) as usize);
        let (mut lo, mut hi) = ([0usize; 3], [0usize; 3]);
        for k in 0..3 {
            let c = cells(k);
            lo[k] = c[0].min(c[1]).min(c[2]);
            hi[k] = c[0].max(c[1]).max(c[2]);
        }
        if (0..3).any(|k| hi[k] > lo[k] + 1) {
            return true;
        }
        let c = self.index(lo);
        self.bits[c / 64] & (1 << (c % 64)) != 0
    }

    /// The cell of coordinate `x` on axis `k`: monotone in `x`, clamped to the grid.
    #[inline]
    fn cell(&self, k: usize, x: f64) -> usize {
        // Clamped first, then truncated: on [0, n - 1] truncation is the floor, without a
        // call to `floor` (a libm call on baseline x86-64, which has no SSE4.1 rounding; the
        // pre-test of 217k faces, in a first version, took 2.9 ms with it, 2.5 without). NaN
        // (not reached: callers test the box against `bounds` first) goes to 0.
        ((x - self.bounds.min[k]) * self.inv[k]).clamp(0.0, (self.n[k] - 1) as f64) as usize
    }

    /// The first and last cells of box `b` on each axis.
    #[inline]
    fn range(&self, b: &Aabb) -> ([usize; 3], [usize; 3]) {
        (
            std::array::from_fn(|k| self.cell(k, b.min[k])),
            std::array::from_fn(|k| self.cell(k, b.max[k])),
        )
    }

    #[inline]
    fn index(&self, [x, y, z]: [usize; 3]) -> usize {
        (z * self.n[1] + y) * self.n[0] + x
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    fn boxes_from(v: &[([f64; 3], [f64; 3])]) -> Vec<Aabb> {
        v.iter()
            .map(|&(c, s)| Aabb::new(c, std::array::from_fn(|k| c[k] + s[k])))
            .collect()
    }

    /// Coordinates from a small lattice (exact ties between box faces are common) or random.
    fn coord() -> impl Strategy<Value = f64> {
        prop_oneof![(-4i32..=4).prop_map(|i| f64::from(i) * 0.25), -1.0f64..1.0]
    }

    fn size() -> impl Strategy<Value = f64> {
        prop_oneof![
            Just(0.0),
            (0i32..=4).prop_map(|i| f64::from(i) * 0.25),
            0.0f64..0.5
        ]
    }

    proptest! {
        /// Never a false "no": every query box that overlaps a stored box is let through,
        /// whatever the grid size (touching boxes and zero-size boxes included).
        #[test]
        fn never_rejects_an_overlapping_box(
            stored in prop::collection::vec(([coord(), coord(), coord()], [size(), size(), size()]), 1..12),
            queries in prop::collection::vec(([coord(), coord(), coord()], [size(), size(), size()]), 1..24),
            max_cells in 1usize..5000,
        ) {
            let stored = boxes_from(&stored);
            let queries = boxes_from(&queries);
            if let Some(grid) = CoverGrid::new(&stored, max_cells) {
                prop_assert!(grid.n.iter().product::<usize>() <= max_cells);
                for q in &queries {
                    if stored.iter().any(|s| s.overlaps(q)) {
                        prop_assert!(grid.may_overlap(q), "{q:?} overlaps one of {stored:?}");
                    }
                }
            }
        }
    }

    proptest! {
        /// The three points' keys give the answer of their box, whatever the grid.
        #[test]
        fn point_keys_answer_like_the_points_box(
            stored in prop::collection::vec(([coord(), coord(), coord()], [size(), size(), size()]), 1..12),
            triangles in prop::collection::vec([[coord(), coord(), coord()], [coord(), coord(), coord()], [coord(), coord(), coord()]], 1..24),
            max_cells in 1usize..5000,
        ) {
            let stored = boxes_from(&stored);
            if let Some(grid) = CoverGrid::new(&stored, max_cells) {
                prop_assert!(grid.has_point_keys());
                for t in &triangles {
                    let by_keys = grid.may_overlap_points(t.map(|p| grid.point_key(p)));
                    prop_assert_eq!(by_keys, grid.may_overlap(&Aabb::from_points(t)), "{:?}", t);
                }
            }
        }
    }

    #[test]
    fn rejects_far_boxes_and_declines_what_it_cannot_grid() {
        // Two small boxes in opposite corners of the unit cube, a fine grid: the centre and
        // the other corners are rejected, the corners' neighbourhoods are not.
        let stored = boxes_from(&[([0.0; 3], [0.01; 3]), ([0.99; 3], [0.01; 3])]);
        let grid = CoverGrid::new(&stored, 1 << 15).expect("finite");
        assert!(grid.n.iter().all(|&n| n > 8), "{:?}", grid.n);
        let q = |c: [f64; 3]| Aabb::new(c, c.map(|x| x + 0.01));
        assert!(!grid.may_overlap(&q([0.5; 3])));
        assert!(!grid.may_overlap(&q([0.99, 0.0, 0.0])));
        assert!(!grid.may_overlap(&q([2.0; 3]))); // outside the bounds
        assert!(grid.may_overlap(&q([0.01; 3])));
        assert!(grid.may_overlap(&q([0.98; 3])));
        assert!(!grid.may_overlap(&Aabb::EMPTY));
        assert!(!grid.may_overlap(&Aabb::new([f64::NAN; 3], [f64::NAN; 3])));
        // Nothing to grid, or coordinates that are not finite.
        assert!(CoverGrid::new(&[], 100).is_none());
        assert!(CoverGrid::new(&[Aabb::EMPTY], 100).is_none());
        let inf = Aabb::new([0.0; 3], [f64::INFINITY, 1.0, 1.0]);
        assert!(CoverGrid::new(&[inf], 100).is_none());
        // Ten huge boxes among many tiny ones (the grid follows the tiny ones): marking the
        // huge ones would exceed the budget.
        let mut many = boxes_from(&[([0.0; 3], [1.0; 3]); 10]);
        many.extend((0..1000).map(|i| {
            let x = f64::from(i) * 1e-3;
            Aabb::new([x; 3], [x + 1e-6; 3])
        }));
        assert!(CoverGrid::new(&many, 1 << 12).is_none());
        // A single point: one cell.
        let p = CoverGrid::new(&[Aabb::from_point([1.0, 2.0, 3.0])], 100).expect("finite");
        assert_eq!(p.n, [1, 1, 1]);
        assert!(p.may_overlap(&Aabb::new([0.0; 3], [5.0; 3])));
        assert!(!p.may_overlap(&Aabb::new([0.0; 3], [0.5; 3])));
    }
}
