//! Ground-truth occupancy and the "close" mask of the `N^3` cells of a grid over `[-1,1]^3`
//! (SPEC section 4).
//!
//! Cell `(i, j, k)` spans `[-1 + 2i/N, -1 + 2(i+1)/N] x ...`; its corners are the nodes
//! `(i..=i+1, j..=j+1, k..=k+1)` of the `(N+1)^3` SDF grid ([`crate::sdf::SdfGrid`]). Masks are
//! `Vec<bool>` of `N^3` entries in C order: cell `(i, j, k)` at `(i * N + j) * N + k`.

use crate::error::{DataError, Result};

/// Index of the cell holding coordinate `x`: `floor((x + 1) / 2 * n)` clamped to `0..n`
/// (so `x = 1` belongs to the last cell); `None` for a non-finite `x`.
#[inline]
pub fn cell_coord(x: f64, n: usize) -> Option<usize> {
    if !x.is_finite() {
        return None;
    }
    let c = ((x + 1.0) * 0.5 * n as f64).floor();
    Some(if c <= 0.0 { 0 } else { (c as usize).min(n - 1) })
}

/// C-order index of the cell holding `p` (see [`cell_coord`]); `None` when a coordinate is
/// not finite. `n` must be positive.
#[inline]
pub fn cell_index(p: [f64; 3], n: usize) -> Option<usize> {
    let i = cell_coord(p[0], n)?;
    let j = cell_coord(p[1], n)?;
    let k = cell_coord(p[2], n)?;
    Some((i * n + j) * n + k)
}

/// Number of samples per cell of an `n^3` grid (C order); samples outside `[-1,1]^3` count in
/// the nearest boundary cell, non-finite ones are ignored.
///
/// # Errors
/// `n == 0`.
pub fn sample_counts(points: &[[f64; 3]], n: usize) -> Result<Vec<u32>> {
    check_n(n)?;
    let mut counts = vec![0u32; n * n * n];
    for &p in points {
        if let Some(c) = cell_index(p, n) {
            counts[c] = counts[c].saturating_add(1);
        }
    }
    Ok(counts)
}

/// Ground-truth occupancy: a cell is occupied when it holds at least one surface sample
/// (cell of a sample as in [`cell_coord`]).
///
/// # Errors
/// `n == 0`.
pub fn occupancy_from_samples(points: &[[f64; 3]], n: usize) -> Result<Vec<bool>> {
    check_n(n)?;
    let mut occ = vec![false; n * n * n];
    for &p in points {
        if let Some(c) = cell_index(p, n) {
            occ[c] = true;
        }
    }
    Ok(occ)
}

/// The "close" threshold `2 sqrt(3) / (n + 1)` in `[-1,1]` units.
pub fn close_threshold(n: usize) -> f64 {
    2.0 * 3f64.sqrt() / (n as f64 + 1.0)
}

/// The "close" mask of the `n^3` cells from the `(n+1)^3` node values of an SDF grid (C
/// order, `[-1,1]` units, any float type): a cell is close when all 8 corner values satisfy
/// `|sdf| < 2 sqrt(3) / (n + 1)`.
///
/// # Errors
/// `n == 0`, or `values.len() != (n+1)^3`.
pub fn close_mask<T: Copy + Into<f64>>(values: &[T], n: usize) -> Result<Vec<bool>> {
    check_n(n)?;
    let m = n + 1;
    if values.len() != m * m * m {
        return Err(DataError::Invalid(format!(
            "a close mask of {n}^3 cells needs {m}^3 = {} node values, got {}",
            m * m * m,
            values.len()
        )));
    }
    let t = close_threshold(n);
    let near: Vec<bool> = values.iter().map(|&v| v.into().abs() < t).collect();
    let mut out = vec![false; n * n * n];
    for i in 0..n {
        for j in 0..n {
            for k in 0..n {
                let a = (i * m + j) * m + k;
                out[(i * n + j) * n + k] = [0, 1, m, m + 1]
                    .iter()
                    .all(|&o| near[a + o] && near[a + o + m * m]);
            }
        }
    }
    Ok(out)
}

fn check_n(n: usize) -> Result<()> {
    if n == 0 {
        return Err(DataError::Invalid(
            "the grid must have at least one cell per axis".into(),
        ));
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn cells_clamp() {
        assert_eq!(cell_coord(-1.0, 4), Some(0));
        assert_eq!(cell_coord(-1.5, 4), Some(0));
        assert_eq!(cell_coord(1.0, 4), Some(3));
        assert_eq!(cell_coord(0.0, 4), Some(2));
        assert_eq!(cell_coord(-0.0001, 4), Some(1));
        assert_eq!(cell_coord(f64::NAN, 4), None);
        assert_eq!(cell_index([1.0, -1.0, 0.0], 4), Some(3 * 16 + 2));
    }

    #[test]
    fn close_mask_of_constant_grids() {
        let n = 3;
        let t = close_threshold(n) as f32;
        let small = vec![0.5 * t; 64];
        assert!(close_mask(&small, n).unwrap().iter().all(|&c| c));
        let mut one_far = small.clone();
        one_far[0] = 2.0 * t;
        let m = close_mask(&one_far, n).unwrap();
        assert!(!m[0] && m[1..].iter().all(|&c| c));
        assert!(close_mask(&small[1..], n).is_err());
    }
}
