//! Marching cubes on a grid of signed values: the baseline reconstruction users know.
//!
//! Instead of the 256-case lookup table, each cube's polygons are built from its faces: on every
//! face the sign changes along the edges are joined by segments (an ambiguous face, with
//! alternating signs, is split by the sign of its centre value, the mean of its corners, as in
//! marching squares). Both cubes sharing a face make the same decision from the same four values,
//! so the surface has no crack; the segments of one cube close into polygons that are
//! triangulated around their centroid. Vertices on grid edges are shared between cubes.
//! Output faces are oriented with their normals towards positive values (outside).

use std::collections::HashMap;

use crate::error::{Error, Result};
use crate::trimesh::TriMesh;

/// Corner offsets of a cube, bit 0 = x, bit 1 = y, bit 2 = z.
const CORNER: [[usize; 3]; 8] = [
    [0, 0, 0],
    [1, 0, 0],
    [0, 1, 0],
    [1, 1, 0],
    [0, 0, 1],
    [1, 0, 1],
    [0, 1, 1],
    [1, 1, 1],
];

/// The six faces as corner cycles, counter-clockwise seen from outside the cube.
const FACE: [[usize; 4]; 6] = [
    [0, 4, 6, 2], // x = 0, normal -x
    [1, 3, 7, 5], // x = 1, normal +x
    [0, 1, 5, 4], // y = 0, normal -y
    [2, 6, 7, 3], // y = 1, normal +y
    [0, 2, 3, 1], // z = 0, normal -z
    [4, 5, 7, 6], // z = 1, normal +z
];

/// Extracts the zero level set of `values`, given on the `(nx, ny, nz)` nodes (C order, x
/// slowest) of a grid spanning the box `lo..hi`. Values below zero are inside. Non-finite
/// values are an error.
pub fn marching_cubes(
    values: &[f64],
    dims: [usize; 3],
    lo: [f64; 3],
    hi: [f64; 3],
) -> Result<TriMesh> {
    let [nx, ny, nz] = dims;
    if nx < 2 || ny < 2 || nz < 2 {
        return Err(Error::InvalidInput(format!(
            "marching cubes needs at least 2 nodes per axis, got {dims:?}"
        )));
    }
    if values.len() != nx * ny * nz {
        return Err(Error::InvalidInput(format!(
            "{} values for a {nx}x{ny}x{nz} grid",
            values.len()
        )));
    }
    if let Some(i) = values.iter().position(|v| !v.is_finite()) {
        return Err(Error::InvalidInput(format!("grid value {i} is not finite")));
    }
    let node = |i: usize, j: usize, k: usize| (i * ny + j) * nz + k;
    let pos = |i: usize, j: usize, k: usize| {
        let t = |a: usize, n: usize, d: usize| lo[d] + (hi[d] - lo[d]) * a as f64 / (n - 1) as f64;
        [t(i, nx, 0), t(j, ny, 1), t(k, nz, 2)]
    };
    let inside = |v: f64| v < 0.0;
    let mut vertices: Vec<[f64; 3]> = Vec::new();
    let mut faces: Vec<[u32; 3]> = Vec::new();
    // Edge (node a < node b) -> vertex index.
    let mut edge_vertex: HashMap<(usize, usize), u32> = HashMap::new();
    let mut segs: Vec<(u32, u32)> = Vec::new();
    for i in 0..nx - 1 {
        for j in 0..ny - 1 {
            for k in 0..nz - 1 {
                let cn: [usize; 8] = std::array::from_fn(|c| {
                    node(i + CORNER[c][0], j + CORNER[c][1], k + CORNER[c][2])
                });
                let cv: [f64; 8] = std::array::from_fn(|c| values[cn[c]]);
                let n_in = cv.iter().filter(|&&v| inside(v)).count();
                if n_in == 0 || n_in == 8 {
                    continue;
                }
                let mut vertex_on = |a: usize, b: usize| -> u32 {
                    let (na, nb) = (cn[a], cn[b]);
                    let key = (na.min(nb), na.max(nb));
                    *edge_vertex.entry(key).or_insert_with(|| {
                        let (va, vb) = (values[key.0], values[key.1]);
                        // Keep the vertex strictly inside the edge so that vertices never
                        // coincide at a node.
                        let t = (va / (va - vb)).clamp(1e-6, 1.0 - 1e-6);
                        let pa = pos(key.0 / (ny * nz), (key.0 / nz) % ny, key.0 % nz);
                        let pb = pos(key.1 / (ny * nz), (key.1 / nz) % ny, key.1 % nz);
                        vertices.push(std::array::from_fn(|d| pa[d] + t * (pb[d] - pa[d])));
                        (vertices.len() - 1) as u32
                    })
                };
                segs.clear();
                for f in &FACE {
                    // Crossings along the counter-clockwise walk: (vertex, is_entry).
                    let mut cr: Vec<(u32, bool)> = Vec::with_capacity(4);
                    for s in 0..4 {
                        let (a, b) = (f[s], f[(s + 1) % 4]);
                        if inside(cv[a]) != inside(cv[b]) {
                            cr.push((vertex_on(a, b), !inside(cv[a])));
                        }
                    }
                    match cr.len() {
                        2 => {
                            let (e, x) = if cr[0].1 {
                                (cr[0], cr[1])
                            } else {
                                (cr[1], cr[0])
                            };
                            segs.push((e.0, x.0));
                        }
                        4 => {
                            let centre_inside = f.iter().map(|&c| cv[c]).sum::<f64>() < 0.0;
                            for s in 0..4 {
                                if !cr[s].1 {
                                    continue;
                                }
                                // An entry is joined to the exit that follows it (cutting off
                                // an inside corner) or, when the centre is inside, to the exit
                                // that precedes it (cutting off an outside corner).
                                let x = if centre_inside {
                                    cr[(s + 3) % 4]
                                } else {
                                    cr[(s + 1) % 4]
                                };
                                segs.push((cr[s].0, x.0));
                            }
                        }
                        _ => {}
                    }
                }
                // Close the segments into loops and triangulate each around its centroid.
                let mut used = vec![false; segs.len()];
                for s0 in 0..segs.len() {
                    if used[s0] {
                        continue;
                    }
                    let mut lp = vec![segs[s0].0];
                    used[s0] = true;
                    let mut cur = segs[s0].1;
                    while cur != lp[0] {
                        lp.push(cur);
                        match (0..segs.len()).find(|&s| !used[s] && segs[s].0 == cur) {
                            Some(s) => {
                                used[s] = true;
                                cur = segs[s].1;
                            }
                            None => break,
                        }
                    }
                    if lp.len() < 3 {
                        continue;
                    }
                    if lp.len() == 3 {
                        faces.push([lp[0], lp[1], lp[2]]);
                        continue;
                    }
                    let c: [f64; 3] = std::array::from_fn(|d| {
                        lp.iter().map(|&v| vertices[v as usize][d]).sum::<f64>() / lp.len() as f64
                    });
                    vertices.push(c);
                    let ci = (vertices.len() - 1) as u32;
                    for s in 0..lp.len() {
                        faces.push([lp[s], lp[(s + 1) % lp.len()], ci]);
                    }
                }
            }
        }
    }
    Ok(TriMesh { vertices, faces })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::validity;

    fn grid(n: usize, mut f: impl FnMut([f64; 3]) -> f64) -> Vec<f64> {
        let mut v = Vec::new();
        for i in 0..=n {
            for j in 0..=n {
                for k in 0..=n {
                    let p = [i, j, k].map(|a| -1.0 + 2.0 * a as f64 / n as f64);
                    v.push(f(p));
                }
            }
        }
        v
    }

    #[test]
    fn sphere_is_closed_oriented_and_has_the_right_volume() {
        let n = 24;
        let v = grid(n, |p| {
            (p[0] * p[0] + p[1] * p[1] + p[2] * p[2]).sqrt() - 0.61
        });
        let m = marching_cubes(&v, [n + 1; 3], [-1.0; 3], [1.0; 3]).unwrap();
        let r = validity::check(&m);
        assert!(r.is_valid(), "{r}");
        let exact = 4.0 / 3.0 * std::f64::consts::PI * 0.61f64.powi(3);
        assert!(
            (m.signed_volume() - exact).abs() / exact < 0.02,
            "{}",
            m.signed_volume()
        );
    }

    #[test]
    fn ambiguous_configurations_stay_watertight() {
        // Random values on a coarse grid: every ambiguous face and cube case occurs.
        let mut seed = 11u64;
        for _ in 0..40 {
            let n = 6;
            let v = grid(n, |_| {
                seed ^= seed << 13;
                seed ^= seed >> 7;
                seed ^= seed << 17;
                (seed >> 11) as f64 / (1u64 << 53) as f64 - 0.5
            });
            // Keep the border outside so that the surface is closed.
            let v: Vec<f64> = v
                .iter()
                .enumerate()
                .map(|(idx, &x)| {
                    let (i, j, k) = (idx / 49, (idx / 7) % 7, idx % 7);
                    if [i, j, k].iter().any(|&a| a == 0 || a == n) {
                        1.0
                    } else {
                        x
                    }
                })
                .collect();
            let m = marching_cubes(&v, [n + 1; 3], [-1.0; 3], [1.0; 3]).unwrap();
            let r = validity::check_topology(&m);
            assert!(r.closed && r.oriented, "{r}");
            assert!(m.signed_volume() > 0.0);
        }
    }

    #[test]
    fn bad_grids_are_errors() {
        assert!(marching_cubes(&[0.0; 8], [2, 2, 2], [-1.0; 3], [1.0; 3]).is_ok());
        assert!(marching_cubes(&[0.0; 7], [2, 2, 2], [-1.0; 3], [1.0; 3]).is_err());
        assert!(marching_cubes(&[0.0; 4], [1, 2, 2], [-1.0; 3], [1.0; 3]).is_err());
        assert!(marching_cubes(&[f64::NAN; 8], [2, 2, 2], [-1.0; 3], [1.0; 3]).is_err());
    }
}
