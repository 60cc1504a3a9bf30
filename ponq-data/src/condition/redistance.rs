//! The last resort of the conditioning: exact distances to a field's zero set, for a field no
//! map explains (its values follow no one function of the distance, or too few nodes could
//! tell which): the surface is then marching cubes', and its distances are exact.

use rayon::prelude::*;

use crate::error::{DataError, Result};
use crate::sdf::MeshSdf;

/// Signed distances, in the normalised frame (node `(i, j, k)` at `-1 + h (i, j, k)`), from the
/// nodes of a field `u` (after its level and sign: negative inside; `dims` nodes, C order) to
/// its zero set, as marching cubes places it: exact (to that surface) at every node within
/// `reach_cells` cells of a node of the other sign, and `+-reach_cells` cells elsewhere (a
/// truncated distance), signed by `u`.
///
/// # Errors
/// A grid without a sign change, or one marching cubes cannot mesh.
pub fn redistance(u: &[f64], dims: [usize; 3], h: f64, reach_cells: f64) -> Result<Vec<f64>> {
    let lo = [-1.0; 3];
    let hi: [f64; 3] = std::array::from_fn(|a| -1.0 + (dims[a] - 1) as f64 * h);
    let surface = ponq_mesh::marching_cubes::marching_cubes(u, dims, lo, hi)?;
    if surface.faces.is_empty() {
        return Err(DataError::Invalid(
            "the field's zero set is empty: nothing to take distances to".into(),
        ));
    }
    let sdf = MeshSdf::for_distances(&surface)?;
    // Nodes near the zero set: within a block (dilated) of a block holding both signs.
    const B: usize = 8;
    let nb = dims.map(|d| d.div_ceil(B));
    let at = |i: usize, j: usize, k: usize| (i * dims[1] + j) * dims[2] + k;
    let mut mixed = vec![false; nb[0] * nb[1] * nb[2]];
    for bx in 0..nb[0] {
        for by in 0..nb[1] {
            for bz in 0..nb[2] {
                let (mut neg, mut pos) = (false, false);
                // One node past the block's end, so that a sign change across its face counts.
                for i in bx * B..((bx + 1) * B + 1).min(dims[0]) {
                    for j in by * B..((by + 1) * B + 1).min(dims[1]) {
                        for k in bz * B..((bz + 1) * B + 1).min(dims[2]) {
                            if u[at(i, j, k)] < 0.0 {
                                neg = true;
                            } else {
                                pos = true;
                            }
                        }
                    }
                }
                mixed[(bx * nb[1] + by) * nb[2] + bz] = neg && pos;
            }
        }
    }
    let r = (reach_cells / B as f64).ceil() as usize;
    let near = |b: [usize; 3]| {
        (b[0].saturating_sub(r)..=(b[0] + r).min(nb[0] - 1)).any(|x| {
            (b[1].saturating_sub(r)..=(b[1] + r).min(nb[1] - 1)).any(|y| {
                (b[2].saturating_sub(r)..=(b[2] + r).min(nb[2] - 1))
                    .any(|z| mixed[(x * nb[1] + y) * nb[2] + z])
            })
        })
    };
    let far = reach_cells * h;
    let out: Vec<f64> = (0..u.len())
        .into_par_iter()
        .map(|f| {
            let x = [
                f / (dims[1] * dims[2]),
                (f / dims[2]) % dims[1],
                f % dims[2],
            ];
            let sign = if u[f] < 0.0 { -1.0 } else { 1.0 };
            if !near(x.map(|c| c / B)) {
                return sign * far;
            }
            let p = x.map(|c| -1.0 + c as f64 * h);
            sign * sdf.distance(p).min(far)
        })
        .collect();
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_sphere_field_gets_its_distances_back() {
        // A sphere's distance, and d |d| of it: re-distanced to marching cubes' surface,
        // within its error of the distance (a few hundredths of a cell for the distance; for
        // d |d|, whose zero set marching cubes places by a line, a third of a cell).
        let n = 33;
        let h = 2.0 / 32.0;
        let (mut d, mut sq) = (Vec::new(), Vec::new());
        for i in 0..n {
            for j in 0..n {
                for k in 0..n {
                    let p = [i, j, k].map(|c| -1.0 + c as f64 * h);
                    let r = (p[0] * p[0] + p[1] * p[1] + p[2] * p[2]).sqrt() - 0.6;
                    d.push(r);
                    sq.push(r * r.abs());
                }
            }
        }
        for (u, tol) in [(&d, 0.05), (&sq, 0.35)] {
            let got = redistance(u, [n; 3], h, 4.0).unwrap();
            for (g, e) in got.iter().zip(&d) {
                assert_eq!(g.signum(), e.signum());
                if e.abs() < 3.0 * h {
                    assert!((g - e).abs() < tol * h, "{g} {e}");
                } else {
                    assert!(g.abs() >= 3.0 * h - tol * h);
                }
            }
        }
    }
}
