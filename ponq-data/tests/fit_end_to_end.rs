//! ponq-fit end to end on a shipped CAD mesh and on an open surface.

use ponq_data::fit::{FitOptions, fit_mesh};
use ponq_data::normalize::Normalization;
use ponq_data::sampling::{boundary_edges, sample_boundary};
use ponq_mesh::metrics::{MetricOptions, compare};
use ponq_mesh::{TriMesh, io, validity};

fn shipped(name: &str) -> TriMesh {
    let p = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../examples")
        .join(name);
    io::read_mesh(&p).expect("shipped example mesh")
}

/// The paper's protocol (100k samples): fewer samples raise the CD floor and lower F1.
fn metric_opts() -> MetricOptions {
    MetricOptions::default()
}

#[test]
fn fit_a_cad_part_is_watertight_and_close() {
    let gt = shipped("example001.obj");
    let opts = FitOptions {
        grid: 32,
        samples: Some(40_000),
        iterations: 150,
        ..Default::default()
    };
    let f = fit_mesh(&gt, &opts, |_| {}).expect("fit");
    let report = validity::check(&f.meshing.mesh);
    assert!(report.is_valid(), "{report}");
    let pred = f.normalization.invert_mesh(&f.meshing.mesh);
    let m = compare(&pred, &gt, &metric_opts());
    // The authors' mesher on a PoNQ of this part at 32^3 scores CD 1.14, NC 0.988, EF1 0.95
    // (shared reference data); a rounded marching-cubes surface has far lower EF1.
    assert!(m.cd_x1e5 < 2.0, "{m:?}");
    assert!(m.nc > 0.97, "{m:?}");
    assert!(m.ef1 > 0.6, "{m:?}");
}

/// An open cup: the lower half of a UV sphere with a single pole vertex (boundary: the
/// equator).
fn cup(n: usize) -> TriMesh {
    let rings = n / 2;
    let mut v = Vec::new();
    let mut f = Vec::new();
    // Rings 0 (equator) .. rings-1, then the south pole.
    for i in 0..rings {
        let th = std::f64::consts::PI * (0.5 + 0.5 * i as f64 / rings as f64);
        for j in 0..n {
            let ph = std::f64::consts::TAU * j as f64 / n as f64;
            v.push([th.sin() * ph.cos(), th.sin() * ph.sin(), th.cos()]);
        }
    }
    let pole = v.len() as u32;
    v.push([0.0, 0.0, -1.0]);
    for i in 0..rings {
        for j in 0..n {
            let a = (i * n + j) as u32;
            let b = (i * n + (j + 1) % n) as u32;
            if i + 1 < rings {
                let (c, d) = (a + n as u32, b + n as u32);
                f.push([a, c, b]);
                f.push([b, c, d]);
            } else {
                f.push([a, pole, b]);
            }
        }
    }
    TriMesh::new(v, f).unwrap()
}

#[test]
fn boundary_samples_have_rotated_normals() {
    let m = cup(24);
    let b = boundary_edges(&m);
    assert_eq!(b.len(), 24, "the equator");
    let s = sample_boundary(&m, 100, 3);
    assert_eq!(s.points.len(), 200);
    for k in 0..100 {
        let (n0, n1) = (s.normals[2 * k], s.normals[2 * k + 1]);
        let d = n0[0] * n1[0] + n0[1] * n1[1] + n0[2] * n1[2];
        assert!(d.abs() < 1e-9, "the copy's normal is rotated by 90 degrees");
        // On the equator of the cup, the rotated normal points up (out of the surface).
        assert!(n1[2] > 0.9, "{n1:?}");
    }
}

/// The open-surface culling of the paper is a heuristic (a triangle survives when one of its
/// vertices is not anisotropic): on some seeds a flap of triangles stays across the rim. The
/// guarantees (embedded, no non-manifold edge, an open rim) hold on every seed; the quality
/// bound is asserted on the median of three seeds.
#[test]
fn open_surface_fit_keeps_the_hole_open() {
    let gt = cup(48);
    let norm = Normalization::of(&gt).unwrap();
    let rim = norm.apply([0.0, 0.0, 0.0])[2];
    let mut cds = Vec::new();
    for seed in 0..3 {
        let opts = FitOptions {
            grid: 32,
            samples: Some(40_000),
            iterations: 150,
            open: FitOptions::open_default(),
            seed,
            ..Default::default()
        };
        let f = fit_mesh(&gt, &opts, |_| {}).expect("fit");
        let r = validity::check(&f.meshing.mesh);
        assert_eq!(r.self_intersections, 0, "{r}");
        assert_eq!(r.nonmanifold_edges, 0, "{r}");
        assert!(r.boundary_edges > 0, "the cup's rim must stay open: {r}");
        // Nothing is left above the rim (the closed mesh would cap the cup there).
        let above = f
            .meshing
            .mesh
            .faces
            .iter()
            .filter(|t| {
                let z = t
                    .iter()
                    .map(|&i| f.meshing.mesh.vertices[i as usize][2])
                    .sum::<f64>()
                    / 3.0;
                z > rim + 0.05
            })
            .count();
        assert_eq!(above, 0);
        let pred = norm.invert_mesh(&f.meshing.mesh);
        let m = compare(&pred, &gt, &metric_opts());
        assert!(m.nc > 0.9, "{m:?}");
        cds.push(m.cd_x1e5);
    }
    cds.sort_by(f64::total_cmp);
    assert!(cds[1] < 3.0, "median CD over seeds: {cds:?}");
}

#[test]
fn bad_inputs_are_errors() {
    let empty = TriMesh::default();
    assert!(fit_mesh(&empty, &FitOptions::default(), |_| {}).is_err());
    let gt = shipped("example001.obj");
    for grid in [0usize, 1, 5000] {
        let o = FitOptions {
            grid,
            ..Default::default()
        };
        assert!(fit_mesh(&gt, &o, |_| {}).is_err());
    }
    // A single degenerate triangle has no area.
    let flat = TriMesh::new(
        vec![[0.0; 3], [1.0, 0.0, 0.0], [2.0, 0.0, 0.0]],
        vec![[0, 1, 2]],
    )
    .unwrap();
    assert!(fit_mesh(&flat, &FitOptions::default(), |_| {}).is_err());
}
