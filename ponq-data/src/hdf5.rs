//! Reader for the authors' preprocessed HDF5 files (one file per shape): datasets
//! `pointcloud` `(N,3)`, `normals` `(N,3)` and `32_sdf` `(33,33,33)`, `64_sdf`, `128_sdf`,
//! all over the `[-0.5,0.5]^3` box. They are converted to the project's `[-1,1]` convention
//! (positions and distances times 2) and to a [`ShapeRecord`] with the occupancy of every
//! resolution. Pure Rust (`hdf5-pure`): no HDF5 C library is needed.

use std::path::Path;

use hdf5_pure::File;

use crate::dataset::ShapeRecord;
use crate::error::{DataError, Result};
use crate::occupancy::occupancy_from_samples;

fn err(path: &Path, msg: impl std::fmt::Display) -> DataError {
    DataError::Invalid(format!("{}: {msg}", path.display()))
}

fn read_floats(file: &File, path: &Path, name: &str) -> Result<Option<(Vec<usize>, Vec<f64>)>> {
    let Ok(ds) = file.dataset(name) else {
        return Ok(None);
    };
    let shape: Vec<usize> = ds
        .shape()
        .map_err(|e| err(path, format!("dataset '{name}': {e}")))?
        .into_iter()
        .map(|d| d as usize)
        .collect();
    let data = match ds.read_f64() {
        Ok(v) => v,
        Err(_) => ds
            .read_f32()
            .map_err(|e| err(path, format!("dataset '{name}' is not a float array: {e}")))?
            .into_iter()
            .map(f64::from)
            .collect(),
    };
    if shape.iter().product::<usize>() != data.len() {
        return Err(err(
            path,
            format!("dataset '{name}': shape {shape:?} vs {} values", data.len()),
        ));
    }
    if let Some(i) = data.iter().position(|x| !x.is_finite()) {
        return Err(err(
            path,
            format!("dataset '{name}': value {i} is not finite"),
        ));
    }
    Ok(Some((shape, data)))
}

fn rows3(path: &Path, name: &str, v: Option<(Vec<usize>, Vec<f64>)>) -> Result<Vec<[f32; 3]>> {
    let (shape, data) = v.ok_or_else(|| err(path, format!("missing dataset '{name}'")))?;
    if shape.len() != 2 || shape[1] != 3 {
        return Err(err(
            path,
            format!("dataset '{name}' must be (N, 3), found {shape:?}"),
        ));
    }
    Ok(data
        .chunks_exact(3)
        .map(|c| [c[0] as f32, c[1] as f32, c[2] as f32])
        .collect())
}

/// Reads one of the authors' HDF5 shape files into the `[-1,1]` convention.
///
/// # Errors
/// Not an HDF5 file, a missing `pointcloud` / `normals`, no `<res>_sdf` dataset, wrong shapes,
/// non-finite values — each message names the file and the dataset.
pub fn read_authors_h5(path: impl AsRef<Path>) -> Result<ShapeRecord> {
    let path = path.as_ref();
    let file = File::open(path).map_err(|e| err(path, format!("not a readable HDF5 file: {e}")))?;
    let mut rec = ShapeRecord {
        samples: rows3(path, "pointcloud", read_floats(&file, path, "pointcloud")?)?,
        normals: rows3(path, "normals", read_floats(&file, path, "normals")?)?,
        ..Default::default()
    };
    if rec.samples.len() != rec.normals.len() {
        return Err(err(path, "pointcloud and normals differ in length"));
    }
    for p in &mut rec.samples {
        *p = p.map(|x| 2.0 * x);
    }
    let pts: Vec<[f64; 3]> = rec.samples.iter().map(|p| p.map(f64::from)).collect();
    for res in [16usize, 32, 64, 128, 256] {
        let name = format!("{res}_sdf");
        if let Some((shape, data)) = read_floats(&file, path, &name)? {
            if shape != vec![res + 1; 3] {
                return Err(err(
                    path,
                    format!(
                        "dataset '{name}' must be ({0}, {0}, {0}), found {shape:?}",
                        res + 1
                    ),
                ));
            }
            rec.sdf
                .insert(res, data.iter().map(|&x| (2.0 * x) as f32).collect());
            rec.occupancy
                .insert(res, occupancy_from_samples(&pts, res)?);
        }
    }
    if rec.sdf.is_empty() {
        return Err(err(path, "no '<res>_sdf' dataset (expected e.g. '32_sdf')"));
    }
    Ok(rec)
}
