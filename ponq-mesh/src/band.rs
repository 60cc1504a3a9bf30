//! A grid of values stored near its surface only: [`BandGrid`].
//!
//! Inference reads a signed distance grid at the nodes near its zero level set (the cells the
//! network can keep, the encoder's reach around them, the refinement's band); a fine grid
//! (513^3 and up) holds 400 times more nodes than that. A `BandGrid` keeps the values of the
//! bricks of [`BRICK`]^3 nodes that hold a node with `|v| < threshold` (or both signs), and of
//! the bricks within `reach` nodes of those; every other brick keeps only its sign. Memory
//! follows the surface's area, not the grid's volume, and the grid is built plane by plane
//! ([`BandBuilder`]) so that no dense copy is ever made (`io::npy::read_npy_band` streams a
//! `.npy` file into one).
//!
//! No crate does this: OpenVDB's sparse trees are C++, and Rust's sparse voxel crates are
//! built for rendering (no streamed build, no exact statistics over the dropped values).
//!
//! ```
//! use ponq_mesh::band::BandGrid;
//! // The distance to the plane x = 0.3 on a 33^3 grid over [-1, 1]^3.
//! let n = 33;
//! let h = 2.0 / 32.0;
//! let data: Vec<f64> = (0..n * n * n).map(|f| -1.0 + h * (f / (n * n)) as f64 - 0.3).collect();
//! let band = BandGrid::from_dense([n; 3], &data, 1.0, 2.0 * h, 2).unwrap();
//! assert!(band.stored_bricks() < band.brick_dims().iter().product::<usize>());
//! // Stored where it matters, exact there; a far node gives its sign and the threshold.
//! assert_eq!(band.get(21, 5, 7), data[(21 * n + 5) * n + 7]);
//! assert_eq!(band.get(0, 0, 0), -2.0 * h);
//! ```

use rayon::prelude::*;

use crate::error::{Error, Result};

/// Nodes per side of a brick.
pub const BRICK: usize = 8;
const B3: usize = BRICK * BRICK * BRICK;
/// Slot of a brick whose nodes are all negative and far.
const FAR_NEG: u32 = u32::MAX - 1;
/// Slot of a brick whose nodes are all positive and far.
const FAR_POS: u32 = u32::MAX;

/// Statistics over every node of the grid, stored or not (exact: taken while building).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ValueStats {
    /// Smallest value.
    pub min: f64,
    /// Largest value.
    pub max: f64,
    /// Nodes equal to `min`.
    pub min_count: u64,
    /// Nodes equal to `max`.
    pub max_count: u64,
    /// Nodes with a negative value.
    pub negative: u64,
    /// All nodes.
    pub nodes: u64,
}

impl Default for ValueStats {
    fn default() -> Self {
        Self {
            min: f64::INFINITY,
            max: f64::NEG_INFINITY,
            min_count: 0,
            max_count: 0,
            negative: 0,
            nodes: 0,
        }
    }
}

impl ValueStats {
    fn add(&mut self, v: f64) {
        self.nodes += 1;
        if v < 0.0 {
            self.negative += 1;
        }
        if v < self.min {
            self.min = v;
            self.min_count = 1;
        } else if v == self.min {
            self.min_count += 1;
        }
        if v > self.max {
            self.max = v;
            self.max_count = 1;
        } else if v == self.max {
            self.max_count += 1;
        }
    }

    /// [`ValueStats::add`] of every value of `v`, in lanes (the reading of a fine grid spends
    /// most of its time here).
    fn add_slice(&mut self, v: &[f64]) {
        if v.is_empty() {
            return;
        }
        const L: usize = 8;
        let mut mn = [f64::INFINITY; L];
        let mut mx = [f64::NEG_INFINITY; L];
        let mut neg = [0u64; L];
        let chunks = v.chunks_exact(L);
        let rest = chunks.remainder();
        for c in chunks {
            for l in 0..L {
                mn[l] = if c[l] < mn[l] { c[l] } else { mn[l] };
                mx[l] = if c[l] > mx[l] { c[l] } else { mx[l] };
                neg[l] += u64::from(c[l] < 0.0);
            }
        }
        for (l, &x) in rest.iter().enumerate() {
            mn[l] = if x < mn[l] { x } else { mn[l] };
            mx[l] = if x > mx[l] { x } else { mx[l] };
            neg[l] += u64::from(x < 0.0);
        }
        let lo = mn
            .iter()
            .fold(f64::INFINITY, |a, &b| if b < a { b } else { a });
        let hi = mx
            .iter()
            .fold(f64::NEG_INFINITY, |a, &b| if b > a { b } else { a });
        let (mut n_lo, mut n_hi) = (0u64, 0u64);
        for &x in v {
            n_lo += u64::from(x == lo);
            n_hi += u64::from(x == hi);
        }
        if lo < self.min {
            self.min = lo;
            self.min_count = n_lo;
        } else if lo == self.min {
            self.min_count += n_lo;
        }
        if hi > self.max {
            self.max = hi;
            self.max_count = n_hi;
        } else if hi == self.max {
            self.max_count += n_hi;
        }
        self.nodes += v.len() as u64;
        self.negative += neg.iter().sum::<u64>();
    }

    /// The statistics of both sets of nodes.
    fn merge(mut self, o: Self) -> Self {
        if o.min < self.min {
            self.min = o.min;
            self.min_count = o.min_count;
        } else if o.min == self.min {
            self.min_count += o.min_count;
        }
        if o.max > self.max {
            self.max = o.max;
            self.max_count = o.max_count;
        } else if o.max == self.max {
            self.max_count += o.max_count;
        }
        self.nodes += o.nodes;
        self.negative += o.negative;
        self
    }

    fn add_many(&mut self, v: f64, n: u64) {
        if n == 0 {
            return;
        }
        self.add(v);
        let more = n - 1;
        self.nodes += more;
        if v < 0.0 {
            self.negative += more;
        }
        if v == self.min {
            self.min_count += more;
        }
        if v == self.max {
            self.max_count += more;
        }
    }

    /// Nodes equal to `v` when `v` is the smallest or the largest value, else `None`.
    pub fn count_of_extreme(&self, v: f64) -> Option<u64> {
        if v == self.min {
            Some(self.min_count)
        } else if v == self.max {
            Some(self.max_count)
        } else {
            None
        }
    }
}

/// A 3D grid of values in C order (`(i, j, k)`, `k` fastest) stored near its surface only.
///
/// Invariants: every node whose value `v` has `|v| < threshold`, and every node within
/// `reach` nodes (along each axis) of one, is stored exactly; so is every node of a brick
/// holding both signs. Each other node belongs to a brick whose nodes all have one sign and
/// `|v| >= threshold`: [`BandGrid::get`] gives it `±threshold` (a lower bound of its
/// magnitude, with its sign). [`BandGrid::stats`] covers all nodes.
#[derive(Debug, Clone, PartialEq)]
pub struct BandGrid {
    dims: [usize; 3],
    bricks: [usize; 3],
    /// Per brick (C order): its index in `values` (times [`B3`]), or [`FAR_NEG`] /
    /// [`FAR_POS`].
    slots: Vec<u32>,
    /// Stored bricks, [`B3`] values each in brick-local C order (padding past the grid's
    /// last node is 0).
    values: Vec<f64>,
    threshold: f64,
    reach: usize,
    stats: ValueStats,
}

impl BandGrid {
    /// The band of a dense grid (`data` in C order over `dims`), each value times `scale`;
    /// `threshold` and the values stored are in scaled units (see [`BandBuilder::new`]).
    ///
    /// # Errors
    /// As [`BandBuilder`]: a size mismatch, a non-finite value.
    pub fn from_dense(
        dims: [usize; 3],
        data: &[f64],
        scale: f64,
        threshold: f64,
        reach: usize,
    ) -> Result<Self> {
        let plane = dims[1] * dims[2];
        if dims.iter().product::<usize>() != data.len() {
            return Err(Error::InvalidInput(format!(
                "{} values for a grid of {dims:?} nodes",
                data.len()
            )));
        }
        let mut b = BandBuilder::new(dims, scale, threshold, reach)?;
        for p in data.chunks(plane.max(1)) {
            b.push_plane(p)?;
        }
        b.finish()
    }

    /// A band from its bricks, for values computed near a surface only (a mesh's distances,
    /// a neural field): `stored` lists `(brick, values)` (bricks in C order over
    /// [`BandGrid::brick_dims_of`], [`BRICK`]^3 values each in brick-local C order; padding past
    /// the grid is ignored); every other brick is far, negative where `far_negative(brick)`.
    /// The caller guarantees the invariants of [`BandGrid`] for `threshold` and `reach`. The
    /// statistics count the far nodes as `±threshold` (their values are unknown).
    ///
    /// # Errors
    /// A brick out of range or listed twice, a values block of another size, a non-finite
    /// value, and the errors of [`BandBuilder::new`].
    pub fn from_bricks(
        dims: [usize; 3],
        threshold: f64,
        reach: usize,
        mut stored: Vec<(usize, Vec<f64>)>,
        far_negative: impl Fn(usize) -> bool,
    ) -> Result<Self> {
        let b = BandBuilder::new(dims, 1.0, threshold, reach)?;
        let bricks = b.bricks;
        let nb = bricks.iter().product::<usize>();
        stored.sort_unstable_by_key(|x| x.0);
        if stored.windows(2).any(|w| w[0].0 == w[1].0) || stored.last().is_some_and(|x| x.0 >= nb) {
            return Err(Error::InvalidInput(
                "band bricks listed twice or out of range".into(),
            ));
        }
        let mut slots = vec![FAR_POS; nb];
        let mut values = Vec::with_capacity(stored.len() * B3);
        let mut stats = ValueStats::default();
        let [_, b1, b2] = bricks;
        let extent = |b: usize| -> [usize; 3] {
            let bc = [b / (b1 * b2), (b / b2) % b1, b % b2];
            std::array::from_fn(|a| (dims[a] - bc[a] * BRICK).min(BRICK))
        };
        for (slot, (b, v)) in stored.into_iter().enumerate() {
            if v.len() != B3 {
                return Err(Error::InvalidInput(format!(
                    "a brick of {} values, expected {B3}",
                    v.len()
                )));
            }
            let e = extent(b);
            for x in 0..e[0] {
                for y in 0..e[1] {
                    for &val in &v[(x * BRICK + y) * BRICK..(x * BRICK + y) * BRICK + e[2]] {
                        if !val.is_finite() {
                            return Err(Error::InvalidInput(format!(
                                "a non-finite value ({val}) in brick {b}"
                            )));
                        }
                        stats.add(val);
                    }
                }
            }
            slots[b] = slot as u32;
            values.extend_from_slice(&v);
        }
        for (b, s) in slots.iter_mut().enumerate() {
            if *s == FAR_POS {
                let neg = far_negative(b);
                *s = if neg { FAR_NEG } else { FAR_POS };
                let v = if neg { -threshold } else { threshold };
                stats.add_many(v, extent(b).iter().product::<usize>() as u64);
            }
        }
        Ok(Self {
            dims,
            bricks,
            slots,
            values,
            threshold,
            reach,
            stats,
        })
    }

    /// Bricks per axis of a grid of `dims` nodes.
    pub fn brick_dims_of(dims: [usize; 3]) -> [usize; 3] {
        dims.map(|d| d.div_ceil(BRICK))
    }

    /// Nodes per axis.
    pub fn dims(&self) -> [usize; 3] {
        self.dims
    }

    /// Bricks per axis.
    pub fn brick_dims(&self) -> [usize; 3] {
        self.bricks
    }

    /// Nodes with `|v|` below this are stored (with their neighbours within [`Self::reach`]).
    pub fn threshold(&self) -> f64 {
        self.threshold
    }

    /// How far (in nodes, along each axis) around a node below the threshold values are
    /// stored.
    pub fn reach(&self) -> usize {
        self.reach
    }

    /// Statistics over every node.
    pub fn stats(&self) -> ValueStats {
        self.stats
    }

    /// Bricks whose values are stored.
    pub fn stored_bricks(&self) -> usize {
        self.values.len() / B3
    }

    /// Bytes held by the grid.
    pub fn memory_bytes(&self) -> usize {
        self.values.len() * 8 + self.slots.len() * 4
    }

    /// Number of nodes.
    pub fn len(&self) -> usize {
        self.dims.iter().product()
    }

    /// Whether the grid has no node.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    #[inline]
    fn brick_of(&self, i: usize, j: usize, k: usize) -> usize {
        ((i / BRICK) * self.bricks[1] + j / BRICK) * self.bricks[2] + k / BRICK
    }

    /// The value at `(i, j, k)`: exact where stored, `±threshold` elsewhere. Panics out of
    /// range.
    #[inline]
    pub fn get(&self, i: usize, j: usize, k: usize) -> f64 {
        match self.slots[self.brick_of(i, j, k)] {
            FAR_NEG => -self.threshold,
            FAR_POS => self.threshold,
            s => {
                self.values[s as usize * B3 + ((i % BRICK) * BRICK + j % BRICK) * BRICK + k % BRICK]
            }
        }
    }

    /// The value at flat C-order index `f`.
    #[inline]
    pub fn get_flat(&self, f: usize) -> f64 {
        let [i, j, k] = self.coords(f);
        self.get(i, j, k)
    }

    /// Whether the value at `(i, j, k)` is stored (exact).
    #[inline]
    pub fn is_stored(&self, i: usize, j: usize, k: usize) -> bool {
        self.slots[self.brick_of(i, j, k)] < FAR_NEG
    }

    /// Coordinates of flat C-order index `f`.
    #[inline]
    pub fn coords(&self, f: usize) -> [usize; 3] {
        let k = f % self.dims[2];
        let ij = f / self.dims[2];
        [ij / self.dims[1], ij % self.dims[1], k]
    }

    /// Flat C-order index of `(i, j, k)`.
    #[inline]
    pub fn index(&self, i: usize, j: usize, k: usize) -> usize {
        (i * self.dims[1] + j) * self.dims[2] + k
    }

    /// The stored bricks: the node range `lo..hi` of each, in C order of the bricks.
    pub fn stored_ranges(&self) -> impl Iterator<Item = ([usize; 3], [usize; 3])> + '_ {
        let [_, b1, b2] = self.bricks;
        self.slots
            .iter()
            .enumerate()
            .filter(|(_, s)| **s < FAR_NEG)
            .map(move |(b, _)| {
                let bc = [b / (b1 * b2), (b / b2) % b1, b % b2];
                let lo = bc.map(|x| x * BRICK);
                let hi = std::array::from_fn(|a| (lo[a] + BRICK).min(self.dims[a]));
                (lo, hi)
            })
    }

    /// Calls `f(i, j, k, v)` for every stored node (brick by brick).
    pub fn for_each_stored(&self, mut f: impl FnMut(usize, usize, usize, f64)) {
        for (lo, hi) in self.stored_ranges() {
            for i in lo[0]..hi[0] {
                for j in lo[1]..hi[1] {
                    for k in lo[2]..hi[2] {
                        f(i, j, k, self.get(i, j, k));
                    }
                }
            }
        }
    }

    /// Flat C-order indices, ascending, of the stored nodes whose value passes `keep`.
    pub fn stored_where(&self, keep: impl Fn(f64) -> bool) -> Vec<usize> {
        let mut out = Vec::new();
        self.for_each_stored(|i, j, k, v| {
            if keep(v) {
                out.push(self.index(i, j, k));
            }
        });
        out.sort_unstable();
        out
    }

    /// The values of the block of nodes `lo..=hi` in C order (far nodes as [`Self::get`]
    /// gives them).
    pub fn block(&self, lo: [usize; 3], hi: [usize; 3]) -> Vec<f64> {
        let mut out = Vec::with_capacity((0..3).map(|a| hi[a] + 1 - lo[a]).product());
        for i in lo[0]..=hi[0] {
            for j in lo[1]..=hi[1] {
                for k in lo[2]..=hi[2] {
                    out.push(self.get(i, j, k));
                }
            }
        }
        out
    }

    /// The grid with its axes reversed (node `(i, j, k)` of the result is `(k, j, i)` of
    /// this one): a Fortran-order array read as C order, turned around.
    pub fn reversed(&self) -> Self {
        let d = self.dims;
        let dims = [d[2], d[1], d[0]];
        let bricks = [self.bricks[2], self.bricks[1], self.bricks[0]];
        let mut slots = vec![0u32; self.slots.len()];
        let mut values = vec![0.0; self.values.len()];
        let [b0, b1, b2] = self.bricks;
        for (b, &s) in self.slots.iter().enumerate() {
            let bc = [b / (b1 * b2), (b / b2) % b1, b % b2];
            let rb = (bc[2] * bricks[1] + bc[1]) * bricks[2] + bc[0];
            slots[rb] = s;
            if s < FAR_NEG {
                let src = &self.values[s as usize * B3..(s as usize + 1) * B3];
                let dst = &mut values[s as usize * B3..(s as usize + 1) * B3];
                for x in 0..BRICK {
                    for y in 0..BRICK {
                        for z in 0..BRICK {
                            dst[(z * BRICK + y) * BRICK + x] = src[(x * BRICK + y) * BRICK + z];
                        }
                    }
                }
            }
        }
        debug_assert_eq!(b0 * b1 * b2, slots.len());
        Self {
            dims,
            bricks,
            slots,
            values,
            threshold: self.threshold,
            reach: self.reach,
            stats: self.stats,
        }
    }

    /// The dense values in C order (for small grids and tests).
    pub fn to_dense(&self) -> Vec<f64> {
        self.block([0; 3], self.dims.map(|d| d.saturating_sub(1)))
    }
}

/// One layer of bricks (`BRICK` node planes along the first axis) being built.
struct Layer {
    /// The planes' values (scaled), C order over `(planes, dims[1], dims[2])`.
    data: Vec<f64>,
    planes: usize,
}

/// Builds a [`BandGrid`] from its node planes (`i = 0, 1, ...`), keeping at most
/// `2 + reach / BRICK` layers of [`BRICK`] planes in memory.
pub struct BandBuilder {
    dims: [usize; 3],
    bricks: [usize; 3],
    scale: f64,
    threshold: f64,
    reach: usize,
    /// Bricks of reach around a near brick.
    reach_bricks: usize,
    /// Per layer: per brick of the layer, near (a node below the threshold, or both signs).
    near: Vec<Vec<bool>>,
    /// Per layer: per brick, the sign of its nodes (true: negative), meaningful when not near.
    negative: Vec<Vec<bool>>,
    /// Layers whose values are kept until their storage is decided, with their layer index.
    pending: std::collections::VecDeque<(usize, Layer)>,
    /// The layer being filled.
    current: Layer,
    planes_done: usize,
    slots: Vec<u32>,
    values: Vec<f64>,
    stats: ValueStats,
    limit: Option<usize>,
    /// Buffers of decided layers, for the next ones (no fresh pages per layer).
    spare: Vec<Vec<f64>>,
}

impl BandBuilder {
    /// Stops the build with an error once the stored values would take more than `bytes`
    /// (a field with a surface everywhere, e.g. noise, stores the whole grid).
    pub fn with_limit(mut self, bytes: Option<usize>) -> Self {
        self.limit = bytes;
        self
    }

    /// A builder for a grid of `dims` nodes. Each value pushed is multiplied by `scale`;
    /// `threshold` is in the scaled units; nodes within `reach` nodes of one below it are
    /// stored too (whole bricks around: `reach` is rounded up to bricks).
    ///
    /// # Errors
    /// An empty grid, a brick count over `u32`, a scale or threshold that is not positive
    /// (`threshold` may be infinite: everything is stored).
    pub fn new(dims: [usize; 3], scale: f64, threshold: f64, reach: usize) -> Result<Self> {
        if dims.contains(&0) {
            return Err(Error::InvalidInput(format!(
                "an empty grid: {dims:?} nodes"
            )));
        }
        if !(scale > 0.0 && scale.is_finite() && threshold > 0.0) {
            return Err(Error::InvalidInput(format!(
                "band grid: scale {scale} and threshold {threshold} must be positive"
            )));
        }
        let bricks = dims.map(|d| d.div_ceil(BRICK));
        let nb = bricks
            .iter()
            .try_fold(1usize, |a, &b| a.checked_mul(b))
            .filter(|&n| n < FAR_NEG as usize)
            .ok_or_else(|| Error::InvalidInput(format!("grid of {dims:?} nodes is too large")))?;
        Ok(Self {
            dims,
            bricks,
            scale,
            threshold,
            reach,
            reach_bricks: reach.div_ceil(BRICK),
            near: Vec::with_capacity(bricks[0]),
            negative: Vec::with_capacity(bricks[0]),
            pending: Default::default(),
            current: Layer {
                data: Vec::new(),
                planes: 0,
            },
            planes_done: 0,
            slots: vec![FAR_POS; nb],
            values: Vec::new(),
            stats: ValueStats::default(),
            limit: None,
            spare: Vec::new(),
        })
    }

    /// Adds the next plane (`dims[1] * dims[2]` values, C order).
    ///
    /// # Errors
    /// A plane of another size, a plane past the last one, a non-finite value (named by its
    /// node).
    pub fn push_plane(&mut self, plane: &[f64]) -> Result<()> {
        let [d0, d1, d2] = self.dims;
        if plane.len() != d1 * d2 {
            return Err(Error::InvalidInput(format!(
                "a plane of {} values for {d1} x {d2} nodes",
                plane.len()
            )));
        }
        if self.planes_done >= d0 {
            return Err(Error::InvalidInput(format!(
                "more than {d0} planes pushed to a band grid"
            )));
        }
        let i = self.planes_done;
        if !plane.iter().all(|v| v.is_finite())
            && let Some(p) = plane.iter().position(|v| !v.is_finite())
        {
            return Err(Error::InvalidInput(format!(
                "grid value at [{i}, {}, {}] is {}",
                p / d2,
                p % d2,
                plane[p]
            )));
        }
        if self.current.data.capacity() == 0 {
            self.current.data = self.spare.pop().unwrap_or_default();
            self.current.data.clear();
            self.current.data.reserve_exact(BRICK * d1 * d2);
        }
        let s = self.scale;
        let start = self.current.data.len();
        self.current.data.resize(start + plane.len(), 0.0);
        // Scaled and summarised in parallel blocks of rows (this is most of the reading).
        let block = (d2 * 64).max(1);
        let stats = self.current.data[start..]
            .par_chunks_mut(block)
            .zip(plane.par_chunks(block))
            .map(|(dst, src)| {
                for (d, &v) in dst.iter_mut().zip(src) {
                    *d = v * s;
                }
                let mut st = ValueStats::default();
                st.add_slice(dst);
                st
            })
            .reduce(ValueStats::default, ValueStats::merge);
        self.stats = self.stats.merge(stats);
        self.current.planes += 1;
        self.planes_done += 1;
        if self.current.planes == BRICK || self.planes_done == d0 {
            self.close_layer();
        }
        if let Some(l) = self.limit
            && self.values.len() * 8 > l
        {
            return Err(Error::InvalidInput(format!(
                "not enough memory: the values near the surface of this grid take more than \
                 the {} they may have ({} of {} planes read, {} bricks of 8^3 nodes stored): \
                 its surface fills much of the grid (a noisy field?), or the machine (or its \
                 container's limit, or PONQ_MEMORY_LIMIT) is short of memory",
                crate::memory::gb(l as u64),
                self.planes_done,
                d0,
                self.values.len() / B3
            )));
        }
        Ok(())
    }

    /// Summarises the filled layer and decides every layer whose reach is complete.
    fn close_layer(&mut self) {
        let [_, d1, d2] = self.dims;
        let [_, b1, b2] = self.bricks;
        let layer = std::mem::replace(
            &mut self.current,
            Layer {
                data: Vec::new(),
                planes: 0,
            },
        );
        let mut near = vec![false; b1 * b2];
        let mut neg = vec![false; b1 * b2];
        let mut pos = vec![false; b1 * b2];
        let t = self.threshold;
        // Per row of the layer (in parallel), per brick of the row: bit 0 a node below the
        // threshold, bit 1 a negative node, bit 2 a node >= 0.
        let flags: Vec<Vec<u8>> = layer.data[..layer.planes * d1 * d2]
            .par_chunks(d2)
            .map(|row| {
                row.chunks(BRICK)
                    .map(|chunk| {
                        let (mut amin, mut lo, mut hi) =
                            (f64::INFINITY, f64::INFINITY, f64::NEG_INFINITY);
                        for &v in chunk {
                            let a = v.abs();
                            amin = if a < amin { a } else { amin };
                            lo = if v < lo { v } else { lo };
                            hi = if v > hi { v } else { hi };
                        }
                        u8::from(amin < t) | (u8::from(lo < 0.0) << 1) | (u8::from(hi >= 0.0) << 2)
                    })
                    .collect()
            })
            .collect();
        for (r, f) in flags.iter().enumerate() {
            let bj = (r % d1) / BRICK;
            for (bk, &x) in f.iter().enumerate() {
                let b = bj * b2 + bk;
                near[b] |= x & 1 != 0;
                neg[b] |= x & 2 != 0;
                pos[b] |= x & 4 != 0;
            }
        }
        for b in 0..near.len() {
            near[b] |= neg[b] && pos[b];
        }
        let li = self.near.len();
        self.near.push(near);
        self.negative.push(neg);
        self.pending.push_back((li, layer));
        let last = self.near.len() == self.bricks[0];
        while let Some((l, _)) = self.pending.front() {
            if !last && l + self.reach_bricks >= self.near.len() {
                break;
            }
            let Some((l, layer)) = self.pending.pop_front() else {
                break;
            };
            self.decide(l, &layer);
            self.spare.push(layer.data);
        }
    }

    /// Stores or drops the bricks of layer `l` (its neighbours' near flags are known).
    fn decide(&mut self, l: usize, layer: &Layer) {
        let [_, d1, d2] = self.dims;
        let [_, b1, b2] = self.bricks;
        let r = self.reach_bricks;
        let lo_l = l.saturating_sub(r);
        let hi_l = (l + r).min(self.near.len() - 1);
        for bj in 0..b1 {
            for bk in 0..b2 {
                let mut stored = false;
                'search: for ll in lo_l..=hi_l {
                    let nl = &self.near[ll];
                    for jj in bj.saturating_sub(r)..=(bj + r).min(b1 - 1) {
                        for kk in bk.saturating_sub(r)..=(bk + r).min(b2 - 1) {
                            if nl[jj * b2 + kk] {
                                stored = true;
                                break 'search;
                            }
                        }
                    }
                }
                let b = (l * b1 + bj) * b2 + bk;
                if !stored {
                    self.slots[b] = if self.negative[l][bj * b2 + bk] {
                        FAR_NEG
                    } else {
                        FAR_POS
                    };
                    continue;
                }
                let s = self.values.len() / B3;
                self.slots[b] = s as u32;
                self.values.resize(self.values.len() + B3, 0.0);
                let dst = &mut self.values[s * B3..(s + 1) * B3];
                for p in 0..layer.planes {
                    for y in 0..BRICK.min(d1 - bj * BRICK) {
                        let j = bj * BRICK + y;
                        let k0 = bk * BRICK;
                        let n = BRICK.min(d2 - k0);
                        let src = &layer.data[(p * d1 + j) * d2 + k0..(p * d1 + j) * d2 + k0 + n];
                        dst[(p * BRICK + y) * BRICK..(p * BRICK + y) * BRICK + n]
                            .copy_from_slice(src);
                    }
                }
            }
        }
    }

    /// Bytes the layers waiting for their neighbours hold now.
    pub fn pending_bytes(&self) -> usize {
        self.pending
            .iter()
            .map(|(_, l)| l.data.len() * 8)
            .sum::<usize>()
            + self.current.data.capacity() * 8
    }

    /// The grid.
    ///
    /// # Errors
    /// Fewer planes than `dims[0]` pushed.
    pub fn finish(self) -> Result<BandGrid> {
        if self.planes_done != self.dims[0] || !self.pending.is_empty() {
            return Err(Error::InvalidInput(format!(
                "a band grid of {} planes got {}",
                self.dims[0], self.planes_done
            )));
        }
        let mut values = self.values;
        values.shrink_to_fit();
        Ok(BandGrid {
            dims: self.dims,
            bricks: self.bricks,
            slots: self.slots,
            values,
            threshold: self.threshold,
            reach: self.reach,
            stats: self.stats,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{Rng, SeedableRng};

    /// A sphere's distance on an uneven grid (sizes not multiples of the brick).
    fn sphere(dims: [usize; 3], r: f64) -> Vec<f64> {
        let c = dims.map(|d| (d - 1) as f64 / 2.0);
        let mut out = Vec::new();
        for i in 0..dims[0] {
            for j in 0..dims[1] {
                for k in 0..dims[2] {
                    let p = [i as f64 - c[0], j as f64 - c[1], k as f64 - c[2]];
                    out.push((p[0] * p[0] + p[1] * p[1] + p[2] * p[2]).sqrt() - r);
                }
            }
        }
        out
    }

    /// Every node below the threshold and every node within reach of one is stored and
    /// exact; every other node has its sign and at least the threshold's magnitude; the
    /// statistics are those of all values.
    #[test]
    fn band_invariants_hold() {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(5);
        for dims in [[37, 29, 45], [9, 9, 9], [2, 17, 3], [64, 8, 1]] {
            let mut data = sphere(dims, 7.3);
            // A few exact extremes, repeated.
            data[0] = 99.0;
            let last = data.len() - 1;
            data[last] = 99.0;
            for reach in [0usize, 2, 4, 9] {
                let scale = rng.random_range(0.5..2.0);
                let t = 1.5 * scale;
                let g = BandGrid::from_dense(dims, &data, scale, t, reach).unwrap();
                assert_eq!(g.to_dense().len(), data.len());
                let near: Vec<[usize; 3]> = (0..data.len())
                    .filter(|&f| (data[f] * scale).abs() < t)
                    .map(|f| g.coords(f))
                    .collect();
                for f in 0..data.len() {
                    let [i, j, k] = g.coords(f);
                    let v = data[f] * scale;
                    let within = near
                        .iter()
                        .any(|n| (0..3).all(|a| n[a].abs_diff([i, j, k][a]) <= reach));
                    if within {
                        assert!(g.is_stored(i, j, k));
                    }
                    if g.is_stored(i, j, k) {
                        assert_eq!(g.get(i, j, k).to_bits(), v.to_bits());
                    } else {
                        assert!(v.abs() >= t && g.get(i, j, k) == t.copysign(v));
                    }
                }
                let s = g.stats();
                assert_eq!(s.max, 99.0 * scale);
                assert_eq!(s.max_count, 2);
                assert_eq!(s.nodes as usize, data.len());
                assert_eq!(
                    s.negative as usize,
                    data.iter().filter(|&&v| v < 0.0).count()
                );
                let want: Vec<usize> = (0..data.len())
                    .filter(|&f| (data[f] * scale).abs() < t)
                    .collect();
                assert_eq!(g.stored_where(|v| v.abs() < t), want);
                // Reversed axes: the Fortran reading.
                let r = g.reversed();
                for f in 0..data.len() {
                    let [i, j, k] = g.coords(f);
                    assert_eq!(r.get(k, j, i).to_bits(), g.get(i, j, k).to_bits());
                }
            }
        }
    }

    #[test]
    fn infinite_threshold_stores_everything_and_errors_are_clear() {
        let dims = [11, 5, 19];
        let data = sphere(dims, 3.0);
        let g = BandGrid::from_dense(dims, &data, 1.0, f64::INFINITY, 0).unwrap();
        assert_eq!(g.stored_bricks(), g.brick_dims().iter().product::<usize>());
        assert_eq!(g.to_dense(), data);
        let mut bad = data.clone();
        bad[(3 * 5 + 2) * 19 + 7] = f64::NAN;
        let e = BandGrid::from_dense(dims, &bad, 1.0, 1.0, 0).unwrap_err();
        assert!(e.to_string().contains("[3, 2, 7]"), "{e}");
        assert!(BandGrid::from_dense(dims, &data[1..], 1.0, 1.0, 0).is_err());
        let mut b = BandBuilder::new(dims, 1.0, 1.0, 0).unwrap();
        b.push_plane(&data[..95]).unwrap();
        assert!(b.finish().is_err());
    }
}
