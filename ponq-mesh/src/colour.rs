//! Colours on a triangle mesh, as files carry them: one colour per vertex (PLY `red green blue`,
//! OBJ `v x y z r g b`), one per face (PLY face `red green blue`, OBJ materials' `Kd`), or a
//! texture (OBJ `vt` coordinates per face corner and an image per material, `map_Kd` in its
//! MTL). [`Colours::at`] gives the colour at a point of a face; colours are the file's RGB
//! values (sRGB bytes / 255, interpolated as they are, as viewers do) in `[0, 1]`, `f32`.
//!
//! ```
//! use ponq_mesh::colour::Colours;
//! // Per-vertex colours, interpolated barycentrically.
//! let c = Colours::Vertex(vec![[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]]);
//! let faces = [[0u32, 1, 2]];
//! assert_eq!(c.at(&faces, 0, [0.5, 0.5, 0.0]), [0.5, 0.5, 0.0]);
//! ```

/// A colour: red, green, blue in `[0, 1]`.
pub type Rgb = [f32; 3];

/// An RGB image, row 0 at the top.
///
/// Invariant: `pixels.len() == width * height`, both at least 1.
#[derive(Debug, Clone, PartialEq)]
pub struct Image {
    width: usize,
    height: usize,
    pixels: Vec<Rgb>,
}

impl Image {
    /// An image of `width x height` pixels, rows top to bottom; `None` when the sizes do not
    /// match or one is 0.
    pub fn new(width: usize, height: usize, pixels: Vec<Rgb>) -> Option<Self> {
        (width > 0 && height > 0 && pixels.len() == width * height).then_some(Self {
            width,
            height,
            pixels,
        })
    }

    /// Width and height in pixels.
    pub fn size(&self) -> (usize, usize) {
        (self.width, self.height)
    }

    /// The colour at texture coordinates `(u, v)` (OBJ's: `v = 0` at the bottom row, the
    /// image repeated outside `[0, 1]`), bilinear between the pixels' centres.
    pub fn sample(&self, u: f64, v: f64) -> Rgb {
        let (w, h) = (self.width as f64, self.height as f64);
        let x = u.rem_euclid(1.0) * w - 0.5;
        let y = (1.0 - v.rem_euclid(1.0)) * h - 0.5;
        let (x0, y0) = (x.floor(), y.floor());
        let (fx, fy) = ((x - x0) as f32, (y - y0) as f32);
        let wrap = |i: f64, n: usize| (i as i64).rem_euclid(n as i64) as usize;
        let px = |ix: f64, iy: f64| {
            self.pixels[wrap(iy, self.height) * self.width + wrap(ix, self.width)]
        };
        let (a, b, c, d) = (
            px(x0, y0),
            px(x0 + 1.0, y0),
            px(x0, y0 + 1.0),
            px(x0 + 1.0, y0 + 1.0),
        );
        std::array::from_fn(|k| {
            (a[k] * (1.0 - fx) + b[k] * fx) * (1.0 - fy) + (c[k] * (1.0 - fx) + d[k] * fx) * fy
        })
    }
}

/// A material of a textured mesh: its diffuse colour, and its diffuse texture when it has one
/// (the texture's colour is used as it is where there is one).
#[derive(Debug, Clone, PartialEq)]
pub struct Material {
    /// `Kd`.
    pub diffuse: Rgb,
    /// `map_Kd`, read (shared by the materials that name one file).
    pub texture: Option<std::sync::Arc<Image>>,
}

/// A textured mesh's colours: per face, its material and its corners' texture coordinates.
///
/// Invariants: `uv.len() == material.len()` (the faces), every material index below
/// `materials.len()`.
#[derive(Debug, Clone, PartialEq)]
pub struct Textured {
    /// Texture coordinates of each face's three corners (`NaN` where a corner has none).
    pub uv: Vec<[[f32; 2]; 3]>,
    /// Material of each face.
    pub material: Vec<u32>,
    /// The materials.
    pub materials: Vec<Material>,
}

/// The colours of a mesh.
#[derive(Debug, Clone, PartialEq)]
pub enum Colours {
    /// One colour per vertex.
    Vertex(Vec<Rgb>),
    /// One colour per face.
    Face(Vec<Rgb>),
    /// Materials and textures.
    Texture(Textured),
}

impl Colours {
    /// Whether they fit a mesh of `vertices` vertices and `faces` faces.
    pub fn fits(&self, vertices: usize, faces: usize) -> bool {
        match self {
            Self::Vertex(c) => c.len() == vertices,
            Self::Face(c) => c.len() == faces,
            Self::Texture(t) => {
                t.uv.len() == faces
                    && t.material.len() == faces
                    && t.material.iter().all(|&m| (m as usize) < t.materials.len())
            }
        }
    }

    /// The colour at barycentric coordinates `bary` of face `face` (`faces` the mesh's
    /// faces, for per-vertex colours). Callers keep [`Colours::fits`].
    pub fn at(&self, faces: &[[u32; 3]], face: usize, bary: [f64; 3]) -> Rgb {
        match self {
            Self::Vertex(c) => {
                let f = faces[face];
                std::array::from_fn(|k| {
                    (0..3)
                        .map(|i| bary[i] as f32 * c[f[i] as usize][k])
                        .sum::<f32>()
                        .clamp(0.0, 1.0)
                })
            }
            Self::Face(c) => c[face],
            Self::Texture(t) => {
                let m = &t.materials[t.material[face] as usize];
                let uv = t.uv[face];
                match &m.texture {
                    Some(img) if uv.iter().all(|c| c[0].is_finite() && c[1].is_finite()) => {
                        let u = (0..3).map(|i| bary[i] * f64::from(uv[i][0])).sum::<f64>();
                        let v = (0..3).map(|i| bary[i] * f64::from(uv[i][1])).sum::<f64>();
                        img.sample(u, v)
                    }
                    _ => m.diffuse,
                }
            }
        }
    }
}

/// A colour in `[0, 1]` as three bytes (rounded).
pub fn to_bytes(c: Rgb) -> [u8; 3] {
    c.map(|x| (x.clamp(0.0, 1.0) * 255.0).round() as u8)
}

/// Three bytes as a colour.
pub fn from_bytes(c: [u8; 3]) -> Rgb {
    c.map(|x| f32::from(x) / 255.0)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn images_sample_bilinearly_with_obj_orientation() {
        // 2 x 2: top row red, green; bottom row blue, white.
        let img = Image::new(
            2,
            2,
            vec![
                [1.0, 0.0, 0.0],
                [0.0, 1.0, 0.0],
                [0.0, 0.0, 1.0],
                [1.0, 1.0, 1.0],
            ],
        )
        .unwrap();
        // v = 0 is the bottom row.
        assert_eq!(img.sample(0.25, 0.25), [0.0, 0.0, 1.0]);
        assert_eq!(img.sample(0.75, 0.75), [0.0, 1.0, 0.0]);
        // Half-way between the centres of red and green.
        assert_eq!(img.sample(0.5, 0.75), [0.5, 0.5, 0.0]);
        // Repeated outside [0, 1].
        assert_eq!(img.sample(1.25, -0.75), img.sample(0.25, 0.25));
        assert!(Image::new(2, 2, vec![[0.0; 3]; 3]).is_none());
    }

    #[test]
    fn colours_at_points_of_faces() {
        let faces = [[0, 1, 2], [0, 2, 3]];
        let f = Colours::Face(vec![[1.0, 0.0, 0.0], [0.0, 1.0, 0.0]]);
        assert!(f.fits(4, 2) && !f.fits(4, 3));
        assert_eq!(f.at(&faces, 1, [0.2, 0.3, 0.5]), [0.0, 1.0, 0.0]);
        let t = Colours::Texture(Textured {
            uv: vec![[[0.25, 0.25]; 3], [[0.0, 0.0], [1.0, 0.0], [0.0, 1.0]]],
            material: vec![0, 1],
            materials: vec![
                Material {
                    diffuse: [0.5, 0.5, 0.5],
                    texture: None,
                },
                Material {
                    diffuse: [0.0; 3],
                    texture: Image::new(1, 1, vec![[0.2, 0.4, 0.6]]).map(std::sync::Arc::new),
                },
            ],
        });
        assert!(t.fits(4, 2));
        assert_eq!(t.at(&faces, 0, [1.0, 0.0, 0.0]), [0.5, 0.5, 0.5]);
        assert_eq!(t.at(&faces, 1, [0.3, 0.3, 0.4]), [0.2, 0.4, 0.6]);
        assert_eq!(to_bytes([1.0, 0.5, -1.0]), [255, 128, 0]);
    }
}
