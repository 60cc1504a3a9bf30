//! Step 4 of the mesher: the triangles between inside and outside tets, oriented outward.

use crate::complex::{FACES, Label, TetComplex, is_outside};
use crate::trimesh::TriMesh;

/// Boundary of the union of the inside tets, oriented outward, vertices re-indexed to the
/// used ones. Also returns, for each output vertex, its Delaunay vertex index.
pub fn extract_boundary(cx: &TetComplex, labels: &[Label]) -> (TriMesh, Vec<u32>) {
    let mut faces = Vec::new();
    for (t, tv) in cx.dt.tets.iter().enumerate() {
        if labels[t] != Label::Inside {
            continue;
        }
        for (k, f) in FACES.iter().enumerate() {
            if is_outside(labels, cx.neighbor(t as u32, k)) {
                faces.push(f.map(|i| tv[i]));
            }
        }
    }
    let mut mesh = TriMesh {
        vertices: cx.dt.vertices.clone(),
        faces,
    };
    let back = mesh.remove_unreferenced_vertices();
    (mesh, back)
}
