//! `ponq-infer` with a mesh as input (the same mesh as `ponq-prep sdf` + `ponq-infer` on its
//! grid, in the input's frame) and the refinement against exact distances (`--refine`): it
//! runs on exact and truncated grids, stays off on scaled, smoothed and noisy ones, and no
//! such grid gives a worse mesh than without it.

use std::path::Path;

use ponq_data::normalize::Normalization;
use ponq_data::sdf::MeshSdf;
use ponq_mesh::io::npy::{Grid3, write_npy_grid_f32};
use ponq_mesh::metrics::{MetricOptions, compare};
use ponq_mesh::{TriMesh, io, validity};

mod common;
use common::{repo, run, tmp};

fn os(p: &Path) -> &std::ffi::OsStr {
    p.as_os_str()
}

/// The CAD part of `examples/` in the [-1,1] frame and its exact SDF grid (as `ponq-prep
/// sdf` computes and stores it: float32).
fn csg(res: usize) -> (TriMesh, TriMesh, Normalization, Grid3) {
    let mesh = io::read_mesh(repo("examples/csg.obj")).unwrap();
    let norm = Normalization::of(&mesh).unwrap();
    let truth = norm.apply_mesh(&mesh);
    let g = MeshSdf::new(&truth).unwrap().grid(res, |_| {}).unwrap();
    (mesh, truth, norm, g.to_grid3())
}

fn metrics(pred: &TriMesh, truth: &TriMesh) -> [f64; 5] {
    let m = compare(
        pred,
        truth,
        &MetricOptions {
            surface_samples: 30_000,
            edge_samples: 30_000,
            check_validity: false,
            ..Default::default()
        },
    );
    [m.cd_x1e5, m.f1, m.nc, m.ecd_x1e2, m.ef1]
}

#[test]
fn a_mesh_input_gives_the_grid_path_mesh_in_the_input_frame() {
    let d = tmp("meshin");
    let (mesh, truth, norm, grid) = csg(32);
    write_npy_grid_f32(d.join("sdf.npy"), &grid).unwrap();
    let (code, out) = run(&[
        os(&d.join("sdf.npy")),
        "-o".as_ref(),
        os(&d.join("grid.obj")),
    ]);
    assert_eq!(code, Some(0), "{out}");
    let (code, out) = run(&[
        os(&repo("examples/csg.obj")),
        "--res".as_ref(),
        "32".as_ref(),
        "-o".as_ref(),
        os(&d.join("mesh.obj")),
    ]);
    assert_eq!(code, Some(0), "{out}");
    assert!(out.contains("output in the input's coordinates"), "{out}");
    let (code, out) = run(&[
        os(&repo("examples/csg.obj")),
        "--res".as_ref(),
        "32".as_ref(),
        "--normalized".as_ref(),
        "-o".as_ref(),
        os(&d.join("norm.obj")),
    ]);
    assert_eq!(code, Some(0), "{out}");
    let a = io::read_mesh(d.join("grid.obj")).unwrap();
    let b = io::read_mesh(d.join("mesh.obj")).unwrap();
    let c = io::read_mesh(d.join("norm.obj")).unwrap();
    // --normalized: exactly the grid path's mesh.
    assert_eq!(a, c);
    // Default: the same mesh in the input's coordinates.
    assert_eq!(a.faces, b.faces);
    let diag = {
        let (lo, hi) = mesh.bounding_box().unwrap();
        (0..3).map(|k| (hi[k] - lo[k]).powi(2)).sum::<f64>().sqrt()
    };
    for (p, q) in a.vertices.iter().zip(&b.vertices) {
        let back = norm.invert(*p);
        for k in 0..3 {
            assert!((back[k] - q[k]).abs() < 1e-12 * diag, "{back:?} vs {q:?}");
        }
    }
    assert!(validity::check(&b).is_valid());
    // The metrics against the input are those of the grid path.
    let ma = metrics(&a, &truth);
    let mb = metrics(&norm.apply_mesh(&b), &truth);
    for k in 0..5 {
        assert!(
            (ma[k] - mb[k]).abs() <= 1e-6 * ma[k].abs().max(1e-9),
            "{ma:?} vs {mb:?}"
        );
    }
}

#[test]
fn bad_mesh_inputs_and_flags_are_clear_errors() {
    let d = tmp("meshbad");
    // An open mesh: the box of examples/csg.obj without its first face.
    let mut open = io::read_mesh(repo("examples/csg.obj")).unwrap();
    open.faces.remove(0);
    io::write_mesh(d.join("open.obj"), &open).unwrap();
    let o = d.join("o.obj");
    // Without the repair (the behaviour before it): an error that says what to do.
    let (code, out) = run(&[
        os(&d.join("open.obj")),
        "--no-repair".as_ref(),
        "-o".as_ref(),
        os(&o),
    ]);
    assert_eq!(code, Some(2), "{out}");
    assert!(
        out.contains("not a closed") && out.contains("--open"),
        "{out}"
    );
    // By default the hole is closed, the report says so, and the output is valid.
    let (code, out) = run(&[os(&d.join("open.obj")), "-o".as_ref(), os(&o)]);
    assert_eq!(code, Some(0), "{out}");
    assert!(out.contains("filled holes: 1"), "{out}");
    assert!(validity::check(&io::read_mesh(&o).unwrap()).is_valid());
    // The documented open-surface path.
    let (code, out) = run(&[
        os(&d.join("open.obj")),
        "--open".as_ref(),
        "--res".as_ref(),
        "24".as_ref(),
        "-o".as_ref(),
        os(&o),
    ]);
    assert_eq!(code, Some(0), "{out}");
    // A mesh without triangles, a mesh that is not one, flags for the other input kind.
    std::fs::write(d.join("empty.obj"), "v 0 0 0\nv 1 0 0\n").unwrap();
    let (code, out) = run(&[os(&d.join("empty.obj")), "-o".as_ref(), os(&o)]);
    assert_eq!(code, Some(2), "{out}");
    assert!(out.contains("no triangle"), "{out}");
    std::fs::write(d.join("junk.off"), "not an off file").unwrap();
    let (code, out) = run(&[os(&d.join("junk.off")), "-o".as_ref(), os(&o)]);
    assert_eq!(code, Some(2), "{out}");
    assert!(out.contains("junk.off"), "{out}");
    let csg = repo("examples/csg.obj");
    for (args, needle) in [
        (vec!["--res", "1"], "resolution"),
        (vec!["--bounds", "-1,-1,-1,1,1,1"], "--bounds"),
    ] {
        let mut a: Vec<&std::ffi::OsStr> = vec![os(&csg), "-o".as_ref(), os(&o)];
        a.extend(args.iter().map(std::ffi::OsStr::new));
        let (code, out) = run(&a);
        assert_eq!(code, Some(2), "{args:?}: {out}");
        assert!(out.contains(needle), "{args:?}: {out}");
    }
    let (code, out) = run(&[
        os(&repo("examples/csg_sdf_33.npy")),
        "--res".as_ref(),
        "32".as_ref(),
        "-o".as_ref(),
        os(&o),
    ]);
    assert_eq!(code, Some(2), "{out}");
    assert!(out.contains("--res"), "{out}");
    let (code, out) = run(&[
        os(&repo("examples/csg_sdf_33.npy")),
        "--refine".as_ref(),
        "sometimes".as_ref(),
        "-o".as_ref(),
        os(&o),
    ]);
    assert_eq!(code, Some(2), "{out}");
    assert!(out.contains("auto, on or off"), "{out}");
}

/// The grid scaled, smoothed, noisy or truncated.
fn altered(g: &Grid3, how: &str) -> Grid3 {
    let n = g.dims[0];
    let h = 2.0 / (n - 1) as f64;
    let idx = |i: usize, j: usize, k: usize| (i * n + j) * n + k;
    let data: Vec<f64> = match how {
        "scaled" => g.data.iter().map(|v| 0.6 * v).collect(),
        "truncated" => g.data.iter().map(|v| v.clamp(-3.0 * h, 3.0 * h)).collect(),
        "noisy" => g
            .data
            .iter()
            .enumerate()
            .map(|(i, v)| v + 0.1 * h * (((i as f64) * 12.9898).sin() * 43758.545).fract())
            .collect(),
        "smoothed" => {
            let mut out = g.data.clone();
            for i in 1..n - 1 {
                for j in 1..n - 1 {
                    for k in 1..n - 1 {
                        let mut s = 0.0;
                        for t in 0..27 {
                            s += g.data[idx(i + t / 9 - 1, j + (t / 3) % 3 - 1, k + t % 3 - 1)];
                        }
                        out[idx(i, j, k)] = 0.5 * g.data[idx(i, j, k)] + 0.5 * s / 27.0;
                    }
                }
            }
            out
        }
        _ => unreachable!(),
    };
    Grid3::new(g.dims, data).unwrap()
}

#[test]
fn refinement_runs_on_true_distances_only_and_never_makes_a_grid_worse() {
    let d = tmp("refine");
    let (_, truth, _, exact) = csg(32);
    for how in ["exact", "truncated", "scaled", "smoothed", "noisy"] {
        let g = if how == "exact" {
            exact.clone()
        } else {
            altered(&exact, how)
        };
        let sdf = d.join(format!("{how}.npy"));
        write_npy_grid_f32(&sdf, &g).unwrap();
        let (auto_obj, off_obj) = (
            d.join(format!("{how}_auto.obj")),
            d.join(format!("{how}_off.obj")),
        );
        let (code, out) = run(&[os(&sdf), "-o".as_ref(), os(&auto_obj)]);
        assert_eq!(code, Some(0), "{how}: {out}");
        let (code, off_out) = run(&[
            os(&sdf),
            "--refine".as_ref(),
            "off".as_ref(),
            "-o".as_ref(),
            os(&off_obj),
        ]);
        assert_eq!(code, Some(0), "{how}: {off_out}");
        assert!(!off_out.contains("refinement ("), "{off_out}");
        let ran = out.contains("round(s) kept");
        let refused = out.contains("not a true signed distance");
        match how {
            // A distance in other units is rescaled into one first (the grid's conditioning).
            "exact" | "truncated" | "scaled" => {
                assert!(ran, "{how}: refinement did not run: {out}")
            }
            _ => assert!(refused, "{how}: refinement was not refused: {out}"),
        }
        if how == "scaled" {
            assert!(out.contains("rescaled by 1.666667"), "{out}");
        }
        let auto = io::read_mesh(&auto_obj).unwrap();
        let off = io::read_mesh(&off_obj).unwrap();
        assert!(validity::check(&auto).is_valid(), "{how}");
        if refused {
            assert_eq!(auto, off, "{how}: refused, yet the mesh changed");
            continue;
        }
        // Refined: no metric worse than the network's mesh alone, and sharper edges.
        let (ma, mo) = (metrics(&auto, &truth), metrics(&off, &truth));
        assert!(ma[0] <= mo[0] * 1.02, "{how}: CD {ma:?} vs {mo:?}");
        assert!(ma[1] >= mo[1] - 0.005, "{how}: F1 {ma:?} vs {mo:?}");
        assert!(ma[2] >= mo[2] - 0.002, "{how}: NC {ma:?} vs {mo:?}");
        assert!(ma[4] > mo[4], "{how}: EF1 {ma:?} vs {mo:?}");
        // --refine on on an altered grid is the user's choice; it still gives a valid mesh.
    }
    let (code, out) = run(&[
        os(&d.join("scaled.npy")),
        "--refine".as_ref(),
        "on".as_ref(),
        "-o".as_ref(),
        os(&d.join("forced.obj")),
    ]);
    assert_eq!(code, Some(0), "{out}");
    assert!(out.contains("refinement (on)"), "{out}");
}
