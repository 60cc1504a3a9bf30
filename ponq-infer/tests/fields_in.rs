//! Any field in: the shipped part's exact grid rewritten in people's conventions
//! (`ponq_data::conventions`) gives the exact grid's surface through `ponq-infer` (a distance
//! up to unit, sign and level within 0.01 of its F1; a monotone function of a distance with a
//! slope at its surface within 0.03), never below marching cubes on the same copy, never an
//! empty mesh, always a valid one; and the decisions a user must hear are said, or are errors.

use std::path::Path;

use ponq_data::conventions::Convention;
use ponq_data::normalize::Normalization;
use ponq_data::sdf::MeshSdf;
use ponq_mesh::io::npy::{Grid3, write_npy_grid_f32};
use ponq_mesh::marching_cubes::marching_cubes;
use ponq_mesh::metrics::{MetricOptions, compare};
use ponq_mesh::{TriMesh, io, validity};

mod common;
use common::{repo, run, tmp};

fn os(p: &Path) -> &std::ffi::OsStr {
    p.as_os_str()
}

/// The shipped CSG part, normalised, and its exact grid at `res` cells per side.
fn csg(res: usize) -> (TriMesh, Grid3) {
    let mesh = io::read_mesh(repo("examples/csg.obj")).unwrap();
    let truth = Normalization::of(&mesh).unwrap().apply_mesh(&mesh);
    let g = MeshSdf::new(&truth).unwrap().grid(res, |_| {}).unwrap();
    (truth, g.to_grid3())
}

fn f1(pred: &TriMesh, truth: &TriMesh) -> f64 {
    compare(
        pred,
        truth,
        &MetricOptions {
            surface_samples: 30_000,
            edge_samples: 30_000,
            check_validity: false,
            ..Default::default()
        },
    )
    .f1
}

#[test]
fn every_convention_gives_the_surface() {
    let d = tmp("fields");
    let res = 32;
    let h = 2.0 / res as f64;
    let (truth, exact) = csg(res);
    let mut exact_f1 = None;
    for c in Convention::BENCHMARK {
        let values = c.apply(&exact.data, h, 1);
        let grid = Grid3::new(exact.dims, values).unwrap();
        let path = d.join(format!("{}.npy", c.to_string().replace(':', "_")));
        write_npy_grid_f32(&path, &grid).unwrap();
        let out = d.join("out.obj");
        let mut args: Vec<&std::ffi::OsStr> = vec![os(&path), "-o".as_ref(), os(&out)];
        let level = c.level().map(|l| l.to_string());
        if let Some(l) = &level {
            args.push("--level".as_ref());
            args.push(l.as_ref());
        }
        let (code, text) = run(&args);
        assert_eq!(code, Some(0), "{c}: {text}");
        assert!(text.contains("field: "), "{c}: {text}");
        let mesh = io::read_mesh(&out).unwrap();
        assert!(!mesh.faces.is_empty(), "{c}");
        assert!(validity::check(&mesh).is_valid(), "{c}");
        let got = f1(&mesh, &truth);
        // Marching cubes on the same copy, at its level and with its sign.
        let (l, inside_above) = c.surface();
        let signed: Vec<f64> = grid
            .data
            .iter()
            .map(|&v| if inside_above { l - v } else { v - l })
            .collect();
        let mc = marching_cubes(&signed, grid.dims, [-1.0; 3], [1.0; 3]).unwrap();
        let mc_f1 = f1(&mc, &truth);
        assert!(
            got >= mc_f1,
            "{c}: F1 {got:.3} below marching cubes' {mc_f1:.3}"
        );
        let e = *exact_f1.get_or_insert(got);
        if c.is_distance_up_to_scale() {
            assert!(
                got >= e - 0.01,
                "{c}: F1 {got:.3}, the exact grid's {e:.3}: {text}"
            );
        }
        if matches!(c, Convention::Tanh | Convention::Sigmoid) {
            assert!(
                got >= e - 0.03,
                "{c}: F1 {got:.3}, the exact grid's {e:.3}: {text}"
            );
            assert!(text.contains("mapped to distances"), "{c}: {text}");
        }
        match c {
            Convention::Exact => assert!(text.contains("used as it is"), "{text}"),
            Convention::Voxel | Convention::Scale(_) => {
                assert!(text.contains("rescaled by"), "{c}: {text}")
            }
            Convention::InsidePositive => assert!(text.contains("sign flipped"), "{text}"),
            Convention::Sigmoid => assert!(text.contains("level 0.5"), "{text}"),
            _ => {}
        }
    }
    std::fs::remove_dir_all(&d).ok();
}

#[test]
fn decisions_that_cannot_be_made_are_clear_errors() {
    let d = tmp("fields-errors");
    let (_, exact) = csg(16);
    let n = exact.dims[0];
    let out = d.join("out.obj");
    // A half space through the middle: the boundary on both sides.
    let half: Vec<f64> = (0..n * n * n)
        .map(|i| (i / (n * n)) as f64 / (n - 1) as f64 * 2.0 - 1.0 - 0.03)
        .collect();
    let p = d.join("half.npy");
    write_npy_grid_f32(&p, &Grid3::new([n; 3], half).unwrap()).unwrap();
    let (code, text) = run(&[os(&p), "-o".as_ref(), os(&out)]);
    assert_eq!(code, Some(2), "{text}");
    assert!(text.contains("both sides of the level"), "{text}");
    assert!(text.contains("--inside"), "{text}");
    assert!(!out.exists());
    // Told which side is inside, it meshes.
    let (code, text) = run(&[
        os(&p),
        "-o".as_ref(),
        os(&out),
        "--inside".as_ref(),
        "negative".as_ref(),
    ]);
    assert_eq!(code, Some(0), "{text}");
    std::fs::remove_file(&out).unwrap();
    // No sign change at the level: exit 4, the values' range, what to try.
    let p2 = d.join("shifted.npy");
    let shifted: Vec<f64> = exact.data.iter().map(|v| v + 10.0).collect();
    write_npy_grid_f32(&p2, &Grid3::new(exact.dims, shifted).unwrap()).unwrap();
    let (code, text) = run(&[os(&p2), "-o".as_ref(), os(&out)]);
    assert_eq!(code, Some(4), "{text}");
    assert!(
        text.contains("no sign change") && text.contains("--level"),
        "{text}"
    );
    let (code, text) = run(&[
        os(&p2),
        "-o".as_ref(),
        os(&out),
        "--level".as_ref(),
        "10".as_ref(),
    ]);
    assert_eq!(code, Some(0), "{text}");
    assert!(text.contains("level 10"), "{text}");
    std::fs::remove_file(&out).unwrap();
    // Flags of grids are refused with a mesh input.
    let (code, text) = run(&[
        os(&repo("examples/csg.obj")),
        "-o".as_ref(),
        os(&out),
        "--level".as_ref(),
        "0.5".as_ref(),
    ]);
    assert_eq!(code, Some(2), "{text}");
    assert!(text.contains("for grids"), "{text}");
    std::fs::remove_dir_all(&d).ok();
}

#[test]
fn unequal_node_counts_take_cubic_cells() {
    let d = tmp("fields-unequal");
    // A sphere of radius 0.5 on 33 x 17 x 25 nodes of spacing 1/16, centred.
    let dims = [33, 17, 25];
    let h = 2.0 / 32.0;
    let mut data = Vec::new();
    for i in 0..dims[0] {
        for j in 0..dims[1] {
            for k in 0..dims[2] {
                let p = [i, j, k]
                    .iter()
                    .zip(dims)
                    .map(|(&x, n)| (x as f64 - (n - 1) as f64 / 2.0) * h)
                    .collect::<Vec<_>>();
                data.push((p[0] * p[0] + p[1] * p[1] + p[2] * p[2]).sqrt() - 0.4);
            }
        }
    }
    let p = d.join("sphere.npy");
    write_npy_grid_f32(&p, &Grid3::new(dims, data).unwrap()).unwrap();
    let out = d.join("out.obj");
    let (code, text) = run(&[os(&p), "-o".as_ref(), os(&out)]);
    assert_eq!(code, Some(0), "{text}");
    let mesh = io::read_mesh(&out).unwrap();
    assert!(validity::check(&mesh).is_valid());
    // Centred on the origin with the radius it has in those cubic cells.
    for v in &mesh.vertices {
        let r = (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt();
        assert!((r - 0.4).abs() < 0.5 * h, "{v:?}: {r}");
    }
    std::fs::remove_dir_all(&d).ok();
}

/// A true signed distance is used as it is: the measured reading gives the same file, byte for
/// byte, as taking the values as distances without measuring. A hard 0/1 voxel grid (no
/// distance in it at all) is re-distanced to its zero set: a valid mesh, not the whole grid in
/// the band.
#[test]
fn exact_grids_pass_through_and_binary_voxels_are_redistanced() {
    let d = tmp("fields-exact");
    for g in ["examples/csg_sdf_33.npy", "examples/example001_sdf_65.npy"] {
        let (a, b) = (d.join("auto.obj"), d.join("distance.obj"));
        let (code, text) = run(&[os(&repo(g)), "-o".as_ref(), os(&a)]);
        assert_eq!(code, Some(0), "{text}");
        assert!(text.contains("used as it is"), "{text}");
        let (code, text) = run(&[
            os(&repo(g)),
            "-o".as_ref(),
            os(&b),
            "--field".as_ref(),
            "distance".as_ref(),
        ]);
        assert_eq!(code, Some(0), "{text}");
        assert_eq!(
            std::fs::read(&a).unwrap(),
            std::fs::read(&b).unwrap(),
            "{g}"
        );
    }
    let (truth, exact) = csg(32);
    let voxels: Vec<f64> = exact
        .data
        .iter()
        .map(|&v| if v < 0.0 { 1.0 } else { 0.0 })
        .collect();
    let p = d.join("voxels.npy");
    write_npy_grid_f32(&p, &Grid3::new(exact.dims, voxels.clone()).unwrap()).unwrap();
    let out = d.join("voxels.obj");
    let (code, text) = run(&[os(&p), "-o".as_ref(), os(&out)]);
    assert_eq!(code, Some(0), "{text}");
    assert!(text.contains("re-distanced"), "{text}");
    assert!(text.contains("level 0.5"), "{text}");
    let mesh = io::read_mesh(&out).unwrap();
    assert!(validity::check(&mesh).is_valid());
    let signed: Vec<f64> = voxels.iter().map(|v| 0.5 - v).collect();
    let mc = marching_cubes(&signed, exact.dims, [-1.0; 3], [1.0; 3]).unwrap();
    assert!(f1(&mesh, &truth) >= f1(&mc, &truth) - 0.02, "{text}");
    std::fs::remove_dir_all(&d).ok();
}
