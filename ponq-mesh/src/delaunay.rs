//! Exact 3D Delaunay tetrahedralisation.
//!
//! Written here because no MIT/Apache crate does it well enough: the pure-Rust candidates
//! measured on this project's machine were either MPL-licensed and 7 s on a 27k-point lattice
//! (PoNQ-lite puts v* on lattices), aborted on lattices, emitted flat tets, or were 1000x slower;
//! TetGen is AGPL. This is the classic Bowyer-Watson insertion in a BRIO / Hilbert-curve order
//! with a stochastic visibility walk, on top of [`crate::predicates`]: exact orientation and
//! insphere tests with Devillers-Teillaud symbolic perturbation, so co-spherical and coplanar
//! inputs (lattices) give a valid triangulation with no flat tetrahedron and no jitter.
//! The triangulation covers all of space, as CGAL's does: every face of the convex hull has an
//! infinite tet, the face and one symbolic infinite vertex (no position). A point beyond a
//! hull face is in conflict with that face's infinite tet; a point on the face's plane is in
//! conflict with it where it is in conflict with the finite tet across the face (inside the
//! face's circumcircle, ties broken by the same perturbation). The insertion starts from four
//! affinely independent points, their tet and its four infinite tets. (Until 2026-12-05 it
//! started from a super-tetrahedron of four far real points, which left the filters undecided
//! along the hull and cut off the hull's flat tets, whose circumspheres reach far: the
//! triangulation was then built again with a larger one.)
//!
//! Parallel insertion: after the first BRIO rounds, each worker thread takes one stretch of
//! every later round's Hilbert order (so the workers are far apart in space), cut into chunks;
//! a worker that has finished its own chunks takes the others' from the back of their queues
//! (work stealing). It walks to each vertex without locks, then try-locks the tet it ends in
//! (checked to contain the vertex), the cavity and the cavity's neighbours. A worker that
//! finds a tet busy undoes its stamps and locks, tries the vertex again after its chunk, and
//! else leaves it for a final one-thread pass. The perturbed Delaunay triangulation is unique,
//! and the output is put in a canonical order, so the result is the same arrays for any
//! number of workers and any timing (tested, with injected lock failures and stealing too).
//!
//! ```
//! use ponq_mesh::delaunay::Delaunay;
//! let pts = [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0], [1.0, 1.0, 1.0]];
//! let dt = Delaunay::new(&pts).unwrap();
//! assert_eq!(dt.tets.len(), 2);
//! ```

use std::sync::atomic::Ordering::{Acquire, Relaxed, Release};
use std::sync::atomic::{AtomicBool, AtomicU32, AtomicUsize};
use std::time::{Duration, Instant};

use crate::error::{Error, Result};
use crate::predicates::{
    collinear, in_conflict_bounded, in_conflict_past_static, insphere_static_lanes, orient3d,
    orient3d_bounded, static_insphere_bound, static_orient_bound,
};
#[cfg(target_arch = "x86_64")]
use crate::predicates::{insphere_static4_avx2, orient3d_faces_avx2};
use crate::vec3;

/// The vertices of the first tet ([`Builder::new`]): the first four of the insertion order
/// ([`independent_first`]), inserted before any other.
const FIRST_TET: u32 = 4;

/// Marker for "no neighbour" (a face on the boundary of the triangulated region).
pub const NONE: u32 = u32::MAX;

/// A Delaunay tetrahedralisation.
///
/// Invariants: every tet `tets[t]` is positively oriented (`orient3d > 0`, never flat);
/// `neighbors[t][k]` is the tet sharing the face opposite `tets[t][k]`, or [`NONE`] on the
/// convex hull; adjacency is symmetric. The union of the tets is the convex hull of the
/// vertices (when they are not all in one plane), and every vertex is in a tet.
#[derive(Debug, Clone, Default)]
pub struct Delaunay {
    /// The distinct input points (exact duplicates merged; the first occurrence is kept).
    pub vertices: Vec<[f64; 3]>,
    /// For each input point, the index of its vertex in `vertices`.
    pub vertex_of_point: Vec<u32>,
    /// Tetrahedra as vertex indices, positively oriented.
    pub tets: Vec<[u32; 4]>,
    /// `neighbors[t][k]`: the tet across the face opposite vertex `k` of `t`, or [`NONE`].
    pub neighbors: Vec<[u32; 4]>,
    /// How the triangulation was built.
    pub stats: DelaunayStats,
}

/// How a [`Delaunay`] was built (for benchmarks and tests; the tets never depend on it).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct DelaunayStats {
    /// Worker threads of the parallel phase (1: all insertions by one thread).
    pub workers: usize,
    /// Vertices inserted by the parallel phase.
    pub parallel_insertions: usize,
    /// Vertices inserted after the parallel phase by one thread: those a worker backed off
    /// from twice (a tet it needed was held by another worker), and those the workers left
    /// when they stopped early ([`DelaunayStats::parallel_stopped`]).
    pub deferred: usize,
    /// First attempts of the parallel phase that backed off (each vertex is tried again after
    /// the rest of its chunk).
    pub backed_off: usize,
    /// The workers stopped before the end of the parallel phase because more than one first
    /// attempt in 8 backed off (cavities so large that the workers' cavities keep overlapping, e.g. on
    /// points of a nearly flat convex surface); the rest went to the one-thread pass.
    pub parallel_stopped: bool,
    /// Chunks of the parallel phase inserted by a worker other than their owner (one that
    /// had finished its own share).
    pub stolen_chunks: usize,
    /// Insertions whose cavity boundary had too many vertices for the local-number map and
    /// whose new tets were linked through the directed-edge hash table instead.
    pub large_cavities: usize,
    /// Points merged into a vertex at another position ([`DelaunayOptions::merge_within`]).
    pub merged_near: usize,
    /// Points with a coordinate set to 0 because it was too small next to the largest
    /// coordinate for exact predicates (see [`Delaunay::with_options`]).
    pub snapped: usize,
    /// Wall-clock time of each stage.
    pub times: DelaunayTimes,
}

/// Wall-clock time of the stages of [`Delaunay::with_options`]; their sum is the whole call.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct DelaunayTimes {
    /// Checking the input, merging duplicates and ordering the points for insertion (the
    /// Hilbert sort, the BRIO rounds).
    pub ordering: Duration,
    /// Inserting the points: the tet arena, the first tet, the walks and cavities.
    pub insertion: Duration,
    /// The output: the finite tets in canonical form and order with their neighbours, the
    /// input numbering restored.
    pub output: Duration,
}

/// Options of [`Delaunay::with_options`].
#[derive(Debug, Clone, Copy)]
pub struct DelaunayOptions {
    /// At most this many worker threads (of the current rayon pool); inputs under 8192
    /// points use one.
    pub threads: usize,
    /// Testing aid: make every `n`-th lock attempt of the parallel phase fail as if another
    /// worker held the tet, so that the back-off path runs (0: never).
    pub fail_every_nth_lock: u32,
    /// Testing aid: insert with the portable code even where the CPU has AVX2 (the same
    /// source compiled without it; the result is the same).
    pub portable: bool,
    /// Points within this (Euclidean) distance of the first point of their run in the
    /// sorted order (by Hilbert cell, then position) become one vertex, as exact duplicates
    /// do (0: exact duplicates only, the default). Best effort: points a rounding apart are
    /// nearly always next to each other in that order, but not always (a Hilbert cell's edge
    /// between them); the triangulation of the vertices is exact either way.
    pub merge_within: f64,
}

impl Default for DelaunayOptions {
    fn default() -> Self {
        Self {
            threads: rayon::current_num_threads(),
            fail_every_nth_lock: 0,
            portable: false,
            merge_within: 0.0,
        }
    }
}

/// Whether the insertion runs [`Worker::insert_avx2`]: on x86-64 CPUs with AVX2, unless
/// `opts.portable`.
fn avx2_insertion(opts: &DelaunayOptions) -> bool {
    !opts.portable && crate::cpu::has_avx2()
}

/// SplitMix64: a tiny deterministic generator for the insertion order and walk.
struct SplitMix(u64);
impl SplitMix {
    fn next(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    }
}

/// [`hilbert_index_lanes`] of one point.
#[cfg(test)]
fn hilbert_index(x: [u32; 3], bits: u32) -> u64 {
    hilbert_index_lanes(x.map(|c| [c]), bits)[0]
}

/// Indices of `L` points on the 3D Hilbert curve of order `bits` (at most 21; Skilling's
/// transpose method), coordinate `k` of point `l` at `x[k][l]`.
///
/// Without a branch on the coordinates' bits: they are as often set as not, and the branches
/// of the textbook form (kept in the tests as the reference) were mispredicted half the time.
/// Written lane by lane over arrays, so that the compiler keeps `L` points in one vector
/// register (eight 32-bit lanes with AVX2, see [`hilbert_keys`]).
#[inline(always)]
fn hilbert_index_lanes<const L: usize>(mut x: [[u32; L]; 3], bits: u32) -> [u64; L] {
    let m = 1u32 << (bits - 1);
    let mut q = m;
    while q > 1 {
        let p = q - 1;
        for i in 0..3 {
            for l in 0..L {
                // All ones where bit q of x[i] is set: then x[0] ^= p; else exchange the low
                // bits of x[0] and x[i] (for i = 0, t is 0).
                let set = 0u32.wrapping_sub(u32::from(x[i][l] & q != 0));
                let t = (x[0][l] ^ x[i][l]) & p & !set;
                x[0][l] ^= (p & set) | t;
                x[i][l] ^= t;
            }
        }
        q >>= 1;
    }
    for i in 1..3 {
        for l in 0..L {
            x[i][l] ^= x[i - 1][l];
        }
    }
    let mut t = [0u32; L];
    let mut q = m;
    while q > 1 {
        for l in 0..L {
            t[l] ^= (q - 1) & 0u32.wrapping_sub(u32::from(x[2][l] & q != 0));
        }
        q >>= 1;
    }
    for v in &mut x {
        for l in 0..L {
            v[l] ^= t[l];
        }
    }
    // Interleave the bits, x[0]'s highest: spread each coordinate's bits three apart.
    std::array::from_fn(|l| spread3(x[0][l]) << 2 | spread3(x[1][l]) << 1 | spread3(x[2][l]))
}

/// [`hilbert_index_lanes`] of eight cells, compiled for AVX2 (eight 32-bit lanes; the x86-64
/// baseline, SSE2, has four).
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
fn hilbert_index8_avx2(x: [[u32; 8]; 3], bits: u32) -> [u64; 8] {
    hilbert_index_lanes(x, bits)
}

/// The low 21 bits of `v`, bit `b` moved to bit `3 b` (the usual magic-number spreading).
fn spread3(v: u32) -> u64 {
    let mut v = u64::from(v) & 0x1f_ffff;
    v = (v | v << 32) & 0x001f_0000_0000_ffff;
    v = (v | v << 16) & 0x001f_0000_ff00_00ff;
    v = (v | v << 8) & 0x100f_00f0_0f00_f00f;
    v = (v | v << 4) & 0x10c3_0c30_c30c_30c3;
    v = (v | v << 2) & 0x1249_2492_4924_9249;
    v
}

/// Keys of `pts` along a Hilbert curve on a `2^10`-cell grid over their bounding box (2^10
/// cells per side is finer than any point spacing that matters for locality), each with the
/// point's index. Equal points get equal keys.
fn hilbert_keys(pts: &[[f64; 3]]) -> Vec<(u64, u32)> {
    use rayon::prelude::*;
    const BITS: u32 = 10;
    // The bounding box (min and max are exact, so any grouping gives the same box).
    let (lo, hi) = pts.par_iter().map(|p| (*p, *p)).reduce(
        || ([f64::INFINITY; 3], [f64::NEG_INFINITY; 3]),
        |(l1, h1), (l2, h2)| {
            (
                std::array::from_fn(|k| l1[k].min(l2[k])),
                std::array::from_fn(|k| h1[k].max(h2[k])),
            )
        },
    );
    let scale: [f64; 3] = std::array::from_fn(|k| {
        let e = hi[k] - lo[k];
        if e > 0.0 {
            ((1u32 << BITS) - 1) as f64 / e
        } else {
            0.0
        }
    });
    let cell = |p: &[f64; 3], k: usize| (((p[k] - lo[k]) * scale[k]) as u32).min((1 << BITS) - 1);
    #[cfg(target_arch = "x86_64")]
    let avx2 = crate::cpu::has_avx2();
    // Eight points at a time: the keys of 109k points took 2.4 ms on two threads one by one.
    let mut keys = vec![(0u64, 0u32); pts.len()];
    keys.par_chunks_mut(4096)
        .zip(pts.par_chunks(4096))
        .enumerate()
        .for_each(|(c, (out, pts))| {
            let base = c * 4096;
            for (j, (out, pts)) in out.chunks_mut(8).zip(pts.chunks(8)).enumerate() {
                let x: [[u32; 8]; 3] = std::array::from_fn(|k| {
                    std::array::from_fn(|l| pts.get(l).map_or(0, |p| cell(p, k)))
                });
                #[cfg(target_arch = "x86_64")]
                // SAFETY: the CPU has AVX2 (`cpu::has_avx2`).
                let h = if avx2 {
                    unsafe { hilbert_index8_avx2(x, BITS) }
                } else {
                    hilbert_index_lanes(x, BITS)
                };
                #[cfg(not(target_arch = "x86_64"))]
                let h = hilbert_index_lanes(x, BITS);
                for (l, o) in out.iter_mut().enumerate() {
                    *o = (h[l], (base + 8 * j + l) as u32);
                }
            }
        });
    keys
}

/// `x * 2^k`, exact wherever the result is a normal number or `x` is scaled up (in two
/// steps: `2^k` alone need not be a finite `f64`). `k` within `-1100..=1100`.
fn times_pow2(x: f64, k: i32) -> f64 {
    let pow2 = |j: i32| f64::from_bits(((j + 1023) as u64) << 52);
    let h = k / 2;
    x * pow2(h) * pow2(k - h)
}

/// How the input is brought into the range where the exact predicates' expansions can
/// neither underflow nor overflow: scaled by `2^k` so that the largest coordinate magnitude
/// is in `[1, 2)` (`k = 0` when it is already within `[2^-10, 2^10]`), and every nonzero
/// coordinate below `2^-140` of that set to 0.
///
/// Why this suffices: a nonzero coordinate is then at least `2^-150` in magnitude, so an
/// integer multiple of `2^-202`; the insphere determinant is a polynomial of degree 5 in the
/// coordinates (orient3d: 3), so every product and rounding error in its exact evaluation is
/// a multiple of `2^-1010`, representable (subnormal floats are the multiples of `2^-1074`),
/// and every magnitude stays far below `2^1024`. Scaling by a power of two is exact and
/// multiplies each determinant by a positive power of two: no predicate changes sign, so the
/// triangulation of the scaled points is that of the input.
#[derive(Debug, Clone, Copy)]
struct ExactRange {
    /// The points are multiplied by `2^k`.
    k: i32,
    /// Nonzero coordinates below this (after scaling) are set to 0.
    snap_below: f64,
}

impl ExactRange {
    fn of(points: &[[f64; 3]]) -> Self {
        use rayon::prelude::*;
        // In parallel: the largest of finite numbers is the same in any grouping.
        let m = points
            .par_iter()
            .with_min_len(4096)
            .map(|p| p[0].abs().max(p[1].abs()).max(p[2].abs()))
            .reduce(|| 0.0f64, f64::max);
        if m == 0.0 {
            return Self {
                k: 0,
                snap_below: 0.0,
            };
        }
        let (lo, hi) = (2f64.powi(-10), 2f64.powi(10));
        if (lo..=hi).contains(&m) {
            return Self {
                k: 0,
                snap_below: m * 2f64.powi(-140),
            };
        }
        // floor(log2 m), also for a subnormal m.
        let bits = m.to_bits();
        let biased = ((bits >> 52) & 0x7ff) as i32;
        let e = if biased == 0 {
            -1074 + 63 - (bits & ((1 << 52) - 1)).leading_zeros() as i32
        } else {
            biased - 1023
        };
        Self {
            k: -e,
            snap_below: 2f64.powi(-140),
        }
    }

    /// A length in input units, in the units of the scaled points.
    fn scale(&self, x: f64) -> f64 {
        if self.k == 0 {
            x
        } else {
            times_pow2(x, self.k)
        }
    }

    /// The points as the predicates see them, and how many had a coordinate set to 0.
    /// Borrowed (no copy) when nothing changes: the usual case.
    fn apply<'a>(&self, points: &'a [[f64; 3]]) -> (std::borrow::Cow<'a, [[f64; 3]]>, usize) {
        use rayon::prelude::*;
        let tiny = |x: f64| x != 0.0 && x.abs() < self.snap_below;
        if self.k == 0 && !points.par_iter().any(|p| p.iter().any(|&x| tiny(x))) {
            return (std::borrow::Cow::Borrowed(points), 0);
        }
        let mut snapped = 0;
        let out = points
            .iter()
            .map(|p| {
                let q = p.map(|x| self.scale(x));
                if q.iter().any(|&x| tiny(x)) {
                    snapped += 1;
                    q.map(|x| if tiny(x) { 0.0 } else { x })
                } else {
                    q
                }
            })
            .collect();
        (std::borrow::Cow::Owned(out), snapped)
    }
}

/// The distinct points of an input and their order along the Hilbert curve, from one sort.
struct Distinct {
    /// The distinct points, numbered by the first occurrence of each position in input order.
    vertices: Vec<[f64; 3]>,
    /// For each input point, its vertex.
    vertex_of_point: Vec<u32>,
    /// The vertices along the Hilbert curve with their keys (ties: by position).
    hilbert: Vec<(u64, u32)>,
}

/// Merges exact duplicates (`-0.0` and `0.0` are one position) and orders the distinct
/// points along the Hilbert curve with a single sort by (key, position, input index):
/// duplicates have one key, so they end up next to each other. (Before: a sort by position to
/// merge, then a sort by key of each BRIO round; merging and ordering took 12.9 ms at best at
/// 109k points on two threads, now 10.6, side by side.)
///
/// The runs of merged points are found in one pass over the sorted order (a point joins the
/// run before it if it is at the position of the point before it, or within `merge_within` of
/// the run's first point), but that pass reads points only where a parallel pass found the
/// point before within twice `merge_within` (or at the same position): every point of a run
/// is within `merge_within` of its first one, so two consecutive ones within twice that. Most
/// inputs have no such pair, and then the vertices are the points as they are. (One pass
/// over all the points and a renumbering pass, both on one thread: 3-4 ms of the 109k-point
/// ordering on two threads, see `docs/meshing.md`.)
fn distinct_points(points: &[[f64; 3]], merge_within: f64) -> Distinct {
    use rayon::prelude::*;
    let idx = curve_order(points);
    let near2 = merge_within * merge_within;
    let same_position = |p: &[f64; 3], q: &[f64; 3]| p[0] == q[0] && p[1] == q[1] && p[2] == q[2];
    let dist2 =
        |r: &[f64; 3], q: &[f64; 3]| (0..3).map(|c| (r[c] - q[c]) * (r[c] - q[c])).sum::<f64>();
    let pt = |k: usize| &points[idx[k].1 as usize];
    // Whether sorted position k may join the run before it. (Rounding: the distances are
    // computed to a few ulps, far inside the factor 4.5 against 4.)
    let may_join: Vec<bool> = (0..idx.len())
        .into_par_iter()
        .with_min_len(4096)
        .map(|k| {
            k > 0 && {
                let (p, q) = (pt(k - 1), pt(k));
                same_position(p, q) || (near2 > 0.0 && dist2(p, q) <= 4.5 * near2)
            }
        })
        .collect();
    // The sorted positions that join the run before them, with the run's first position.
    let mut joins: Vec<(u32, u32)> = Vec::new();
    let mut first = 0usize;
    for (k, &may) in may_join.iter().enumerate() {
        let same = may
            && (same_position(pt(k - 1), pt(k))
                || (near2 > 0.0 && dist2(pt(first), pt(k)) <= near2));
        if same {
            joins.push((first as u32, k as u32));
        } else {
            first = k;
        }
    }
    if joins.is_empty() {
        // Every point is a vertex of its own, numbered as in the input.
        return Distinct {
            vertices: points.to_vec(),
            vertex_of_point: (0..points.len() as u32).collect(),
            hilbert: idx,
        };
    }
    // Each merged run becomes one vertex, at its first point in input order (its smallest
    // index); the others are dropped, the vertices keep their input order.
    let mut dropped: Vec<(u32, u32)> = Vec::new();
    for run in joins.chunk_by(|a, b| a.0 == b.0) {
        let members = || {
            std::iter::once(run[0].0)
                .chain(run.iter().map(|j| j.1))
                .map(|k| idx[k as usize].1)
        };
        let keep = members().min().unwrap_or(u32::MAX);
        dropped.extend(members().filter(|&i| i != keep).map(|i| (i, keep)));
    }
    dropped.sort_unstable();
    let mut vertex_of_point: Vec<u32> = (0..points.len() as u32)
        .into_par_iter()
        .map(|i| i - dropped.partition_point(|d| d.0 < i) as u32)
        .collect();
    for &(i, keep) in &dropped {
        vertex_of_point[i as usize] = vertex_of_point[keep as usize];
    }
    let vertices: Vec<[f64; 3]> = points
        .par_iter()
        .enumerate()
        .filter(|&(i, _)| dropped.binary_search_by_key(&(i as u32), |d| d.0).is_err())
        .map(|(_, p)| *p)
        .collect();
    let mut joined = vec![false; idx.len()];
    for &(_, k) in &joins {
        joined[k as usize] = true;
    }
    // The runs in curve order, each with the key of its first point.
    let hilbert = idx
        .par_iter()
        .zip(&joined)
        .filter(|&(_, &j)| !j)
        .map(|(&(key, i), _)| (key, vertex_of_point[i as usize]))
        .collect();
    Distinct {
        vertices,
        vertex_of_point,
        hilbert,
    }
}

/// The points' Hilbert keys with their indices, sorted by (key, position, index): equal
/// positions (`-0.0` and `0.0` as one) are next to each other.
fn curve_order(points: &[[f64; 3]]) -> Vec<(u64, u32)> {
    use rayon::prelude::*;
    let mut idx = hilbert_keys(points);
    // `+ 0.0` turns -0.0 into 0.0: the same position must sort as one.
    let position = |i: u32| points[i as usize].map(|c| c + 0.0);
    idx.par_sort_unstable_by(|&(ka, a), &(kb, b)| {
        ka.cmp(&kb).then_with(|| {
            let (p, q) = (position(a), position(b));
            p[0].total_cmp(&q[0])
                .then(p[1].total_cmp(&q[1]))
                .then(p[2].total_cmp(&q[2]))
                .then(a.cmp(&b))
        })
    });
    idx
}

/// Biased randomised insertion order of `n` vertices: rounds growing eightfold (the last holds
/// 7/8 of the vertices), each along the Hilbert curve (`hilbert`: all vertices in curve
/// order with their keys); ties (one Hilbert cell) keep the shuffled order. Fewer, larger
/// rounds than BRIO's doubling mean fewer passes over the whole domain, so the tets a round
/// touches are more often in cache (measured: about 8% faster on 100k surface points, the
/// same on 10k).
/// Returns the order and the start of each round, ascending, followed by `n`.
fn brio_order(hilbert: &[(u64, u32)]) -> (Vec<u32>, Vec<usize>) {
    let n = hilbert.len();
    let mut order: Vec<u32> = (0..n as u32).collect();
    let mut rng = SplitMix(0x005E_ED0F_D3A1);
    for i in (1..order.len()).rev() {
        let j = (rng.next() % (i as u64 + 1)) as usize;
        order.swap(i, j);
    }
    let mut end = n;
    let mut rounds = vec![end];
    while end > 0 {
        let start = if end <= 64 { 0 } else { end / 8 };
        rounds.push(start);
        end = start;
    }
    rounds.reverse();
    // A vertex's round is where the shuffle put it; each round is then filled in curve order
    // (a counting sort by round of the curve order), ties in the shuffled order: the order
    // one sort of each round by (key, shuffled position) gave, so the same tets come out in
    // the same order as from that.
    let mut shuffled = vec![0u32; n];
    for (j, &v) in order.iter().enumerate() {
        shuffled[v as usize] = j as u32;
    }
    let mut curve: Vec<u32> = Vec::with_capacity(n);
    for run in hilbert.chunk_by(|a, b| a.0 == b.0) {
        let start = curve.len();
        curve.extend(run.iter().map(|&(_, v)| v));
        if run.len() > 1 {
            curve[start..].sort_unstable_by_key(|&v| shuffled[v as usize]);
        }
    }
    let round_of = |v: u32| {
        let j = shuffled[v as usize] as usize;
        rounds.partition_point(|&r| r <= j) - 1
    };
    let mut next: Vec<usize> = rounds[..rounds.len() - 1].to_vec();
    for v in curve {
        let r = round_of(v);
        order[next[r]] = v;
        next[r] += 1;
    }
    (order, rounds)
}

/// Moves the vertices extreme along the eight diagonal directions `(±1, ±1, ±1)` (hull
/// vertices: the corners of an enclosing box, when there is one) to the front of the insertion
/// order `order`, shifting the round starts `rounds` (as [`brio_order`] returns them) to match.
/// Inserted late, such a vertex conflicts with the long tets along the hull: each of the
/// mesher's eight protective corners replaced 2k-11k tets at once (40k in all at 109k
/// points), in large cavities that hold many tets' locks and need the hashed linking. The
/// triangulation does not depend on the order (ties are broken by input numbers).
fn extremes_first(vertices: &[[f64; 3]], order: &mut Vec<u32>, rounds: &mut [usize]) {
    use rayon::prelude::*;
    // The largest `±x ± y ± z` per direction, the smallest index among equal values.
    let better = |a: (f64, u32), b: (f64, u32)| {
        if b.0 > a.0 || (b.0 == a.0 && b.1 < a.1) {
            b
        } else {
            a
        }
    };
    let none = [(f64::NEG_INFINITY, u32::MAX); 8];
    // Each fold sees its points in increasing index order, so a strictly larger value is
    // the only one to take there (without a branch: eight selects per point); the reduce
    // breaks ties between folds by index.
    let best = vertices
        .par_iter()
        .with_min_len(4096)
        .enumerate()
        .fold(
            || ([f64::NEG_INFINITY; 8], [u32::MAX; 8]),
            |(mut value, mut index), (i, p)| {
                for d in 0..8 {
                    let s = |k: usize| if (d >> k) & 1 == 1 { p[k] } else { -p[k] };
                    let v = s(0) + s(1) + s(2);
                    let take = v > value[d];
                    value[d] = if take { v } else { value[d] };
                    index[d] = if take { i as u32 } else { index[d] };
                }
                (value, index)
            },
        )
        .map(|(value, index)| std::array::from_fn(|d| (value[d], index[d])))
        .reduce(|| none, |a, b| std::array::from_fn(|d| better(a[d], b[d])));
    let mut extreme: Vec<u32> = best
        .iter()
        .map(|b| b.1)
        .filter(|&v| v != u32::MAX)
        .collect();
    extreme.sort_unstable();
    extreme.dedup();
    // Their places in the order (at most eight: a scan of the order in parallel, then copies
    // of the stretches between them).
    let moved: Vec<usize> = order
        .par_iter()
        .enumerate()
        .filter(|&(_, v)| extreme.contains(v))
        .map(|(j, _)| j)
        .collect();
    move_to_front(order, rounds, &moved);
}

/// Moves the vertices at the (increasing) places `moved` of `order` to its front, in that
/// order, the others keeping theirs; shifts the round starts `rounds` to match.
fn move_to_front(order: &mut Vec<u32>, rounds: &mut [usize], moved: &[usize]) {
    // A round that started at `r > 0` now starts after all moved vertices and the others
    // before `r`.
    for r in rounds.iter_mut().filter(|r| **r > 0) {
        *r += moved.iter().filter(|&&j| j >= *r).count();
    }
    let mut moved_first = Vec::with_capacity(order.len());
    moved_first.extend(moved.iter().map(|&j| order[j]));
    let mut from = 0;
    for &j in moved {
        moved_first.extend_from_slice(&order[from..j]);
        from = j + 1;
    }
    moved_first.extend_from_slice(&order[from..]);
    *order = moved_first;
}

/// Moves four affinely independent vertices (exactly: the first in `order` that are, as
/// [`Builder::new`]'s first tet needs) to the front of `order`, shifting `rounds` to match;
/// `false` (nothing moved) when the vertices span no volume (all on one plane). After
/// [`extremes_first`] the first four of the order almost always are.
fn independent_first(vertices: &[[f64; 3]], order: &mut Vec<u32>, rounds: &mut [usize]) -> bool {
    let p = |j: usize| &vertices[order[j] as usize];
    // The vertices are distinct (duplicates merged), so the second one differs from the first.
    if order.len() < 4 {
        return false;
    }
    let Some(c) = (2..order.len()).find(|&j| !collinear(p(0), p(1), p(j))) else {
        return false;
    };
    let Some(d) = (c + 1..order.len()).find(|&j| orient3d(p(0), p(1), p(c), p(j)) != 0) else {
        return false;
    };
    if (c, d) != (2, 3) {
        move_to_front(order, rounds, &[0, 1, c, d]);
    }
    true
}

impl Delaunay {
    /// Triangulates `points`. Exact duplicates are merged (see [`Delaunay::vertex_of_point`]).
    /// Fewer than four affinely independent points give a triangulation without tets.
    ///
    /// Any finite coordinates work, tiny or huge: the predicates run on the points scaled by
    /// a power of two (exact, and no sign changes) where their products cannot underflow or
    /// overflow. A nonzero coordinate below 2^-140 of the largest coordinate magnitude (a
    /// subnormal next to 1, say) is set to 0 first (the point is then counted in
    /// [`DelaunayStats::snapped`], and may become a copy of another): its products would
    /// underflow. The vertices are the input points (with such coordinates at 0).
    ///
    /// # Errors
    /// [`Error::InvalidInput`] for a non-finite coordinate or 2^28 points or more.
    pub fn new(points: &[[f64; 3]]) -> Result<Self> {
        Self::with_threads(points, rayon::current_num_threads())
    }

    /// [`Delaunay::new`] with at most `threads` worker threads (of the current rayon pool).
    /// The result does not depend on `threads`: the symbolically perturbed Delaunay
    /// triangulation is unique, so every insertion order gives the same tets.
    ///
    /// # Errors
    /// As [`Delaunay::new`].
    pub fn with_threads(points: &[[f64; 3]], threads: usize) -> Result<Self> {
        Self::with_options(
            points,
            &DelaunayOptions {
                threads,
                ..Default::default()
            },
        )
    }

    /// [`Delaunay::new`] with options.
    ///
    /// # Errors
    /// As [`Delaunay::new`].
    pub fn with_options(points: &[[f64; 3]], opts: &DelaunayOptions) -> Result<Self> {
        use rayon::prelude::*;
        let start = Instant::now();
        // Tet slots and the vertices' stamps are `u32` (see `MAX_POINTS`).
        if points.len() >= MAX_POINTS {
            return Err(Error::InvalidInput(format!(
                "{} points is more than the triangulation supports",
                points.len()
            )));
        }
        if let Some(i) = points
            .par_iter()
            .with_min_len(4096)
            .position_first(|p| p.iter().any(|c| !c.is_finite()))
        {
            return Err(Error::InvalidInput(format!(
                "point {i} = {:?} is not finite",
                points[i]
            )));
        }
        let exact = ExactRange::of(points);
        let (points, snapped) = exact.apply(points);
        let Distinct {
            mut vertices,
            vertex_of_point,
            hilbert,
        } = distinct_points(&points, exact.scale(opts.merge_within.max(0.0)));
        // Number the vertices in insertion order inside the builder, so that consecutive
        // insertions touch neighbouring memory; `finish` maps the numbers back.
        let (mut order, mut rounds) = brio_order(&hilbert);
        extremes_first(&vertices, &mut order, &mut rounds);
        let spans = independent_first(&vertices, &mut order, &mut rounds);
        let capacity = 8 * vertices.len() + 4096 * (opts.threads.clamp(1, 64) + 1);
        let parallel = in_parallel(opts.threads, vertices.len());
        let mut times = DelaunayTimes {
            ordering: start.elapsed(),
            ..Default::default()
        };
        let t = Instant::now();
        // In parallel (a gather through the insertion order).
        let mut sorted: Vec<[f64; 3]> = Vec::with_capacity(order.len() + 1);
        order
            .par_iter()
            .map(|&i| vertices[i as usize])
            .collect_into_vec(&mut sorted);
        let mut dt = Builder::new(sorted, order, capacity, parallel, spans)?.run(&rounds, opts);
        // `finish` timed the output stage.
        times.output += dt.stats.times.output;
        times.insertion += t.elapsed() - dt.stats.times.output;
        let t = Instant::now();
        if opts.merge_within > 0.0 {
            dt.stats.merged_near = points
                .iter()
                .zip(&vertex_of_point)
                .filter(|&(p, &v)| {
                    let q = &vertices[v as usize];
                    p[0] != q[0] || p[1] != q[1] || p[2] != q[2]
                })
                .count();
        }
        dt.stats.snapped = snapped;
        if exact.k != 0 {
            vertices
                .par_iter_mut()
                .for_each(|p| *p = p.map(|x| times_pow2(x, -exact.k)));
        }
        dt.vertices = vertices;
        dt.vertex_of_point = vertex_of_point;
        times.output += t.elapsed();
        dt.stats.times = times;
        Ok(dt)
    }

    /// For every vertex, one tet incident to it (or [`NONE`] for a vertex in no tet).
    pub fn vertex_to_tet(&self) -> Vec<u32> {
        let mut v2t = vec![NONE; self.vertices.len()];
        for (t, tet) in self.tets.iter().enumerate() {
            for &v in tet {
                v2t[v as usize] = t as u32;
            }
        }
        v2t
    }
}

/// A tet of the builder: vertices, neighbours and the insertion stamp, kept together so that
/// the cavity search touches one tet's 36 bytes at a time.
///
/// Worker threads share the tets; in the parallel phase a thread writes a tet, or reads it
/// for an insertion, only while it holds the slot's lock ([`Shared::locks`], apart from the
/// tets; no waiting: a busy lock makes the insertion back off). The fields are atomics so
/// that this needs no `unsafe`; relaxed accesses are plain loads and stores.
///
/// All-zero bytes are a free slot ([`DEAD`]). The parallel phase's arena is allocated zeroed:
/// fresh pages from the system cost nothing until a worker first uses them, and slots never
/// used are never touched (filling a 30 MB arena up front took 20-30 ms of one thread at 100k
/// points). One thread writes its free slots a block at a time instead ([`Builder::new`]).
#[derive(bytemuck::Zeroable)]
struct Tet {
    v: [AtomicU32; 4],
    n: [AtomicU32; 4],
    /// [`DEAD`] for a free slot, else [`NO_STAMP`] or an insertion's stamp ([`Stamps`]).
    mark: AtomicU32,
}

impl Tet {
    fn dead() -> Self {
        bytemuck::Zeroable::zeroed()
    }
    #[inline]
    fn verts(&self) -> [u32; 4] {
        [0, 1, 2, 3].map(|k| self.v[k].load(Relaxed))
    }
    #[inline]
    fn nbrs(&self) -> [u32; 4] {
        [0, 1, 2, 3].map(|k| self.n[k].load(Relaxed))
    }
    #[inline]
    fn mark(&self) -> u32 {
        self.mark.load(Relaxed)
    }
    #[inline]
    fn set_mark(&self, m: u32) {
        self.mark.store(m, Relaxed);
    }
    #[inline]
    fn set_nbr(&self, k: usize, t: u32) {
        self.n[k].store(t, Relaxed);
    }
}

/// The mark of a free slot (all-zero bytes, see [`Tet`]).
const DEAD: u32 = 0;
/// The mark of a live tet that carries no stamp of the insertion holding it.
const NO_STAMP: u32 = 1;

/// `APEX_FACE[k]`: the positions of the face opposite position `k`, ordered so that the
/// vertex at `k` is on the face's positive side (`(APEX_FACE[k], k)` is an even permutation of
/// `0..4`, so for a positively oriented tet `orient3d(face..., t[k]) > 0`).
const APEX_FACE: [[usize; 3]; 4] = [[1, 3, 2], [0, 2, 3], [0, 3, 1], [0, 1, 2]];

/// The three directed edges `(i, j)` of a boundary face, as indices into its
/// [`APEX_FACE`] order, each with the index of the face's third vertex: a new tet shares with
/// the new tet across edge `(i, j)` its face opposite `APEX_FACE[k][third]`.
const FACE_EDGES: [(usize, usize, usize); 3] = [(0, 1, 2), (1, 2, 0), (2, 0, 1)];

/// Cavities whose boundary has at most this many vertices are linked by
/// [`Worker::link_small`] (a Delaunay cavity in 3D has about 16 on average).
const SMALL_CAVITY: usize = 32;

/// The stamps an insertion puts on the tets it looks at (see [`Tet::mark`]): distinct for
/// each vertex, and never [`DEAD`] or [`NO_STAMP`].
#[derive(Debug, Clone, Copy)]
struct Stamps {
    /// In the cavity (in conflict with the new vertex).
    in_cavity: u32,
    /// Next to the cavity and not in conflict.
    outside: u32,
    /// Next to the cavity, its conflict test not yet done.
    waiting: u32,
}

impl Stamps {
    /// The stamps of vertex `v` (`3v + 2`, `3v + 3`, `3v + 4`: there are fewer than
    /// [`MAX_POINTS`] vertices, so they fit in a `u32`).
    #[inline(always)]
    fn of(v: u32) -> Self {
        Self {
            in_cavity: 3 * v + 2,
            outside: 3 * v + 3,
            waiting: 3 * v + 4,
        }
    }
}

/// The face of tet `nt` that looks back at its neighbour `c` (adjacency is symmetric).
#[inline(always)]
fn back_face(nt: &Tet, c: u32) -> u8 {
    let nn = nt.nbrs();
    let j = (nn[1] == c) as u8 + 2 * (nn[2] == c) as u8 + 3 * (nn[3] == c) as u8;
    debug_assert_eq!(nn[j as usize], c, "adjacency is symmetric");
    j
}

/// A slot of a worker's directed-edge table (see [`Worker::link_hashed`]).
#[derive(Debug, Clone, Copy, Default)]
struct EdgeSlot {
    key: u64,
    tet: u32,
    generation: u32,
}

/// The key of the directed edge `x -> y`.
#[inline(always)]
fn edge_key(x: u32, y: u32) -> u64 {
    ((x as u64) << 32) | y as u64
}

/// The most points a triangulation takes: the tet arena starts at 8 slots per point (2^31 at
/// this limit, 77 GB) and grows by half when it must, and slot numbers stay below [`NONE`];
/// the stamps ([`Stamps::of`]) fit in a `u32` far beyond.
const MAX_POINTS: usize = 1 << 28;

/// Makes room for `n` more items in `v` (for [`push_if_in_room`]).
#[inline(always)]
fn make_room<T>(v: &mut Vec<T>, n: usize) {
    if v.capacity() - v.len() < n {
        v.reserve(n.max(64));
    }
}

/// Writes `x` after the last item of `v` and keeps it only if `keep`: a conditional push
/// without a branch on `keep`, and without a capacity check (measured: 2-3% of a one-thread
/// insertion against `Vec::push` and `Vec::truncate`).
///
/// # Safety
/// `v` must have room for one more item ([`make_room`]).
#[inline(always)]
unsafe fn push_if_in_room<T: Copy>(v: &mut Vec<T>, x: T, keep: bool) {
    let len = v.len();
    debug_assert!(len < v.capacity());
    // SAFETY: `len < capacity` (this function's contract): the write is to the vector's own
    // spare room, and the length grows over it only once it is written.
    unsafe {
        v.as_mut_ptr().add(len).write(x);
        v.set_len(len + keep as usize);
    }
}

/// The free slots a one-thread insertion writes at a time when it runs out (147 KB: they are
/// filled by the next ~600 insertions while still in the cache; see [`Builder::new`]).
const FRESH_BLOCK: usize = 4096;

/// Inputs smaller than this are triangulated by one thread.
const PARALLEL_MIN_POINTS: usize = 8192;

/// Whether `n` distinct points are inserted by `threads` workers (see [`Builder::run`]).
fn in_parallel(threads: usize, n: usize) -> bool {
    threads.clamp(1, 64) > 1 && n >= PARALLEL_MIN_POINTS
}

/// Why an insertion backed off (nothing was changed).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Fail {
    /// A tet it needed is held by another worker.
    Busy,
    /// The worker ran out of free tet slots.
    NoSpace,
}

/// What the workers share: the points (numbered in insertion order) and the tet arena.
struct Shared<'a> {
    pos: &'a [[f64; 3]],
    /// Input number of each real vertex (the infinite vertex, numbered past them, is in no
    /// perturbed test: see [`Shared::infinite_conflict`]).
    rank: &'a [u32],
    tets: &'a [Tet],
    n_real: u32,
    /// Static insphere bound for tets of real vertices only (their differences are bounded by
    /// the extent of the input).
    static_eps: f64,
    /// Static orientation bound, likewise.
    static_orient_eps: f64,
    /// Never-used slots for the parallel phase, handed out in blocks: the next one is
    /// `pool.load()`, the last one `tets.len() - 1`.
    pool: Option<&'a AtomicUsize>,
    /// Parallel phase: the lock of each slot, 0 when free, else the id of the worker holding
    /// it (see [`Worker::try_lock`]).
    locks: &'a [AtomicU32],
}

/// Slots a worker takes from the shared pool at a time.
const POOL_BLOCK: usize = 2048;

/// Vertices a worker claims at a time in the parallel phase (see [`Builder::run`]).
const CHUNK: usize = 256;

/// The workers stop claiming chunks once at least [`STOP_MIN_ATTEMPTS`] insertions have been
/// tried and more than one in `STOP_BACKOFF_RATIO` backed off: two workers whose cavities keep
/// overlapping are slower than one (20k points on a flat paraboloid cap: 2.5x slower, with
/// 7,283 vertices backed off twice), and the rest is then inserted by one thread. On the
/// mesher's inputs about one insertion in 1,000 backs off.
const STOP_BACKOFF_RATIO: usize = 8;
/// See [`STOP_BACKOFF_RATIO`].
const STOP_MIN_ATTEMPTS: usize = 1024;

impl Shared<'_> {
    #[inline]
    fn p(&self, v: u32) -> &[f64; 3] {
        &self.pos[v as usize]
    }

    /// Whether all four vertices are real: a finite tet, not an infinite one (whose
    /// infinite vertex is numbered `n_real`, see [`Builder::new`]).
    #[inline(always)]
    fn real(&self, tv: [u32; 4]) -> bool {
        tv[0].max(tv[1]).max(tv[2].max(tv[3])) < self.n_real
    }

    /// The position of the infinite vertex in infinite tet `tv`.
    #[inline]
    fn inf_at(&self, tv: [u32; 4]) -> usize {
        (0..4).find(|&k| tv[k] >= self.n_real).unwrap_or(3)
    }

    /// The orientation of infinite tet `tv` with its infinite vertex replaced by the real
    /// point `p`: positive where `p` is strictly beyond its finite face (the hull face).
    #[inline]
    fn beyond_hull_face(&self, tv: [u32; 4], p: &[f64; 3]) -> i32 {
        let k = self.inf_at(tv);
        let q = [0, 1, 2, 3].map(|j| if j == k { p } else { self.p(tv[j]) });
        orient3d(q[0], q[1], q[2], q[3])
    }

    /// Whether tet `tv` holds the real point `p`: a finite tet, in its closed volume (no face
    /// sees `p` from behind); an infinite tet, strictly beyond its hull face (so that it is
    /// in conflict with `p`).
    fn holds(&self, tv: [u32; 4], p: &[f64; 3]) -> bool {
        if self.real(tv) {
            (0..4).all(|k| self.face_sees(tv, k, p) >= 0)
        } else {
            self.beyond_hull_face(tv, p) > 0
        }
    }

    /// Whether infinite tet `tv` is in conflict with vertex `v` (CGAL's rule for its
    /// infinite vertex): `v` strictly beyond the tet's hull face; or on the face's plane and
    /// strictly inside its circumcircle, ties broken by the perturbation of the finite tets.
    /// On the plane this is the test of a finite tet through the face and any point `w` on
    /// the inner side: its circumsphere meets the plane in the face's circumcircle, and in
    /// the perturbation `w`'s term vanishes (`v` on the face's plane) while the others are
    /// orientations of planes that are the face's, so they depend on `w`'s side only (the
    /// finite tet across the face gives the same answer; this needs no look at it, so no
    /// lock).
    #[cold]
    #[inline(never)]
    fn infinite_conflict(&self, tv: [u32; 4], v: u32) -> bool {
        let p = self.p(v);
        let o = self.beyond_hull_face(tv, p);
        if o != 0 {
            return o > 0;
        }
        let k = self.inf_at(tv);
        let f = APEX_FACE[k].map(|q| *self.p(tv[q]));
        // A point well inside: the face's first vertex moved along an axis by the face's size
        // plus the coordinate's magnitude (so that the coordinate does change, however far
        // from 0 the face is), the axis nearest the face's normal first (as computed; `w` has
        // the face's coordinates but one, which keeps the exact stages on their fast paths),
        // whichever way is exactly on the inner side (orientation negative with `w` in the
        // infinite vertex's place). Some axis is not parallel to the face, and one of its two
        // ways is inside.
        let (u, w) = (vec3::sub(f[1], f[0]), vec3::sub(f[2], f[0]));
        let n = vec3::cross(u, w);
        let size = (0..3)
            .map(|j| u[j].abs().max(w[j].abs()))
            .fold(0.0f64, f64::max);
        let mut axes = [0, 1, 2];
        axes.sort_by(|&x, &y| n[y].abs().total_cmp(&n[x].abs()));
        let inner = axes
            .iter()
            .flat_map(|&j| {
                let d = size + f[0][j].abs();
                [d, -d].map(|d| {
                    let mut w = f[0];
                    w[j] += d;
                    w
                })
            })
            .find(|w| {
                let q = [0, 1, 2, 3].map(|j| if j == k { w } else { self.p(tv[j]) });
                orient3d(q[0], q[1], q[2], q[3]) < 0
            });
        let Some(w) = inner else {
            // Only for a flat hull face, which the triangulation never has.
            unreachable!("no point inside the hull face of {tv:?}");
        };
        // The finite tet: `w` in the infinite vertex's place, two vertices swapped to make it
        // positive; `w` ranks after every vertex (its term vanishes either way).
        let mut ft = [0, 1, 2, 3].map(|j| if j == k { &w } else { self.p(tv[j]) });
        let rank = |x: u32| self.rank.get(x as usize).copied().unwrap_or(x);
        let mut ranks = [0, 1, 2, 3].map(|j| if j == k { u32::MAX } else { rank(tv[j]) });
        // The first two positions other than `k`.
        let (a, b) = if k <= 1 { (1 - k, 2) } else { (0, 1) };
        ft.swap(a, b);
        ranks.swap(a, b);
        in_conflict_bounded(ft, || (ranks, rank(v)), p, f64::INFINITY)
    }

    /// The orientation of tet `tv` with its vertex `k` replaced by the real point `p`.
    #[inline]
    fn face_sees(&self, tv: [u32; 4], k: usize, p: &[f64; 3]) -> i32 {
        let mut q = [self.p(tv[0]), self.p(tv[1]), self.p(tv[2]), self.p(tv[3])];
        q[k] = p;
        orient3d_bounded(q[0], q[1], q[2], q[3], self.orient_eps(tv))
    }

    /// The static orientation bound for tet `tv` with one vertex replaced by a real point:
    /// [`Shared::static_orient_eps`] when all its vertices are real, else none.
    #[inline(always)]
    fn orient_eps(&self, tv: [u32; 4]) -> f64 {
        if self.real(tv) {
            self.static_orient_eps
        } else {
            f64::INFINITY
        }
    }

    /// The static conflict tests of four tets (by their vertices) against vertex `v`, one per
    /// lane ([`insphere_static_lanes`]); with `AVX2` ([`insphere_static4_avx2`]) the points go
    /// from `pos` into the lanes with no copy in between. The same bits either way.
    #[inline(always)]
    fn conflict_lanes<const AVX2: bool>(
        &self,
        ids: &[[u32; 4]; 4],
        v: u32,
        eps: &[f64; 4],
    ) -> ([i32; 4], [f64; 4]) {
        #[cfg(target_arch = "x86_64")]
        if AVX2 {
            // SAFETY: `AVX2` is set only by `Worker::insert_avx2`, which runs only where the
            // CPU has AVX2.
            return unsafe { insphere_static4_avx2(self.pos, ids, self.p(v), eps) };
        }
        let pts = ids.map(|tv| tv.map(|x| *self.p(x)));
        insphere_static_lanes(&pts, self.p(v), eps)
    }

    /// Whether tet `tv` is in conflict with vertex `v` (its circumsphere strictly contains
    /// `v`, ties broken symbolically), once the static bound of [`insphere_static_lanes`] has
    /// not decided, from the determinant it computed (rare: ties, and the infinite tets,
    /// whose bound is infinite: [`Shared::infinite_conflict`]).
    #[inline(never)]
    fn conflicts_past_static(&self, tv: [u32; 4], v: u32, det: f64) -> bool {
        if !self.real(tv) {
            return self.infinite_conflict(tv, v);
        }
        // Ties are broken by the input numbering, not the insertion order, so that the
        // result does not depend on how the points are scheduled.
        let rank = |x: u32| self.rank.get(x as usize).copied().unwrap_or(x);
        in_conflict_past_static(
            [self.p(tv[0]), self.p(tv[1]), self.p(tv[2]), self.p(tv[3])],
            || (tv.map(rank), rank(v)),
            self.p(v),
            det,
        )
    }
}

/// One inserting thread: its free slots and scratch space. With `PAR = false` it is the only
/// thread and takes no locks.
struct Worker {
    /// Lock id (>= 1).
    id: u32,
    /// Free tet slots owned by this worker.
    free: Vec<u32>,
    /// Never-used slots reserved for this worker (`fresh.0..fresh.1`).
    fresh: (u32, u32),
    /// A tet made by the last insertion (the start of the next walk).
    last: u32,
    /// Vertices this worker backed off from.
    deferred: Vec<u32>,
    /// Chunks this worker took from other workers' queues.
    stolen: usize,
    /// First attempts of this worker that backed off.
    backed_off: usize,
    /// Insertions linked by [`Worker::link_hashed`].
    large_cavities: usize,
    /// Testing aid: every `n`-th lock attempt fails (0: never).
    fail_every: u32,
    /// Insert with [`Worker::insert_avx2`] (only set where the CPU has AVX2).
    #[cfg_attr(not(target_arch = "x86_64"), allow(dead_code))]
    avx2: bool,
    lock_attempts: u32,
    rng: SplitMix,
    /// Cavity tets still to look around, each with the face it was entered through.
    stack: Vec<(u32, u8)>,
    /// Faces of cavity tets whose neighbour was waiting for its conflict test (queued from
    /// another cavity tet): boundary faces if that neighbour turns out not in conflict.
    later: Vec<(u32, u8, u32)>,
    cavity: Vec<u32>,
    /// Slots locked by the current insertion (parallel phase).
    held: Vec<u32>,
    boundary: Vec<(u32, u8, u32, u8)>,
    new_tets: Vec<([u32; 4], u32, u8)>,
    /// Slots taken from `free` / `fresh` for the current insertion.
    taken: Vec<u32>,
    /// Open-addressing table directed edge -> new tet for linking the new tets. An entry
    /// belongs to the current insertion only if its generation is `generation`, so the table
    /// is never cleared (but when the generation wraps around).
    table: Vec<EdgeSlot>,
    generation: u32,
    /// The first slot of each vertex of the cavity boundary (see [`Worker::link_small`]),
    /// indexed by vertex; only the entries of the current boundary mean anything.
    local_id: Vec<u8>,
    /// `edge_map[x * SMALL_CAVITY + y]`: the new tet with the directed edge `x -> y`.
    edge_map: Box<[u32; SMALL_CAVITY * SMALL_CAVITY]>,
}

impl Worker {
    fn new(id: u32, seed: u64) -> Self {
        Self {
            id,
            free: Vec::new(),
            fresh: (0, 0),
            last: 0,
            deferred: Vec::new(),
            stolen: 0,
            backed_off: 0,
            large_cavities: 0,
            fail_every: 0,
            avx2: false,
            lock_attempts: 0,
            rng: SplitMix(seed),
            stack: Vec::new(),
            later: Vec::new(),
            cavity: Vec::new(),
            held: Vec::new(),
            boundary: Vec::new(),
            new_tets: Vec::new(),
            taken: Vec::new(),
            table: vec![EdgeSlot::default(); 256],
            generation: 0,
            local_id: Vec::new(),
            edge_map: Box::new([0; SMALL_CAVITY * SMALL_CAVITY]),
        }
    }

    /// Takes a block of never-used slots from the shared pool (parallel phase only).
    fn refill(&mut self, sh: &Shared) -> bool {
        let Some(pool) = sh.pool else {
            return false;
        };
        let start = pool.fetch_add(POOL_BLOCK, Relaxed);
        let end = (start + POOL_BLOCK).min(sh.tets.len());
        if start >= end {
            return false;
        }
        self.fresh = (start as u32, end as u32);
        true
    }

    /// Makes sure this worker holds the lock of slot `t`: `true` if it did already or takes
    /// it now, `false` if another worker holds it (nothing waits).
    #[inline]
    fn try_lock<const PAR: bool>(&mut self, sh: &Shared, t: u32) -> bool {
        if !PAR {
            return true;
        }
        let lock = &sh.locks[t as usize];
        // Only this worker writes its own id: reading it means the slot is ours.
        if lock.load(Relaxed) == self.id {
            return true;
        }
        if self.fail_every > 0 {
            self.lock_attempts += 1;
            if self.lock_attempts.is_multiple_of(self.fail_every) {
                return false;
            }
        }
        let ok = lock.compare_exchange(0, self.id, Acquire, Relaxed).is_ok();
        if ok {
            self.held.push(t);
        }
        ok
    }

    /// Lets go of every slot this worker holds.
    #[inline]
    fn unlock_all<const PAR: bool>(&mut self, sh: &Shared) {
        if PAR {
            for &t in &self.held {
                sh.locks[t as usize].store(0, Release);
            }
        }
        self.held.clear();
    }

    /// A live tet to start a walk from: the last one made, or (in parallel, when another
    /// worker has removed it) one of the slots before it, which this worker filled recently.
    /// In parallel the tet is not locked, so it may be gone by the time the walk reads it;
    /// the walk's end is checked under lock.
    fn start<const PAR: bool>(&self, sh: &Shared) -> Option<u32> {
        let len = sh.tets.len() as u32;
        let tries = if PAR { 256 } else { 1 };
        (0..tries)
            .map(|i| (self.last + len - i % len) % len)
            .find(|&t| sh.tets[t as usize].mark() != DEAD)
    }

    /// Stochastic visibility walk from `t` towards `p`; returns the tet where no face sees
    /// `p` from behind. In parallel the tets are read without locks: another worker may be
    /// changing them, so the result is only a candidate (see [`Worker::locate`]).
    fn walk<const PAR: bool>(&mut self, sh: &Shared, t: u32, p: &[f64; 3]) -> Option<u32> {
        #[cfg(target_arch = "x86_64")]
        {
            if self.avx2 {
                // SAFETY: the CPU has AVX2 (`avx2` is only set when it does).
                return unsafe { self.walk_avx2::<PAR>(sh, t, p) };
            }
        }
        self.walk_body::<PAR, false>(sh, t, p)
    }

    /// [`Worker::walk`] with AVX2: the four faces of a tet are tested together
    /// ([`orient3d_faces_avx2`]), then the first face in the walk's random order that sees
    /// `p` from behind is taken without a branch per face (each face's sign goes either way
    /// about as often). Where the static bound decides every open face, the same face is
    /// chosen as one by one; where it does not, a decided face that sees `p` goes first (see
    /// the body), so the walk may differ there, and ends in a tet containing `p` all the same.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2")]
    fn walk_avx2<const PAR: bool>(&mut self, sh: &Shared, t: u32, p: &[f64; 3]) -> Option<u32> {
        self.walk_body::<PAR, true>(sh, t, p)
    }

    #[inline(always)]
    fn walk_body<const PAR: bool, const AVX2: bool>(
        &mut self,
        sh: &Shared,
        mut t: u32,
        p: &[f64; 3],
    ) -> Option<u32> {
        let mut prev = NONE;
        let max_steps = if PAR {
            (64 + 4 * sh.tets.len()).min(1 << 16)
        } else {
            64 + 4 * sh.tets.len()
        };
        for step in 0..max_steps {
            let tet = &sh.tets[t as usize];
            let (tv, tn) = (tet.verts(), tet.nbrs());
            // An infinite tet (rare; with AVX2 it is found where its faces are undecided, off
            // the common path): entered through its hull face, which sees `p` from behind, it
            // is in conflict with `p` (strictly beyond the face), the walk's end; at the
            // start, the walk goes on from the finite tet across that face.
            macro_rules! infinite_tet {
                () => {
                    if step > 0 {
                        return Some(t);
                    }
                    let f = tn[sh.inf_at(tv)];
                    if f == NONE {
                        return None;
                    }
                    t = f;
                    continue;
                };
            }
            let r = (self.rng.next() & 3) as usize;
            #[cfg(target_arch = "x86_64")]
            if AVX2 {
                // The faces the walk may cross: not the hull, not back.
                let open = (0..4).fold(0u32, |m, k| {
                    m | (((tn[k] != NONE) & (tn[k] != prev)) as u32) << k
                });
                let eps = sh.orient_eps(tv);
                // SAFETY: `AVX2` is set only by `walk_avx2`, which runs only where the CPU
                // has AVX2.
                let (negative, undecided) =
                    unsafe { orient3d_faces_avx2(tv.map(|x| sh.p(x)), p, eps) };
                let mut seen = negative & open;
                // The open faces the static bound leaves undecided (ties, near-flat tets, the
                // hull; on a CAD PoNQ's v*, points coplanar with faces of flat regions: 30% of
                // the steps on the mesher's 109k v*) get the exact test only where no decided
                // face sees `p` from behind: the walk goes through a face that does, decided
                // or not, so it is a visibility walk (which ends in a Delaunay
                // triangulation), and it ends only where no face does, exactly. (Exact tests
                // of every undecided face, to take the first face of the random order as one
                // by one: 1.8 per insertion on those v*; this way 0.6, and 3% fewer steps.)
                let pending = undecided & open;
                if pending != 0 && seen == 0 {
                    // An infinite tet's bound is infinite: every face undecided.
                    if !sh.real(tv) {
                        infinite_tet!();
                    }
                    for k in 0..4 {
                        if (pending >> k) & 1 == 1 && sh.face_sees(tv, k, p) < 0 {
                            seen |= 1 << k;
                        }
                    }
                }
                // The faces in the order r, r + 1, ...: bit j is face (r + j) & 3.
                let rotated = ((seen >> r) | (seen << (4 - r))) & 0xF;
                if rotated == 0 {
                    debug_assert!(
                        PAR || (0..4).all(|k| sh.face_sees(tv, k, p) >= 0),
                        "the walk ended outside tet {t}"
                    );
                    return Some(t);
                }
                prev = t;
                t = tn[(r + rotated.trailing_zeros() as usize) & 3];
                continue;
            }
            if !sh.real(tv) {
                infinite_tet!();
            }
            let mut next = NONE;
            for j in 0..4 {
                let k = (r + j) & 3;
                let nb = tn[k];
                if nb == NONE || nb == prev {
                    continue;
                }
                if sh.face_sees(tv, k, p) < 0 {
                    next = nb;
                    break;
                }
            }
            if next == NONE {
                // `prev` was skipped: p is strictly in front of the face we came through.
                debug_assert!(
                    PAR || (0..4).all(|k| sh.face_sees(tv, k, p) >= 0),
                    "the walk ended outside tet {t}"
                );
                return Some(t);
            }
            prev = t;
            t = next;
        }
        None
    }

    /// A tet containing vertex `v`, returned locked. In parallel, the walk's end is locked and
    /// then checked (live, `v` on no face's negative side); a tet that changed under the walk
    /// makes it walk on from there.
    fn locate<const PAR: bool>(&mut self, sh: &Shared, v: u32) -> std::result::Result<u32, Fail> {
        let p = sh.pos[v as usize];
        let mut t = self.start::<PAR>(sh).ok_or(Fail::Busy)?;
        if !PAR {
            if let Some(end) = self.walk::<PAR>(sh, t, &p) {
                return Ok(end);
            }
            // Safety net (never expected): scan for a tet that holds `p`.
            return Ok((0..sh.tets.len() as u32)
                .find(|&t| {
                    let tet = &sh.tets[t as usize];
                    tet.mark() != DEAD && sh.holds(tet.verts(), &p)
                })
                .unwrap_or(t));
        }
        for _ in 0..4 {
            t = self.walk::<PAR>(sh, t, &p).ok_or(Fail::Busy)?;
            if !self.try_lock::<PAR>(sh, t) {
                // Keep the progress: the next walk starts here.
                self.last = t;
                return Err(Fail::Busy);
            }
            let tet = &sh.tets[t as usize];
            if tet.mark() != DEAD && sh.holds(tet.verts(), &p) {
                return Ok(t);
            }
            self.unlock_all::<PAR>(sh);
        }
        Err(Fail::Busy)
    }

    /// Links the new tets of a cavity whose boundary has at most [`SMALL_CAVITY`] vertices
    /// (almost every cavity), as HXT does (Marot et al. 2019): the boundary vertices get local
    /// numbers, each directed edge `x -> y` of a boundary face enters its new tet at
    /// `map[x][y]`, then each tet reads its neighbour across `x -> y` at `map[y][x]`. No
    /// hashing, no probing and no branch on the data. Returns `false` (nothing changed) for a
    /// larger boundary.
    ///
    /// The local numbers follow the order of first visit. Numbering in one pass (read the
    /// vertex's number, give the next one if it has none) made every step wait for the
    /// store of an earlier step to the same vertex: this function held 10% of a one-thread
    /// insertion's samples. Here each vertex's first slot is found by stores alone, the
    /// count of first visits is a chain of one-cycle additions, and every other read is
    /// independent: 8% of the samples, the insertion stage 2-5% faster (measured side by
    /// side, `docs/meshing.md`).
    fn link_small(&mut self, sh: &Shared) -> bool {
        const L: usize = SMALL_CAVITY;
        // A triangulated sphere with V vertices has 2V - 4 faces, so at most this many slots
        // (three per face), each below `u8::MAX`.
        const SLOTS: usize = 3 * (2 * L - 4);
        const { assert!(SLOTS < u8::MAX as usize) };
        let faces = self.new_tets.len();
        if faces > 2 * L - 4 {
            return false;
        }
        if self.local_id.len() < sh.pos.len() {
            self.local_id.resize(sh.pos.len(), 0);
        }
        let slots = 3 * faces;
        // Slot `3 f + q`: vertex `q` of new tet `f`'s boundary face, in `APEX_FACE` order.
        let mut xs = [0u32; SLOTS];
        for (f, &(tv, _, k)) in self.new_tets.iter().enumerate() {
            for (q, p) in APEX_FACE[k as usize].into_iter().enumerate() {
                xs[3 * f + q] = tv[p];
            }
        }
        let xs = &xs[..slots];
        // Each vertex's first slot: written from the last slot back, so the first one stays.
        let first_slot = &mut self.local_id[..];
        for (s, &x) in xs.iter().enumerate().rev() {
            first_slot[x as usize] = s as u8;
        }
        // `number[s]`: the local number of slot `s`'s vertex. A first slot gives the count of
        // first slots before it; any other reads its first slot's (written before it).
        // (256 entries: indexed by a `u8`, no bounds checks.)
        let mut number = [0u8; 256];
        let mut count = 0u8;
        for (s, &x) in xs.iter().enumerate() {
            let f = first_slot[x as usize];
            let fresh = f as usize == s;
            let seen = number[f as usize];
            number[s as u8 as usize] = if fresh { count } else { seen };
            count += fresh as u8;
        }
        if count as usize > L {
            return false;
        }
        let map = &mut self.edge_map;
        // The numbers are below `L`, so the mask changes no index: it spares the bounds checks.
        let at = |a: u8, b: u8| (a as usize * L + b as usize) & (L * L - 1);
        for (&(_, id, _), l) in self.new_tets.iter().zip(number.chunks_exact(3)) {
            for (i, j, _) in FACE_EDGES {
                map[at(l[i], l[j])] = id;
            }
        }
        for (&(_, id, k), l) in self.new_tets.iter().zip(number.chunks_exact(3)) {
            let tet = &sh.tets[id as usize];
            for (i, j, third) in FACE_EDGES {
                tet.set_nbr(APEX_FACE[k as usize][third], map[at(l[j], l[i])]);
            }
        }
        true
    }

    /// Links the new tets of any cavity: an open-addressing table of directed edges. Pass 1
    /// enters every directed edge, pass 2 looks up every reversed one (twice the probes of one
    /// "insert or find" pass, but the probes' branches are predictable).
    fn link_hashed(&mut self, sh: &Shared) {
        let entries = 3 * self.new_tets.len();
        let bits = (4 * entries).next_power_of_two().max(256).trailing_zeros();
        if self.table.len() < 1 << bits {
            self.table = vec![EdgeSlot::default(); 1 << bits];
            self.generation = 0;
        }
        self.generation = self.generation.wrapping_add(1);
        if self.generation == 0 {
            self.table.iter_mut().for_each(|e| e.generation = 0);
            self.generation = 1;
        }
        let generation = self.generation;
        // Hash into the first `1 << bits` slots only: the table may have grown for one big
        // cavity, and spreading small cavities over all of it would miss the cache.
        let mask = (1usize << bits) - 1;
        let slot_of = |key: u64| (key.wrapping_mul(0x9E37_79B9_7F4A_7C15) >> (64 - bits)) as usize;
        for &(tv, id, k) in &self.new_tets {
            let face = APEX_FACE[k as usize].map(|p| tv[p]);
            for (i, j, _) in FACE_EDGES {
                let key = edge_key(face[i], face[j]);
                let mut h = slot_of(key);
                while self.table[h].generation == generation {
                    h = (h + 1) & mask;
                }
                self.table[h] = EdgeSlot {
                    key,
                    tet: id,
                    generation,
                };
            }
        }
        for &(tv, id, k) in &self.new_tets {
            let tet = &sh.tets[id as usize];
            let face = APEX_FACE[k as usize].map(|p| tv[p]);
            for (i, j, third) in FACE_EDGES {
                let key = edge_key(face[j], face[i]);
                let mut h = slot_of(key);
                let mut other = NONE;
                loop {
                    let slot = self.table[h];
                    if slot.generation != generation {
                        break;
                    }
                    if slot.key == key {
                        other = slot.tet;
                        break;
                    }
                    h = (h + 1) & mask;
                }
                debug_assert_ne!(other, NONE, "the cavity boundary is closed");
                tet.set_nbr(APEX_FACE[k as usize][third], other);
            }
        }
    }

    /// Undoes the stamps and locks of a failed insertion. Its stamps are on the tets of the
    /// cavity found so far, on those still to look around (the stack), on the tets next to
    /// them (the boundary) and on those waiting for their conflict test (`waiting`, the
    /// neighbour of each): a neighbour is stamped only after it is locked, and then waits for
    /// its test and goes to the stack or to the boundary. (A list of the stamped tets kept as
    /// they were stamped: a store per conflict test.)
    fn back_off<const PAR: bool>(
        &mut self,
        sh: &Shared,
        waiting: &[(u32, u8, u32)],
        fail: Fail,
    ) -> Fail {
        let next_to = self.boundary.iter().map(|b| b.2).filter(|&t| t != NONE);
        let pending = self.stack.iter().map(|e| e.0);
        let waiting = waiting.iter().map(|w| w.2);
        for t in self
            .cavity
            .iter()
            .copied()
            .chain(pending)
            .chain(next_to)
            .chain(waiting)
        {
            sh.tets[t as usize].set_mark(NO_STAMP);
        }
        self.unlock_all::<PAR>(sh);
        fail
    }

    /// The conflict tests of the cavity search waiting in `lanes` (at most four; `ids` and
    /// `eps` hold their tets' vertices and static bounds in the same lanes, any tets in the
    /// lanes after them): a tet in conflict with `v` joins the cavity (the stack), any other
    /// gives a boundary face.
    #[inline(always)]
    fn test_lanes<const AVX2: bool>(
        &mut self,
        sh: &Shared,
        v: u32,
        stamps: Stamps,
        lanes: &[(u32, u8, u32)],
        ids: &[[u32; 4]; 4],
        eps: &[f64; 4],
    ) {
        let (signs, dets) = sh.conflict_lanes::<AVX2>(ids, v, eps);
        make_room(&mut self.stack, lanes.len());
        make_room(&mut self.boundary, lanes.len());
        for (r, &(c, k, nb)) in lanes.iter().enumerate() {
            let nt = &sh.tets[nb as usize];
            let conflict = if signs[r] != 0 {
                signs[r] > 0
            } else {
                sh.conflicts_past_static(ids[r], v, dets[r])
            };
            // From here on without a branch on `conflict` (in a cavity search it is true
            // about as often as false): the mark is a select, the tet goes to the stack
            // or to the boundary by a write after the last item that is kept or not.
            nt.set_mark(if conflict {
                stamps.in_cavity
            } else {
                stamps.outside
            });
            let j = back_face(nt, c);
            // SAFETY: room for one item per lane was made above.
            unsafe {
                push_if_in_room(&mut self.stack, (nb, j), conflict);
                push_if_in_room(&mut self.boundary, (c, k, nb, j), !conflict);
            }
        }
    }

    /// Inserts vertex `v`, or backs off leaving the triangulation unchanged. On x86-64 CPUs
    /// with AVX2 the insertion is compiled for it ([`Worker::insert_avx2`]); the same code
    /// otherwise.
    #[inline]
    fn insert<const PAR: bool>(&mut self, sh: &Shared, v: u32) -> std::result::Result<(), Fail> {
        #[cfg(target_arch = "x86_64")]
        {
            if self.avx2 {
                // SAFETY: the CPU has AVX2 (`avx2` is only set when it does).
                return unsafe { self.insert_avx2::<PAR>(sh, v) };
            }
        }
        self.insert_body::<PAR, false>(sh, v)
    }

    /// [`Worker::insert`] with AVX2: the cavity search's conflict tests
    /// ([`insphere_static_lanes`]) then run four to a register. Measured side by side with
    /// the build before the lanes (`delaunay_bench`, six alternating rounds, the mesher's 109k
    /// v*, insertion stage): one thread 2.44 -> 2.22 us per point, two threads 1.34 -> 1.28;
    /// in other rounds the lanes without AVX2 (SSE2 pairs) gave 2.47 -> 2.29 and 1.36 -> 1.35,
    /// AVX2 without the lanes 2.44 -> 2.35 and 1.34 -> 1.35. Same results (no fused
    /// operations). Since then the points go straight from `pos` into the lanes
    /// ([`insphere_static4_avx2`], see [`Shared::conflict_lanes`]): one thread 2-4% faster;
    /// and the lanes are filled four at a time from any cavity tets (they held the three
    /// other neighbours of one cavity tet, so a fourth of the work was idle): one thread
    /// 8-9% faster.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2")]
    fn insert_avx2<const PAR: bool>(
        &mut self,
        sh: &Shared,
        v: u32,
    ) -> std::result::Result<(), Fail> {
        self.insert_body::<PAR, true>(sh, v)
    }

    /// The insertion; `AVX2` only where the CPU has it (see [`Shared::conflict_lanes`]).
    #[inline(always)]
    fn insert_body<const PAR: bool, const AVX2: bool>(
        &mut self,
        sh: &Shared,
        v: u32,
    ) -> std::result::Result<(), Fail> {
        let t = self.locate::<PAR>(sh, v)?;
        let stamps = Stamps::of(v);
        self.cavity.clear();
        self.boundary.clear();
        self.stack.clear();
        self.later.clear();
        // Each stack entry keeps the face it was entered through (4: none), which leads back
        // into the cavity and needs no look.
        self.stack.push((t, 4));
        sh.tets[t as usize].set_mark(stamps.in_cavity);
        // The conflict tests wait here until four are ready, then run together
        // ([`Shared::conflict_lanes`]): lane r tests neighbour `ids[r]` of cavity tet `c`
        // across its face `k` (`lanes[r] = (c, k, neighbour)`). The cavity search goes on
        // from the other cavity tets meanwhile; the cavity is the same in any order.
        let mut lanes = [(NONE, 0u8, NONE); 4];
        let mut ids = [[0u32; 4]; 4];
        let mut eps = [f64::INFINITY; 4];
        let mut ready = 0usize;
        loop {
            while let Some((c, entry)) = self.stack.pop() {
                self.cavity.push(c);
                let cn = sh.tets[c as usize].nbrs();
                // Touch the four neighbours together so that their cache misses overlap.
                let _touch =
                    cn.map(|nb| sh.tets.get(nb as usize).map_or(0, |t| t.mark.load(Relaxed)));
                // The other faces: three after the entry face, or all four of the first tet
                // (a count instead of a skip, which would be a branch on the data).
                let (first, count) = if entry == 4 { (0, 4) } else { (entry + 1, 3) };
                for r in 0..count {
                    let k = (first + r) & 3;
                    let nb = cn[k as usize];
                    if nb == NONE {
                        // Never: every face has a tet across it, infinite tets included.
                        self.boundary.push((c, k, NONE, 0));
                        continue;
                    }
                    // (One thread takes no locks: `try_lock::<false>` is `true`.)
                    if !self.try_lock::<PAR>(sh, nb) {
                        return Err(self.back_off::<PAR>(sh, &lanes[..ready], Fail::Busy));
                    }
                    let nt = &sh.tets[nb as usize];
                    let mark = nt.mark();
                    if mark == stamps.in_cavity {
                        continue;
                    }
                    if mark == stamps.outside {
                        self.boundary.push((c, k, nb, back_face(nt, c)));
                        continue;
                    }
                    if mark == stamps.waiting {
                        // Waiting for its test, from another cavity tet: a boundary face if
                        // it is not in conflict, known at the end.
                        self.later.push((c, k, nb));
                        continue;
                    }
                    nt.set_mark(stamps.waiting);
                    let tv = nt.verts();
                    lanes[ready] = (c, k, nb);
                    ids[ready] = tv;
                    eps[ready] = if sh.real(tv) {
                        sh.static_eps
                    } else {
                        f64::INFINITY
                    };
                    ready += 1;
                    if ready == 4 {
                        self.test_lanes::<AVX2>(sh, v, stamps, &lanes, &ids, &eps);
                        ready = 0;
                    }
                }
            }
            if ready == 0 {
                break;
            }
            // Fewer than four (the lanes after them hold earlier tests: computed, not read).
            self.test_lanes::<AVX2>(sh, v, stamps, &lanes[..ready], &ids, &eps);
            ready = 0;
        }
        for i in 0..self.later.len() {
            let (c, k, nb) = self.later[i];
            let nt = &sh.tets[nb as usize];
            if nt.mark() == stamps.outside {
                self.boundary.push((c, k, nb, back_face(nt, c)));
            }
        }
        // Slots: the cavity's, then free ones, then fresh ones; all taken before any change.
        let extra = self.boundary.len().saturating_sub(self.cavity.len());
        self.taken.clear();
        let mut skipped = 0usize;
        while self.taken.len() < extra {
            if self.free.len() > skipped {
                let i = self.free.len() - 1 - skipped;
                let f = self.free[i];
                // A walker of another worker may hold a free slot for a moment.
                if self.try_lock::<PAR>(sh, f) {
                    self.free.swap_remove(i);
                    self.taken.push(f);
                } else {
                    skipped += 1;
                }
            } else if self.fresh.0 < self.fresh.1 || self.refill(sh) {
                let f = self.fresh.0;
                // A never-used slot of this worker's: no walker reaches it before a tet is
                // written there, so nobody else locks it (no compare-exchange).
                if PAR {
                    sh.locks[f as usize].store(self.id, Relaxed);
                    self.held.push(f);
                }
                self.fresh.0 += 1;
                self.taken.push(f);
            } else {
                self.free.extend_from_slice(&self.taken);
                self.taken.clear();
                return Err(self.back_off::<PAR>(sh, &[], Fail::NoSpace));
            }
        }
        // New tets: one per boundary face, the cavity tet's vertex k replaced by v. Read the
        // cavity tets' vertices before their slots are reused.
        self.new_tets.clear();
        make_room(&mut self.new_tets, self.boundary.len());
        for &(c, k, _, _) in &self.boundary {
            let old = sh.tets[c as usize].verts();
            // A select per position rather than a store at position k: the array is written
            // whole, so reading it back does not stall on store forwarding (measured: the
            // store-then-load of `tv[k] = v` cost ~8% of the insertion).
            let tv = [0, 1, 2, 3].map(|q| if q == k as usize { v } else { old[q] });
            // SAFETY: room for one item per boundary face was made above.
            unsafe { push_if_in_room(&mut self.new_tets, (tv, 0, k), true) };
        }
        let ncav = self.cavity.len();
        for i in 0..self.new_tets.len() {
            self.new_tets[i].1 = if i < ncav {
                self.cavity[i]
            } else {
                self.taken[i - ncav]
            };
        }
        for i in self.new_tets.len()..ncav {
            let c = self.cavity[i];
            sh.tets[c as usize].set_mark(DEAD);
            self.free.push(c);
        }
        for i in 0..self.new_tets.len() {
            let (tv, id, k) = self.new_tets[i];
            let (_, _, nb, j) = self.boundary[i];
            let tet = &sh.tets[id as usize];
            for q in 0..4 {
                tet.v[q].store(tv[q], Relaxed);
            }
            tet.set_mark(NO_STAMP);
            tet.set_nbr(k as usize, nb);
            if nb != NONE {
                sh.tets[nb as usize].set_nbr(j as usize, id);
            }
            debug_assert!(
                !sh.real(tv) || orient3d(sh.p(tv[0]), sh.p(tv[1]), sh.p(tv[2]), sh.p(tv[3])) > 0,
                "flat or inverted tet created inserting {v}: {tv:?} cavity {} boundary {}",
                self.cavity.len(),
                self.boundary.len()
            );
        }
        // Link the new tets to each other. They all have `v` as apex over a boundary face,
        // and the faces (ordered by `APEX_FACE`, `v` on their positive side) orient the
        // cavity boundary consistently: two new tets are neighbours exactly where one face
        // has the directed edge (x, y) and the other (y, x).
        if !self.link_small(sh) {
            self.link_hashed(sh);
            self.large_cavities += 1;
        }
        self.last = self.new_tets[0].1;
        // Let go: the cavity slots (reused or dead), their neighbours, the new slots.
        self.unlock_all::<PAR>(sh);
        Ok(())
    }
}

/// How many items ahead a gather through a permutation asks for (see [`prefetch`]): the
/// output's tets from their arena slots in [`Builder::finish`]. Measured with 8, 16 and 32:
/// the same.
const GATHER_AHEAD: usize = 16;

/// Asks the CPU to bring the cache lines of `x` (at most two: `size_of::<T>() <= 64`) into
/// the cache, for a read soon. A gather through a permutation misses the cache at every
/// step; the out-of-order core overlaps only a few of those misses, the prefetches many
/// more (the output stage at 400k points: 155 -> 106 ms on two threads). No effect on any
/// result.
#[inline(always)]
fn prefetch<T>(x: &T) {
    const { assert!(size_of::<T>() >= 1 && size_of::<T>() <= 64) };
    #[cfg(target_arch = "x86_64")]
    {
        use std::arch::x86_64::{_MM_HINT_T0, _mm_prefetch};
        let p = (x as *const T).cast::<i8>();
        // SAFETY: a prefetch is a hint; it never faults and changes no memory, and SSE (its
        // instruction set) is part of every x86-64 CPU.
        unsafe {
            _mm_prefetch::<_MM_HINT_T0>(p);
            _mm_prefetch::<_MM_HINT_T0>(p.wrapping_add(size_of::<T>() - 1));
        }
    }
    #[cfg(not(target_arch = "x86_64"))]
    let _ = x;
}

/// Even permutations of a tet's four positions: `EVEN_PERMS[3 * i + j]` brings position `i`
/// to the front (a double transposition) and then rotates the other three by `j`.
const EVEN_PERMS: [[usize; 4]; 12] = {
    const TO_FRONT: [[usize; 4]; 4] = [[0, 1, 2, 3], [1, 0, 3, 2], [2, 3, 0, 1], [3, 2, 1, 0]];
    const ROTATE: [[usize; 4]; 3] = [[0, 1, 2, 3], [0, 2, 3, 1], [0, 3, 1, 2]];
    let mut p = [[0usize; 4]; 12];
    let mut i = 0;
    while i < 4 {
        let mut j = 0;
        while j < 3 {
            let mut k = 0;
            while k < 4 {
                p[3 * i + j][k] = TO_FRONT[i][ROTATE[j][k]];
                k += 1;
            }
            j += 1;
        }
        i += 1;
    }
    p
};

/// Index into [`EVEN_PERMS`] of the even permutation that puts the smallest vertex of `tv`
/// first and the smallest of the other three second; `tv` holds four distinct vertices (a
/// tet's). From the six comparisons of its vertices, by [`ROTATION_BY_ORDER`]: no branch on
/// the data. (Two searches for a minimum, the second through a permutation: ~2 ms of the
/// output stage's gather at 109k points on two threads, about half of it.)
#[inline]
fn canonical_rotation(tv: [u32; 4]) -> u8 {
    ROTATION_BY_ORDER[order_code(tv)]
}

/// The six comparisons of four values as bits: `v0 < v1`, `v0 < v2`, `v0 < v3`, `v1 < v2`,
/// `v1 < v3`, `v2 < v3` (bit 0 first).
#[inline(always)]
const fn order_code(v: [u32; 4]) -> usize {
    (v[0] < v[1]) as usize
        | ((v[0] < v[2]) as usize) << 1
        | ((v[0] < v[3]) as usize) << 2
        | ((v[1] < v[2]) as usize) << 3
        | ((v[1] < v[3]) as usize) << 4
        | ((v[2] < v[3]) as usize) << 5
}

/// `ROTATION_BY_ORDER[order_code(tv)]`: the index into [`EVEN_PERMS`] of the even permutation
/// that puts the smallest of four distinct values first and the smallest of the other three
/// second, for each of the 24 orders of four distinct values (computed from each order's
/// ranks; the other 40 codes, which no four distinct values give, hold 0).
const ROTATION_BY_ORDER: [u8; 64] = {
    let mut table = [0u8; 64];
    // Every assignment of the ranks 0..4 to the positions that is a permutation.
    let mut code = 0;
    while code < 256 {
        let r = [code & 3, (code >> 2) & 3, (code >> 4) & 3, (code >> 6) & 3];
        let distinct = r[0] != r[1]
            && r[0] != r[2]
            && r[0] != r[3]
            && r[1] != r[2]
            && r[1] != r[3]
            && r[2] != r[3];
        if distinct {
            let v = [r[0] as u32, r[1] as u32, r[2] as u32, r[3] as u32];
            // The position of rank 0, brought to the front; then, among the other three in
            // that permutation's order, the position of the smallest.
            let mut i = 0;
            while v[i] != 0 {
                i += 1;
            }
            let p = EVEN_PERMS[3 * i];
            let mut j = 1;
            let mut k = 2;
            while k < 4 {
                if v[p[k]] < v[p[j]] {
                    j = k;
                }
                k += 1;
            }
            table[order_code(v)] = (3 * i + j - 1) as u8;
        }
        code += 1;
    }
    table
};

/// Buckets of at most this many tets are sorted by rank (see [`sort_bucket`]).
const RANK_SORT_MAX: usize = 24;

/// The number of output tets of each sort key `0..n` (a tet's largest vertex; [`NONE`] and
/// any other key `>= n` is not counted), in one pass over `key` shared by `parts` threads.
fn key_counts(key: &[u32], n: u32, parts: usize) -> Vec<u32> {
    use rayon::prelude::*;
    let len = key.len();
    (0..parts)
        .into_par_iter()
        .map(|c| {
            let mut count = vec![0u32; n as usize];
            for &f in &key[len * c / parts..len * (c + 1) / parts] {
                if f < n {
                    count[f as usize] += 1;
                }
            }
            count
        })
        .reduce_with(|mut a, b| {
            a.iter_mut().zip(b).for_each(|(x, y)| *x += y);
            a
        })
        .unwrap_or_else(|| vec![0; n as usize])
}

/// Vertex bounds `0 = b_0 <= b_1 <= ... <= b_parts = n` that cut the output into `parts`
/// ranges of sort keys holding about as many tets each (each part within one key's tets of
/// its share), from `offsets` (`n + 1` entries: the tets of keys below each vertex). Equal
/// vertex ranges are not balanced: a tet's key is its newest vertex, and the last BRIO round,
/// about half the vertices, makes most of the tets (59% in the upper half at 109k points).
/// The bounds change which thread writes which part of the output, never the output.
fn balanced_bounds(offsets: &[u32], parts: usize) -> Vec<u32> {
    let n = offsets.len() - 1;
    let total = u64::from(offsets[n]);
    let mut bounds = Vec::with_capacity(parts + 1);
    bounds.push(0);
    for i in 1..parts {
        // The first vertex with at least the first i parts' share of the tets below it.
        let target = total * i as u64 / parts as u64;
        bounds.push(offsets.partition_point(|&o| u64::from(o) < target).min(n) as u32);
    }
    bounds.push(n as u32);
    bounds
}

/// Scratch space of [`sort_bucket`].
struct BucketScratch {
    ranked: [(u128, [u32; 4], [u32; 4], u32); RANK_SORT_MAX],
    bucket: Vec<([u32; 4], [u32; 4], u32)>,
}

impl Default for BucketScratch {
    fn default() -> Self {
        Self {
            ranked: [(0, [0; 4], [0; 4], 0); RANK_SORT_MAX],
            bucket: Vec::new(),
        }
    }
}

/// Sorts one bucket of output tets by their (rotated) vertices, moving each tet's neighbours
/// and slot with it. The tets must be distinct (they are: distinct tets of a triangulation).
/// A small bucket (about 7 tets on average) is sorted by rank, with no branch on the data:
/// each tet goes to the number of smaller ones (measured: half the time of a comparison sort,
/// whose branches the random orders mispredict); a larger one by a comparison sort.
fn sort_bucket(
    pt: &mut [[u32; 4]],
    pn: &mut [[u32; 4]],
    ps: &mut [u32],
    scratch: &mut BucketScratch,
) {
    let len = pt.len();
    if len < 2 {
        return;
    }
    if len <= RANK_SORT_MAX {
        let ranked = &mut scratch.ranked[..len];
        for (q, r) in ranked.iter_mut().enumerate() {
            let t = pt[q];
            // Lexicographic order of the four vertices as one number.
            let lex = t.iter().fold(0u128, |acc, &x| acc << 32 | x as u128);
            *r = (lex, t, pn[q], ps[q]);
        }
        for &(lex, t, nb, s) in ranked.iter() {
            let r = ranked.iter().map(|x| (x.0 < lex) as usize).sum::<usize>();
            (pt[r], pn[r], ps[r]) = (t, nb, s);
        }
    } else {
        let bucket = &mut scratch.bucket;
        bucket.clear();
        bucket.extend((0..len).map(|i| (pt[i], pn[i], ps[i])));
        bucket.sort_unstable_by_key(|it| it.0);
        for (i, it) in bucket.iter().enumerate() {
            (pt[i], pn[i], ps[i]) = *it;
        }
    }
}

struct Builder {
    /// Real vertices (in insertion order) followed by an entry for the infinite vertex (NaN,
    /// see [`Builder::new`]).
    pos: Vec<[f64; 3]>,
    /// Input number of each real vertex.
    rank: Vec<u32>,
    n_real: u32,
    static_eps: f64,
    static_orient_eps: f64,
    /// The tet arena: `tets[..used]` have been handed out, the slots after them are free
    /// ([`DEAD`]); room for more is reserved (see [`Builder::new`]).
    tets: Vec<Tet>,
    used: usize,
}

impl Builder {
    /// A builder with the first tet, on the first four vertices (affinely independent, see
    /// [`independent_first`]; `spans` says whether they are: otherwise no tet at all), and
    /// its four infinite tets, one per face: the face and the infinite vertex (numbered
    /// `pos.len()`, past the real ones), ordered as if that vertex were a point far beyond the
    /// face, so that the insertion makes and links infinite tets as any others. Room for
    /// `capacity` tets (more are added when needed).
    ///
    /// With `zeroed`, the arena's `capacity` slots are allocated zeroed (free) at once, as
    /// the parallel phase needs: its workers take slots from one pool and may look at any
    /// of them. Without it (one thread), only the room is reserved, and [`Builder::reserve`]
    /// writes the free slots a few thousand at a time, just before the insertions fill them.
    /// An allocator that serves the arena from memory freed before must clear it for a zeroed
    /// allocation: a pass over the whole arena (29 MB at 100k points) whose lines have left
    /// the caches again by the time they are filled.
    fn new(
        mut pos: Vec<[f64; 3]>,
        rank: Vec<u32>,
        capacity: usize,
        zeroed: bool,
        spans: bool,
    ) -> Result<Self> {
        let n_real = pos.len() as u32;
        let (mut lo, mut hi) = ([0.0f64; 3], [0.0f64; 3]);
        if let Some(first) = pos.first() {
            lo = *first;
            hi = *first;
        }
        for p in &pos {
            for k in 0..3 {
                lo[k] = lo[k].min(p[k]);
                hi[k] = hi[k].max(p[k]);
            }
        }
        let extent = (0..3).map(|k| hi[k] - lo[k]).fold(0.0f64, f64::max);
        let static_eps = static_insphere_bound(extent);
        let static_orient_eps = static_orient_bound(extent);
        // The infinite vertex's entry: NaN, so that every floating-point filter of a tet
        // with it is undecided (their comparisons are false for NaN), which sends the tet to
        // the tests made for infinite tets; no exact predicate reads it.
        pos.push([f64::NAN; 3]);
        let no_memory = || Error::InvalidInput(format!("no memory for {capacity} tetrahedra"));
        let mut tets: Vec<Tet> = if zeroed {
            bytemuck::allocation::try_zeroed_vec(capacity.max(5)).map_err(|_| no_memory())?
        } else {
            let mut tets = Vec::new();
            tets.try_reserve_exact(capacity.max(5))
                .map_err(|_| no_memory())?;
            tets
        };
        let mut used = 0;
        if spans {
            let inf = n_real;
            let mut first = [0, 1, 2, 3];
            if orient3d(&pos[0], &pos[1], &pos[2], &pos[3]) < 0 {
                first.swap(0, 1);
            }
            // Slot 0: the first tet; slot 1 + k: the infinite tet on its face k (the face's
            // first two vertices swapped, so that the far side is the positive one).
            let mut five = vec![first];
            for face in APEX_FACE {
                let f = face.map(|q| first[q]);
                five.push([f[1], f[0], f[2], inf]);
            }
            if !zeroed {
                tets.resize_with(5, Tet::dead);
            }
            for (t, tv) in five.iter().enumerate() {
                for k in 0..4 {
                    tets[t].v[k].store(tv[k], Relaxed);
                    // The tet across face k: the other of the five with the same three
                    // vertices.
                    let mut face: Vec<u32> = (0..4).filter(|&q| q != k).map(|q| tv[q]).collect();
                    face.sort_unstable();
                    let across = (0..5).find(|&u| {
                        u != t && {
                            let mut g: Vec<u32> = five[u].to_vec();
                            g.sort_unstable();
                            face.iter().all(|x| g.contains(x))
                        }
                    });
                    tets[t].set_nbr(k, across.map_or(NONE, |u| u as u32));
                }
                tets[t].set_mark(NO_STAMP);
            }
            used = 5;
        }
        Ok(Self {
            pos,
            rank,
            n_real,
            static_eps,
            static_orient_eps,
            tets,
            used,
        })
    }

    fn shared(&self) -> Shared<'_> {
        Shared {
            pos: &self.pos,
            rank: &self.rank,
            tets: &self.tets[..self.used],
            n_real: self.n_real,
            static_eps: self.static_eps,
            static_orient_eps: self.static_orient_eps,
            pool: None,
            locks: &[],
        }
    }

    /// Hands out `count` never-used slots (written free here if they were not yet; the
    /// room grows by half when it is too small).
    fn reserve(&mut self, count: usize) -> (u32, u32) {
        let end = self.used + count;
        if end > self.tets.len() {
            if end > self.tets.capacity() {
                let room = end.max(self.tets.capacity() + self.tets.capacity() / 2);
                self.tets.reserve_exact(room - self.tets.len());
            }
            self.tets.resize_with(end, Tet::dead);
        }
        let start = std::mem::replace(&mut self.used, end);
        (start as u32, end as u32)
    }

    /// Adds `count` free slots for `w`.
    fn grow(&mut self, w: &mut Worker, count: usize) {
        if w.fresh.0 < w.fresh.1 {
            w.free.extend(w.fresh.0..w.fresh.1);
        }
        w.fresh = self.reserve(count);
    }

    /// Inserts `verts` one after the other with a single worker.
    fn insert_sequential(&mut self, w: &mut Worker, verts: impl IntoIterator<Item = u32>) {
        for v in verts {
            loop {
                let result = {
                    let sh = self.shared();
                    w.insert::<false>(&sh, v)
                };
                match result {
                    Ok(()) => break,
                    Err(_) => {
                        // Half again as many slots within the slots already written free,
                        // else `FRESH_BLOCK` more (see `Builder::new`).
                        let room = self.tets.len() - self.used;
                        let count = (self.used / 2).max(1024).min(room.max(FRESH_BLOCK));
                        self.grow(w, count);
                    }
                }
            }
        }
    }

    /// Inserts every vertex: the first BRIO rounds by one thread, the later (large) rounds by
    /// `threads` workers, each owning one stretch of every round's Hilbert order in chunks
    /// (and taking other workers' chunks once its own are done), then the vertices the
    /// workers backed off from by one thread.
    ///
    /// The first four vertices are in the first tet already ([`Builder::new`]); with no tet
    /// (the vertices span no volume) nothing is inserted.
    fn run(mut self, rounds: &[usize], opts: &DelaunayOptions) -> Delaunay {
        let n = self.n_real as usize;
        let mut main = Worker::new(1, 12345);
        main.avx2 = avx2_insertion(opts);
        let threads = opts.threads.clamp(1, 64);
        if self.used == 0 {
            return self.finish(DelaunayStats {
                workers: 1,
                ..Default::default()
            });
        }
        if !in_parallel(threads, n) {
            self.insert_sequential(&mut main, FIRST_TET..self.n_real);
            return self.finish(DelaunayStats {
                workers: 1,
                large_cavities: main.large_cavities,
                ..Default::default()
            });
        }
        // Sequential prefix: enough points that the workers' regions hardly interact.
        // It ends at a round boundary (a prefix of a round covers only part of the domain),
        // and leaves at least half of the points to the workers.
        // (A smaller prefix, 64 points per worker at least, measured 6% faster at 10k points
        // than 512 per worker: the other threads wait less; the same at 100k.)
        let prefix_min = (n / 64).max(64 * threads);
        let split = match rounds.iter().copied().find(|&r| r >= prefix_min) {
            Some(r) if r <= n / 2 => r,
            _ => rounds
                .iter()
                .copied()
                .filter(|&r| r <= n / 2)
                .max()
                .unwrap_or(0),
        }
        // The first tet's vertices are in already: the workers' stretches start after them.
        .max(FIRST_TET as usize);
        self.insert_sequential(&mut main, FIRST_TET..split as u32);
        // Per-round stretches, cut into chunks of consecutive vertices; alternate directions so
        // that neighbouring workers never start a round where the other one ends the previous
        // one. `queues[i]`: the chunks of worker i, in its order of work.
        let mut queues: Vec<Vec<(u32, u32, bool)>> = vec![Vec::new(); threads];
        for (r, w) in rounds.windows(2).enumerate() {
            let (a, b) = (w[0].max(split), w[1]);
            if a >= b {
                continue;
            }
            let len = b - a;
            for (i, queue) in queues.iter_mut().enumerate() {
                let (s, e) = (a + len * i / threads, a + len * (i + 1) / threads);
                let chunks = (s..e)
                    .step_by(CHUNK)
                    .map(|c| (c as u32, (c + CHUNK).min(e) as u32));
                if r % 2 == 0 {
                    queue.extend(chunks.map(|(c, d)| (c, d, false)));
                } else {
                    queue.extend(chunks.rev().map(|(c, d)| (c, d, true)));
                }
            }
        }
        let parallel_insertions: usize =
            queues.iter().flatten().map(|c| (c.1 - c.0) as usize).sum();
        let mut workers: Vec<Worker> = (0..threads)
            .map(|i| Worker::new(i as u32 + 2, 0x9E37 + i as u64))
            .collect();
        for (w, queue) in workers.iter_mut().zip(&queues) {
            w.fail_every = opts.fail_every_nth_lock;
            w.avx2 = main.avx2;
            // Start each worker in its own region: at the tet holding its first vertex.
            w.last = main.last;
            if let Some(&(c, d, rev)) = queue.first() {
                let first = if rev { d - 1 } else { c };
                let sh = self.shared();
                if let Ok(t) = main.locate::<false>(&sh, first) {
                    w.last = t;
                }
            }
        }
        workers[0].free = std::mem::take(&mut main.free);
        // The slots of the parallel phase come from one pool, in blocks, so that a worker
        // that does more than its share never runs out; slots past the last block handed out
        // are never touched.
        let pool_start = self.used;
        self.reserve((15 * parallel_insertions / 2).max(POOL_BLOCK * threads) + 4096);
        let pool = AtomicUsize::new(pool_start);
        // The locks apart from the tets: 36-byte tets instead of 40 made one-thread insertion
        // ~10% faster and the parallel phase ~8%, side by side. Tried: one lock per 4 to 64
        // consecutive slots (a cavity and its neighbours sit in few such blocks): fewer
        // compare-exchanges but more back-offs, no faster; the marks apart too (32-byte tets,
        // a mark array beside them): no faster either (the cavity search reads both).
        // Zeroed pages: the locks of slots never used cost nothing.
        let locks: Vec<AtomicU32> = bytemuck::allocation::zeroed_vec(self.used);
        let (left, parallel_stopped) = {
            use rayon::prelude::*;
            let mut sh = self.shared();
            sh.pool = Some(&pool);
            sh.locks = &locks;
            // Each chunk is inserted by the one worker that claims it: its owner, going
            // forward through its queue, or (once a worker's own queue is done) a worker
            // taking the others' chunks from the back, far from where their owners are.
            let claimed: Vec<Vec<AtomicBool>> = queues
                .iter()
                .map(|q| q.iter().map(|_| AtomicBool::new(false)).collect())
                .collect();
            // First attempts and back-offs so far, all workers; `stop` once too many back off.
            let (attempts, backoffs, stop) = (
                AtomicUsize::new(0),
                AtomicUsize::new(0),
                AtomicBool::new(false),
            );
            workers.par_iter_mut().enumerate().for_each(|(i, w)| {
                // A vertex backed off from is tried again after the rest of its chunk (the
                // other worker has usually moved on by then), and only then deferred.
                let insert_chunk = |w: &mut Worker, (c, d, rev): (u32, u32, bool)| {
                    let mut retry = Vec::new();
                    let mut one = |v: u32| {
                        if w.insert::<true>(&sh, v).is_err() {
                            retry.push(v);
                        }
                    };
                    if rev {
                        (c..d).rev().for_each(&mut one);
                    } else {
                        (c..d).for_each(&mut one);
                    }
                    w.backed_off += retry.len();
                    let tried = attempts.fetch_add((d - c) as usize, Relaxed) + (d - c) as usize;
                    let failed = backoffs.fetch_add(retry.len(), Relaxed) + retry.len();
                    if tried >= STOP_MIN_ATTEMPTS && failed * STOP_BACKOFF_RATIO > tried {
                        stop.store(true, Relaxed);
                    }
                    for v in retry {
                        if w.insert::<true>(&sh, v).is_err() {
                            w.deferred.push(v);
                        }
                    }
                };
                for (j, &chunk) in queues[i].iter().enumerate() {
                    if stop.load(Relaxed) {
                        return;
                    }
                    if !claimed[i][j].swap(true, Relaxed) {
                        insert_chunk(w, chunk);
                    }
                }
                for other in (1..threads).map(|k| (i + k) % threads) {
                    // Owners claim from the front and thieves from the back, so the first
                    // claimed chunk from the back ends the search.
                    for (j, &chunk) in queues[other].iter().enumerate().rev() {
                        if stop.load(Relaxed) || claimed[other][j].swap(true, Relaxed) {
                            break;
                        }
                        w.stolen += 1;
                        insert_chunk(w, chunk);
                    }
                }
            });
            // The chunks no worker claimed (the workers stopped) go to the one-thread pass.
            let mut left: Vec<u32> = Vec::new();
            for (queue, claimed) in queues.iter().zip(&claimed) {
                for (&(c, d, _), taken) in queue.iter().zip(claimed) {
                    if !taken.load(Relaxed) {
                        left.extend(c..d);
                    }
                }
            }
            (left, stop.load(Relaxed))
        };
        self.used = pool.load(Relaxed).min(self.used);
        // Gather the slots and the deferred vertices; finish with one thread.
        let parallel_insertions = parallel_insertions - left.len();
        let mut deferred = left;
        for w in &mut workers {
            main.free.append(&mut w.free);
            main.free.extend(w.fresh.0..w.fresh.1);
            deferred.append(&mut w.deferred);
            if self.tets[w.last as usize].mark() != DEAD {
                main.last = w.last;
            }
        }
        if self.tets[main.last as usize].mark() == DEAD {
            main.last = (0..self.used as u32)
                .find(|&t| self.tets[t as usize].mark() != DEAD)
                .unwrap_or(0);
        }
        deferred.sort_unstable();
        let mut stats = DelaunayStats {
            workers: threads,
            parallel_insertions,
            deferred: deferred.len(),
            stolen_chunks: workers.iter().map(|w| w.stolen).sum(),
            backed_off: workers.iter().map(|w| w.backed_off).sum(),
            parallel_stopped,
            ..Default::default()
        };
        self.insert_sequential(&mut main, deferred);
        stats.large_cavities =
            main.large_cavities + workers.iter().map(|w| w.large_cavities).sum::<usize>();
        self.finish(stats)
    }

    /// The tets of real vertices in a canonical form, so that the output does not depend on the
    /// worker count or timing (which arena slots the tets went to): each tet starts at its
    /// smallest vertex (insertion numbering), followed by the smaller of the next two in cyclic
    /// order (even permutations only, so orientations are kept); the tets are sorted by their
    /// largest vertex, then by their rotated vertices. The largest vertex is usually the one
    /// whose insertion made the tet, so this order follows the finest Hilbert order: the
    /// later stages, which read the tets in order with their vertices and neighbours, run
    /// faster than with the tets sorted by smallest vertex (measured: the whole mesher 9%
    /// faster at 100k points), and the sort itself writes more nearly in order. The output
    /// tets' vertices then get their input numbers ([`Builder::rank`]), bucket by bucket while
    /// it is in the cache (a pass of its own over the output took 1.65 ms at 109k points on
    /// two threads).
    fn finish(self, mut stats: DelaunayStats) -> Delaunay {
        use rayon::prelude::*;
        let start = Instant::now();
        let n = self.n_real;
        let arena = &self.tets[..self.used];
        let rank = &self.rank;
        // The sort key of each output tet (its largest vertex); NONE for free slots and
        // infinite tets. The passes below read this array, not the 36-byte tets.
        let key: Vec<u32> = arena
            .par_iter()
            .map(|tet| {
                let tv = tet.verts();
                if tet.mark() == DEAD || tv.iter().any(|&v| v >= n) {
                    NONE
                } else {
                    tv[0].max(tv[1]).max(tv[2]).max(tv[3])
                }
            })
            .collect();
        // Counting sort by key, one vertex range per thread (each scans `key` in
        // order and writes only its own part), then each small bucket by the other vertices.
        let parts = rayon::current_num_threads().clamp(1, 16);
        let mut offsets = Vec::with_capacity(n as usize + 1);
        offsets.push(0u32);
        for c in key_counts(&key, n, parts) {
            offsets.push(offsets[offsets.len() - 1] + c);
        }
        let bounds = balanced_bounds(&offsets, parts);
        // Fill the output arrays bucket by bucket (the rotated vertices and neighbour slots),
        // each thread its own vertex range; sort each small bucket; record where each slot
        // went; then map the neighbour slots to output positions.
        let total = offsets[n as usize] as usize;
        let mut tets = vec![[0u32; 4]; total];
        let mut neighbors = vec![[0u32; 4]; total];
        // Output position + 1 of each slot (0: not in the output).
        let new_id: Vec<AtomicU32> = bytemuck::allocation::zeroed_vec(arena.len());
        let mut parts_mut = Vec::with_capacity(parts);
        let (mut rt, mut rn) = (&mut tets[..], &mut neighbors[..]);
        for c in 0..parts {
            let len = (offsets[bounds[c + 1] as usize] - offsets[bounds[c] as usize]) as usize;
            let (at, bt) = rt.split_at_mut(len);
            let (an, bn) = rn.split_at_mut(len);
            parts_mut.push((c, at, an));
            (rt, rn) = (bt, bn);
        }
        parts_mut.into_par_iter().for_each(|(c, pt, pn)| {
            let (lo, hi) = (bounds[c], bounds[c + 1]);
            let base = offsets[lo as usize];
            let mut fill: Vec<u32> = offsets[lo as usize..hi as usize]
                .iter()
                .map(|o| o - base)
                .collect();
            // The slots of this part's tets, bucket by bucket (in slot order inside a bucket):
            // 4-byte scattered writes into a small array.
            let mut ps = vec![0u32; pt.len()];
            for (s, &f) in key.iter().enumerate() {
                if f >= lo && f < hi {
                    let i = &mut fill[(f - lo) as usize];
                    ps[*i as usize] = s as u32;
                    *i += 1;
                }
            }
            // Then bucket by bucket: the rotated tets in that order (sequential writes, and
            // reads of the arena that do not depend on each other, so their cache misses
            // overlap), each bucket sorted while it is in the cache. (Writing the 32 bytes of
            // each tet straight to its bucket as the slots were scanned: ~31 ms at 100k points
            // on one thread, against ~21 ms for a scatter of slots, then a gather. Sorting
            // the buckets in a pass of their own after the gather: 0.5 ms slower at 100k
            // points on two threads, 4% of the output stage.)
            let mut scratch = BucketScratch::default();
            for v in lo..hi {
                let (a, b) = (
                    (offsets[v as usize] - base) as usize,
                    (offsets[v as usize + 1] - base) as usize,
                );
                for i in a..b {
                    if let Some(&ahead) = ps.get(i + GATHER_AHEAD) {
                        prefetch(&arena[ahead as usize]);
                    }
                    let s = ps[i] as usize;
                    let (tv, tn) = (arena[s].verts(), arena[s].nbrs());
                    let p = EVEN_PERMS[canonical_rotation(tv) as usize];
                    pt[i] = p.map(|k| tv[k]);
                    pn[i] = p.map(|k| tn[k]);
                }
                // Each bucket sorted by its rotated vertices while it is in the cache, then
                // its vertices given their input numbers.
                sort_bucket(&mut pt[a..b], &mut pn[a..b], &mut ps[a..b], &mut scratch);
                for t in &mut pt[a..b] {
                    *t = t.map(|v| rank[v as usize]);
                }
            }
            for (i, &s) in ps.iter().enumerate() {
                new_id[s as usize].store(base + i as u32 + 1, Relaxed);
            }
        });
        neighbors.par_iter_mut().for_each(|nb| {
            *nb = nb.map(|x| {
                new_id
                    .get(x as usize)
                    .map_or(NONE, |i| i.load(Relaxed).wrapping_sub(1))
            });
        });
        let mut vertices = self.pos;
        vertices.truncate(n as usize);
        // The arena's release (an unmap) is part of the output stage.
        drop(self.tets);
        stats.times.output = start.elapsed();
        Delaunay {
            vertices,
            vertex_of_point: Vec::new(),
            tets,
            neighbors,
            stats,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The output split: bounds from 0 to n, never decreasing, each part within one bin's
    /// tets of an equal share (the keys skewed towards the newest vertices, as the output's
    /// are; `NONE` keys ignored), for any number of parts, vertex counts below and above the
    /// bin count, and no key at all.
    #[test]
    fn key_counts_and_balanced_bounds_split_the_keys_evenly() {
        let mut rng = SplitMix(7);
        for (n, len, parts) in [
            (100_000u32, 700_000usize, 2usize),
            (100_000, 700_000, 3),
            (5_000, 30_000, 16),
            (37, 300, 4),
            (1, 10, 2),
            (1_000, 0, 2),
        ] {
            let key: Vec<u32> = (0..len)
                .map(|_| {
                    let r = rng.next();
                    if r.is_multiple_of(10) {
                        NONE
                    } else {
                        // The larger of two uniform draws: most keys in the upper half.
                        ((r >> 8) % n as u64).max((r >> 36) % n as u64) as u32
                    }
                })
                .collect();
            let counts = key_counts(&key, n, parts);
            assert_eq!(counts.len(), n as usize);
            for v in [0, n / 2, n - 1] {
                let direct = key.iter().filter(|&&f| f == v).count();
                assert_eq!(counts[v as usize] as usize, direct, "key {v}");
            }
            let mut offsets = vec![0u32];
            for c in counts {
                offsets.push(offsets[offsets.len() - 1] + c);
            }
            let b = balanced_bounds(&offsets, parts);
            assert_eq!(b.len(), parts + 1);
            assert_eq!((b[0], b[parts]), (0, n));
            assert!(b.windows(2).all(|w| w[0] <= w[1]), "{b:?}");
            // The most tets of one key.
            let key_max = offsets.windows(2).map(|w| w[1] - w[0]).max().unwrap_or(0) as usize;
            let total = key.iter().filter(|&&f| f < n).count();
            for w in b.windows(2) {
                let inside = key.iter().filter(|&&f| f >= w[0] && f < w[1]).count();
                assert!(
                    inside.abs_diff(total / parts) <= key_max + parts,
                    "n {n} parts {parts}: {inside} of {total} in {w:?}"
                );
            }
        }
    }

    /// Skilling's transpose method as usually written, with branches.
    fn hilbert_index_reference(mut x: [u32; 3], bits: u32) -> u64 {
        let m = 1u32 << (bits - 1);
        let mut q = m;
        while q > 1 {
            let p = q - 1;
            for i in 0..3 {
                if x[i] & q != 0 {
                    x[0] ^= p;
                } else {
                    let t = (x[0] ^ x[i]) & p;
                    x[0] ^= t;
                    x[i] ^= t;
                }
            }
            q >>= 1;
        }
        for i in 1..3 {
            x[i] ^= x[i - 1];
        }
        let mut t = 0;
        let mut q = m;
        while q > 1 {
            if x[2] & q != 0 {
                t ^= q - 1;
            }
            q >>= 1;
        }
        for v in &mut x {
            *v ^= t;
        }
        let mut h = 0u64;
        for b in (0..bits).rev() {
            for v in &x {
                h = (h << 1) | ((v >> b) & 1) as u64;
            }
        }
        h
    }

    /// The keys of eight points at once are the keys of each point (with and without AVX2),
    /// and [`hilbert_keys`] gives every point its index and the key of its cell.
    #[test]
    fn hilbert_keys_in_lanes_are_the_keys_of_each_point() {
        let mut rng = SplitMix(11);
        for _ in 0..20_000 {
            let x: [[u32; 8]; 3] =
                std::array::from_fn(|_| std::array::from_fn(|_| rng.next() as u32 & 1023));
            let each: [u64; 8] = std::array::from_fn(|l| hilbert_index(x.map(|c| c[l]), 10));
            assert_eq!(hilbert_index_lanes(x, 10), each, "{x:?}");
            #[cfg(target_arch = "x86_64")]
            if std::arch::is_x86_feature_detected!("avx2") {
                // SAFETY: the CPU has AVX2.
                assert_eq!(unsafe { hilbert_index8_avx2(x, 10) }, each, "{x:?}");
            }
        }
        for n in [1usize, 7, 8, 9, 4095, 4096, 4097, 20_003] {
            let pts: Vec<[f64; 3]> = (0..n)
                .map(|_| [0; 3].map(|_: u8| (rng.next() >> 11) as f64 / (1u64 << 53) as f64 - 0.3))
                .collect();
            let keys = hilbert_keys(&pts);
            assert_eq!(keys.len(), n);
            let lo: [f64; 3] =
                std::array::from_fn(|k| pts.iter().map(|p| p[k]).fold(f64::INFINITY, f64::min));
            let hi: [f64; 3] =
                std::array::from_fn(|k| pts.iter().map(|p| p[k]).fold(f64::NEG_INFINITY, f64::max));
            for (i, (&(key, at), p)) in keys.iter().zip(&pts).enumerate() {
                assert_eq!(at as usize, i);
                let cell = |k: usize| {
                    let e = hi[k] - lo[k];
                    let scale = if e > 0.0 { 1023.0 / e } else { 0.0 };
                    (((p[k] - lo[k]) * scale) as u32).min(1023)
                };
                assert_eq!(
                    key,
                    hilbert_index([cell(0), cell(1), cell(2)], 10),
                    "n {n} point {i}"
                );
            }
        }
    }

    /// The branchless Hilbert index is the textbook one, and a bijection on a small grid
    /// whose consecutive cells are neighbours (so the reference itself is a Hilbert curve).
    #[test]
    fn hilbert_index_matches_the_reference() {
        let mut rng = SplitMix(7);
        for _ in 0..200_000 {
            let r = rng.next();
            let x = [
                r as u32 & 1023,
                (r >> 10) as u32 & 1023,
                (r >> 20) as u32 & 1023,
            ];
            assert_eq!(
                hilbert_index(x, 10),
                hilbert_index_reference(x, 10),
                "{x:?}"
            );
            let y = [
                r as u32 & 0x1f_ffff,
                (r >> 21) as u32 & 0x1f_ffff,
                (r >> 42) as u32 & 0x1f_ffff,
            ];
            assert_eq!(
                hilbert_index(y, 21),
                hilbert_index_reference(y, 21),
                "{y:?}"
            );
        }
        let mut cells = vec![[0u32; 3]; 512];
        for x in 0..8 {
            for y in 0..8 {
                for z in 0..8 {
                    let h = hilbert_index([x, y, z], 3);
                    assert_eq!(h, hilbert_index_reference([x, y, z], 3));
                    cells[h as usize] = [x, y, z];
                }
            }
        }
        for w in cells.windows(2) {
            let d: u32 = (0..3).map(|k| w[0][k].abs_diff(w[1][k])).sum();
            assert_eq!(d, 1, "{:?} -> {:?}", w[0], w[1]);
        }
    }

    /// [`distinct_points`] as it was before its runs were found in parallel (changed on
    /// 2026-12-05): one pass over the sorted points, then one over the input.
    fn distinct_points_reference(points: &[[f64; 3]], merge_within: f64) -> Distinct {
        let idx = curve_order(points);
        let mut group_of_point = vec![0u32; points.len()];
        let mut group_key = Vec::new();
        let near2 = merge_within * merge_within;
        let mut first = 0usize;
        for k in 0..idx.len() {
            let (key, i) = idx[k];
            let q = &points[i as usize];
            let same = k > 0 && {
                let p = &points[idx[k - 1].1 as usize];
                (p[0] == q[0] && p[1] == q[1] && p[2] == q[2])
                    || (near2 > 0.0 && {
                        let r = &points[idx[first].1 as usize];
                        (0..3).map(|c| (r[c] - q[c]) * (r[c] - q[c])).sum::<f64>() <= near2
                    })
            };
            if !same {
                group_key.push(key);
                first = k;
            }
            group_of_point[i as usize] = group_key.len() as u32 - 1;
        }
        let mut group_vertex = vec![u32::MAX; group_key.len()];
        let mut vertices = Vec::new();
        let mut vertex_of_point = vec![0u32; points.len()];
        for (i, p) in points.iter().enumerate() {
            let g = group_of_point[i] as usize;
            if group_vertex[g] == u32::MAX {
                group_vertex[g] = vertices.len() as u32;
                vertices.push(*p);
            }
            vertex_of_point[i] = group_vertex[g];
        }
        Distinct {
            vertices,
            vertex_of_point,
            hilbert: group_key.into_iter().zip(group_vertex).collect(),
        }
    }

    /// The vertices, the vertex of each point and the curve order are those of the one-pass
    /// reference, with exact duplicates (`-0.0` against `0.0` too), chains of near points
    /// and none at all.
    #[test]
    fn distinct_points_match_the_one_pass_reference() {
        let mut rng = SplitMix(11);
        for case in 0..60u64 {
            let n = [0usize, 1, 2, 9, 300, 5000][case as usize % 6];
            // Positions on a coarse lattice (many duplicates), near the lattice points (pairs
            // and chains within the merge distance), or anywhere.
            let step = [1e-6, 1e-3, 0.25][(case / 6) as usize % 3];
            let merge = [0.0, 0.4e-6, 1e-6, 3e-6, 1e-3][(case / 18) as usize % 5];
            let points: Vec<[f64; 3]> = (0..n)
                .map(|i| {
                    std::array::from_fn(|_| {
                        let r = rng.next();
                        match i % 4 {
                            0 => (r % 8) as f64 * step - 4.0 * step,
                            1 => (r % 8) as f64 * step + ((r >> 8) % 5) as f64 * 0.3e-6,
                            2 => -0.0,
                            _ => (r % 1_000_000) as f64 * 1e-6,
                        }
                    })
                })
                .collect();
            let got = distinct_points(&points, merge);
            let want = distinct_points_reference(&points, merge);
            assert_eq!(got.vertices, want.vertices, "case {case}");
            assert_eq!(got.vertex_of_point, want.vertex_of_point, "case {case}");
            assert_eq!(got.hilbert, want.hilbert, "case {case}");
        }
    }

    /// [`canonical_rotation`] as it was before its table: the first minimum brought to the
    /// front, then the first minimum of the other three.
    fn canonical_rotation_reference(tv: [u32; 4]) -> u8 {
        let i = (0..4).min_by_key(|&k| tv[k]).unwrap_or(0);
        let front = EVEN_PERMS[3 * i].map(|k| tv[k]);
        let j = (1..4).min_by_key(|&k| front[k]).unwrap_or(1) - 1;
        (3 * i + j) as u8
    }

    /// The table gives the rotation of the two searches for every order of four distinct
    /// vertices (and, for random ones, a rotation that is even, puts the smallest first and
    /// the smallest of the others second).
    #[test]
    fn canonical_rotation_matches_the_searches() {
        let mut orders = 0;
        for code in 0..256u32 {
            let tv =
                [code & 3, (code >> 2) & 3, (code >> 4) & 3, (code >> 6) & 3].map(|r| 10 * r + 7);
            let mut sorted = tv;
            sorted.sort_unstable();
            if sorted.windows(2).any(|w| w[0] == w[1]) {
                continue;
            }
            orders += 1;
            assert_eq!(
                canonical_rotation(tv),
                canonical_rotation_reference(tv),
                "{tv:?}"
            );
        }
        assert_eq!(orders, 24);
        let mut rng = SplitMix(9);
        for _ in 0..100_000 {
            let tv: [u32; 4] = std::array::from_fn(|_| rng.next() as u32);
            let mut sorted = tv;
            sorted.sort_unstable();
            if sorted.windows(2).any(|w| w[0] == w[1]) {
                continue;
            }
            let r = canonical_rotation(tv);
            assert_eq!(r, canonical_rotation_reference(tv), "{tv:?}");
            let rotated = EVEN_PERMS[r as usize].map(|k| tv[k]);
            assert_eq!(rotated[0], sorted[0]);
            assert_eq!(rotated[1], rotated[1].min(rotated[2]).min(rotated[3]));
        }
    }

    /// The insertion order is the one of sorting each round of the shuffle by (Hilbert key,
    /// shuffled position), which it replaces; tested with many equal keys (ties) and
    /// duplicated points.
    #[test]
    fn brio_order_sorts_each_round_of_the_shuffle_by_key() {
        let mut rng = SplitMix(3);
        for n in [0usize, 1, 5, 64, 65, 700, 5000] {
            // Half the points on a lattice of 4^3 positions far finer than a Hilbert cell (so
            // many share a cell or a position), the others anywhere in the unit cube.
            let points: Vec<[f64; 3]> = (0..n)
                .map(|i| {
                    std::array::from_fn(|_| {
                        if i % 2 == 0 {
                            (rng.next() % 4) as f64 * 1e-5
                        } else {
                            (rng.next() % 1_000_000) as f64 * 1e-6
                        }
                    })
                })
                .collect();
            let d = distinct_points(&points, 0.0);
            let nv = d.vertices.len();
            for (i, p) in points.iter().enumerate() {
                assert_eq!(d.vertices[d.vertex_of_point[i] as usize], *p);
            }
            let (order, rounds) = brio_order(&d.hilbert);
            // The reference: the shuffle, then each round sorted by (key, position in it).
            let keys = hilbert_keys(&d.vertices);
            let mut reference: Vec<u32> = (0..nv as u32).collect();
            let mut shuffle = SplitMix(0x005E_ED0F_D3A1);
            for i in (1..nv).rev() {
                let j = (shuffle.next() % (i as u64 + 1)) as usize;
                reference.swap(i, j);
            }
            for w in rounds.windows(2) {
                let mut round: Vec<(u64, usize, u32)> = reference[w[0]..w[1]]
                    .iter()
                    .enumerate()
                    .map(|(j, &v)| (keys[v as usize].0, j, v))
                    .collect();
                round.sort_unstable();
                for (slot, r) in reference[w[0]..w[1]].iter_mut().zip(&round) {
                    *slot = r.2;
                }
            }
            assert_eq!(order, reference, "{n} points, {nv} distinct");
            assert_eq!(rounds.first(), Some(&0));
            assert_eq!(rounds.last(), Some(&nv));
        }
    }

    /// `extremes_first` puts the box corners first (in their order) and leaves every other
    /// vertex in its round, in its order.
    #[test]
    fn extremes_go_first_and_the_rest_keep_their_rounds() {
        let mut rng = SplitMix(5);
        for n in [0usize, 3, 100, 5000] {
            let mut points: Vec<[f64; 3]> = (0..n)
                .map(|_| std::array::from_fn(|_| (rng.next() % 1_000_000) as f64 * 1e-6))
                .collect();
            let corners: Vec<[f64; 3]> = (0..8)
                .map(|c| std::array::from_fn(|k| if (c >> k) & 1 == 1 { 2.0 } else { -1.0 }))
                .collect();
            points.extend(&corners);
            let d = distinct_points(&points, 0.0);
            let (before, rounds_before) = brio_order(&d.hilbert);
            let (mut order, mut rounds) = (before.clone(), rounds_before.clone());
            extremes_first(&d.vertices, &mut order, &mut rounds);
            let is_corner = |v: u32| corners.contains(&d.vertices[v as usize]);
            let expected_front: Vec<u32> =
                before.iter().copied().filter(|&v| is_corner(v)).collect();
            assert_eq!(order[..8], expected_front[..], "{n} points");
            let round_of = |r: &[usize], j: usize| r.partition_point(|&x| x <= j) - 1;
            let mut sorted = order.clone();
            sorted.sort_unstable();
            assert_eq!(sorted, (0..d.vertices.len() as u32).collect::<Vec<_>>());
            let rest = |o: &[u32], r: &[usize]| -> Vec<(usize, u32)> {
                (0..o.len())
                    .filter(|&j| !is_corner(o[j]))
                    .map(|j| (round_of(r, j), o[j]))
                    .collect()
            };
            assert_eq!(rest(&order, &rounds), rest(&before, &rounds_before));
            assert_eq!(round_of(&rounds, 7), 0);
            assert_eq!((rounds[0], rounds.last()), (0, Some(&d.vertices.len())));
        }
    }

    /// Both paths of `sort_bucket` (rank sort and comparison sort) order the tets as a plain
    /// sort of the (tet, neighbours, slot) triples does.
    #[test]
    fn buckets_sort_like_a_plain_sort() {
        let mut rng = SplitMix(7);
        let mut scratch = BucketScratch::default();
        for len in 0..=2 * RANK_SORT_MAX {
            for round in 0..20 {
                // Distinct tets with few distinct vertex numbers (shared prefixes, as in a
                // bucket: every tet has the bucket's vertex) and, in some rounds, large ones.
                let range = if round % 2 == 0 {
                    6
                } else {
                    u32::MAX as u64 + 1
                };
                let mut items: Vec<([u32; 4], [u32; 4], u32)> = Vec::new();
                while items.len() < len {
                    let t = [0; 4].map(|_: u32| (rng.next() % range) as u32);
                    if items.iter().all(|it| it.0 != t) {
                        let n = [0; 4].map(|_: u32| rng.next() as u32);
                        items.push((t, n, rng.next() as u32));
                    }
                }
                let mut pt: Vec<[u32; 4]> = items.iter().map(|it| it.0).collect();
                let mut pn: Vec<[u32; 4]> = items.iter().map(|it| it.1).collect();
                let mut ps: Vec<u32> = items.iter().map(|it| it.2).collect();
                sort_bucket(&mut pt, &mut pn, &mut ps, &mut scratch);
                items.sort_unstable();
                let got: Vec<([u32; 4], [u32; 4], u32)> =
                    (0..len).map(|i| (pt[i], pn[i], ps[i])).collect();
                assert_eq!(got, items, "bucket of {len}, round {round}");
            }
        }
    }
}
