//! Axis-aligned bounding-box hierarchy (BVH) over arbitrary items (typically triangles).
//!
//! [`Bvh::build`] takes one [`Aabb`] per item and builds a binary tree with a binned
//! surface-area heuristic (falling back to median splits), stored as a flat node array in
//! depth-first order; [`Bvh::build_morton`] builds the same kind of tree faster from a Morton
//! (Z-order) sort of the box centres, for one-shot queries over many similar boxes (the
//! validity check's face pairs). The tree answers:
//!
//! * box queries: [`Bvh::query_overlaps`];
//! * self-overlap queries: [`Bvh::overlapping_pairs`], [`Bvh::for_each_overlapping_pair`] and
//!   the parallel [`Bvh::par_fold_overlapping_pairs`] (simultaneous descent of the tree against
//!   itself, every pair reported once);
//! * closest-item queries: [`Bvh::nearest`] (best-first branch and bound with a user supplied
//!   exact per-item squared distance).
//!
//! All box tests are exact comparisons on the `f64` coordinates (closed boxes, no epsilon), so
//! a box query never misses an item whose box touches the query box.

use std::cmp::Ordering;
use std::collections::BinaryHeap;

/// An axis-aligned box `[min, max]` (closed).
///
/// A box is *empty* when `min[k] > max[k]` on some axis (see [`Aabb::EMPTY`]); an empty box
/// overlaps nothing and contains nothing. A single point is a valid (non-empty) box with
/// `min == max`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Aabb {
    /// Lower corner.
    pub min: [f64; 3],
    /// Upper corner.
    pub max: [f64; 3],
}

impl Default for Aabb {
    fn default() -> Self {
        Self::EMPTY
    }
}

impl Aabb {
    /// The empty box (`min = +inf`, `max = -inf`), neutral element of [`Aabb::union`].
    pub const EMPTY: Aabb = Aabb {
        min: [f64::INFINITY; 3],
        max: [f64::NEG_INFINITY; 3],
    };

    /// A box from its corners (not checked: `min > max` on an axis gives an empty box).
    pub fn new(min: [f64; 3], max: [f64; 3]) -> Self {
        Self { min, max }
    }

    /// The degenerate box holding the single point `p`.
    pub fn from_point(p: [f64; 3]) -> Self {
        Self { min: p, max: p }
    }

    /// The smallest box containing all `points`; [`Aabb::EMPTY`] when there is none.
    pub fn from_points(points: &[[f64; 3]]) -> Self {
        let mut b = Self::EMPTY;
        for &p in points {
            b.grow(p);
        }
        b
    }

    /// True when the box contains no point (`min[k] > max[k]`, or NaN, on some axis).
    pub fn is_empty(&self) -> bool {
        (0..3).any(|k| self.min[k] > self.max[k] || self.min[k].is_nan() || self.max[k].is_nan())
    }

    /// Enlarges the box to contain `p`.
    pub fn grow(&mut self, p: [f64; 3]) {
        for (k, &x) in p.iter().enumerate() {
            self.min[k] = self.min[k].min(x);
            self.max[k] = self.max[k].max(x);
        }
    }

    /// The smallest box containing both boxes.
    pub fn union(&self, other: &Aabb) -> Aabb {
        let mut r = *self;
        for k in 0..3 {
            r.min[k] = r.min[k].min(other.min[k]);
            r.max[k] = r.max[k].max(other.max[k]);
        }
        r
    }

    /// True when the two closed boxes share at least one point (touching counts).
    /// Exact: only comparisons of the stored coordinates.
    #[inline]
    pub fn overlaps(&self, other: &Aabb) -> bool {
        self.min[0] <= other.max[0]
            && other.min[0] <= self.max[0]
            && self.min[1] <= other.max[1]
            && other.min[1] <= self.max[1]
            && self.min[2] <= other.max[2]
            && other.min[2] <= self.max[2]
    }

    /// True when the closed box contains `p`.
    pub fn contains_point(&self, p: [f64; 3]) -> bool {
        (0..3).all(|k| self.min[k] <= p[k] && p[k] <= self.max[k])
    }

    /// The centre of the box.
    pub fn center(&self) -> [f64; 3] {
        [
            0.5 * (self.min[0] + self.max[0]),
            0.5 * (self.min[1] + self.max[1]),
            0.5 * (self.min[2] + self.max[2]),
        ]
    }

    /// Surface area of the box; `0` for an empty box.
    pub fn surface_area(&self) -> f64 {
        if self.is_empty() {
            return 0.0;
        }
        let d = [
            self.max[0] - self.min[0],
            self.max[1] - self.min[1],
            self.max[2] - self.min[2],
        ];
        2.0 * (d[0] * d[1] + d[1] * d[2] + d[2] * d[0])
    }

    /// Squared Euclidean distance from `p` to the closed box (`0` inside, `+inf` for an empty
    /// box). Computed in floating point; a lower bound of the distance to anything inside the
    /// box up to rounding.
    #[inline]
    pub fn distance_sq_to_point(&self, p: [f64; 3]) -> f64 {
        let mut d2 = 0.0;
        for ((&lo, &hi), &x) in self.min.iter().zip(&self.max).zip(&p) {
            let d = (lo - x).max(x - hi).max(0.0);
            d2 += d * d;
        }
        d2
    }
}

/// Marker of a leaf in [`Node::right`].
const LEAF: u32 = u32::MAX;
/// Number of bins of the binned SAH.
const BINS: usize = 16;
/// Below this depth SAH splits are used; deeper, median splits guarantee `O(log n)` depth.
const MAX_SAH_DEPTH: usize = 40;
/// Nodes with at most this many items are split at the median (binning does not pay off).
const SAH_MIN: usize = 16;
/// Subtrees with more items than this are built in parallel.
const PAR_BUILD_MIN: usize = 16 * 1024;
/// Pair traversals of subtrees with fewer items than this run sequentially.
const PAR_PAIRS_MIN: usize = 2048;
/// Default maximal number of items per leaf.
pub const DEFAULT_LEAF_SIZE: usize = 4;

/// A node of the flat tree.
///
/// Invariants: nodes are stored in depth-first pre-order, so the left child of an inner node
/// `n` is `n + 1` and its right child is `right`; every node covers the contiguous range
/// `start..end` of [`Bvh::items`]; `aabb` is the union of the boxes of those items.
#[derive(Debug, Clone, Copy)]
struct Node {
    aabb: Aabb,
    start: u32,
    end: u32,
    /// Right child, or [`LEAF`].
    right: u32,
}

impl Node {
    #[inline]
    fn is_leaf(&self) -> bool {
        self.right == LEAF
    }
    #[inline]
    fn len(&self) -> usize {
        (self.end - self.start) as usize
    }
}

/// A bounding-volume hierarchy over a fixed set of boxes (one per item, items numbered by
/// their position in the slice given to [`Bvh::build`]).
///
/// Invariants:
/// * the tree is binary, every inner node has exactly two non-empty children;
/// * a leaf holds at most the leaf size (default [`DEFAULT_LEAF_SIZE`]) items, except that
///   no limit is needed for correctness;
/// * the box of a node contains the boxes of all items below it;
/// * the depth is `O(log n)` (SAH splits for the first levels, then median splits);
/// * the tree is immutable; build cost is `O(n log n)` and it is `Send + Sync`.
#[derive(Debug, Clone, Default)]
pub struct Bvh {
    nodes: Vec<Node>,
    /// Item indices in leaf order.
    items: Vec<u32>,
    /// `boxes[k]` is the box of item `items[k]` (leaf order, for locality).
    boxes: Vec<Aabb>,
}

/// Context shared by the recursive build.
struct BuildCtx {
    leaf_size: usize,
}

/// An item during the build; the work array is permuted in place so that every pass reads
/// memory sequentially. Centroids are used doubled (`min + max`) throughout the build.
#[derive(Clone, Copy)]
struct Work {
    b: Aabb,
    id: u32,
}

impl Work {
    #[inline(always)]
    fn centroid2(&self) -> [f64; 3] {
        [
            self.b.min[0] + self.b.max[0],
            self.b.min[1] + self.b.max[1],
            self.b.min[2] + self.b.max[2],
        ]
    }
}

impl Bvh {
    /// Builds the hierarchy over `boxes` (item `i` has box `boxes[i]`) with leaves of at most
    /// [`DEFAULT_LEAF_SIZE`] items.
    ///
    /// Panics if there are more than `u32::MAX - 1` boxes.
    pub fn build(boxes: &[Aabb]) -> Self {
        Self::build_with_leaf_size(boxes, DEFAULT_LEAF_SIZE)
    }

    /// Like [`Bvh::build`] with leaves of at most `leaf_size` (at least 1) items.
    pub fn build_with_leaf_size(boxes: &[Aabb], leaf_size: usize) -> Self {
        assert!(
            boxes.len() < u32::MAX as usize,
            "Bvh supports fewer than 2^32 - 1 items"
        );
        if boxes.is_empty() {
            return Self::default();
        }
        let mut work: Vec<Work> = boxes
            .iter()
            .enumerate()
            .map(|(i, &b)| Work { b, id: i as u32 })
            .collect();
        let ctx = BuildCtx {
            leaf_size: leaf_size.max(1),
        };
        let mut nodes = Vec::with_capacity(2 * boxes.len() / ctx.leaf_size + 2);
        let bounds = Bounds::of(&work);
        build_rec(&ctx, &mut nodes, &mut work, 0, 0, bounds);
        Self {
            nodes,
            items: work.iter().map(|w| w.id).collect(),
            boxes: work.iter().map(|w| w.b).collect(),
        }
    }

    /// Builds the hierarchy from the boxes sorted along a Morton (Z-order) curve of their
    /// centres (21 bits per axis), each range split where its codes first differ (a plane of
    /// the implicit octree; at the middle when all codes are equal): a parallel sort and one
    /// pass of box unions instead of binning at every level, so it builds about twice as fast
    /// as [`Bvh::build`] (the 217k faces of a mesh: about 20 vs 42 ms on two cores here) for
    /// trees a little looser. Meant for one-shot queries over many small boxes of similar size, such as all
    /// face pairs of a mesh, where the build dominates. Same invariants as [`Bvh::build`]
    /// (leaves of at most [`DEFAULT_LEAF_SIZE`] items; depth at most 63 octree-plane splits
    /// plus `log2(n)` for equal codes), same answers to every query.
    ///
    /// Panics if there are more than `u32::MAX - 1` boxes.
    pub fn build_morton(boxes: &[Aabb]) -> Self {
        use rayon::prelude::*;
        assert!(
            boxes.len() < u32::MAX as usize,
            "Bvh supports fewer than 2^32 - 1 items"
        );
        if boxes.is_empty() {
            return Self::default();
        }
        let centre = |b: &Aabb| std::array::from_fn::<f64, 3, _>(|k| b.min[k] + b.max[k]);
        // Bounds of the (finite) centres; the codes use 21 bits per axis.
        let (lo, hi) = boxes
            .par_iter()
            .map(|b| {
                let c = centre(b);
                if c.iter().all(|x| x.is_finite()) {
                    (c, c)
                } else {
                    ([f64::INFINITY; 3], [f64::NEG_INFINITY; 3])
                }
            })
            .reduce(
                || ([f64::INFINITY; 3], [f64::NEG_INFINITY; 3]),
                |a, b| {
                    (
                        std::array::from_fn(|k| a.0[k].min(b.0[k])),
                        std::array::from_fn(|k| a.1[k].max(b.1[k])),
                    )
                },
            );
        let scale: [f64; 3] = std::array::from_fn(|k| {
            let e = hi[k] - lo[k];
            if e > 0.0 && e.is_finite() {
                ((1u32 << 21) - 1) as f64 / e
            } else {
                0.0
            }
        });
        // Spreads the 21 low bits of x to every third bit.
        fn spread(x: u64) -> u64 {
            let mut x = x & 0x1f_ffff;
            x = (x | x << 32) & 0x1f_0000_0000_ffff;
            x = (x | x << 16) & 0x1f_0000_ff00_00ff;
            x = (x | x << 8) & 0x100f_00f0_0f00_f00f;
            x = (x | x << 4) & 0x10c3_0c30_c30c_30c3;
            (x | x << 2) & 0x1249_2492_4924_9249
        }
        let mut keyed: Vec<(u64, u32)> = boxes
            .par_iter()
            .enumerate()
            .map(|(i, b)| {
                let c = centre(b);
                // Saturating casts: non-finite centres go to an end of the curve.
                let q = |k: usize| (((c[k] - lo[k]) * scale[k]) as u64).min((1 << 21) - 1);
                (
                    spread(q(0)) << 2 | spread(q(1)) << 1 | spread(q(2)),
                    i as u32,
                )
            })
            .collect();
        keyed.par_sort_unstable();
        let items: Vec<u32> = keyed.iter().map(|&(_, i)| i).collect();
        let codes: Vec<u64> = keyed.iter().map(|&(c, _)| c).collect();
        drop(keyed);
        let sorted: Vec<Aabb> = items.par_iter().map(|&i| boxes[i as usize]).collect();
        let mut nodes = Vec::with_capacity(2 * boxes.len() / DEFAULT_LEAF_SIZE + 2);
        morton_rec(&mut nodes, &sorted, &codes, 0);
        Self {
            nodes,
            items,
            boxes: sorted,
        }
    }

    /// The items in leaf order: position `k` of [`Bvh::par_fold_overlapping_leaf_pairs`] is
    /// item `items()[k]`. Items of one leaf, and of nearby leaves, are near in space.
    pub fn items(&self) -> &[u32] {
        &self.items
    }

    /// Number of items.
    pub fn len(&self) -> usize {
        self.items.len()
    }

    /// True when built over no item.
    pub fn is_empty(&self) -> bool {
        self.items.is_empty()
    }

    /// Number of nodes of the tree.
    pub fn node_count(&self) -> usize {
        self.nodes.len()
    }

    /// Box of all items; `None` for an empty hierarchy.
    pub fn bounds(&self) -> Option<Aabb> {
        self.nodes.first().map(|n| n.aabb)
    }

    /// Depth of the tree (a single leaf has depth 1, an empty tree 0).
    pub fn depth(&self) -> usize {
        fn rec(t: &Bvh, n: usize) -> usize {
            let node = &t.nodes[n];
            if node.is_leaf() {
                1
            } else {
                1 + rec(t, n + 1).max(rec(t, node.right as usize))
            }
        }
        if self.nodes.is_empty() {
            0
        } else {
            rec(self, 0)
        }
    }

    /// Calls `f(i)` for every item `i` whose box overlaps the closed box `b` (touching counts),
    /// each once, in no particular order.
    pub fn query_overlaps(&self, b: &Aabb, f: impl FnMut(usize)) {
        // The nodes to visit: on the call stack up to 64 of them (the depth of any reasonable
        // tree), on the heap beyond. A `Vec` per query cost a heap allocation per call: most
        // of the time of the crease flips' intersection test, which queries the tree once per
        // face of the mesh.
        self.query_overlaps_inline::<64>(b, f);
    }

    /// [`Bvh::query_overlaps`] with room for `INLINE` nodes to visit on the call stack
    /// (`INLINE >= 1`; the tests take a small one to reach the heap part).
    fn query_overlaps_inline<const INLINE: usize>(&self, b: &Aabb, mut f: impl FnMut(usize)) {
        if self.nodes.is_empty() {
            return;
        }
        let mut inline = [0u32; INLINE];
        let mut len = 1usize;
        let mut spill: Vec<u32> = Vec::new();
        loop {
            let n = if let Some(n) = spill.pop() {
                n
            } else if len > 0 {
                len -= 1;
                inline[len]
            } else {
                break;
            };
            let node = &self.nodes[n as usize];
            if !node.aabb.overlaps(b) {
                continue;
            }
            if node.is_leaf() {
                for k in node.start as usize..node.end as usize {
                    if self.boxes[k].overlaps(b) {
                        f(self.items[k] as usize);
                    }
                }
            } else {
                // Nothing spills while the inline part has room (it is emptied only after
                // the spilled nodes), so this keeps one stack, last in first out.
                for c in [node.right, n + 1] {
                    if len < INLINE {
                        inline[len] = c;
                        len += 1;
                    } else {
                        spill.push(c);
                    }
                }
            }
        }
    }

    /// All pairs `(i, j)` with `i < j` whose boxes overlap (touching counts), each once.
    ///
    /// Computed in parallel with rayon; the order of the pairs is unspecified but deterministic
    /// for a given tree.
    pub fn overlapping_pairs(&self) -> Vec<(usize, usize)> {
        self.par_fold_overlapping_pairs(
            Vec::new,
            |v: &mut Vec<(usize, usize)>, i, j| v.push((i, j)),
            |mut a, mut b| {
                a.append(&mut b);
                a
            },
        )
    }

    /// Calls `f(i, j)` (sequentially) for every pair `i < j` of items whose boxes overlap,
    /// each pair once.
    pub fn for_each_overlapping_pair(&self, mut f: impl FnMut(usize, usize)) {
        if !self.nodes.is_empty() {
            self.self_seq(0, &mut |a, b| {
                f(self.items[a] as usize, self.items[b] as usize)
            });
        }
    }

    /// Parallel fold over all pairs `i < j` of items whose boxes overlap (each pair once):
    /// each rayon task starts from `init()`, folds pairs with `visit(&mut acc, i, j)`, and
    /// partial results are combined with `reduce(left, right)` (always in tree order, so an
    /// order-sensitive `reduce` gives a deterministic result).
    pub fn par_fold_overlapping_pairs<A, I, V, R>(&self, init: I, visit: V, reduce: R) -> A
    where
        A: Send,
        I: Fn() -> A + Sync,
        V: Fn(&mut A, usize, usize) + Sync,
        R: Fn(A, A) -> A + Sync,
    {
        let items = &self.items;
        self.par_fold_overlapping_leaf_pairs(
            init,
            |acc, a, b| {
                let (i, j) = (items[a] as usize, items[b] as usize);
                visit(acc, i.min(j), i.max(j))
            },
            reduce,
        )
    }

    /// [`Bvh::par_fold_overlapping_pairs`] by leaf-order positions: `visit(&mut acc, a, b)`
    /// with `a < b` for the items `items()[a]` and `items()[b]`, so that a caller can keep
    /// the items' data in leaf order ([`Bvh::items`]) and read nearby memory for nearby pairs.
    pub fn par_fold_overlapping_leaf_pairs<A, I, V, R>(&self, init: I, visit: V, reduce: R) -> A
    where
        A: Send,
        I: Fn() -> A + Sync,
        V: Fn(&mut A, usize, usize) + Sync,
        R: Fn(A, A) -> A + Sync,
    {
        if self.nodes.is_empty() {
            return init();
        }
        let ctx = PairCtx {
            init: &init,
            visit: &visit,
            reduce: &reduce,
        };
        self.self_par(0, &ctx)
    }

    /// The item closest to `p`: returns `(i, dist_sq(i))` for an item minimising
    /// `dist_sq(i)`, or `None` when there is no item or no finite distance.
    ///
    /// `dist_sq(i)` must be the squared distance from `p` to item `i`, and the item must lie
    /// inside its box, so that the box distance is a lower bound used for pruning
    /// (branch-and-bound, nodes visited best-first). The result is exact whenever
    /// `dist_sq(i) >= (1 - 1e-12) * box(i).distance_sq_to_point(p)` for every item, which
    /// holds for any reasonably accurate distance computation. NaN distances are ignored.
    /// Ties are broken arbitrarily.
    pub fn nearest(
        &self,
        p: [f64; 3],
        mut dist_sq: impl FnMut(usize) -> f64,
    ) -> Option<(usize, f64)> {
        if self.nodes.is_empty() {
            return None;
        }
        // Slack so that rounding in the box distance never prunes a true minimum.
        const SLACK: f64 = 1.0 - 1e-12;
        let mut best: Option<(usize, f64)> = None;
        let mut best_d = f64::INFINITY;
        let mut heap = BinaryHeap::new();
        heap.push(HeapEntry {
            d: self.nodes[0].aabb.distance_sq_to_point(p) * SLACK,
            node: 0,
        });
        while let Some(HeapEntry { d, node }) = heap.pop() {
            if d >= best_d || d.is_nan() {
                break;
            }
            let n = &self.nodes[node as usize];
            if n.is_leaf() {
                for k in n.start as usize..n.end as usize {
                    let lb = self.boxes[k].distance_sq_to_point(p) * SLACK;
                    if lb >= best_d || lb.is_nan() {
                        continue;
                    }
                    let item = self.items[k] as usize;
                    let di = dist_sq(item);
                    if di < best_d {
                        best_d = di;
                        best = Some((item, di));
                    }
                }
            } else {
                for c in [node + 1, n.right] {
                    let dc = self.nodes[c as usize].aabb.distance_sq_to_point(p) * SLACK;
                    if dc < best_d {
                        heap.push(HeapEntry { d: dc, node: c });
                    }
                }
            }
        }
        best
    }

    // ----- pair traversal internals -----

    fn leaf_self_pairs(&self, n: &Node, f: &mut impl FnMut(usize, usize)) {
        let (s, e) = (n.start as usize, n.end as usize);
        for a in s..e {
            for b in a + 1..e {
                if self.boxes[a].overlaps(&self.boxes[b]) {
                    f(a, b);
                }
            }
        }
    }

    // The pair traversals below report leaf-order positions (see `Bvh::items`).
    fn leaf_cross_pairs(&self, na: &Node, nb: &Node, f: &mut impl FnMut(usize, usize)) {
        for a in na.start as usize..na.end as usize {
            let ba = &self.boxes[a];
            if !ba.overlaps(&nb.aabb) {
                continue;
            }
            for b in nb.start as usize..nb.end as usize {
                if ba.overlaps(&self.boxes[b]) {
                    f(a, b);
                }
            }
        }
    }

    /// All overlapping pairs inside subtree `n` (sequential).
    fn self_seq(&self, n: usize, f: &mut impl FnMut(usize, usize)) {
        let node = &self.nodes[n];
        if node.is_leaf() {
            self.leaf_self_pairs(node, f);
        } else {
            let r = node.right as usize;
            self.self_seq(n + 1, f);
            self.self_seq(r, f);
            self.cross_seq(n + 1, r, f);
        }
    }

    /// All overlapping pairs between two disjoint subtrees (sequential).
    fn cross_seq(&self, a: usize, b: usize, f: &mut impl FnMut(usize, usize)) {
        let (na, nb) = (&self.nodes[a], &self.nodes[b]);
        if !na.aabb.overlaps(&nb.aabb) {
            return;
        }
        match (na.is_leaf(), nb.is_leaf()) {
            (true, true) => self.leaf_cross_pairs(na, nb, f),
            (false, true) => {
                self.cross_seq(a + 1, b, f);
                self.cross_seq(na.right as usize, b, f);
            }
            (true, false) => {
                self.cross_seq(a, b + 1, f);
                self.cross_seq(a, nb.right as usize, f);
            }
            (false, false) => {
                if na.aabb.surface_area() >= nb.aabb.surface_area() {
                    self.cross_seq(a + 1, b, f);
                    self.cross_seq(na.right as usize, b, f);
                } else {
                    self.cross_seq(a, b + 1, f);
                    self.cross_seq(a, nb.right as usize, f);
                }
            }
        }
    }

    fn self_par<A: Send, I, V, R>(&self, n: usize, ctx: &PairCtx<'_, I, V, R>) -> A
    where
        I: Fn() -> A + Sync,
        V: Fn(&mut A, usize, usize) + Sync,
        R: Fn(A, A) -> A + Sync,
    {
        let node = &self.nodes[n];
        if node.is_leaf() || node.len() < PAR_PAIRS_MIN {
            let mut acc = (ctx.init)();
            self.self_seq(n, &mut |i, j| (ctx.visit)(&mut acc, i.min(j), i.max(j)));
            return acc;
        }
        let r = node.right as usize;
        let (a, (b, c)) = rayon::join(
            || self.self_par(n + 1, ctx),
            || rayon::join(|| self.self_par(r, ctx), || self.cross_par(n + 1, r, ctx)),
        );
        (ctx.reduce)((ctx.reduce)(a, b), c)
    }

    fn cross_par<A: Send, I, V, R>(&self, a: usize, b: usize, ctx: &PairCtx<'_, I, V, R>) -> A
    where
        I: Fn() -> A + Sync,
        V: Fn(&mut A, usize, usize) + Sync,
        R: Fn(A, A) -> A + Sync,
    {
        let (na, nb) = (&self.nodes[a], &self.nodes[b]);
        if !na.aabb.overlaps(&nb.aabb) {
            return (ctx.init)();
        }
        if na.len() + nb.len() < PAR_PAIRS_MIN || (na.is_leaf() && nb.is_leaf()) {
            let mut acc = (ctx.init)();
            self.cross_seq(a, b, &mut |i, j| (ctx.visit)(&mut acc, i.min(j), i.max(j)));
            return acc;
        }
        let split_a = !na.is_leaf() && (nb.is_leaf() || na.len() >= nb.len());
        let (x, y) = if split_a {
            let r = na.right as usize;
            rayon::join(
                || self.cross_par(a + 1, b, ctx),
                || self.cross_par(r, b, ctx),
            )
        } else {
            let r = nb.right as usize;
            rayon::join(
                || self.cross_par(a, b + 1, ctx),
                || self.cross_par(a, r, ctx),
            )
        };
        (ctx.reduce)(x, y)
    }
}

/// Closures of a parallel pair fold.
struct PairCtx<'a, I, V, R> {
    init: &'a I,
    visit: &'a V,
    reduce: &'a R,
}

/// Min-heap entry of [`Bvh::nearest`] (ordered by increasing `d`).
#[derive(Debug, Clone, Copy)]
struct HeapEntry {
    d: f64,
    node: u32,
}

impl PartialEq for HeapEntry {
    fn eq(&self, other: &Self) -> bool {
        self.cmp(other) == Ordering::Equal
    }
}
impl Eq for HeapEntry {}
impl PartialOrd for HeapEntry {
    fn partial_cmp(&self, other: &Self) -> Option<Ordering> {
        Some(self.cmp(other))
    }
}
impl Ord for HeapEntry {
    fn cmp(&self, other: &Self) -> Ordering {
        // Reversed: BinaryHeap is a max-heap.
        other
            .d
            .total_cmp(&self.d)
            .then_with(|| other.node.cmp(&self.node))
    }
}

/// Branch-based `min` (a single `minsd`); NaN in `b` is ignored.
#[inline(always)]
fn fmin(a: f64, b: f64) -> f64 {
    if b < a { b } else { a }
}

/// Branch-based `max` (a single `maxsd`); NaN in `b` is ignored.
#[inline(always)]
fn fmax(a: f64, b: f64) -> f64 {
    if b > a { b } else { a }
}

#[inline(always)]
fn grow_box(acc: &mut Aabb, b: &Aabb) {
    for k in 0..3 {
        acc.min[k] = fmin(acc.min[k], b.min[k]);
        acc.max[k] = fmax(acc.max[k], b.max[k]);
    }
}

#[inline(always)]
fn grow_point(acc: &mut Aabb, p: &[f64; 3]) {
    for (k, &x) in p.iter().enumerate() {
        acc.min[k] = fmin(acc.min[k], x);
        acc.max[k] = fmax(acc.max[k], x);
    }
}

/// Bounds of the boxes and of the centroids of a set of items.
#[derive(Clone, Copy)]
struct Bounds {
    boxes: Aabb,
    centroids: Aabb,
}

impl Bounds {
    const EMPTY: Bounds = Bounds {
        boxes: Aabb::EMPTY,
        centroids: Aabb::EMPTY,
    };

    fn of(work: &[Work]) -> Bounds {
        let mut b = Bounds::EMPTY;
        for w in work {
            grow_box(&mut b.boxes, &w.b);
            grow_point(&mut b.centroids, &w.centroid2());
        }
        b
    }

    fn merge(&mut self, o: &Bounds) {
        grow_box(&mut self.boxes, &o.boxes);
        grow_box(&mut self.centroids, &o.centroids);
    }
}

/// Builds the subtree over `idx` (whose first item has global position `start`, and whose
/// bounds are `bounds`) and appends its nodes to `nodes` in pre-order; node indices are
/// relative to `nodes[0]`.
fn build_rec(
    ctx: &BuildCtx,
    nodes: &mut Vec<Node>,
    idx: &mut [Work],
    start: usize,
    depth: usize,
    bounds: Bounds,
) {
    let me = nodes.len();
    nodes.push(Node {
        aabb: bounds.boxes,
        start: start as u32,
        end: (start + idx.len()) as u32,
        right: LEAF,
    });
    if idx.len() <= ctx.leaf_size {
        return;
    }
    let (mid, lb, rb) = split(idx, depth, &bounds.centroids);
    let (l, r) = idx.split_at_mut(mid);
    if l.len().min(r.len()) >= PAR_BUILD_MIN {
        let (ln, rn) = rayon::join(
            || {
                let mut v = Vec::with_capacity(2 * l.len() / ctx.leaf_size + 2);
                build_rec(ctx, &mut v, l, start, depth + 1, lb);
                v
            },
            || {
                let mut v = Vec::with_capacity(2 * r.len() / ctx.leaf_size + 2);
                build_rec(ctx, &mut v, r, start + mid, depth + 1, rb);
                v
            },
        );
        splice_children(nodes, me, ln, rn);
    } else {
        build_rec(ctx, nodes, l, start, depth + 1, lb);
        nodes[me].right = nodes.len() as u32;
        build_rec(ctx, nodes, r, start + mid, depth + 1, rb);
    }
}

/// Appends the two subtrees of node `me`, built separately (their `right` links relative to
/// their own first node), after `nodes`, whose last node is `me`: shifts their links and
/// points `me`'s right link at the second.
fn splice_children(nodes: &mut Vec<Node>, me: usize, mut ln: Vec<Node>, mut rn: Vec<Node>) {
    let off_l = (me + 1) as u32;
    let off_r = (me + 1 + ln.len()) as u32;
    for n in ln.iter_mut().filter(|n| !n.is_leaf()) {
        n.right += off_l;
    }
    for n in rn.iter_mut().filter(|n| !n.is_leaf()) {
        n.right += off_r;
    }
    nodes[me].right = off_r;
    nodes.append(&mut ln);
    nodes.append(&mut rn);
}

/// The subtree of [`Bvh::build_morton`] over `boxes` (already in leaf order, with their sorted
/// Morton `codes`, starting at item `start`), appended to `nodes` in depth-first pre-order;
/// returns its box. A range is split where the highest bit in which its codes differ turns
/// on (a plane of the octree), or at its middle when all its codes are equal.
fn morton_rec(nodes: &mut Vec<Node>, boxes: &[Aabb], codes: &[u64], start: usize) -> Aabb {
    let me = nodes.len();
    nodes.push(Node {
        aabb: Aabb::EMPTY,
        start: start as u32,
        end: (start + boxes.len()) as u32,
        right: LEAF,
    });
    let aabb = if boxes.len() <= DEFAULT_LEAF_SIZE {
        let mut acc = Aabb::EMPTY;
        for b in boxes {
            grow_box(&mut acc, b);
        }
        acc
    } else {
        let (first, last) = (codes[0], codes[codes.len() - 1]);
        let mid = if first == last {
            boxes.len() / 2
        } else {
            let bit = 63 - (first ^ last).leading_zeros();
            codes.partition_point(|&c| c >> bit & 1 == 0)
        };
        let (l, r) = boxes.split_at(mid);
        let (cl, cr) = codes.split_at(mid);
        let (lb, rb) = if mid.min(boxes.len() - mid) >= PAR_BUILD_MIN {
            let ((ln, lb), (rn, rb)) = rayon::join(
                || {
                    let mut v = Vec::with_capacity(2 * l.len() / DEFAULT_LEAF_SIZE + 2);
                    let b = morton_rec(&mut v, l, cl, start);
                    (v, b)
                },
                || {
                    let mut v = Vec::with_capacity(2 * r.len() / DEFAULT_LEAF_SIZE + 2);
                    let b = morton_rec(&mut v, r, cr, start + mid);
                    (v, b)
                },
            );
            splice_children(nodes, me, ln, rn);
            (lb, rb)
        } else {
            let lb = morton_rec(nodes, l, cl, start);
            nodes[me].right = nodes.len() as u32;
            let rb = morton_rec(nodes, r, cr, start + mid);
            (lb, rb)
        };
        let mut acc = lb;
        grow_box(&mut acc, &rb);
        acc
    };
    nodes[me].aabb = aabb;
    aabb
}

/// Reorders `idx` (centroid bounds `cb`) and returns `(mid, left bounds, right bounds)` with
/// `0 < mid < idx.len()`: items `..mid` go left.
///
/// Binned SAH along the longest centroid axis while `depth < MAX_SAH_DEPTH` and the node has
/// more than `SAH_MIN` items; median split
/// (always balanced) otherwise or when binning cannot separate the items.
fn split(idx: &mut [Work], depth: usize, cb: &Aabb) -> (usize, Bounds, Bounds) {
    let n = idx.len();
    let ext = [
        cb.max[0] - cb.min[0],
        cb.max[1] - cb.min[1],
        cb.max[2] - cb.min[2],
    ];
    let mut axis = 0;
    for k in 1..3 {
        if ext[k] > ext[axis] {
            axis = k;
        }
    }
    if n > SAH_MIN && depth < MAX_SAH_DEPTH && ext[axis] > 0.0 && ext[axis].is_finite() {
        let lo = cb.min[axis];
        let scale = BINS as f64 / ext[axis];
        let mut counts = [0usize; BINS];
        let mut bins = [Bounds::EMPTY; BINS];
        for w in idx.iter() {
            let c = w.centroid2();
            let b = bin_of(c[axis], lo, scale);
            counts[b] += 1;
            grow_box(&mut bins[b].boxes, &w.b);
            grow_point(&mut bins[b].centroids, &c);
        }
        // Right sweep: area and count of bins `s..`.
        let mut right_area = [0.0f64; BINS];
        let mut right_count = [0usize; BINS];
        let mut acc = Aabb::EMPTY;
        let mut cnt = 0;
        for s in (1..BINS).rev() {
            grow_box(&mut acc, &bins[s].boxes);
            cnt += counts[s];
            right_area[s] = acc.surface_area();
            right_count[s] = cnt;
        }
        let mut acc = Aabb::EMPTY;
        let mut cnt = 0;
        let mut best: Option<(f64, usize)> = None;
        for s in 0..BINS - 1 {
            grow_box(&mut acc, &bins[s].boxes);
            cnt += counts[s];
            let rc = right_count[s + 1];
            if cnt == 0 || rc == 0 {
                continue;
            }
            let cost = acc.surface_area() * cnt as f64 + right_area[s + 1] * rc as f64;
            if best.is_none_or(|(bc, _)| cost < bc) {
                best = Some((cost, s));
            }
        }
        if let Some((_, split_bin)) = best {
            // In-place partition by bin.
            let goes_left = |w: &Work| bin_of(w.centroid2()[axis], lo, scale) <= split_bin;
            let mut l = 0;
            let mut r = n;
            while l < r {
                if goes_left(&idx[l]) {
                    l += 1;
                } else {
                    r -= 1;
                    idx.swap(l, r);
                }
            }
            if l > 0 && l < n {
                let mut lb = Bounds::EMPTY;
                let mut rb = Bounds::EMPTY;
                for (s, b) in bins.iter().enumerate() {
                    if s <= split_bin {
                        lb.merge(b);
                    } else {
                        rb.merge(b);
                    }
                }
                return (l, lb, rb);
            }
        }
    }
    // Median split along the longest centroid axis (any split if all centroids coincide).
    let mid = n / 2;
    idx.select_nth_unstable_by(mid, |a, b| {
        a.centroid2()[axis].total_cmp(&b.centroid2()[axis])
    });
    let (l, r) = idx.split_at(mid);
    (mid, Bounds::of(l), Bounds::of(r))
}

#[inline]
fn bin_of(x: f64, lo: f64, scale: f64) -> usize {
    // NaN and negatives saturate to 0 with `as`.
    (((x - lo) * scale) as usize).min(BINS - 1)
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{Rng, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    fn random_boxes(n: usize, size: f64, seed: u64) -> Vec<Aabb> {
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        (0..n)
            .map(|_| {
                let c: [f64; 3] = std::array::from_fn(|_| rng.random_range(0.0..1.0));
                let h: [f64; 3] = std::array::from_fn(|_| rng.random_range(0.0..size));
                Aabb::new(
                    [c[0] - h[0], c[1] - h[1], c[2] - h[2]],
                    [c[0] + h[0], c[1] + h[1], c[2] + h[2]],
                )
            })
            .collect()
    }

    fn brute_pairs(b: &[Aabb]) -> Vec<(usize, usize)> {
        let mut v = Vec::new();
        for i in 0..b.len() {
            for j in i + 1..b.len() {
                if b[i].overlaps(&b[j]) {
                    v.push((i, j));
                }
            }
        }
        v
    }

    #[test]
    fn aabb_basics() {
        let a = Aabb::from_points(&[[0.0, 0.0, 0.0], [1.0, 2.0, 3.0]]);
        assert_eq!(a.min, [0.0; 3]);
        assert_eq!(a.max, [1.0, 2.0, 3.0]);
        assert!(!a.is_empty());
        assert!(Aabb::EMPTY.is_empty());
        assert!(Aabb::from_points(&[]).is_empty());
        assert!(!Aabb::EMPTY.overlaps(&a));
        let b = Aabb::new([1.0, 2.0, 3.0], [4.0, 4.0, 4.0]);
        assert!(a.overlaps(&b), "touching closed boxes overlap");
        let c = Aabb::new([1.0 + 1e-15, 0.0, 0.0], [2.0, 1.0, 1.0]);
        assert!(!a.overlaps(&c));
        assert_eq!(a.union(&b).max, [4.0, 4.0, 4.0]);
        assert_eq!(a.union(&Aabb::EMPTY), a);
        assert_eq!(a.distance_sq_to_point([0.5, 0.5, 0.5]), 0.0);
        assert_eq!(a.distance_sq_to_point([-1.0, 4.0, 3.0]), 5.0);
        assert_eq!(Aabb::EMPTY.distance_sq_to_point([0.0; 3]), f64::INFINITY);
        assert_eq!(a.surface_area(), 2.0 * (2.0 + 6.0 + 3.0));
        assert!(a.contains_point([1.0, 2.0, 3.0]));
    }

    #[test]
    fn empty_and_single() {
        let t = Bvh::build(&[]);
        assert!(t.is_empty());
        assert!(t.overlapping_pairs().is_empty());
        assert!(t.nearest([0.0; 3], |_| 0.0).is_none());
        let mut hit = false;
        t.query_overlaps(&Aabb::new([-1e9; 3], [1e9; 3]), |_| hit = true);
        assert!(!hit);
        let one = Bvh::build(&[Aabb::from_point([1.0, 1.0, 1.0])]);
        assert_eq!(one.len(), 1);
        assert_eq!(one.depth(), 1);
        assert_eq!(one.nearest([0.0; 3], |_| 3.0), Some((0, 3.0)));
    }

    #[test]
    fn pairs_match_brute_force() {
        for (n, size, seed) in [(50, 0.2, 1), (700, 0.05, 2), (3000, 0.02, 3)] {
            let b = random_boxes(n, size, seed);
            let t = Bvh::build(&b);
            let mut got = t.overlapping_pairs();
            got.sort_unstable();
            let want = brute_pairs(&b);
            assert_eq!(got, want, "n = {n}");
            let mut seq = Vec::new();
            t.for_each_overlapping_pair(|i, j| seq.push((i.min(j), i.max(j))));
            seq.sort_unstable();
            assert_eq!(seq, want);
            let count = t.par_fold_overlapping_pairs(|| 0usize, |c, _, _| *c += 1, |a, b| a + b);
            assert_eq!(count, want.len());
        }
    }

    #[test]
    fn identical_boxes_and_points() {
        // All centroids equal: median fallback must still terminate and be correct.
        let b = vec![Aabb::new([0.0; 3], [1.0; 3]); 37];
        let t = Bvh::build(&b);
        assert_eq!(t.overlapping_pairs().len(), 37 * 36 / 2);
        assert!(t.depth() <= 10);
        // Coincident points touch.
        let p = vec![Aabb::from_point([0.5; 3]); 5];
        assert_eq!(Bvh::build(&p).overlapping_pairs().len(), 10);
    }

    #[test]
    fn query_matches_brute_force() {
        let b = random_boxes(2000, 0.03, 7);
        let t = Bvh::build_with_leaf_size(&b, 3);
        let queries = random_boxes(50, 0.1, 8);
        // Whole-domain queries too: they visit every node, so the small stacks below fill up.
        let all = [
            Aabb::new([-2.0; 3], [2.0; 3]),
            Aabb::new([0.0; 3], [2.0; 3]),
        ];
        for q in queries.iter().chain(&all) {
            let want: Vec<usize> = (0..b.len()).filter(|&i| b[i].overlaps(q)).collect();
            // The stack on the call stack alone (64), and spilling to the heap (1, 2, 5).
            let runs: [fn(&Bvh, &Aabb, &mut Vec<usize>); 4] = [
                |t, q, got| t.query_overlaps(q, |i| got.push(i)),
                |t, q, got| t.query_overlaps_inline::<1>(q, |i| got.push(i)),
                |t, q, got| t.query_overlaps_inline::<2>(q, |i| got.push(i)),
                |t, q, got| t.query_overlaps_inline::<5>(q, |i| got.push(i)),
            ];
            for run in runs {
                let mut got = Vec::new();
                run(&t, q, &mut got);
                got.sort_unstable();
                assert_eq!(got, want);
            }
        }
        assert!(t.depth() > 5, "the heap part is reached");
    }

    /// Nearest-item queries of both builds (SAH and Morton order) against brute force.
    #[test]
    fn nearest_matches_brute_force() {
        let builds: [fn(&[Aabb]) -> Bvh; 2] = [Bvh::build, Bvh::build_morton];
        for build in builds {
            nearest_against_brute_force(build);
        }
    }

    fn nearest_against_brute_force(build: fn(&[Aabb]) -> Bvh) {
        let mut rng = ChaCha8Rng::seed_from_u64(11);
        let pts: Vec<[f64; 3]> = (0..3000)
            .map(|_| std::array::from_fn(|_| rng.random_range(-1.0..1.0)))
            .collect();
        let boxes: Vec<Aabb> = pts.iter().map(|&p| Aabb::from_point(p)).collect();
        let t = build(&boxes);
        let d2 = |a: [f64; 3], b: [f64; 3]| (0..3).map(|k| (a[k] - b[k]).powi(2)).sum::<f64>();
        for _ in 0..100 {
            let q: [f64; 3] = std::array::from_fn(|_| rng.random_range(-1.5..1.5));
            let mut calls = 0;
            let (i, d) = t
                .nearest(q, |i| {
                    calls += 1;
                    d2(q, pts[i])
                })
                .unwrap();
            let want = pts.iter().map(|&p| d2(q, p)).fold(f64::INFINITY, f64::min);
            assert_eq!(d, want);
            assert_eq!(d2(q, pts[i]), want);
            assert!(calls < 300, "branch and bound should prune ({calls} calls)");
        }
    }

    #[test]
    fn tree_invariants() {
        let b = random_boxes(5000, 0.01, 5);
        check_invariants(&Bvh::build(&b), &b);
    }

    fn check_invariants(t: &Bvh, b: &[Aabb]) {
        let mut seen = vec![false; b.len()];
        for (n, node) in t.nodes.iter().enumerate() {
            for k in node.start as usize..node.end as usize {
                let bb = &t.boxes[k];
                assert_eq!(*bb, b[t.items[k] as usize]);
                assert_eq!(node.aabb.union(bb), node.aabb);
            }
            if node.is_leaf() {
                assert!(node.len() <= DEFAULT_LEAF_SIZE && node.len() > 0);
                for k in node.start..node.end {
                    seen[t.items[k as usize] as usize] = true;
                }
            } else {
                let (l, r) = (&t.nodes[n + 1], &t.nodes[node.right as usize]);
                assert_eq!(l.start, node.start);
                assert_eq!(l.end, r.start);
                assert_eq!(r.end, node.end);
            }
        }
        assert!(seen.iter().all(|&s| s));
        assert!(t.depth() < 40, "depth {}", t.depth());
    }

    /// The Morton-ordered build answers every query as the SAH build and brute force do, and
    /// keeps the tree invariants, sequential and parallel, on degenerate inputs too (nearest
    /// items: `nearest_matches_brute_force`).
    #[test]
    fn morton_build_answers_the_same() {
        for (n, size, seed) in [
            (1, 0.1, 20),
            (5, 0.1, 21),
            (50, 0.2, 1),
            (700, 0.05, 2),
            (3000, 0.02, 3),
        ] {
            let b = random_boxes(n, size, seed);
            let t = Bvh::build_morton(&b);
            check_invariants(&t, &b);
            let mut got = t.overlapping_pairs();
            got.sort_unstable();
            assert_eq!(got, brute_pairs(&b), "n = {n}");
            for q in &random_boxes(30, 0.1, seed + 100) {
                let mut got = Vec::new();
                t.query_overlaps(q, |i| got.push(i));
                got.sort_unstable();
                let want: Vec<usize> = (0..b.len()).filter(|&i| b[i].overlaps(q)).collect();
                assert_eq!(got, want);
            }
        }
        // All centres equal, points, an empty box and a non-finite one among ordinary ones.
        let same = vec![Aabb::new([0.0; 3], [1.0; 3]); 37];
        assert_eq!(
            Bvh::build_morton(&same).overlapping_pairs().len(),
            37 * 36 / 2
        );
        let p = vec![Aabb::from_point([0.5; 3]); 5];
        assert_eq!(Bvh::build_morton(&p).overlapping_pairs().len(), 10);
        let mut odd = random_boxes(200, 0.05, 30);
        odd[7] = Aabb::EMPTY;
        odd[50] = Aabb::new([f64::NEG_INFINITY, 0.0, 0.0], [0.5, 0.5, 0.5]);
        let t = Bvh::build_morton(&odd);
        check_invariants(&t, &odd);
        let mut got = t.overlapping_pairs();
        got.sort_unstable();
        assert_eq!(got, brute_pairs(&odd));
        // Large enough for the parallel build: the same pairs as the SAH tree.
        let b = random_boxes(40_000, 0.002, 9);
        let (t, sah) = (Bvh::build_morton(&b), Bvh::build(&b));
        check_invariants(&t, &b);
        let mut x = t.overlapping_pairs();
        let mut y = sah.overlapping_pairs();
        x.sort_unstable();
        y.sort_unstable();
        assert_eq!(x, y);
        let count = t.par_fold_overlapping_pairs(|| 0usize, |c, _, _| *c += 1, |a, b| a + b);
        assert_eq!(count, x.len());
    }

    #[test]
    fn parallel_build_matches_pairs() {
        // Large enough to use the parallel build and the parallel traversal.
        let b = random_boxes(40_000, 0.002, 9);
        let t = Bvh::build(&b);
        let count = t.par_fold_overlapping_pairs(|| 0usize, |c, _, _| *c += 1, |a, b| a + b);
        let mut seq = 0usize;
        t.for_each_overlapping_pair(|_, _| seq += 1);
        assert_eq!(count, seq);
        // Spot-check against a brute force on a subset.
        for i in (0..b.len()).step_by(997) {
            let mut got = Vec::new();
            t.query_overlaps(&b[i], |j| got.push(j));
            got.sort_unstable();
            let want: Vec<usize> = (0..b.len()).filter(|&j| b[j].overlaps(&b[i])).collect();
            assert_eq!(got, want);
        }
    }
}
