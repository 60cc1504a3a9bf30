//! Exact SDF grids against brute force: every node's distance (min over all triangles) and
//! sign (exact winding-number sum over all triangles), on closed meshes (convex, thin,
//! non-convex, CAD parts, inverted, hollow, unwelded) and an open cup; occupancy and the
//! close mask against their definitions.

use std::sync::atomic::{AtomicUsize, Ordering};

use ponq_data::normalize::Normalization;
use ponq_data::occupancy::{close_mask, close_threshold, occupancy_from_samples, sample_counts};
use ponq_data::sdf::{ClosestQueries, MeshSdf, SdfGrid, signed_distance_grid};
use ponq_mesh::sampling::sample_surface;
use ponq_mesh::{TriMesh, io};
use rayon::prelude::*;

// ----- brute force (written independently of the library) -----

fn sub(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}
fn dot(a: [f64; 3], b: [f64; 3]) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}
fn cross(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ]
}

fn seg_dist2(p: [f64; 3], a: [f64; 3], b: [f64; 3]) -> f64 {
    let ab = sub(b, a);
    let l2 = dot(ab, ab);
    let t = if l2 > 0.0 {
        (dot(sub(p, a), ab) / l2).clamp(0.0, 1.0)
    } else {
        0.0
    };
    let q = [a[0] + t * ab[0], a[1] + t * ab[1], a[2] + t * ab[2]];
    let d = sub(p, q);
    dot(d, d)
}

/// Plane projection when it falls inside the triangle (barycentric signs), else the edges.
fn tri_dist2(p: [f64; 3], [a, b, c]: [[f64; 3]; 3]) -> f64 {
    let n = cross(sub(b, a), sub(c, a));
    let nn = dot(n, n);
    if nn > 1e-30 {
        let h = dot(sub(p, a), n) / nn;
        let q = [p[0] - h * n[0], p[1] - h * n[1], p[2] - h * n[2]];
        let s = [
            dot(cross(sub(b, a), sub(q, a)), n),
            dot(cross(sub(c, b), sub(q, b)), n),
            dot(cross(sub(a, c), sub(q, c)), n),
        ];
        if s.iter().all(|&x| x >= 0.0) {
            return h * h * nn;
        }
    }
    seg_dist2(p, a, b)
        .min(seg_dist2(p, b, c))
        .min(seg_dist2(p, c, a))
}

fn brute_distance(m: &TriMesh, p: [f64; 3]) -> f64 {
    (0..m.faces.len())
        .map(|f| tri_dist2(p, m.triangle(f)))
        .fold(f64::INFINITY, f64::min)
        .sqrt()
}

fn brute_winding(m: &TriMesh, p: [f64; 3]) -> f64 {
    let mut s = 0.0;
    for f in 0..m.faces.len() {
        let [a, b, c] = m.triangle(f).map(|v| sub(v, p));
        let (la, lb, lc) = (dot(a, a).sqrt(), dot(b, b).sqrt(), dot(c, c).sqrt());
        let num = dot(a, cross(b, c));
        let den = la * lb * lc + dot(a, b) * lc + dot(b, c) * la + dot(c, a) * lb;
        s += 2.0 * num.atan2(den);
    }
    s / (4.0 * std::f64::consts::PI)
}

/// Compares every node of the `res^3` grid of `m` with brute force; returns the grid.
fn check_grid(name: &str, m: &TriMesh, res: usize) -> SdfGrid {
    let max_seen = AtomicUsize::new(0);
    let g = signed_distance_grid(m, res, |n| {
        max_seen.fetch_max(n, Ordering::Relaxed);
    })
    .expect("sdf");
    let n1 = res + 1;
    assert_eq!(g.values.len(), n1 * n1 * n1);
    assert_eq!(max_seen.into_inner(), n1 * n1 * n1, "{name}: progress");
    // Brute force over the x slabs in parallel; each slab returns its inside count.
    let inside: usize = (0..n1)
        .into_par_iter()
        .map(|i| {
            let mut inside = 0;
            for j in 0..n1 {
                for k in 0..n1 {
                    let p = g.node_position(i, j, k);
                    let want = brute_distance(m, p);
                    let got = f64::from(g.get(i, j, k));
                    assert!(
                        (got.abs() - want).abs() <= 1e-6 * want + 1e-12,
                        "{name}: |sdf| at node ({i},{j},{k}) = {p:?}: {got} vs brute force {want}"
                    );
                    if want < 1e-12 {
                        continue; // on the surface: no sign
                    }
                    let w = brute_winding(m, p);
                    if (w.abs() - 0.5).abs() < 1e-9 {
                        continue; // an open mesh's sign is undecided exactly at |w| = 1/2
                    }
                    let want_in = w.abs() > 0.5;
                    inside += want_in as usize;
                    assert_eq!(
                        got < 0.0,
                        want_in,
                        "{name}: sign at node ({i},{j},{k}) = {p:?}: sdf {got}, winding number {w}"
                    );
                }
            }
            inside
        })
        .sum();
    eprintln!(
        "{name}: {res}^3 cells, {inside} nodes inside, open = {}",
        g.open
    );
    g
}

// ----- meshes -----

fn shipped(name: &str) -> TriMesh {
    let p = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../examples")
        .join(name);
    io::read_mesh(&p).expect("shipped example mesh")
}

fn normalised(m: &TriMesh) -> TriMesh {
    Normalization::of(m).unwrap().apply_mesh(m)
}

/// Outward-oriented box.
fn cuboid(lo: [f64; 3], hi: [f64; 3]) -> TriMesh {
    let v: Vec<[f64; 3]> = (0..8)
        .map(|i| {
            [
                if i & 1 == 0 { lo[0] } else { hi[0] },
                if i & 2 == 0 { lo[1] } else { hi[1] },
                if i & 4 == 0 { lo[2] } else { hi[2] },
            ]
        })
        .collect();
    let quads = [
        [0, 2, 3, 1], // z = lo
        [4, 5, 7, 6], // z = hi
        [0, 1, 5, 4], // y = lo
        [2, 6, 7, 3], // y = hi
        [0, 4, 6, 2], // x = lo
        [1, 3, 7, 5], // x = hi
    ];
    let mut f = Vec::new();
    for q in quads {
        f.push([q[0], q[1], q[2]]);
        f.push([q[0], q[2], q[3]]);
    }
    TriMesh::new(v, f).unwrap()
}

/// Extrusion of a simple counter-clockwise polygon whose vertex 0 sees every other vertex
/// (fan triangulation), between heights `z0 < z1`.
fn prism(poly: &[[f64; 2]], z0: f64, z1: f64) -> TriMesh {
    let n = poly.len() as u32;
    let mut v: Vec<[f64; 3]> = poly.iter().map(|p| [p[0], p[1], z0]).collect();
    v.extend(poly.iter().map(|p| [p[0], p[1], z1]));
    let mut f = Vec::new();
    for i in 1..n - 1 {
        f.push([0, i + 1, i]); // bottom, facing -z
        f.push([n, n + i, n + i + 1]); // top, facing +z
    }
    for i in 0..n {
        let j = (i + 1) % n;
        f.push([i, j, n + j]);
        f.push([i, n + j, n + i]);
    }
    TriMesh::new(v, f).unwrap()
}

fn l_prism() -> TriMesh {
    // Vertex 0 is the reflex corner, which sees the whole L.
    prism(
        &[
            [-0.1, 0.05],
            [-0.1, 0.7],
            [-0.75, 0.7],
            [-0.75, -0.6],
            [0.8, -0.6],
            [0.8, 0.05],
        ],
        -0.45,
        0.5,
    )
}

fn flipped(m: &TriMesh) -> TriMesh {
    TriMesh {
        vertices: m.vertices.clone(),
        faces: m.faces.iter().map(|f| [f[0], f[2], f[1]]).collect(),
    }
}

fn merged(a: &TriMesh, b: &TriMesh) -> TriMesh {
    let off = a.vertices.len() as u32;
    let mut m = a.clone();
    m.vertices.extend_from_slice(&b.vertices);
    m.faces.extend(b.faces.iter().map(|f| f.map(|v| v + off)));
    m
}

/// One vertex triple per face (a triangle soup).
fn unwelded(m: &TriMesh) -> TriMesh {
    let mut v = Vec::new();
    let mut f = Vec::new();
    for i in 0..m.faces.len() {
        let t = m.triangle(i);
        let b = v.len() as u32;
        v.extend_from_slice(&t);
        f.push([b, b + 1, b + 2]);
    }
    TriMesh::new(v, f).unwrap()
}

/// `m` rotated about the axis `(1, 2, 3)` by `angle` radians (Rodrigues).
fn rotated(m: &TriMesh, angle: f64) -> TriMesh {
    let l = 14f64.sqrt();
    let k = [1.0 / l, 2.0 / l, 3.0 / l];
    let (c, s) = (angle.cos(), angle.sin());
    let rot = |v: [f64; 3]| {
        let kv = cross(k, v);
        let kd = dot(k, v);
        std::array::from_fn(|i| v[i] * c + kv[i] * s + k[i] * kd * (1.0 - c))
    };
    TriMesh {
        vertices: m.vertices.iter().map(|&v| rot(v)).collect(),
        faces: m.faces.clone(),
    }
}

/// An open cylinder with a bottom: a cup, open at the top.
fn cup() -> TriMesh {
    let n = 24u32;
    let (r, z0, z1) = (0.6, -0.7, 0.65);
    let mut v = vec![[0.0, 0.0, z0]];
    for z in [z0, z1] {
        for i in 0..n {
            let a = 2.0 * std::f64::consts::PI * f64::from(i) / f64::from(n);
            v.push([r * a.cos(), r * a.sin(), z]);
        }
    }
    let mut f = Vec::new();
    for i in 0..n {
        let j = (i + 1) % n;
        f.push([0, 1 + j, 1 + i]);
        f.push([1 + i, 1 + j, 1 + n + j]);
        f.push([1 + i, 1 + n + j, 1 + n + i]);
    }
    TriMesh::new(v, f).unwrap()
}

// ----- tests -----

#[test]
fn cube_exact_on_every_node() {
    // Faces at 0.5 and -0.5 lie on node planes of the 32^3 grid.
    let m = cuboid([-0.6, -0.5, -0.55], [0.7, 0.5, 0.45]);
    let g = check_grid("cube", &m, 32);
    assert!(!g.open);
    let g = check_grid("cube/unwelded", &unwelded(&m), 20);
    assert!(!g.open, "exactly coincident vertices are welded");
    let g = check_grid("cube/inverted", &flipped(&m), 20);
    assert!(!g.open);
    assert!(g.inside_count() > 0);
}

#[test]
fn thin_plate_exact_on_every_node() {
    // Thinner than a cell, with the node plane z = 0 inside it.
    let m = cuboid([-0.7, -0.6, -0.01], [0.8, 0.65, 0.02]);
    let g = check_grid("thin plate", &m, 32);
    assert!(
        g.inside_count() > 0,
        "the node plane z = 0 is inside the plate"
    );
}

#[test]
fn hollow_box_has_an_outside_cavity() {
    let outer = cuboid([-0.8, -0.8, -0.8], [0.8, 0.8, 0.8]);
    let inner = flipped(&cuboid([-0.33, -0.4, -0.35], [0.45, 0.3, 0.38]));
    let m = merged(&outer, &inner);
    let g = check_grid("hollow box", &m, 24);
    assert!(!g.open);
    assert!(g.get(12, 12, 12) > 0.0, "the cavity is outside");
    assert!(g.get(12, 12, 4) < 0.0, "the wall is inside");
}

#[test]
fn overlapping_and_flipped_cubes() {
    // Two overlapping closed shells (self-intersecting; w = 2 in the overlap): closed chain.
    let a = cuboid([-0.6, -0.5, -0.4], [0.3, 0.4, 0.5]);
    let b = rotated(&cuboid([-0.2, -0.3, -0.35], [0.7, 0.6, 0.3]), 0.4);
    let g = check_grid("overlapping cubes", &merged(&a, &b), 20);
    assert!(!g.open);
    // One flipped triangle: the boundary chain no longer vanishes, the winding number is
    // evaluated everywhere (and still matches brute force).
    let mut f = rotated(&a, 0.3);
    f.faces[3] = [f.faces[3][0], f.faces[3][2], f.faces[3][1]];
    let g = check_grid("cube with a flipped face", &f, 16);
    assert!(g.open);
}

#[test]
fn rotated_part_exact_on_every_node() {
    let m = rotated(&normalised(&shipped("example001.obj")), 0.7);
    check_grid("example001.obj (rotated)", &m, 15);
}

#[test]
fn l_prism_exact_on_every_node() {
    check_grid("L prism", &l_prism(), 32);
}

#[test]
fn csg_part_exact_on_every_node() {
    let m = normalised(&shipped("csg.obj"));
    let g = check_grid("csg.obj", &m, 16);
    assert!(!g.open);
    // A frame that does not align the part's faces with node planes.
    let s = Normalization {
        centre: [0.013, -0.021, 0.007],
        scale: 0.93,
    };
    check_grid("csg.obj (shifted)", &s.apply_mesh(&m), 14);
}

#[test]
fn example001_part_exact_on_every_node() {
    let m = normalised(&shipped("example001.obj"));
    let g = check_grid("example001.obj", &m, 20);
    assert!(!g.open);
}

#[test]
fn open_cup_gives_winding_number_signs_and_a_flag() {
    let m = cup();
    let g = check_grid("cup", &m, 20);
    assert!(g.open);
    assert!(g.values.iter().all(|v| v.is_finite()));
    // The bottom of the cup is well inside (w close to 1), far above the opening outside.
    assert!(g.get(10, 10, 4) < 0.0);
    assert!(g.get(10, 10, 20) > 0.0);
}

#[test]
fn single_point_queries_match_the_grid() {
    let m = normalised(&shipped("example001.obj"));
    let sdf = MeshSdf::new(&m).unwrap();
    let g = sdf.grid(8, |_| {}).unwrap();
    for (i, j, k) in [(0, 0, 0), (4, 4, 4), (2, 5, 3), (8, 1, 7)] {
        let p = g.node_position(i, j, k);
        let d = sdf.signed_distance(p);
        assert!((d - f64::from(g.get(i, j, k))).abs() <= 1e-6 * d.abs());
        assert!((sdf.winding_number(p) - brute_winding(&m, p)).abs() < 1e-9);
    }
    let pts = [[0.0, 0.0, 0.0], [0.9, -0.9, 0.9]];
    let many = sdf.signed_distances(&pts);
    assert_eq!(many[1], sdf.signed_distance(pts[1]));
}

#[test]
fn random_points_match_brute_force() {
    use rand::{Rng, SeedableRng};
    let m = normalised(&shipped("csg.obj"));
    let sdf = MeshSdf::new(&m).unwrap();
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(5);
    let pts: Vec<[f64; 3]> = (0..1500)
        .map(|_| std::array::from_fn(|_| rng.random_range(-1.6..1.6)))
        .collect();
    let got = sdf.signed_distances(&pts);
    let bad: Vec<String> = pts
        .par_iter()
        .zip(&got)
        .filter_map(|(&p, &d)| {
            let want = brute_distance(&m, p);
            let w = brute_winding(&m, p);
            let sign_ok = (d < 0.0) == (w.abs() > 0.5);
            ((d.abs() - want).abs() > 1e-12 * (1.0 + want) || !sign_ok)
                .then(|| format!("{p:?}: {d} vs {want} (w = {w})"))
        })
        .collect();
    assert!(bad.is_empty(), "{bad:?}");
}

#[test]
fn runs_of_closest_point_queries_match_brute_force() {
    // Queries in a run start from the previous query's triangle (a grid row here, then jumps
    // back across the part), and the run state moves to a second mesh.
    let m = normalised(&shipped("csg.obj"));
    let sdf = MeshSdf::for_distances(&m).unwrap();
    let small = MeshSdf::for_distances(&cuboid([-0.2; 3], [0.3; 3])).unwrap();
    let mut queries = ClosestQueries::default();
    let n = 24;
    for i in 0..n {
        for j in [3, 11, 20] {
            for k in 0..n {
                let c = |t: usize| -1.1 + 2.2 * t as f64 / (n - 1) as f64;
                let p = [c(i), c(j), c(k)];
                let (y, normal) = sdf.closest_point_and_normal_with(p, &mut queries);
                let want = brute_distance(&m, p);
                let got = dot(sub(y, p), sub(y, p)).sqrt();
                assert!(
                    (got - want).abs() <= 1e-12 * (1.0 + want),
                    "{p:?}: {got} vs {want}"
                );
                // A point of the mesh (where two are equally close, either one).
                assert!(
                    brute_distance(&m, y) <= 1e-12,
                    "{p:?}: {y:?} is off the mesh"
                );
                assert!((dot(normal, normal) - 1.0).abs() < 1e-9);
            }
        }
        let p = [0.9, -0.4, 0.1 * i as f64];
        let (y, _) = small.closest_point_and_normal_with(p, &mut queries);
        let (fresh, _) = small.closest_point_and_normal(p);
        let gap = dot(sub(y, p), sub(y, p)).sqrt() - dot(sub(fresh, p), sub(fresh, p)).sqrt();
        assert!(gap.abs() <= 1e-12, "{p:?}: {y:?} vs {fresh:?}");
    }
}

#[test]
fn bad_inputs_are_errors() {
    assert!(signed_distance_grid(&TriMesh::default(), 8, |_| {}).is_err());
    let m = cuboid([-0.5; 3], [0.5; 3]);
    assert!(signed_distance_grid(&m, 0, |_| {}).is_err());
    let mut bad = m.clone();
    bad.vertices[0][1] = f64::NAN;
    assert!(signed_distance_grid(&bad, 8, |_| {}).is_err());
}

#[test]
fn occupancy_matches_a_brute_force_count() {
    let m = normalised(&shipped("csg.obj"));
    let s = sample_surface(&m, 20_000, 3);
    for n in [1usize, 7, 16] {
        let occ = occupancy_from_samples(&s.points, n).unwrap();
        let counts = sample_counts(&s.points, n).unwrap();
        assert_eq!(
            counts.iter().map(|&c| c as usize).sum::<usize>(),
            s.points.len()
        );
        let lo = |i: usize| -1.0 + 2.0 * i as f64 / n as f64;
        let mut want = vec![0u32; n * n * n];
        for p in &s.points {
            // The cell whose half-open interval holds each coordinate (the last one closed).
            let c = p.map(|x| (0..n).find(|&i| x < lo(i + 1) || i == n - 1).unwrap());
            want[(c[0] * n + c[1]) * n + c[2]] += 1;
        }
        assert_eq!(counts, want, "n = {n}");
        assert!(occ.iter().zip(&want).all(|(&o, &w)| o == (w > 0)));
    }
}

#[test]
fn close_mask_matches_its_definition() {
    let m = normalised(&shipped("example001.obj"));
    for n in [9usize, 16] {
        let g = signed_distance_grid(&m, n, |_| {}).unwrap();
        let mask = close_mask(&g.values, n).unwrap();
        let t = close_threshold(n);
        assert!((t - 2.0 * 3f64.sqrt() / (n as f64 + 1.0)).abs() < 1e-15);
        let mut close = 0;
        for i in 0..n {
            for j in 0..n {
                for k in 0..n {
                    let want = (0..8).all(|c| {
                        let v = g.get(i + (c & 1), j + ((c >> 1) & 1), k + (c >> 2));
                        f64::from(v).abs() < t
                    });
                    close += want as usize;
                    assert_eq!(mask[(i * n + j) * n + k], want, "cell ({i},{j},{k})");
                }
            }
        }
        assert!(close > 0, "n = {n}: some cells are close");
        // f64 grids work too.
        let g64: Vec<f64> = g.values.iter().map(|&v| f64::from(v)).collect();
        assert_eq!(close_mask(&g64, n).unwrap(), mask);
    }
}
