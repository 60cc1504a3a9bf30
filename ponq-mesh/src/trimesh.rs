//! Indexed triangle meshes.

/// An indexed triangle mesh.
///
/// Invariants kept by every constructor of the crate: every index in `faces` is
/// `< vertices.len()`. Faces are counter-clockwise seen from outside (outward normals by the
/// right-hand rule) for meshes produced by the mesher.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct TriMesh {
    /// Vertex positions.
    pub vertices: Vec<[f64; 3]>,
    /// Triangles as indices into `vertices`.
    pub faces: Vec<[u32; 3]>,
}

/// Renumbers the vertices of `faces` (indices below `n`) in order of first use; returns, for
/// each new number, the old index. (Tried: two passes, the first corners found by stores
/// alone and then counted, as `delaunay::Worker::link_small` does; its two extra arrays made
/// it slower here.)
///
/// # Panics
/// If an index is `>= n`.
fn number_by_first_use(faces: &mut [[u32; 3]], n: usize) -> Vec<u32> {
    let mut map = vec![u32::MAX; n];
    let mut old = Vec::new();
    for f in faces {
        for v in f.iter_mut() {
            let m = &mut map[*v as usize];
            if *m == u32::MAX {
                *m = old.len() as u32;
                old.push(*v);
            }
            *v = *m;
        }
    }
    old
}

impl TriMesh {
    /// Creates a mesh; returns an error message if a face index is out of range.
    pub fn new(vertices: Vec<[f64; 3]>, faces: Vec<[u32; 3]>) -> Result<Self, String> {
        let n = vertices.len();
        if let Some((i, f)) = faces
            .iter()
            .enumerate()
            .find(|(_, f)| f.iter().any(|&v| v as usize >= n))
        {
            return Err(format!(
                "face {i} = {f:?} refers to a vertex >= the vertex count {n}"
            ));
        }
        Ok(Self { vertices, faces })
    }

    /// True when the mesh has no face.
    pub fn is_empty(&self) -> bool {
        self.faces.is_empty()
    }

    /// Positions of the three corners of face `f`.
    pub fn triangle(&self, f: usize) -> [[f64; 3]; 3] {
        let [a, b, c] = self.faces[f];
        [
            self.vertices[a as usize],
            self.vertices[b as usize],
            self.vertices[c as usize],
        ]
    }

    /// Axis-aligned bounding box `(min, max)`; `None` for a mesh without vertices.
    pub fn bounding_box(&self) -> Option<([f64; 3], [f64; 3])> {
        let first = *self.vertices.first()?;
        let mut lo = first;
        let mut hi = first;
        for v in &self.vertices {
            for k in 0..3 {
                lo[k] = lo[k].min(v[k]);
                hi[k] = hi[k].max(v[k]);
            }
        }
        Some((lo, hi))
    }

    /// Signed volume enclosed by the faces (positive for a closed, outward-oriented mesh).
    pub fn signed_volume(&self) -> f64 {
        self.faces
            .iter()
            .map(|f| {
                let [a, b, c] = f.map(|v| self.vertices[v as usize]);
                (a[0] * (b[1] * c[2] - b[2] * c[1]) - a[1] * (b[0] * c[2] - b[2] * c[0])
                    + a[2] * (b[0] * c[1] - b[1] * c[0]))
                    / 6.0
            })
            .sum()
    }

    /// Removes vertices no face refers to; the kept vertices are renumbered in order of first
    /// use by the faces. Returns, for each kept vertex, its index before the call.
    pub fn remove_unreferenced_vertices(&mut self) -> Vec<u32> {
        let old = number_by_first_use(&mut self.faces, self.vertices.len());
        self.vertices = old.iter().map(|&v| self.vertices[v as usize]).collect();
        old
    }

    /// The mesh of `faces` over the vertices of `vertices` they use, renumbered in order of
    /// first use (what [`TriMesh::remove_unreferenced_vertices`] makes of a mesh of all of
    /// `vertices`, without copying the unused ones first). Also returns, for each vertex, its
    /// index in `vertices`.
    ///
    /// # Panics
    /// If a face index is out of range of `vertices`.
    pub(crate) fn of_used_vertices(
        vertices: &[[f64; 3]],
        mut faces: Vec<[u32; 3]>,
    ) -> (Self, Vec<u32>) {
        let old = number_by_first_use(&mut faces, vertices.len());
        let vertices = old.iter().map(|&v| vertices[v as usize]).collect();
        (Self { vertices, faces }, old)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The mesh of the used vertices is what removing the unused ones from the mesh of all
    /// vertices gives (faces renumbered in order of first use, the same map back), on faces
    /// over a few of many vertices, with repeats.
    #[test]
    fn of_used_vertices_is_the_mesh_without_its_unused_vertices() {
        use rand::{Rng, SeedableRng};
        let mut rng = rand::rngs::StdRng::seed_from_u64(29);
        for (nv, nf) in [(1usize, 0usize), (5, 3), (100, 40), (2000, 1500)] {
            let vertices: Vec<[f64; 3]> = (0..nv).map(|i| [i as f64, -(i as f64), 0.5]).collect();
            let used = (nv as u64 / 3).max(1);
            let faces: Vec<[u32; 3]> = (0..nf)
                .map(|_| [0; 3].map(|_| (rng.random_range(0..used) * 3 % nv as u64) as u32))
                .collect();
            let mut all = TriMesh {
                vertices: vertices.clone(),
                faces: faces.clone(),
            };
            let back = all.remove_unreferenced_vertices();
            let (mesh, back_used) = TriMesh::of_used_vertices(&vertices, faces.clone());
            assert_eq!(mesh, all);
            assert_eq!(back_used, back);
            // Each face still names the same positions.
            for (f, g) in faces.iter().zip(&mesh.faces) {
                for k in 0..3 {
                    assert_eq!(vertices[f[k] as usize], mesh.vertices[g[k] as usize]);
                }
            }
            assert!(mesh.vertices.len() <= used as usize);
        }
    }
}
