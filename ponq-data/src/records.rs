//! Datasets over many machines: [`Shard`] (a deterministic split of a dataset by name, so that
//! N machines, Slurm array tasks or Ray tasks cover it exactly once) and [`RecordLog`] (one
//! JSON line per shape beside the outputs: a bad file is a record, never the end of a batch).
//!
//! ```
//! use ponq_data::records::Shard;
//! let shards: Vec<Shard> = (0..3).map(|i| Shard::new(i, 3).unwrap()).collect();
//! // Every name falls in exactly one shard.
//! for name in ["bunny", "part_0001", "tshirt"] {
//!     assert_eq!(shards.iter().filter(|s| s.contains(name)).count(), 1);
//! }
//! assert_eq!("2/3".parse::<Shard>().unwrap(), shards[2]);
//! ```

use std::fs::{File, OpenOptions};
use std::io::Write;
use std::path::{Path, PathBuf};
use std::sync::Mutex;

use crate::error::{DataError, Result};

/// Shard `index` of `count`: the names whose 64-bit FNV-1a hash is `index` modulo `count`.
/// The hash depends on the name only (not on the other files, their order or the machine),
/// so the shards of a dataset are disjoint, cover it, and stay so when files are added.
///
/// Invariant: `index < count`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Shard {
    index: u64,
    count: u64,
}

impl Shard {
    /// Shard `index` of `count`; `None` unless `index < count`.
    pub fn new(index: u64, count: u64) -> Option<Self> {
        (index < count).then_some(Self { index, count })
    }

    /// The shard's index.
    pub fn index(&self) -> u64 {
        self.index
    }

    /// The number of shards.
    pub fn count(&self) -> u64 {
        self.count
    }

    /// Whether `name` (an output file's stem) belongs to this shard.
    pub fn contains(&self, name: &str) -> bool {
        fnv1a(name.as_bytes()) % self.count == self.index
    }

    /// The log file name of this shard: `log-shard-I-of-N.jsonl`.
    pub fn log_name(&self) -> String {
        format!("log-shard-{}-of-{}.jsonl", self.index, self.count)
    }
}

impl std::str::FromStr for Shard {
    type Err = String;
    fn from_str(s: &str) -> std::result::Result<Self, String> {
        let (i, n) = s
            .split_once('/')
            .ok_or_else(|| format!("expected I/N (e.g. 0/4), got {s:?}"))?;
        let i: u64 = i
            .trim()
            .parse()
            .map_err(|_| format!("the shard index in {s:?} is not a number"))?;
        let n: u64 = n
            .trim()
            .parse()
            .map_err(|_| format!("the shard count in {s:?} is not a number"))?;
        Shard::new(i, n).ok_or_else(|| {
            format!("the shard index must be below the count (0/N .. N-1/N), got {s:?}")
        })
    }
}

impl std::fmt::Display for Shard {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{}/{}", self.index, self.count)
    }
}

/// The default log of a batch writing into `out`: `out/log.jsonl`, or
/// `out/log-shard-I-of-N.jsonl` for a shard (so that concurrent shards never share a file).
pub fn default_log(out: &Path, shard: Option<Shard>) -> PathBuf {
    out.join(shard.map_or_else(|| "log.jsonl".to_string(), |s| s.log_name()))
}

/// 64-bit FNV-1a (stable across platforms and versions, unlike the standard library's hasher).
fn fnv1a(bytes: &[u8]) -> u64 {
    let mut h: u64 = 0xcbf2_9ce4_8422_2325;
    for &b in bytes {
        h ^= u64::from(b);
        h = h.wrapping_mul(0x0100_0000_01b3);
    }
    h
}

/// What happened to one shape.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Status {
    /// Written in this run.
    Done,
    /// Its output was already there (a resumed run).
    Already,
    /// Failed; the record's `error` says why.
    Error,
}

impl Status {
    /// `"done"`, `"already"` or `"error"`.
    pub fn as_str(&self) -> &'static str {
        match self {
            Self::Done => "done",
            Self::Already => "already",
            Self::Error => "error",
        }
    }
}

/// One shape's line of a [`RecordLog`].
#[derive(Debug, Clone)]
pub struct Record {
    /// The output's name ([`crate::names`]: the input's stem, or its path below the dataset's
    /// folder where stems repeat).
    pub name: String,
    /// When the record was made: UTC, `YYYY-MM-DDTHH:MM:SS.ffffffZ` (fixed width, so that
    /// text order is time order).
    pub time: String,
    /// The shard count of the run that wrote it (1: not sharded).
    pub shards: u64,
    /// The input file.
    pub input: PathBuf,
    /// What happened.
    pub status: Status,
    /// Why it failed.
    pub error: Option<String>,
    /// Seconds per stage, in order.
    pub stages: Vec<(String, f64)>,
    /// Seconds in all.
    pub seconds: f64,
    /// The process's peak resident memory so far, in MB (a batch runs shapes in parallel in
    /// one process: per shape it is an upper bound).
    pub peak_rss_mb: Option<f64>,
    /// Whether the output passed its validity check (meshes).
    pub valid: Option<bool>,
    /// Output vertices and faces (meshes).
    pub vertices: Option<usize>,
    /// Output faces.
    pub faces: Option<usize>,
    /// A warning kept with a written shape.
    pub warning: Option<String>,
    /// The repair's defect report, as its JSON object.
    pub report: Option<String>,
}

impl Record {
    /// A record of `name` with nothing measured yet.
    pub fn new(name: impl Into<String>, input: impl Into<PathBuf>, status: Status) -> Self {
        Self {
            name: name.into(),
            time: utc_now(),
            shards: 1,
            input: input.into(),
            status,
            error: None,
            stages: Vec::new(),
            seconds: 0.0,
            peak_rss_mb: peak_rss_mb(),
            valid: None,
            vertices: None,
            faces: None,
            warning: None,
            report: None,
        }
    }

    /// The record as one line of JSON (no newline).
    pub fn to_json(&self) -> String {
        let mut m = serde_json::Map::new();
        m.insert("name".into(), self.name.clone().into());
        m.insert("time".into(), self.time.clone().into());
        m.insert("shards".into(), self.shards.into());
        m.insert(
            "input".into(),
            self.input.to_string_lossy().into_owned().into(),
        );
        m.insert("status".into(), self.status.as_str().into());
        m.insert("error".into(), self.error.clone().into());
        let stages: serde_json::Map<String, serde_json::Value> = self
            .stages
            .iter()
            .map(|(k, v)| (k.clone(), round(*v).into()))
            .collect();
        m.insert("stages".into(), stages.into());
        m.insert("seconds".into(), round(self.seconds).into());
        m.insert("peak_rss_mb".into(), self.peak_rss_mb.map(round).into());
        m.insert("valid".into(), self.valid.into());
        m.insert("vertices".into(), self.vertices.into());
        m.insert("faces".into(), self.faces.into());
        m.insert("warning".into(), self.warning.clone().into());
        let report = self
            .report
            .as_deref()
            .and_then(|r| serde_json::from_str::<serde_json::Value>(r).ok())
            .unwrap_or(serde_json::Value::Null);
        m.insert("report".into(), report);
        serde_json::Value::Object(m).to_string()
    }
}

/// The time now, UTC, as [`Record::time`] writes it.
pub fn utc_now() -> String {
    let t = time::OffsetDateTime::now_utc();
    format!(
        "{:04}-{:02}-{:02}T{:02}:{:02}:{:02}.{:06}Z",
        t.year(),
        u8::from(t.month()),
        t.day(),
        t.hour(),
        t.minute(),
        t.second(),
        t.microsecond()
    )
}

fn round(x: f64) -> f64 {
    (x * 1e4).round() / 1e4
}

/// The process's peak resident memory in MB (`VmHWM` of `/proc/self/status`; `None` elsewhere).
pub fn peak_rss_mb() -> Option<f64> {
    let s = std::fs::read_to_string("/proc/self/status").ok()?;
    let line = s.lines().find(|l| l.starts_with("VmHWM:"))?;
    let kb: f64 = line.split_whitespace().nth(1)?.parse().ok()?;
    Some(kb / 1024.0)
}

/// A log of [`Record`]s, one JSON line each, appended (a resumed run adds to it; lines are
/// written whole and flushed one by one, so a killed run leaves whole lines). Give each shard
/// or worker its own file ([`Shard::log_name`]) on a shared filesystem; a log is merged by
/// concatenation.
pub struct RecordLog {
    path: PathBuf,
    file: Mutex<File>,
}

impl RecordLog {
    /// Opens (creates) `path` for appending.
    ///
    /// # Errors
    /// The file cannot be opened.
    pub fn append(path: impl AsRef<Path>) -> Result<Self> {
        let path = path.as_ref().to_path_buf();
        let file = OpenOptions::new()
            .create(true)
            .append(true)
            .open(&path)
            .map_err(|e| ponq_mesh::Error::io(&path, e))?;
        Ok(Self {
            path,
            file: Mutex::new(file),
        })
    }

    /// The log's path.
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// Appends one record.
    ///
    /// # Errors
    /// Writing fails.
    pub fn write(&self, r: &Record) -> Result<()> {
        self.append_line(&r.to_json())
    }

    /// Appends one line (a record already in JSON, e.g. read from another log).
    ///
    /// # Errors
    /// Writing fails.
    pub fn append_line(&self, json: &str) -> Result<()> {
        let line = format!("{}\n", json.trim_end());
        let mut f = self
            .file
            .lock()
            .map_err(|_| DataError::Invalid("the log's writer panicked".into()))?;
        f.write_all(line.as_bytes())
            .and_then(|()| f.flush())
            .map_err(|e| ponq_mesh::Error::io(&self.path, e))?;
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn shards_partition_names_and_parse() {
        let names: Vec<String> = (0..2000).map(|i| format!("shape_{i:05}")).collect();
        for n in [1u64, 2, 3, 7] {
            let mut counts = vec![0usize; n as usize];
            for name in &names {
                let owners: Vec<u64> = (0..n)
                    .filter(|&i| Shard::new(i, n).unwrap().contains(name))
                    .collect();
                assert_eq!(owners.len(), 1, "{name} in {owners:?} of {n}");
                counts[owners[0] as usize] += 1;
            }
            // Balanced within a few percent.
            let expect = names.len() as f64 / n as f64;
            assert!(
                counts
                    .iter()
                    .all(|&c| (c as f64 - expect).abs() < 0.15 * expect + 5.0)
            );
        }
        assert!("3/3".parse::<Shard>().is_err());
        assert!("a/3".parse::<Shard>().is_err());
        assert!("1".parse::<Shard>().is_err());
        assert_eq!("1/4".parse::<Shard>().unwrap().to_string(), "1/4");
    }

    #[test]
    fn records_are_json_lines() {
        let mut r = Record::new("a \"quoted\" name", "in/a.obj", Status::Error);
        r.error = Some("line 1\nline 2".into());
        r.stages.push(("sdf".into(), 0.123456));
        r.report = Some("{\"found\": 3}".into());
        let line = r.to_json();
        assert!(!line.contains('\n'));
        let v: serde_json::Value = serde_json::from_str(&line).unwrap();
        assert_eq!(v["name"], "a \"quoted\" name");
        assert_eq!(v["status"], "error");
        assert_eq!(v["error"], "line 1\nline 2");
        assert_eq!(v["stages"]["sdf"], 0.1235);
        assert_eq!(v["report"]["found"], 3);
        assert_eq!(v["shards"], 1);
        let t = v["time"].as_str().unwrap();
        assert_eq!(t.len(), "2026-12-07T20:01:02.123456Z".len(), "{t}");
        assert!(t.ends_with('Z') && t.as_bytes()[10] == b'T');
        assert!(t >= "2026-01-01" && utc_now().as_str() >= t);
    }
}
