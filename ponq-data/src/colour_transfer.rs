//! Colours carried from what a mesh came from to its vertices: from an input mesh at each
//! vertex's closest point on it ([`ColourSource`]: per-vertex colours interpolated
//! barycentrically, per-face colours as they are, textures sampled at the interpolated texture
//! coordinates), or from a grid of colours, trilinearly ([`grid_colours`]).
//!
//! The output of a remeshing lies on the input's surface, with sharp edges where the input
//! had them, so the closest point is where the colour belongs; where the output bridges a hole
//! the input had, the closest point is on the hole's rim, so patches take their neighbours'
//! colours.
//!
//! ```
//! use ponq_data::colour_transfer::ColourSource;
//! use ponq_mesh::TriMesh;
//! use ponq_mesh::colour::Colours;
//! let tri = TriMesh::new(vec![[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]], vec![[0, 1, 2]])
//!     .unwrap();
//! let colours = Colours::Vertex(vec![[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]]);
//! let src = ColourSource::new(&tri, &colours).unwrap();
//! // Above the middle of the edge from red to green.
//! assert_eq!(src.colours(&[[0.5, 0.0, 0.3]]), vec![[0.5, 0.5, 0.0]]);
//! ```

use ponq_mesh::TriMesh;
use ponq_mesh::bvh::{Aabb, Bvh};
use ponq_mesh::colour::{Colours, Rgb};
use rayon::prelude::*;

use crate::error::{DataError, Result};
use crate::sdf::closest_point_on_triangle;

/// A coloured mesh ready for closest-point colour queries.
pub struct ColourSource<'a> {
    mesh: &'a TriMesh,
    colours: &'a Colours,
    bvh: Bvh,
}

impl<'a> ColourSource<'a> {
    /// The source; an error when the colours do not fit the mesh or it has no face.
    pub fn new(mesh: &'a TriMesh, colours: &'a Colours) -> Result<Self> {
        if mesh.faces.is_empty() {
            return Err(DataError::Invalid("a coloured mesh without faces".into()));
        }
        if !colours.fits(mesh.vertices.len(), mesh.faces.len()) {
            return Err(DataError::Invalid(format!(
                "the colours do not fit the mesh of {} vertices and {} faces",
                mesh.vertices.len(),
                mesh.faces.len()
            )));
        }
        let boxes: Vec<Aabb> = (0..mesh.faces.len())
            .map(|f| Aabb::from_points(&mesh.triangle(f)))
            .collect();
        Ok(Self {
            mesh,
            colours,
            bvh: Bvh::build(&boxes),
        })
    }

    /// The colour at each point's closest point on the mesh (in parallel).
    pub fn colours(&self, points: &[[f64; 3]]) -> Vec<Rgb> {
        points.par_iter().map(|&p| self.colour(p)).collect()
    }

    fn colour(&self, p: [f64; 3]) -> Rgb {
        let closest = |f: usize| {
            let t = self.mesh.triangle(f);
            closest_point_on_triangle(p, t[0], t[1], t[2])
        };
        let d2 = |q: [f64; 3]| (0..3).map(|k| (q[k] - p[k]).powi(2)).sum::<f64>();
        let Some((f, _)) = self.bvh.nearest(p, |f| d2(closest(f))) else {
            return [0.0; 3];
        };
        let q = closest(f);
        self.colours
            .at(&self.mesh.faces, f, barycentric(&self.mesh.triangle(f), q))
    }
}

/// Barycentric coordinates of `q` (a point of the triangle) in `t`; a degenerate triangle
/// gives its nearest vertex.
fn barycentric(t: &[[f64; 3]; 3], q: [f64; 3]) -> [f64; 3] {
    let sub = |a: [f64; 3], b: [f64; 3]| [a[0] - b[0], a[1] - b[1], a[2] - b[2]];
    let dot = |a: [f64; 3], b: [f64; 3]| a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
    let (v0, v1, v2) = (sub(t[1], t[0]), sub(t[2], t[0]), sub(q, t[0]));
    let (d00, d01, d11, d20, d21) = (
        dot(v0, v0),
        dot(v0, v1),
        dot(v1, v1),
        dot(v2, v0),
        dot(v2, v1),
    );
    let den = d00 * d11 - d01 * d01;
    if !(den.abs() > 1e-300) {
        let i = (0..3)
            .min_by(|&a, &b| {
                dot(sub(q, t[a]), sub(q, t[a])).total_cmp(&dot(sub(q, t[b]), sub(q, t[b])))
            })
            .unwrap_or(0);
        let mut w = [0.0; 3];
        w[i] = 1.0;
        return w;
    }
    let v = ((d11 * d20 - d01 * d21) / den).clamp(0.0, 1.0);
    let w = ((d00 * d21 - d01 * d20) / den).clamp(0.0, 1.0 - v);
    [1.0 - v - w, v, w]
}

/// The colours of a grid of colours at points: `rgb` holds a colour per node of a grid of
/// `dims` nodes (C order) from `lo` with spacing `h`, interpolated trilinearly (points outside
/// take the nearest node's).
pub fn grid_colours(
    rgb: &[Rgb],
    dims: [usize; 3],
    lo: [f64; 3],
    h: f64,
    points: &[[f64; 3]],
) -> Vec<Rgb> {
    points
        .par_iter()
        .map(|p| {
            let x: [f64; 3] =
                std::array::from_fn(|a| ((p[a] - lo[a]) / h).clamp(0.0, (dims[a] - 1) as f64));
            let i: [usize; 3] =
                std::array::from_fn(|a| (x[a].floor() as usize).min(dims[a].saturating_sub(2)));
            let t: [f64; 3] = std::array::from_fn(|a| x[a] - i[a] as f64);
            let mut c = [0.0f32; 3];
            for corner in 0..8 {
                let o = [corner >> 2, (corner >> 1) & 1, corner & 1];
                let w: f64 = (0..3)
                    .map(|a| if o[a] == 1 { t[a] } else { 1.0 - t[a] })
                    .product();
                let n: [usize; 3] = std::array::from_fn(|a| (i[a] + o[a]).min(dims[a] - 1));
                let v = rgb[(n[0] * dims[1] + n[1]) * dims[2] + n[2]];
                for k in 0..3 {
                    c[k] += w as f32 * v[k];
                }
            }
            c.map(|x| x.clamp(0.0, 1.0))
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn face_colours_stay_on_their_faces() {
        // Two triangles of a square, red and blue: points above each take its colour.
        let m = TriMesh::new(
            vec![
                [0.0, 0.0, 0.0],
                [1.0, 0.0, 0.0],
                [1.0, 1.0, 0.0],
                [0.0, 1.0, 0.0],
            ],
            vec![[0, 1, 2], [0, 2, 3]],
        )
        .unwrap();
        let c = Colours::Face(vec![[1.0, 0.0, 0.0], [0.0, 0.0, 1.0]]);
        let s = ColourSource::new(&m, &c).unwrap();
        assert_eq!(
            s.colours(&[[0.8, 0.2, 0.5], [0.2, 0.8, -0.5]]),
            vec![[1.0, 0.0, 0.0], [0.0, 0.0, 1.0]]
        );
        assert!(ColourSource::new(&m, &Colours::Face(vec![[0.0; 3]])).is_err());
    }

    #[test]
    fn grids_interpolate_trilinearly() {
        // A grid whose red channel is x: linear, so trilinear interpolation is exact.
        let dims = [3, 3, 3];
        let rgb: Vec<Rgb> = (0..27).map(|i| [(i / 9) as f32 / 2.0, 0.0, 1.0]).collect();
        let got = grid_colours(
            &rgb,
            dims,
            [-1.0; 3],
            1.0,
            &[[0.5, 0.0, 0.3], [5.0, 0.0, 0.0]],
        );
        assert!((got[0][0] - 0.75).abs() < 1e-6 && got[0][2] == 1.0);
        assert_eq!(got[1][0], 1.0);
    }
}
