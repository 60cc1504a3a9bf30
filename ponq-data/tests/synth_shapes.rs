//! The procedural CAD-like shapes of `ponq_data::synth` on 220 seeds: every mesh is valid
//! (closed, oriented, manifold, no self-intersection: exact check), non-empty and normalised;
//! the analytic samples lie on the mesh and their normals agree with the CSG solid; the same
//! seed gives the same shape; the set is varied (primitive kinds, holes / genus > 0, sharp
//! edges of dihedral angles other than 90 degrees).
//!
//! The tests use smaller settings than the defaults (mesh resolution 48 instead of 96, 1,500
//! instead of 100,000 returned samples, 8 instead of 16 samples per cell, 20,000 instead of
//! 100,000 Monte-Carlo volume points) so that the debug-profile run stays well under a minute
//! on two cores.

use std::collections::{BTreeMap, BTreeSet};

use ponq_data::synth::geom::point_triangle_dist2;
use ponq_data::synth::{SynthOptions, SynthShape, generate};
use ponq_mesh::bvh::{Aabb, Bvh};
use ponq_mesh::vec3::{cross, dot, norm, sub};
use ponq_mesh::{TriMesh, validity};

const SEEDS: u64 = 220;
const RES: usize = 48;

fn test_opts() -> SynthOptions {
    SynthOptions {
        mesh_resolution: RES,
        samples: 1_500,
        samples_per_cell: 8.0,
        volume_samples: 20_000,
        ..Default::default()
    }
}

/// Distances from `points` to the mesh surface.
fn distances_to_mesh(mesh: &TriMesh, points: &[[f64; 3]]) -> Vec<f64> {
    let boxes: Vec<Aabb> = (0..mesh.faces.len())
        .map(|f| Aabb::from_points(&mesh.triangle(f)))
        .collect();
    let bvh = Bvh::build(&boxes);
    points
        .iter()
        .map(|&p| {
            bvh.nearest(p, |f| {
                let [a, b, c] = mesh.triangle(f);
                point_triangle_dist2(p, a, b, c)
            })
            .map_or(f64::INFINITY, |x| x.1.sqrt())
        })
        .collect()
}

/// Whether the solid is planar around the sample `(p, n)`: points at 0.005 and 0.01 from `p`
/// in eight tangent directions are inside just below the tangent plane and outside just above
/// it (a curved surface leaves the plane by more than the 1e-6 probe).
fn planar_at(s: &SynthShape, p: [f64; 3], n: [f64; 3]) -> bool {
    let a = if n[0].abs() < 0.6 {
        [1.0, 0.0, 0.0]
    } else {
        [0.0, 1.0, 0.0]
    };
    let t1 = cross(n, a);
    let l = norm(t1);
    let t1 = t1.map(|x| x / l);
    let t2 = cross(n, t1);
    (0..8).all(|k| {
        let (sn, cs) = (k as f64 * std::f64::consts::FRAC_PI_4).sin_cos();
        [0.005, 0.01].iter().all(|&r| {
            let q: [f64; 3] = std::array::from_fn(|i| p[i] + r * (cs * t1[i] + sn * t2[i]));
            s.inside(std::array::from_fn(|i| q[i] - 1e-6 * n[i]))
                && !s.inside(std::array::from_fn(|i| q[i] + 1e-6 * n[i]))
        })
    })
}

/// Whether two planar pieces of the surface less than 0.1 apart meet at an angle away from
/// 90 degrees (their normals 20 to 80 or 100 to 160 degrees apart): evidence, from the exact
/// solid, of sharp edges with dihedral angles other than 90 degrees.
fn has_non_right_planar_angles(s: &SynthShape) -> bool {
    let planar: Vec<usize> = (0..s.samples.len())
        .filter(|&i| planar_at(s, s.samples[i], s.normals[i]))
        .collect();
    planar.iter().enumerate().any(|(a, &i)| {
        planar[a + 1..].iter().any(|&j| {
            if norm(sub(s.samples[i], s.samples[j])) > 0.1 {
                return false;
            }
            let t = dot(s.normals[i], s.normals[j])
                .clamp(-1.0, 1.0)
                .acos()
                .to_degrees();
            (20.0..=80.0).contains(&t) || (100.0..=160.0).contains(&t)
        })
    })
}

/// Every per-shape property; returns the largest and the mean sample-to-mesh distance (in
/// cells) and the fraction of samples beyond half a cell.
fn check_shape(seed: u64, s: &SynthShape, opts: &SynthOptions) -> [f64; 3] {
    let m = &s.mesh;
    assert!(!m.faces.is_empty(), "seed {seed}: empty mesh");
    let report = validity::check(m);
    assert!(report.is_valid(), "seed {seed}: {report}");
    assert_eq!(report.unreferenced_vertices, 0, "seed {seed}");

    // Normalised: bounding box centred at the origin with diagonal 2.
    let (lo, hi) = m.bounding_box().unwrap();
    let diag = norm(sub(hi, lo));
    assert!((diag - 2.0).abs() < 1e-9, "seed {seed}: diagonal {diag}");
    for k in 0..3 {
        assert!(
            (lo[k] + hi[k]).abs() < 1e-9,
            "seed {seed}: box {lo:?}..{hi:?}"
        );
    }

    // Samples: count, unit normals, agreement with the CSG solid.
    assert_eq!(s.samples.len(), opts.samples, "seed {seed}");
    assert_eq!(s.normals.len(), opts.samples, "seed {seed}");
    let eps = 1e-8;
    for (p, n) in s.samples.iter().zip(&s.normals) {
        assert!((norm(*n) - 1.0).abs() < 1e-9, "seed {seed}: normal {n:?}");
        let inner = std::array::from_fn(|k| p[k] - eps * n[k]);
        let outer = std::array::from_fn(|k| p[k] + eps * n[k]);
        assert!(
            s.inside(inner) && !s.inside(outer),
            "seed {seed}: sample {p:?} normal {n:?} disagrees with the solid"
        );
    }

    // The analytic samples lie on the mesh: cell = 2 / RES of the meshing frame, which is at
    // most 2 / 1.9 times larger in the [-1,1] frame.
    let cell = 2.0 / RES as f64 * (2.0 / 1.9);
    let d = distances_to_mesh(m, &s.samples);
    let max = d.iter().copied().fold(0.0, f64::max);
    let mean = d.iter().sum::<f64>() / d.len() as f64;
    let far = d.iter().filter(|&&x| x > 0.5 * cell).count() as f64 / d.len() as f64;
    assert!(
        mean < 0.1 * cell,
        "seed {seed}: mean sample distance {mean}"
    );
    assert!(
        far < 0.02,
        "seed {seed}: {far} of the samples beyond half a cell"
    );
    assert!(max < 2.0 * cell, "seed {seed}: sample {max} from the mesh");

    // The mesh encloses the CSG's volume (Monte-Carlo) within the accepted tolerance.
    let rel = (s.stats.mesh_volume - s.stats.csg_volume).abs() / s.stats.csg_volume;
    assert!(rel < 0.08, "seed {seed}: volume {:?}", s.stats);
    assert!(s.description.lines().count() >= s.solid.primitives().len());
    [max / cell, mean / cell, far]
}

#[test]
fn many_seeds_give_valid_normalised_faithful_and_varied_shapes() {
    let opts = test_opts();
    let t = std::time::Instant::now();
    let mut kinds: BTreeMap<&str, usize> = BTreeMap::new();
    let mut features: BTreeMap<String, usize> = BTreeMap::new();
    let mut with_genus = 0;
    let mut with_difference = 0;
    let mut with_other_angles = 0;
    let mut attempts = 0;
    let mut faces = 0;
    let mut worst = [0.0f64; 3];
    for seed in 0..SEEDS {
        let s = generate(seed, &opts).unwrap_or_else(|e| panic!("seed {seed}: {e}"));
        let d = check_shape(seed, &s, &opts);
        for k in 0..3 {
            worst[k] = worst[k].max(d[k]);
        }
        let non_right = has_non_right_planar_angles(&s);
        attempts += s.attempts;
        faces += s.mesh.faces.len();
        let set: BTreeSet<&str> = s.primitive_kinds().into_iter().collect();
        for k in set {
            *kinds.entry(k).or_default() += 1;
        }
        let roles: BTreeSet<String> = s.solid.labels().iter().cloned().collect();
        for r in roles {
            *features.entry(r).or_default() += 1;
        }
        with_genus += usize::from(s.stats.genus > 0);
        with_difference += usize::from(s.description.contains("difference("));
        with_other_angles += usize::from(non_right);
        println!(
            "seed {seed}: {} attempts, {} faces, genus {}, non-right planar angles {non_right}",
            s.attempts,
            s.mesh.faces.len(),
            s.stats.genus
        );
    }
    println!(
        "{SEEDS} shapes in {:.1}s ({attempts} designs), {} faces on average; kinds {kinds:?}; \
         features {features:?}; \
         genus > 0: {with_genus}; with differences: {with_difference}; \
         non-right sharp edges: {with_other_angles}; worst sample-to-mesh distance \
         {:.3} cells, worst mean {:.3} cells, worst fraction beyond half a cell {:.4}",
        t.elapsed().as_secs_f64(),
        faces / SEEDS as usize,
        worst[0],
        worst[1],
        worst[2],
    );
    let n = SEEDS as usize;
    for k in [
        "box", "cylinder", "cone", "sphere", "torus", "prism", "slot",
    ] {
        assert!(
            kinds.get(k).copied().unwrap_or(0) >= n / 20,
            "kind {k} in too few shapes: {kinds:?}"
        );
    }
    for f in ["hole", "plane cut", "rib", "pocket", "boss"] {
        assert!(
            features.get(f).copied().unwrap_or(0) >= n / 20,
            "feature {f} in too few shapes: {features:?}"
        );
    }
    assert!(with_genus >= n / 4, "{with_genus} shapes with genus > 0");
    assert!(
        with_difference >= n / 2,
        "{with_difference} shapes with holes/cuts"
    );
    assert!(
        with_other_angles >= n / 5,
        "{with_other_angles} shapes with non-right edges"
    );
    // Most designs are accepted at once.
    assert!(attempts < 2 * n as u32, "{attempts} designs for {n} shapes");
}

#[test]
fn the_same_seed_gives_the_same_shape_bit_for_bit() {
    let opts = test_opts();
    for seed in [3, 1_000_003, u64::MAX] {
        let a = generate(seed, &opts).unwrap();
        let b = generate(seed, &opts).unwrap();
        assert_eq!(a.mesh, b.mesh, "seed {seed}");
        let bits =
            |v: &[[f64; 3]]| -> Vec<[u64; 3]> { v.iter().map(|p| p.map(f64::to_bits)).collect() };
        assert_eq!(bits(&a.samples), bits(&b.samples), "seed {seed}");
        assert_eq!(bits(&a.normals), bits(&b.normals), "seed {seed}");
        assert_eq!(a.description, b.description, "seed {seed}");
        assert_eq!(a.solid, b.solid, "seed {seed}");
    }
    let a = generate(5, &opts).unwrap();
    let b = generate(6, &opts).unwrap();
    assert_ne!(a.mesh, b.mesh);
}

#[test]
fn bad_options_are_rejected() {
    for opts in [
        SynthOptions {
            mesh_resolution: 2,
            ..test_opts()
        },
        SynthOptions {
            samples_per_cell: 0.0,
            ..test_opts()
        },
        SynthOptions {
            max_primitives: 0,
            ..test_opts()
        },
    ] {
        assert!(generate(0, &opts).is_err(), "{opts:?}");
    }
}
