//! Tests of `ponq_mesh::validity`: topology defects on small built meshes, exact
//! triangle/triangle intersection cases, and property tests of the exact test.

use std::collections::HashMap;

use ponq_mesh::TriMesh;
use ponq_mesh::validity::{
    ValidityReport, check, check_topology, faces_intersect, intersecting_face_pairs,
    intersecting_face_pairs_among, triangles_intersect,
};
use ponq_mesh::vec3::{cross, dot, sub};
use proptest::prelude::*;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

// ----- mesh builders -----

fn tetrahedron() -> TriMesh {
    TriMesh::new(
        vec![[0., 0., 0.], [1., 0., 0.], [0., 1., 0.], [0., 0., 1.]],
        vec![[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]],
    )
    .unwrap()
}

fn octahedron() -> TriMesh {
    let vertices = vec![
        [1., 0., 0.],
        [-1., 0., 0.],
        [0., 1., 0.],
        [0., -1., 0.],
        [0., 0., 1.],
        [0., 0., -1.],
    ];
    let mut faces = Vec::new();
    for sx in [0u32, 1] {
        for sy in [0u32, 1] {
            for sz in [0u32, 1] {
                let (x, y, z) = (sx, 2 + sy, 4 + sz);
                // Outward iff the octant has an even number of negative signs.
                if (sx + sy + sz) % 2 == 0 {
                    faces.push([x, y, z]);
                } else {
                    faces.push([x, z, y]);
                }
            }
        }
    }
    TriMesh::new(vertices, faces).unwrap()
}

/// Axis-aligned cube `[origin, origin + size]`, each face an `n x n` grid of quads split in
/// two triangles, shared vertices, outward orientation.
fn cube(n: usize, origin: [f64; 3], size: f64) -> TriMesh {
    let mut index: HashMap<[usize; 3], u32> = HashMap::new();
    let mut vertices = Vec::new();
    let mut vid = |g: [usize; 3]| -> u32 {
        *index.entry(g).or_insert_with(|| {
            vertices.push(std::array::from_fn(|k| {
                origin[k] + size * g[k] as f64 / n as f64
            }));
            (vertices.len() - 1) as u32
        })
    };
    let mut faces = Vec::new();
    for axis in 0..3 {
        for side in [0, n] {
            // (u, v) with u x v = outward normal.
            let (mut u, mut v) = ((axis + 1) % 3, (axis + 2) % 3);
            if side == 0 {
                std::mem::swap(&mut u, &mut v);
            }
            for i in 0..n {
                for j in 0..n {
                    let corner = |di: usize, dj: usize| {
                        let mut g = [0; 3];
                        g[axis] = side;
                        g[u] = i + di;
                        g[v] = j + dj;
                        g
                    };
                    let (c00, c10, c11, c01) = (
                        vid(corner(0, 0)),
                        vid(corner(1, 0)),
                        vid(corner(1, 1)),
                        vid(corner(0, 1)),
                    );
                    faces.push([c00, c10, c11]);
                    faces.push([c00, c11, c01]);
                }
            }
        }
    }
    TriMesh::new(vertices, faces).unwrap()
}

/// Disjoint union; with `merge`, vertices of `b` at exactly the position of a vertex of `a`
/// are replaced by that vertex.
fn union(a: &TriMesh, b: &TriMesh, merge: bool) -> TriMesh {
    let mut vertices = a.vertices.clone();
    let mut faces = a.faces.clone();
    let map: Vec<u32> = b
        .vertices
        .iter()
        .map(|p| {
            if merge && let Some(i) = a.vertices.iter().position(|q| q == p) {
                return i as u32;
            }
            vertices.push(*p);
            (vertices.len() - 1) as u32
        })
        .collect();
    faces.extend(b.faces.iter().map(|f| f.map(|v| map[v as usize])));
    TriMesh::new(vertices, faces).unwrap()
}

fn assert_valid(m: &TriMesh, what: &str) -> ValidityReport {
    let r = check(m);
    assert!(r.is_valid(), "{what}: {r}");
    assert!(r.is_watertight());
    assert!(r.closed && r.oriented && r.manifold, "{what}: {r:?}");
    assert_eq!(
        r.to_string(),
        "valid (closed, oriented, manifold, no self-intersection)"
    );
    r
}

// ----- meshes -----

#[test]
fn valid_closed_meshes() {
    assert_valid(&tetrahedron(), "tetrahedron");
    assert_valid(&octahedron(), "octahedron");
    assert_valid(&cube(1, [0.; 3], 1.0), "cube 1");
    let r = assert_valid(&cube(6, [-0.3, 0.1, 0.7], 2.5), "cube 6");
    assert_eq!(r.degenerate_faces, 0);
    assert_eq!(r.coincident_vertices, 0);
    // Non-dyadic coordinates: still exact.
    assert_valid(&cube(5, [0.1, 0.2, 0.3], 0.7), "cube 5 non-dyadic");
    let t = check_topology(&cube(3, [0.; 3], 1.0));
    assert!(t.is_valid() && !t.self_intersections_checked);
    assert!(t.to_string().contains("not checked"), "{t}");
}

#[test]
fn empty_and_unreferenced() {
    let r = check(&TriMesh::default());
    assert!(r.is_valid(), "{r}");
    let m = TriMesh::new(vec![[0.; 3], [1.; 3]], vec![]).unwrap();
    let r = check(&m);
    assert!(r.is_valid());
    assert_eq!(r.unreferenced_vertices, 2);
    assert!(r.to_string().ends_with("; 2 unreferenced vertices"), "{r}");
    let mut t = tetrahedron();
    t.vertices.push([5.; 3]);
    t.vertices.push([0.; 3]); // unreferenced duplicate of vertex 0: not a coincidence defect
    let r = check(&t);
    assert!(r.is_valid(), "{r}");
    assert_eq!(r.unreferenced_vertices, 2);
    assert_eq!(r.coincident_vertices, 0);
}

#[test]
fn flipped_face_is_not_oriented() {
    let mut m = cube(3, [0.; 3], 1.0);
    m.faces[7].swap(1, 2);
    let r = check(&m);
    assert!(r.closed && r.manifold && !r.oriented, "{r:?}");
    assert!(!r.is_valid());
    assert_eq!(r.self_intersections, 0);
    assert_eq!(r.to_string(), "invalid: not oriented");
}

#[test]
fn removed_face_gives_three_boundary_edges() {
    let mut m = octahedron();
    m.faces.remove(3);
    let r = check(&m);
    assert!(!r.closed && !r.oriented && !r.manifold);
    assert_eq!(r.boundary_edges, 3);
    assert_eq!(r.nonmanifold_edges, 0);
    assert_eq!(r.nonmanifold_vertices, 0);
    assert_eq!(r.to_string(), "invalid: 3 boundary edges");
}

#[test]
fn cubes_glued_at_an_edge() {
    let a = cube(1, [0., 0., 0.], 1.0);
    let b = cube(1, [1., 1., 0.], 1.0);
    let m = union(&a, &b, true);
    assert_eq!(m.vertices.len(), 14);
    let r = check(&m);
    assert_eq!(r.nonmanifold_edges, 1, "{r:?}");
    assert_eq!(r.boundary_edges, 0);
    assert!(!r.closed && !r.manifold && !r.is_valid());
    assert_eq!(r.self_intersections, 0, "{r:?}");
    assert_eq!(r.coincident_vertices, 0);
    assert!(r.to_string().contains("1 non-manifold edge"), "{r}");
}

#[test]
fn tetrahedra_sharing_a_vertex() {
    let a = tetrahedron();
    let mut b = tetrahedron();
    for p in &mut b.vertices {
        *p = p.map(|x| -x);
    }
    for f in &mut b.faces {
        f.swap(1, 2); // the reflection flipped the orientation
    }
    let m = union(&a, &b, true);
    assert_eq!(m.vertices.len(), 7);
    let r = check(&m);
    assert!(r.closed && r.oriented && !r.manifold, "{r:?}");
    assert_eq!(r.nonmanifold_vertices, 1);
    assert_eq!(r.nonmanifold_edges, 0);
    assert_eq!(r.self_intersections, 0);
    assert_eq!(r.to_string(), "invalid: 1 non-manifold vertex");
}

#[test]
fn interpenetrating_cubes() {
    let a = cube(2, [0., 0., 0.], 1.0);
    let b = cube(2, [0.5, 0.3, 0.2], 1.0);
    let m = union(&a, &b, false);
    let r = check(&m);
    assert!(r.closed && r.oriented && r.manifold, "{r:?}");
    assert_eq!(r.coincident_vertices, 0);
    assert!(r.self_intersections > 0);
    assert!(!r.is_valid());
    let pairs = intersecting_face_pairs(&m);
    assert_eq!(pairs.len(), r.self_intersections);
    let na = a.faces.len();
    for &(i, j) in &pairs {
        assert!(
            i < na && j >= na,
            "only faces of different cubes cross: {i} {j}"
        );
        assert!(faces_intersect(&m, i, j) && faces_intersect(&m, j, i));
    }
    assert!(check_topology(&m).is_valid());
}

/// The pairs found from a subset of faces are exactly the full list's pairs that involve the
/// subset, for subsets on both cubes, on one, of one face, with repeats, and empty.
#[test]
fn intersecting_pairs_among_a_subset_match_the_full_list() {
    let a = cube(3, [0., 0., 0.], 1.0);
    let b = cube(2, [0.5, 0.3, 0.2], 1.0);
    let m = union(&a, &b, false);
    let all = intersecting_face_pairs(&m);
    assert!(!all.is_empty());
    let mut rng = ChaCha8Rng::seed_from_u64(5);
    let n = m.faces.len();
    let mut subsets: Vec<Vec<usize>> = vec![
        Vec::new(),
        (0..n).collect(),
        (0..a.faces.len()).collect(),
        vec![all[0].0],
        vec![all[0].1, all[0].1, all[0].0],
    ];
    for _ in 0..20 {
        let k = rng.random_range(1..n);
        subsets.push((0..k).map(|_| rng.random_range(0..n)).collect());
    }
    for sub in subsets {
        let expect: Vec<(usize, usize)> = all
            .iter()
            .copied()
            .filter(|&(i, j)| sub.contains(&i) || sub.contains(&j))
            .collect();
        assert_eq!(
            intersecting_face_pairs_among(&m, &sub),
            expect,
            "subset {sub:?}"
        );
    }
}

#[test]
fn cubes_touching_on_a_face_with_separate_vertices() {
    let a = cube(1, [0., 0., 0.], 1.0);
    let b = cube(1, [1., 0., 0.], 1.0);
    let m = union(&a, &b, false);
    let r = check(&m);
    assert!(r.closed && r.oriented && r.manifold);
    assert_eq!(r.coincident_vertices, 8, "{r:?}");
    assert!(r.self_intersections > 0);
    assert!(!r.is_valid());
    let s = r.to_string();
    assert!(
        s.contains("8 coincident vertices") && s.contains("self-intersecting"),
        "{s}"
    );

    // Separated by one ulp-scale gap (~1.1e-15): valid.
    let b = cube(1, [1.0 + 1e-15, 0., 0.], 1.0);
    assert!(b.vertices.iter().all(|p| p[0] > 1.0));
    assert_valid(&union(&a, &b, false), "near miss");
}

#[test]
fn degenerate_and_duplicate_faces() {
    let mut m = tetrahedron();
    m.faces.push(m.faces[0]);
    let r = check(&m);
    assert_eq!(r.self_intersections, 1, "{r:?}");
    assert_eq!(r.nonmanifold_edges, 3);

    let mut m = tetrahedron();
    m.faces.push([0, 0, 1]);
    let r = check(&m);
    assert_eq!(r.degenerate_faces, 1);
    assert!(!r.is_valid());

    // Exactly collinear corners (all three axis projections vanish) vs an almost collinear
    // triangle (last coordinate one ulp away).
    let m = TriMesh::new(
        vec![
            [1., 2., 3.],
            [2., 4., 6.],
            [3., 6., 9.],
            [3., 6., 9.000000000000002],
        ],
        vec![[0, 1, 2], [0, 1, 3]],
    )
    .unwrap();
    let r = check(&m);
    assert_eq!(r.degenerate_faces, 1, "{r:?}");
    // Coincident referenced vertices of a closed mesh.
    let mut t = tetrahedron();
    t.vertices.push([0.; 3]);
    t.faces[0][0] = 4; // face [4, 2, 1] uses a copy of vertex 0
    let r = check(&t);
    assert_eq!(r.coincident_vertices, 2, "{r:?}");
    assert!(!r.is_valid());
}

// ----- exact triangle / triangle cases -----

fn t(a: [f64; 3], b: [f64; 3], c: [f64; 3]) -> [[f64; 3]; 3] {
    [a, b, c]
}

const BASE: [[f64; 3]; 3] = [[0., 0., 0.], [1., 0., 0.], [0., 1., 0.]];

#[test]
fn touching_at_a_single_point() {
    // Vertex on the interior of the other triangle.
    let up = t([0.25, 0.25, 0.], [0.25, 0.25, 1.], [1., 1., 1.]);
    assert!(triangles_intersect(&BASE, &up));
    let lifted = t([0.25, 0.25, 1e-15], [0.25, 0.25, 1.], [1., 1., 1.]);
    assert!(!triangles_intersect(&BASE, &lifted));
    let sunk = t([0.25, 0.25, -1e-15], [0.25, 0.25, 1.], [1., 1., 1.]);
    assert!(triangles_intersect(&BASE, &sunk), "crossing");
    // Vertex on an edge (hypotenuse).
    let on_edge = t([0.5, 0.5, 0.], [0.5, 0.5, 1.], [2., 2., 1.]);
    assert!(triangles_intersect(&BASE, &on_edge));
    let off_edge = t([0.5, 0.5 + 1e-15, 0.], [0.5, 0.5, 1.], [2., 2., 1.]);
    assert!(!triangles_intersect(&BASE, &off_edge));
    // Edge touching edge at one point, transverse planes.
    let e = t([0.5, -1., 1.], [0.5, 1., -1.], [0.5, -3., -3.]);
    assert!(triangles_intersect(&BASE, &e));
    let e_off = t(
        [0.5, -1. - 1e-15, 1.],
        [0.5, 1. - 1e-15, -1.],
        [0.5, -3., -3.],
    );
    assert!(!triangles_intersect(&BASE, &e_off));
    // Vertex on vertex.
    let vv = t([1., 0., 0.], [2., 0., 1.], [2., 1., 1.]);
    assert!(triangles_intersect(&BASE, &vv));
    // Non-dyadic coordinates: a point exactly on an axis-parallel edge.
    let tn = t([0.1, 0.2, 0.3], [0.1, 0.2, 0.7], [0.9, 0.4, 0.5]);
    let pn = t([0.1, 0.2, 0.5], [-0.3, 0.3, 0.1], [-0.2, -0.6, 0.9]);
    assert!(triangles_intersect(&tn, &pn));
    let pn_off = t([0.1, 0.2 - 1e-15, 0.5], [-0.3, 0.3, 0.1], [-0.2, -0.6, 0.9]);
    assert!(!triangles_intersect(&tn, &pn_off));
}

#[test]
fn coplanar_cases() {
    let shifted = t([0.2, 0.2, 0.], [1.2, 0.2, 0.], [0.2, 1.2, 0.]);
    assert!(triangles_intersect(&BASE, &shifted), "overlap");
    let inside = t([0.1, 0.1, 0.], [0.3, 0.1, 0.], [0.1, 0.3, 0.]);
    assert!(triangles_intersect(&BASE, &inside), "containment");
    assert!(triangles_intersect(&inside, &BASE));
    let star = t([0.5, -0.2, 0.], [0.5, 0.8, 0.], [-0.5, 0.3, 0.]);
    assert!(
        triangles_intersect(&BASE, &star),
        "edges crossing, no vertex inside"
    );
    let edge_touch = t([1., 0., 0.], [0., 1., 0.], [1., 1., 0.]);
    assert!(
        triangles_intersect(&BASE, &edge_touch),
        "shared edge geometrically"
    );
    let gap = t([0.5 + 1e-15, 0.5, 0.], [1., 1., 0.], [1.5, 0.5, 0.]);
    assert!(!triangles_intersect(&BASE, &gap), "1e-15 gap");
    let touch = t([0.5, 0.5, 0.], [1., 1., 0.], [1.5, 0.5, 0.]);
    assert!(triangles_intersect(&BASE, &touch));
    // Coplanar in a vertical plane (z projection degenerate).
    let va = t([0., 0., 0.], [1., 1., 0.], [0., 0., 1.]);
    let vb = t([0.5, 0.5, 0.5], [2., 2., 0.], [2., 2., 2.]);
    let vc = t([0.6, 0.6, 0.5], [2., 2., 0.], [2., 2., 2.]);
    assert!(triangles_intersect(&va, &vb));
    assert!(!triangles_intersect(&va, &vc));
    // Parallel planes 1e-15 apart.
    let par = t([0., 0., 1e-15], [1., 0., 1e-15], [0., 1., 1e-15]);
    assert!(!triangles_intersect(&BASE, &par));
}

// ----- properties -----

fn permutations(tr: &[[f64; 3]; 3]) -> [[[f64; 3]; 3]; 6] {
    let [a, b, c] = *tr;
    [
        [a, b, c],
        [b, c, a],
        [c, a, b],
        [a, c, b],
        [c, b, a],
        [b, a, c],
    ]
}

fn assert_symmetric_invariant(a: &[[f64; 3]; 3], b: &[[f64; 3]; 3]) -> bool {
    let r = triangles_intersect(a, b);
    for pa in permutations(a) {
        for pb in permutations(b) {
            assert_eq!(triangles_intersect(&pa, &pb), r, "{a:?} {b:?}");
            assert_eq!(triangles_intersect(&pb, &pa), r, "{a:?} {b:?}");
        }
    }
    r
}

/// Floating-point separating-axis reference: `Some(false)` when some axis separates the
/// triangles by more than `margin`, `Some(true)` when they overlap by more than `margin` on
/// every candidate axis (face normals, edge x edge, normal x edge: complete for triangles),
/// `None` when undecided.
fn sat_reference(a: &[[f64; 3]; 3], b: &[[f64; 3]; 3], margin: f64) -> Option<bool> {
    let ea: [[f64; 3]; 3] = std::array::from_fn(|k| sub(a[(k + 1) % 3], a[k]));
    let eb: [[f64; 3]; 3] = std::array::from_fn(|k| sub(b[(k + 1) % 3], b[k]));
    let (na, nb) = (cross(ea[0], ea[1]), cross(eb[0], eb[1]));
    let mut axes = vec![na, nb];
    for (&a_edge, &b_edge) in ea.iter().zip(&eb) {
        for &other in &eb {
            axes.push(cross(a_edge, other));
        }
        axes.push(cross(na, a_edge));
        axes.push(cross(nb, b_edge));
    }
    let mut all_overlap = true;
    for ax in axes {
        let len = dot(ax, ax).sqrt();
        if len < 1e-6 {
            // Nearly parallel edges: the axis is unreliable, give up.
            return None;
        }
        let u = ax.map(|x| x / len);
        let pa = a.map(|p| dot(p, u));
        let pb = b.map(|p| dot(p, u));
        let (amin, amax) = (
            pa.iter().copied().fold(f64::INFINITY, f64::min),
            pa.iter().copied().fold(f64::NEG_INFINITY, f64::max),
        );
        let (bmin, bmax) = (
            pb.iter().copied().fold(f64::INFINITY, f64::min),
            pb.iter().copied().fold(f64::NEG_INFINITY, f64::max),
        );
        let gap = (bmin - amax).max(amin - bmax);
        if gap > margin {
            return Some(false);
        }
        if gap > -margin {
            all_overlap = false;
        }
    }
    all_overlap.then_some(true)
}

fn random_triangle(rng: &mut ChaCha8Rng, center: [f64; 3], r: f64) -> [[f64; 3]; 3] {
    std::array::from_fn(|_| std::array::from_fn(|k| center[k] + rng.random_range(-r..r)))
}

#[test]
fn agrees_with_float_reference_on_clear_cases() {
    let mut rng = ChaCha8Rng::seed_from_u64(42);
    let (mut yes, mut no) = (0, 0);
    for _ in 0..20_000 {
        let a = random_triangle(&mut rng, [0.; 3], 1.0);
        let c: [f64; 3] = std::array::from_fn(|_| rng.random_range(-0.6..0.6));
        let b = random_triangle(&mut rng, c, 1.0);
        if let Some(want) = sat_reference(&a, &b, 1e-6) {
            assert_eq!(triangles_intersect(&a, &b), want, "{a:?} {b:?}");
            assert_eq!(triangles_intersect(&b, &a), want);
            if want { yes += 1 } else { no += 1 }
        }
    }
    assert!(yes > 2000 && no > 2000, "{yes} {no}");

    // Constructed crossings: an edge of `b` pierces `a` deep inside.
    for _ in 0..2000 {
        let a = random_triangle(&mut rng, [0.; 3], 1.0);
        let w: [f64; 3] = std::array::from_fn(|_| rng.random_range(0.2..1.0));
        let s = w[0] + w[1] + w[2];
        let inner: [f64; 3] =
            std::array::from_fn(|k| (w[0] * a[0][k] + w[1] * a[1][k] + w[2] * a[2][k]) / s);
        let n = cross(sub(a[1], a[0]), sub(a[2], a[0]));
        let nl = dot(n, n).sqrt();
        if nl < 1e-3 {
            continue;
        }
        let (up, down) = (rng.random_range(0.1..1.0), rng.random_range(0.1..1.0));
        let d: [f64; 3] = std::array::from_fn(|k| n[k] / nl);
        let b = [
            std::array::from_fn(|k| inner[k] + up * d[k]),
            std::array::from_fn(|k| inner[k] - down * d[k]),
            std::array::from_fn(|k| inner[k] + rng.random_range(-1.0..1.0)),
        ];
        assert!(triangles_intersect(&a, &b), "{a:?} {b:?}");
        assert!(triangles_intersect(&b, &a));
        // The same triangle moved far along the normal is clearly disjoint.
        let far = b.map(|p| std::array::from_fn(|k| p[k] + 5.0 * n[k] / nl));
        assert!(!triangles_intersect(&a, &far));
    }
}

fn grid_triangle() -> impl Strategy<Value = [[f64; 3]; 3]> {
    // Small integer grid: many exactly touching, coplanar and degenerate configurations.
    prop::array::uniform3(prop::array::uniform3(
        (-2i32..=2).prop_map(|x| x as f64 * 0.5),
    ))
}

fn float_triangle() -> impl Strategy<Value = [[f64; 3]; 3]> {
    prop::array::uniform3(prop::array::uniform3(-1.0f64..1.0))
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 400, ..ProptestConfig::default() })]

    #[test]
    fn symmetric_and_permutation_invariant_on_grid(a in grid_triangle(), b in grid_triangle()) {
        assert_symmetric_invariant(&a, &b);
    }

    #[test]
    fn symmetric_and_permutation_invariant_random(a in float_triangle(), b in float_triangle()) {
        let r = assert_symmetric_invariant(&a, &b);
        if let Some(want) = sat_reference(&a, &b, 1e-9) {
            prop_assert_eq!(r, want);
        }
    }

    #[test]
    fn translation_by_exact_offsets(a in grid_triangle(), b in grid_triangle(), off in prop::array::uniform3((-8i32..8).prop_map(|x| x as f64))) {
        // Integer translations of half-integer coordinates are exact: same answer.
        let m = |t: [[f64; 3]; 3]| t.map(|p| std::array::from_fn(|k| p[k] + off[k]));
        prop_assert_eq!(triangles_intersect(&a, &b), triangles_intersect(&m(a), &m(b)));
    }

    #[test]
    fn mesh_check_is_invariant_under_face_rotation(rot in prop::collection::vec(0usize..3, 72), n in 1usize..4) {
        let mut m = cube(n, [0.1, -0.2, 0.3], 1.3);
        let base = check(&m);
        for (f, r) in m.faces.iter_mut().zip(rot.iter().cycle()) {
            f.rotate_left(*r);
        }
        prop_assert_eq!(check(&m), base);
    }
}

// ----- certified fans (`ponq_mesh::fan`) against the pair-by-pair rule -----

/// A closed torus of `nu * nv` quads split into triangles, vertices moved by `jitter` (a
/// random offset of up to `scale`, then rounded to multiples of `snap` when `snap > 0`, which
/// makes coplanar faces, collinear rays and exact ties), and every `fold_every`-th vertex
/// pushed through the tube to beyond its far side (faces through the surface, folded fans).
fn jittered_torus(
    nu: usize,
    nv: usize,
    seed: u64,
    scale: f64,
    snap: f64,
    fold_every: usize,
) -> TriMesh {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let mut vertices = Vec::with_capacity(nu * nv);
    for i in 0..nu {
        let u = i as f64 / nu as f64 * std::f64::consts::TAU;
        for j in 0..nv {
            let v = j as f64 / nv as f64 * std::f64::consts::TAU;
            let rr = 2.0 + 0.8 * v.cos();
            let mut p = [rr * u.cos(), rr * u.sin(), 0.8 * v.sin()];
            for x in &mut p {
                *x += rng.random_range(-scale..=scale);
                if snap > 0.0 {
                    *x = (*x / snap).round() * snap;
                }
            }
            if fold_every > 0 && (i * nv + j).is_multiple_of(fold_every) {
                // Through the surface: the opposite side of the tube's centre line.
                let c = [2.0 * u.cos(), 2.0 * u.sin(), 0.0];
                p = std::array::from_fn(|k| c[k] - 1.3 * (p[k] - c[k]));
            }
            vertices.push(p);
        }
    }
    let id = |i: usize, j: usize| ((i % nu) * nv + j % nv) as u32;
    let mut faces = Vec::with_capacity(2 * nu * nv);
    for i in 0..nu {
        for j in 0..nv {
            let (a, b, c, d) = (id(i, j), id(i + 1, j), id(i + 1, j + 1), id(i, j + 1));
            if rng.random_bool(0.5) {
                faces.push([a, b, c]);
                faces.push([a, c, d]);
            } else {
                faces.push([a, b, d]);
                faces.push([b, c, d]);
            }
        }
    }
    TriMesh::new(vertices, faces).unwrap()
}

/// Every intersecting pair by the pair-by-pair rule (`faces_intersect`, no hierarchy, no
/// certified fans).
fn brute_force_pairs(m: &TriMesh) -> Vec<(usize, usize)> {
    let n = m.faces.len();
    (0..n)
        .flat_map(|i| (i + 1..n).map(move |j| (i, j)))
        .filter(|&(i, j)| faces_intersect(m, i, j))
        .collect()
}

#[test]
fn certified_fans_give_the_pairs_of_the_pair_by_pair_rule() {
    // Smooth, rough, snapped to coarse lattices (ties everywhere), folded; each kind of fan
    // is certified or not somewhere, and the whole-mesh answer must not change.
    let mut kinds = [0usize; 4];
    for seed in 0..24u64 {
        let (scale, snap, fold) = match seed % 6 {
            0 => (0.0, 0.0, 0),
            1 => (0.05, 0.0, 0),
            2 => (0.5, 0.0, 0),
            3 => (0.1, 0.25, 0),
            4 => (0.0, 0.5, 0),
            _ => (0.05, 0.0, 7),
        };
        let m = jittered_torus(10, 7, seed, scale, snap, fold);
        let want = brute_force_pairs(&m);
        assert_eq!(intersecting_face_pairs(&m), want, "seed {seed}");
        assert_eq!(check(&m).self_intersections, want.len(), "seed {seed}");
        let fans = ponq_mesh::fan::graph_fans(&m.vertices, &m.faces);
        let certified = fans.iter().filter(|&&c| c).count();
        kinds[0] += (certified == fans.len()) as usize;
        kinds[1] += (certified > 0 && certified < fans.len()) as usize;
        let shares = |&(i, j): &(usize, usize)| m.faces[i].iter().any(|v| m.faces[j].contains(v));
        kinds[2] += want.iter().any(shares) as usize;
        kinds[3] += want.iter().any(|p| !shares(p)) as usize;
    }
    // The cases are not all alike: all fans certified, some not, and self-intersecting
    // pairs that share a vertex or an edge, and pairs that do not.
    assert!(kinds.iter().all(|&k| k > 0), "{kinds:?}");
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 48, ..ProptestConfig::default() })]

    #[test]
    fn certified_fans_agree_with_the_rule_on_random_tori(
        seed in any::<u64>(),
        scale in prop::sample::select(vec![0.0, 0.02, 0.1, 0.3, 0.6]),
        snap in prop::sample::select(vec![0.0, 0.125, 0.5]),
        fold in prop::sample::select(vec![0usize, 3, 11]),
    ) {
        let m = jittered_torus(8, 6, seed, scale, snap, fold);
        prop_assert_eq!(intersecting_face_pairs(&m), brute_force_pairs(&m));
    }
}
