//! The loss curves of a run's `metrics.csv` as a PNG (`losses.png`), drawn with
//! `ponq_eval::chart` (plotters, embedded font): log-scale loss against the epoch, one colour
//! per term (total, Chamfer, normals, A, v*, regularisation, occupancy), training solid and
//! validation dashed, with a legend; a second panel shows the meshed validation (CD, F1, NC)
//! when the run computed it.

use std::path::Path;

use anyhow::{Context, Result, bail};
use ponq_eval::chart::{self, Chart, Series};

/// Loss terms as named in `metrics.csv` (`train_<term>`, `val_<term>`), their legend text and
/// colour.
const TERMS: [(&str, &str, [u8; 3]); 7] = [
    ("total", "total", [20, 20, 20]),
    ("cd", "Chamfer", [31, 119, 180]),
    ("normals", "normals", [44, 160, 44]),
    ("a", "A (quadric)", [214, 39, 40]),
    ("vstar", "v*", [148, 103, 189]),
    ("reg", "regularisation", [140, 86, 75]),
    ("occ", "occupancy", [255, 127, 14]),
];

/// The columns of a `metrics.csv`: header and rows.
struct Table {
    header: Vec<String>,
    rows: Vec<Vec<String>>,
}

impl Table {
    fn read(csv: &Path) -> Result<Self> {
        let text =
            std::fs::read_to_string(csv).with_context(|| format!("reading {}", csv.display()))?;
        let mut lines = text.lines();
        let header = lines
            .next()
            .with_context(|| format!("{} is empty", csv.display()))?
            .split(',')
            .map(str::to_string)
            .collect();
        let rows = lines
            .filter(|l| !l.trim().is_empty())
            .map(|l| l.split(',').map(str::to_string).collect())
            .collect();
        Ok(Self { header, rows })
    }

    /// `(epoch, value)` of a column, skipping empty or unparsable cells.
    fn series(&self, name: &str) -> Vec<(f64, f64)> {
        let Some(c) = self.header.iter().position(|h| h == name) else {
            return Vec::new();
        };
        self.rows
            .iter()
            .filter_map(|r| {
                let e: f64 = r.first()?.parse().ok()?;
                let v: f64 = r.get(c)?.parse().ok()?;
                v.is_finite().then_some((e, v))
            })
            .collect()
    }
}

/// The charts of a `metrics.csv`: the losses, and the meshed validation when present.
pub fn loss_charts(csv: &Path) -> Result<Vec<Chart>> {
    let t = Table::read(csv)?;
    if t.rows.is_empty() {
        bail!("no epochs yet in {}", csv.display());
    }
    let mut series = Vec::new();
    for (split, dashed, what) in [("train", false, "train"), ("val", true, "val")] {
        for (key, label, colour) in TERMS {
            let pts = t.series(&format!("{split}_{key}"));
            if pts.iter().any(|p| p.1 > 0.0) {
                series.push(Series {
                    label: format!("{label} ({what})"),
                    colour,
                    dashed,
                    bold: key == "total",
                    points: pts,
                });
            }
        }
    }
    if series.is_empty() {
        bail!("{} has no positive loss values", csv.display());
    }
    let mut charts = vec![Chart {
        title: "losses".into(),
        x_label: "epoch".into(),
        y_label: "loss (log scale)".into(),
        log_y: true,
        x_ticks: None,
        series,
    }];
    let meshed: Vec<Series> = [
        ("val_mesh_f1", "F1", [44, 160, 44]),
        ("val_mesh_nc", "NC", [31, 119, 180]),
    ]
    .into_iter()
    .map(|(col, label, colour)| Series::new(label, colour, t.series(col)))
    .filter(|s| !s.points.is_empty())
    .collect();
    if !meshed.is_empty() {
        charts.push(Chart {
            title: "meshed validation".into(),
            x_label: "epoch".into(),
            y_label: "F1, NC".into(),
            log_y: false,
            x_ticks: None,
            series: meshed,
        });
    }
    let cd = t.series("val_mesh_cd");
    if !cd.is_empty() {
        charts.push(Chart {
            title: "meshed validation CD x1e5".into(),
            x_label: "epoch".into(),
            y_label: "CD x1e5 (log scale)".into(),
            log_y: true,
            x_ticks: None,
            series: vec![Series::new("CD", [214, 39, 40], cd)],
        });
    }
    Ok(charts)
}

/// Reads `metrics.csv` and writes its loss curves to `png`.
pub fn plot_losses(csv: &Path, png: &Path) -> Result<()> {
    let charts = loss_charts(csv)?;
    // The losses fill the top row; the meshed-validation panels share the row below.
    let (losses, meshed) = charts.split_at(1);
    chart::draw_rows(&[(losses, 560), (meshed, 320)], 1100, png)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_term_gets_a_train_and_a_validation_line() {
        let dir = std::env::temp_dir().join(format!("ponq-plot-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let header = "epoch,steps,seconds,lr,train_total,train_cd,train_normals,train_a,train_vstar,train_reg,train_occ,val_total,val_cd,val_normals,val_a,val_vstar,val_reg,val_occ,val_mesh_cd,val_mesh_f1,val_mesh_nc,val_mesh_valid";
        let mut csv = format!("{header}\n");
        for e in 1..=4 {
            let v = |k: f64| format!("{:e}", k / e as f64);
            let losses: Vec<String> = (1..=7).map(|k| v(f64::from(k))).collect();
            let mesh = if e % 2 == 0 {
                "5.0,0.8,0.9,true"
            } else {
                ",,,"
            };
            csv += &format!(
                "{e},{},{},4e-4,{},{},{mesh}\n",
                10 * e,
                5 * e,
                losses.join(","),
                losses.join(",")
            );
        }
        std::fs::write(dir.join("metrics.csv"), &csv).unwrap();
        let charts = loss_charts(&dir.join("metrics.csv")).unwrap();
        assert_eq!(charts.len(), 3, "losses, meshed F1/NC, meshed CD");
        let labels: Vec<&str> = charts[0].series.iter().map(|s| s.label.as_str()).collect();
        for (_, name, _) in TERMS {
            assert!(
                labels.contains(&format!("{name} (train)").as_str()),
                "{labels:?}"
            );
            assert!(
                labels.contains(&format!("{name} (val)").as_str()),
                "{labels:?}"
            );
        }
        assert!(charts[0].log_y);
        assert!(charts[0].series.iter().all(|s| s.points.len() == 4));
        assert!(
            charts[0]
                .series
                .iter()
                .all(|s| s.dashed == s.label.ends_with("(val)"))
        );
        assert_eq!(charts[1].series[0].points, vec![(2.0, 0.8), (4.0, 0.8)]);
        plot_losses(&dir.join("metrics.csv"), &dir.join("losses.png")).unwrap();
        assert!(std::fs::metadata(dir.join("losses.png")).unwrap().len() > 1000);
        // A header only is an error, not a panic or an empty picture.
        std::fs::write(dir.join("empty.csv"), format!("{header}\n")).unwrap();
        assert!(plot_losses(&dir.join("empty.csv"), &dir.join("e.png")).is_err());
        std::fs::remove_dir_all(&dir).ok();
    }
}
