//! The results of an evaluation: one [`Row`] per (shape, method, resolution), kept in
//! `OUT/rows/<shape>@<res>.csv` (written atomically, so a rerun skips the pairs already there),
//! and the report built from them: `per_shape.csv`, `summary.md` (the paper's table layout),
//! `report.md` with the renders and charts.

use std::path::{Path, PathBuf};

use anyhow::{Context, Result, bail};

use crate::chart::{self, Chart, Series};

/// One result line.
#[derive(Debug, Clone, PartialEq)]
pub struct Row {
    /// Shape id.
    pub shape: String,
    /// Method name.
    pub method: String,
    /// Resolution.
    pub res: usize,
    /// CD x 1e5.
    pub cd: f64,
    /// F1.
    pub f1: f64,
    /// Normal consistency.
    pub nc: f64,
    /// Edge CD x 1e2 (NaN without a ground-truth mesh).
    pub ecd: f64,
    /// Edge F1 (NaN without a ground-truth mesh).
    pub ef1: f64,
    /// Closed, oriented, manifold, free of self-intersections.
    pub watertight: bool,
    /// Vertices.
    pub vertices: usize,
    /// Faces.
    pub faces: usize,
    /// Reconstruction time from the grid (seconds).
    pub seconds: f64,
}

/// CSV header of [`Row`].
pub const CSV_HEADER: &str =
    "shape,method,res,cd_x1e5,f1,nc,ecd_x1e2,ef1,watertight,vertices,faces,seconds";

impl Row {
    /// One CSV line.
    pub fn csv(&self) -> String {
        format!(
            "{},{},{},{},{},{},{},{},{},{},{},{}",
            self.shape,
            self.method,
            self.res,
            self.cd,
            self.f1,
            self.nc,
            self.ecd,
            self.ef1,
            self.watertight,
            self.vertices,
            self.faces,
            self.seconds
        )
    }

    /// Parses a line written by [`Row::csv`].
    pub fn parse(line: &str) -> Result<Self> {
        let f: Vec<&str> = line.split(',').collect();
        if f.len() != 12 {
            bail!("a result row needs 12 fields: {line}");
        }
        let num = |i: usize| -> Result<f64> {
            f[i].parse().with_context(|| format!("field {i} of {line}"))
        };
        Ok(Self {
            shape: f[0].to_string(),
            method: f[1].to_string(),
            res: f[2].parse()?,
            cd: num(3)?,
            f1: num(4)?,
            nc: num(5)?,
            ecd: num(6)?,
            ef1: num(7)?,
            watertight: f[8].parse()?,
            vertices: f[9].parse()?,
            faces: f[10].parse()?,
            seconds: num(11)?,
        })
    }
}

/// Means per (method, resolution) in the paper's layout, as a Markdown table.
pub fn summary_markdown(rows: &[Row]) -> String {
    let mut keys: Vec<(usize, String)> = rows.iter().map(|r| (r.res, r.method.clone())).collect();
    keys.sort();
    keys.dedup();
    let mut s = String::from(
        "| method | grid | shapes | CD x1e5 | F1 | NC | ECD x1e2 | EF1 | watertight % | #V | #F | time (s) |\n\
         |---|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|\n",
    );
    for (res, method) in keys {
        let g: Vec<&Row> = rows
            .iter()
            .filter(|r| r.res == res && r.method == method)
            .collect();
        let n = g.len() as f64;
        let mean = |f: &dyn Fn(&Row) -> f64| {
            let v: Vec<f64> = g.iter().map(|r| f(r)).filter(|x| x.is_finite()).collect();
            if v.is_empty() {
                f64::NAN
            } else {
                v.iter().sum::<f64>() / v.len() as f64
            }
        };
        let fmt = |x: f64, d: usize| {
            if x.is_nan() {
                "-".to_string()
            } else {
                format!("{x:.d$}")
            }
        };
        s += &format!(
            "| {method} | {}^3 | {} | {} | {} | {} | {} | {} | {:.1} | {:.0} | {:.0} | {} |\n",
            res + 1,
            g.len(),
            fmt(mean(&|r| r.cd), 3),
            fmt(mean(&|r| r.f1), 3),
            fmt(mean(&|r| r.nc), 3),
            fmt(mean(&|r| r.ecd), 3),
            fmt(mean(&|r| r.ef1), 3),
            100.0 * g.iter().filter(|r| r.watertight).count() as f64 / n,
            mean(&|r| r.vertices as f64),
            mean(&|r| r.faces as f64),
            fmt(mean(&|r| r.seconds), 3),
        );
    }
    s
}

/// Means and medians per (method, grid) of every group of shapes (`groups`: shape id to group
/// name, e.g. `cad` / `freeform`), one Markdown table per group; empty with fewer than two
/// groups.
pub fn summary_by_group(
    rows: &[Row],
    groups: &std::collections::BTreeMap<String, String>,
) -> String {
    let mut names: Vec<&String> = groups.values().collect();
    names.sort();
    names.dedup();
    if names.len() < 2 {
        return String::new();
    }
    let mut s = String::new();
    for g in names {
        let sub: Vec<&Row> = rows
            .iter()
            .filter(|r| groups.get(&r.shape) == Some(g))
            .collect();
        let mut keys: Vec<(usize, String)> =
            sub.iter().map(|r| (r.res, r.method.clone())).collect();
        keys.sort();
        keys.dedup();
        s += &format!(
            "\n### {g} (mean / median)\n\n| method | grid | shapes | CD x1e5 | F1 | NC | ECD x1e2 | EF1 | valid % |\n|---|---|---:|---:|---:|---:|---:|---:|---:|\n"
        );
        for (res, method) in keys {
            let v: Vec<&&Row> = sub
                .iter()
                .filter(|r| r.res == res && r.method == method)
                .collect();
            let stat = |f: &dyn Fn(&Row) -> f64| {
                let mut x: Vec<f64> = v.iter().map(|r| f(r)).filter(|x| x.is_finite()).collect();
                if x.is_empty() {
                    return "-".to_string();
                }
                x.sort_by(f64::total_cmp);
                let mean = x.iter().sum::<f64>() / x.len() as f64;
                let med = if x.len() % 2 == 1 {
                    x[x.len() / 2]
                } else {
                    0.5 * (x[x.len() / 2 - 1] + x[x.len() / 2])
                };
                format!("{mean:.3} / {med:.3}")
            };
            s += &format!(
                "| {method} | {}^3 | {} | {} | {} | {} | {} | {} | {:.1} |\n",
                res + 1,
                v.len(),
                stat(&|r| r.cd),
                stat(&|r| r.f1),
                stat(&|r| r.nc),
                stat(&|r| r.ecd),
                stat(&|r| r.ef1),
                100.0 * v.iter().filter(|r| r.watertight).count() as f64 / v.len().max(1) as f64,
            );
        }
    }
    s
}

/// Reads all rows of `out/rows`.
pub fn read_rows(out: &Path) -> Result<Vec<Row>> {
    let dir = out.join("rows");
    let mut rows = Vec::new();
    if !dir.is_dir() {
        return Ok(rows);
    }
    let mut files: Vec<PathBuf> = std::fs::read_dir(&dir)?
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.extension().is_some_and(|e| e == "csv"))
        .collect();
    files.sort();
    for f in files {
        for line in std::fs::read_to_string(&f)?.lines().skip(1) {
            rows.push(Row::parse(line).with_context(|| format!("in {}", f.display()))?);
        }
    }
    Ok(rows)
}

/// Path of the rows of one (shape, resolution) for the model named `name` (`PoNQ`: no
/// suffix).
pub fn rows_path(out: &Path, id: &str, res: usize, name: &str) -> PathBuf {
    if name == "PoNQ" {
        out.join("rows").join(format!("{id}@{res}.csv"))
    } else {
        out.join("rows").join(format!("{id}@{res}@{name}.csv"))
    }
}

/// Writes rows atomically.
pub fn write_rows(path: &Path, rows: &[Row]) -> Result<()> {
    let tmp = path.with_extension("csv.tmp");
    let mut text = String::from(CSV_HEADER);
    text.push('\n');
    for r in rows {
        text += &r.csv();
        text.push('\n');
    }
    std::fs::write(&tmp, text)?;
    std::fs::rename(&tmp, path)?;
    Ok(())
}

/// Writes `per_shape.csv`, `summary.md` and `report.md` of `out` from its rows.
/// `groups` maps shape ids to groups (see [`summary_by_group`]; empty: no group tables).
pub fn write_report(
    out: &Path,
    missing: &[String],
    failed: &[(String, String)],
    groups: &std::collections::BTreeMap<String, String>,
) -> Result<Vec<Row>> {
    let mut rows = read_rows(out)?;
    rows.sort_by(|a, b| (a.res, &a.method, &a.shape).cmp(&(b.res, &b.method, &b.shape)));
    let mut csv = String::from(CSV_HEADER);
    csv.push('\n');
    for r in &rows {
        csv += &r.csv();
        csv.push('\n');
    }
    std::fs::write(out.join("per_shape.csv"), csv)?;
    let summary = summary_markdown(&rows) + &summary_by_group(&rows, groups);
    std::fs::write(out.join("summary.md"), &summary)?;
    let mut rep = String::from(
        "# PoNQ-rs evaluation\n\nMeans over shapes; metrics at unit bounding-box diagonal (SPEC section 8); time is the reconstruction from the grid (network + meshing, or marching cubes).\n\n",
    );
    rep += &summary;
    if !missing.is_empty() {
        rep += &format!(
            "\n{} shapes of the split have no file here: {}\n",
            missing.len(),
            missing.join(", ")
        );
    }
    if !failed.is_empty() {
        rep += "\nFailed shapes:\n\n";
        for (id, e) in failed {
            rep += &format!("- {id}: {e}\n");
        }
    }
    if rows.iter().any(|r| r.faces > 0) {
        match chart::draw(
            &metric_charts(&rows),
            3,
            (480, 330),
            &out.join("charts.png"),
        ) {
            Ok(()) => {
                rep += "\n## Metrics against grid resolution (means over shapes)\n\n![charts](charts.png)\n";
            }
            Err(e) => rep += &format!("\n(charts not drawn: {e:#})\n"),
        }
    }
    let rdir = out.join("renders");
    if rdir.is_dir() {
        let mut imgs: Vec<PathBuf> = std::fs::read_dir(&rdir)?
            .filter_map(|e| e.ok().map(|e| e.path()))
            .collect();
        imgs.sort();
        if !imgs.is_empty() {
            rep += "\n## Renders (ground truth, then the methods in the table's order)\n\n";
            for p in imgs {
                if let Some(name) = p.file_name().and_then(|n| n.to_str()) {
                    rep += &format!("{name}\n\n![{name}](renders/{name})\n\n");
                }
            }
        }
    }
    std::fs::write(out.join("report.md"), rep)?;
    Ok(rows)
}

/// Colour of a method in charts (the renders' colours).
fn method_colour(method: &str) -> [u8; 3] {
    match method {
        "MC" => [230, 120, 60],
        "PoNQ" => [40, 100, 200],
        "PoNQ-lite" => [50, 160, 70],
        _ => [120, 120, 120],
    }
}

/// One panel per metric (CD and ECD on log axes): the mean over shapes of each method
/// against the grid resolution.
pub fn metric_charts(rows: &[Row]) -> Vec<Chart> {
    let mut res: Vec<usize> = rows.iter().map(|r| r.res).collect();
    res.sort();
    res.dedup();
    let mut methods: Vec<&str> = rows.iter().map(|r| r.method.as_str()).collect();
    methods.sort();
    methods.dedup();
    let ticks: Vec<(f64, String)> = res
        .iter()
        .enumerate()
        .map(|(i, r)| (i as f64, format!("{}^3", r + 1)))
        .collect();
    type Metric = (&'static str, bool, fn(&Row) -> f64);
    let metrics: [Metric; 6] = [
        ("CD x1e5", true, |r| r.cd),
        ("F1", false, |r| r.f1),
        ("NC", false, |r| r.nc),
        ("ECD x1e2", true, |r| r.ecd),
        ("EF1", false, |r| r.ef1),
        ("valid %", false, |r| if r.watertight { 100.0 } else { 0.0 }),
    ];
    metrics
        .iter()
        .map(|&(name, log_y, f)| Chart {
            title: name.to_string(),
            x_label: "grid".to_string(),
            y_label: name.to_string(),
            log_y,
            x_ticks: Some(ticks.clone()),
            series: methods
                .iter()
                .map(|&m| {
                    let pts = res
                        .iter()
                        .enumerate()
                        .filter_map(|(i, &r)| {
                            let v: Vec<f64> = rows
                                .iter()
                                .filter(|row| row.res == r && row.method == m)
                                .map(f)
                                .filter(|x| x.is_finite())
                                .collect();
                            (!v.is_empty())
                                .then(|| (i as f64, v.iter().sum::<f64>() / v.len() as f64))
                        })
                        .collect();
                    Series::new(m, method_colour(m), pts)
                })
                .collect(),
        })
        .filter(|c| c.series.iter().any(|s| !s.points.is_empty()))
        .collect()
}
