//! Summaries of batch logs (`ponq_data::records`: one JSON line per shape): counts by status
//! and by error reason, time percentiles, peak memory. `ponq-eval log LOG...` prints one.

use std::collections::BTreeMap;
use std::path::PathBuf;

use anyhow::{Context, Result};

/// What [`summarise`] found in the logs.
#[derive(Debug, Clone, Default)]
pub struct LogSummary {
    /// Lines read (records).
    pub records: usize,
    /// Shapes by their newest status (a resumed run logs a shape again: the newest record
    /// wins, but a shape logged as done and later as already there counts as done, with its
    /// time).
    pub by_status: BTreeMap<String, usize>,
    /// Failed shapes by reason (the error's text up to its first colon-free part).
    pub by_reason: BTreeMap<String, usize>,
    /// Seconds of the shapes done, sorted.
    pub seconds: Vec<f64>,
    /// Largest peak memory recorded (MB).
    pub peak_rss_mb: Option<f64>,
    /// Outputs checked and found invalid.
    pub invalid: usize,
    /// Lines that are not records (reported, not fatal).
    pub bad_lines: Vec<(PathBuf, usize)>,
    /// The shard counts of the runs that wrote the records (several: the dataset was run with
    /// other splits; the newest record of each shape still decides).
    pub shard_counts: std::collections::BTreeSet<u64>,
}

/// Reads every log (JSON lines) and summarises the newest record of each shape: by its `time`
/// (UTC; records of older versions without one count as older than any with one, in the
/// order read), so that logs of runs with other shard counts, read in any order, never let
/// an old error stand over a newer success. A shape whose newest record says "already" and
/// that has a "done" record counts as done, with that record's time.
///
/// # Errors
/// A log that cannot be read.
pub fn summarise(logs: &[PathBuf]) -> Result<LogSummary> {
    let mut s = LogSummary::default();
    // Per shape: its newest record and its newest "done" record, each with its order key
    // (time, then reading order).
    type Keyed = ((String, usize), serde_json::Value);
    let mut newest: BTreeMap<String, Keyed> = BTreeMap::new();
    let mut newest_done: BTreeMap<String, Keyed> = BTreeMap::new();
    let mut order = 0usize;
    for path in logs {
        let text = std::fs::read_to_string(path)
            .with_context(|| format!("reading the log {}", path.display()))?;
        for (i, line) in text.lines().enumerate() {
            if line.trim().is_empty() {
                continue;
            }
            match serde_json::from_str::<serde_json::Value>(line) {
                Ok(v) if v["name"].is_string() => {
                    s.records += 1;
                    order += 1;
                    if let Some(n) = v["shards"].as_u64() {
                        s.shard_counts.insert(n);
                    }
                    let name = v["name"].as_str().unwrap_or_default().to_string();
                    let key = (v["time"].as_str().unwrap_or("").to_string(), order);
                    let slot = if v["status"] == "done" {
                        Some(&mut newest_done)
                    } else {
                        None
                    };
                    if let Some(m) = slot
                        && m.get(&name).is_none_or(|(k, _)| *k < key)
                    {
                        m.insert(name.clone(), (key.clone(), v.clone()));
                    }
                    if newest.get(&name).is_none_or(|(k, _)| *k < key) {
                        newest.insert(name, (key, v));
                    }
                }
                _ => s.bad_lines.push((path.clone(), i + 1)),
            }
        }
    }
    let mut last: BTreeMap<String, serde_json::Value> = BTreeMap::new();
    for (name, (_, v)) in newest {
        // A re-run logs a done shape as already there: its done record stands.
        let v = if v["status"] == "already" {
            newest_done.remove(&name).map_or(v, |(_, d)| d)
        } else {
            v
        };
        last.insert(name, v);
    }
    for v in last.values() {
        let status = v["status"].as_str().unwrap_or("unknown").to_string();
        if status == "error" {
            *s.by_reason
                .entry(reason(v["error"].as_str().unwrap_or("")))
                .or_default() += 1;
        }
        if status == "done"
            && let Some(t) = v["seconds"].as_f64()
        {
            s.seconds.push(t);
        }
        if v["valid"] == serde_json::Value::Bool(false) {
            s.invalid += 1;
        }
        if let Some(m) = v["peak_rss_mb"].as_f64() {
            s.peak_rss_mb = Some(s.peak_rss_mb.map_or(m, |p: f64| p.max(m)));
        }
        *s.by_status.entry(status).or_default() += 1;
    }
    s.seconds.sort_by(f64::total_cmp);
    Ok(s)
}

/// The reason of an error: its last part (after the context the programs put before a
/// colon), with numbers replaced by `N` so that the same failure groups together.
fn reason(error: &str) -> String {
    let tail = error.rsplit(": ").next().unwrap_or(error).trim();
    let mut out = String::new();
    let mut in_num = false;
    for c in tail.chars().take(120) {
        if c.is_ascii_digit() {
            if !in_num {
                out.push('N');
            }
            in_num = true;
        } else {
            in_num = false;
            out.push(c);
        }
    }
    out
}

/// The `q` quantile (0..=1) of sorted values, nearest rank.
pub fn quantile(sorted: &[f64], q: f64) -> Option<f64> {
    if sorted.is_empty() {
        return None;
    }
    let i = ((q * (sorted.len() - 1) as f64).round() as usize).min(sorted.len() - 1);
    Some(sorted[i])
}

impl std::fmt::Display for LogSummary {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let shapes: usize = self.by_status.values().sum();
        writeln!(f, "{shapes} shapes ({} records)", self.records)?;
        for (k, n) in &self.by_status {
            writeln!(f, "  {k}: {n}")?;
        }
        if !self.by_reason.is_empty() {
            writeln!(f, "errors by reason:")?;
            let mut r: Vec<_> = self.by_reason.iter().collect();
            r.sort_by(|a, b| b.1.cmp(a.1).then(a.0.cmp(b.0)));
            for (k, n) in r {
                writeln!(f, "  {n:>6}  {k}")?;
            }
        }
        if !self.seconds.is_empty() {
            let q = |x| quantile(&self.seconds, x).unwrap_or(f64::NAN);
            writeln!(
                f,
                "seconds per shape done: p50 {:.2}, p90 {:.2}, p99 {:.2}, max {:.2}, total {:.1}",
                q(0.5),
                q(0.9),
                q(0.99),
                q(1.0),
                self.seconds.iter().sum::<f64>()
            )?;
        }
        if let Some(m) = self.peak_rss_mb {
            writeln!(f, "peak memory: {m:.0} MB")?;
        }
        if self.invalid > 0 {
            writeln!(f, "invalid outputs: {}", self.invalid)?;
        }
        if !self.bad_lines.is_empty() {
            writeln!(f, "lines that are not records: {}", self.bad_lines.len())?;
        }
        if self.shard_counts.len() > 1 {
            let counts: Vec<String> = self.shard_counts.iter().map(u64::to_string).collect();
            writeln!(
                f,
                "runs with {} shards: each shape's newest record counts",
                counts.join(", ")
            )?;
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn summary_counts_statuses_reasons_and_times() {
        let dir = std::env::temp_dir().join(format!("ponq-logs-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let a = dir.join("a.jsonl");
        let b = dir.join("b.jsonl");
        std::fs::write(
            &a,
            concat!(
                r#"{"name":"x","status":"error","error":"reading x.obj: line 12: bad face","seconds":0.1}"#,
                "\n",
                r#"{"name":"y","status":"done","seconds":2.0,"peak_rss_mb":100}"#,
                "\n",
                "not json\n",
            ),
        )
        .unwrap();
        std::fs::write(
            &b,
            concat!(
                r#"{"name":"z","status":"error","error":"reading z.obj: line 7: bad face"}"#,
                "\n",
                r#"{"name":"x","status":"done","seconds":4.0,"peak_rss_mb":300,"valid":true}"#,
                "\n",
                r#"{"name":"x","status":"already","seconds":0.0}"#,
                "\n",
            ),
        )
        .unwrap();
        let s = summarise(&[a, b]).unwrap();
        assert_eq!(s.records, 5);
        assert_eq!(s.by_status["done"], 2);
        assert_eq!(s.by_status["error"], 1);
        assert_eq!(s.by_reason["bad face"], 1);
        assert_eq!(s.seconds, vec![2.0, 4.0]);
        assert_eq!(s.peak_rss_mb, Some(300.0));
        assert_eq!(s.bad_lines.len(), 1);
        assert!(s.to_string().contains("p50"));
        assert_eq!(reason("at 12.5 mm: 3 faces"), "N faces");
        std::fs::remove_dir_all(&dir).ok();
    }

    /// Two logs of runs with different shard counts: whatever order they are read in, the
    /// newest record of a shape decides (an old error never overrides a newer done).
    #[test]
    fn newest_record_wins_across_shard_counts() {
        let dir = std::env::temp_dir().join(format!("ponq-logs-shards-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        // The first run: 2 shards; "a" failed, "b" done.
        let old = dir.join("log-shard-1-of-2.jsonl");
        std::fs::write(
            &old,
            concat!(
                r#"{"name":"a","time":"2026-12-01T10:00:00.000000Z","shards":2,"status":"error","error":"x: out of memory"}"#,
                "\n",
                r#"{"name":"b","time":"2026-12-01T10:00:01.000000Z","shards":2,"status":"done","seconds":3.0}"#,
                "\n",
            ),
        )
        .unwrap();
        // The re-run: 3 shards; "a" done now, "b" already there.
        let new = dir.join("log-shard-0-of-3.jsonl");
        std::fs::write(
            &new,
            concat!(
                r#"{"name":"a","time":"2026-12-02T09:00:00.000000Z","shards":3,"status":"done","seconds":5.0}"#,
                "\n",
                r#"{"name":"b","time":"2026-12-02T09:00:01.000000Z","shards":3,"status":"already","seconds":0.0}"#,
                "\n",
            ),
        )
        .unwrap();
        for logs in [
            vec![old.clone(), new.clone()],
            vec![new.clone(), old.clone()],
        ] {
            let s = summarise(&logs).unwrap();
            assert_eq!(s.by_status.get("done"), Some(&2), "{s}");
            assert_eq!(s.by_status.get("error"), None, "{s}");
            assert_eq!(s.seconds, vec![3.0, 5.0]);
            assert_eq!(s.shard_counts.len(), 2);
            assert!(s.to_string().contains("2, 3 shards"), "{s}");
        }
        std::fs::remove_dir_all(&dir).ok();
    }
}
