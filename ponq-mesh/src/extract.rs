//! Step 4 of the mesher: the triangles between inside and outside tets, oriented outward.

use crate::complex::{FACES, Label, TetComplex, is_outside};
use crate::trimesh::TriMesh;

/// The triangles between inside tets and outside tets (or the hull), oriented outward, as
/// Delaunay vertex indices, in tet order.
pub fn boundary_faces(cx: &TetComplex, labels: &[Label]) -> Vec<[u32; 3]> {
    use rayon::prelude::*;
    // Chunks of tets, each collected in order, then joined.
    const CHUNK: usize = 1 << 14;
    let parts: Vec<Vec<[u32; 3]>> = cx
        .dt
        .tets
        .par_chunks(CHUNK)
        .zip(cx.dt.neighbors.par_chunks(CHUNK))
        .zip(labels.par_chunks(CHUNK))
        .map(|((tets, neighbors), own)| {
            let mut faces = Vec::new();
            for ((tv, nb), &l) in tets.iter().zip(neighbors).zip(own) {
                if l == Label::Inside {
                    for (k, f) in FACES.iter().enumerate() {
                        if is_outside(labels, nb[k]) {
                            faces.push(f.map(|i| tv[i]));
                        }
                    }
                }
            }
            faces
        })
        .collect();
    parts.concat()
}

/// Boundary of the union of the inside tets, oriented outward, vertices re-indexed to the
/// used ones. Also returns, for each output vertex, its Delaunay vertex index.
pub fn extract_boundary(cx: &TetComplex, labels: &[Label]) -> (TriMesh, Vec<u32>) {
    extract_faces(cx, boundary_faces(cx, labels))
}

/// [`extract_boundary`] of boundary faces already computed ([`boundary_faces`]).
pub fn extract_faces(cx: &TetComplex, faces: Vec<[u32; 3]>) -> (TriMesh, Vec<u32>) {
    TriMesh::of_used_vertices(&cx.dt.vertices, faces)
}
