//! The corners of a triangle mesh grouped by vertex, and whether a vertex's corners form one
//! cycle (a closed, oriented fan).
//!
//! A corner is an occurrence of a vertex `v` in a face `(v, r, r')`; it holds the directed edge
//! `r -> r'` of `v`'s link. [`corner_rows`] groups the corners of every vertex (compressed
//! rows, a counting sort, in parallel on large surfaces); [`one_cycle`] says whether a vertex's
//! corners form a single cycle. The half-edges ([`crate::halfedge`]), the fan certificate
//! ([`crate::fan`]) and the manifold check build on these two.

/// Surfaces with at least this many corners (3 per face; about 175k points) group them by
/// vertex in parallel ([`corner_rows`], [`HalfEdges::checking_links`]).
pub(crate) const PARALLEL_MIN_CORNERS: usize = 1 << 20;

/// The corners of the faces grouped by vertex (compressed rows, a counting sort): the corners
/// of vertex `v` are `rows[start[v]..start[v + 1]]`, in face order, each made by
/// `corner(face index, face, k)` for the face's position `k` holding `v`. Every index of
/// `faces` must be below `n`.
///
/// In parallel over vertex ranges: each thread scans all faces and counts, then writes, the
/// corners of its own range only (its part of `rows`), so the rows come out the same as from
/// one scan. A single scan was sequential and, past the cache, bound by its scattered writes
/// (at 870k faces ~20 ms, 12 times its time at 200k faces).
pub(crate) fn corner_rows<T: Copy + Default + Send + Sync>(
    faces: &[[u32; 3]],
    n: usize,
    corner: impl Fn(usize, &[u32; 3], usize) -> T + Sync,
) -> (Vec<u32>, Vec<T>) {
    // Below [`PARALLEL_MIN_CORNERS`] in one range: there the scan is fast (its rows fit in
    // the cache), and a parallel call from outside the pool waits for a worker to wake up
    // (fresh `ponq-mesh` processes, 10k-109k points: the manifold stage 0.2-0.5 ms slower).
    let parts = if 3 * faces.len() < PARALLEL_MIN_CORNERS {
        1
    } else {
        rayon::current_num_threads().clamp(1, 16)
    };
    corner_rows_in_parts(faces, n, parts, corner)
}

/// [`corner_rows`] with the vertices cut into `parts` ranges (at least one).
fn corner_rows_in_parts<T: Copy + Default + Send + Sync>(
    faces: &[[u32; 3]],
    n: usize,
    parts: usize,
    corner: impl Fn(usize, &[u32; 3], usize) -> T + Sync,
) -> (Vec<u32>, Vec<T>) {
    use rayon::prelude::*;
    // Range `c`: the vertices from `bound(c)` to `bound(c + 1)`. One range runs on this
    // thread (no call into the pool), several in parallel.
    let parts = parts.max(1);
    let chunk = n.div_ceil(parts).max(1);
    let bound = |c: usize| (chunk * c).min(n) as u32;
    // `start[v + 1]` counts the corners of `v`, then the prefix sums make it the row ends.
    let mut start = vec![0u32; n + 1];
    let count_range = |(c, count): (usize, &mut [u32])| {
        let lo = bound(c);
        for f in faces {
            for &v in f {
                if let Some(x) = v.checked_sub(lo).and_then(|i| count.get_mut(i as usize)) {
                    *x += 1;
                }
            }
        }
    };
    if parts == 1 {
        start[1..]
            .chunks_mut(chunk)
            .enumerate()
            .for_each(count_range);
    } else {
        start[1..]
            .par_chunks_mut(chunk)
            .enumerate()
            .for_each(count_range);
    }
    for v in 0..n {
        start[v + 1] += start[v];
    }
    let mut rows = vec![T::default(); start[n] as usize];
    // Each range's rows are one slice of `rows`.
    let mut slices = Vec::with_capacity(parts);
    let mut rest = &mut rows[..];
    for c in 0..parts {
        let len = (start[bound(c + 1) as usize] - start[bound(c) as usize]) as usize;
        let (mine, tail) = rest.split_at_mut(len);
        slices.push((c, mine));
        rest = tail;
    }
    let fill_range = |(c, mine): (usize, &mut [T])| {
        let (lo, hi) = (bound(c), bound(c + 1));
        let base = start[lo as usize];
        let mut fill: Vec<u32> = start[lo as usize..hi as usize]
            .iter()
            .map(|&s| s - base)
            .collect();
        for (fi, f) in faces.iter().enumerate() {
            for k in 0..3 {
                let v = f[k];
                if v >= lo && v < hi {
                    let i = &mut fill[(v - lo) as usize];
                    mine[*i as usize] = corner(fi, f, k);
                    *i += 1;
                }
            }
        }
    };
    if parts == 1 {
        slices.into_iter().for_each(fill_range);
    } else {
        slices.into_par_iter().for_each(fill_range);
    }
    (start, rows)
}

/// A corner of a vertex `v` as the directed edge `(r, r')` of `v`'s link it holds (its face
/// is `(v, r, r')`).
pub(crate) trait Link {
    fn link(&self) -> (u32, u32);
}

impl Link for (u32, u32) {
    #[inline(always)]
    fn link(&self) -> (u32, u32) {
        *self
    }
}

/// Whether the directed edges `(r, r')` (the corners of a vertex: faces `(v, r, r')`) form
/// one simple cycle: from the first, each edge's `r'` starts exactly one edge, and following
/// them comes back to the first after visiting all. (Each edge is then the only one starting
/// at its `r`, so the `r` are distinct, and so are the `r'`.) `false` for no edge.
pub(crate) fn one_cycle<C: Link>(corners: &[C]) -> bool {
    one_cycle_steps(corners, |_, _| {})
}

/// [`one_cycle`], calling `step(i, j)` for each corner `i` followed and its successor `j`
/// (corner `j`'s `r` is corner `i`'s `r'`). When the answer is `true`, every corner was `i`
/// once and `j` once (so `j`'s predecessor is known for every `j`).
pub(crate) fn one_cycle_steps<C: Link>(corners: &[C], step: impl FnMut(usize, usize)) -> bool {
    let n = corners.len();
    if n == 0 {
        return false;
    }
    if n > SMALL_DEGREE {
        one_cycle_sorted(corners, step)
    } else {
        one_cycle_quadratic(corners, step)
    }
}

/// [`one_cycle`] for a few corners: at each step a search of all of them, without early exit
/// (branch-free).
fn one_cycle_quadratic<C: Link>(corners: &[C], mut step_to: impl FnMut(usize, usize)) -> bool {
    let n = corners.len();
    let mut cur = 0usize;
    for step in 0..n {
        let next = corners[cur].link().1;
        let (mut found, mut count) = (0usize, 0u32);
        for (j, c) in corners.iter().enumerate() {
            let hit = c.link().0 == next;
            found = if hit { j } else { found };
            count += hit as u32;
        }
        if count != 1 {
            return false;
        }
        step_to(cur, found);
        cur = found;
        if cur == 0 {
            // Back at the start: all corners visited iff this took n steps (a corner seen
            // twice before would be on a cycle without the first, never coming back).
            return step == n - 1;
        }
    }
    false
}

/// Degrees up to this are tested by [`one_cycle_quadratic`], larger ones by
/// [`one_cycle_sorted`].
const SMALL_DEGREE: usize = 32;

/// [`one_cycle`] in `O(n log n)`: the corners sorted by first vertex (a repeated one fails),
/// then the successors found by binary search.
fn one_cycle_sorted<C: Link>(corners: &[C], mut step_to: impl FnMut(usize, usize)) -> bool {
    let n = corners.len();
    // (r, r', index), sorted by r.
    let mut e: Vec<(u32, u32, usize)> = corners
        .iter()
        .enumerate()
        .map(|(i, c)| {
            let (r, r2) = c.link();
            (r, r2, i)
        })
        .collect();
    e.sort_unstable();
    if e.windows(2).any(|w| w[0].0 == w[1].0) {
        return false;
    }
    let next = |x: u32| e.binary_search_by_key(&x, |p| p.0).ok().map(|i| e[i]);
    let first = corners[0].link().0;
    let (mut cur, mut steps) = (0usize, 0usize);
    loop {
        match next(corners[cur].link().1) {
            Some((_, _, j)) if steps < n => {
                step_to(cur, j);
                cur = j;
                steps += 1;
                if corners[cur].link().0 == first {
                    return steps == n;
                }
            }
            _ => return false,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The corner rows in any number of vertex ranges are those of one plain counting sort,
    /// on random faces over vertices some of which are in no face.
    #[test]
    fn corner_rows_in_parts_are_one_scans() {
        use rand::{Rng, SeedableRng};
        let mut rng = rand::rngs::StdRng::seed_from_u64(17);
        for (n, nf) in [(0, 0), (1, 0), (3, 1), (7, 5), (1000, 3000), (4097, 40_000)] {
            let faces: Vec<[u32; 3]> = (0..nf)
                .map(|_| [0; 3].map(|_| rng.random_range(0..n as u32)))
                .collect();
            let corner = |fi: usize, f: &[u32; 3], k: usize| (fi as u32, f[(k + 1) % 3]);
            let mut start = vec![0u32; n + 1];
            let mut rows: Vec<Vec<(u32, u32)>> = vec![Vec::new(); n];
            for (fi, f) in faces.iter().enumerate() {
                for k in 0..3 {
                    rows[f[k] as usize].push(corner(fi, f, k));
                }
            }
            for v in 0..n {
                start[v + 1] = start[v] + rows[v].len() as u32;
            }
            let flat: Vec<(u32, u32)> = rows.concat();
            for parts in [1, 2, 3, 5, 16] {
                let got = corner_rows_in_parts(&faces, n, parts, corner);
                assert_eq!(got, (start.clone(), flat.clone()), "n {n}, {parts} parts");
            }
            assert_eq!(corner_rows(&faces, n, corner), (start, flat), "n {n}");
        }
    }

    #[test]
    fn both_cycle_tests_agree() {
        // Random corner sets over few vertices (repeats, dead ends, several cycles) and
        // shuffled cycles, small and large.
        let mut s = 0x2545_F491_4F6C_DD1Du64;
        let mut r = |m: u32| {
            s ^= s << 13;
            s ^= s >> 7;
            s ^= s << 17;
            (s % m as u64) as u32
        };
        let (mut cycles, mut others) = (0, 0);
        for case in 0..4000 {
            let n = 1 + r(if case % 2 == 0 { 8 } else { 80 }) as usize;
            let mut c: Vec<(u32, u32)> = if case % 3 == 0 {
                (0..n).map(|_| (r(n as u32 + 2), r(n as u32 + 2))).collect()
            } else {
                // A cycle through a shuffled ring, sometimes with one end changed.
                let mut ring: Vec<u32> = (0..n as u32).map(|i| 3 * i + 1).collect();
                for i in (1..n).rev() {
                    ring.swap(i, r(i as u32 + 1) as usize);
                }
                let mut c: Vec<(u32, u32)> = (0..n).map(|i| (ring[i], ring[(i + 1) % n])).collect();
                if case % 3 == 2 {
                    let i = r(n as u32) as usize;
                    c[i].1 = ring[r(n as u32) as usize];
                }
                c
            };
            for i in (1..c.len()).rev() {
                c.swap(i, r(i as u32 + 1) as usize);
            }
            // The quadratic test whatever the size; on a cycle, both report every corner's
            // predecessor, the corner whose r' is its r.
            let (mut p1, mut p2) = (vec![usize::MAX; c.len()], vec![usize::MAX; c.len()]);
            let small = one_cycle_quadratic(&c, |i, j| p1[j] = i);
            assert_eq!(small, one_cycle_sorted(&c, |i, j| p2[j] = i), "{c:?}");
            assert_eq!(one_cycle(&c), small);
            if small {
                assert_eq!(p1, p2);
                assert!((0..c.len()).all(|j| p1[j] < c.len() && c[p1[j]].1 == c[j].0));
            }
            if small { cycles += 1 } else { others += 1 }
        }
        assert!(cycles > 500 && others > 500, "{cycles} / {others}");
    }
}
