//! File formats: PoNQ `.npz` files and triangle meshes (OBJ, PLY, OFF, STL).
//!
//! * [`read_mesh`] / [`write_mesh`] pick the mesh format from the file extension
//!   (case-insensitive): OBJ, PLY, OFF and STL can be read; OBJ, PLY (binary little-endian)
//!   and OFF can be written.
//! * [`npz`] reads and writes the PoNQ representation ([`crate::Ponq`]) as a NumPy `.npz`
//!   archive; [`npy`] reads and writes standalone `.npy` arrays (3D grids).
//!
//! All readers treat the file content as untrusted: garbage, truncated files, out-of-range
//! indices, non-finite coordinates and absurd element counts give an [`Error`], never a panic,
//! and no memory is reserved from a count in a header beyond what the file size allows.
//! Polygons are fan-triangulated (`(a,b,c,d)` gives `(a,b,c)` and `(a,c,d)`); faces with fewer
//! than three corners are errors. Every error names the file.
//!
//! Each mesh module also has a `parse(&[u8])` function that reads a file already in memory and
//! returns a plain message on error, and (except [`stl`], read only) a
//! `write_to(impl Write, &TriMesh)` function.

mod builder;
mod coloured;
mod file;
pub mod npy;
pub mod npz;
pub mod obj;
pub mod off;
pub mod ply;
pub mod stl;

use std::path::Path;

pub use coloured::{read_mesh_coloured, read_mesh_coloured_noted, write_mesh_coloured};

use crate::error::{Error, Result};
use crate::trimesh::TriMesh;

/// The mesh formats [`read_mesh`] understands, by extension.
pub const READ_FORMATS: &[&str] = &["obj", "ply", "off", "stl"];

/// The mesh formats [`write_mesh`] can write, by extension.
pub const WRITE_FORMATS: &[&str] = &["obj", "ply", "off"];

/// The mesh file formats of this module.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum MeshFormat {
    /// Wavefront OBJ (`.obj`).
    Obj,
    /// Stanford PLY (`.ply`).
    Ply,
    /// Object File Format (`.off`).
    Off,
    /// STereoLithography (`.stl`), read only.
    Stl,
}

impl MeshFormat {
    /// The format of `path` from its extension (case-insensitive); `None` when the extension
    /// is missing or not one of `obj`, `ply`, `off`, `stl`.
    pub fn from_path(path: impl AsRef<Path>) -> Option<Self> {
        let ext = path.as_ref().extension()?.to_str()?.to_ascii_lowercase();
        match ext.as_str() {
            "obj" => Some(Self::Obj),
            "ply" => Some(Self::Ply),
            "off" => Some(Self::Off),
            "stl" => Some(Self::Stl),
            _ => None,
        }
    }
}

fn describe_extension(path: &Path) -> String {
    match path.extension() {
        Some(e) => format!("extension '.{}'", e.to_string_lossy()),
        None => "no extension".to_string(),
    }
}

/// Reads a triangle mesh, choosing the format from the extension (`.obj`, `.ply`, `.off`,
/// `.stl`, case-insensitive).
///
/// Polygons are fan-triangulated. Errors: [`Error::Unsupported`] for another extension,
/// [`Error::Io`] when the file cannot be read, [`Error::Format`] for invalid content (bad
/// syntax, truncation, a face index out of range, a non-finite coordinate, ...).
pub fn read_mesh(path: impl AsRef<Path>) -> Result<TriMesh> {
    let path = path.as_ref();
    match MeshFormat::from_path(path) {
        Some(MeshFormat::Obj) => obj::read(path),
        Some(MeshFormat::Ply) => ply::read(path),
        Some(MeshFormat::Off) => off::read(path),
        Some(MeshFormat::Stl) => stl::read(path),
        None => Err(Error::Unsupported(format!(
            "cannot read mesh {}: {}; supported mesh formats for reading: {}",
            path.display(),
            describe_extension(path),
            READ_FORMATS.join(", ")
        ))),
    }
}

/// Writes a triangle mesh, choosing the format from the extension: `.obj` (full `f64`
/// precision), `.ply` (binary little-endian, see [`ply::write`]; [`ply::write_ascii`] writes
/// ASCII) or `.off`.
///
/// Errors: [`Error::Unsupported`] for another extension (STL cannot be written),
/// [`Error::InvalidInput`] when the mesh has a face index out of range or a non-finite
/// coordinate, [`Error::Io`] when writing fails.
pub fn write_mesh(path: impl AsRef<Path>, mesh: &TriMesh) -> Result<()> {
    let path = path.as_ref();
    match MeshFormat::from_path(path) {
        Some(MeshFormat::Obj) => obj::write(path, mesh),
        Some(MeshFormat::Ply) => ply::write(path, mesh),
        Some(MeshFormat::Off) => off::write(path, mesh),
        _ => Err(Error::Unsupported(format!(
            "cannot write mesh {}: {}; supported mesh formats for writing: {}",
            path.display(),
            describe_extension(path),
            WRITE_FORMATS.join(", ")
        ))),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    #[test]
    fn format_from_path() {
        assert_eq!(MeshFormat::from_path("a/b.OBJ"), Some(MeshFormat::Obj));
        assert_eq!(MeshFormat::from_path("x.Ply"), Some(MeshFormat::Ply));
        assert_eq!(MeshFormat::from_path("x.off"), Some(MeshFormat::Off));
        assert_eq!(MeshFormat::from_path("x.stl"), Some(MeshFormat::Stl));
        assert_eq!(MeshFormat::from_path("x.gltf"), None);
        assert_eq!(MeshFormat::from_path("noext"), None);
    }

    #[test]
    fn unsupported_extension_lists_formats() {
        let e = read_mesh("shape.gltf").unwrap_err();
        let msg = e.to_string();
        assert!(matches!(e, Error::Unsupported(_)), "{msg}");
        assert!(
            msg.contains("shape.gltf") && msg.contains("obj, ply, off, stl"),
            "{msg}"
        );
        let e = write_mesh("shape.stl", &TriMesh::default()).unwrap_err();
        assert!(matches!(e, Error::Unsupported(_)));
        assert!(e.to_string().contains("obj, ply, off"));
    }
}
