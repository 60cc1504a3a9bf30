//! Scale tests of `ponq_mesh::validity` on tori.
//!
//! The 200k-face timing test is ignored by default; run it with
//! `cargo test -p ponq-mesh --release --test validity_perf -- --ignored --nocapture`.

use std::time::Instant;

use ponq_mesh::TriMesh;
use ponq_mesh::validity::{check, check_topology, intersecting_face_pairs};

/// Closed torus with `nu * nv` quads split into `2 * nu * nv` consistently oriented triangles.
fn torus(nu: usize, nv: usize, big_r: f64, r: f64) -> TriMesh {
    let mut vertices = Vec::with_capacity(nu * nv);
    for i in 0..nu {
        let u = i as f64 / nu as f64 * std::f64::consts::TAU;
        for j in 0..nv {
            let v = j as f64 / nv as f64 * std::f64::consts::TAU;
            let rr = big_r + r * v.cos();
            vertices.push([rr * u.cos(), rr * u.sin(), r * v.sin()]);
        }
    }
    let id = |i: usize, j: usize| ((i % nu) * nv + j % nv) as u32;
    let mut faces = Vec::with_capacity(2 * nu * nv);
    for i in 0..nu {
        for j in 0..nv {
            let (a, b, c, d) = (id(i, j), id(i + 1, j), id(i + 1, j + 1), id(i, j + 1));
            faces.push([a, b, c]);
            faces.push([a, c, d]);
        }
    }
    TriMesh::new(vertices, faces).unwrap()
}

/// Appends a small axis-aligned box (12 triangles) centred at `c` with half size `h`.
fn add_box(m: &mut TriMesh, c: [f64; 3], h: f64) {
    let base = m.vertices.len() as u32;
    for k in 0..8 {
        m.vertices.push([
            c[0] + if k & 1 == 0 { -h } else { h },
            c[1] + if k & 2 == 0 { -h } else { h },
            c[2] + if k & 4 == 0 { -h } else { h },
        ]);
    }
    let quads = [
        [0, 2, 3, 1],
        [4, 5, 7, 6],
        [0, 1, 5, 4],
        [2, 6, 7, 3],
        [0, 4, 6, 2],
        [1, 3, 7, 5],
    ];
    for q in quads {
        m.faces.push([base + q[0], base + q[1], base + q[2]]);
        m.faces.push([base + q[0], base + q[2], base + q[3]]);
    }
}

#[test]
fn torus_is_valid_and_box_crossing_it_is_found() {
    let mut m = torus(120, 40, 1.0, 0.3);
    let r = check(&m);
    assert!(r.is_valid(), "{r}");
    let n = m.faces.len();
    // A box straddling the tube surface at (1.3, 0, 0).
    add_box(&mut m, [1.3, 0.0, 0.0], 0.05);
    let r = check(&m);
    assert!(r.closed && r.oriented && r.manifold, "{r}");
    assert!(r.self_intersections > 0);
    let pairs = intersecting_face_pairs(&m);
    assert_eq!(pairs.len(), r.self_intersections);
    assert!(pairs.iter().all(|&(i, j)| i < n && j >= n));
}

#[test]
#[ignore = "timing; run in release"]
fn torus_200k_timing() {
    let m = torus(500, 200, 1.0, 0.3);
    assert_eq!(m.faces.len(), 200_000);
    for _ in 0..3 {
        let t = Instant::now();
        let topo = check_topology(&m);
        let t_topo = t.elapsed();
        let t = Instant::now();
        let r = check(&m);
        let t_full = t.elapsed();
        assert!(topo.is_valid() && r.is_valid(), "{r}");
        println!(
            "200k-face torus: check_topology {:.1} ms, check {:.1} ms ({} threads)",
            t_topo.as_secs_f64() * 1e3,
            t_full.as_secs_f64() * 1e3,
            rayon::current_num_threads()
        );
    }
    let m = torus(1000, 500, 1.0, 0.3);
    let t = Instant::now();
    let r = check(&m);
    println!(
        "1M-face torus: check {:.1} ms: {r}",
        t.elapsed().as_secs_f64() * 1e3
    );
    assert!(r.is_valid());
}
