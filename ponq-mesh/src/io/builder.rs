//! Building a mesh from parsed content, as every reader does: vertices and polygons
//! collected with their coordinates and indices checked, polygons fan-triangulated, and
//! capacities from header counts capped.

use crate::trimesh::TriMesh;

/// Never reserve more than this many elements from a count read in a header; vectors grow
/// as the data is actually read.
pub(crate) const MAX_PREALLOC: usize = 1 << 20;

/// A capacity for `count` announced elements of at least `min_bytes` bytes each when only
/// `available` bytes are left.
pub(crate) fn capped_capacity(count: u64, min_bytes: usize, available: usize) -> usize {
    let by_size = available / min_bytes.max(1);
    (count.min(by_size as u64) as usize).min(MAX_PREALLOC)
}

/// Collects vertices and polygons of a mesh being read, fan-triangulating polygons and
/// checking coordinates and indices.
#[derive(Debug, Default)]
pub(crate) struct MeshBuilder {
    vertices: Vec<[f64; 3]>,
    faces: Vec<[u32; 3]>,
    polygons: usize,
}

impl MeshBuilder {
    pub(crate) fn with_capacity(vertices: usize, faces: usize) -> Self {
        Self {
            vertices: Vec::with_capacity(vertices),
            faces: Vec::with_capacity(faces),
            polygons: 0,
        }
    }

    /// Number of vertices so far.
    pub(crate) fn vertex_count(&self) -> usize {
        self.vertices.len()
    }

    /// Adds a vertex; an error if a coordinate is not finite or there are too many vertices.
    pub(crate) fn push_vertex(&mut self, v: [f64; 3]) -> std::result::Result<(), String> {
        if v.iter().any(|c| !c.is_finite()) {
            return Err(format!(
                "vertex {} = {v:?} has a non-finite coordinate",
                self.vertices.len()
            ));
        }
        if self.vertices.len() > u32::MAX as usize {
            return Err("more vertices than 32-bit indices can address".to_string());
        }
        self.vertices.push(v);
        Ok(())
    }

    /// Adds a polygon (0-based vertex indices), fan-triangulated. `limit` is the vertex count
    /// when already known; indices are always checked again by [`MeshBuilder::finish`].
    pub(crate) fn push_polygon(
        &mut self,
        poly: &[u64],
        limit: Option<usize>,
    ) -> std::result::Result<(), String> {
        let id = self.polygons;
        self.polygons += 1;
        if poly.len() < 3 {
            return Err(format!(
                "face {id} has {} corner(s); a face needs at least 3",
                poly.len()
            ));
        }
        let bound = limit.map_or(u32::MAX as u64 + 1, |l| l as u64);
        if let Some(&bad) = poly.iter().find(|&&i| i >= bound) {
            return Err(match limit {
                Some(l) => format!(
                    "face {id} refers to vertex {bad} but there are only {l} vertices (indices are 0-based here)"
                ),
                None => format!("face {id} refers to vertex {bad}, beyond 32-bit indices"),
            });
        }
        let a = poly[0] as u32;
        for w in poly[1..].windows(2) {
            self.faces.push([a, w[0] as u32, w[1] as u32]);
        }
        Ok(())
    }

    /// The mesh, checking every index against the final vertex count.
    pub(crate) fn finish(self) -> std::result::Result<TriMesh, String> {
        TriMesh::new(self.vertices, self.faces)
    }
}

/// Parses a decimal number token as `f64` (Rust syntax, which also accepts `inf` and `nan`;
/// those are rejected later by the finiteness checks).
pub(crate) fn parse_f64(tok: &str) -> Option<f64> {
    tok.parse::<f64>().ok()
}

#[cfg(test)]
mod tests {
    use super::*;
    #[test]
    fn builder_fans_and_checks() {
        let mut b = MeshBuilder::default();
        for i in 0..5 {
            b.push_vertex([i as f64, 0.0, 0.0]).unwrap();
        }
        b.push_polygon(&[0, 1, 2, 3, 4], Some(5)).unwrap();
        assert!(b.push_polygon(&[0, 1], Some(5)).is_err());
        assert!(b.push_polygon(&[0, 1, 5], Some(5)).is_err());
        assert!(b.push_vertex([f64::NAN, 0.0, 0.0]).is_err());
        let m = b.finish().unwrap();
        assert_eq!(m.faces, vec![[0, 1, 2], [0, 2, 3], [0, 3, 4]]);
        let mut b = MeshBuilder::default();
        b.push_polygon(&[0, 1, 2], None).unwrap();
        assert!(b.finish().is_err());
    }

    #[test]
    fn capacity_is_capped() {
        assert_eq!(capped_capacity(u64::MAX, 12, 120), 10);
        assert_eq!(capped_capacity(5, 12, 1200), 5);
        assert_eq!(capped_capacity(u64::MAX, 1, usize::MAX), MAX_PREALLOC);
    }
}
