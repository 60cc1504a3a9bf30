//! The PoNQ file: a NumPy `.npz` archive with the arrays
//!
//! * `points`: `(M, 3)`, the point positions,
//! * `normals`: `(M, 3)`,
//! * `quadrics`: `(M, 4, 4)`, each the symmetric matrix `[[A, -b], [-b^T, c]]`
//!   (see [`Quadric::to_matrix4`]),
//! * `vstars` (optional): `(M, 3)`, the QEM-optimal vertices.
//!
//! Arrays may be `float32` or `float64`, either byte order, C or Fortran order, stored or
//! deflate-compressed (`np.savez` and `np.savez_compressed` both work). Other arrays in the
//! archive are ignored. [`write_ponq`] writes `float64` C-order arrays, uncompressed, like
//! `np.savez`, so a write/read round trip of a PoNQ with symmetric quadric matrices is exact.
//! Entries carry a fixed date (1980-01-01), so the same arrays give the same bytes (records of
//! a dataset prepared on several machines compare and hash equal).
//!
//! ```python
//! import numpy as np
//! d = np.load("shape.npz"); d["points"].shape, d["quadrics"].shape   # (M, 3), (M, 4, 4)
//! ```

use std::io::{BufReader, BufWriter, Cursor, Read, Seek, Write};
use std::path::Path;

use nalgebra::Matrix4;
use npyz::WriterBuilder;
use npyz::zip::{self, ZipArchive, result::ZipError};

use super::npy::{NpyArray, read_array, shape_str};
use crate::error::{Error, Result};
use crate::ponq::Ponq;
use crate::quadric::Quadric;

/// Reads a PoNQ `.npz` file; see the [module documentation](self) for the layout.
///
/// Errors name the file and say what is wrong: not a zip archive, a missing array (which),
/// a wrong shape (expected and found), an unsupported dtype, arrays disagreeing on `M`,
/// truncated data, non-finite values.
pub fn read_ponq(path: impl AsRef<Path>) -> Result<Ponq> {
    let path = path.as_ref();
    let file = std::fs::File::open(path).map_err(|e| Error::io(path, e))?;
    read_from(BufReader::new(file)).map_err(|m| Error::format(path, m))
}

/// Parses a PoNQ `.npz` file already in memory; errors are plain messages.
pub fn parse_ponq(bytes: &[u8]) -> std::result::Result<Ponq, String> {
    read_from(Cursor::new(bytes))
}

fn get_array<R: Read + Seek>(
    zip: &mut ZipArchive<R>,
    name: &str,
) -> std::result::Result<Option<NpyArray>, String> {
    let file_name = npyz::npz::file_name_from_array_name(name);
    let mut f = match zip.by_name(&file_name) {
        Ok(f) => f,
        Err(ZipError::FileNotFound) => return Ok(None),
        Err(e) => return Err(format!("array '{name}': {e}")),
    };
    let size = f.size();
    let reader = BufReader::with_capacity(1 << 16, (&mut f).take(size));
    read_array(reader, size)
        .map(Some)
        .map_err(|m| format!("array '{name}': {m}"))
}

fn require<R: Read + Seek>(
    zip: &mut ZipArchive<R>,
    name: &str,
) -> std::result::Result<NpyArray, String> {
    match get_array(zip, name)? {
        Some(a) => Ok(a),
        None => {
            let mut names: Vec<&str> = zip
                .file_names()
                .filter_map(npyz::npz::array_name_from_file_name)
                .collect();
            names.sort_unstable();
            Err(format!(
                "missing array '{name}' (the archive holds: {})",
                if names.is_empty() {
                    "no array".to_string()
                } else {
                    names.join(", ")
                }
            ))
        }
    }
}

/// Checks that `a` has shape `(M, tail...)` and returns `M`.
fn check_shape(name: &str, a: &NpyArray, tail: &[usize]) -> std::result::Result<usize, String> {
    let ok = a.shape.len() == tail.len() + 1 && a.shape[1..] == *tail;
    if !ok {
        let expected = std::iter::once("M".to_string())
            .chain(tail.iter().map(|d| d.to_string()))
            .collect::<Vec<_>>()
            .join(", ");
        return Err(format!(
            "array '{name}': expected shape ({expected}), found {}",
            shape_str(&a.shape)
        ));
    }
    Ok(a.shape[0])
}

fn rows3(a: &NpyArray) -> Vec<[f64; 3]> {
    a.data.chunks_exact(3).map(|c| [c[0], c[1], c[2]]).collect()
}

fn read_from<R: Read + Seek>(r: R) -> std::result::Result<Ponq, String> {
    let mut zip = ZipArchive::new(r).map_err(|e| format!("not a .npz (zip) archive: {e}"))?;
    let points = require(&mut zip, "points")?;
    let normals = require(&mut zip, "normals")?;
    let quadrics = require(&mut zip, "quadrics")?;
    let vstars = get_array(&mut zip, "vstars")?;

    let m = check_shape("points", &points, &[3])?;
    let mut ms = vec![("points", m)];
    ms.push(("normals", check_shape("normals", &normals, &[3])?));
    ms.push(("quadrics", check_shape("quadrics", &quadrics, &[4, 4])?));
    if let Some(v) = &vstars {
        ms.push(("vstars", check_shape("vstars", v, &[3])?));
    }
    if ms.iter().any(|&(_, k)| k != m) {
        let list = ms
            .iter()
            .map(|(n, k)| format!("{n} has {k}"))
            .collect::<Vec<_>>()
            .join(", ");
        return Err(format!(
            "the arrays disagree on the number of points M: {list}"
        ));
    }
    let qs = quadrics
        .data
        .chunks_exact(16)
        .map(|c| Quadric::from_matrix4(&Matrix4::from_row_slice(c)))
        .collect();
    Ponq::new(
        rows3(&points),
        rows3(&normals),
        qs,
        vstars.as_ref().map(rows3),
    )
    .map_err(|e| match e {
        Error::InvalidInput(m) => m,
        other => other.to_string(),
    })
}

fn check_ponq(p: &Ponq) -> Result<()> {
    let m = p.points.len();
    let v = p.vstars.as_ref().map_or(m, |v| v.len());
    if p.normals.len() != m || p.quadrics.len() != m || v != m {
        return Err(Error::InvalidInput(format!(
            "cannot write a PoNQ with {m} points, {} normals, {} quadrics and {v} vstars",
            p.normals.len(),
            p.quadrics.len()
        )));
    }
    Ok(())
}

fn write_array<W: Write + Seek>(
    npz: &mut npyz::npz::NpzWriter<W>,
    name: &str,
    shape: &[u64],
    values: impl Iterator<Item = f64>,
) -> std::io::Result<()> {
    let bytes = shape.iter().fold(8u64, |a, &d| a.saturating_mul(d));
    let options = zip::write::FileOptions::default()
        .compression_method(zip::CompressionMethod::Stored)
        .last_modified_time(zip::DateTime::default())
        .large_file(bytes > u32::MAX as u64 / 2);
    let mut w = npz
        .array::<f64>(name, options)?
        .default_dtype()
        .shape(shape)
        .begin_nd()?;
    w.extend(values)?;
    w.finish()
}

/// Writes `ponq` to the `.npz` file `path` as `float64` arrays `points`, `normals`,
/// `quadrics` and, when present, `vstars`.
///
/// Errors: [`Error::InvalidInput`] when the vectors of `ponq` have different lengths,
/// [`Error::Io`] (naming the file) when writing fails.
pub fn write_ponq(path: impl AsRef<Path>, ponq: &Ponq) -> Result<()> {
    let path = path.as_ref();
    check_ponq(ponq)?;
    let io = |e: std::io::Error| Error::io(path, e);
    let file = std::fs::File::create(path).map_err(io)?;
    let mut npz = npyz::npz::NpzWriter::new(BufWriter::new(file));
    let m = ponq.points.len() as u64;
    write_array(
        &mut npz,
        "points",
        &[m, 3],
        ponq.points.iter().flatten().copied(),
    )
    .map_err(io)?;
    write_array(
        &mut npz,
        "normals",
        &[m, 3],
        ponq.normals.iter().flatten().copied(),
    )
    .map_err(io)?;
    write_array(
        &mut npz,
        "quadrics",
        &[m, 4, 4],
        ponq.quadrics.iter().flat_map(|q| {
            let mat = q.to_matrix4();
            (0..16).map(move |k| mat[(k / 4, k % 4)])
        }),
    )
    .map_err(io)?;
    if let Some(v) = &ponq.vstars {
        write_array(&mut npz, "vstars", &[m, 3], v.iter().flatten().copied()).map_err(io)?;
    }
    let mut w = npz
        .zip_writer()
        .finish()
        .map_err(|e| io(std::io::Error::other(e)))?;
    w.flush().map_err(io)
}

/// One named array of an `.npz` archive: `shape` in C order and the values, stored as
/// `float32` (`f32_storage`) or `float64`.
#[derive(Debug, Clone, PartialEq)]
pub struct NamedArray {
    /// Array name (the file `NAME.npy` in the archive).
    pub name: String,
    /// Shape, C order.
    pub shape: Vec<usize>,
    /// Values, C order; `shape.iter().product()` of them.
    pub data: Vec<f64>,
    /// Store as `float32` instead of `float64`.
    pub f32_storage: bool,
}

/// Writes named float arrays to an `.npz` archive (uncompressed, like `np.savez`).
///
/// # Errors
/// [`Error::InvalidInput`] for a shape that does not match its data, [`Error::Io`] when
/// writing fails.
pub fn write_arrays(path: impl AsRef<Path>, arrays: &[NamedArray]) -> Result<()> {
    let path = path.as_ref();
    for a in arrays {
        if a.shape.iter().product::<usize>() != a.data.len() {
            return Err(Error::InvalidInput(format!(
                "array '{}': shape {} does not hold {} values",
                a.name,
                shape_str(&a.shape),
                a.data.len()
            )));
        }
    }
    let io = |e: std::io::Error| Error::io(path, e);
    let file = std::fs::File::create(path).map_err(io)?;
    let mut npz = npyz::npz::NpzWriter::new(BufWriter::new(file));
    for a in arrays {
        let shape: Vec<u64> = a.shape.iter().map(|&d| d as u64).collect();
        if a.f32_storage {
            let bytes = shape.iter().fold(4u64, |acc, &d| acc.saturating_mul(d));
            let options = zip::write::FileOptions::default()
                .compression_method(zip::CompressionMethod::Stored)
                .last_modified_time(zip::DateTime::default())
                .large_file(bytes > u32::MAX as u64 / 2);
            let mut w = npz
                .array::<f32>(&a.name, options)
                .map_err(io)?
                .default_dtype()
                .shape(&shape)
                .begin_nd()
                .map_err(io)?;
            w.extend(a.data.iter().map(|&x| x as f32)).map_err(io)?;
            w.finish().map_err(io)?;
        } else {
            write_array(&mut npz, &a.name, &shape, a.data.iter().copied()).map_err(io)?;
        }
    }
    let mut w = npz
        .zip_writer()
        .finish()
        .map_err(|e| io(std::io::Error::other(e)))?;
    w.flush().map_err(io)
}

/// Reads every float array of an `.npz` archive (any float dtype, byte order or memory
/// order), sorted by name. Arrays of other dtypes are an error naming the array.
///
/// # Errors
/// [`Error::Io`] for an unreadable file, [`Error::Format`] for anything that is not a valid
/// archive of float arrays.
pub fn read_arrays(path: impl AsRef<Path>) -> Result<Vec<(String, NpyArray)>> {
    let path = path.as_ref();
    let file = std::fs::File::open(path).map_err(|e| Error::io(path, e))?;
    let mut zip = ZipArchive::new(BufReader::new(file))
        .map_err(|e| Error::format(path, format!("not a .npz (zip) archive: {e}")))?;
    let mut names: Vec<String> = zip
        .file_names()
        .filter_map(npyz::npz::array_name_from_file_name)
        .map(str::to_string)
        .collect();
    names.sort_unstable();
    let mut out = Vec::with_capacity(names.len());
    for name in names {
        match get_array(&mut zip, &name) {
            Ok(Some(a)) => out.push((name, a)),
            Ok(None) => {}
            Err(m) => return Err(Error::format(path, m)),
        }
    }
    Ok(out)
}
