//! SDF grid benchmark: time of `signed_distance_grid` at 33^3, 65^3 and 129^3 nodes for a
//! ~10k-face and a ~100k-face mesh, and the speed of surface sampling.
//!
//! `cargo bench -p ponq-data --bench sdf_bench` prints a table. Meshes: the shipped
//! `examples/csg.obj` subdivided once (12k faces) and `examples/example001.obj` subdivided three
//! times (81k faces), 4:1 midpoint subdivision; `../shared/data/bunny.obj` and the FreeCAD
//! drilling plate (28k faces, and subdivided once, 112k faces) when present.
//! Extra mesh files given after `--` are added (normalised to the [-1,1] frame); `--only S`
//! keeps the meshes whose name contains `S`, `--res N` computes only `(N+1)^3` grids.

use std::path::Path;
use std::time::Instant;

use ponq_data::normalize::Normalization;
use ponq_data::sdf::MeshSdf;
use ponq_mesh::sampling::sample_surface;
use ponq_mesh::{TriMesh, io};

/// 4:1 midpoint subdivision (shared edge midpoints are shared vertices).
fn subdivide(m: &TriMesh) -> TriMesh {
    let mut v = m.vertices.clone();
    let mut mids = std::collections::HashMap::new();
    let mut mid = |a: u32, b: u32, v: &mut Vec<[f64; 3]>| -> u32 {
        *mids.entry((a.min(b), a.max(b))).or_insert_with(|| {
            let (p, q) = (v[a as usize], v[b as usize]);
            v.push([
                0.5 * (p[0] + q[0]),
                0.5 * (p[1] + q[1]),
                0.5 * (p[2] + q[2]),
            ]);
            (v.len() - 1) as u32
        })
    };
    let mut f = Vec::with_capacity(4 * m.faces.len());
    for &[a, b, c] in &m.faces {
        let (ab, bc, ca) = (mid(a, b, &mut v), mid(b, c, &mut v), mid(c, a, &mut v));
        f.extend_from_slice(&[[a, ab, ca], [ab, b, bc], [ca, bc, c], [ab, bc, ca]]);
    }
    TriMesh {
        vertices: v,
        faces: f,
    }
}

fn load(path: &Path) -> Option<TriMesh> {
    if !path.exists() {
        eprintln!("skipping {} (missing)", path.display());
        return None;
    }
    match io::read_mesh(path) {
        Ok(m) => Some(Normalization::of(&m).ok()?.apply_mesh(&m)),
        Err(e) => {
            eprintln!("skipping {}: {e}", path.display());
            None
        }
    }
}

/// CPU time of this process in seconds (user + system, all threads; Linux `/proc`), NaN
/// elsewhere. Reported next to wall times because this machine's 2 cores are shared.
fn cpu_time() -> f64 {
    let Ok(s) = std::fs::read_to_string("/proc/self/stat") else {
        return f64::NAN;
    };
    // Fields after the command name (which is in parentheses and may hold spaces).
    let Some(rest) = s.rfind(')').map(|i| &s[i + 2..]) else {
        return f64::NAN;
    };
    let f: Vec<&str> = rest.split_whitespace().collect();
    let tick = |i: usize| {
        f.get(i)
            .and_then(|x| x.parse::<f64>().ok())
            .unwrap_or(f64::NAN)
    };
    // utime and stime are fields 14 and 15 of the full line (11 and 12 after the name);
    // clock ticks are 1/100 s on Linux.
    (tick(11) + tick(12)) / 100.0
}

fn row(name: &str, m: &TriMesh, resolutions: &[usize]) {
    let t = Instant::now();
    let sdf = MeshSdf::new(m).expect("mesh");
    let build = t.elapsed().as_secs_f64();
    let mut cells = Vec::new();
    let mut open = false;
    for &res in resolutions {
        // Best of 2 below 129^3 (the first run warms up), one run at 129^3.
        let runs = if res < 128 { 2 } else { 1 };
        let mut best = (f64::INFINITY, f64::INFINITY);
        for _ in 0..runs {
            let (t, c) = (Instant::now(), cpu_time());
            let g = sdf.grid(res, |_| {}).expect("grid");
            let wall = t.elapsed().as_secs_f64();
            if wall < best.0 {
                best = (wall, cpu_time() - c);
            }
            open = g.open;
        }
        cells.push(best);
    }
    let t = Instant::now();
    let n = 1_000_000;
    let s = sample_surface(m, n, 1);
    let sps = s.points.len() as f64 / t.elapsed().as_secs_f64();
    let c = |i: usize| {
        cells
            .get(i)
            .map_or(String::from("-"), |(w, c)| format!("{w:.3} ({c:.2})"))
    };
    println!(
        "{:<22} {:>7} {:>6.3} {:>14} {:>14} {:>14} {:>10.2} {:>4}",
        name,
        m.faces.len(),
        build,
        c(0),
        c(1),
        c(2),
        sps / 1e6,
        if open { "yes" } else { "no" }
    );
}

fn main() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("..");
    let shared = root.join("../shared/data");
    let mut meshes: Vec<(String, TriMesh)> = Vec::new();
    if let Some(m) = load(&root.join("examples/csg.obj")) {
        meshes.push(("csg.obj x4".into(), subdivide(&m)));
    }
    if let Some(m) = load(&shared.join("bunny.obj")) {
        meshes.push(("bunny.obj".into(), m));
    }
    let plate = shared.join("meshes/cad/freecad_fcstd/fcstd_drilling_plate_final.obj");
    let plate = load(&plate);
    if let Some(m) = &plate {
        meshes.push(("drilling_plate".into(), m.clone()));
    }
    if let Some(m) = load(&root.join("examples/example001.obj")) {
        meshes.push((
            "example001.obj x64".into(),
            subdivide(&subdivide(&subdivide(&m))),
        ));
    }
    if let Some(m) = &plate {
        meshes.push(("drilling_plate x4".into(), subdivide(m)));
    }
    let args: Vec<String> = std::env::args().skip(1).collect();
    let mut only = None;
    let mut resolutions = vec![32, 64, 128];
    let mut i = 0;
    while i < args.len() {
        match args[i].as_str() {
            "--only" => {
                only = args.get(i + 1).cloned();
                i += 1;
            }
            "--res" => {
                let r = args
                    .get(i + 1)
                    .and_then(|r| r.parse().ok())
                    .expect("--res N");
                resolutions = vec![r];
                i += 1;
            }
            a if a.starts_with('-') => {} // cargo's own flags (--bench)
            a => {
                if let Some(m) = load(Path::new(a)) {
                    meshes.push((a.to_string(), m));
                }
            }
        }
        i += 1;
    }
    if let Some(o) = &only {
        meshes.retain(|(n, _)| n.contains(o.as_str()));
    }
    println!(
        "SDF grids: wall seconds (CPU seconds, all {} threads); surface sampling (1M samples)",
        rayon::current_num_threads()
    );
    println!(
        "{:<22} {:>7} {:>6} {:>14} {:>14} {:>14} {:>10} {:>4}",
        "mesh", "faces", "build", "33^3", "65^3", "129^3", "Msample/s", "open"
    );
    for (name, m) in &meshes {
        row(name, m, &resolutions);
    }
}
