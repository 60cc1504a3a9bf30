//! Welding: vertices at the same position, or within a tolerance of each other (the cracks of
//! a mesh whose vertices were written with too few digits or moved apart), become one.
//!
//! Written here rather than with a k-d tree crate: a hash grid of cells as wide as the
//! tolerance finds every pair within it by looking at 27 cells, and keeps the result
//! independent of the thread count (one pass in vertex order).

use std::collections::HashMap;

/// The vertex each vertex is welded to (the smallest index of its cluster, whose position is
/// kept) and the number of vertices merged away. Vertices within `tol` of each other are in
/// one cluster, and clusters are closed under that relation (a chain of close vertices is one
/// cluster); `tol = 0` merges exactly equal positions only (`-0.0` equals `0.0`).
pub(crate) fn weld_map(vertices: &[[f64; 3]], tol: f64) -> (Vec<u32>, usize) {
    let n = vertices.len();
    let mut parent: Vec<u32> = (0..n as u32).collect();
    fn find(p: &mut [u32], mut x: u32) -> u32 {
        while p[x as usize] != x {
            p[x as usize] = p[p[x as usize] as usize];
            x = p[x as usize];
        }
        x
    }
    let union = |p: &mut Vec<u32>, a: u32, b: u32| {
        let (ra, rb) = (find(p, a), find(p, b));
        if ra != rb {
            p[ra.max(rb) as usize] = ra.min(rb);
        }
    };
    if tol > 0.0 && tol.is_finite() {
        let cell = |p: &[f64; 3]| p.map(|x| (x / tol).floor() as i64);
        let mut grid: HashMap<[i64; 3], Vec<u32>> = HashMap::with_capacity(n);
        let tol2 = tol * tol;
        for (i, p) in vertices.iter().enumerate() {
            let c = cell(p);
            for dx in -1..=1 {
                for dy in -1..=1 {
                    for dz in -1..=1 {
                        if let Some(list) = grid.get(&[c[0] + dx, c[1] + dy, c[2] + dz]) {
                            for &j in list {
                                let q = &vertices[j as usize];
                                let d2: f64 = (0..3).map(|k| (p[k] - q[k]) * (p[k] - q[k])).sum();
                                if d2 <= tol2 {
                                    union(&mut parent, i as u32, j);
                                }
                            }
                        }
                    }
                }
            }
            grid.entry(c).or_default().push(i as u32);
        }
    } else {
        let key = |p: &[f64; 3]| p.map(|x| if x == 0.0 { 0u64 } else { x.to_bits() });
        let mut first: HashMap<[u64; 3], u32> = HashMap::with_capacity(n);
        for (i, p) in vertices.iter().enumerate() {
            let j = *first.entry(key(p)).or_insert(i as u32);
            union(&mut parent, i as u32, j);
        }
    }
    let map: Vec<u32> = (0..n as u32).map(|i| find(&mut parent, i)).collect();
    let merged = map
        .iter()
        .enumerate()
        .filter(|&(i, &r)| r != i as u32)
        .count();
    (map, merged)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn welds_exact_and_near_copies_only() {
        let v = [
            [0.0, 0.0, 0.0],
            [1.0, 0.0, 0.0],
            [-0.0, 0.0, 0.0],
            [1.0 + 1e-7, 0.0, 0.0],
            [0.5, 0.0, 0.0],
        ];
        let (m, merged) = weld_map(&v, 0.0);
        assert_eq!(m, vec![0, 1, 0, 3, 4]);
        assert_eq!(merged, 1);
        let (m, merged) = weld_map(&v, 1e-6);
        assert_eq!(m, vec![0, 1, 0, 1, 4]);
        assert_eq!(merged, 2);
        // Across a cell boundary of the hash grid.
        let v = [[0.999_999_9e-3, 0.0, 0.0], [1.000_000_1e-3, 0.0, 0.0]];
        assert_eq!(weld_map(&v, 1e-3).0, vec![0, 0]);
    }
}
