//! Delaunay benchmark: random points in a cube, exact lattices (all co-spherical) and the
//! points the mesher triangulates for a real PoNQ (the shipped example's PoNQ at 64^3, if
//! present: its v* and the corners of the protective box, `mesher::delaunay_points`; and its
//! v* alone, whose convex hull is the part's own).
//!
//! ```sh
//! cargo bench -p ponq-mesh --bench delaunay_bench                     # the built-in sets
//! cargo bench -p ponq-mesh --bench delaunay_bench -- --write DIR      # also write them as DIR/*.f64
//! cargo bench -p ponq-mesh --bench delaunay_bench -- A.f64 B.npz      # point files instead
//! ponq-mesh/benches/cgal/side_by_side.sh                              # the same points in CGAL
//! ```
//!
//! One worker, then one per rayon thread (`RAYON_NUM_THREADS` sets how many); best of 5
//! (`--runs`). Each is timed as a whole and by its insertion stage alone
//! (`DelaunayStats::times`: without the Hilbert ordering and the canonical output).
//! A `.npz` file is a PoNQ (the mesher's points for it are triangulated, or its v* alone with
//! `--vstars-only`); any other point file is raw
//! little-endian `f64` x, y, z triples (what `--write` writes and
//! `benches/cgal/delaunay_cgal.cpp` reads).

#[path = "util/args.rs"]
mod args;

use anyhow::{Context, Result, ensure};
use ponq_mesh::delaunay::{Delaunay, DelaunayStats};
use ponq_mesh::mesher::{MeshingOptions, delaunay_points};
use ponq_mesh::ponq::Ponq;
use std::path::{Path, PathBuf};
use std::time::Instant;

/// The points the mesher triangulates for a PoNQ ([`delaunay_points`], the default domain
/// `[-1, 1]^3`), or its v* alone.
fn ponq_points(ponq: &Ponq, vstars_only: bool) -> Vec<[f64; 3]> {
    let v = ponq.vstars();
    if vstars_only {
        v
    } else {
        delaunay_points(&v, &MeshingOptions::default())
    }
}

/// Named point sets.
type Sets = Vec<(String, Vec<[f64; 3]>)>;

/// The built-in point sets, and the PoNQ they read (kept until the end, see [`read_points`]).
fn built_in_sets() -> (Sets, Vec<Ponq>) {
    let mut s = 1u64;
    let mut r = || {
        s ^= s << 13;
        s ^= s >> 7;
        s ^= s << 17;
        (s >> 11) as f64 / (1u64 << 53) as f64
    };
    let mut sets = Vec::new();
    let mut ponqs = Vec::new();
    for n in [10_000usize, 100_000, 400_000] {
        let pts: Vec<[f64; 3]> = (0..n).map(|_| [r(), r(), r()]).collect();
        sets.push((format!("random_{n}"), pts));
    }
    for m in [30usize, 47] {
        let mut pts = Vec::new();
        for i in 0..m {
            for j in 0..m {
                for k in 0..m {
                    pts.push([i as f64 * 0.1, j as f64 * 0.1, k as f64 * 0.1]);
                }
            }
        }
        sets.push((format!("lattice_{}", pts.len()), pts));
    }
    let ponq = Path::new(env!("CARGO_MANIFEST_DIR")).join("../examples/example001_ponq_64.npz");
    match ponq_mesh::io::npz::read_ponq(&ponq) {
        Ok(p) => {
            let v = ponq_points(&p, false);
            sets.push((format!("ponq_example001_64_box_{}", v.len()), v));
            let v = ponq_points(&p, true);
            sets.push((format!("ponq_example001_64_vstars_{}", v.len()), v));
            ponqs.push(p);
        }
        Err(e) => eprintln!("skipping the PoNQ set ({}): {e}", ponq.display()),
    }
    (sets, ponqs)
}

/// Reads a raw point file straight into the points (no byte buffer freed before the timed
/// calls, whose tet arena could reuse it: the first call's arena is fresh memory, as in a
/// `ponq-mesh` run).
fn read_points(path: &Path) -> Result<Vec<[f64; 3]>> {
    use std::io::Read;
    let mut file = std::fs::File::open(path)
        .with_context(|| format!("cannot read point file {}", path.display()))?;
    let len = file
        .metadata()
        .with_context(|| format!("cannot read point file {}", path.display()))?
        .len();
    ensure!(
        len.is_multiple_of(24),
        "{}: not a whole number of f64 triples",
        path.display()
    );
    let mut pts = vec![[0.0f64; 3]; (len / 24) as usize];
    file.read_exact(bytemuck::cast_slice_mut(&mut pts))
        .with_context(|| format!("cannot read point file {}", path.display()))?;
    for x in pts.iter_mut().flatten() {
        *x = f64::from_bits(u64::from_le(x.to_bits()));
    }
    Ok(pts)
}

fn write_points(path: &Path, pts: &[[f64; 3]]) -> Result<()> {
    let bytes: Vec<u8> = pts
        .iter()
        .flat_map(|p| p.iter().flat_map(|c| c.to_le_bytes()))
        .collect();
    std::fs::write(path, bytes).with_context(|| format!("cannot write {}", path.display()))
}

const USAGE: &str = "\
Delaunay alone: one worker, then one per rayon thread (RAYON_NUM_THREADS), best of 5 (--runs).

usage: cargo bench -p ponq-mesh --bench delaunay_bench -- [--write DIR] [--keep-freed-memory]
         [--vstars-only] [--runs N] [FILE ...]

  FILE         a point file (raw little-endian f64 x, y, z triples) or a PoNQ .npz (the points
               the mesher triangulates for it: its v* and the 8 corners of the protective box
               around the domain [-1, 1]^3); without files: random points (10k, 100k, 400k),
               lattices (30^3, 47^3) and the example PoNQ's points, with the box and without.
               Cargo runs benches in the package folder: give absolute paths.
  --vstars-only
               a PoNQ .npz's v* alone, without the box: their convex hull is then the part's
               own, with flat faces on CAD parts (the mesher never triangulates these points;
               a library user of Delaunay::new may)
  --write DIR  also write the point sets as DIR/NAME.f64 (for CGAL and HXT: benches/cgal)
  --runs N     time each set N times on one worker and N times on all, print the best of
               each (default 5); --runs 1 in a new process times the first call alone, whose
               tet arena is fresh memory from the system (as in a ponq-mesh run)
  --keep-freed-memory
               the allocator setting of the ponq-* programs (ponq_mesh::memory): freed blocks
               up to 32 MiB are kept for the next allocation, so the runs after the first reuse
               memory instead of taking fresh pages (each costs a page fault on first touch,
               about 1.6 us per 4 KB page on this machine); without it glibc decides by size
  -h, --help   this text

Columns: tets, time and microseconds per point on one and on all threads (the whole call, and
its insertion stage alone: without the ordering before it and the canonical output after it,
see DelaunayStats::times; best of the runs each), the ordering and output stages on all
threads (best of the runs each), insertions that backed off and vertices left to the final
one-thread pass (\"stopped\": the workers stopped early, too many backed off).";

fn main() -> Result<()> {
    let args = args::parse(
        USAGE,
        &["--write", "--keep-freed-memory", "--vstars-only", "--runs"],
    );
    let mut runs = 5usize;
    let mut write_dir: Option<PathBuf> = None;
    let mut vstars_only = false;
    let mut files = Vec::new();
    let mut it = args.iter();
    while let Some(a) = it.next() {
        if a == "--keep-freed-memory" {
            ponq_mesh::memory::keep_freed_memory();
        } else if a == "--vstars-only" {
            vstars_only = true;
        } else if a == "--runs" {
            match it.next().map(|n| n.parse::<usize>()) {
                Some(Ok(n)) if n >= 1 => runs = n,
                _ => {
                    eprintln!("error: --runs needs a whole number of at least 1\n\n{USAGE}");
                    std::process::exit(2);
                }
            }
        } else if a == "--write" {
            match it.next() {
                Some(dir) => write_dir = Some(PathBuf::from(dir)),
                None => {
                    eprintln!("error: --write needs a folder\n\n{USAGE}");
                    std::process::exit(2);
                }
            }
        } else {
            files.push(PathBuf::from(a));
        }
    }
    // The PoNQs stay until the end, as in a `ponq-mesh` run (freed, their memory would serve
    // the first call's tet arena).
    let (sets, _ponqs): (Sets, Vec<Ponq>) = if files.is_empty() {
        built_in_sets()
    } else {
        let mut ponqs = Vec::new();
        let sets = files
            .iter()
            .map(|f| {
                let pts = if f.extension().is_some_and(|e| e == "npz") {
                    let ponq = ponq_mesh::io::npz::read_ponq(f)
                        .with_context(|| format!("cannot read {}", f.display()))?;
                    let pts = ponq_points(&ponq, vstars_only);
                    ponqs.push(ponq);
                    pts
                } else {
                    read_points(f)?
                };
                Ok((f.display().to_string(), pts))
            })
            .collect::<Result<_>>()?;
        (sets, ponqs)
    };
    if let Some(dir) = &write_dir {
        std::fs::create_dir_all(dir)
            .with_context(|| format!("cannot create the --write folder {}", dir.display()))?;
        for (name, pts) in &sets {
            write_points(&dir.join(format!("{name}.f64")), pts)?;
        }
    }
    let threads = rayon::current_num_threads();
    println!(
        "| input | points | tets | 1 thread (ms) | us / point | insertion only | {threads} threads (ms) | us / point | insertion only | ordering / output (ms) | backed off / deferred |"
    );
    println!("|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|");
    for (name, pts) in &sets {
        // The best whole call and, apart, the best of each stage, of `runs` (seconds: whole
        // call, ordering, insertion, output).
        let time = |workers: usize| -> Result<_> {
            let mut best = [f64::MAX; 4];
            let mut tets = 0;
            let mut stats = DelaunayStats::default();
            for _ in 0..runs {
                let t = Instant::now();
                let dt = Delaunay::with_threads(pts, workers)
                    .with_context(|| format!("cannot triangulate {name}"))?;
                let s = dt.stats.times;
                let run = [t.elapsed(), s.ordering, s.insertion, s.output];
                for (b, r) in best.iter_mut().zip(run) {
                    *b = b.min(r.as_secs_f64());
                }
                tets = dt.tets.len();
                stats = dt.stats;
            }
            Ok((best, tets, stats))
        };
        let ([one, _, one_insertion, _], tets, _) = time(1)?;
        let ([all, ordering, all_insertion, output], _, stats) = time(threads)?;
        let per_point = |s: f64| s * 1e6 / pts.len() as f64;
        let stopped = if stats.parallel_stopped {
            " (stopped)"
        } else {
            ""
        };
        println!(
            "| {name} | {} | {tets} | {:.1} | {:.2} | {:.2} | {:.1} | {:.2} | {:.2} | {:.1} / {:.1} | {} / {}{stopped} |",
            pts.len(),
            one * 1e3,
            per_point(one),
            per_point(one_insertion),
            all * 1e3,
            per_point(all),
            per_point(all_insertion),
            ordering * 1e3,
            output * 1e3,
            stats.backed_off,
            stats.deferred,
        );
    }
    Ok(())
}
