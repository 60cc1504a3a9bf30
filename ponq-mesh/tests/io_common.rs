//! Helpers shared by the `io_*` integration tests (included with `#[path]`; as a test
//! target of its own it holds no test).
#![allow(dead_code)]

use std::path::{Path, PathBuf};

use nalgebra::{Matrix3, Vector3};
use ponq_mesh::{Ponq, Quadric, TriMesh};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

/// A fresh, empty scratch directory for one test.
pub fn scratch(test: &str) -> PathBuf {
    let dir = Path::new(env!("CARGO_TARGET_TMPDIR"))
        .join("ponq-mesh-io")
        .join(test);
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

/// The directory of the hand-written test files.
pub fn data(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("tests/data/io")
        .join(name)
}

/// Awkward but finite `f64` values that a text format must round-trip exactly.
pub const SPECIAL: [f64; 10] = [
    -0.0,
    0.1,
    0.30000000000000004,
    1e-300,
    5e-324,
    1e300,
    -1.7976931348623157e308,
    2.2250738585072014e-308,
    123456789.12345679,
    -1.0 / 3.0,
];

/// A deterministic random mesh with special coordinates, unreferenced vertices and
/// arbitrary vertex order.
pub fn sample_mesh(seed: u64, nv: usize, nf: usize) -> TriMesh {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let mut vertices: Vec<[f64; 3]> = (0..nv)
        .map(|_| {
            [
                rng.random_range(-1.0..1.0),
                rng.random_range(-1.0..1.0),
                rng.random_range(-1.0..1.0),
            ]
        })
        .collect();
    for (i, s) in SPECIAL.iter().enumerate() {
        if let Some(v) = vertices.get_mut(i) {
            v[i % 3] = *s;
        }
    }
    let faces = if nv == 0 {
        Vec::new()
    } else {
        (0..nf)
            .map(|_| {
                [
                    rng.random_range(0..nv as u32),
                    rng.random_range(0..nv as u32),
                    rng.random_range(0..nv as u32),
                ]
            })
            .collect()
    };
    TriMesh::new(vertices, faces).unwrap()
}

/// The square pyramid of the hand-written files: a quad base, fan-triangulated, and four
/// sides.
pub fn pyramid() -> TriMesh {
    TriMesh::new(
        vec![
            [0.0, 0.0, 0.0],
            [1.0, 0.0, 0.0],
            [1.0, 1.0, 0.0],
            [0.0, 1.0, 0.0],
            [0.5, 0.5, 1.0],
        ],
        vec![
            [3, 2, 1],
            [3, 1, 0],
            [0, 1, 4],
            [1, 2, 4],
            [2, 3, 4],
            [3, 0, 4],
        ],
    )
    .unwrap()
}

/// A deterministic random PoNQ with symmetric quadrics (so the 4x4 round trip is exact).
pub fn sample_ponq(seed: u64, m: usize, with_vstars: bool) -> Ponq {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let v3 = |rng: &mut ChaCha8Rng| {
        [
            rng.random_range(-1.0..1.0),
            rng.random_range(-1.0..1.0),
            rng.random_range(-1.0..1.0),
        ]
    };
    let points: Vec<[f64; 3]> = (0..m).map(|_| v3(&mut rng)).collect();
    let normals: Vec<[f64; 3]> = (0..m).map(|_| v3(&mut rng)).collect();
    let quadrics: Vec<Quadric> = (0..m)
        .map(|_| {
            let u = Matrix3::from_fn(|_, _| rng.random_range(-1.0..1.0));
            let a = u * u.transpose();
            let a = (a + a.transpose()) * 0.5;
            Quadric {
                a,
                b: Vector3::new(
                    rng.random_range(-1.0..1.0),
                    rng.random_range(-1.0..1.0),
                    rng.random_range(-1.0..1.0),
                ),
                c: rng.random_range(0.0..1.0),
            }
        })
        .collect();
    let vstars = with_vstars.then(|| (0..m).map(|_| v3(&mut rng)).collect());
    Ponq::new(points, normals, quadrics, vstars).unwrap()
}

/// Writes an `.npz` whose arrays are given as `(name, shape, values)`, in `float32`
/// (`f32 = true`) or `float64`, through `npyz`, optionally big-endian and/or Fortran order
/// (values are always given in C order).
pub fn write_npz(
    path: &Path,
    arrays: &[(&str, Vec<u64>, Vec<f64>)],
    f32: bool,
    big_endian: bool,
    fortran: bool,
) {
    use npyz::WriterBuilder;
    let file = std::io::BufWriter::new(std::fs::File::create(path).unwrap());
    let mut npz = npyz::npz::NpzWriter::new(file);
    for (name, shape, values) in arrays {
        let vals = if fortran {
            c_to_fortran(values, shape)
        } else {
            values.clone()
        };
        let order = if fortran {
            npyz::Order::Fortran
        } else {
            npyz::Order::C
        };
        let e = if big_endian { ">" } else { "<" };
        if f32 {
            let dtype = npyz::DType::Plain(format!("{e}f4").parse().unwrap());
            let mut w = npz
                .array::<f32>(name, Default::default())
                .unwrap()
                .dtype(dtype)
                .shape(shape)
                .order(order)
                .begin_nd()
                .unwrap();
            w.extend(vals.iter().map(|&v| v as f32)).unwrap();
            w.finish().unwrap();
        } else {
            let dtype = npyz::DType::Plain(format!("{e}f8").parse().unwrap());
            let mut w = npz
                .array::<f64>(name, Default::default())
                .unwrap()
                .dtype(dtype)
                .shape(shape)
                .order(order)
                .begin_nd()
                .unwrap();
            w.extend(vals.iter().copied()).unwrap();
            w.finish().unwrap();
        }
    }
    npz.zip_writer().finish().unwrap();
}

/// Reorders C-order values into Fortran order.
pub fn c_to_fortran(values: &[f64], shape: &[u64]) -> Vec<f64> {
    let shape: Vec<usize> = shape.iter().map(|&d| d as usize).collect();
    let rank = shape.len();
    let mut cstride = vec![1usize; rank];
    for a in (0..rank.saturating_sub(1)).rev() {
        cstride[a] = cstride[a + 1] * shape[a + 1];
    }
    let mut out = Vec::with_capacity(values.len());
    let mut idx = vec![0usize; rank];
    for _ in 0..values.len() {
        let off: usize = idx.iter().zip(&cstride).map(|(i, s)| i * s).sum();
        out.push(values[off]);
        // Fortran order: first axis fastest.
        for a in 0..rank {
            idx[a] += 1;
            if idx[a] < shape[a] {
                break;
            }
            idx[a] = 0;
        }
    }
    out
}

/// The arrays of a PoNQ as `(name, shape, C-order values)`.
pub fn ponq_arrays(p: &Ponq) -> Vec<(&'static str, Vec<u64>, Vec<f64>)> {
    let m = p.len() as u64;
    let flat = |v: &[[f64; 3]]| v.iter().flatten().copied().collect::<Vec<_>>();
    let mut out = vec![
        ("points", vec![m, 3], flat(&p.points)),
        ("normals", vec![m, 3], flat(&p.normals)),
        (
            "quadrics",
            vec![m, 4, 4],
            p.quadrics
                .iter()
                .flat_map(|q| {
                    let mat = q.to_matrix4();
                    (0..16).map(move |k| mat[(k / 4, k % 4)])
                })
                .collect(),
        ),
    ];
    if let Some(v) = &p.vstars {
        out.push(("vstars", vec![m, 3], flat(v)));
    }
    out
}

/// A binary STL from triangles (normals zero), with the given start of the 80-byte header.
pub fn binary_stl(tris: &[[[f32; 3]; 3]], header: &[u8]) -> Vec<u8> {
    let mut b = vec![0u8; 80];
    b[..header.len()].copy_from_slice(header);
    b.extend_from_slice(&(tris.len() as u32).to_le_bytes());
    for t in tris {
        b.extend_from_slice(&[0u8; 12]);
        for v in t {
            for c in v {
                b.extend_from_slice(&c.to_le_bytes());
            }
        }
        b.extend_from_slice(&[0u8; 2]);
    }
    b
}
