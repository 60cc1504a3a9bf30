//! Open surfaces: after meshing, drop the triangles that close the holes (SPEC section 6).
//!
//! Boundary samples with rotated normals make the quadrics of boundary points elongated
//! ("cigars", anisotropy `lambda2/lambda1` close to 1), while points on the surface are flat
//! ("pancakes", close to 0). A triangle is kept only if one of its vertices has anisotropy
//! at most the threshold.

use crate::trimesh::TriMesh;

/// Default anisotropy threshold.
pub const DEFAULT_OPEN_THRESHOLD: f64 = 0.35;

/// Culls in place the triangles whose three vertices all have `anisotropy > threshold`,
/// removes unused vertices, and returns for each remaining vertex its index before culling.
pub fn cull_open(mesh: &mut TriMesh, anisotropy: &[f64], threshold: f64) -> Vec<u32> {
    mesh.faces
        .retain(|f| f.iter().any(|&v| anisotropy[v as usize] <= threshold));
    mesh.remove_unreferenced_vertices()
}
