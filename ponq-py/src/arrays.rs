//! Array conversion: NumPy arrays (any real dtype, any memory order) in, checked as the
//! programs check their files (grids, meshes, PoNQs), and float64 / int64 arrays out.

use nalgebra::Matrix4;
use numpy::{PyArray1, PyArrayMethods, PyReadonlyArrayDyn, PyUntypedArrayMethods};
use ponq_mesh::io::npy::{Grid3, shape_str};
use ponq_mesh::{Ponq, Quadric, TriMesh};
use pyo3::exceptions::PyRuntimeError;
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyTuple};

use crate::errors::value_err;

/// An array-like as C-order values of `dtype` (`"float64"` or `"int64"`) with its shape,
/// after checking that its dtype kind is one of `kinds` (NumPy's `dtype.kind` letters).
fn array_as<'py, T: numpy::Element + Copy>(
    obj: &Bound<'py, PyAny>,
    name: &str,
    dtype: &str,
    kinds: &str,
    what: &str,
) -> PyResult<(Vec<usize>, Vec<T>)> {
    let py = obj.py();
    let np = py.import("numpy")?;
    let arr = np.call_method1("asarray", (obj,))?;
    let dt = arr.getattr("dtype")?;
    let kind: String = dt.getattr("kind")?.extract()?;
    let size: usize = arr.getattr("size")?.extract()?;
    // An empty list comes in as float64: any dtype will do for no values.
    if size > 0 && !kinds.contains(kind.as_str()) {
        return Err(value_err(format!(
            "{name}: expected {what}, got an array of dtype {}",
            dt.str()?
        )));
    }
    let kw = PyDict::new(py);
    kw.set_item("dtype", dtype)?;
    let c = np.call_method("ascontiguousarray", (arr,), Some(&kw))?;
    let ro: PyReadonlyArrayDyn<'py, T> = c.extract()?;
    let shape = ro.shape().to_vec();
    let data = ro
        .as_slice()
        .map_err(|e| PyRuntimeError::new_err(format!("{name}: {e}")))?
        .to_vec();
    Ok((shape, data))
}

/// Real values (any float, int or unsigned dtype, any memory order) as `f64`, C order.
pub(crate) fn floats(obj: &Bound<'_, PyAny>, name: &str) -> PyResult<(Vec<usize>, Vec<f64>)> {
    array_as::<f64>(obj, name, "float64", "fiu", "an array of real numbers")
}

/// Integers (any int or unsigned dtype) as `i64`, C order.
pub(crate) fn ints(obj: &Bound<'_, PyAny>, name: &str) -> PyResult<(Vec<usize>, Vec<i64>)> {
    array_as::<i64>(obj, name, "int64", "iu", "an array of integers")
}

/// An `(M, 3)` array's rows; `letter` names `M` in the message.
pub(crate) fn rows3(
    shape: &[usize],
    data: &[f64],
    name: &str,
    letter: &str,
) -> PyResult<Vec<[f64; 3]>> {
    if shape.len() != 2 || shape[1] != 3 {
        return Err(value_err(format!(
            "array '{name}': expected shape ({letter}, 3), found {}",
            shape_str(shape)
        )));
    }
    Ok(data.chunks_exact(3).map(|c| [c[0], c[1], c[2]]).collect())
}

/// A 3D grid (rank 3, finite values), checked as `ponq-infer` checks a `.npy` grid.
pub(crate) fn grid3(obj: &Bound<'_, PyAny>) -> PyResult<Grid3> {
    let (shape, data) = floats(obj, "sdf")?;
    if shape.len() != 3 {
        return Err(value_err(format!(
            "expected a 3D grid (rank 3), found an array of shape {}",
            shape_str(&shape)
        )));
    }
    let dims = [shape[0], shape[1], shape[2]];
    if let Some(p) = data.iter().position(|v| !v.is_finite()) {
        let k = p % dims[2];
        let j = (p / dims[2]) % dims[1];
        let i = p / (dims[2] * dims[1]);
        return Err(value_err(format!(
            "grid value at [{i}, {j}, {k}] is {}",
            data[p]
        )));
    }
    Ok(Grid3 { dims, data })
}

/// A triangle mesh from `(V, 3)` vertices and `(F, 3)` faces (0-based), checked as the mesh
/// readers check a file.
pub(crate) fn mesh_in(
    vertices: &Bound<'_, PyAny>,
    faces: &Bound<'_, PyAny>,
    name: &str,
) -> PyResult<TriMesh> {
    let vname = format!("{name}vertices");
    let fname = format!("{name}faces");
    let (vs, vd) = floats(vertices, &vname)?;
    let vertices = rows3(&vs, &vd, &vname, "V")?;
    if let Some(i) = vertices
        .iter()
        .position(|v| v.iter().any(|c| !c.is_finite()))
    {
        return Err(value_err(format!(
            "vertex {i} = {:?} has a non-finite coordinate",
            vertices[i]
        )));
    }
    let (fs, fd) = ints(faces, &fname)?;
    // An empty list of faces comes in as shape (0,).
    let fs = if fs == [0] { vec![0, 3] } else { fs };
    if fs.len() != 2 || fs[1] != 3 {
        return Err(value_err(format!(
            "array '{fname}': expected shape (F, 3), found {}",
            shape_str(&fs)
        )));
    }
    let n = vertices.len();
    let mut out = Vec::with_capacity(fd.len() / 3);
    for (id, f) in fd.chunks_exact(3).enumerate() {
        if let Some(&b) = f.iter().find(|&&i| i < 0 || i as u64 >= n as u64) {
            return Err(value_err(format!(
                "face {id} refers to vertex {b} but there are only {n} vertices (indices are 0-based here)"
            )));
        }
        out.push([f[0] as u32, f[1] as u32, f[2] as u32]);
    }
    if n > u32::MAX as usize {
        return Err(value_err("more vertices than 32-bit indices can address"));
    }
    Ok(TriMesh {
        vertices,
        faces: out,
    })
}

/// A PoNQ from arrays, checked as `ponq_mesh::io::npz` checks a file.
pub(crate) fn ponq_in(
    points: &Bound<'_, PyAny>,
    normals: &Bound<'_, PyAny>,
    quadrics: &Bound<'_, PyAny>,
    vstars: Option<&Bound<'_, PyAny>>,
) -> PyResult<Ponq> {
    let shape_err = |name: &str, tail: &str, s: &[usize]| {
        value_err(format!(
            "array '{name}': expected shape (M, {tail}), found {}",
            shape_str(s)
        ))
    };
    let (ps, pd) = floats(points, "points")?;
    let (ns, nd) = floats(normals, "normals")?;
    let (qs, qd) = floats(quadrics, "quadrics")?;
    let vs = match vstars {
        Some(v) if !v.is_none() => Some(floats(v, "vstars")?),
        _ => None,
    };
    let p = rows3(&ps, &pd, "points", "M")?;
    let n = rows3(&ns, &nd, "normals", "M")?;
    if !(qs.len() == 3 && qs[1] == 4 && qs[2] == 4) {
        return Err(shape_err("quadrics", "4, 4", &qs));
    }
    let v = match &vs {
        Some((s, d)) => Some(rows3(s, d, "vstars", "M")?),
        None => None,
    };
    let mut ms = vec![
        ("points", p.len()),
        ("normals", n.len()),
        ("quadrics", qs[0]),
    ];
    if let Some(v) = &v {
        ms.push(("vstars", v.len()));
    }
    if ms.iter().any(|&(_, k)| k != p.len()) {
        let list = ms
            .iter()
            .map(|(n, k)| format!("{n} has {k}"))
            .collect::<Vec<_>>()
            .join(", ");
        return Err(value_err(format!(
            "the arrays disagree on the number of points M: {list}"
        )));
    }
    let q = qd
        .chunks_exact(16)
        .map(|c| Quadric::from_matrix4(&Matrix4::from_row_slice(c)))
        .collect();
    Ponq::new(p, n, q, v).map_err(|e| match e {
        ponq_mesh::Error::InvalidInput(m) => value_err(m),
        other => value_err(other.to_string()),
    })
}

pub(crate) fn vec3_out<'py>(py: Python<'py>, v: &[[f64; 3]]) -> PyResult<Bound<'py, PyAny>> {
    let flat: Vec<f64> = v.iter().flatten().copied().collect();
    Ok(PyArray1::from_vec(py, flat)
        .reshape([v.len(), 3])?
        .into_any())
}

fn faces_out<'py>(py: Python<'py>, f: &[[u32; 3]]) -> PyResult<Bound<'py, PyAny>> {
    let flat: Vec<i64> = f.iter().flatten().map(|&i| i64::from(i)).collect();
    Ok(PyArray1::from_vec(py, flat)
        .reshape([f.len(), 3])?
        .into_any())
}

/// A colour per grid node from an `(nx, ny, nz, 3)` array of floats in `[0, 1]` or of bytes
/// (any integer dtype, 0 to 255), matching the grid's `dims`.
pub(crate) fn grid_colours(
    obj: &Bound<'_, PyAny>,
    dims: [usize; 3],
) -> PyResult<Vec<ponq_mesh::colour::Rgb>> {
    let bytes = obj
        .getattr("dtype")
        .and_then(|d| d.getattr("kind"))
        .and_then(|k| k.extract::<String>())
        .is_ok_and(|k| k == "u" || k == "i");
    let (shape, data) = floats(obj, "colours")?;
    if shape != [dims[0], dims[1], dims[2], 3] {
        return Err(value_err(format!(
            "colours: expected the grid's shape with 3 channels, ({}, {}, {}, 3), found {}",
            dims[0],
            dims[1],
            dims[2],
            shape_str(&shape)
        )));
    }
    let (scale, top) = if bytes {
        (1.0 / 255.0, 255.0)
    } else {
        (1.0, 1.0)
    };
    if let Some(v) = data
        .iter()
        .find(|v| !(v.is_finite() && **v >= 0.0 && **v <= top))
    {
        return Err(value_err(format!(
            "colours: {v} is outside [0, {top}] ({})",
            if bytes {
                "bytes"
            } else {
                "floats are in [0, 1]"
            }
        )));
    }
    Ok(data
        .chunks_exact(3)
        .map(|c| [c[0], c[1], c[2]].map(|x| (x * scale) as f32))
        .collect())
}

/// Colours as a float64 `(V, 3)` array in `[0, 1]`.
pub(crate) fn colours_out<'py>(
    py: Python<'py>,
    c: &[ponq_mesh::colour::Rgb],
) -> PyResult<Bound<'py, PyAny>> {
    let flat: Vec<f64> = c.iter().flatten().map(|&x| f64::from(x)).collect();
    Ok(PyArray1::from_vec(py, flat)
        .reshape([c.len(), 3])?
        .into_any())
}

pub(crate) fn mesh_out<'py>(py: Python<'py>, m: &TriMesh) -> PyResult<Vec<Bound<'py, PyAny>>> {
    Ok(vec![vec3_out(py, &m.vertices)?, faces_out(py, &m.faces)?])
}

/// The PoNQ as a dict of float64 arrays `points`, `normals`, `quadrics` (M, 4, 4), `vstars`.
pub(crate) fn ponq_out<'py>(py: Python<'py>, p: &Ponq) -> PyResult<Bound<'py, PyAny>> {
    let d = PyDict::new(py);
    d.set_item("points", vec3_out(py, &p.points)?)?;
    d.set_item("normals", vec3_out(py, &p.normals)?)?;
    let mut q = Vec::with_capacity(16 * p.len());
    for m in p.quadrics.iter().map(Quadric::to_matrix4) {
        for r in 0..4 {
            for c in 0..4 {
                q.push(m[(r, c)]);
            }
        }
    }
    d.set_item(
        "quadrics",
        PyArray1::from_vec(py, q).reshape([p.len(), 4, 4])?,
    )?;
    d.set_item("vstars", vec3_out(py, &p.vstars())?)?;
    Ok(d.into_any())
}

pub(crate) fn tuple<'py>(
    py: Python<'py>,
    items: Vec<Bound<'py, PyAny>>,
) -> PyResult<Bound<'py, PyTuple>> {
    PyTuple::new(py, items)
}
