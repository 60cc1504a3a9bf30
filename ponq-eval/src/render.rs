//! A small software rasteriser for report images: a mesh seen from a fixed oblique viewpoint
//! (perspective-free, orthographic), z-buffered, Lambert-shaded by face normal with a
//! headlight and a key light, on a white background. Back faces are drawn darker so holes
//! and flipped faces show.

use std::path::Path;

use anyhow::{Context, Result};
use ponq_mesh::TriMesh;
use ponq_mesh::vec3::{cross, dot, sub, unit};

/// An RGB image.
#[derive(Debug, Clone)]
pub struct Image {
    /// Width in pixels.
    pub width: usize,
    /// Height in pixels.
    pub height: usize,
    /// Row-major RGB pixels.
    pub pixels: Vec<[u8; 3]>,
}

impl Image {
    /// A white image.
    pub fn new(width: usize, height: usize) -> Self {
        Self {
            width,
            height,
            pixels: vec![[255; 3]; width * height],
        }
    }

    /// Images side by side (heights must match), separated by a 4-pixel grey gap.
    pub fn hstack(images: &[Image]) -> Image {
        let h = images.iter().map(|i| i.height).max().unwrap_or(0);
        let gap = 4;
        let w =
            images.iter().map(|i| i.width).sum::<usize>() + gap * images.len().saturating_sub(1);
        let mut out = Image::new(w, h);
        out.pixels.iter_mut().for_each(|p| *p = [200; 3]);
        let mut x0 = 0;
        for im in images {
            for y in 0..im.height {
                for x in 0..im.width {
                    out.pixels[y * w + x0 + x] = im.pixels[y * im.width + x];
                }
            }
            x0 += im.width + gap;
        }
        out
    }

    /// Writes a PNG.
    pub fn save_png(&self, path: &Path) -> Result<()> {
        let f =
            std::fs::File::create(path).with_context(|| format!("creating {}", path.display()))?;
        let mut enc = png::Encoder::new(
            std::io::BufWriter::new(f),
            self.width as u32,
            self.height as u32,
        );
        enc.set_color(png::ColorType::Rgb);
        enc.set_depth(png::BitDepth::Eight);
        let mut w = enc.write_header()?;
        let data: Vec<u8> = self.pixels.iter().flatten().copied().collect();
        w.write_image_data(&data)?;
        Ok(())
    }
}

/// Renders `mesh` (its points within the box `view` = (centre, half-size)) into a
/// `size x size` image with the given base colour.
pub fn render(mesh: &TriMesh, view: ([f64; 3], f64), size: usize, colour: [f64; 3]) -> Image {
    let mut img = Image::new(size, size);
    let mut depth = vec![f64::INFINITY; size * size];
    // Camera looking from direction d (towards -d) with up roughly +z.
    let d = unit([1.0, -1.4, 0.9]);
    let right = unit(cross([0.0, 0.0, 1.0], d));
    let up = cross(d, right);
    let (c, half) = view;
    let half = if half > 0.0 { half * 1.8 } else { 1.0 };
    let project = |p: [f64; 3]| {
        let q = sub(p, c);
        let x = (dot(q, right) / half * 0.5 + 0.5) * size as f64;
        let y = (0.5 - dot(q, up) / half * 0.5) * size as f64;
        (x, y, -dot(q, d))
    };
    let key = unit([0.4, -0.3, 1.0]);
    for f in &mesh.faces {
        let v = f.map(|i| mesh.vertices[i as usize]);
        let n = unit(cross(sub(v[1], v[0]), sub(v[2], v[0])));
        let front = dot(n, d) >= 0.0;
        let ns = if front { n } else { n.map(|x| -x) };
        let shade = 0.25 + 0.45 * dot(ns, d).abs() + 0.3 * dot(ns, key).max(0.0);
        let rgb = colour.map(|k| {
            let s = if front { shade } else { 0.35 * shade };
            (255.0 * (k * s).clamp(0.0, 1.0)) as u8
        });
        let p = v.map(project);
        let (minx, maxx) = (
            p.iter().map(|q| q.0).fold(f64::MAX, f64::min),
            p.iter().map(|q| q.0).fold(f64::MIN, f64::max),
        );
        let (miny, maxy) = (
            p.iter().map(|q| q.1).fold(f64::MAX, f64::min),
            p.iter().map(|q| q.1).fold(f64::MIN, f64::max),
        );
        let area = (p[1].0 - p[0].0) * (p[2].1 - p[0].1) - (p[2].0 - p[0].0) * (p[1].1 - p[0].1);
        if area.abs() < 1e-12 {
            continue;
        }
        let x0 = minx.floor().max(0.0) as usize;
        let x1 = (maxx.ceil() as isize).min(size as isize - 1);
        let y0 = miny.floor().max(0.0) as usize;
        let y1 = (maxy.ceil() as isize).min(size as isize - 1);
        if x1 < 0 || y1 < 0 {
            continue;
        }
        for y in y0..=y1 as usize {
            for x in x0..=x1 as usize {
                let (px, py) = (x as f64 + 0.5, y as f64 + 0.5);
                let w0 = ((p[1].0 - px) * (p[2].1 - py) - (p[2].0 - px) * (p[1].1 - py)) / area;
                let w1 = ((p[2].0 - px) * (p[0].1 - py) - (p[0].0 - px) * (p[2].1 - py)) / area;
                let w2 = 1.0 - w0 - w1;
                if w0 < -1e-9 || w1 < -1e-9 || w2 < -1e-9 {
                    continue;
                }
                let z = w0 * p[0].2 + w1 * p[1].2 + w2 * p[2].2;
                let k = y * size + x;
                if z < depth[k] {
                    depth[k] = z;
                    img.pixels[k] = rgb;
                }
            }
        }
    }
    img
}
