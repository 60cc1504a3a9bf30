//! The shapes of an evaluation: the files of a data folder (meshes, `ponq-prep` records or the
//! authors' HDF5 files), restricted to a split, and each shape's ground truth and SDF grids in
//! the `[-1,1]` frame.

use std::path::{Path, PathBuf};

use anyhow::{Context, Result, bail};
use ponq_data::normalize::Normalization;
use ponq_data::sdf::MeshSdf;
use ponq_mesh::io::npy::Grid3;
use ponq_mesh::{TriMesh, io};

/// A shape to evaluate: its id (the file stem) and its file.
pub type Shape = (String, PathBuf);

const MESH_EXT: [&str; 4] = ["obj", "ply", "off", "stl"];

/// The shapes to evaluate: files of `data` (meshes, or `.npz` / `.hdf5` records) sorted by
/// name, restricted to a split's ids when given; also returns the split ids with no file.
pub fn inputs(data: &Path, split: Option<&Path>) -> Result<(Vec<Shape>, Vec<String>)> {
    let is_shape = |p: &Path| {
        p.extension()
            .and_then(|e| e.to_str())
            .map(|e| e.to_ascii_lowercase())
            .is_some_and(|e| {
                MESH_EXT.contains(&e.as_str()) || matches!(e.as_str(), "npz" | "hdf5" | "h5")
            })
    };
    // The folder is searched recursively (data sets are often grouped in sub-folders).
    let mut files: Vec<(String, PathBuf)> = Vec::new();
    let mut stack = vec![data.to_path_buf()];
    while let Some(dir) = stack.pop() {
        for e in
            std::fs::read_dir(&dir).with_context(|| format!("cannot list {}", dir.display()))?
        {
            let p = e
                .with_context(|| format!("cannot list {}", dir.display()))?
                .path();
            if p.is_dir() {
                stack.push(p);
            } else if is_shape(&p)
                && let Some(stem) = p.file_stem().and_then(|s| s.to_str())
            {
                files.push((stem.to_string(), p));
            }
        }
    }
    files.sort();
    // The id of a shape is its file stem: two files with one stem would be ambiguous.
    if let Some(w) = files.windows(2).find(|w| w[0].0 == w[1].0) {
        bail!(
            "two shapes with the id {:?} ({} and {}); ids are file stems and must be unique",
            w[0].0,
            w[0].1.display(),
            w[1].1.display()
        );
    }
    let mut missing = Vec::new();
    if let Some(split) = split {
        let ids = ponq_data::dataset::read_split(split)
            .with_context(|| format!("cannot read the split {}", split.display()))?;
        let have: std::collections::HashSet<&str> = files.iter().map(|f| f.0.as_str()).collect();
        missing = ids
            .iter()
            .filter(|id| !have.contains(id.as_str()))
            .cloned()
            .collect();
        let want: std::collections::HashSet<&str> = ids.iter().map(String::as_str).collect();
        files.retain(|f| want.contains(f.0.as_str()));
    }
    Ok((files, missing))
}

/// The group of a shape file: the first folder of its path below the data folder (e.g. `cad`
/// or `freeform`), or an empty string for a file directly in it.
pub fn group_of(data: &Path, file: &Path) -> String {
    file.strip_prefix(data)
        .ok()
        .and_then(|rel| {
            let mut c = rel.components();
            let first = c.next()?;
            c.next()?;
            Some(first.as_os_str().to_string_lossy().into_owned())
        })
        .unwrap_or_default()
}

/// Ground truth of a shape in the `[-1,1]` frame: the normalised mesh when the input is a
/// mesh, else the record's samples and normals, plus its SDF grids.
pub struct Truth {
    /// The normalised mesh, when the input is a mesh.
    pub mesh: Option<TriMesh>,
    /// Surface samples of a record (empty for a mesh).
    pub samples: Vec<[f64; 3]>,
    /// Their normals.
    pub normals: Vec<[f64; 3]>,
    /// The source of the SDF grids.
    pub sdf: MeshOrRecord,
}

/// Where the SDF grids of a shape come from.
pub enum MeshOrRecord {
    /// Grids computed from the normalised mesh.
    Mesh(Box<MeshSdf>),
    /// The record's stored grids, by resolution.
    Record(std::collections::BTreeMap<usize, Vec<f32>>),
}

/// Reads the ground truth of a shape file.
pub fn truth(path: &Path) -> Result<Truth> {
    let ext = path
        .extension()
        .and_then(|e| e.to_str())
        .map(|e| e.to_ascii_lowercase())
        .unwrap_or_default();
    if MESH_EXT.contains(&ext.as_str()) {
        let m = io::read_mesh(path)?;
        let m = Normalization::of(&m)?.apply_mesh(&m);
        let sdf = MeshSdf::new(&m)?;
        Ok(Truth {
            mesh: Some(m),
            samples: vec![],
            normals: vec![],
            sdf: MeshOrRecord::Mesh(Box::new(sdf)),
        })
    } else {
        let rec = if ext == "npz" {
            ponq_data::dataset::ShapeRecord::read(path)?
        } else {
            ponq_data::hdf5::read_authors_h5(path)?
        };
        let f = |v: &[[f32; 3]]| v.iter().map(|p| p.map(f64::from)).collect();
        Ok(Truth {
            mesh: None,
            samples: f(&rec.samples),
            normals: f(&rec.normals),
            sdf: MeshOrRecord::Record(rec.sdf),
        })
    }
}

/// The SDF grid of a shape at `res` cells per side.
pub fn grid_of(t: &Truth, res: usize) -> Result<Grid3> {
    let values: Vec<f64> = match &t.sdf {
        MeshOrRecord::Mesh(s) => s
            .grid(res, |_| {})?
            .values
            .iter()
            .map(|&v| f64::from(v))
            .collect(),
        MeshOrRecord::Record(g) => g
            .get(&res)
            .with_context(|| format!("the record has no SDF grid at resolution {res}"))?
            .iter()
            .map(|&v| f64::from(v))
            .collect(),
    };
    Ok(Grid3::new([res + 1; 3], values)?)
}
