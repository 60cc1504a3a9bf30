//! Line charts as PNG files, drawn with `plotters` (bitmap backend): the loss curves of a
//! training run (`ponq-train`) and the metric-vs-resolution figures of an evaluation report.
//!
//! Text is drawn with a font embedded in the program (a 14 KB ASCII subset of DejaVu Sans,
//! `assets/`, licence beside it) through plotters' `ab_glyph` feature, so charts need no
//! system font library and look the same on every machine.
//!
//! ```no_run
//! use ponq_eval::chart::{Chart, Series};
//! let chart = Chart {
//!     title: "loss".into(),
//!     x_label: "epoch".into(),
//!     y_label: "loss".into(),
//!     log_y: true,
//!     x_ticks: None,
//!     series: vec![Series::new("train", [31, 119, 180], vec![(1.0, 0.5), (2.0, 0.3)])],
//! };
//! ponq_eval::chart::draw(&[chart], 1, (800, 500), "loss.png".as_ref()).unwrap();
//! ```

use std::path::Path;
use std::sync::OnceLock;

use anyhow::{Result, anyhow, bail};
use plotters::prelude::*;
use plotters::style::FontStyle;

/// The embedded font (printable ASCII, degree, squares, multiplication sign, en dash).
const FONT: &[u8] = include_bytes!("../assets/DejaVuSans-subset.ttf");
/// The family name charts ask for.
const FAMILY: &str = "sans-serif";

/// Registers the embedded font with plotters once per process.
fn register_font() -> Result<()> {
    static DONE: OnceLock<bool> = OnceLock::new();
    let ok = *DONE.get_or_init(|| {
        plotters::style::register_font(FAMILY, FontStyle::Normal, FONT).is_ok()
            && plotters::style::register_font(FAMILY, FontStyle::Bold, FONT).is_ok()
    });
    if ok {
        Ok(())
    } else {
        bail!("the embedded chart font could not be loaded")
    }
}

/// One line of a chart.
#[derive(Debug, Clone, PartialEq)]
pub struct Series {
    /// Legend text.
    pub label: String,
    /// Colour (RGB).
    pub colour: [u8; 3],
    /// Dashed instead of solid.
    pub dashed: bool,
    /// Thicker line (the series a reader looks at first).
    pub bold: bool,
    /// Points `(x, y)`; points with a non-finite coordinate (or `y <= 0` on a log axis) are
    /// skipped.
    pub points: Vec<(f64, f64)>,
}

impl Series {
    /// A solid, normal-weight series.
    pub fn new(label: impl Into<String>, colour: [u8; 3], points: Vec<(f64, f64)>) -> Self {
        Self {
            label: label.into(),
            colour,
            dashed: false,
            bold: false,
            points,
        }
    }
}

/// One panel: axes, grid, lines and their legend.
#[derive(Debug, Clone, PartialEq)]
pub struct Chart {
    /// Caption above the panel.
    pub title: String,
    /// Text under the x axis.
    pub x_label: String,
    /// Text beside the y axis.
    pub y_label: String,
    /// Logarithmic y axis.
    pub log_y: bool,
    /// Named x ticks `(x, text)` instead of numbers (e.g. grid resolutions); without them the
    /// x axis shows numbers, whole numbers only when all x values are whole (epochs).
    pub x_ticks: Option<Vec<(f64, String)>>,
    /// The lines.
    pub series: Vec<Series>,
}

impl Chart {
    /// The points of all series that can be drawn on this chart's axes.
    fn drawable(&self) -> impl Iterator<Item = (usize, (f64, f64))> + '_ {
        let log = self.log_y;
        self.series.iter().enumerate().flat_map(move |(i, s)| {
            s.points
                .iter()
                .filter(move |p| p.0.is_finite() && p.1.is_finite() && (!log || p.1 > 0.0))
                .map(move |&p| (i, p))
        })
    }

    /// Data range `(x0, x1, y0, y1)` with some room, or `None` when nothing can be drawn.
    fn range(&self) -> Option<(f64, f64, f64, f64)> {
        let (mut x0, mut x1, mut y0, mut y1) = (f64::MAX, f64::MIN, f64::MAX, f64::MIN);
        for (_, (x, y)) in self.drawable() {
            x0 = x0.min(x);
            x1 = x1.max(x);
            y0 = y0.min(y);
            y1 = y1.max(y);
        }
        if let Some(t) = &self.x_ticks {
            for (x, _) in t {
                x0 = x0.min(*x);
                x1 = x1.max(*x);
            }
        }
        if x0 > x1 {
            return None;
        }
        if x1 - x0 < 1e-12 {
            x0 -= 0.5;
            x1 += 0.5;
        } else if self.x_ticks.is_some() {
            let pad = 0.08 * (x1 - x0);
            x0 -= pad;
            x1 += pad;
        }
        if self.log_y {
            // Whole decades, at least one (plotters labels a log axis at its decades).
            y0 = 10f64.powf(y0.log10().floor());
            y1 = 10f64.powf(y1.log10().ceil());
            if y1 <= y0 {
                y1 = 10.0 * y0;
            }
        } else {
            let pad = if y1 > y0 {
                0.06 * (y1 - y0)
            } else {
                0.5 * y0.abs().max(1e-3)
            };
            y0 -= pad;
            y1 += pad;
        }
        Some((x0, x1, y0, y1))
    }
}

fn rgb(c: [u8; 3]) -> RGBColor {
    RGBColor(c[0], c[1], c[2])
}

/// Draws `charts` into one PNG of `columns` panels per row, each `panel` pixels (width,
/// height); each panel's legend sits to the right of its plot area.
///
/// Errors: no chart, a chart with nothing to draw, or the file cannot be written.
pub fn draw(charts: &[Chart], columns: usize, panel: (u32, u32), path: &Path) -> Result<()> {
    let columns = columns.clamp(1, charts.len().max(1));
    let rows: Vec<(&[Chart], u32)> = charts.chunks(columns).map(|c| (c, panel.1)).collect();
    draw_rows(&rows, panel.0 * columns as u32, path)
}

/// Draws rows of panels into one PNG `width` pixels wide: each row is its charts side by side
/// (equal widths) and its height in pixels.
///
/// Errors: no chart, a chart with nothing to draw, or the file cannot be written.
pub fn draw_rows(rows: &[(&[Chart], u32)], width: u32, path: &Path) -> Result<()> {
    if rows.iter().all(|r| r.0.is_empty()) {
        bail!("no chart to draw");
    }
    register_font()?;
    let height = rows.iter().map(|r| r.1).sum::<u32>();
    let root = BitMapBackend::new(path, (width, height)).into_drawing_area();
    root.fill(&WHITE).map_err(|e| anyhow!("{e}"))?;
    let mut rest = root;
    for (charts, h) in rows {
        let (row, below) = rest.split_vertically(*h);
        rest = below;
        if charts.is_empty() {
            continue;
        }
        for (chart, area) in charts.iter().zip(row.split_evenly((1, charts.len()))) {
            draw_panel(chart, &area).map_err(|e| anyhow!("chart {:?}: {e}", chart.title))?;
        }
    }
    rest.present()
        .map_err(|e| anyhow!("cannot write {}: {e}", path.display()))?;
    Ok(())
}

/// Tick text of a y value: plain for moderate magnitudes, `1e-5` style otherwise.
fn tick_text(v: f64) -> String {
    let a = v.abs();
    if a == 0.0 {
        "0".into()
    } else if (1e-3..1e4).contains(&a) {
        // Up to 3 significant digits, no trailing zeros.
        let digits = (2 - a.log10().floor() as i32).max(0) as usize;
        let t = format!("{v:.digits$}");
        if t.contains('.') {
            t.trim_end_matches('0').trim_end_matches('.').to_string()
        } else {
            t
        }
    } else {
        let t = format!("{v:.1e}");
        t.replace(".0e", "e")
    }
}

type Area<'a> = DrawingArea<BitMapBackend<'a>, plotters::coord::Shift>;

fn draw_panel(chart: &Chart, area: &Area<'_>) -> Result<()> {
    let (x0, x1, y0, y1) = chart
        .range()
        .ok_or_else(|| anyhow!("nothing to plot (no finite points)"))?;
    let (w, _) = area.dim_in_pixel();
    let longest = chart
        .series
        .iter()
        .map(|s| s.label.len())
        .max()
        .unwrap_or(0) as u32;
    // Legend column: sample line + text at about 7 px per character.
    let legend_w = (50 + 7 * longest).min(w / 2);
    let (plot, legend) = area.split_horizontally(w - legend_w);
    let err = |e: &dyn std::fmt::Display| anyhow!("{e}");
    let mut builder = ChartBuilder::on(&plot);
    builder
        .caption(&chart.title, (FAMILY, 18))
        .margin(8)
        .x_label_area_size(38)
        .y_label_area_size(62);
    let whole_x = chart.drawable().all(|(_, (x, _))| x.fract() == 0.0);
    let ticks = chart.x_ticks.clone();
    let x_fmt = move |x: &f64| -> String {
        if let Some(t) = &ticks {
            return t
                .iter()
                .find(|(tx, _)| (tx - x).abs() < 1e-9)
                .map(|(_, s)| s.clone())
                .unwrap_or_default();
        }
        if whole_x {
            if x.fract() == 0.0 {
                format!("{x:.0}")
            } else {
                String::new()
            }
        } else {
            format!("{x:.3}")
        }
    };
    let n_xlabels = match &chart.x_ticks {
        Some(t) => t.len().max(1),
        None if whole_x => ((x1 - x0).round() as usize + 1).clamp(2, 11),
        None => 8,
    };
    macro_rules! body {
        ($ctx:expr) => {{
            let mut ctx = $ctx;
            let mut mesh = ctx.configure_mesh();
            mesh.x_desc(chart.x_label.as_str())
                .y_desc(chart.y_label.as_str())
                .x_labels(n_xlabels)
                .x_label_formatter(&x_fmt)
                .y_label_formatter(&|y: &f64| tick_text(*y))
                .label_style((FAMILY, 13))
                .axis_desc_style((FAMILY, 14))
                .light_line_style(RGBColor(235, 235, 235))
                .bold_line_style(RGBColor(200, 200, 200));
            if let Some(t) = &chart.x_ticks {
                // Only the named ticks: one grid line per tick.
                mesh.x_labels(t.len().max(1));
            }
            mesh.draw().map_err(|e| err(&e))?;
            for s in &chart.series {
                let pts: Vec<(f64, f64)> = s
                    .points
                    .iter()
                    .copied()
                    .filter(|p| p.0.is_finite() && p.1.is_finite() && (!chart.log_y || p.1 > 0.0))
                    .collect();
                let style = rgb(s.colour).stroke_width(if s.bold { 3 } else { 1 });
                if s.dashed {
                    ctx.draw_series(DashedLineSeries::new(pts.clone(), 6, 4, style))
                        .map_err(|e| err(&e))?;
                } else {
                    ctx.draw_series(LineSeries::new(pts.clone(), style))
                        .map_err(|e| err(&e))?;
                }
                if pts.len() <= 12 {
                    ctx.draw_series(
                        pts.iter()
                            .map(|&p| Circle::new(p, 3, rgb(s.colour).filled())),
                    )
                    .map_err(|e| err(&e))?;
                }
            }
        }};
    }
    if chart.log_y {
        body!(
            builder
                .build_cartesian_2d(x0..x1, (y0..y1).log_scale())
                .map_err(|e| err(&e))?
        );
    } else {
        body!(
            builder
                .build_cartesian_2d(x0..x1, y0..y1)
                .map_err(|e| err(&e))?
        );
    }
    // The legend: one line per series, sample stroke then label.
    let top = 40;
    for (i, s) in chart.series.iter().enumerate() {
        let y = top + 20 * i as i32;
        let style = rgb(s.colour).stroke_width(if s.bold { 3 } else { 1 });
        if s.dashed {
            for k in 0..3 {
                legend
                    .draw(&PathElement::new(
                        vec![(8 + 11 * k, y), (14 + 11 * k, y)],
                        style,
                    ))
                    .map_err(|e| err(&e))?;
            }
        } else {
            legend
                .draw(&PathElement::new(vec![(8, y), (38, y)], style))
                .map_err(|e| err(&e))?;
        }
        legend
            .draw(&Text::new(
                s.label.clone(),
                (44, y - 7),
                (FAMILY, 13).into_font().color(&BLACK),
            ))
            .map_err(|e| err(&e))?;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn chart(log_y: bool, series: Vec<Series>) -> Chart {
        Chart {
            title: "t".into(),
            x_label: "x".into(),
            y_label: "y".into(),
            log_y,
            x_ticks: None,
            series,
        }
    }

    #[test]
    fn tick_texts_are_short() {
        assert_eq!(tick_text(1e-5), "1e-5");
        assert_eq!(tick_text(9.999999e-5), "1e-4");
        assert_eq!(tick_text(0.001), "0.001");
        assert_eq!(tick_text(0.25), "0.25");
        assert_eq!(tick_text(2.0), "2");
        assert_eq!(tick_text(10.0), "10");
        assert_eq!(tick_text(0.0), "0");
        assert_eq!(tick_text(25000.0), "2.5e4");
    }

    #[test]
    fn log_range_is_whole_decades_and_skips_non_positive_values() {
        let c = chart(
            true,
            vec![Series::new(
                "a",
                [0; 3],
                vec![(1.0, 0.03), (2.0, 0.0), (3.0, 2.0), (4.0, f64::NAN)],
            )],
        );
        let (x0, x1, y0, y1) = c.range().unwrap();
        assert_eq!((x0, x1), (1.0, 3.0));
        assert!(
            (y0 - 0.01).abs() < 1e-15 && (y1 - 10.0).abs() < 1e-12,
            "{y0} {y1}"
        );
    }

    #[test]
    fn nothing_to_plot_is_an_error_not_a_panic() {
        let c = chart(true, vec![Series::new("a", [0; 3], vec![(1.0, -1.0)])]);
        assert!(c.range().is_none());
        let dir = std::env::temp_dir().join(format!("ponq-chart-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let err = draw(&[c], 1, (300, 200), &dir.join("x.png")).unwrap_err();
        assert!(err.to_string().contains("nothing to plot"), "{err}");
        assert!(draw(&[], 1, (300, 200), &dir.join("y.png")).is_err());
        std::fs::remove_dir_all(&dir).ok();
    }

    fn decode(path: &Path) -> (u32, u32, Vec<u8>) {
        let dec = png::Decoder::new(std::io::BufReader::new(std::fs::File::open(path).unwrap()));
        let mut reader = dec.read_info().unwrap();
        let mut buf = vec![0; reader.output_buffer_size().unwrap()];
        let info = reader.next_frame(&mut buf).unwrap();
        buf.truncate(info.buffer_size());
        assert_eq!(info.color_type, png::ColorType::Rgb);
        (info.width, info.height, buf)
    }

    /// The embedded font draws text: two charts that differ only in their title differ in
    /// the caption band and nowhere else, and the caption has dark (text) pixels.
    #[test]
    fn text_is_drawn_with_the_embedded_font() {
        let dir = std::env::temp_dir().join(format!("ponq-chart-text-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let mut c = chart(
            false,
            vec![Series::new("a", [200, 0, 0], vec![(1.0, 1.0), (2.0, 3.0)])],
        );
        c.title = "Loss".into();
        draw(&[c.clone()], 1, (400, 300), &dir.join("a.png")).unwrap();
        c.title = "Wxyz".into();
        draw(&[c], 1, (400, 300), &dir.join("b.png")).unwrap();
        let (w, h, a) = decode(&dir.join("a.png"));
        let (_, _, b) = decode(&dir.join("b.png"));
        assert_eq!((w, h), (400, 300));
        let px = |img: &[u8], x: u32, y: u32| {
            let i = 3 * (y * w + x) as usize;
            [img[i], img[i + 1], img[i + 2]]
        };
        let mut differ_top = 0;
        let mut dark_top = 0;
        for y in 0..h {
            for x in 0..w {
                let (p, q) = (px(&a, x, y), px(&b, x, y));
                if p != q {
                    assert!(y < 40, "only the caption changes, not ({x}, {y})");
                    differ_top += 1;
                }
                if y < 30 && p.iter().all(|&v| v < 100) {
                    dark_top += 1;
                }
            }
        }
        assert!(differ_top > 50, "{differ_top} caption pixels differ");
        assert!(dark_top > 20, "{dark_top} dark caption pixels");
        std::fs::remove_dir_all(&dir).ok();
    }
}
