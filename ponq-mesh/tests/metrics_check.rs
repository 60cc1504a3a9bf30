//! Metrics against brute force and on meshes with known answers.

use ponq_mesh::TriMesh;
use ponq_mesh::metrics::{
    MetricOptions, chamfer_f1, compare, grid_frame_to_gt, unit_diagonal_transform,
};
use ponq_mesh::sampling::{sample_edges, sample_surface, sharp_edges};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

fn cube(lo: [f64; 3], hi: [f64; 3]) -> TriMesh {
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
        [0, 2, 3, 1],
        [4, 5, 7, 6],
        [0, 1, 5, 4],
        [2, 6, 7, 3],
        [0, 4, 6, 2],
        [1, 3, 7, 5],
    ];
    let mut f = Vec::new();
    for q in quads {
        f.push([q[0], q[1], q[2]]);
        f.push([q[0], q[2], q[3]]);
    }
    TriMesh::new(v, f).unwrap()
}

fn octahedron(r: f64) -> TriMesh {
    let v = vec![
        [r, 0.0, 0.0],
        [-r, 0.0, 0.0],
        [0.0, r, 0.0],
        [0.0, -r, 0.0],
        [0.0, 0.0, r],
        [0.0, 0.0, -r],
    ];
    let f = vec![
        [0, 2, 4],
        [2, 1, 4],
        [1, 3, 4],
        [3, 0, 4],
        [2, 0, 5],
        [1, 2, 5],
        [3, 1, 5],
        [0, 3, 5],
    ];
    TriMesh::new(v, f).unwrap()
}

fn brute(a: &[[f64; 3]], b: &[[f64; 3]], tau: f64) -> (f64, f64) {
    let one = |x: &[[f64; 3]], y: &[[f64; 3]]| -> Vec<f64> {
        x.iter()
            .map(|p| {
                y.iter()
                    .map(|q| (p[0] - q[0]).powi(2) + (p[1] - q[1]).powi(2) + (p[2] - q[2]).powi(2))
                    .fold(f64::MAX, f64::min)
            })
            .collect()
    };
    let ab = one(a, b);
    let ba = one(b, a);
    let mean = |v: &[f64]| v.iter().sum::<f64>() / v.len() as f64;
    let frac = |v: &[f64]| v.iter().filter(|&&d| d < tau * tau).count() as f64 / v.len() as f64;
    let (r, p) = (frac(&ab), frac(&ba));
    (
        mean(&ab) + mean(&ba),
        if r + p > 0.0 {
            2.0 * r * p / (r + p)
        } else {
            0.0
        },
    )
}

#[test]
fn chamfer_and_f1_equal_brute_force() {
    let mut rng = ChaCha8Rng::seed_from_u64(3);
    for case in 0..20 {
        let n = 50 + case * 20;
        let a: Vec<[f64; 3]> = (0..n)
            .map(|_| std::array::from_fn(|_| rng.random_range(-0.5..0.5)))
            .collect();
        let b: Vec<[f64; 3]> = (0..n + 7)
            .map(|_| std::array::from_fn(|_| rng.random_range(-0.5..0.5)))
            .collect();
        let tau = 0.05 + 0.01 * case as f64;
        let (cd, f1, _) = chamfer_f1(&a, &b, tau);
        let (cd2, f12) = brute(&a, &b, tau);
        assert!((cd - cd2).abs() <= 1e-12 * cd2.max(1e-30), "{cd} vs {cd2}");
        assert!((f1 - f12).abs() < 1e-12, "{f1} vs {f12}");
    }
    assert_eq!(chamfer_f1(&[], &[[0.0; 3]], 0.1).0, f64::INFINITY);
}

#[test]
fn sharp_edges_of_a_cube_and_samples_on_them() {
    let c = cube([0.0; 3], [1.0; 3]);
    let e = sharp_edges(&c, 30.0);
    assert_eq!(e.len(), 12, "the 12 cube edges, not the flat diagonals");
    let s = sample_edges(&c, &e, 1000, 1);
    assert_eq!(s.len(), 1000);
    for p in &s {
        // On a cube edge: at least two coordinates are 0 or 1.
        let on = p
            .iter()
            .filter(|&&x| x.abs() < 1e-12 || (x - 1.0).abs() < 1e-12)
            .count();
        assert!(on >= 2, "{p:?}");
    }
    assert!(sharp_edges(&octahedron(1.0), 100.0).is_empty());
}

#[test]
fn surface_samples_are_on_the_surface_and_seeded() {
    let c = cube([0.0; 3], [1.0; 3]);
    let s = sample_surface(&c, 5000, 9);
    assert_eq!(s.points.len(), 5000);
    for (p, n) in s.points.iter().zip(&s.normals) {
        let on = p
            .iter()
            .filter(|&&x| x.abs() < 1e-12 || (x - 1.0).abs() < 1e-12)
            .count();
        assert!(on >= 1);
        assert!((n[0] * n[0] + n[1] * n[1] + n[2] * n[2] - 1.0).abs() < 1e-12);
    }
    assert_eq!(
        sample_surface(&c, 100, 9).points,
        sample_surface(&c, 100, 9).points
    );
    // Area weighting: each of the 6 faces gets about 1/6 of the samples.
    let top = s
        .points
        .iter()
        .filter(|p| (p[2] - 1.0).abs() < 1e-12)
        .count();
    assert!((top as f64 / 5000.0 - 1.0 / 6.0).abs() < 0.03);
}

#[test]
fn identical_meshes_score_well_and_a_shift_scores_worse() {
    let gt = cube([-0.3, -0.2, -0.1], [0.4, 0.3, 0.2]);
    let opts = MetricOptions {
        surface_samples: 20_000,
        edge_samples: 20_000,
        ..Default::default()
    };
    let same = compare(&gt, &gt, &opts);
    // Two independent samplings of one surface: the floor of the protocol at 20k samples
    // (mean spacing ~0.009 at unit diagonal) is a few units of CD x1e5.
    assert!(same.cd_x1e5 < 8.0, "{same:?}");
    assert!(same.nc > 0.97, "{same:?}");
    assert!(same.ecd_x1e2 < 1e-3 && same.ef1 > 0.95, "{same:?}");
    assert_eq!(same.watertight, Some(true));
    let mut last = same;
    for d in [0.01, 0.03, 0.1] {
        let moved = gt.clone().translated([d, d, d]);
        let m = compare(&moved, &gt, &opts);
        assert!(
            m.cd_x1e5 > last.cd_x1e5 && m.ecd_x1e2 > last.ecd_x1e2,
            "{m:?} vs {last:?}"
        );
        last = m;
    }
    assert!(
        last.f1 < 0.5 * same.f1 && last.ef1 < 0.5 * same.ef1,
        "{last:?}"
    );
    // No sharp edges on either side: ECD 0, EF1 1 (the single origin point convention).
    let smooth = TriMesh::default();
    let e = compare(&smooth, &gt, &opts);
    assert_eq!((e.cd_x1e5, e.f1), (f64::INFINITY, 0.0));
}

#[test]
fn grid_frame_maps_back_to_the_gt_frame() {
    let gt = cube([1.0, 2.0, 3.0], [3.0, 3.0, 4.0]);
    let (c, s) = unit_diagonal_transform(&gt).unwrap();
    // The gt in the [-1,1] convention (diagonal 2), mapped back, is the gt.
    let grid = ponq_mesh::metrics::transformed(&gt, c, 2.0 * s);
    let back = grid_frame_to_gt(&grid, &gt).unwrap();
    for (p, q) in back.vertices.iter().zip(&gt.vertices) {
        for k in 0..3 {
            assert!((p[k] - q[k]).abs() < 1e-12);
        }
    }
}
