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

/// The memory this process may still take, in bytes: `$PONQ_MEMORY_LIMIT` when set (bytes,
/// or a number with a `K`, `M` or `G` suffix, powers of 1024), else the kernel's estimate of
/// the memory available without swapping (`MemAvailable` in `/proc/meminfo`); `None` where
/// neither is known. Work that would take more stops before it starts, with an error that
/// says how much it needs, instead of being killed by the system's memory killer.
pub fn available_bytes() -> Option<u64> {
    if let Some(v) = std::env::var_os("PONQ_MEMORY_LIMIT") {
        return parse_size(&v.to_string_lossy());
    }
    let info = std::fs::read_to_string("/proc/meminfo").ok()?;
    let line = info.lines().find(|l| l.starts_with("MemAvailable:"))?;
    let kb: u64 = line.split_whitespace().nth(1)?.parse().ok()?;
    Some(kb * 1024)
}

/// `123`, `64K`, `1.5G` -> bytes.
fn parse_size(s: &str) -> Option<u64> {
    let s = s.trim();
    let (num, mult) = match s.chars().last()?.to_ascii_uppercase() {
        'K' => (&s[..s.len() - 1], 1u64 << 10),
        'M' => (&s[..s.len() - 1], 1 << 20),
        'G' => (&s[..s.len() - 1], 1 << 30),
        _ => (s, 1),
    };
    let v: f64 = num.trim().parse().ok()?;
    (v >= 0.0 && v.is_finite()).then_some((v * mult as f64) as u64)
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
        assert_eq!(super::parse_size("x"), None);
    }
}
