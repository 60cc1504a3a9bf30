//! A PNG plot of the loss curves of a `metrics.csv` (log-scale y), drawn by hand: a raster,
//! Bresenham lines and the `png` encoder, so no font or system library is needed.
//!
//! Colours: training total loss blue, validation total loss orange; the six training terms
//! (cd, normals, a, vstar, reg, occ) as thin grey-tinted lines. Horizontal grid lines mark
//! the powers of ten; the legend is in the README and in the `.txt` file written beside.

use std::path::Path;

use anyhow::{Context, Result, bail};

const W: usize = 800;
const H: usize = 500;
const MARGIN: usize = 40;

struct Canvas {
    px: Vec<[u8; 3]>,
}

impl Canvas {
    fn new() -> Self {
        Self {
            px: vec![[255; 3]; W * H],
        }
    }
    fn set(&mut self, x: i64, y: i64, c: [u8; 3]) {
        if x >= 0 && y >= 0 && (x as usize) < W && (y as usize) < H {
            self.px[y as usize * W + x as usize] = c;
        }
    }
    fn line(&mut self, (x0, y0): (i64, i64), (x1, y1): (i64, i64), c: [u8; 3], thick: bool) {
        let (dx, dy) = ((x1 - x0).abs(), -(y1 - y0).abs());
        let (sx, sy) = (if x0 < x1 { 1 } else { -1 }, if y0 < y1 { 1 } else { -1 });
        let (mut x, mut y, mut err) = (x0, y0, dx + dy);
        loop {
            self.set(x, y, c);
            if thick {
                self.set(x, y + 1, c);
                self.set(x + 1, y, c);
            }
            if x == x1 && y == y1 {
                break;
            }
            let e2 = 2 * err;
            if e2 >= dy {
                err += dy;
                x += sx;
            }
            if e2 <= dx {
                err += dx;
                y += sy;
            }
        }
    }
}

/// Reads `metrics.csv` and writes the plot to `png` (plus `png` with `.txt`: the legend).
pub fn plot_losses(csv: &Path, png: &Path) -> Result<()> {
    let text =
        std::fs::read_to_string(csv).with_context(|| format!("reading {}", csv.display()))?;
    let mut lines = text.lines();
    let header: Vec<&str> = lines
        .next()
        .context("empty metrics.csv")?
        .split(',')
        .collect();
    let rows: Vec<Vec<&str>> = lines.map(|l| l.split(',').collect()).collect();
    if rows.is_empty() {
        bail!("no epochs yet");
    }
    let col = |name: &str| header.iter().position(|h| *h == name);
    let series_names = [
        ("train_total", [31u8, 119, 180], true),
        ("val_total", [255, 127, 14], true),
        ("train_cd", [150, 150, 200], false),
        ("train_normals", [150, 200, 150], false),
        ("train_a", [200, 150, 150], false),
        ("train_vstar", [200, 200, 120], false),
        ("train_reg", [180, 140, 200], false),
        ("train_occ", [120, 200, 200], false),
    ];
    let mut series = Vec::new();
    for (name, colour, thick) in series_names {
        let Some(c) = col(name) else { continue };
        let pts: Vec<(f64, f64)> = rows
            .iter()
            .filter_map(|r| {
                let e: f64 = r.first()?.parse().ok()?;
                let v: f64 = r.get(c)?.parse().ok()?;
                (v > 0.0 && v.is_finite()).then_some((e, v.log10()))
            })
            .collect();
        if !pts.is_empty() {
            series.push((pts, colour, thick));
        }
    }
    let all = series.iter().flat_map(|s| s.0.iter());
    let (mut x0, mut x1, mut y0, mut y1) = (f64::MAX, f64::MIN, f64::MAX, f64::MIN);
    for &(x, y) in all {
        x0 = x0.min(x);
        x1 = x1.max(x);
        y0 = y0.min(y);
        y1 = y1.max(y);
    }
    if x0 > x1 {
        bail!("nothing to plot");
    }
    if x1 - x0 < 1.0 {
        x1 = x0 + 1.0;
    }
    y0 = y0.floor();
    y1 = y1.ceil().max(y0 + 1.0);
    let mut cv = Canvas::new();
    let px = |x: f64| MARGIN as i64 + ((x - x0) / (x1 - x0) * (W - 2 * MARGIN) as f64) as i64;
    let py = |y: f64| (H - MARGIN) as i64 - ((y - y0) / (y1 - y0) * (H - 2 * MARGIN) as f64) as i64;
    let grey = [220, 220, 220];
    let mut d = y0;
    while d <= y1 + 1e-9 {
        cv.line((px(x0), py(d)), (px(x1), py(d)), grey, false);
        d += 1.0;
    }
    let axis = [0, 0, 0];
    cv.line((px(x0), py(y0)), (px(x1), py(y0)), axis, false);
    cv.line((px(x0), py(y0)), (px(x0), py(y1)), axis, false);
    for (pts, colour, thick) in series.iter().rev() {
        for w in pts.windows(2) {
            cv.line(
                (px(w[0].0), py(w[0].1)),
                (px(w[1].0), py(w[1].1)),
                *colour,
                *thick,
            );
        }
        if pts.len() == 1 {
            cv.line(
                (px(pts[0].0), py(pts[0].1)),
                (px(pts[0].0) + 2, py(pts[0].1)),
                *colour,
                true,
            );
        }
    }
    let file = std::fs::File::create(png).with_context(|| format!("creating {}", png.display()))?;
    let mut enc = png::Encoder::new(std::io::BufWriter::new(file), W as u32, H as u32);
    enc.set_color(png::ColorType::Rgb);
    enc.set_depth(png::BitDepth::Eight);
    let mut w = enc.write_header()?;
    let data: Vec<u8> = cv.px.iter().flatten().copied().collect();
    w.write_image_data(&data)?;
    let legend = format!(
        "{}: x = epoch {x0}..{x1}, y = log10(loss) {y0}..{y1} (grid lines at powers of ten)\n\
         blue: train_total (thick), orange: val_total (thick), thin: train_cd (blue-grey), \
         train_normals (green), train_a (red), train_vstar (yellow), train_reg (purple), train_occ (cyan)\n",
        png.display()
    );
    std::fs::write(png.with_extension("txt"), legend)?;
    Ok(())
}
