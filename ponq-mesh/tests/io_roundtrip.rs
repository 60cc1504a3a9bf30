//! Exact write/read round trips and reading hand-written files of every format.

#[path = "io_common.rs"]
mod io_common;

use io_common::*;
use ponq_mesh::io::{self, npy, npz, obj, off, ply, stl};
use ponq_mesh::{Ponq, TriMesh};

fn meshes() -> Vec<TriMesh> {
    vec![
        sample_mesh(1, 50, 80),
        sample_mesh(2, 12, 3), // mostly unreferenced vertices
        sample_mesh(3, 4, 0),  // vertices only
        TriMesh::default(),
        pyramid(),
    ]
}

#[test]
fn obj_roundtrip_exact() {
    let dir = scratch("obj_roundtrip_exact");
    for (i, m) in meshes().iter().enumerate() {
        let p = dir.join(format!("m{i}.obj"));
        obj::write(&p, m).unwrap();
        assert_eq!(&obj::read(&p).unwrap(), m, "mesh {i}");
    }
}

#[test]
fn ply_binary_roundtrip_exact() {
    let dir = scratch("ply_binary_roundtrip_exact");
    for (i, m) in meshes().iter().enumerate() {
        let p = dir.join(format!("m{i}.ply"));
        ply::write(&p, m).unwrap();
        let bytes = std::fs::read(&p).unwrap();
        assert!(bytes.starts_with(b"ply\nformat binary_little_endian 1.0\n"));
        assert_eq!(&ply::read(&p).unwrap(), m, "mesh {i}");
    }
}

#[test]
fn ply_ascii_roundtrip_exact() {
    let dir = scratch("ply_ascii_roundtrip_exact");
    for (i, m) in meshes().iter().enumerate() {
        let p = dir.join(format!("m{i}.ply"));
        ply::write_ascii(&p, m).unwrap();
        let bytes = std::fs::read(&p).unwrap();
        assert!(bytes.starts_with(b"ply\nformat ascii 1.0\n"));
        assert_eq!(&ply::read(&p).unwrap(), m, "mesh {i}");
    }
}

#[test]
fn off_roundtrip_exact() {
    let dir = scratch("off_roundtrip_exact");
    for (i, m) in meshes().iter().enumerate() {
        let p = dir.join(format!("m{i}.off"));
        off::write(&p, m).unwrap();
        assert_eq!(&off::read(&p).unwrap(), m, "mesh {i}");
    }
}

#[test]
fn write_mesh_and_read_mesh_dispatch_on_extension() {
    let dir = scratch("write_mesh_and_read_mesh_dispatch_on_extension");
    let m = sample_mesh(7, 20, 30);
    for name in ["a.obj", "b.PLY", "c.Off"] {
        let p = dir.join(name);
        io::write_mesh(&p, &m).unwrap();
        assert_eq!(io::read_mesh(&p).unwrap(), m, "{name}");
    }
    // write_mesh(.ply) is binary.
    let bytes = std::fs::read(dir.join("b.PLY")).unwrap();
    assert!(bytes.starts_with(b"ply\nformat binary_little_endian"));
}

#[test]
fn in_memory_writers_match_parsers() {
    let m = sample_mesh(11, 30, 40);
    let mut b = Vec::new();
    obj::write_to(&mut b, &m).unwrap();
    assert_eq!(obj::parse(&b).unwrap(), m);
    b.clear();
    off::write_to(&mut b, &m).unwrap();
    assert_eq!(off::parse(&b).unwrap(), m);
    b.clear();
    ply::write_to(&mut b, &m).unwrap();
    assert_eq!(ply::parse(&b).unwrap(), m);
    b.clear();
    ply::write_ascii_to(&mut b, &m).unwrap();
    assert_eq!(ply::parse(&b).unwrap(), m);
}

#[test]
fn reads_hand_written_polygon_files() {
    let expected = pyramid();
    for name in [
        "square_pyramid.obj",
        "square_pyramid.off",
        "square_pyramid_ascii.ply",
    ] {
        let m = io::read_mesh(data(name)).unwrap_or_else(|e| panic!("{name}: {e}"));
        assert_eq!(m, expected, "{name}");
    }
}

#[test]
fn reads_binary_big_endian_ply_with_float_coordinates() {
    let dir = scratch("reads_binary_big_endian_ply_with_float_coordinates");
    let m = pyramid();
    let mut b = format!(
        "ply\nformat binary_big_endian 1.0\nelement vertex {}\nproperty float32 x\n\
         property float32 y\nproperty float32 z\nproperty list uchar float texcoord\n\
         element face 5\nproperty list uint8 uint32 vertex_index\nend_header\n",
        m.vertices.len()
    )
    .into_bytes();
    for v in &m.vertices {
        for c in v {
            b.extend_from_slice(&(*c as f32).to_be_bytes());
        }
        b.push(2);
        b.extend_from_slice(&0.5f32.to_be_bytes());
        b.extend_from_slice(&0.25f32.to_be_bytes());
    }
    let polys: [&[u32]; 5] = [
        &[3, 2, 1, 0],
        &[0, 1, 4],
        &[1, 2, 4],
        &[2, 3, 4],
        &[3, 0, 4],
    ];
    for poly in polys {
        b.push(poly.len() as u8);
        for i in poly {
            b.extend_from_slice(&i.to_be_bytes());
        }
    }
    let p = dir.join("pyramid_be.ply");
    std::fs::write(&p, &b).unwrap();
    assert_eq!(io::read_mesh(&p).unwrap(), m);
}

#[test]
fn stl_ascii_and_binary() {
    let tetra = TriMesh::new(
        vec![
            [0.0, 0.0, 0.0],
            [0.0, 1.0, 0.0],
            [1.0, 0.0, 0.0],
            [0.0, 0.0, 1.0],
        ],
        vec![[0, 1, 2], [0, 2, 3], [0, 3, 1], [2, 1, 3]],
    )
    .unwrap();
    assert_eq!(io::read_mesh(data("tetra_ascii.stl")).unwrap(), tetra);

    // The same tetrahedron, binary, written with stl_io.
    let tris: Vec<stl_io::Triangle> = tetra
        .faces
        .iter()
        .map(|f| stl_io::Triangle {
            normal: stl_io::Normal::new([0.0, 0.0, 0.0]),
            vertices: f.map(|i| {
                let v = tetra.vertices[i as usize];
                stl_io::Vertex::new([v[0] as f32, v[1] as f32, v[2] as f32])
            }),
        })
        .collect();
    let dir = scratch("stl_ascii_and_binary");
    let p = dir.join("tetra.STL");
    let mut f = std::fs::File::create(&p).unwrap();
    stl_io::write_stl(&mut f, tris.iter()).unwrap();
    drop(f);
    assert_eq!(io::read_mesh(&p).unwrap(), tetra);
    assert_eq!(stl::read(&p).unwrap(), tetra);

    // Binary with a header starting with "solid " (as many exporters write).
    let raw: Vec<[[f32; 3]; 3]> = tetra
        .faces
        .iter()
        .map(|f| f.map(|i| tetra.vertices[i as usize].map(|c| c as f32)))
        .collect();
    let p = dir.join("solid_header.stl");
    std::fs::write(&p, binary_stl(&raw, b"solid exported by a CAD tool")).unwrap();
    assert_eq!(stl::read(&p).unwrap(), tetra);

    // An empty binary STL.
    assert_eq!(
        stl::parse(&binary_stl(&[], b"")).unwrap(),
        TriMesh::default()
    );
}

fn assert_ponq_roundtrip(test: &str, p: &Ponq) {
    let dir = scratch(test);
    let path = dir.join("p.npz");
    npz::write_ponq(&path, p).unwrap();
    let q = npz::read_ponq(&path).unwrap();
    assert_eq!(&q, p);
}

#[test]
fn npz_roundtrip_exact_with_vstars() {
    assert_ponq_roundtrip("npz_roundtrip_exact_with_vstars", &sample_ponq(5, 40, true));
}

#[test]
fn npz_roundtrip_exact_without_vstars() {
    let p = sample_ponq(6, 33, false);
    assert_ponq_roundtrip("npz_roundtrip_exact_without_vstars", &p);
}

#[test]
fn npz_roundtrip_empty() {
    assert_ponq_roundtrip("npz_roundtrip_empty", &Ponq::default());
    let e = Ponq::new(vec![], vec![], vec![], Some(vec![])).unwrap();
    assert_ponq_roundtrip("npz_roundtrip_empty_vstars", &e);
}

#[test]
fn npz_reads_f32_big_endian_and_fortran_files() {
    let dir = scratch("npz_reads_f32_big_endian_and_fortran_files");
    let p = sample_ponq(8, 9, true);
    // Values representable in f32, so that the comparison is exact.
    let to32 = |v: &[[f64; 3]]| -> Vec<[f64; 3]> {
        v.iter().map(|x| x.map(|c| c as f32 as f64)).collect()
    };
    let quads = p
        .quadrics
        .iter()
        .map(|q| ponq_mesh::Quadric::from_matrix4(&q.to_matrix4().map(|c| c as f32 as f64)))
        .collect();
    let p32 = Ponq::new(
        to32(&p.points),
        to32(&p.normals),
        quads,
        p.vstars.as_deref().map(to32),
    )
    .unwrap();
    for (f32, be, fortran) in [
        (true, false, false),
        (true, true, false),
        (true, false, true),
        (false, true, true),
    ] {
        let path = dir.join(format!("p_{f32}_{be}_{fortran}.npz"));
        write_npz(&path, &ponq_arrays(&p32), f32, be, fortran);
        let q = npz::read_ponq(&path).unwrap();
        assert_eq!(q, p32, "f32 {f32} big-endian {be} fortran {fortran}");
    }
    // Extra arrays are ignored.
    let mut arrays = ponq_arrays(&p32);
    arrays.push(("extra", vec![2], vec![1.0, 2.0]));
    let path = dir.join("extra.npz");
    write_npz(&path, &arrays, false, false, false);
    assert_eq!(npz::read_ponq(&path).unwrap(), p32);
}

#[test]
fn npy_grid_roundtrip_and_orders() {
    let dir = scratch("npy_grid_roundtrip_and_orders");
    let dims = [3, 4, 5];
    let data: Vec<f64> = (0..60).map(|i| i as f64 * 0.25 - 3.0).collect();
    let g = npy::Grid3::new(dims, data.clone()).unwrap();
    assert_eq!(g.get(1, 2, 3), data[(4 + 2) * 5 + 3]);
    let p = dir.join("g.npy");
    npy::write_npy_grid_f32(&p, &g).unwrap();
    assert_eq!(npy::read_npy_grid(&p).unwrap(), g);
    let a = npy::read_npy(&p).unwrap();
    assert!(a.was_f32);
    assert_eq!(a.shape, vec![3, 4, 5]);

    // float64, Fortran order, written by npyz directly.
    use npyz::WriterBuilder;
    let p = dir.join("f.npy");
    let shape = [3u64, 4, 5];
    let mut w = npyz::WriteOptions::<f64>::new()
        .default_dtype()
        .shape(&shape)
        .order(npyz::Order::Fortran)
        .writer(std::io::BufWriter::new(std::fs::File::create(&p).unwrap()))
        .begin_nd()
        .unwrap();
    w.extend(c_to_fortran(&data, &shape)).unwrap();
    w.finish().unwrap();
    assert_eq!(npy::read_npy_grid(&p).unwrap(), g);

    // An empty grid.
    let e = npy::Grid3::new([0, 2, 2], vec![]).unwrap();
    let p = dir.join("e.npy");
    npy::write_npy_grid_f32(&p, &e).unwrap();
    assert_eq!(npy::read_npy_grid(&p).unwrap(), e);
}
