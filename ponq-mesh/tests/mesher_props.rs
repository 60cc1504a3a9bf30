//! The mesher's guarantees on many structured and random inputs: the output is closed,
//! oriented, manifold and free of self-intersections (exact check), or empty with a message.

mod common;

use common::*;
use ponq_mesh::mesher::{MeshingOptions, MeshingOutput, mesh_ponq};
use ponq_mesh::validity;
use ponq_mesh::{Ponq, Quadric};
use rand::Rng;

fn mesh(ponq: &Ponq, grid: f64) -> MeshingOutput {
    mesh_ponq(
        ponq,
        &MeshingOptions {
            grid_scale: grid,
            ..Default::default()
        },
    )
    .expect("meshing succeeds on finite input")
}

/// Valid, or empty with a message.
fn assert_valid(out: &MeshingOutput, what: &str) {
    if out.mesh.faces.is_empty() {
        assert!(out.message.is_some(), "{what}: empty mesh without message");
        return;
    }
    let r = validity::check(&out.mesh);
    assert!(r.is_valid(), "{what}: {r}");
}

#[test]
fn sphere_is_watertight_with_the_right_volume() {
    let s = sphere_samples([0.05, -0.1, 0.0], 0.6, 40_000, &mut rng(1));
    let ponq = ponq_by_grid(&s, 32);
    let out = mesh(&ponq, 32.0);
    assert_valid(&out, "sphere");
    let v = out.mesh.signed_volume();
    let exact = 4.0 / 3.0 * std::f64::consts::PI * 0.6f64.powi(3);
    assert!((v - exact).abs() / exact < 0.05, "volume {v} vs {exact}");
}

#[test]
fn box_keeps_its_corners_sharp() {
    let s = box_samples(
        [-0.47, -0.41, -0.29],
        [0.53, 0.39, 0.31],
        60_000,
        &mut rng(2),
    );
    let ponq = ponq_by_grid(&s, 16);
    let out = mesh(&ponq, 16.0);
    assert_valid(&out, "box");
    let v = out.mesh.signed_volume();
    assert!((v - 0.48).abs() / 0.48 < 0.02, "volume {v}");
    // The QEM-optimal vertices recover the 8 corners (cells are not aligned with the box).
    let corners_found = (0..8)
        .filter(|i| {
            let c = [
                if i & 1 == 0 { -0.47 } else { 0.53 },
                if i & 2 == 0 { -0.41 } else { 0.39 },
                if i & 4 == 0 { -0.29 } else { 0.31 },
            ];
            out.mesh.vertices.iter().any(|p| {
                (p[0] - c[0]).abs() < 1e-6
                    && (p[1] - c[1]).abs() < 1e-6
                    && (p[2] - c[2]).abs() < 1e-6
            })
        })
        .count();
    assert_eq!(corners_found, 8);
}

#[test]
fn cad_like_unions_and_thin_plates() {
    let mut r = rng(3);
    for case in 0..6 {
        let mut s = Samples {
            points: vec![],
            normals: vec![],
        };
        // Two overlapping boxes' surfaces plus a thin plate and a cylinder: self-overlapping
        // sample sets make ambiguous, CAD-like configurations.
        for _ in 0..3 {
            let c: [f64; 3] = std::array::from_fn(|_| r.random_range(-0.4..0.4));
            let h: [f64; 3] = std::array::from_fn(|k| {
                if k == case % 3 {
                    r.random_range(0.02..0.08)
                } else {
                    r.random_range(0.1..0.4)
                }
            });
            let b = box_samples(
                [c[0] - h[0], c[1] - h[1], c[2] - h[2]],
                [c[0] + h[0], c[1] + h[1], c[2] + h[2]],
                15_000,
                &mut r,
            );
            s.points.extend(b.points);
            s.normals.extend(b.normals);
        }
        let cy = cylinder_samples(0.25, -0.6, 0.6, 15_000, &mut r);
        s.points.extend(cy.points);
        s.normals.extend(cy.normals);
        for grid in [16usize, 32] {
            let out = mesh(&ponq_by_grid(&s, grid), grid as f64);
            assert_valid(&out, &format!("case {case} grid {grid}"));
            assert!(!out.mesh.faces.is_empty());
        }
    }
}

#[test]
fn random_garbage_ponqs_still_give_valid_meshes() {
    let mut r = rng(4);
    for case in 0..40 {
        let m = r.random_range(0..300);
        let mut pts = Vec::new();
        let mut nrm = Vec::new();
        let mut q = Vec::new();
        for _ in 0..m {
            let p: [f64; 3] = std::array::from_fn(|_| r.random_range(-1.2..1.2));
            let n: [f64; 3] = std::array::from_fn(|_| r.random_range(-1.0..1.0));
            let u: [f64; 6] = std::array::from_fn(|_| r.random_range(-2.0..2.0));
            pts.push(p);
            nrm.push(n);
            q.push(Quadric::from_a_vstar(Quadric::a_from_upper(u), p));
        }
        let ponq = Ponq::new(pts.clone(), nrm, q, Some(pts)).unwrap();
        let out = mesh(&ponq, 8.0);
        assert_valid(&out, &format!("garbage case {case}"));
    }
}

#[test]
fn exact_lattices_and_duplicates() {
    // PoNQ-lite-like input: v* exactly on a lattice, normals of a sphere, each point twice.
    let mut pts = Vec::new();
    let mut nrm = Vec::new();
    let n = 12;
    for i in 0..n {
        for j in 0..n {
            for k in 0..n {
                let p = [
                    -0.55 + 0.1 * i as f64,
                    -0.55 + 0.1 * j as f64,
                    -0.55 + 0.1 * k as f64,
                ];
                let rr = (p[0] * p[0] + p[1] * p[1] + p[2] * p[2]).sqrt();
                if (rr - 0.45).abs() < 0.1 {
                    for _ in 0..2 {
                        pts.push(p);
                        nrm.push(p.map(|x| x / rr));
                    }
                }
            }
        }
    }
    let q: Vec<Quadric> = pts
        .iter()
        .zip(&nrm)
        .map(|(p, n)| Quadric::from_plane(*p, *n))
        .collect();
    let ponq = Ponq::new(pts.clone(), nrm, q, Some(pts)).unwrap();
    let out = mesh(&ponq, 20.0);
    assert_valid(&out, "lattice");
    assert!(!out.mesh.faces.is_empty());
}

#[test]
fn tiny_and_degenerate_inputs() {
    let mk = |pts: Vec<[f64; 3]>, n: [f64; 3]| {
        let q = pts.iter().map(|p| Quadric::from_plane(*p, n)).collect();
        let nn = vec![n; pts.len()];
        Ponq::new(pts.clone(), nn, q, Some(pts)).unwrap()
    };
    let cases: Vec<(&str, Ponq)> = vec![
        ("empty", Ponq::default()),
        ("one", mk(vec![[0.0; 3]], [0.0, 0.0, 1.0])),
        ("two", mk(vec![[0.0; 3], [0.1, 0.0, 0.0]], [0.0, 0.0, 1.0])),
        (
            "three",
            mk(
                vec![[0.0; 3], [0.1, 0.0, 0.0], [0.0, 0.1, 0.0]],
                [0.0, 0.0, 1.0],
            ),
        ),
        (
            "four",
            mk(
                vec![[0.0; 3], [0.1, 0.0, 0.0], [0.0, 0.1, 0.0], [0.0, 0.0, 0.1]],
                [1.0, 1.0, 1.0],
            ),
        ),
        (
            "coplanar",
            mk(
                (0..100)
                    .map(|i| {
                        [
                            (i % 10) as f64 * 0.1 - 0.5,
                            (i / 10) as f64 * 0.1 - 0.5,
                            0.25,
                        ]
                    })
                    .collect(),
                [0.0, 0.0, 1.0],
            ),
        ),
        (
            "all the same point",
            mk(vec![[0.3, 0.3, 0.3]; 50], [0.0, 1.0, 0.0]),
        ),
        (
            "on the domain corners",
            mk(
                vec![
                    [-1.0, -1.0, -1.0],
                    [1.0, 1.0, 1.0],
                    [1.0, -1.0, 1.0],
                    [0.0, 0.0, 0.0],
                ],
                [0.0, 0.0, 1.0],
            ),
        ),
        (
            "outside the domain",
            mk(
                vec![
                    [3.0, 0.0, 0.0],
                    [-2.5, 1.0, 0.0],
                    [0.0, 4.0, -3.0],
                    [0.5, 0.5, 0.5],
                ],
                [1.0, 0.0, 0.0],
            ),
        ),
        (
            "zero normals",
            mk(
                sphere_samples([0.0; 3], 0.5, 200, &mut rng(9)).points,
                [0.0; 3],
            ),
        ),
    ];
    for (name, p) in cases {
        let out = mesh(&p, 16.0);
        assert_valid(&out, name);
    }
}

#[test]
fn bad_options_are_errors_not_panics() {
    let p = Ponq::default();
    for g in [0.0, -1.0, f64::NAN, f64::INFINITY] {
        let o = MeshingOptions {
            grid_scale: g,
            ..Default::default()
        };
        assert!(mesh_ponq(&p, &o).is_err());
    }
    let o = MeshingOptions {
        domain: ([0.0; 3], [0.0; 3]),
        ..Default::default()
    };
    assert!(mesh_ponq(&p, &o).is_err());
}

#[test]
fn output_is_the_same_for_any_thread_count() {
    // Above the size where the Delaunay stage runs on several workers: the mesh, down to the
    // order of its vertices and faces, must not depend on the threads or their timing.
    let mut r = rng(21);
    let mut s = box_samples([-0.6, -0.5, -0.4], [0.55, 0.5, 0.45], 150_000, &mut r);
    let ball = sphere_samples([0.4, 0.3, 0.3], 0.35, 100_000, &mut r);
    s.points.extend(ball.points);
    s.normals.extend(ball.normals);
    let ponq = ponq_by_grid(&s, 72);
    assert!(ponq.len() > 9000, "{} points", ponq.len());
    let run = |threads: usize| {
        rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .expect("thread pool")
            .install(|| mesh(&ponq, 72.0))
    };
    let one = run(1);
    assert_valid(&one, "box and ball");
    for threads in [2, 4] {
        let out = run(threads);
        // (assert! rather than assert_eq!: a failure would print whole meshes.)
        assert!(
            out.mesh.vertices == one.mesh.vertices,
            "{threads} threads: vertices"
        );
        assert!(out.mesh.faces == one.mesh.faces, "{threads} threads: faces");
        assert!(
            out.source_point == one.source_point,
            "{threads} threads: sources"
        );
    }
}

#[test]
fn every_small_tet_rule_gives_valid_meshes() {
    use ponq_mesh::tagging::SmallTetRule;
    let mut r = rng(11);
    let mut differ = [0; 2];
    for case in 0..4 {
        // A box, a thin plate and a cylinder, as in `cad_like_unions_and_thin_plates`.
        let mut s = box_samples([-0.5, -0.4, -0.3], [0.3, 0.4, 0.2], 12_000, &mut r);
        let t = 0.02 + 0.02 * case as f64;
        let p = box_samples([-0.2, -0.7, -0.6], [0.6, 0.1, -0.6 + t], 12_000, &mut r);
        let c = cylinder_samples(0.2, -0.8, 0.7, 12_000, &mut r);
        s.points.extend(p.points.into_iter().chain(c.points));
        s.normals.extend(p.normals.into_iter().chain(c.normals));
        let grid = 16 + 8 * case;
        let ponq = ponq_by_grid(&s, grid);
        let faces: Vec<_> = [
            SmallTetRule::InsideOnly,
            SmallTetRule::BothWays,
            SmallTetRule::Authors,
        ]
        .into_iter()
        .map(|rule| {
            let out = mesh_ponq(
                &ponq,
                &MeshingOptions {
                    grid_scale: grid as f64,
                    small_tet_rule: rule,
                    ..Default::default()
                },
            )
            .expect("meshing succeeds on finite input");
            assert_valid(&out, &format!("case {case}, {rule:?}"));
            assert!(!out.mesh.faces.is_empty());
            out.mesh.faces
        })
        .collect();
        differ[0] += usize::from(faces[0] != faces[1]);
        differ[1] += usize::from(faces[0] != faces[2]);
    }
    // Each option takes effect on these CAD-like inputs.
    assert!(differ[0] > 0 && differ[1] > 0, "{differ:?}");
}

/// The shortest edge of a mesh.
fn shortest_edge(m: &ponq_mesh::TriMesh) -> f64 {
    m.faces
        .iter()
        .flat_map(|f| (0..3).map(move |k| (f[k], f[(k + 1) % 3])))
        .map(|(a, b)| {
            let (p, q) = (m.vertices[a as usize], m.vertices[b as usize]);
            (0..3).map(|i| (p[i] - q[i]).powi(2)).sum::<f64>().sqrt()
        })
        .fold(f64::INFINITY, f64::min)
}

#[test]
fn near_coincident_vstars_are_welded_into_one_vertex() {
    // A box PoNQ, and copies of its points at the box's corners whose v* are a rounding away
    // from the originals' (as ponq-fit's PoNQs of CAD parts have where cells meet at a
    // corner).
    let s = box_samples(
        [-0.47, -0.41, -0.29],
        [0.53, 0.39, 0.31],
        40_000,
        &mut rng(9),
    );
    let base = ponq_by_grid(&s, 16);
    let mut ponq = base.clone();
    let mut vs = ponq.vstars();
    let corners: Vec<usize> = (0..8)
        .filter_map(|c| {
            let target: [f64; 3] = std::array::from_fn(|k| {
                let (lo, hi) = ([-0.47, -0.41, -0.29][k], [0.53, 0.39, 0.31][k]);
                if c >> k & 1 == 0 { lo } else { hi }
            });
            (0..vs.len()).min_by(|&i, &j| {
                let d = |p: [f64; 3]| (0..3).map(|k| (p[k] - target[k]).powi(2)).sum::<f64>();
                d(vs[i]).total_cmp(&d(vs[j]))
            })
        })
        .collect();
    for &i in &corners {
        ponq.points.push(ponq.points[i]);
        ponq.normals.push(ponq.normals[i]);
        ponq.quadrics.push(ponq.quadrics[i]);
        vs.push(vs[i].map(|x| x.next_up()));
    }
    ponq.vstars = Some(vs);
    let mesh = |ponq: &ponq_mesh::Ponq, weld: f64| {
        let out = mesh_ponq(
            ponq,
            &MeshingOptions {
                grid_scale: 16.0,
                weld,
                ..Default::default()
            },
        )
        .expect("meshing succeeds on finite input");
        assert_valid(&out, &format!("weld {weld}"));
        out
    };
    // Without the weld the copies give edges a rounding long (and triangles of no area).
    let plain = mesh(&ponq, 0.0);
    assert_eq!(plain.stats.welded, 0);
    assert!(
        shortest_edge(&plain.mesh) < 1e-15,
        "{}",
        shortest_edge(&plain.mesh)
    );
    // With it, each copy is merged into its original: no such edge is left. The copies sit
    // next to their originals in the Delaunay's sorted order, so one pass does it.
    let welded = mesh(&ponq, ponq_mesh::mesher::DEFAULT_WELD);
    assert_eq!(welded.stats.welded, corners.len());
    assert!(!welded.stats.meshed_twice);
    assert!(
        shortest_edge(&welded.mesh) > 1e-6,
        "{}",
        shortest_edge(&welded.mesh)
    );
    assert!(welded.mesh.vertices.len() < plain.mesh.vertices.len());
    // A copy two roundings away in x with a third point between them in that order (one
    // rounding in x, 1e-4 away in y): the Delaunay's merge misses the pair, the check of the
    // output's edges finds it and the second pass welds it.
    let mut apart = ponq.clone();
    let vs = apart.vstars.as_mut().expect("stored v*");
    let i = corners[0];
    let p = vs[i];
    let copy = vs.len() - corners.len();
    vs[copy] = [p[0].next_up().next_up(), p[1], p[2]];
    vs.push([p[0].next_up(), p[1] - 1e-4, p[2]]);
    apart.points.push(apart.points[i]);
    apart.normals.push(apart.normals[i]);
    apart.quadrics.push(apart.quadrics[i]);
    let apart_plain = mesh(&apart, 0.0);
    let short = shortest_edge(&apart_plain.mesh);
    assert!(short < 1e-15, "{short}");
    let twice = mesh(&apart, ponq_mesh::mesher::DEFAULT_WELD);
    assert!(twice.stats.meshed_twice);
    assert!(twice.stats.welded >= corners.len());
    let short = shortest_edge(&twice.mesh);
    assert!(short > 1e-6, "{short}");
    // On the PoNQ without copies the weld changes nothing.
    let (a, b) = (
        mesh(&base, 0.0),
        mesh(&base, ponq_mesh::mesher::DEFAULT_WELD),
    );
    assert_eq!(b.stats.welded, 0);
    assert_eq!(a.mesh.faces, b.mesh.faces);
    assert_eq!(a.mesh.vertices, b.mesh.vertices);
    // A negative or non-finite tolerance is an error, not a silent default.
    for bad in [-1e-12, f64::NAN, f64::INFINITY] {
        let r = mesh_ponq(
            &base,
            &MeshingOptions {
                weld: bad,
                ..Default::default()
            },
        );
        assert!(
            matches!(r, Err(ponq_mesh::Error::InvalidInput(_))),
            "weld {bad}"
        );
    }
}
