//! Timing of `ponq_mesh::maxflow` on large PoNQ-like graphs (no assertion on time).
//!
//! Run with `cargo test -p ponq-mesh --release --test maxflow_timing -- --ignored --nocapture`.

use ponq_mesh::maxflow::{Graph, Segment};
use rand::seq::SliceRandom;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use std::time::Instant;

const INF: f64 = f64::INFINITY;

/// An `s^3` lattice where every node has degree 4 (like the dual of a tetrahedralisation):
/// `(x, y, z) - (x + 1, y, z)`, and `(x, y, z) - (x, y + 1, z)` if `x + y + z` is even,
/// `(x, y, z) - (x, y, z + 1)` if it is odd.
struct Lattice {
    s: usize,
    edges: Vec<(usize, usize, f64, f64)>,
    tweights: Vec<(f64, f64)>,
}

/// `terminals`: `true` -> infinite source / sink seeds inside / outside a sphere with a band of
/// free nodes between (PoNQ); `false` -> finite random data terms everywhere (vision).
fn lattice(s: usize, terminals: bool, seed: u64) -> Lattice {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let id = |x: usize, y: usize, z: usize| x + s * (y + s * z);
    let mut edges = Vec::with_capacity(2 * s * s * s);
    let mut tweights = Vec::with_capacity(s * s * s);
    let c = (s as f64 - 1.0) / 2.0;
    let r = 0.35 * s as f64;
    for z in 0..s {
        for y in 0..s {
            for x in 0..s {
                let v = id(x, y, z);
                if x + 1 < s {
                    let w = rng.random_range(0.0..1.0);
                    edges.push((v, id(x + 1, y, z), w, w));
                }
                if (x + y + z) % 2 == 0 {
                    if y + 1 < s {
                        let w = rng.random_range(0.0..1.0);
                        edges.push((v, id(x, y + 1, z), w, w));
                    }
                } else if z + 1 < s {
                    let w = rng.random_range(0.0..1.0);
                    edges.push((v, id(x, y, z + 1), w, w));
                }
                if terminals {
                    let d =
                        ((x as f64 - c).powi(2) + (y as f64 - c).powi(2) + (z as f64 - c).powi(2))
                            .sqrt();
                    if d < r - 3.0 {
                        tweights.push((INF, 0.0));
                    } else if d > r + 3.0 {
                        tweights.push((0.0, INF));
                    } else {
                        tweights.push((0.0, 0.0));
                    }
                } else {
                    tweights.push((rng.random_range(0.0..2.0), rng.random_range(0.0..2.0)));
                }
            }
        }
    }
    Lattice { s, edges, tweights }
}

fn run(name: &str, l: &Lattice, permute: bool) {
    let n = l.s * l.s * l.s;
    let mut perm: Vec<usize> = (0..n).collect();
    if permute {
        perm.shuffle(&mut ChaCha8Rng::seed_from_u64(1));
    }
    let t0 = Instant::now();
    let mut g = Graph::new(n, l.edges.len());
    for (v, &(cs, ct)) in l.tweights.iter().enumerate() {
        g.add_tweights(perm[v], cs, ct);
    }
    for &(i, j, c, r) in &l.edges {
        g.add_edge(perm[i], perm[j], c, r);
    }
    let t1 = Instant::now();
    let f = g.maxflow();
    let t2 = Instant::now();

    // The cut must be a minimum cut.
    let seg: Vec<Segment> = (0..n).map(|v| g.segment(perm[v])).collect();
    let mut cut = 0.0;
    for (v, &(cs, ct)) in l.tweights.iter().enumerate() {
        cut += if seg[v] == Segment::Source { ct } else { cs };
    }
    for &(i, j, c, r) in &l.edges {
        match (seg[i], seg[j]) {
            (Segment::Source, Segment::Sink) => cut += c,
            (Segment::Sink, Segment::Source) => cut += r,
            _ => {}
        }
    }
    let n_src = seg.iter().filter(|&&s| s == Segment::Source).count();
    println!(
        "{name}{}: {n} nodes, {} edges: build {:.3} s, maxflow {:.3} s, flow {f:.6}, cut {cut:.6}, {n_src} source nodes",
        if permute { " (random node order)" } else { "" },
        l.edges.len(),
        (t1 - t0).as_secs_f64(),
        (t2 - t1).as_secs_f64(),
    );
    assert!((f - cut).abs() <= 1e-9 * f.abs().max(1.0));
}

#[test]
#[ignore = "timing; run with --release -- --ignored --nocapture"]
fn timing_500k_degree4() {
    let l = lattice(80, true, 1);
    run("PoNQ-like lattice, infinite seeds + band", &l, false);
    run("PoNQ-like lattice, infinite seeds + band", &l, true);
    let l = lattice(80, false, 2);
    run("vision-like lattice, finite data terms", &l, false);
    run("vision-like lattice, finite data terms", &l, true);
}
