//! Colours through `ponq-infer`: a remeshed coloured mesh (per-face colours, a texture) gives
//! each output vertex the colour of the input at its closest point; a grid's colours
//! (`.npz` with `rgb`) are interpolated; an uncoloured input gives the same file as before.

use std::path::Path;

use ponq_mesh::colour::Colours;
use ponq_mesh::io::{self, read_mesh_coloured};

mod common;
use common::{repo, run, tmp};

fn os(p: &Path) -> &std::ffi::OsStr {
    p.as_os_str()
}

const RED: [f32; 3] = [1.0, 0.0, 0.0];
const BLUE: [f32; 3] = [0.0, 0.0, 1.0];

/// The cube [-0.5, 0.5]^3: 8 vertices, 12 triangles, two per face, faces in the order
/// -x, +x, -y, +y, -z, +z (outward).
fn cube() -> (Vec<[f64; 3]>, Vec<[u32; 3]>) {
    let v: Vec<[f64; 3]> = (0..8)
        .map(|i| [i & 1, (i >> 1) & 1, i >> 2].map(|b| f64::from(b) - 0.5))
        .collect();
    let f = vec![
        [0, 4, 6],
        [0, 6, 2], // -x
        [1, 3, 7],
        [1, 7, 5], // +x
        [0, 1, 5],
        [0, 5, 4], // -y
        [2, 6, 7],
        [2, 7, 3], // +y
        [0, 2, 3],
        [0, 3, 1], // -z
        [4, 5, 7],
        [4, 7, 6], // +z
    ];
    (v, f)
}

/// The cube's face (0..6 as in [`cube`]) a point lies on, when it lies on exactly one (more
/// than `margin` from the others).
fn faces_of(p: [f64; 3], margin: f64) -> Vec<usize> {
    (0..6)
        .filter(|&k| {
            let (axis, side) = (k / 2, if k % 2 == 0 { -0.5 } else { 0.5 });
            (p[axis] - side).abs() < margin
        })
        .collect()
}

/// The face colour of the two-coloured cube: the x faces and +y red, the rest blue.
fn face_colour(k: usize) -> [f32; 3] {
    if k <= 1 || k == 3 { RED } else { BLUE }
}

#[test]
fn a_two_coloured_cube_keeps_its_colours() {
    let d = tmp("colours-cube");
    let (v, f) = cube();
    // A PLY with face colours.
    let mut ply = String::from(
        "ply\nformat ascii 1.0\nelement vertex 8\nproperty float x\nproperty float y\n\
         property float z\nelement face 12\nproperty list uchar int vertex_indices\n\
         property uchar red\nproperty uchar green\nproperty uchar blue\nend_header\n",
    );
    for p in &v {
        ply += &format!("{} {} {}\n", p[0], p[1], p[2]);
    }
    for (i, t) in f.iter().enumerate() {
        let c = face_colour(i / 2).map(|x| (x * 255.0) as u8);
        ply += &format!("3 {} {} {} {} {} {}\n", t[0], t[1], t[2], c[0], c[1], c[2]);
    }
    let input = d.join("cube.ply");
    std::fs::write(&input, ply).unwrap();
    let out = d.join("out.ply");
    let (code, text) = run(&[
        os(&input),
        "-o".as_ref(),
        os(&out),
        "--res".as_ref(),
        "32".as_ref(),
    ]);
    assert_eq!(code, Some(0), "{text}");
    assert!(text.contains("colours: at the closest points"), "{text}");
    let (mesh, colours) = read_mesh_coloured(&out).unwrap();
    let Some(Colours::Vertex(c)) = colours else {
        panic!("no vertex colours in {}", out.display())
    };
    let h = 1.0 / 32.0;
    let (mut inner, mut edges) = (0, 0);
    for (p, col) in mesh.vertices.iter().zip(&c) {
        // On a face: within a tenth of a cell of its plane (the output follows the surface to
        // a few hundredths of a cell).
        let on = faces_of(*p, 0.1 * h);
        match on.len() {
            0 => {}
            1 => {
                // Away from the edges (more than a cell from the other faces): exact.
                if faces_of(*p, 2.0 * h).len() == 1 {
                    assert_eq!(*col, face_colour(on[0]), "{p:?}");
                    inner += 1;
                }
            }
            _ => {
                assert!(on.iter().any(|&k| face_colour(k) == *col), "{p:?}: {col:?}");
                edges += 1;
            }
        }
    }
    assert!(inner > 100 && edges > 8, "{inner} {edges}");
    // Without colours: the same mesh, the plain file.
    let (plain, nocol) = (d.join("plain.ply"), d.join("nocol.ply"));
    let (code, text) = run(&[
        os(&input),
        "-o".as_ref(),
        os(&nocol),
        "--res".as_ref(),
        "32".as_ref(),
        "--no-colours".as_ref(),
    ]);
    assert_eq!(code, Some(0), "{text}");
    io::write_mesh(&plain, &mesh).unwrap();
    assert_eq!(
        std::fs::read(&plain).unwrap(),
        std::fs::read(&nocol).unwrap()
    );
    std::fs::remove_dir_all(&d).ok();
}

#[test]
fn a_textured_cube_keeps_each_region_colour() {
    let d = tmp("colours-texture");
    let (v, f) = cube();
    // A 64 x 8 texture: the left half red, the right half blue.
    let img = image::RgbImage::from_fn(64, 8, |x, _| {
        if x < 32 {
            image::Rgb([255, 0, 0])
        } else {
            image::Rgb([0, 0, 255])
        }
    });
    img.save(d.join("tex.png")).unwrap();
    std::fs::write(
        d.join("cube.mtl"),
        "newmtl skin\nKd 1 1 1\nmap_Kd tex.png\n",
    )
    .unwrap();
    let mut obj = String::from("mtllib cube.mtl\n");
    for p in &v {
        obj += &format!("v {} {} {}\n", p[0], p[1], p[2]);
    }
    // Texture coordinates: red faces map into u in [0.1, 0.4], blue ones into [0.6, 0.9].
    for (lo, hi) in [(0.1, 0.4), (0.6, 0.9)] {
        obj += &format!("vt {lo} 0.2\nvt {hi} 0.2\nvt {hi} 0.8\nvt {lo} 0.8\n");
    }
    obj += "usemtl skin\n";
    for (i, t) in f.iter().enumerate() {
        let base = if face_colour(i / 2) == RED { 1 } else { 5 };
        let uv = if i % 2 == 0 { [0, 1, 2] } else { [0, 2, 3] };
        obj += &format!(
            "f {}/{} {}/{} {}/{}\n",
            t[0] + 1,
            base + uv[0],
            t[1] + 1,
            base + uv[1],
            t[2] + 1,
            base + uv[2]
        );
    }
    let input = d.join("cube.obj");
    std::fs::write(&input, obj).unwrap();
    let out = d.join("out.obj");
    let (code, text) = run(&[
        os(&input),
        "-o".as_ref(),
        os(&out),
        "--res".as_ref(),
        "32".as_ref(),
    ]);
    assert_eq!(code, Some(0), "{text}");
    let (mesh, colours) = read_mesh_coloured(&out).unwrap();
    let Some(Colours::Vertex(c)) = colours else {
        panic!("no vertex colours")
    };
    let h = 1.0 / 32.0;
    let mut checked = 0;
    for (p, col) in mesh.vertices.iter().zip(&c) {
        let on = faces_of(*p, 2.0 * h);
        if on.len() == 1 {
            let want = face_colour(on[0]);
            assert!(
                (0..3).all(|k| (col[k] - want[k]).abs() <= 0.02),
                "{p:?}: {col:?}"
            );
            checked += 1;
        }
    }
    assert!(checked > 100);
    std::fs::remove_dir_all(&d).ok();
}

#[test]
fn a_grid_of_colours_is_interpolated() {
    let d = tmp("colours-grid");
    let g = io::npy::read_npy_grid(repo("examples/csg_sdf_33.npy")).unwrap();
    let n = g.dims[0];
    // Red rising with x, blue with z: linear, so exact at any point up to rounding.
    let mut rgb = Vec::with_capacity(g.data.len() * 3);
    for i in 0..n {
        for _j in 0..n {
            for k in 0..n {
                rgb.extend([i as f64 / (n - 1) as f64, 0.5, k as f64 / (n - 1) as f64]);
            }
        }
    }
    let npz = d.join("grid.npz");
    io::npz::write_arrays(
        &npz,
        &[
            io::npz::NamedArray {
                name: "sdf".into(),
                shape: vec![n, n, n],
                data: g.data.clone(),
                f32_storage: true,
            },
            io::npz::NamedArray {
                name: "rgb".into(),
                shape: vec![n, n, n, 3],
                data: rgb,
                f32_storage: true,
            },
        ],
    )
    .unwrap();
    let out = d.join("out.ply");
    let (code, text) = run(&[os(&npz), "-o".as_ref(), os(&out)]);
    assert_eq!(code, Some(0), "{text}");
    assert!(text.contains("trilinear"), "{text}");
    let (mesh, colours) = read_mesh_coloured(&out).unwrap();
    let Some(Colours::Vertex(c)) = colours else {
        panic!("no vertex colours")
    };
    for (p, col) in mesh.vertices.iter().zip(&c) {
        let want = [(p[0] + 1.0) / 2.0, 0.5, (p[2] + 1.0) / 2.0];
        // Bytes in the PLY: within one step.
        assert!(
            (0..3).all(|k| (f64::from(col[k]) - want[k]).abs() <= 1.0 / 255.0),
            "{p:?}"
        );
    }
    // The same grid as .npy gives the same mesh.
    let plain = d.join("plain.ply");
    let (code, _) = run(&[
        os(&repo("examples/csg_sdf_33.npy")),
        "-o".as_ref(),
        os(&plain),
    ]);
    assert_eq!(code, Some(0));
    assert_eq!(io::read_mesh(&plain).unwrap(), mesh);
    // Float colours past 1 are an error (bytes are uint8 arrays); --no-colours reads no rgb.
    let bad = d.join("bad.npz");
    io::npz::write_arrays(
        &bad,
        &[
            io::npz::NamedArray {
                name: "sdf".into(),
                shape: vec![n, n, n],
                data: g.data.clone(),
                f32_storage: true,
            },
            io::npz::NamedArray {
                name: "rgb".into(),
                shape: vec![n, n, n, 3],
                data: vec![2.0; g.data.len() * 3],
                f32_storage: true,
            },
        ],
    )
    .unwrap();
    let (code, text) = run(&[os(&bad), "-o".as_ref(), os(&d.join("bad.ply"))]);
    assert_eq!(code, Some(2), "{text}");
    assert!(text.contains("'rgb' holds 2"), "{text}");
    let (code, text) = run(&[
        os(&bad),
        "-o".as_ref(),
        os(&d.join("bad.ply")),
        "--no-colours".as_ref(),
    ]);
    assert_eq!(code, Some(0), "{text}");
    assert_eq!(io::read_mesh(d.join("bad.ply")).unwrap(), mesh);
    std::fs::remove_dir_all(&d).ok();
}
