//! Property test of the mesher on adversarial PoNQs: coordinates snapped to coarse lattices
//! (co-planar and co-spherical ties everywhere), duplicated points, points on and outside the
//! domain box, coordinates tiny next to the others, zero and random normals, degenerate
//! quadrics, with and without the weld. The output must always be valid
//! (closed, oriented, manifold, no self-intersection, checked exactly) or empty with a message.

use ponq_mesh::mesher::{MAX_COORDINATE, MeshingOptions, mesh_ponq};
use ponq_mesh::{Ponq, Quadric, validity};
use proptest::prelude::*;

fn coord() -> impl Strategy<Value = f64> {
    prop_oneof![
        // Coarse lattice values, including the domain faces and beyond.
        (-5i32..=5).prop_map(|i| i as f64 * 0.25),
        -1.2f64..1.2,
        // Tiny next to the others (subnormals among them): the exact predicates' products
        // would underflow there (the Delaunay sets them to 0); huge ones: refused.
        prop::sample::select(vec![
            5e-324,
            -5e-324,
            f64::MIN_POSITIVE,
            1e-200,
            -1e-60,
            1e25,
            1e100,
            -3e40
        ]),
    ]
}

fn normal() -> impl Strategy<Value = [f64; 3]> {
    prop_oneof![
        Just([0.0, 0.0, 0.0]),
        (0usize..6).prop_map(|a| {
            let mut n = [0.0; 3];
            n[a / 2] = if a % 2 == 0 { 1.0 } else { -1.0 };
            n
        }),
        prop::array::uniform3(-1.0f64..1.0),
    ]
}

fn quadric_u() -> impl Strategy<Value = [f64; 6]> {
    prop_oneof![
        Just([0.0; 6]),
        Just([1.0, 0.0, 0.0, 0.0, 0.0, 0.0]),
        prop::array::uniform6(-1.5f64..1.5),
    ]
}

fn ponq() -> impl Strategy<Value = Ponq> {
    prop::collection::vec(
        (
            prop::array::uniform3(coord()),
            normal(),
            quadric_u(),
            1usize..3,
        ),
        0..50,
    )
    .prop_map(|pts| {
        let (mut p, mut n, mut q) = (Vec::new(), Vec::new(), Vec::new());
        for (x, nn, u, copies) in pts {
            for _ in 0..copies {
                p.push(x);
                n.push(nn);
                q.push(Quadric::from_a_vstar(Quadric::a_from_upper(u), x));
            }
        }
        Ponq::new(p.clone(), n, q, Some(p)).expect("finite by construction")
    })
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 192, ..ProptestConfig::default() })]

    #[test]
    fn mesher_output_is_always_valid_or_empty(
        p in ponq(),
        grid in prop_oneof![Just(4.0f64), Just(8.0), Just(32.0)],
        manifold in any::<bool>(),
        weld in prop_oneof![Just(0.0f64), Just(1e-10)],
    ) {
        let opts = MeshingOptions { grid_scale: grid, manifold, weld, ..Default::default() };
        let beyond = p.points.iter().flatten().any(|c| c.abs() > MAX_COORDINATE);
        let out = match mesh_ponq(&p, &opts) {
            Err(e) => {
                // Only v* beyond the exact predicates' range are refused, with a clear error.
                prop_assert!(beyond && e.to_string().contains("rescale the input"), "{}", e);
                return Ok(());
            }
            Ok(out) => out,
        };
        prop_assert!(!beyond, "v* beyond {:e} meshed", MAX_COORDINATE);
        if out.mesh.faces.is_empty() {
            prop_assert!(out.message.is_some());
        } else {
            let r = validity::check(&out.mesh);
            prop_assert_eq!(r.self_intersections, 0, "{}", r);
            prop_assert_eq!(r.boundary_edges, 0, "{}", r);
            prop_assert_eq!(r.degenerate_faces, 0, "{}", r);
            if manifold {
                prop_assert!(r.is_valid(), "{}", r);
            }
        }
    }
}
