//! Step 4 of the mesher: the triangles between inside and outside tets, oriented outward.

use crate::complex::{FACES, Label, TetComplex, is_outside};
use crate::trimesh::TriMesh;

/// The triangles between inside tets and outside tets (or the hull), oriented outward, as
/// Delaunay vertex indices, in tet order.
pub fn boundary_faces(cx: &TetComplex, labels: &[Label]) -> Vec<[u32; 3]> {
    use rayon::prelude::*;
    cx.dt
        .tets
        .par_iter()
        .enumerate()
        .filter(|(t, _)| labels[*t] == Label::Inside)
        .flat_map_iter(|(t, tv)| {
            FACES
                .iter()
                .enumerate()
                .filter(move |(k, _)| is_outside(labels, cx.neighbor(t as u32, *k)))
                .map(move |(_, f)| f.map(|i| tv[i]))
        })
        .collect()
}

/// Boundary of the union of the inside tets, oriented outward, vertices re-indexed to the
/// used ones. Also returns, for each output vertex, its Delaunay vertex index.
pub fn extract_boundary(cx: &TetComplex, labels: &[Label]) -> (TriMesh, Vec<u32>) {
    let mut mesh = TriMesh {
        vertices: cx.dt.vertices.clone(),
        faces: boundary_faces(cx, labels),
    };
    let back = mesh.remove_unreferenced_vertices();
    (mesh, back)
}
