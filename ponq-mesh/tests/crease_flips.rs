//! Crease-aligned diagonals (`ponq_mesh::flips`): on PoNQs of boxes clustered by grid cells
//! (lattice-like, so the Delaunay diagonals are decided by the symbolic perturbation), the
//! flips bring the mesh closer to the true surface along its edges, never break validity, and
//! are deterministic.

mod common;

use common::*;
use ponq_mesh::TriMesh;
use ponq_mesh::mesher::{MeshingOptions, mesh_ponq};
use ponq_mesh::validity;

/// Distance from `p` to the surface of the axis-aligned box `lo..hi`.
fn box_distance(p: [f64; 3], lo: [f64; 3], hi: [f64; 3]) -> f64 {
    let c: [f64; 3] = std::array::from_fn(|k| 0.5 * (lo[k] + hi[k]));
    let h: [f64; 3] = std::array::from_fn(|k| 0.5 * (hi[k] - lo[k]));
    let d: [f64; 3] = std::array::from_fn(|k| (p[k] - c[k]).abs() - h[k]);
    let out = d.iter().map(|x| x.max(0.0).powi(2)).sum::<f64>().sqrt();
    (out + d[0].max(d[1]).max(d[2]).min(0.0)).abs()
}

/// Mean distance of the edge midpoints to the box surface, and how many are farther than
/// `far`.
fn edge_error(m: &TriMesh, lo: [f64; 3], hi: [f64; 3], far: f64) -> (f64, usize) {
    let mut sum = 0.0;
    let mut n = 0;
    let mut bad = 0;
    for f in &m.faces {
        for k in 0..3 {
            let (a, b) = (
                m.vertices[f[k] as usize],
                m.vertices[f[(k + 1) % 3] as usize],
            );
            let mid: [f64; 3] = std::array::from_fn(|i| 0.5 * (a[i] + b[i]));
            let d = box_distance(mid, lo, hi);
            sum += d;
            n += 1;
            if d > far {
                bad += 1;
            }
        }
    }
    (sum / n as f64, bad)
}

#[test]
fn flips_follow_the_box_edges_and_keep_the_mesh_valid() {
    let mut better = 0;
    for (seed, (lo, hi), grid) in [
        (1, ([-0.61, -0.43, -0.52], [0.57, 0.49, 0.38]), 16),
        (2, ([-0.71, -0.33, -0.27], [0.66, 0.41, 0.55]), 24),
        (3, ([-0.5, -0.5, -0.5], [0.5, 0.5, 0.5]), 16),
    ] {
        let s = box_samples(lo, hi, 60_000, &mut rng(seed));
        let ponq = ponq_by_grid(&s, grid);
        let opts = |align| MeshingOptions {
            grid_scale: grid as f64,
            align_creases: align,
            ..Default::default()
        };
        let with = mesh_ponq(&ponq, &opts(true)).unwrap();
        let without = mesh_ponq(&ponq, &opts(false)).unwrap();
        assert_eq!(without.stats.flips.flips, 0);
        for out in [&with, &without] {
            let r = validity::check(&out.mesh);
            assert!(r.is_valid(), "seed {seed}: {r}");
        }
        assert_eq!(
            with.mesh.vertices, without.mesh.vertices,
            "flips keep the vertices"
        );
        assert_eq!(with.mesh.faces.len(), without.mesh.faces.len());
        let far = 0.05 * 2.0 / grid as f64;
        let (e_with, bad_with) = edge_error(&with.mesh, lo, hi, far);
        let (e_without, bad_without) = edge_error(&without.mesh, lo, hi, far);
        assert!(
            e_with <= e_without * (1.0 + 1e-12),
            "seed {seed}: mean edge error {e_with} with flips vs {e_without}"
        );
        assert!(
            bad_with <= bad_without,
            "seed {seed}: {bad_with} vs {bad_without}"
        );
        if with.stats.flips.flips > 0 && e_with < e_without {
            better += 1;
        }
        // Deterministic.
        let again = mesh_ponq(&ponq, &opts(true)).unwrap();
        assert_eq!(again.mesh.faces, with.mesh.faces);
    }
    assert!(better >= 1, "the flips improved no box");
}
