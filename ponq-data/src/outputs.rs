//! A batch's output files: written whole or not at all, and recognised as whole on resume.
//!
//! An output is written under a temporary name beside it ([`partial_path`]: a hidden file
//! named after the output, this machine and this process), then [`commit`]ted: the file's
//! data are flushed to the disk (`fsync`), it is renamed to its name, and the folder is
//! flushed, so that after a crash of the machine either the whole file is there under its
//! name or nothing is. A resumed batch counts an output as done only if [`is_whole`] says so
//! (a file of a run that crashed before these rules, or cut by a full disk, is redone), and
//! removes the temporary files that crashed runs left ([`StalePartials`]).
//!
//! ```no_run
//! use std::path::Path;
//! use ponq_data::outputs::{commit, partial_path};
//! let out = Path::new("out/a/model.npz");
//! let tmp = partial_path(out);
//! std::fs::write(&tmp, b"...").map_err(|e| ponq_mesh::Error::io(&tmp, e))?;
//! commit(&tmp, out)?;
//! # Ok::<(), ponq_data::DataError>(())
//! ```

use std::collections::HashMap;
use std::io::{Read, Seek, SeekFrom};
use std::path::{Path, PathBuf};

use crate::error::{DataError, Result};

/// The marker between an output's name and the writer's identity in a temporary file name.
const PARTIAL: &str = ".partial-";

/// How long a temporary file of another machine (or an older version) must be untouched to
/// count as left by a crashed run: no shape takes that long to write.
pub const FOREIGN_STALE_AFTER: std::time::Duration = std::time::Duration::from_secs(6 * 3600);

/// This machine's name (`/proc/sys/kernel/hostname`, else `$HOSTNAME`, else `host`), with
/// every character but letters, digits and `-` replaced by `-`.
fn host() -> String {
    let raw = std::fs::read_to_string("/proc/sys/kernel/hostname")
        .ok()
        .or_else(|| std::env::var("HOSTNAME").ok())
        .unwrap_or_else(|| "host".into());
    let h: String = raw
        .trim()
        .chars()
        .map(|c| if c.is_ascii_alphanumeric() { c } else { '-' })
        .collect();
    if h.is_empty() { "host".into() } else { h }
}

/// The temporary file an output is written to before [`commit`]: `DIR/.STEM.partial-HOST-PID.EXT`
/// beside `output` (hidden; the same folder, so the rename is atomic).
pub fn partial_path(output: &Path) -> PathBuf {
    let stem = output
        .file_stem()
        .map(|s| s.to_string_lossy().into_owned())
        .unwrap_or_default();
    let ext = output
        .extension()
        .map(|e| format!(".{}", e.to_string_lossy()))
        .unwrap_or_default();
    output.with_file_name(format!(
        ".{stem}{PARTIAL}{}-{}{ext}",
        host(),
        std::process::id()
    ))
}

/// Makes a whole `partial` file the output `output`: flushes its data to the disk, renames it
/// and flushes the folder (the rename itself survives a crash of the machine).
///
/// # Errors
/// Flushing or renaming fails (the partial file is then removed).
pub fn commit(partial: &Path, output: &Path) -> Result<()> {
    let io = |p: &Path, e| DataError::from(ponq_mesh::Error::io(p, e));
    let result = std::fs::File::open(partial)
        .and_then(|f| f.sync_all())
        .map_err(|e| io(partial, e))
        .and_then(|()| std::fs::rename(partial, output).map_err(|e| io(output, e)));
    if result.is_err() {
        let _ = std::fs::remove_file(partial);
    }
    result?;
    // The folder's entry (the rename) to the disk. Not every platform can open a folder;
    // where it cannot, the rename is still atomic, only not yet durable.
    if let Some(dir) = output.parent().filter(|d| !d.as_os_str().is_empty())
        && let Ok(d) = std::fs::File::open(dir)
    {
        d.sync_all().map_err(|e| io(dir, e))?;
    }
    Ok(())
}

/// Whether `path` is a whole output: an `.npz` whose zip directory ends the file where its
/// end record says (a cut file has no end record); a mesh (`.obj`, `.ply`, `.off`) that reads
/// back with at least one face and, for an OBJ this project wrote, the vertex and triangle
/// counts of its first line (a cut text file loses its last lines; PLY and OFF headers hold
/// their counts, which the readers check). Whether the mesh is valid is another matter (the
/// log says). Any other file: it exists and is not empty.
pub fn is_whole(path: &Path) -> bool {
    let ext = path
        .extension()
        .and_then(|e| e.to_str())
        .map(str::to_ascii_lowercase);
    match ext.as_deref() {
        Some("npz") => zip_is_whole(path).unwrap_or(false),
        Some(e @ ("obj" | "ply" | "off")) => match ponq_mesh::io::read_mesh(path) {
            Ok(m) => {
                !m.faces.is_empty()
                    && (e != "obj"
                        || obj_header_counts(path)
                            .is_none_or(|c| c == (m.vertices.len(), m.faces.len())))
            }
            Err(_) => false,
        },
        _ => std::fs::metadata(path).is_ok_and(|m| m.is_file() && m.len() > 0),
    }
}

/// The counts of the first line `# V vertices, F triangles, ...` that this project's OBJ
/// writer puts first; `None` for another file.
fn obj_header_counts(path: &Path) -> Option<(usize, usize)> {
    use std::io::BufRead;
    let f = std::fs::File::open(path).ok()?;
    let mut line = String::new();
    std::io::BufReader::new(f).read_line(&mut line).ok()?;
    let rest = line.strip_prefix("# ")?;
    let (v, rest) = rest.split_once(" vertices, ")?;
    let (f, _) = rest.split_once(" triangles")?;
    Some((v.trim().parse().ok()?, f.trim().parse().ok()?))
}

/// A zip file (an `.npz`) ends with its end-of-central-directory record (no comment: the
/// files this project writes have none; a comment of up to 64 KiB is searched for too), and
/// the central directory it points at ends where that record starts.
fn zip_is_whole(path: &Path) -> std::io::Result<bool> {
    let mut f = std::fs::File::open(path)?;
    let len = f.metadata()?.len();
    // The end record is the last 22 bytes when there is no comment (always, for the files
    // this project writes): read those first, and search further back only if need be.
    for window in [22u64, 22 + 65_535] {
        if let Some(ok) = zip_end(&mut f, len, window)? {
            return Ok(ok);
        }
    }
    Ok(false)
}

/// [`zip_is_whole`] on the last `window` bytes: `None` when no end record is found there.
fn zip_end(f: &mut std::fs::File, len: u64, window: u64) -> std::io::Result<Option<bool>> {
    let tail_len = len.min(window);
    f.seek(SeekFrom::Start(len - tail_len))?;
    let mut tail = vec![0u8; tail_len as usize];
    f.read_exact(&mut tail)?;
    let u16_at = |b: &[u8], i: usize| u16::from_le_bytes([b[i], b[i + 1]]);
    let u32_at = |b: &[u8], i: usize| u32::from_le_bytes([b[i], b[i + 1], b[i + 2], b[i + 3]]);
    // The last record signature whose comment length reaches exactly the end of the file.
    for start in (0..tail.len().saturating_sub(21)).rev() {
        if u32_at(&tail, start) != 0x0605_4b50 {
            continue;
        }
        let comment = usize::from(u16_at(&tail, start + 20));
        if start + 22 + comment != tail.len() {
            continue;
        }
        let record_at = len - tail_len + start as u64;
        // A zip64 file (an array past 2 GB) puts its directory's place in the zip64 end
        // record, found through the 20-byte locator just before this one.
        if record_at >= 20 {
            let mut loc = [0u8; 20];
            f.seek(SeekFrom::Start(record_at - 20))?;
            f.read_exact(&mut loc)?;
            if u32_at(&loc, 0) == 0x0706_4b50 {
                let at = u64_at(&loc, 8);
                let mut rec = [0u8; 56];
                if at.checked_add(56).is_none_or(|end| end > record_at - 20) {
                    return Ok(Some(false));
                }
                f.seek(SeekFrom::Start(at))?;
                f.read_exact(&mut rec)?;
                return Ok(Some(
                    u32_at(&rec, 0) == 0x0606_4b50
                        && u64_at(&rec, 48).checked_add(u64_at(&rec, 40)) == Some(at),
                ));
            }
        }
        let cd_size = u64::from(u32_at(&tail, start + 12));
        let cd_offset = u64::from(u32_at(&tail, start + 16));
        return Ok(Some(cd_offset + cd_size == record_at));
    }
    Ok(None)
}

fn u64_at(b: &[u8], i: usize) -> u64 {
    let mut a = [0u8; 8];
    a.copy_from_slice(&b[i..i + 8]);
    u64::from_le_bytes(a)
}

/// The temporary files of [`partial_path`] under an output folder, by the output they were
/// meant for, found once at the start of a batch.
#[derive(Debug, Default)]
pub struct StalePartials {
    by_output: HashMap<PathBuf, Vec<PathBuf>>,
}

impl StalePartials {
    /// Every temporary file under `out` (recursively) that no live writer holds: on this
    /// machine, one whose process no longer runs; of another machine (or of an older version
    /// of this program, which named files by process only), one untouched for
    /// [`FOREIGN_STALE_AFTER`] (its writer may still be at work: leaving it costs disk only,
    /// since every writer writes its own file).
    pub fn find(out: &Path) -> Self {
        let me = host();
        let now = std::time::SystemTime::now();
        let old_enough = |p: &Path| {
            std::fs::metadata(p)
                .and_then(|m| m.modified())
                .ok()
                .and_then(|t| now.duration_since(t).ok())
                .is_some_and(|age| age >= FOREIGN_STALE_AFTER)
        };
        let alive = |pid: &str| {
            pid.parse::<u32>().is_ok_and(|pid| {
                pid == std::process::id() || Path::new(&format!("/proc/{pid}")).exists()
            })
        };
        let mut by_output: HashMap<PathBuf, Vec<PathBuf>> = HashMap::new();
        let mut stack = vec![out.to_path_buf()];
        while let Some(d) = stack.pop() {
            let Ok(entries) = std::fs::read_dir(&d) else {
                continue;
            };
            for e in entries.flatten() {
                let p = e.path();
                if e.file_type().is_ok_and(|t| t.is_dir()) {
                    stack.push(p);
                    continue;
                }
                let Some(name) = p.file_name().and_then(|n| n.to_str()) else {
                    continue;
                };
                let Some((stem, rest)) = name.strip_prefix('.').and_then(|n| n.split_once(PARTIAL))
                else {
                    continue;
                };
                // rest: HOST-PID[.EXT[.MORE]] (a writer may add its own temporary suffix), or
                // PID[.EXT] from older versions.
                let (who, ext) = rest.split_once('.').unwrap_or((rest, ""));
                let ext = ext.split('.').next().unwrap_or("");
                let stale = match who.rsplit_once('-') {
                    Some((h, pid)) if h == me => !alive(pid),
                    _ => old_enough(&p),
                };
                if !stale {
                    continue;
                }
                let output = if ext.is_empty() {
                    d.join(stem)
                } else {
                    d.join(format!("{stem}.{ext}"))
                };
                by_output.entry(output).or_default().push(p);
            }
        }
        Self { by_output }
    }

    /// Removes the stale temporary files of `output`; returns how many.
    pub fn remove_for(&self, output: &Path) -> usize {
        self.by_output.get(output).map_or(0, |v| {
            v.iter().filter(|p| std::fs::remove_file(p).is_ok()).count()
        })
    }

    /// How many were found.
    pub fn len(&self) -> usize {
        self.by_output.values().map(Vec::len).sum()
    }

    /// Whether none was found.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn tmp(name: &str) -> PathBuf {
        let d = std::env::temp_dir().join(format!("ponq-outputs-{name}-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&d);
        std::fs::create_dir_all(&d).unwrap();
        d
    }

    #[test]
    fn cut_files_are_not_whole() {
        let d = tmp("cut");
        let npz = d.join("r.npz");
        ponq_mesh::io::npz::write_arrays(
            &npz,
            &[ponq_mesh::io::npz::NamedArray {
                name: "a".into(),
                shape: vec![1000],
                data: (0..1000).map(f64::from).collect(),
                f32_storage: true,
            }],
        )
        .unwrap();
        assert!(is_whole(&npz));
        let bytes = std::fs::read(&npz).unwrap();
        for cut in [bytes.len() - 1, bytes.len() - 30, bytes.len() / 2, 10, 0] {
            std::fs::write(&npz, &bytes[..cut]).unwrap();
            assert!(!is_whole(&npz), "cut at {cut} of {}", bytes.len());
        }
        // A mesh cut anywhere is not whole, in every format; an open one is whole.
        let obj = d.join("m.obj");
        let v: Vec<[f64; 3]> = (0..8)
            .map(|i| [f64::from(i & 1), f64::from((i >> 1) & 1), f64::from(i >> 2)])
            .collect();
        let f = vec![
            [0, 2, 1],
            [1, 2, 3],
            [4, 5, 6],
            [5, 7, 6],
            [0, 1, 4],
            [1, 5, 4],
            [2, 6, 3],
            [3, 6, 7],
            [0, 4, 2],
            [2, 4, 6],
            [1, 3, 5],
            [3, 7, 5],
        ];
        let cube = ponq_mesh::TriMesh::new(v, f).unwrap();
        for ext in ["obj", "ply", "off"] {
            let path = d.join(format!("m.{ext}"));
            ponq_mesh::io::write_mesh(&path, &cube).unwrap();
            assert!(is_whole(&path), "{ext}");
            let bytes = std::fs::read(&path).unwrap();
            // Cut inside the faces, at a line end of the faces, in the vertices.
            let last_faces = bytes.len() - bytes.len() / 8;
            let line_end = bytes[..bytes.len() - 2]
                .iter()
                .rposition(|&b| b == b'\n')
                .map_or(bytes.len() / 2, |i| i + 1);
            for cut in [last_faces, line_end, bytes.len() / 3] {
                std::fs::write(&path, &bytes[..cut]).unwrap();
                assert!(!is_whole(&path), "{ext} cut at {cut} of {}", bytes.len());
            }
        }
        let mut open = cube.clone();
        open.faces.pop();
        ponq_mesh::io::write_mesh(&obj, &open).unwrap();
        assert!(is_whole(&obj));
        std::fs::remove_dir_all(&d).ok();
    }

    #[test]
    fn commit_renames_and_stale_partials_are_found() {
        let d = tmp("commit");
        let out = d.join("sub").join("a.npz");
        std::fs::create_dir_all(out.parent().unwrap()).unwrap();
        let p = partial_path(&out);
        assert!(
            p.file_name()
                .unwrap()
                .to_str()
                .unwrap()
                .starts_with(".a.partial-")
        );
        std::fs::write(&p, b"x").unwrap();
        commit(&p, &out).unwrap();
        assert!(!p.exists() && out.is_file());
        // A file left by a process of this machine that no longer runs (pid far past any
        // pid_max); one of another machine and one of an older version, both recent (their
        // writers may be at work) and both old.
        let dead = out.with_file_name(format!(".a{PARTIAL}{}-4294967290.npz", host()));
        let other = out.with_file_name(format!(".a{PARTIAL}elsewhere-1.npz.tmp"));
        let older = out.with_file_name(format!(".a{PARTIAL}4294967290.npz"));
        let mine = partial_path(&out);
        for f in [&dead, &other, &older, &mine] {
            std::fs::write(f, b"x").unwrap();
        }
        let stale = StalePartials::find(&d);
        assert_eq!(stale.len(), 1, "{stale:?}");
        assert_eq!(stale.remove_for(&out), 1);
        assert!(!dead.exists() && other.exists() && older.exists() && mine.exists());
        let long_ago = std::time::SystemTime::now() - FOREIGN_STALE_AFTER * 2;
        for f in [&other, &older] {
            std::fs::File::options()
                .write(true)
                .open(f)
                .unwrap()
                .set_modified(long_ago)
                .unwrap();
        }
        let stale = StalePartials::find(&d);
        assert_eq!(stale.remove_for(&out), 2);
        assert!(!other.exists() && !older.exists() && mine.exists());
        std::fs::remove_dir_all(&d).ok();
    }
}
