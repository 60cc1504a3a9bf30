//! The repair of broken meshes: on broken copies of two shipped parts (a CSG part and an
//! OpenSCAD example), one class of defect at a time, the signed distance grid of the repaired
//! copy has the sign of the clean part's grid (of the union of the two copies, for overlaps)
//! at all but a sliver of the nodes next to the surface, and its distances are the clean
//! ones up to the defect's size; clean meshes come out unchanged; meshes with nothing to
//! reconstruct are clear errors.

use ponq_data::broken::{Defect, break_mesh};
use ponq_data::normalize::Normalization;
use ponq_data::repair::{RepairOptions, repair, repair_with_solid};
use ponq_data::sdf::{MeshSdf, SdfGrid};
use ponq_mesh::{TriMesh, io, validity};

const RES: usize = 32;

fn example(name: &str) -> TriMesh {
    let p = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../examples")
        .join(name);
    io::read_mesh(&p).unwrap()
}

fn grid(m: &TriMesh) -> SdfGrid {
    MeshSdf::new(m).unwrap().grid(RES, |_| {}).unwrap()
}

/// Nodes whose sign differs, and the largest distance difference at nodes farther than
/// `margin` from both surfaces.
fn compare(a: &SdfGrid, b: &SdfGrid, margin: f32) -> (usize, f32) {
    let mut signs = 0;
    let mut worst = 0.0f32;
    for (x, y) in a.values.iter().zip(&b.values) {
        if (*x < 0.0) != (*y < 0.0) {
            signs += 1;
        }
        if x.abs() > margin && y.abs() > margin {
            worst = worst.max((x - y).abs());
        }
    }
    (signs, worst)
}

#[test]
fn every_defect_class_gives_back_the_solid() {
    let cell = 2.0 / RES as f32;
    for name in ["csg.obj", "example001.obj"] {
        let clean = example(name);
        let norm = Normalization::of(&clean).unwrap();
        let clean_n = norm.apply_mesh(&clean);
        let want = grid(&clean_n);
        // The union of the part and its moved copy: inside either, at the distance to the
        // union's surface.
        let shift = ponq_data::broken::overlap_shift(&clean_n);
        let moved = TriMesh {
            vertices: clean_n
                .vertices
                .iter()
                .map(|p| [0, 1, 2].map(|k| p[k] + shift[k]))
                .collect(),
            faces: clean_n.faces.clone(),
        };
        let moved_grid = grid(&moved);
        let surface =
            grid(&ponq_data::broken::union_surface(&clean_n, 0.25 * cell as f64).unwrap());
        let union_values: Vec<f32> = (0..want.values.len())
            .map(|i| {
                let d = surface.values[i].abs();
                if want.values[i] < 0.0 || moved_grid.values[i] < 0.0 {
                    -d
                } else {
                    d
                }
            })
            .collect();
        for defect in Defect::ALL {
            // In the normalised frame the diagonal is 2: a cell is 2 / RES.
            let broken = break_mesh(&clean_n, defect, 7, 2.0 / RES as f64).unwrap();
            let repaired = repair_with_solid(&broken, &RepairOptions::default()).unwrap();
            let (fixed, report) = (repaired.mesh.clone(), repaired.report.clone());
            // An exactly welded soup of a clean part is clean: it is used as it is.
            if defect != Defect::Soup {
                assert!(report.repaired, "{name} {defect}: {report}");
                assert!(report.found_defects(), "{name} {defect}: {report}");
            }
            // Distances to the repaired surface, the sign of the surface it was cut from.
            let got = repaired.grid(|m| m.clone(), RES, |_| {}).unwrap();
            let (signs, worst) = if defect == Defect::Overlap {
                let w = SdfGrid {
                    values: union_values.clone(),
                    ..want.clone()
                };
                compare(&w, &got, 2.0 * cell)
            } else {
                compare(&want, &got, 2.0 * cell)
            };
            let nodes = want.values.len();
            // Past the weld (soups with gaps, T-junctions): signed by the fast winding number
            // of the faces as read, whose corners moved by up to `jitter`; nodes closer to the
            // surface than that may change sign, and distances move by up to it.
            let jitter = match defect {
                Defect::Gaps3 | Defect::Mixed => 2e-3,
                Defect::Gaps2 => 2e-2,
                _ => 0.0,
            };
            let past_weld = matches!(
                defect,
                Defect::Gaps3 | Defect::Gaps2 | Defect::TJunctions | Defect::Mixed
            );
            assert_eq!(
                report.winding_sign.is_some(),
                past_weld,
                "{name} {defect}: {report}"
            );
            let signs = if past_weld {
                want.values
                    .iter()
                    .zip(&got.values)
                    .filter(|(x, y)| x.abs() > jitter && (**x < 0.0) != (**y < 0.0))
                    .count()
            } else {
                signs
            };
            // A sliver of nodes next to the surface may change sign where holes were patched
            // or faces crossing another copy were kept or dropped whole; single faces flipped
            // in a soup with gaps (mixed) invert the winding number next to them.
            let allowed = match defect {
                Defect::Holes | Defect::Overlap => nodes / 500,
                Defect::Mixed => nodes / 100,
                _ => 0,
            };
            assert!(
                signs <= allowed,
                "{name} {defect}: {signs} of {nodes} nodes change sign\n{report}"
            );
            // Distances away from the surface are the clean ones, up to the welds' moves
            // (cracks); for overlaps, faces that cross the other copy are kept or dropped whole,
            // so distances near the crossing are off by up to a face's size (CAD parts have
            // large faces): within a cell.
            let tol = match defect {
                Defect::Overlap => cell,
                // Fins stand half a cell off the surface (kept: nothing is removed there).
                Defect::Mixed => cell,
                _ => 1e-4 + jitter,
            };
            assert!(
                worst <= tol,
                "{name} {defect}: distances differ by {worst}\n{report}"
            );
            // Closed and oriented (vertices at one position merged) where the defect leaves a
            // solid's surface behind.
            if !matches!(defect, Defect::Overlap) && !past_weld {
                assert!(
                    !MeshSdf::new(&fixed).unwrap().is_open(),
                    "{name} {defect}: {}\n{report}",
                    validity::check_topology(&fixed)
                );
            }
        }
    }
}

/// Defects together, as real meshes have them: holes, then half the faces flipped, then a
/// soup with cracks; and fins on top of flipped faces.
#[test]
fn combined_defects_give_back_the_solid() {
    let cell = 2.0 / RES as f64;
    for name in ["csg.obj", "example001.obj"] {
        let clean = example(name);
        let norm = Normalization::of(&clean).unwrap();
        let clean_n = norm.apply_mesh(&clean);
        let want = grid(&clean_n);
        for (i, chain) in [
            [Defect::Holes, Defect::Flip50, Defect::Cracks],
            [Defect::Flip10, Defect::Fins, Defect::Duplicates],
        ]
        .iter()
        .enumerate()
        {
            let mut m = clean_n.clone();
            for (k, &d) in chain.iter().enumerate() {
                m = break_mesh(&m, d, 11 + k as u64, cell).unwrap();
            }
            let r = repair_with_solid(&m, &RepairOptions::default()).unwrap();
            let got = r.grid(|m| m.clone(), RES, |_| {}).unwrap();
            let (signs, worst) = compare(&want, &got, 2.0 * cell as f32);
            assert!(
                signs <= want.values.len() / 500,
                "{name} chain {i}: {signs} nodes change sign\n{}",
                r.report
            );
            assert!(worst <= 1e-4, "{name} chain {i}: {worst}\n{}", r.report);
            assert!(r.report.internal_faces_removed <= 60, "{}", r.report);
        }
    }
}

#[test]
fn clean_meshes_are_used_as_they_are() {
    for name in ["csg.obj", "example001.obj"] {
        let clean = example(name);
        let (out, report) = repair(&clean, &RepairOptions::default()).unwrap();
        assert!(!report.repaired, "{name}: {report}");
        assert!(!report.found_defects(), "{name}: {report}");
        assert_eq!(out.vertices, clean.vertices);
        assert_eq!(out.faces, clean.faces);
    }
    // Two separate closed parts, and a part with a cavity facing inward: no defect.
    let clean = example("example001.obj");
    let norm = Normalization::of(&clean).unwrap();
    let a = norm.apply_mesh(&clean);
    let mut two = a.clone();
    let base = two.vertices.len() as u32;
    two.vertices
        .extend(a.vertices.iter().map(|p| [p[0] + 3.0, p[1], p[2]]));
    two.faces
        .extend(a.faces.iter().map(|f| f.map(|v| v + base)));
    let (_, report) = repair(&two, &RepairOptions::default()).unwrap();
    assert!(!report.repaired, "{report}");
    assert_eq!(report.components, 2);
    // The part facing inward inside a cube facing outward: a cavity.
    let mut hollow = a.clone();
    for f in &mut hollow.faces {
        f.swap(1, 2);
    }
    let base = hollow.vertices.len() as u32;
    hollow
        .vertices
        .extend((0..8).map(|i| [0, 1, 2].map(|k| if (i >> k) & 1 == 1 { 3.0 } else { -3.0 })));
    let cube: [[u32; 3]; 12] = [
        [0, 2, 1],
        [1, 2, 3],
        [0, 1, 5],
        [0, 5, 4],
        [1, 3, 7],
        [1, 7, 5],
        [3, 2, 6],
        [3, 6, 7],
        [2, 0, 4],
        [2, 4, 6],
        [4, 5, 7],
        [4, 7, 6],
    ];
    hollow
        .faces
        .extend(cube.iter().map(|f| f.map(|v| v + base)));
    assert!(hollow.signed_volume() > 0.0);
    let (_, report) = repair(&hollow, &RepairOptions::default()).unwrap();
    assert!(!report.repaired, "{report}");
}

#[test]
fn nothing_to_reconstruct_is_a_clear_error() {
    let empty = TriMesh::default();
    let e = repair(&empty, &RepairOptions::default()).unwrap_err();
    assert!(e.to_string().contains("no face"), "{e}");
    let flat = TriMesh::new(
        vec![[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]],
        vec![[0, 1, 2]],
    )
    .unwrap();
    // One triangle: its hole closes onto itself, a face on both sides: no volume.
    let e = repair(&flat, &RepairOptions::default()).unwrap_err();
    assert!(e.to_string().contains("no volume"), "{e}");
    let point = TriMesh::new(vec![[1.0, 1.0, 1.0]; 3], vec![[0, 1, 2]]).unwrap();
    let e = repair(&point, &RepairOptions::default()).unwrap_err();
    assert!(e.to_string().contains("one point"), "{e}");
}

#[test]
fn open_surfaces_are_oriented_but_not_closed() {
    // A square of two triangles, one flipped, and a soup copy of it: welded, deduplicated,
    // oriented; the boundary stays.
    let v = vec![
        [0.0, 0.0, 0.0],
        [1.0, 0.0, 0.0],
        [1.0, 1.0, 0.0],
        [0.0, 1.0, 0.0],
    ];
    let m = TriMesh::new(v, vec![[0, 1, 2], [0, 3, 2], [2, 1, 0]]).unwrap();
    let (out, report) = repair(&m, &RepairOptions::open_surface()).unwrap();
    assert_eq!(out.faces.len(), 2);
    assert_eq!((report.duplicate_faces, report.opposite_duplicates), (1, 1));
    let t = validity::check_topology(&out);
    assert_eq!(t.boundary_edges, 4, "{t}");
    // Oriented: no directed edge twice.
    let mut directed: Vec<(u32, u32)> = out
        .faces
        .iter()
        .flat_map(|f| (0..3).map(move |k| (f[k], f[(k + 1) % 3])))
        .collect();
    directed.sort_unstable();
    let n = directed.len();
    directed.dedup();
    assert_eq!(directed.len(), n, "{:?}", out.faces);
}
