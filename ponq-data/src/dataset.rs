//! The project's own dataset format: one `.npz` per shape, in the `[-1,1]` frame, with the
//! array names of the authors' HDF5 files where they exist:
//!
//! * `pointcloud` `(N, 3)` float32: area-weighted surface samples,
//! * `normals` `(N, 3)` float32: their unit face normals,
//! * `{res}_sdf` `(res+1, res+1, res+1)` float32: signed distance on the nodes of a grid
//!   over `[-1,1]^3` (C order, x slowest, negative inside) — unlike the authors' files, no
//!   factor 2 is needed,
//! * `{res}_occupancy` `(res, res, res)` float32 (0 or 1): ground-truth occupancy of the cells
//!   (SPEC section 4).
//!
//! A split file (one id per line, like `../shared/splits/*.txt`) selects shapes of a folder:
//! see [`read_split`].

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use ponq_mesh::io::npz::{NamedArray, read_arrays, write_arrays};

use crate::error::{DataError, Result};

/// One training / evaluation shape.
///
/// Invariants: `normals.len() == samples.len()`; `sdf[res]` has `(res+1)^3` values and
/// `occupancy[res]` has `res^3`.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct ShapeRecord {
    /// Surface samples.
    pub samples: Vec<[f32; 3]>,
    /// Unit normals of the samples.
    pub normals: Vec<[f32; 3]>,
    /// SDF grids by resolution `res` (cells per side).
    pub sdf: BTreeMap<usize, Vec<f32>>,
    /// Occupancy by resolution.
    pub occupancy: BTreeMap<usize, Vec<bool>>,
}

fn rows(data: &[[f32; 3]]) -> Vec<f64> {
    data.iter().flatten().map(|&x| f64::from(x)).collect()
}

impl ShapeRecord {
    /// Checks the invariants.
    pub fn validate(&self) -> Result<()> {
        if self.normals.len() != self.samples.len() {
            return Err(DataError::Invalid(format!(
                "{} samples but {} normals",
                self.samples.len(),
                self.normals.len()
            )));
        }
        for (&r, g) in &self.sdf {
            if g.len() != (r + 1).pow(3) {
                return Err(DataError::Invalid(format!(
                    "sdf at resolution {r} has {} values, expected {}",
                    g.len(),
                    (r + 1).pow(3)
                )));
            }
        }
        for (&r, g) in &self.occupancy {
            if g.len() != r.pow(3) {
                return Err(DataError::Invalid(format!(
                    "occupancy at resolution {r} has {} values, expected {}",
                    g.len(),
                    r.pow(3)
                )));
            }
        }
        Ok(())
    }

    /// Writes the record atomically (a temporary file renamed into place), so an interrupted
    /// run never leaves a half-written shape behind.
    pub fn write(&self, path: impl AsRef<Path>) -> Result<()> {
        self.validate()?;
        let path = path.as_ref();
        let n = self.samples.len();
        let mut arrays = vec![
            NamedArray {
                name: "pointcloud".into(),
                shape: vec![n, 3],
                data: rows(&self.samples),
                f32_storage: true,
            },
            NamedArray {
                name: "normals".into(),
                shape: vec![n, 3],
                data: rows(&self.normals),
                f32_storage: true,
            },
        ];
        for (&r, g) in &self.sdf {
            arrays.push(NamedArray {
                name: format!("{r}_sdf"),
                shape: vec![r + 1; 3],
                data: g.iter().map(|&x| f64::from(x)).collect(),
                f32_storage: true,
            });
        }
        for (&r, g) in &self.occupancy {
            arrays.push(NamedArray {
                name: format!("{r}_occupancy"),
                shape: vec![r; 3],
                data: g.iter().map(|&b| if b { 1.0 } else { 0.0 }).collect(),
                f32_storage: true,
            });
        }
        let tmp = tmp_path(path);
        write_arrays(&tmp, &arrays)?;
        std::fs::rename(&tmp, path).map_err(|e| ponq_mesh::Error::io(path, e))?;
        Ok(())
    }

    /// Reads a record written by [`ShapeRecord::write`] (or any `.npz` with those arrays).
    pub fn read(path: impl AsRef<Path>) -> Result<Self> {
        let path = path.as_ref();
        let bad = |m: String| DataError::Invalid(format!("{}: {m}", path.display()));
        let mut rec = ShapeRecord::default();
        for (name, a) in read_arrays(path)? {
            let to3 = |a: &ponq_mesh::io::npy::NpyArray| -> Result<Vec<[f32; 3]>> {
                if a.shape.len() != 2 || a.shape[1] != 3 {
                    return Err(bad(format!("array '{name}' must have shape (N, 3)")));
                }
                Ok(a.data
                    .chunks_exact(3)
                    .map(|c| [c[0] as f32, c[1] as f32, c[2] as f32])
                    .collect())
            };
            if name == "pointcloud" {
                rec.samples = to3(&a)?;
            } else if name == "normals" {
                rec.normals = to3(&a)?;
            } else if let Some(r) = name.strip_suffix("_sdf").and_then(|r| r.parse().ok()) {
                if a.shape != vec![r + 1; 3] {
                    return Err(bad(format!(
                        "array '{name}' must be ({0}, {0}, {0})",
                        r + 1
                    )));
                }
                rec.sdf
                    .insert(r, a.data.iter().map(|&x| x as f32).collect());
            } else if let Some(r) = name.strip_suffix("_occupancy").and_then(|r| r.parse().ok()) {
                if a.shape != vec![r; 3] {
                    return Err(bad(format!("array '{name}' must be ({r}, {r}, {r})")));
                }
                rec.occupancy
                    .insert(r, a.data.iter().map(|&x| x > 0.5).collect());
            }
        }
        if rec.samples.is_empty() && rec.sdf.is_empty() {
            return Err(bad(
                "no 'pointcloud' and no '<res>_sdf' array: not a shape record".into(),
            ));
        }
        rec.validate()?;
        Ok(rec)
    }
}

fn tmp_path(path: &Path) -> PathBuf {
    let mut name = path
        .file_name()
        .map(|n| n.to_os_string())
        .unwrap_or_default();
    name.push(".tmp");
    path.with_file_name(name)
}

/// Ids of a split file: one id per line; blank lines and `#` comments are ignored.
pub fn read_split(path: impl AsRef<Path>) -> Result<Vec<String>> {
    let path = path.as_ref();
    let text = std::fs::read_to_string(path).map_err(|e| ponq_mesh::Error::io(path, e))?;
    Ok(text
        .lines()
        .map(|l| l.split('#').next().unwrap_or("").trim())
        .filter(|l| !l.is_empty())
        .map(str::to_string)
        .collect())
}

/// The record files of `dir` selected by `ids` (`<id>.npz`), and the ids that have no file.
pub fn select(dir: impl AsRef<Path>, ids: &[String]) -> (Vec<PathBuf>, Vec<String>) {
    let dir = dir.as_ref();
    let mut found = Vec::new();
    let mut missing = Vec::new();
    for id in ids {
        let p = dir.join(format!("{id}.npz"));
        if p.is_file() {
            found.push(p);
        } else {
            missing.push(id.clone());
        }
    }
    (found, missing)
}
