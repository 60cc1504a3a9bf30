//! Refinement against exact distances (`ponq_data::refine`): the distance check accepts
//! exact and truncated grids and rejects scaled, smoothed and noisy ones; samples read off an
//! exact grid lie on the surface; a refit puts v* on the edges the samples describe; v* leave
//! the nodes' balls; a refinement round is kept only when it fits the distances better, and
//! it improves a perturbed PoNQ of a CAD-like part.

use ponq_data::refine::{
    DistanceGrid, GridSamples, RefineOptions, check_distance, clear_balls, fit_residual,
    grid_samples, refine, refit,
};
use ponq_data::sdf::MeshSdf;
use ponq_mesh::mesher::{MeshingOptions, mesh_ponq};
use ponq_mesh::metrics::{MetricOptions, compare};
use ponq_mesh::vec3::{cross, dot, sub};
use ponq_mesh::{Ponq, Quadric, TriMesh, validity};

/// A box rotated off the axes (so that no face lies on grid planes), in [-1,1]^3.
fn tilted_box() -> TriMesh {
    let (a, b, c) = (0.55, 0.4, 0.3);
    let corners: Vec<[f64; 3]> = (0..8)
        .map(|i| {
            let p = [
                if i & 1 == 0 { -a } else { a },
                if i & 2 == 0 { -b } else { b },
                if i & 4 == 0 { -c } else { c },
            ];
            rotate(p)
        })
        .collect();
    let faces = vec![
        [0, 2, 1],
        [1, 2, 3],
        [4, 5, 6],
        [5, 7, 6],
        [0, 1, 4],
        [1, 5, 4],
        [2, 6, 3],
        [3, 6, 7],
        [0, 4, 2],
        [2, 4, 6],
        [1, 3, 5],
        [3, 7, 5],
    ];
    TriMesh {
        vertices: corners,
        faces,
    }
}

fn rotate(p: [f64; 3]) -> [f64; 3] {
    let (s1, c1) = 0.37f64.sin_cos();
    let (s2, c2) = 0.23f64.sin_cos();
    let q = [c1 * p[0] - s1 * p[1], s1 * p[0] + c1 * p[1], p[2]];
    [q[0], c2 * q[1] - s2 * q[2], s2 * q[1] + c2 * q[2]]
}

/// Signed distances of `mesh` on a grid of `res` cells over [-1,1]^3 (f64).
fn exact_grid(mesh: &TriMesh, res: usize) -> Vec<f64> {
    let g = MeshSdf::new(mesh).unwrap().grid(res, |_| {}).unwrap();
    g.values.iter().map(|&v| f64::from(v)).collect()
}

fn grid_of(values: &[f64], res: usize) -> DistanceGrid<'_> {
    DistanceGrid::new([res + 1; 3], [-1.0; 3], 2.0 / res as f64, values).unwrap()
}

/// A 3x3x3 box blur (a smoothed field).
fn blurred(v: &[f64], n: usize) -> Vec<f64> {
    let idx = |i: usize, j: usize, k: usize| (i * n + j) * n + k;
    let mut out = v.to_vec();
    for i in 1..n - 1 {
        for j in 1..n - 1 {
            for k in 1..n - 1 {
                let mut s = 0.0;
                for (a, b, c) in (0..27).map(|t| (t / 9, (t / 3) % 3, t % 3)) {
                    s += v[idx(i + a - 1, j + b - 1, k + c - 1)];
                }
                out[idx(i, j, k)] = s / 27.0;
            }
        }
    }
    out
}

#[test]
fn the_check_accepts_exact_and_truncated_grids_and_rejects_altered_ones() {
    let res = 24;
    let mesh = tilted_box();
    let exact = exact_grid(&mesh, res);
    let h = 2.0 / res as f64;
    let c = check_distance(&grid_of(&exact, res));
    assert!(c.is_distance(), "exact: {c}");
    let truncated: Vec<f64> = exact.iter().map(|v| v.clamp(-3.5 * h, 3.5 * h)).collect();
    let c = check_distance(&grid_of(&truncated, res));
    assert!(c.is_distance(), "truncated: {c}");
    for (name, field) in [
        (
            "scaled by 0.5",
            exact.iter().map(|v| 0.5 * v).collect::<Vec<_>>(),
        ),
        ("scaled by 2", exact.iter().map(|v| 2.0 * v).collect()),
        ("box-blurred", blurred(&exact, res + 1)),
        (
            "noisy",
            exact
                .iter()
                .enumerate()
                .map(|(i, v)| v + 0.15 * h * ((i as f64 * 12.9898).sin() * 43758.545).fract())
                .collect(),
        ),
    ] {
        let c = check_distance(&grid_of(&field, res));
        assert!(!c.is_distance(), "{name} passed: {c}");
    }
}

#[test]
fn samples_of_an_exact_grid_lie_on_the_surface() {
    let res = 20;
    let mesh = tilted_box();
    let values = exact_grid(&mesh, res);
    let grid = grid_of(&values, res);
    // Directions from the true surface: every sample is a closest point.
    let s = grid_samples(&grid, &mesh, &RefineOptions::default()).unwrap();
    assert!(s.band_nodes > 100);
    assert_eq!(
        s.dropped, 0,
        "no sample of an exact grid along exact directions is dropped"
    );
    assert!(
        s.residual < 1e-5,
        "the true surface fits its distances: {}",
        s.residual
    );
    let sdf = MeshSdf::new(&mesh).unwrap();
    for (p, n) in s.points.iter().zip(&s.normals) {
        assert!(sdf.distance(*p) < 1e-5, "sample {p:?} off the surface");
        assert!((n[0] * n[0] + n[1] * n[1] + n[2] * n[2] - 1.0).abs() < 1e-9);
    }
    // Nodes in the normal cones of the edges give samples on the edges: many samples lie on
    // two faces' planes at once.
    let on_edges = s
        .points
        .iter()
        .filter(|p| {
            let (_, n) = sdf.closest_point_and_normal(**p);
            mesh.faces
                .iter()
                .filter(|f| {
                    let [a, b, c] = f.map(|v| mesh.vertices[v as usize]);
                    let fnrm = cross(sub(b, a), sub(c, a));
                    let l = dot(fnrm, fnrm).sqrt();
                    (dot(sub(**p, a), fnrm) / l).abs() < 1e-6 && dot(fnrm, n) / l < 0.99
                })
                .count()
                > 0
        })
        .count();
    assert!(on_edges > 20, "{on_edges} samples on the edges");
}

#[test]
fn a_refit_puts_vstars_on_the_edge_its_samples_describe() {
    // Samples of two planes meeting at the edge x = 0, z = 0 (normals +z and +x), and a point
    // near the edge whose own quadric is a plane (the network's guess).
    let mut g = GridSamples::default();
    for i in 0..10 {
        let t = -0.05 + 0.01 * i as f64;
        g.points.push([-0.01, t, 0.0]);
        g.normals.push([0.0, 0.0, 1.0]);
        g.points.push([0.0, t, -0.01]);
        g.normals.push([1.0, 0.0, 0.0]);
    }
    let p = [-0.004, 0.0, -0.003];
    let ponq = Ponq::new(
        vec![p],
        vec![[0.7, 0.0, 0.7]],
        vec![Quadric::from_plane(p, [0.6, 0.0, 0.8])],
        None,
    )
    .unwrap();
    let opts = RefineOptions {
        prior: 0.0,
        ..Default::default()
    };
    let (r, stats) = refit(&ponq, &g, 0.1, &opts, None).unwrap();
    assert_eq!(stats.refitted, 1);
    let v = r.vstars()[0];
    assert!(
        v[0].abs() < 1e-12 && v[2].abs() < 1e-12,
        "v* {v:?} not on the edge"
    );
    assert!(
        (v[1] - p[1]).abs() < 1e-12,
        "v* slides along the edge: {v:?}"
    );
    // The quadric keeps the network's scale (trace of A).
    let (ta, tb) = (r.quadrics[0].a.trace(), ponq.quadrics[0].a.trace());
    assert!((ta - tb).abs() < 1e-12 * tb);
    // Sharing flags of the wrong length are an error, not a panic.
    assert!(refit(&ponq, &g, 0.1, &opts, Some(&[true, false])).is_err());
}

#[test]
fn vstars_leave_the_nodes_balls() {
    let res = 16;
    let mesh = tilted_box();
    let values = exact_grid(&mesh, res);
    let grid = grid_of(&values, res);
    // Near the box's centre: deep inside the balls of the nodes around it.
    let c = [0.01, 0.02, -0.01];
    let mut ponq = Ponq::new(
        vec![c],
        vec![[1.0, 0.0, 0.0]],
        vec![Quadric::identity_at(c)],
        None,
    )
    .unwrap();
    // Too deep for a move of at most a cell: it stays; with room to move, it leaves.
    assert_eq!(clear_balls(&grid, &mut ponq.clone(), 1.0), 0);
    assert_eq!(clear_balls(&grid, &mut ponq, 10.0), 1);
    let v = ponq.vstars()[0];
    let sdf = MeshSdf::new(&mesh).unwrap();
    // It moved towards the surface: within the nodes' spheres' tolerance of it.
    assert!(
        sdf.distance(v) < 0.3 * grid.h,
        "v* {v:?} at {} from the surface",
        sdf.distance(v)
    );
}

/// The tilted box in the [-1,1] convention and a PoNQ of it like a network's at `res` cells:
/// points near the surface (fitted to samples), each quadric a plane tilted from the truth by
/// a few degrees, so that v* miss the edges.
fn perturbed_box_ponq(res: usize) -> (TriMesh, Ponq) {
    let mesh = tilted_box();
    // fit_mesh works in the [-1,1] convention: take the truth there.
    let truth = ponq_data::normalize::Normalization::of(&mesh)
        .unwrap()
        .apply_mesh(&mesh);
    let fitted = ponq_data::fit::fit_mesh(
        &truth,
        &ponq_data::fit::FitOptions {
            grid: res,
            iterations: 100,
            ..Default::default()
        },
        |_| {},
    )
    .unwrap();
    let p = &fitted.ponq;
    let quadrics: Vec<Quadric> = p
        .points
        .iter()
        .zip(&p.normals)
        .enumerate()
        .map(|(i, (x, n))| {
            let t = 0.12 * ((i as f64 * 1.7).sin());
            Quadric::from_plane(*x, [n[0] + t, n[1] - t, n[2] + 0.5 * t])
        })
        .collect();
    let perturbed = Ponq::new(p.points.clone(), p.normals.clone(), quadrics, None).unwrap();
    (truth, perturbed)
}

#[test]
fn refinement_improves_a_perturbed_ponq_and_keeps_only_better_rounds() {
    let res = 16;
    let (truth, perturbed) = perturbed_box_ponq(res);
    let values = exact_grid(&truth, res);
    let grid = grid_of(&values, res);
    let mopts = MeshingOptions {
        grid_scale: res as f64,
        ..Default::default()
    };
    let base = mesh_ponq(&perturbed, &mopts).unwrap().mesh;
    let r = refine(
        &perturbed,
        &base,
        &grid,
        &RefineOptions::default(),
        None,
        |p| {
            let mut q = p.clone();
            clear_balls(&grid, &mut q, 1.0);
            Ok(mesh_ponq(&q, &mopts)?.mesh)
        },
    )
    .unwrap();
    assert!(r.rounds_kept >= 1, "no round kept: {:?}", r.residuals);
    // Kept rounds fit better than every round before them.
    for k in 1..=r.rounds_kept {
        assert!(r.residuals[k] < r.residuals[k - 1], "{:?}", r.residuals);
    }
    assert_eq!(
        fit_residual(&grid, &r.mesh, &RefineOptions::default()).unwrap(),
        r.residuals[r.rounds_kept]
    );
    assert!(validity::check(&r.mesh).is_valid());
    let m = MetricOptions {
        surface_samples: 20_000,
        edge_samples: 20_000,
        check_validity: false,
        ..Default::default()
    };
    let before = compare(&base, &truth, &m);
    let after = compare(&r.mesh, &truth, &m);
    assert!(after.cd_x1e5 < before.cd_x1e5, "CD {before:?} -> {after:?}");
    assert!(after.ef1 > before.ef1, "EF1 {before:?} -> {after:?}");
    // A grid that contradicts the PoNQ (twice the distances): no round fits it better than
    // the input, or the kept mesh still fits better than the input by the residual.
    let doubled: Vec<f64> = values.iter().map(|v| 2.0 * v).collect();
    let g2 = DistanceGrid::new(grid.dims, grid.lo, grid.h, &doubled).unwrap();
    let r2 = refine(
        &perturbed,
        &base,
        &g2,
        &RefineOptions::default(),
        None,
        |p| Ok(mesh_ponq(p, &mopts)?.mesh),
    )
    .unwrap();
    assert!(r2.residuals[r2.rounds_kept] <= r2.residuals[0]);
}

#[test]
fn default_sharing_radius_follows_the_grid() {
    // The PoNQ of a 16-cell grid refined against finer grids: `share: None` is
    // `RefineOptions::share_for` the grid's cells, 0.75 from 49 to 96 cells, 0.5 otherwise.
    assert_eq!(RefineOptions::share_for(128), 0.5);
    let (truth, perturbed) = perturbed_box_ponq(16);
    let mopts = MeshingOptions {
        grid_scale: 16.0,
        ..Default::default()
    };
    let base = mesh_ponq(&perturbed, &mopts).unwrap().mesh;
    let run = |grid: &DistanceGrid, share: Option<f64>| {
        let opts = RefineOptions {
            share,
            rounds: Some(1),
            ..Default::default()
        };
        let r = refine(&perturbed, &base, grid, &opts, None, |p| {
            Ok(mesh_ponq(p, &mopts)?.mesh)
        })
        .unwrap();
        r.residuals
    };
    for (res, share) in [(40, 0.5), (56, 0.75)] {
        assert_eq!(RefineOptions::share_for(res), share);
        let values = exact_grid(&truth, res);
        let grid = grid_of(&values, res);
        let default = run(&grid, None);
        assert_eq!(default, run(&grid, Some(share)), "{res} cells");
        // The radius matters on this input, so the comparison above could fail.
        let other = if share == 0.5 { 0.75 } else { 0.5 };
        assert_ne!(default, run(&grid, Some(other)), "{res} cells");
    }
}
