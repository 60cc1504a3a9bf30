//! Process-wide allocator settings for the command-line programs, and the memory a run may
//! take ([`available_bytes`]).
//!
//! The mesher allocates and frees arrays of tens of megabytes stage after stage (the
//! Delaunay's tet arena, the output tets, the half-edges). glibc's allocator hands blocks that
//! large to the kernel on `free` and asks for fresh ones on the next `malloc`, and every page
//! of a fresh block costs a page fault and zeroing on first touch. [`keep_freed_memory`] makes
//! it keep freed memory for the next stage instead. A one-shot program loses nothing by it
//! (the memory goes back at exit); a library does not call it on its user's behalf.

/// Asks glibc's `malloc` to serve blocks up to 32 MiB from its heap and not to return freed
/// heap memory to the kernel, so that each meshing stage reuses the pages the previous one
/// freed. Measured (`ponq-mesh` on `mesh_bench`'s 109k-point PoNQ, fresh processes,
/// `perf stat`): 26k page faults instead of 35k. Does nothing on other platforms. Call it once,
/// at the start of `main`, before any other thread allocates.
pub fn keep_freed_memory() {
    #[cfg(all(target_os = "linux", target_env = "gnu"))]
    // SAFETY: `mallopt` only changes the allocator's tuning parameters; glibc serialises it
    // with allocations, and both values are in the ranges its manual documents (the mmap
    // threshold at most 32 MiB on 64-bit systems).
    unsafe {
        libc::mallopt(libc::M_MMAP_THRESHOLD, 32 << 20);
        libc::mallopt(libc::M_TRIM_THRESHOLD, i32::MAX);
    }
}

/// How much more memory this process may take, and which limit says so.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Budget {
    /// Bytes the process may still take.
    pub bytes: u64,
    /// The limit that gives it (the smallest of them), for messages.
    pub source: LimitSource,
}

/// Where a [`Budget`] comes from.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum LimitSource {
    /// `$PONQ_MEMORY_LIMIT`, less what the process already holds.
    Env,
    /// The memory limit of the process's control group (a Docker / Kubernetes container, a
    /// Slurm job, a systemd unit), less what the group holds beyond its reclaimable cache.
    Cgroup,
    /// The kernel's estimate of the memory available without swapping (`MemAvailable`).
    System,
}

impl std::fmt::Display for LimitSource {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            Self::Env => "PONQ_MEMORY_LIMIT less what this process holds",
            Self::Cgroup => "the memory limit of this container / job (cgroup) less its use",
            Self::System => "the system's available memory",
        })
    }
}

/// The memory this process may still take: the smallest of
/// - `$PONQ_MEMORY_LIMIT` (a total for the process: bytes, or a number with a unit `K`, `M`,
///   `G`, `T`, `KB` .. `TB` or `KiB` .. `TiB`, all powers of 1024 as Docker and Slurm read
///   them) less the process's resident memory;
/// - the limit of the process's control group, v2 `memory.max` or v1
///   `memory.limit_in_bytes` (of its group and every group above it), less the group's use
///   beyond its inactive file cache (what a container, a Slurm job or a Ray worker may
///   take; `MemAvailable` ignores it);
/// - the kernel's `MemAvailable`.
///
/// Memory the process already holds is part of each use, so it is counted once: a check of
/// new work against this budget must not add what is already resident. `Ok(None)` where no
/// limit is known. Work that would take more stops before it starts, with an error that says
/// how much it needs, instead of being killed by the memory killer.
///
/// `$PONQ_CGROUP_DIR` names the control group's folder instead of the one found from
/// `/proc/self/cgroup` (for tests, and systems that mount it elsewhere).
///
/// # Errors
/// `$PONQ_MEMORY_LIMIT` set to something that is not a size: a setting that cannot be read
/// is an error, not a silent "no limit".
pub fn budget() -> Result<Option<Budget>, crate::Error> {
    let mut best: Option<Budget> = None;
    let mut offer = |bytes: u64, source| {
        if best.is_none_or(|b| bytes < b.bytes) {
            best = Some(Budget { bytes, source });
        }
    };
    if let Some(v) = std::env::var_os("PONQ_MEMORY_LIMIT") {
        let text = v.to_string_lossy();
        let limit = parse_size(&text).ok_or_else(|| {
            crate::Error::InvalidInput(format!(
                "PONQ_MEMORY_LIMIT={text:?} is not a size: give bytes or a number with a unit \
                 (K, M, G, T, KB..TB, KiB..TiB; e.g. 8G, 8GiB, 1.5T)"
            ))
        })?;
        offer(
            limit.saturating_sub(resident_bytes().unwrap_or(0)),
            LimitSource::Env,
        );
    }
    if let Some(b) = cgroup_headroom() {
        offer(b, LimitSource::Cgroup);
    }
    if let Some(b) = mem_available() {
        offer(b, LimitSource::System);
    }
    Ok(best)
}

/// [`budget`]'s bytes.
///
/// # Errors
/// As [`budget`].
pub fn available_bytes() -> Result<Option<u64>, crate::Error> {
    Ok(budget()?.map(|b| b.bytes))
}

/// Bytes that work running now in this process has reserved ([`reserve`]) and may not hold
/// yet: shapes of a batch run in parallel, and each checks against the same budget.
static RESERVED: std::sync::atomic::AtomicU64 = std::sync::atomic::AtomicU64::new(0);

/// Memory reserved by [`reserve`] for a piece of work, given back when dropped.
#[derive(Debug)]
pub struct Reservation(u64);

impl Drop for Reservation {
    fn drop(&mut self) {
        RESERVED.fetch_sub(self.0, std::sync::atomic::Ordering::SeqCst);
    }
}

/// Reserves `need` bytes for work about to start, or refuses it when the [`budget`] less what
/// other work of this process has reserved is short: `what` names the work in the message
/// (e.g. "the grid's values near its surface"), `hint` says what to try. Keep the returned
/// guard while the work holds its memory.
///
/// # Errors
/// Not enough memory, or a [`budget`] error.
pub fn reserve(need: u64, what: &str, hint: &str) -> Result<Reservation, crate::Error> {
    use std::sync::atomic::Ordering;
    let budget = budget()?;
    // Reserved first, then checked: two workers never both take the last bytes.
    let before = RESERVED.fetch_add(need, Ordering::SeqCst);
    let guard = Reservation(need);
    if let Some(b) = budget {
        let left = b.bytes.saturating_sub(before);
        if need > left {
            return Err(crate::Error::InvalidInput(format!(
                "not enough memory: {what} need about {} and {} is available ({}{}); {hint}",
                gb(need),
                gb(left),
                b.source,
                if before > 0 {
                    format!(
                        ", less {} that work running beside it has taken",
                        gb(before)
                    )
                } else {
                    String::new()
                }
            )));
        }
    }
    Ok(guard)
}

/// Refuses work that needs `need` more bytes than [`reserve`] can give (the check alone, for
/// work that holds its memory as soon as it starts).
///
/// # Errors
/// As [`reserve`].
pub fn check(need: u64, what: &str, hint: &str) -> Result<(), crate::Error> {
    reserve(need, what, hint).map(drop)
}

/// Gives the memory the allocator keeps after [`keep_freed_memory`] back to the system (glibc's
/// `malloc_trim`): between the shapes of a batch, so that one shape's peak does not shrink the
/// next one's [`budget`]. Does nothing on other platforms.
pub fn release_freed() {
    #[cfg(all(target_os = "linux", target_env = "gnu"))]
    // SAFETY: `malloc_trim` only returns free heap pages to the kernel; it is thread-safe.
    unsafe {
        libc::malloc_trim(0);
    }
}

/// `MemAvailable` of `/proc/meminfo`.
fn mem_available() -> Option<u64> {
    let info = std::fs::read_to_string("/proc/meminfo").ok()?;
    let line = info.lines().find(|l| l.starts_with("MemAvailable:"))?;
    let kb: u64 = line.split_whitespace().nth(1)?.parse().ok()?;
    Some(kb * 1024)
}

/// The process's resident memory (`VmRSS` of `/proc/self/status`).
fn resident_bytes() -> Option<u64> {
    let s = std::fs::read_to_string("/proc/self/status").ok()?;
    let line = s.lines().find(|l| l.starts_with("VmRSS:"))?;
    let kb: u64 = line.split_whitespace().nth(1)?.parse().ok()?;
    Some(kb * 1024)
}

/// The smallest headroom (limit less use) of the process's control group and the groups
/// above it, v2 or v1; `None` where no group has a limit.
fn cgroup_headroom() -> Option<u64> {
    let dirs: Vec<std::path::PathBuf> = match std::env::var_os("PONQ_CGROUP_DIR") {
        Some(d) => vec![d.into()],
        None => cgroup_dirs(),
    };
    dirs.iter().filter_map(|d| group_headroom(d)).min()
}

/// The memory folders of this process's groups, innermost first, up to the mount point.
fn cgroup_dirs() -> Vec<std::path::PathBuf> {
    use std::path::{Path, PathBuf};
    let Ok(text) = std::fs::read_to_string("/proc/self/cgroup") else {
        return Vec::new();
    };
    let mut out = Vec::new();
    let mut chain = |mount: &Path, rel: &str| {
        let rel = rel.trim_start_matches('/');
        let mut d: PathBuf = mount.join(rel);
        // A group namespace may show a path that is not under this mount: use the mount.
        if !d.is_dir() {
            d = mount.to_path_buf();
        }
        loop {
            out.push(d.clone());
            if d == mount || !d.pop() || !d.starts_with(mount) {
                break;
            }
        }
    };
    for line in text.lines() {
        let mut f = line.splitn(3, ':');
        let (Some(_), Some(ctrl), Some(rel)) = (f.next(), f.next(), f.next()) else {
            continue;
        };
        if ctrl.is_empty() {
            // v2 (unified), alone or beside v1 controllers (hybrid).
            for mount in ["/sys/fs/cgroup", "/sys/fs/cgroup/unified"] {
                let m = Path::new(mount);
                if m.join("cgroup.controllers").is_file() {
                    chain(m, rel);
                    break;
                }
            }
        } else if ctrl.split(',').any(|c| c == "memory") {
            chain(Path::new("/sys/fs/cgroup/memory"), rel);
        }
    }
    out
}

/// Limit less use (less the inactive file cache, which the kernel reclaims before it kills)
/// of one group's folder: v2 files `memory.max` / `memory.current`, v1
/// `memory.limit_in_bytes` / `memory.usage_in_bytes`. `None` without a limit ("max", or v1's
/// huge "unlimited" value).
fn group_headroom(dir: &std::path::Path) -> Option<u64> {
    let read = |name: &str| std::fs::read_to_string(dir.join(name)).ok();
    let num = |t: Option<String>| t.and_then(|t| t.trim().parse::<u64>().ok());
    let stat = |key: &str| {
        read("memory.stat").and_then(|t| {
            t.lines().find_map(|l| {
                let (k, v) = l.split_once(' ')?;
                (k == key).then(|| v.trim().parse::<u64>().ok()).flatten()
            })
        })
    };
    let (limit, used, cache) = if let Some(max) = read("memory.max") {
        (
            max.trim().parse::<u64>().ok()?,
            num(read("memory.current"))?,
            stat("inactive_file").unwrap_or(0),
        )
    } else {
        let limit = num(read("memory.limit_in_bytes"))?;
        if limit >= 1 << 60 {
            return None;
        }
        (
            limit,
            num(read("memory.usage_in_bytes"))?,
            stat("total_inactive_file").unwrap_or(0),
        )
    };
    Some(limit.saturating_sub(used.saturating_sub(cache)))
}

/// `123`, `64K`, `1.5G`, `8GB`, `8GiB`, `8Gi`, `2t` -> bytes (powers of 1024; `B` alone is
/// bytes). `None` for anything else.
fn parse_size(s: &str) -> Option<u64> {
    let s = s.trim();
    let split = s
        .find(|c: char| !(c.is_ascii_digit() || c == '.'))
        .unwrap_or(s.len());
    let (num, unit) = s.split_at(split);
    let unit = unit.trim().to_ascii_uppercase();
    let power = match unit.as_str() {
        "" | "B" => 0,
        "K" | "KB" | "KI" | "KIB" => 1,
        "M" | "MB" | "MI" | "MIB" => 2,
        "G" | "GB" | "GI" | "GIB" => 3,
        "T" | "TB" | "TI" | "TIB" => 4,
        _ => return None,
    };
    let v: f64 = num.parse().ok()?;
    let bytes = v * (1u64 << (10 * power)) as f64;
    (v >= 0.0 && bytes.is_finite() && bytes < u64::MAX as f64).then_some(bytes as u64)
}

/// Bytes as GB with one decimal (MB below 1 GB), for messages.
pub fn gb(bytes: u64) -> String {
    if bytes < 1 << 30 {
        format!("{:.0} MB", bytes as f64 / (1u64 << 20) as f64)
    } else {
        format!("{:.1} GB", bytes as f64 / (1u64 << 30) as f64)
    }
}

#[cfg(test)]
mod tests {
    #[test]
    fn sizes_parse() {
        assert_eq!(super::parse_size("123"), Some(123));
        assert_eq!(super::parse_size("2K"), Some(2048));
        assert_eq!(super::parse_size("1.5g"), Some(3 << 29));
        for s in ["8G", "8GB", "8Gi", "8GiB", "8 gib", "8192M", "8388608k"] {
            assert_eq!(super::parse_size(s), Some(8 << 30), "{s}");
        }
        assert_eq!(super::parse_size("1T"), Some(1 << 40));
        assert_eq!(super::parse_size("100B"), Some(100));
        for bad in ["x", "", "G", "8 GHz", "-1G", "1e3", "8..1G", "8P"] {
            assert_eq!(super::parse_size(bad), None, "{bad}");
        }
    }

    #[test]
    fn group_limits_v1_and_v2() {
        let d = std::env::temp_dir().join(format!("ponq-cgroup-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&d);
        std::fs::create_dir_all(&d).unwrap();
        std::fs::write(d.join("memory.max"), "1000000000\n").unwrap();
        std::fs::write(d.join("memory.current"), "300000000\n").unwrap();
        std::fs::write(d.join("memory.stat"), "anon 1\ninactive_file 100000000\n").unwrap();
        assert_eq!(super::group_headroom(&d), Some(800_000_000));
        std::fs::write(d.join("memory.max"), "max\n").unwrap();
        assert_eq!(super::group_headroom(&d), None);
        for f in ["memory.max", "memory.current", "memory.stat"] {
            std::fs::remove_file(d.join(f)).unwrap();
        }
        std::fs::write(d.join("memory.limit_in_bytes"), "2000000000\n").unwrap();
        std::fs::write(d.join("memory.usage_in_bytes"), "500000000\n").unwrap();
        assert_eq!(super::group_headroom(&d), Some(1_500_000_000));
        std::fs::write(d.join("memory.limit_in_bytes"), "9223372036854771712\n").unwrap();
        assert_eq!(super::group_headroom(&d), None);
        std::fs::remove_dir_all(&d).ok();
    }
}
