//! The canonical output ([`Builder::finish`]): the finite tets rotated to a canonical form and
//! sorted by their largest vertex, then by their vertices, with their neighbours, so that the
//! result does not depend on the worker count or timing.

use std::sync::atomic::AtomicU32;
use std::sync::atomic::Ordering::Relaxed;
use std::time::Instant;

use super::builder::Builder;
use super::store::DEAD;
use super::triangulation::{Delaunay, DelaunayStats, NONE};

/// How many items ahead a gather through a permutation asks for (see [`prefetch`]): the
/// output's tets from their arena slots in [`Builder::finish`]. Measured with 8, 16 and 32:
/// the same.
pub(super) const GATHER_AHEAD: usize = 16;

/// Asks the CPU to bring the cache lines of `x` (at most two: `size_of::<T>() <= 64`) into
/// the cache, for a read soon. A gather through a permutation misses the cache at every
/// step; the out-of-order core overlaps only a few of those misses, the prefetches many
/// more (the output stage at 400k points: 155 -> 106 ms on two threads). No effect on any
/// result.
#[inline(always)]
pub(super) fn prefetch<T>(x: &T) {
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
pub(super) const EVEN_PERMS: [[usize; 4]; 12] = {
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
pub(super) fn canonical_rotation(tv: [u32; 4]) -> u8 {
    ROTATION_BY_ORDER[order_code(tv)]
}

/// The six comparisons of four values as bits: `v0 < v1`, `v0 < v2`, `v0 < v3`, `v1 < v2`,
/// `v1 < v3`, `v2 < v3` (bit 0 first).
#[inline(always)]
pub(super) const fn order_code(v: [u32; 4]) -> usize {
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
pub(super) const ROTATION_BY_ORDER: [u8; 64] = {
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
pub(super) const RANK_SORT_MAX: usize = 24;

/// The number of output tets of each sort key `0..n` (a tet's largest vertex; [`NONE`] and
/// any other key `>= n` is not counted), in one pass over `key` shared by `parts` threads.
pub(super) fn key_counts(key: &[u32], n: u32, parts: usize) -> Vec<u32> {
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
pub(super) fn balanced_bounds(offsets: &[u32], parts: usize) -> Vec<u32> {
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
pub(super) struct BucketScratch {
    pub(super) ranked: [(u128, [u32; 4], [u32; 4], u32); RANK_SORT_MAX],
    pub(super) bucket: Vec<([u32; 4], [u32; 4], u32)>,
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
pub(super) fn sort_bucket(
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

impl Builder {
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
    pub(super) fn finish(self, mut stats: DelaunayStats) -> Delaunay {
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
    use crate::delaunay::order::SplitMix;

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
