//! Delaunay benchmark: random points in a cube and exact lattices (all co-spherical).
//! `cargo bench -p ponq-mesh --bench delaunay_bench` (one worker, then one per rayon thread;
//! `RAYON_NUM_THREADS` sets how many).

use ponq_mesh::delaunay::Delaunay;
use std::time::Instant;

fn main() {
    let mut s = 1u64;
    let mut r = || {
        s ^= s << 13;
        s ^= s >> 7;
        s ^= s << 17;
        (s >> 11) as f64 / (1u64 << 53) as f64
    };
    let threads = rayon::current_num_threads();
    println!(
        "| input | points | tets | 1 thread (ms) | us / point | {threads} threads (ms) | us / point | deferred |"
    );
    println!("|---|---:|---:|---:|---:|---:|---:|---:|");
    let row = |name: &str, pts: &[[f64; 3]]| {
        let time = |workers: usize| {
            let mut best = f64::MAX;
            let mut tets = 0;
            let mut deferred = 0;
            for _ in 0..5 {
                let t = Instant::now();
                let dt = Delaunay::with_threads(pts, workers).expect("finite points");
                best = best.min(t.elapsed().as_secs_f64());
                tets = dt.tets.len();
                deferred = dt.stats.deferred;
            }
            (best, tets, deferred)
        };
        let (one, tets, _) = time(1);
        let (all, _, deferred) = time(threads);
        println!(
            "| {name} | {} | {tets} | {:.1} | {:.2} | {:.1} | {:.2} | {deferred} |",
            pts.len(),
            one * 1e3,
            one * 1e6 / pts.len() as f64,
            all * 1e3,
            all * 1e6 / pts.len() as f64,
        );
    };
    for n in [10_000usize, 100_000, 400_000] {
        let pts: Vec<[f64; 3]> = (0..n).map(|_| [r(), r(), r()]).collect();
        row("random in a cube", &pts);
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
        row("lattice (co-spherical)", &pts);
    }
}
