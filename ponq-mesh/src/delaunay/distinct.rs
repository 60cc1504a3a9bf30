//! Duplicate merging: the distinct points of an input (exact duplicates, and points within
//! `DelaunayOptions::merge_within` of each other) and their order along the Hilbert curve,
//! from one sort.

use super::order::curve_order;

/// The distinct points of an input and their order along the Hilbert curve, from one sort.
pub(super) struct Distinct {
    /// The distinct points, numbered by the first occurrence of each position in input order.
    pub(super) vertices: Vec<[f64; 3]>,
    /// For each input point, its vertex.
    pub(super) vertex_of_point: Vec<u32>,
    /// The vertices along the Hilbert curve with their keys (ties: by position).
    pub(super) hilbert: Vec<(u64, u32)>,
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
pub(super) fn distinct_points(points: &[[f64; 3]], merge_within: f64) -> Distinct {
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::delaunay::order::{SplitMix, brio_order, extremes_first, hilbert_keys};

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
}
