//! The `[-1,1]` convention: bounding-box centre at the origin, bounding-box diagonal 2.

use ponq_mesh::TriMesh;

use crate::error::{DataError, Result};

/// The similarity `x -> (x - centre) * scale` that puts a mesh in the `[-1,1]` convention;
/// [`Normalization::invert`] maps results back to the input's coordinates.
///
/// Invariant: `scale` is positive and finite.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Normalization {
    /// Bounding-box centre of the input.
    pub centre: [f64; 3],
    /// `2 / diagonal` of the input's bounding box.
    pub scale: f64,
}

impl Normalization {
    /// The normalisation of `mesh`.
    ///
    /// # Errors
    /// A mesh without vertices, with a zero-size box or non-finite coordinates.
    pub fn of(mesh: &TriMesh) -> Result<Self> {
        let (lo, hi) = mesh
            .bounding_box()
            .ok_or_else(|| DataError::Invalid("the mesh has no vertex".into()))?;
        let d =
            ((hi[0] - lo[0]).powi(2) + (hi[1] - lo[1]).powi(2) + (hi[2] - lo[2]).powi(2)).sqrt();
        if !(d > 0.0 && d.is_finite()) {
            return Err(DataError::Invalid(format!(
                "the mesh's bounding box {lo:?}..{hi:?} has no extent or is not finite"
            )));
        }
        Ok(Self {
            centre: std::array::from_fn(|k| 0.5 * (lo[k] + hi[k])),
            scale: 2.0 / d,
        })
    }

    /// Applies the normalisation to a point.
    pub fn apply(&self, p: [f64; 3]) -> [f64; 3] {
        std::array::from_fn(|k| (p[k] - self.centre[k]) * self.scale)
    }

    /// Maps a point of the `[-1,1]` frame back to the input's coordinates.
    pub fn invert(&self, p: [f64; 3]) -> [f64; 3] {
        std::array::from_fn(|k| p[k] / self.scale + self.centre[k])
    }

    /// The mesh in the `[-1,1]` frame.
    pub fn apply_mesh(&self, m: &TriMesh) -> TriMesh {
        TriMesh {
            vertices: m.vertices.iter().map(|&p| self.apply(p)).collect(),
            faces: m.faces.clone(),
        }
    }

    /// The mesh mapped back to the input's coordinates.
    pub fn invert_mesh(&self, m: &TriMesh) -> TriMesh {
        TriMesh {
            vertices: m.vertices.iter().map(|&p| self.invert(p)).collect(),
            faces: m.faces.clone(),
        }
    }
}
