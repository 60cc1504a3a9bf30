//! Seeded sampling of meshes: area-weighted surface samples with face normals, sharp edges and
//! length-weighted edge samples.

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

use crate::trimesh::TriMesh;
use crate::vec3::{cross, norm, sub};

/// Oriented surface samples.
#[derive(Debug, Clone, Default)]
pub struct SurfaceSamples {
    /// Positions.
    pub points: Vec<[f64; 3]>,
    /// Unit face normals.
    pub normals: Vec<[f64; 3]>,
    /// Face each sample lies on.
    pub faces: Vec<u32>,
}

/// Area-weighted normal of face `f` (length = 2 * area).
pub fn face_cross(mesh: &TriMesh, f: usize) -> [f64; 3] {
    let [a, b, c] = mesh.triangle(f);
    cross(sub(b, a), sub(c, a))
}

/// Unit normal of face `f` (zero for a degenerate face).
pub fn face_normal(mesh: &TriMesh, f: usize) -> [f64; 3] {
    let n = face_cross(mesh, f);
    let l = norm(n);
    if l > 0.0 { n.map(|x| x / l) } else { [0.0; 3] }
}

/// Picks `n` indices with probability proportional to `weights` (cumulative table + binary
/// search); empty when all weights are zero.
pub fn weighted_indices(weights: &[f64], n: usize, rng: &mut ChaCha8Rng) -> Vec<u32> {
    let mut cdf = Vec::with_capacity(weights.len());
    let mut acc = 0.0;
    for w in weights {
        acc += w.max(0.0);
        cdf.push(acc);
    }
    if !(acc > 0.0) || !acc.is_finite() {
        return Vec::new();
    }
    (0..n)
        .map(|_| {
            let r = rng.random_range(0.0..acc);
            cdf.partition_point(|&c| c <= r).min(weights.len() - 1) as u32
        })
        .collect()
}

/// `n` area-weighted uniform samples with face normals, reproducible for a given `seed`.
/// A mesh without area gives no sample.
pub fn sample_surface(mesh: &TriMesh, n: usize, seed: u64) -> SurfaceSamples {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let areas: Vec<f64> = (0..mesh.faces.len())
        .map(|f| norm(face_cross(mesh, f)))
        .collect();
    let faces = weighted_indices(&areas, n, &mut rng);
    let mut out = SurfaceSamples::default();
    for f in faces {
        let [a, b, c] = mesh.triangle(f as usize);
        let (mut u, mut v): (f64, f64) = (rng.random(), rng.random());
        if u + v > 1.0 {
            u = 1.0 - u;
            v = 1.0 - v;
        }
        out.points.push(std::array::from_fn(|k| {
            a[k] + u * (b[k] - a[k]) + v * (c[k] - a[k])
        }));
        out.normals.push(face_normal(mesh, f as usize));
        out.faces.push(f);
    }
    out
}

/// Edges (vertex pairs, `a < b`) shared by exactly two faces whose normals make an angle above
/// `angle_deg` degrees (the dihedral "sharpness" of SPEC section 8, 30 degrees).
pub fn sharp_edges(mesh: &TriMesh, angle_deg: f64) -> Vec<[u32; 2]> {
    let mut edges: Vec<(u64, u32)> = Vec::with_capacity(3 * mesh.faces.len());
    for (fi, f) in mesh.faces.iter().enumerate() {
        for k in 0..3 {
            let (a, b) = (f[k], f[(k + 1) % 3]);
            let key = ((a.min(b) as u64) << 32) | a.max(b) as u64;
            edges.push((key, fi as u32));
        }
    }
    edges.sort_unstable();
    let cos_t = angle_deg.to_radians().cos();
    let mut out = Vec::new();
    let mut i = 0;
    while i < edges.len() {
        let mut j = i;
        while j < edges.len() && edges[j].0 == edges[i].0 {
            j += 1;
        }
        if j - i == 2 {
            let n1 = face_normal(mesh, edges[i].1 as usize);
            let n2 = face_normal(mesh, edges[i + 1].1 as usize);
            let d = n1[0] * n2[0] + n1[1] * n2[1] + n1[2] * n2[2];
            if d < cos_t {
                let key = edges[i].0;
                out.push([(key >> 32) as u32, key as u32]);
            }
        }
        i = j;
    }
    out
}

/// `n` length-weighted samples on `edges`, reproducible for a given `seed`.
pub fn sample_edges(mesh: &TriMesh, edges: &[[u32; 2]], n: usize, seed: u64) -> Vec<[f64; 3]> {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let lens: Vec<f64> = edges
        .iter()
        .map(|e| {
            norm(sub(
                mesh.vertices[e[1] as usize],
                mesh.vertices[e[0] as usize],
            ))
        })
        .collect();
    weighted_indices(&lens, n, &mut rng)
        .into_iter()
        .map(|i| {
            let [a, b] = edges[i as usize].map(|v| mesh.vertices[v as usize]);
            let t: f64 = rng.random();
            std::array::from_fn(|k| a[k] + t * (b[k] - a[k]))
        })
        .collect()
}
