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
        let mut map = vec![u32::MAX; self.vertices.len()];
        let mut old = Vec::new();
        for f in &mut self.faces {
            for v in f.iter_mut() {
                let m = &mut map[*v as usize];
                if *m == u32::MAX {
                    *m = old.len() as u32;
                    old.push(*v);
                }
                *v = *m;
            }
        }
        self.vertices = old.iter().map(|&v| self.vertices[v as usize]).collect();
        old
    }
}
