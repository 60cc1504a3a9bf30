//! Properties of the exact Delaunay tetrahedralisation on random, degenerate and lattice inputs.

use ponq_mesh::delaunay::{Delaunay, DelaunayOptions, NONE};
use ponq_mesh::predicates::{insphere, orient3d};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

fn vol6(a: &[f64; 3], b: &[f64; 3], c: &[f64; 3], d: &[f64; 3]) -> f64 {
    let u = [b[0] - a[0], b[1] - a[1], b[2] - a[2]];
    let v = [c[0] - a[0], c[1] - a[1], c[2] - a[2]];
    let w = [d[0] - a[0], d[1] - a[1], d[2] - a[2]];
    u[0] * (v[1] * w[2] - v[2] * w[1]) - u[1] * (v[0] * w[2] - v[2] * w[0])
        + u[2] * (v[0] * w[1] - v[1] * w[0])
}

/// The face of `nb` that `t` is behind (adjacency must be symmetric).
fn back_index(dt: &Delaunay, t: usize, nb: u32) -> usize {
    dt.neighbors[nb as usize]
        .iter()
        .position(|&x| x as usize == t)
        .expect("neighbour relation is symmetric")
}

/// Structural checks; returns the total volume.
/// A cavity too large for the local-number map (more than 32 boundary vertices) is linked
/// through the directed-edge table: the centre of many co-spherical points conflicts with
/// every tet made before it, so its cavity is everything inserted so far.
#[test]
fn large_cavities_are_linked_too() {
    let mut pts = Vec::new();
    let n = 600;
    for i in 0..n {
        // A Fibonacci sphere: well spread, all at distance 1 from the centre (up to rounding;
        // exact co-sphericity is not needed, only that the centre is inside every sphere).
        let z = 1.0 - (2 * i + 1) as f64 / n as f64;
        let r = (1.0 - z * z).sqrt();
        let a = i as f64 * 2.399_963_229_728_653;
        pts.push([r * a.cos(), r * a.sin(), z]);
    }
    pts.push([0.0, 0.0, 0.0]);
    for threads in [1, 2] {
        let dt = Delaunay::with_threads(&pts, threads).unwrap();
        assert!(
            dt.stats.large_cavities >= 1,
            "no large cavity: {:?}",
            dt.stats
        );
        check_structure(&dt);
        check_empty_spheres(&dt);
    }
}

fn check_structure(dt: &Delaunay) -> f64 {
    let p = |v: u32| &dt.vertices[v as usize];
    let mut vol = 0.0;
    for (t, tv) in dt.tets.iter().enumerate() {
        assert_eq!(
            orient3d(p(tv[0]), p(tv[1]), p(tv[2]), p(tv[3])),
            1,
            "tet {t} not positively oriented"
        );
        vol += vol6(p(tv[0]), p(tv[1]), p(tv[2]), p(tv[3])) / 6.0;
        for k in 0..4 {
            let nb = dt.neighbors[t][k];
            if nb == NONE {
                continue;
            }
            let back = back_index(dt, t, nb);
            let mut f1: Vec<u32> = (0..4).filter(|&j| j != k).map(|j| tv[j]).collect();
            let nv = dt.tets[nb as usize];
            let mut f2: Vec<u32> = (0..4).filter(|&j| j != back).map(|j| nv[j]).collect();
            f1.sort();
            f2.sort();
            assert_eq!(f1, f2, "neighbours {t} and {nb} do not share the face");
            assert_ne!(tv[k], nv[back], "the apexes of a face must differ");
        }
    }
    vol
}

/// No vertex strictly inside any circumsphere (brute force).
fn check_empty_spheres(dt: &Delaunay) {
    let p = |v: u32| &dt.vertices[v as usize];
    for tv in &dt.tets {
        for (i, q) in dt.vertices.iter().enumerate() {
            if tv.contains(&(i as u32)) {
                continue;
            }
            assert!(
                insphere(p(tv[0]), p(tv[1]), p(tv[2]), p(tv[3]), q) <= 0,
                "vertex {i} inside the circumsphere of {tv:?}"
            );
        }
    }
}

/// The `m`^3 lattice `step * (i, j, k)`, `i` slowest.
fn lattice(m: usize, step: f64) -> Vec<[f64; 3]> {
    let mut pts = Vec::with_capacity(m * m * m);
    for i in 0..m {
        for j in 0..m {
            for k in 0..m {
                pts.push([i as f64 * step, j as f64 * step, k as f64 * step]);
            }
        }
    }
    pts
}

fn hull_box_volume(pts: &[[f64; 3]]) -> f64 {
    let mut lo = [f64::MAX; 3];
    let mut hi = [f64::MIN; 3];
    for p in pts {
        for k in 0..3 {
            lo[k] = lo[k].min(p[k]);
            hi[k] = hi[k].max(p[k]);
        }
    }
    (hi[0] - lo[0]) * (hi[1] - lo[1]) * (hi[2] - lo[2])
}

fn cube_corners() -> Vec<[f64; 3]> {
    let mut v = Vec::new();
    for i in 0..8 {
        v.push([
            if i & 1 == 0 { -1.0 } else { 1.0 },
            if i & 2 == 0 { -1.0 } else { 1.0 },
            if i & 4 == 0 { -1.0 } else { 1.0 },
        ]);
    }
    v
}

#[test]
fn random_points_in_a_box_fill_the_box() {
    let mut rng = ChaCha8Rng::seed_from_u64(1);
    for n in [0usize, 1, 5, 50, 400] {
        let mut pts = cube_corners();
        for _ in 0..n {
            pts.push([
                rng.random_range(-1.0..1.0),
                rng.random_range(-1.0..1.0),
                rng.random_range(-1.0..1.0),
            ]);
        }
        let dt = Delaunay::new(&pts).unwrap();
        let vol = check_structure(&dt);
        assert!((vol - 8.0).abs() < 1e-9, "n={n}: volume {vol}");
        check_empty_spheres(&dt);
    }
}

#[test]
fn lattice_is_triangulated_without_flat_tets() {
    // 6^3 lattice: every cell's 8 corners are co-spherical.
    let pts = lattice(6, 0.2);
    let dt = Delaunay::new(&pts).unwrap();
    let vol = check_structure(&dt);
    assert!((vol - hull_box_volume(&pts)).abs() < 1e-9, "volume {vol}");
    check_empty_spheres(&dt);
    // Every vertex is used.
    let mut used = vec![false; dt.vertices.len()];
    for t in &dt.tets {
        for &v in t {
            used[v as usize] = true;
        }
    }
    assert!(used.iter().all(|&u| u));
}

#[test]
fn duplicates_are_merged() {
    let mut pts = cube_corners();
    pts.push([0.1, 0.2, 0.3]);
    pts.push([0.1, 0.2, 0.3]);
    pts.push([-1.0, -1.0, -1.0]);
    let dt = Delaunay::new(&pts).unwrap();
    assert_eq!(dt.vertices.len(), 9);
    assert_eq!(dt.vertex_of_point[9], dt.vertex_of_point[8]);
    assert_eq!(dt.vertex_of_point[10], dt.vertex_of_point[0]);
    let vol = check_structure(&dt);
    assert!((vol - 8.0).abs() < 1e-9);
}

#[test]
fn signed_zeros_are_one_position() {
    // -0.0 == 0.0: these are duplicates even with other points sorting between them.
    let mut pts = cube_corners();
    pts.push([0.0, 0.2, -0.5]);
    pts.push([-0.0, 0.1, 0.5]);
    pts.push([-0.0, 0.2, -0.5]);
    pts.push([0.0, -0.0, 0.0]);
    pts.push([-0.0, 0.0, -0.0]);
    let dt = Delaunay::new(&pts).unwrap();
    assert_eq!(dt.vertices.len(), 11);
    assert_eq!(dt.vertex_of_point[10], dt.vertex_of_point[8]);
    assert_eq!(dt.vertex_of_point[12], dt.vertex_of_point[11]);
    let vol = check_structure(&dt);
    assert!((vol - 8.0).abs() < 1e-9);
}

#[test]
fn degenerate_inputs_give_no_tets() {
    // Coplanar points, collinear points, fewer than 4 points.
    let coplanar: Vec<[f64; 3]> = (0..30)
        .map(|i| [(i % 6) as f64, (i / 6) as f64, 2.0])
        .collect();
    for pts in [
        coplanar,
        (0..10).map(|i| [i as f64, 2.0 * i as f64, 0.5]).collect(),
        vec![[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]],
        vec![],
    ] {
        let dt = Delaunay::new(&pts).unwrap();
        assert!(dt.tets.is_empty());
    }
    assert!(Delaunay::new(&[[f64::NAN, 0.0, 0.0]]).is_err());
}

#[test]
fn cospherical_points_on_a_sphere() {
    // Points exactly on the unit sphere along axes and diagonals of a cube (co-spherical).
    let s = 1.0 / 3f64.sqrt();
    let mut pts = vec![
        [1.0, 0.0, 0.0],
        [-1.0, 0.0, 0.0],
        [0.0, 1.0, 0.0],
        [0.0, -1.0, 0.0],
        [0.0, 0.0, 1.0],
        [0.0, 0.0, -1.0],
    ];
    for c in cube_corners() {
        pts.push([c[0] * s, c[1] * s, c[2] * s]);
    }
    pts.push([0.0, 0.0, 0.0]);
    let dt = Delaunay::new(&pts).unwrap();
    check_structure(&dt);
    check_empty_spheres(&dt);
}

#[test]
fn larger_random_set_structure() {
    let mut rng = ChaCha8Rng::seed_from_u64(7);
    let mut pts = cube_corners();
    // Points on a sphere and a grid-snapped cloud: many exact ties.
    for _ in 0..3000 {
        let p: [f64; 3] = [
            (rng.random_range(-8i32..=8) as f64) / 8.0,
            (rng.random_range(-8i32..=8) as f64) / 8.0,
            (rng.random_range(-8i32..=8) as f64) / 8.0,
        ];
        pts.push(p);
    }
    let dt = Delaunay::new(&pts).unwrap();
    let vol = check_structure(&dt);
    assert!((vol - 8.0).abs() < 1e-9, "volume {vol}");
}

/// The tets as sorted vertex quadruples, sorted: equal for equal triangulations.
fn canonical(dt: &Delaunay) -> Vec<[u32; 4]> {
    let mut t: Vec<[u32; 4]> = dt
        .tets
        .iter()
        .map(|tv| {
            let mut s = *tv;
            s.sort_unstable();
            s
        })
        .collect();
    t.sort_unstable();
    t
}

/// Every interior face is locally Delaunay: the apex across it is not strictly inside the
/// circumsphere (locally Delaunay everywhere implies Delaunay).
fn check_locally_delaunay(dt: &Delaunay) {
    let p = |v: u32| &dt.vertices[v as usize];
    for (t, tv) in dt.tets.iter().enumerate() {
        for k in 0..4 {
            let nb = dt.neighbors[t][k];
            if nb == NONE {
                continue;
            }
            let back = back_index(dt, t, nb);
            let apex = dt.tets[nb as usize][back];
            assert!(
                insphere(p(tv[0]), p(tv[1]), p(tv[2]), p(tv[3]), p(apex)) <= 0,
                "apex {apex} inside the circumsphere of tet {t}"
            );
        }
    }
}

/// The v* of the example PoNQ (a CAD part at 64^3, 9,186 points), without the mesher's box.
fn example_vstars() -> Vec<[f64; 3]> {
    let example =
        std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../examples/example001_ponq_64.npz");
    ponq_mesh::io::npz::read_ponq(&example).unwrap().vstars()
}

#[test]
fn parallel_insertion_gives_the_same_triangulation() {
    let mut rng = ChaCha8Rng::seed_from_u64(11);
    let mut inputs: Vec<(&str, Vec<[f64; 3]>)> = Vec::new();
    let random: Vec<[f64; 3]> = (0..12_000)
        .map(|_| {
            [
                rng.random_range(-1.0..1.0),
                rng.random_range(-1.0..1.0),
                rng.random_range(-1.0..1.0),
            ]
        })
        .collect();
    inputs.push(("random", random));
    // Points on the surfaces of a sphere and a box (the mesher's kind of input), with the
    // protective corners: large empty tets inside and outside span the workers' regions.
    let mut surface = cube_corners();
    for i in 0..12_000 {
        let u: [f64; 3] = [
            rng.random_range(-1.0..1.0),
            rng.random_range(-1.0..1.0),
            rng.random_range(-1.0..1.0),
        ];
        if i % 2 == 0 {
            let l = (u[0] * u[0] + u[1] * u[1] + u[2] * u[2]).sqrt().max(1e-9);
            surface.push([0.3 + 0.5 * u[0] / l, 0.5 * u[1] / l, 0.5 * u[2] / l]);
        } else {
            // A face of the box [-0.8, 0.2]^3, snapped to a fine grid: exact coplanar ties.
            let snap = |x: f64| (x * 64.0).round() / 64.0;
            let mut q = [
                snap(-0.3 + 0.5 * u[0]),
                snap(-0.3 + 0.5 * u[1]),
                snap(-0.3 + 0.5 * u[2]),
            ];
            q[i % 3] = if u[0] > 0.0 { 0.2 } else { -0.8 };
            surface.push(q);
        }
    }
    inputs.push(("surfaces", surface));
    // An exact lattice: every cell co-spherical, every insphere decision a symbolic tie.
    inputs.push(("lattice", lattice(22, 0.25)));
    // A coarse grid-snapped cloud: duplicates and ties everywhere.
    let snapped: Vec<[f64; 3]> = (0..15_000)
        .map(|_| [0, 1, 2].map(|_| rng.random_range(-20i32..=20) as f64 / 20.0))
        .collect();
    inputs.push(("snapped", snapped));
    // A CAD part's v* alone (no enclosing box): a convex hull with flat faces, whose points
    // are coplanar and co-circular with many hull faces (the infinite tets' plane rule).
    inputs.push(("CAD v* alone", example_vstars()));
    for (name, pts) in &inputs {
        let one = Delaunay::with_threads(pts, 1).unwrap();
        let reference = canonical(&one);
        assert!(!reference.is_empty());
        assert_eq!(one.stats.workers, 1);
        if *name == "snapped" {
            assert!(
                one.vertices.len() < pts.len(),
                "the snapped cloud has duplicates"
            );
        }
        for threads in [2, 3, 8] {
            let par = Delaunay::with_threads(pts, threads).unwrap();
            assert_eq!(par.stats.workers, threads);
            check_structure(&par);
            assert_eq!(par.vertex_of_point, one.vertex_of_point, "{name}");
            assert_eq!(
                canonical(&par),
                reference,
                "{name}: {threads} workers differ from one"
            );
            // Not only the same tets: the same arrays, whatever the timing.
            assert_eq!(par.tets, one.tets, "{name}: tet order differs");
            assert_eq!(par.neighbors, one.neighbors, "{name}: neighbours differ");
        }
        // These inputs do not make the workers collide: the parallel phase inserts most
        // vertices and does not stop. Timing decides collisions, though: a worker descheduled
        // in the middle of an insertion holds its locks for a whole time slice, and on a
        // loaded machine (the other tests of this binary run alongside) the others back off
        // meanwhile and may stop, which is what the stop rule is for (seen once in six runs of
        // this binary with 3 workers on 2 cores: 312 of ~1,300 attempts backed off). So one of
        // a few two-worker runs must show it.
        let calm = (0..5).find_map(|_| {
            let s = Delaunay::with_threads(pts, 2).unwrap().stats;
            (!s.parallel_stopped && s.parallel_insertions > pts.len() / 4).then_some(s)
        });
        assert!(calm.is_some(), "{name}: two workers stopped in 5 runs of 5");
        // More workers than threads: a worker that finishes its own chunks before the others
        // have started takes theirs (work stealing); the result is still the same.
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(2)
            .build()
            .expect("a thread pool");
        let par = pool.install(|| Delaunay::with_threads(pts, 8).unwrap());
        assert!(par.stats.stolen_chunks > 0, "{name}: no chunk was stolen");
        assert_eq!(par.tets, one.tets, "{name}: stealing changed the tets");
        assert_eq!(
            par.neighbors, one.neighbors,
            "{name}: stealing changed the neighbours"
        );
        // Workers that keep finding tets busy back off, undo their stamps and locks, and
        // leave those vertices to the end: the triangulation must not change. With one lock
        // attempt in 5 failing nearly every insertion backs off, and the workers stop early,
        // leaving their unclaimed chunks to the one-thread pass too.
        for every in [5, 37, 401] {
            let opts = DelaunayOptions {
                threads: 2,
                fail_every_nth_lock: every,
                ..Default::default()
            };
            let par = Delaunay::with_options(pts, &opts).unwrap();
            assert!(
                par.stats.deferred > 0,
                "{name}: no back-off with every={every}"
            );
            if every == 5 {
                assert!(par.stats.parallel_stopped, "{name}: {:?}", par.stats);
                assert!(par.stats.parallel_insertions < pts.len() / 2, "{name}");
            }
            check_structure(&par);
            assert_eq!(
                canonical(&par),
                reference,
                "{name}: backing off every {every} locks changed the result"
            );
        }
        check_locally_delaunay(&one);
    }
}

#[test]
fn near_points_merge_only_when_asked() {
    // A lattice with a copy of some points a rounding away (in x, then in all three axes).
    // (No coordinate is 0: the next float after 0 would be set to 0, not merged; see
    // `tiny_coordinates_are_snapped_to_zero`.)
    let mut pts = Vec::new();
    for i in 0..12 {
        for j in 0..12 {
            for k in 0..12 {
                pts.push([
                    0.05 + i as f64 * 0.1,
                    0.05 + j as f64 * 0.1 + 0.01 * i as f64,
                    0.05 + k as f64 * 0.1,
                ]);
            }
        }
    }
    let n = pts.len();
    let copies: Vec<usize> = (0..n).step_by(97).collect();
    for (c, &i) in copies.iter().enumerate() {
        let p = pts[i];
        pts.push(if c % 2 == 0 {
            [p[0].next_up(), p[1], p[2]]
        } else {
            p.map(|x| x.next_down())
        });
    }
    let exact = Delaunay::new(&pts).unwrap();
    assert_eq!(exact.vertices.len(), pts.len());
    assert_eq!(exact.stats.merged_near, 0);
    let merged = Delaunay::with_options(
        &pts,
        &DelaunayOptions {
            merge_within: 1e-9,
            ..Default::default()
        },
    )
    .unwrap();
    // Each copy is its original's vertex, at the original's position (first in input order).
    assert_eq!(merged.vertices.len(), n);
    assert_eq!(merged.stats.merged_near, copies.len());
    for (c, &i) in copies.iter().enumerate() {
        assert_eq!(merged.vertex_of_point[n + c], merged.vertex_of_point[i]);
        assert_eq!(merged.vertices[merged.vertex_of_point[i] as usize], pts[i]);
    }
    // And the triangulation is the one of the points without the copies.
    let plain = Delaunay::new(&pts[..n]).unwrap();
    assert_eq!(merged.tets, plain.tets);
}

/// Coordinates far below the others' size (a subnormal such as the next float after 0, or
/// 1e-200 next to 1) would make the exact predicates' products underflow: they are set to 0
/// (counted in `stats.snapped`), so those points become copies of the lattice point they
/// were a rounding away from, and the triangulation stays exact.
#[test]
fn tiny_coordinates_are_snapped_to_zero() {
    let mut pts = lattice(5, 0.25);
    let n = pts.len();
    // Copies of (0, 0, 0), (0.25, 0, 0) and (0, 0.5, 0.25) a tiny amount away.
    pts.push([5e-324, 0.0, 0.0]);
    pts.push([0.25, -1e-200, f64::MIN_POSITIVE]);
    pts.push([-1e-300, 0.5, 0.25]);
    for threads in [1, 2] {
        let dt = Delaunay::with_threads(&pts, threads).unwrap();
        assert_eq!(dt.stats.snapped, 3, "{:?}", dt.stats);
        assert_eq!(dt.vertices.len(), n);
        assert_eq!(dt.vertex_of_point[n], dt.vertex_of_point[0]);
        assert_eq!(dt.vertex_of_point[n + 1], dt.vertex_of_point[25]);
        assert_eq!(dt.vertex_of_point[n + 2], dt.vertex_of_point[11]);
        let vol = check_structure(&dt);
        assert!((vol - 1.0).abs() < 1e-12, "volume {vol}");
        check_empty_spheres(&dt);
        assert_eq!(
            canonical(&dt),
            canonical(&Delaunay::new(&pts[..n]).unwrap())
        );
    }
    // Coordinates within 2^150 of the largest are kept as they are.
    let kept = [
        [0.0, 0.0, 0.0],
        [1.0, 0.0, 0.0],
        [0.0, 1.0, 0.0],
        [0.0, 0.0, 1.0],
        [1e-40, 1e-40, 1e-40],
    ];
    let dt = Delaunay::new(&kept).unwrap();
    assert_eq!((dt.stats.snapped, dt.vertices.len()), (0, 5));
    assert_eq!(dt.vertices[4], kept[4]);
}

/// Scaling every point by a power of two is exact and changes no predicate's sign, so the
/// triangulation of points scaled by 2^-1000 or 2^1000 (where the products of the exact
/// predicates would underflow or overflow) is the one of the unscaled points, and the
/// vertices are the scaled points themselves.
#[test]
fn tiny_and_huge_point_sets_give_the_unscaled_triangulation() {
    let mut rng = ChaCha8Rng::seed_from_u64(5);
    let mut pts: Vec<[f64; 3]> = (0..9000)
        .map(|_| {
            [
                rng.random_range(0.5..1.0),
                rng.random_range(0.5..1.0),
                rng.random_range(-1.0..-0.5),
            ]
        })
        .collect();
    // And a lattice part: exactly co-spherical points, decided by the symbolic perturbation.
    pts.extend(lattice(8, 0.0625));
    let plain = Delaunay::new(&pts).unwrap();
    check_locally_delaunay(&plain);
    for scale in [2f64.powi(-1000), 2f64.powi(1000), 2f64.powi(-1070)] {
        let scaled: Vec<[f64; 3]> = pts.iter().map(|p| p.map(|x| x * scale)).collect();
        for threads in [1, 2] {
            let dt = Delaunay::with_threads(&scaled, threads).unwrap();
            // 2^-1070 leaves most coordinates subnormal, some lost (rounded): only the
            // structure is compared there.
            if scale > 2f64.powi(-1050) {
                assert_eq!(dt.stats.snapped, 0, "scale {scale:e}");
                assert!(dt.vertices == scaled, "scale {scale:e}: other vertices");
                assert!(
                    dt.tets == plain.tets && dt.neighbors == plain.neighbors,
                    "scale {scale:e}, {threads} threads: another triangulation"
                );
            } else {
                assert!(!dt.tets.is_empty());
                let back: Vec<[f64; 3]> =
                    dt.vertices.iter().map(|p| p.map(|x| x / scale)).collect();
                let unscaled = Delaunay::new(&back).unwrap();
                assert!(
                    canonical(&dt) == canonical(&unscaled),
                    "{threads} threads: another triangulation"
                );
            }
        }
    }
}

/// The tets fill the convex hull of the vertices: every vertex is in a tet, and no vertex is
/// strictly outside a boundary face (a face without neighbour, seen from its tet's fourth
/// vertex); brute force with exact orientations.
fn check_fills_hull(dt: &Delaunay) {
    let p = |v: u32| &dt.vertices[v as usize];
    let mut used = vec![false; dt.vertices.len()];
    for (t, tv) in dt.tets.iter().enumerate() {
        tv.iter().for_each(|&v| used[v as usize] = true);
        for k in 0..4 {
            if dt.neighbors[t][k] != NONE {
                continue;
            }
            let f: Vec<u32> = (0..4).filter(|&j| j != k).map(|j| tv[j]).collect();
            // The tet's own vertex `k` is on the inner side.
            let inner = orient3d(p(f[0]), p(f[1]), p(f[2]), p(tv[k]));
            for (i, q) in dt.vertices.iter().enumerate() {
                assert!(
                    orient3d(p(f[0]), p(f[1]), p(f[2]), q) != -inner,
                    "vertex {i} is outside the boundary face {f:?} of tet {t}: a hull tet is missing"
                );
            }
        }
    }
    assert!(used.iter().all(|&u| u), "a vertex is in no tet");
}

/// Points whose convex hull has nearly coplanar faces: the flat tets along it have huge
/// circumspheres, which a super-tetrahedron 1000 extents wide cut off (2,000 points in a
/// 1 x 1 x 1e-6 slab lost a third of their tets that way; random points in a cube a few).
/// Checked against the hull by brute force, on one and two threads.
#[test]
fn tets_fill_the_convex_hull() {
    let mut rng = ChaCha8Rng::seed_from_u64(11);
    let mut sets: Vec<(&str, Vec<[f64; 3]>)> = Vec::new();
    for (name, thickness) in [("cube", 1.0), ("slab 1e-3", 1e-3), ("slab 1e-6", 1e-6)] {
        let pts = (0..2000)
            .map(|_| {
                [
                    rng.random_range(0.0..1.0),
                    rng.random_range(0.0..1.0),
                    rng.random_range(0.0..thickness),
                ]
            })
            .collect();
        sets.push((name, pts));
    }
    // A paraboloid cap: every point on the hull, neighbouring faces nearly coplanar.
    let cap = (0..1500)
        .map(|_| {
            let (x, y): (f64, f64) = (rng.random_range(-1.0..1.0), rng.random_range(-1.0..1.0));
            [x, y, 1e-4 * (x * x + y * y)]
        })
        .collect();
    sets.push(("paraboloid", cap));
    // A CAD part's v* alone: flat hull faces with many coplanar, co-circular points (with a
    // super-tetrahedron 2^30 extents wide, parts like it lost hull tets and were built again).
    sets.push(("CAD v* alone", example_vstars()));
    for (_name, pts) in &sets {
        for threads in [1, 2] {
            let dt = Delaunay::with_threads(pts, threads).unwrap();
            check_structure(&dt);
            check_fills_hull(&dt);
        }
        let dt = Delaunay::new(pts).unwrap();
        check_empty_spheres(&dt);
    }
}

/// Points on two skew lines have a quadratic number of tets: each pair of consecutive points
/// on one line with each pair on the other, (150 - 1)^2 = 22,201 here, well past the arena's
/// first room (8 slots per point and a few thousand more), so the arena grows while the
/// insertion runs (with one thread its free slots are written a block at a time, see
/// `Builder::reserve`).
#[test]
fn the_arena_grows_past_its_first_room() {
    let m = 150;
    let mut pts = Vec::new();
    for i in 0..m {
        // Uneven steps, so that no pattern of the spacing repeats.
        let t = i as f64 + 0.3 * ((i * i) % 7) as f64 / 7.0;
        pts.push([t, 0.0, 0.0]);
        pts.push([0.0, 0.7 * t, 50.0]);
    }
    for threads in [1, 2] {
        let dt = Delaunay::with_threads(&pts, threads).unwrap();
        assert_eq!(dt.tets.len(), (m - 1) * (m - 1), "{threads} threads");
        check_structure(&dt);
        check_fills_hull(&dt);
    }
    check_empty_spheres(&Delaunay::new(&pts).unwrap());
}

/// Points far flatter still: a slab 1e-12 thick, and four points of a tet 1e-30 or 1e-40
/// high (its circumradius up to ~2^133 times its base). Their hull tets have circumspheres of
/// any size; the infinite vertex has no position for them to reach, so every tet of the
/// hull is there (with a super-tetrahedron 2^30 extents wide the slab lost tets along its
/// hull, and the flat tets needed one 2^150 extents wide). (Flat tets thinner still are not
/// found with coordinates of one magnitude: a coordinate below 2^-140 of the largest is set
/// to 0 first.)
#[test]
fn flat_point_sets_fill_their_hull() {
    let mut rng = ChaCha8Rng::seed_from_u64(12);
    let slab: Vec<[f64; 3]> = (0..600)
        .map(|_| {
            [
                rng.random_range(0.0..1.0),
                rng.random_range(0.0..1.0),
                rng.random_range(0.0..1e-12),
            ]
        })
        .collect();
    for threads in [1, 2] {
        let dt = Delaunay::with_threads(&slab, threads).unwrap();
        check_structure(&dt);
        check_fills_hull(&dt);
    }
    check_empty_spheres(&Delaunay::new(&slab).unwrap());
    let flat = |h: f64| {
        [
            [0.0, 0.0, 0.0],
            [1.0, 0.0, 0.0],
            [0.0, 1.0, 0.0],
            [0.3, 0.3, h],
        ]
    };
    for h in [1e-30, 1e-40] {
        let dt = Delaunay::new(&flat(h)).unwrap();
        assert_eq!(dt.tets.len(), 1, "height {h}");
        check_structure(&dt);
        check_fills_hull(&dt);
    }
}

/// The stage times of `DelaunayStats::times` are each measured and together no longer than
/// the call (one and two threads; points in a cube and in a flat slab).
#[test]
fn stage_times_add_up_to_at_most_the_call() {
    let mut rng = ChaCha8Rng::seed_from_u64(31);
    let cube: Vec<[f64; 3]> = (0..20_000)
        .map(|_| std::array::from_fn(|_| rng.random_range(-1.0..1.0)))
        .collect();
    let slab: Vec<[f64; 3]> = cube.iter().map(|p| [p[0], p[1], p[2] * 1e-12]).collect();
    for pts in [&cube, &slab] {
        for threads in [1, 2] {
            let start = std::time::Instant::now();
            let dt = Delaunay::with_threads(pts, threads).unwrap();
            let call = start.elapsed();
            let t = dt.stats.times;
            assert!(
                t.ordering > std::time::Duration::ZERO
                    && t.insertion > std::time::Duration::ZERO
                    && t.output > std::time::Duration::ZERO,
                "{t:?}"
            );
            assert!(
                t.ordering + t.insertion + t.output <= call,
                "{t:?} in {call:?}"
            );
            // Inserting 20k points is most of the work.
            assert!(t.insertion > t.ordering, "{t:?}");
        }
    }
}

mod hull_fuzz {
    use super::*;
    use proptest::prelude::*;

    fn coord() -> impl Strategy<Value = f64> {
        prop_oneof![
            // Lattice values: coplanar and co-spherical ties, hull faces with many points.
            (-4i32..=4).prop_map(|i| i as f64 * 0.25),
            -1.0f64..1.0,
            // Nearly flat: a rounding, or far more, off the lattice planes.
            prop::sample::select(vec![1e-16, -3e-13, 1e-30, -1e-40, 2e-300]),
        ]
    }

    proptest! {
        #![proptest_config(ProptestConfig { cases: 256, ..ProptestConfig::default() })]

        /// Any point set, with no enclosing box: the tets are positively oriented, have empty
        /// circumspheres and fill the convex hull (brute force), whatever the flatness.
        #[test]
        fn tets_fill_the_hull_of_any_point_set(
            pts in prop::collection::vec(prop::array::uniform3(coord()), 0..40)
        ) {
            let dt = match Delaunay::new(&pts) {
                Ok(dt) => dt,
                Err(e) => return Err(TestCaseError::fail(e.to_string())),
            };
            if dt.tets.is_empty() {
                // Then no four vertices span a volume.
                let v = &dt.vertices;
                for (a, b, c, d) in (0..v.len()).flat_map(|a| {
                    (a + 1..v.len()).flat_map(move |b| {
                        (b + 1..v.len())
                            .flat_map(move |c| (c + 1..v.len()).map(move |d| (a, b, c, d)))
                    })
                }) {
                    prop_assert_eq!(orient3d(&v[a], &v[b], &v[c], &v[d]), 0);
                }
            } else {
                check_structure(&dt);
                check_fills_hull(&dt);
                check_empty_spheres(&dt);
            }
        }
    }
}

/// The portable insertion (the same code compiled without AVX2, forced by the testing option;
/// with AVX2 the walk tests a tet's four faces in vector lanes and the cavity search reads its
/// points straight into them) gives the same arrays as the default one (AVX2 where the CPU has
/// it), on one thread and
/// two, on random points, a lattice (every conflict test a tie) and grid-snapped points
/// inside a cube (ties, and the hull's infinite tets).
#[test]
fn portable_and_avx2_insertions_give_the_same_triangulation() {
    let mut rng = ChaCha8Rng::seed_from_u64(31);
    let random: Vec<[f64; 3]> = (0..12_000)
        .map(|_| [rng.random(), rng.random(), rng.random()])
        .collect();
    let mut snapped = cube_corners();
    snapped
        .extend((0..9_000).map(|_| [0, 1, 2].map(|_| rng.random_range(-12i32..=12) as f64 / 12.0)));
    for (name, pts) in [
        ("random", random),
        ("lattice", lattice(22, 0.1)),
        ("snapped", snapped),
    ] {
        for threads in [1, 2] {
            let run = |portable: bool| {
                let opts = DelaunayOptions {
                    threads,
                    portable,
                    ..Default::default()
                };
                Delaunay::with_options(&pts, &opts).unwrap()
            };
            let (fast, portable) = (run(false), run(true));
            assert!(fast.tets.len() > 10_000, "{name}");
            assert_eq!(fast.tets, portable.tets, "{name}, {threads} threads");
            assert_eq!(
                fast.neighbors, portable.neighbors,
                "{name}, {threads} threads"
            );
        }
    }
}
