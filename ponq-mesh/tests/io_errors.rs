//! Every reader turns bad files into errors that name the file and say what is wrong.

#[path = "io_common.rs"]
mod io_common;

use std::path::Path;

use io_common::*;
use ponq_mesh::io::{self, npy, npz, ply};
use ponq_mesh::{Error, Ponq, TriMesh};

/// Asserts a [`Error::Format`] for `path` whose message contains every one of `needles`.
fn assert_format(r: Result<impl std::fmt::Debug, Error>, path: &Path, needles: &[&str]) {
    match r {
        Err(Error::Format { path: p, msg }) => {
            assert_eq!(p, path);
            let full = Error::format(&p, msg.clone()).to_string();
            assert!(full.contains(&*path.to_string_lossy()), "{full}");
            for n in needles {
                assert!(msg.contains(n), "message {msg:?} lacks {n:?}");
            }
        }
        other => panic!("{}: expected a format error, got {other:?}", path.display()),
    }
}

fn write(dir: &Path, name: &str, bytes: &[u8]) -> std::path::PathBuf {
    let p = dir.join(name);
    std::fs::write(&p, bytes).unwrap();
    p
}

const GARBAGE: &[u8] = b"\x89\x00\xffGARBAGE\x13\x37\x00\x01\x02 this is not a mesh \xfe\xfd";

#[test]
fn missing_file_is_io_error_naming_the_file() {
    let dir = scratch("missing_file_is_io_error_naming_the_file");
    for name in ["no.obj", "no.ply", "no.off", "no.stl"] {
        let p = dir.join(name);
        match io::read_mesh(&p) {
            Err(e @ Error::Io { .. }) => assert!(e.to_string().contains(name), "{e}"),
            other => panic!("{name}: {other:?}"),
        }
    }
    let p = dir.join("no.npz");
    assert!(matches!(npz::read_ponq(&p), Err(Error::Io { path, .. }) if path == p));
    let p = dir.join("no.npy");
    assert!(matches!(npy::read_npy_grid(&p), Err(Error::Io { path, .. }) if path == p));
    // Writing into a missing directory.
    let p = dir.join("missing/out.obj");
    assert!(matches!(io::write_mesh(&p, &pyramid()), Err(Error::Io { path, .. }) if path == p));
    let p = dir.join("missing/out.npz");
    assert!(matches!(
        npz::write_ponq(&p, &Ponq::default()),
        Err(Error::Io { .. })
    ));
}

#[test]
fn garbage_bytes_are_format_errors() {
    let dir = scratch("garbage_bytes_are_format_errors");
    for name in ["g.obj", "g.ply", "g.off", "g.stl"] {
        let p = write(&dir, name, GARBAGE);
        assert_format(io::read_mesh(&p), &p, &[]);
    }
    let p = write(&dir, "g.npz", GARBAGE);
    assert_format(npz::read_ponq(&p), &p, &["not a .npz (zip) archive"]);
    let p = write(&dir, "g.npy", GARBAGE);
    assert_format(npy::read_npy_grid(&p), &p, &["not a .npy"]);
    // Empty files.
    for name in ["e.ply", "e.off", "e.stl", "e.npz", "e.npy"] {
        let p = write(&dir, name, b"");
        let r = match name {
            "e.npz" => npz::read_ponq(&p).map(|_| ()),
            "e.npy" => npy::read_npy_grid(&p).map(|_| ()),
            _ => io::read_mesh(&p).map(|_| ()),
        };
        assert_format(r, &p, &[]);
    }
}

#[test]
fn truncated_binary_ply() {
    let dir = scratch("truncated_binary_ply");
    let mut b = Vec::new();
    ply::write_to(&mut b, &sample_mesh(3, 20, 30)).unwrap();
    let header_len = b.windows(11).position(|w| w == b"end_header\n").unwrap() + 11;
    for cut in [
        header_len,
        header_len + 7,
        header_len + 20 * 24,
        b.len() - 1,
    ] {
        let p = write(&dir, &format!("t{cut}.ply"), &b[..cut]);
        assert_format(ply::read(&p), &p, &["unexpected end of data"]);
    }
    // Header without end_header.
    let p = write(&dir, "h.ply", &b[..header_len - 11]);
    assert_format(ply::read(&p), &p, &["end_header"]);
}

#[test]
fn huge_counts_do_not_allocate() {
    let dir = scratch("huge_counts_do_not_allocate");
    let p = write(
        &dir,
        "huge.ply",
        b"ply\nformat binary_little_endian 1.0\nelement vertex 4294967296\nproperty double x\nproperty double y\nproperty double z\nend_header\n\0\0\0\0",
    );
    assert_format(ply::read(&p), &p, &[]);
    let p = write(
        &dir,
        "huge2.ply",
        b"ply\nformat ascii 1.0\nelement vertex 4294967295\nproperty double x\nproperty double y\nproperty double z\nelement face 4294967295\nproperty list uint uint vertex_indices\nend_header\n0 0 0\n",
    );
    assert_format(ply::read(&p), &p, &["unexpected end of data"]);
    let p = write(&dir, "huge.off", b"OFF\n4294967295 4294967295 0\n0 0 0\n");
    assert_format(io::read_mesh(&p), &p, &["ends after 1 of the 4294967295"]);
    let p = write(&dir, "huge.stl", &{
        let mut b = binary_stl(&[[[0.0; 3]; 3]], b"");
        b[80..84].copy_from_slice(&u32::MAX.to_le_bytes());
        b
    });
    assert_format(io::read_mesh(&p), &p, &[]);
}

#[test]
fn index_out_of_range() {
    let dir = scratch("index_out_of_range");
    let p = write(&dir, "oob.obj", b"v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 4\n");
    assert_format(io::read_mesh(&p), &p, &["vertex"]);
    let p = write(&dir, "neg.obj", b"v 0 0 0\nv 1 0 0\nv 0 1 0\nf -1 -2 -4\n");
    assert_format(io::read_mesh(&p), &p, &["-4"]);
    let p = write(
        &dir,
        "oob.off",
        b"OFF\n3 1 0\n0 0 0\n1 0 0\n0 1 0\n3 0 1 3\n",
    );
    assert_format(io::read_mesh(&p), &p, &["vertex 3", "only 3 vertices"]);
    let p = write(
        &dir,
        "oob.ply",
        b"ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\nelement face 1\nproperty list uchar int vertex_indices\nend_header\n0 0 0\n1 0 0\n0 1 0\n4 0 1 2 3\n",
    );
    assert_format(io::read_mesh(&p), &p, &["vertex 3", "only 3 vertices"]);
    let p = write(
        &dir,
        "negative.ply",
        b"ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\nelement face 1\nproperty list uchar int vertex_indices\nend_header\n0 0 0\n1 0 0\n0 1 0\n3 0 1 -1\n",
    );
    assert_format(io::read_mesh(&p), &p, &["negative vertex index"]);
    // Too few corners.
    let p = write(&dir, "two.off", b"OFF\n3 1 0\n0 0 0\n1 0 0\n0 1 0\n2 0 1\n");
    assert_format(io::read_mesh(&p), &p, &["at least 3"]);
}

#[test]
fn non_finite_coordinates() {
    let dir = scratch("non_finite_coordinates");
    let p = write(&dir, "nan.obj", b"v 0 0 0\nv NaN 0 0\nv 0 1 0\nf 1 2 3\n");
    assert_format(io::read_mesh(&p), &p, &["non-finite"]);
    let p = write(
        &dir,
        "inf.off",
        b"OFF\n3 1 0\n0 0 0\n1 0 inf\n0 1 0\n3 0 1 2\n",
    );
    assert_format(io::read_mesh(&p), &p, &["non-finite"]);
    let mut b = Vec::new();
    ply::write_to(&mut b, &pyramid()).unwrap();
    let header_len = b.windows(11).position(|w| w == b"end_header\n").unwrap() + 11;
    b[header_len + 8..header_len + 16].copy_from_slice(&f64::NAN.to_le_bytes());
    let p = write(&dir, "nan.ply", &b);
    assert_format(io::read_mesh(&p), &p, &["non-finite"]);
    let p = write(
        &dir,
        "nan.stl",
        &binary_stl(
            &[[[0.0, 0.0, 0.0], [f32::INFINITY, 0.0, 0.0], [0.0, 1.0, 0.0]]],
            b"",
        ),
    );
    assert_format(io::read_mesh(&p), &p, &["non-finite"]);

    let mut ponq = sample_ponq(1, 4, false);
    ponq.points[2][1] = f64::NAN;
    let p = dir.join("nan.npz");
    write_npz(&p, &ponq_arrays(&ponq), false, false, false);
    assert_format(npz::read_ponq(&p), &p, &["points[2]", "not finite"]);

    let p = dir.join("nan.npy");
    let g = npy::Grid3 {
        dims: [2, 2, 2],
        data: vec![0.0, 1.0, 2.0, 3.0, 4.0, f64::NAN, 6.0, 7.0],
    };
    assert!(matches!(
        npy::write_npy_grid_f32(&p, &g),
        Err(Error::InvalidInput(_))
    ));
    write_f32_npy(&p, &[2, 2, 2], &g.data);
    assert_format(npy::read_npy_grid(&p), &p, &["[1, 0, 1]", "NaN"]);
}

fn write_f32_npy(p: &Path, shape: &[u64], data: &[f64]) {
    use npyz::WriterBuilder;
    let mut w = npyz::WriteOptions::<f32>::new()
        .default_dtype()
        .shape(shape)
        .writer(std::io::BufWriter::new(std::fs::File::create(p).unwrap()))
        .begin_nd()
        .unwrap();
    w.extend(data.iter().map(|&v| v as f32)).unwrap();
    w.finish().unwrap();
}

#[test]
fn npz_missing_array() {
    let dir = scratch("npz_missing_array");
    let ponq = sample_ponq(2, 5, false);
    let arrays: Vec<_> = ponq_arrays(&ponq)
        .into_iter()
        .filter(|a| a.0 != "normals")
        .collect();
    let p = dir.join("missing.npz");
    write_npz(&p, &arrays, false, false, false);
    assert_format(
        npz::read_ponq(&p),
        &p,
        &["missing array 'normals'", "points, quadrics"],
    );
}

#[test]
fn npz_wrong_shape_dtype_and_size() {
    let dir = scratch("npz_wrong_shape_dtype_and_size");
    let ponq = sample_ponq(3, 5, true);

    let mut arrays = ponq_arrays(&ponq);
    arrays[2].1 = vec![5, 16];
    let p = dir.join("shape.npz");
    write_npz(&p, &arrays, false, false, false);
    assert_format(
        npz::read_ponq(&p),
        &p,
        &["'quadrics'", "expected shape (M, 4, 4)", "found (5, 16)"],
    );

    let mut arrays = ponq_arrays(&ponq);
    arrays[0].1 = vec![15];
    let p = dir.join("rank.npz");
    write_npz(&p, &arrays, false, false, false);
    assert_format(
        npz::read_ponq(&p),
        &p,
        &["expected shape (M, 3)", "found (15,)"],
    );

    let mut arrays = ponq_arrays(&ponq);
    arrays[3].1 = vec![4, 3];
    arrays[3].2.truncate(12);
    let p = dir.join("m.npz");
    write_npz(&p, &arrays, false, false, false);
    assert_format(
        npz::read_ponq(&p),
        &p,
        &["disagree", "points has 5", "vstars has 4"],
    );

    // An integer array.
    let p = dir.join("int.npz");
    {
        use npyz::WriterBuilder;
        let mut npz_w = npyz::npz::NpzWriter::create(&p).unwrap();
        for (name, shape, values) in ponq_arrays(&ponq) {
            if name == "points" {
                let mut w = npz_w
                    .array::<i64>(name, Default::default())
                    .unwrap()
                    .default_dtype()
                    .shape(&shape)
                    .begin_nd()
                    .unwrap();
                w.extend(values.iter().map(|&v| v as i64)).unwrap();
                w.finish().unwrap();
            } else {
                let mut w = npz_w
                    .array::<f64>(name, Default::default())
                    .unwrap()
                    .default_dtype()
                    .shape(&shape)
                    .begin_nd()
                    .unwrap();
                w.extend(values).unwrap();
                w.finish().unwrap();
            }
        }
        npz_w.zip_writer().finish().unwrap();
    }
    assert_format(
        npz::read_ponq(&p),
        &p,
        &["'points'", "unsupported dtype '<i8'"],
    );

    // A grid of the wrong rank.
    let p = dir.join("rank2.npy");
    write_f32_npy(&p, &[2, 3], &[0.0; 6]);
    assert_format(npy::read_npy_grid(&p), &p, &["rank 3", "(2, 3)"]);

    // A truncated grid.
    let p = dir.join("trunc.npy");
    write_f32_npy(&p, &[2, 3, 4], &[0.5; 24]);
    let b = std::fs::read(&p).unwrap();
    std::fs::write(&p, &b[..b.len() - 5]).unwrap();
    assert_format(npy::read_npy_grid(&p), &p, &["truncated"]);

    // A truncated npz.
    let p = dir.join("trunc.npz");
    npz::write_ponq(&p, &ponq).unwrap();
    let b = std::fs::read(&p).unwrap();
    std::fs::write(&p, &b[..b.len() / 2]).unwrap();
    assert_format(npz::read_ponq(&p), &p, &[]);
}

#[test]
fn writers_reject_invalid_input() {
    let dir = scratch("writers_reject_invalid_input");
    let bad_index = TriMesh {
        vertices: vec![[0.0; 3]; 3],
        faces: vec![[0, 1, 3]],
    };
    let nan = TriMesh {
        vertices: vec![[0.0, f64::NAN, 0.0]],
        faces: vec![],
    };
    for m in [&bad_index, &nan] {
        for name in ["a.obj", "a.ply", "a.off"] {
            let p = dir.join(name);
            assert!(matches!(io::write_mesh(&p, m), Err(Error::InvalidInput(_))));
            assert!(!p.exists());
        }
        assert!(ply::write_ascii(dir.join("b.ply"), m).is_err());
    }
    let mut ponq = sample_ponq(4, 3, false);
    ponq.normals.pop();
    assert!(matches!(
        npz::write_ponq(dir.join("p.npz"), &ponq),
        Err(Error::InvalidInput(_))
    ));
    let g = npy::Grid3 {
        dims: [2, 2, 2],
        data: vec![0.0; 7],
    };
    assert!(matches!(
        npy::write_npy_grid_f32(dir.join("g.npy"), &g),
        Err(Error::InvalidInput(_))
    ));
}
