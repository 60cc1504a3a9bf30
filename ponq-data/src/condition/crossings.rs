//! The zero set of a field sampled on a grid, as crossing points with normals, and the
//! (value, distance) pairs read off its flat pieces.

use ponq_mesh::nn::PointIndex;

/// A point where the field crosses zero along a grid edge, with the unit normal of the zero
/// set there (the field's gradient direction: from negative to positive).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Crossing {
    /// Position, in the window's node units times `h`.
    pub p: [f64; 3],
    /// Unit normal.
    pub n: [f64; 3],
}

/// Node values of a window of a grid: `dims` nodes in C order (`k` fastest).
fn at(dims: [usize; 3], i: usize, j: usize, k: usize) -> usize {
    (i * dims[1] + j) * dims[2] + k
}

/// The gradient of `u` at a node (central differences, one-sided at the window's border), in
/// value units per node step.
fn gradient(u: &[f64], dims: [usize; 3], x: [usize; 3]) -> [f64; 3] {
    std::array::from_fn(|a| {
        let mut lo = x;
        let mut hi = x;
        if x[a] > 0 {
            lo[a] -= 1;
        }
        if x[a] + 1 < dims[a] {
            hi[a] += 1;
        }
        let span = (hi[a] - lo[a]) as f64;
        if span == 0.0 {
            return 0.0;
        }
        (u[at(dims, hi[0], hi[1], hi[2])] - u[at(dims, lo[0], lo[1], lo[2])]) / span
    })
}

/// The crossings of `u` (node values of a window of `dims` nodes, spacing `h`): one per grid
/// edge whose ends have opposite signs (a zero end counts as positive), placed by linear
/// interpolation of `u`, its normal the gradient of `dir` (a field with the same level sets:
/// `u` itself, or the raw field `u` was mapped from) interpolated the same way. Edges whose
/// gradient vanishes are left out.
pub fn crossings(u: &[f64], dir: &[f64], dims: [usize; 3], h: f64) -> Vec<Crossing> {
    use rayon::prelude::*;
    (0..dims[0])
        .into_par_iter()
        .flat_map_iter(|i| plane_crossings(u, dir, dims, h, i))
        .collect()
}

/// The zero in `[0, 1]` of the cubic through `(-1, v0)`, `(0, v1)`, `(1, v2)`, `(2, v3)`
/// (`v1`, `v2` of opposite signs), by bisection; `guess` (the line's zero) when the cubic
/// has no single zero there.
fn cubic_zero(v: [f64; 4], guess: f64) -> f64 {
    // Lagrange basis at t for nodes -1, 0, 1, 2.
    let f = |t: f64| {
        let l0 = -t * (t - 1.0) * (t - 2.0) / 6.0;
        let l1 = (t + 1.0) * (t - 1.0) * (t - 2.0) / 2.0;
        let l2 = -(t + 1.0) * t * (t - 2.0) / 2.0;
        let l3 = (t + 1.0) * t * (t - 1.0) / 6.0;
        v[0] * l0 + v[1] * l1 + v[2] * l2 + v[3] * l3
    };
    let (mut lo, mut hi) = (0.0f64, 1.0f64);
    let (flo, fhi) = (f(lo), f(hi));
    if (flo < 0.0) == (fhi < 0.0) {
        return guess;
    }
    for _ in 0..50 {
        let mid = 0.5 * (lo + hi);
        if (f(mid) < 0.0) == (flo < 0.0) {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    0.5 * (lo + hi)
}

/// [`crossings`] of the edges from the nodes of plane `i`.
fn plane_crossings(u: &[f64], dir: &[f64], dims: [usize; 3], h: f64, i: usize) -> Vec<Crossing> {
    let mut out = Vec::new();
    {
        for j in 0..dims[1] {
            for k in 0..dims[2] {
                let x = [i, j, k];
                let a = u[at(dims, i, j, k)];
                for axis in 0..3 {
                    let mut y = x;
                    y[axis] += 1;
                    if y[axis] >= dims[axis] {
                        continue;
                    }
                    let b = u[at(dims, y[0], y[1], y[2])];
                    if (a < 0.0) == (b < 0.0) {
                        continue;
                    }
                    // The zero of the cubic through the edge's nodes and the next ones along
                    // its line (where they exist and the four values are monotone), else of the
                    // line: a field that bends between nodes (tanh) is placed within a hundredth
                    // of a cell, a linear one exactly as by the line.
                    let mut t = a / (a - b);
                    if x[axis] >= 1 && y[axis] + 1 < dims[axis] {
                        let (mut w, mut z) = (x, y);
                        w[axis] -= 1;
                        z[axis] += 1;
                        let (p0, p3) =
                            (u[at(dims, w[0], w[1], w[2])], u[at(dims, z[0], z[1], z[2])]);
                        let rising = p0 < a && a < b && b < p3;
                        let falling = p0 > a && a > b && b > p3;
                        if rising || falling {
                            t = cubic_zero([p0, a, b, p3], t);
                        }
                    }
                    let ga = gradient(dir, dims, x);
                    let gb = gradient(dir, dims, y);
                    let g: [f64; 3] = std::array::from_fn(|c| ga[c] + t * (gb[c] - ga[c]));
                    let len = (g[0] * g[0] + g[1] * g[1] + g[2] * g[2]).sqrt();
                    if !(len > 0.0 && len.is_finite()) {
                        continue;
                    }
                    let mut p = x.map(|c| c as f64);
                    p[axis] += t;
                    out.push(Crossing {
                        p: p.map(|c| c * h),
                        n: g.map(|c| c / len),
                    });
                }
            }
        }
    }
    out
}

/// Pairs (value, signed distance) at the nodes of a window where the distance is known from
/// the zero set: a node whose nearest crossings (the 8 nearest) lie on one plane (normals within
/// 12 degrees, within a tenth of a cell of the nearest one's plane, spread over the plane in
/// both directions: not along one edge), whose field gradient (of `field`, central differences)
/// points along that plane's normal within 8 degrees, and whose foot on the plane is within
/// `0.75 h` of the nearest crossing gets its distance to that plane. Nodes farther than
/// `max_cells` cells, nearer the window's border than their distance (a crossing outside the
/// window could be nearer), on the wrong side of the plane, or for which `skip(value)` holds
/// (clamped values of a truncated field) give no pair. The nodes tried are those within a
/// block of 8^3 nodes of one holding a crossing, strided down to at most `max_tried`.
#[allow(clippy::too_many_arguments)]
pub fn pairs(
    values: &[f64],
    field: &[f64],
    dims: [usize; 3],
    h: f64,
    zero_set: &[Crossing],
    max_cells: f64,
    max_tried: usize,
    skip: impl Fn(f64) -> bool + Sync,
) -> Vec<(f64, f64)> {
    use rayon::prelude::*;
    let points: Vec<[f64; 3]> = zero_set.iter().map(|c| c.p).collect();
    let Some(index) = PointIndex::new(&points) else {
        return Vec::new();
    };
    let cos_max = 12f64.to_radians().cos();
    let cos_grad = 8f64.to_radians().cos();
    let reach = max_cells * h;
    let dot = |a: [f64; 3], b: [f64; 3]| a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
    // Blocks of 8^3 nodes holding a crossing, and the nodes within one block of them.
    const B: usize = 8;
    let nb = dims.map(|d| d.div_ceil(B));
    let mut holds = vec![false; nb[0] * nb[1] * nb[2]];
    for c in zero_set {
        let b: [usize; 3] = std::array::from_fn(|a| ((c.p[a] / h) as usize / B).min(nb[a] - 1));
        holds[(b[0] * nb[1] + b[1]) * nb[2] + b[2]] = true;
    }
    let near_block = |b: [usize; 3]| {
        (b[0].saturating_sub(1)..=(b[0] + 1).min(nb[0] - 1)).any(|x| {
            (b[1].saturating_sub(1)..=(b[1] + 1).min(nb[1] - 1)).any(|y| {
                (b[2].saturating_sub(1)..=(b[2] + 1).min(nb[2] - 1))
                    .any(|z| holds[(x * nb[1] + y) * nb[2] + z])
            })
        })
    };
    let mut tried: Vec<usize> = Vec::new();
    for bx in 0..nb[0] {
        for by in 0..nb[1] {
            for bz in 0..nb[2] {
                if !near_block([bx, by, bz]) {
                    continue;
                }
                for i in bx * B..((bx + 1) * B).min(dims[0]) {
                    for j in by * B..((by + 1) * B).min(dims[1]) {
                        for k in bz * B..((bz + 1) * B).min(dims[2]) {
                            tried.push((i * dims[1] + j) * dims[2] + k);
                        }
                    }
                }
            }
        }
    }
    let stride = tried.len().div_ceil(max_tried.max(1)).max(1);
    tried
        .into_par_iter()
        .step_by(stride)
        .filter_map(|f| {
            let v = values[f];
            if skip(v) {
                return None;
            }
            let x = [
                f / (dims[1] * dims[2]),
                (f / dims[2]) % dims[1],
                f % dims[2],
            ];
            let q = x.map(|c| c as f64 * h);
            let near = index.nearest_k_within(&q, 8, (reach + 2.0 * h).powi(2));
            if near.len() < 6 {
                return None;
            }
            let c0 = zero_set[near[0].0 as usize];
            let r: [f64; 3] = std::array::from_fn(|a| q[a] - c0.p[a]);
            let d = dot(c0.n, r);
            if d.abs() > reach || (v != 0.0 && (v < 0.0) != (d < 0.0)) {
                return None;
            }
            let lateral2 = dot(r, r) - d * d;
            if lateral2 > (0.75 * h).powi(2) {
                return None;
            }
            // The window's border must be farther than the distance.
            let border = (0..3)
                .map(|a| x[a].min(dims[a] - 1 - x[a]))
                .min()
                .unwrap_or(0) as f64
                * h;
            if border < d.abs() + h {
                return None;
            }
            // The field falls towards the plane along its normal.
            let g = gradient(field, dims, x);
            let gl = dot(g, g).sqrt();
            if !(gl > 0.0) || dot(g, c0.n) < cos_grad * gl {
                return None;
            }
            // One plane: normals agree, points on it, spread in two directions.
            let mut cov = [[0.0f64; 3]; 3];
            for &(j, _) in &near {
                let c = zero_set[j as usize];
                let o: [f64; 3] = std::array::from_fn(|a| c.p[a] - c0.p[a]);
                let off = dot(c0.n, o);
                if dot(c.n, c0.n) < cos_max || off.abs() > 0.1 * h {
                    return None;
                }
                let t: [f64; 3] = std::array::from_fn(|a| o[a] - off * c0.n[a]);
                for a in 0..3 {
                    for b in 0..3 {
                        cov[a][b] += t[a] * t[b];
                    }
                }
            }
            // In-plane basis and the smaller eigenvalue of the offsets' 2x2 covariance.
            let e1 = {
                let a = if c0.n[0].abs() < 0.9 {
                    [1.0, 0.0, 0.0]
                } else {
                    [0.0, 1.0, 0.0]
                };
                let t: [f64; 3] = std::array::from_fn(|i| a[i] - dot(a, c0.n) * c0.n[i]);
                let l = dot(t, t).sqrt();
                t.map(|x| x / l)
            };
            let e2 = [
                c0.n[1] * e1[2] - c0.n[2] * e1[1],
                c0.n[2] * e1[0] - c0.n[0] * e1[2],
                c0.n[0] * e1[1] - c0.n[1] * e1[0],
            ];
            let quad = |a: [f64; 3], b: [f64; 3]| {
                (0..3)
                    .map(|i| (0..3).map(|j| a[i] * cov[i][j] * b[j]).sum::<f64>())
                    .sum::<f64>()
                    / near.len() as f64
            };
            let (m11, m12, m22) = (quad(e1, e1), quad(e1, e2), quad(e2, e2));
            let tr = m11 + m22;
            let det = m11 * m22 - m12 * m12;
            let small = 0.5 * (tr - (tr * tr - 4.0 * det).max(0.0).sqrt());
            (small >= (0.2 * h).powi(2)).then_some((v, d))
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A tilted plane's signed distance on a 20^3 window.
    fn plane(dims: [usize; 3], h: f64, n: [f64; 3], c: f64) -> Vec<f64> {
        let l = (n[0] * n[0] + n[1] * n[1] + n[2] * n[2]).sqrt();
        let mut v = Vec::new();
        for i in 0..dims[0] {
            for j in 0..dims[1] {
                for k in 0..dims[2] {
                    let p = [i, j, k].map(|a| a as f64 * h);
                    v.push((n[0] * p[0] + n[1] * p[1] + n[2] * p[2]) / l - c);
                }
            }
        }
        v
    }

    #[test]
    fn a_plane_gives_its_crossings_and_exact_pairs() {
        let dims = [20; 3];
        let h = 0.1;
        let u = plane(dims, h, [1.0, 2.0, 0.5], 1.2);
        let z = crossings(&u, &u, dims, h);
        assert!(z.len() > 100);
        let n = [1.0, 2.0, 0.5].map(|c: f64| c / 5.25f64.sqrt());
        for c in &z {
            // On the plane, with its normal.
            let d = (0..3).map(|a| n[a] * c.p[a]).sum::<f64>() - 1.2;
            assert!(d.abs() < 1e-12);
            assert!((0..3).all(|a| (c.n[a] - n[a]).abs() < 1e-9));
        }
        let p = pairs(&u, &u, dims, h, &z, 4.0, usize::MAX, |_| false);
        assert!(p.len() > 500, "{}", p.len());
        for (v, d) in p {
            assert!((v - d).abs() < 1e-9, "{v} {d}");
        }
    }

    #[test]
    fn corners_of_a_box_give_no_pairs_across_the_edge() {
        // The distance to a box's corner region: nodes in the edge's normal cone have their
        // nearest crossings on two faces: not flat, no pair.
        let dims = [24; 3];
        let h = 0.1;
        let mut u = Vec::new();
        for i in 0..24 {
            for j in 0..24 {
                for k in 0..24 {
                    let p = [i, j, k].map(|a| a as f64 * h - 1.2);
                    // A box |x|, |y| <= 0.5 (infinite along z).
                    let q = [p[0].abs() - 0.5, p[1].abs() - 0.5];
                    let out = (q[0].max(0.0).powi(2) + q[1].max(0.0).powi(2)).sqrt();
                    u.push(out + q[0].max(q[1]).min(0.0));
                }
            }
        }
        let z = crossings(&u, &u, dims, h);
        let p = pairs(&u, &u, dims, h, &z, 4.0, usize::MAX, |_| false);
        assert!(p.len() > 100);
        // Every pair is exact: the corner regions gave none.
        for (v, d) in p {
            assert!((v - d).abs() < 0.02 * h, "{v} {d}");
        }
    }
}
