//! Surface samples for PoNQ fitting and training, and the boundary samples of open surfaces
//! (SPEC section 6): samples on the boundary edges, duplicated, the copy's normal rotated by 90
//! degrees about the boundary (`normalise(edge x face normal)`), so that the quadrics of
//! boundary points become elongated along the boundary.

pub use ponq_mesh::sampling::{SurfaceSamples, face_normal, sample_surface, weighted_indices};

use ponq_mesh::TriMesh;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

/// Boundary edges (`a -> b` as oriented in their single face) with that face's index.
pub fn boundary_edges(mesh: &TriMesh) -> Vec<(u32, u32, u32)> {
    let mut e: Vec<(u32, u32, u32, u32)> = Vec::new();
    for (fi, f) in mesh.faces.iter().enumerate() {
        for k in 0..3 {
            let (a, b) = (f[k], f[(k + 1) % 3]);
            e.push((a.min(b), a.max(b), fi as u32, k as u32));
        }
    }
    e.sort_unstable();
    let mut out = Vec::new();
    let mut i = 0;
    while i < e.len() {
        let mut j = i;
        while j < e.len() && e[j].0 == e[i].0 && e[j].1 == e[i].1 {
            j += 1;
        }
        if j - i == 1 {
            let (_, _, fi, k) = e[i];
            let f = mesh.faces[fi as usize];
            out.push((f[k as usize], f[(k as usize + 1) % 3], fi));
        }
        i = j;
    }
    out
}

/// `n` length-weighted samples on the boundary edges, each emitted twice: with its face's
/// normal and with that normal rotated by 90 degrees about the edge (pointing out of the
/// surface across the boundary). Returns an empty set for a closed mesh.
pub fn sample_boundary(mesh: &TriMesh, n: usize, seed: u64) -> SurfaceSamples {
    let edges = boundary_edges(mesh);
    let mut out = SurfaceSamples::default();
    if edges.is_empty() || n == 0 {
        return out;
    }
    let lengths: Vec<f64> = edges
        .iter()
        .map(|&(a, b, _)| {
            let (p, q) = (mesh.vertices[a as usize], mesh.vertices[b as usize]);
            ((p[0] - q[0]).powi(2) + (p[1] - q[1]).powi(2) + (p[2] - q[2]).powi(2)).sqrt()
        })
        .collect();
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    for i in weighted_indices(&lengths, n, &mut rng) {
        let (a, b, f) = edges[i as usize];
        let (p, q) = (mesh.vertices[a as usize], mesh.vertices[b as usize]);
        let t: f64 = rng.random();
        let x = std::array::from_fn(|k| p[k] + t * (q[k] - p[k]));
        let nf = face_normal(mesh, f as usize);
        let e = [q[0] - p[0], q[1] - p[1], q[2] - p[2]];
        // The face lies to the left of a -> b (counter-clockwise): e x n points away from it.
        let r = [
            e[1] * nf[2] - e[2] * nf[1],
            e[2] * nf[0] - e[0] * nf[2],
            e[0] * nf[1] - e[1] * nf[0],
        ];
        let l = (r[0] * r[0] + r[1] * r[1] + r[2] * r[2]).sqrt();
        if !(l > 0.0) {
            continue;
        }
        out.points.push(x);
        out.normals.push(nf);
        out.faces.push(f);
        out.points.push(x);
        out.normals.push(r.map(|c| c / l));
        out.faces.push(f);
    }
    out
}
