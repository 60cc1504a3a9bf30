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

pub mod npy;
pub mod npz;
pub mod obj;
pub mod off;
pub mod ply;
pub mod stl;

use std::path::Path;

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

// ---------------------------------------------------------------------------------------------
// Shared helpers.

/// Reads a whole file, naming it in the error.
pub(crate) fn read_file(path: &Path) -> Result<Vec<u8>> {
    std::fs::read(path).map_err(|e| Error::io(path, e))
}

/// Creates `path`, lets `f` write into a buffered writer and flushes, naming the file in
/// every error.
pub(crate) fn write_file(
    path: &Path,
    f: impl FnOnce(&mut std::io::BufWriter<std::fs::File>) -> std::io::Result<()>,
) -> Result<()> {
    use std::io::Write;
    let file = std::fs::File::create(path).map_err(|e| Error::io(path, e))?;
    let mut w = std::io::BufWriter::with_capacity(1 << 20, file);
    f(&mut w).map_err(|e| Error::io(path, e))?;
    w.flush().map_err(|e| Error::io(path, e))
}

/// Writes one text line per item of `items` to `w`, in order: the lines are formatted by
/// `line` in parallel, a block of items per task, a few blocks at a time (the formatting of
/// floats is most of the time of writing a mesh as text; the memory held is a few blocks').
pub(crate) fn write_lines_par<T: Sync, W: std::io::Write>(
    w: &mut W,
    items: &[T],
    line: impl Fn(&mut Vec<u8>, &T) -> std::io::Result<()> + Sync,
) -> std::io::Result<()> {
    use rayon::prelude::*;
    const BLOCK: usize = 1 << 13;
    let group = BLOCK * 4 * rayon::current_num_threads().max(1);
    for part in items.chunks(group) {
        let texts: Vec<Vec<u8>> = part
            .par_chunks(BLOCK)
            .map(|block| {
                let mut out = Vec::with_capacity(block.len() * 48);
                for item in block {
                    line(&mut out, item)?;
                }
                Ok(out)
            })
            .collect::<std::io::Result<_>>()?;
        for t in &texts {
            w.write_all(t)?;
        }
    }
    Ok(())
}

/// Checks that a mesh can be written: every face index in range, every coordinate finite.
pub(crate) fn check_writable(mesh: &TriMesh) -> Result<()> {
    let n = mesh.vertices.len();
    if n > u32::MAX as usize + 1 {
        return Err(Error::InvalidInput(format!(
            "the mesh has {n} vertices, more than 32-bit indices can address"
        )));
    }
    if let Some(i) = mesh
        .vertices
        .iter()
        .position(|v| v.iter().any(|c| !c.is_finite()))
    {
        return Err(Error::InvalidInput(format!(
            "vertex {i} = {:?} is not finite",
            mesh.vertices[i]
        )));
    }
    if let Some(i) = mesh
        .faces
        .iter()
        .position(|f| f.iter().any(|&v| v as usize >= n))
    {
        return Err(Error::InvalidInput(format!(
            "face {i} = {:?} refers to a vertex >= the vertex count {n}",
            mesh.faces[i]
        )));
    }
    Ok(())
}

/// Never reserve more than this many elements from a count read in a header; vectors grow
/// as the data is actually read.
pub(crate) const MAX_PREALLOC: usize = 1 << 20;

/// A capacity for `count` announced elements of at least `min_bytes` bytes each when only
/// `available` bytes are left.
pub(crate) fn capped_capacity(count: u64, min_bytes: usize, available: usize) -> usize {
    let by_size = available / min_bytes.max(1);
    (count.min(by_size as u64) as usize).min(MAX_PREALLOC)
}

/// Collects vertices and polygons of a mesh being read, fan-triangulating polygons and
/// checking coordinates and indices.
#[derive(Debug, Default)]
pub(crate) struct MeshBuilder {
    vertices: Vec<[f64; 3]>,
    faces: Vec<[u32; 3]>,
    polygons: usize,
}

impl MeshBuilder {
    pub(crate) fn with_capacity(vertices: usize, faces: usize) -> Self {
        Self {
            vertices: Vec::with_capacity(vertices),
            faces: Vec::with_capacity(faces),
            polygons: 0,
        }
    }

    /// Number of vertices so far.
    pub(crate) fn vertex_count(&self) -> usize {
        self.vertices.len()
    }

    /// Adds a vertex; an error if a coordinate is not finite or there are too many vertices.
    pub(crate) fn push_vertex(&mut self, v: [f64; 3]) -> std::result::Result<(), String> {
        if v.iter().any(|c| !c.is_finite()) {
            return Err(format!(
                "vertex {} = {v:?} has a non-finite coordinate",
                self.vertices.len()
            ));
        }
        if self.vertices.len() > u32::MAX as usize {
            return Err("more vertices than 32-bit indices can address".to_string());
        }
        self.vertices.push(v);
        Ok(())
    }

    /// Adds a polygon (0-based vertex indices), fan-triangulated. `limit` is the vertex count
    /// when already known; indices are always checked again by [`MeshBuilder::finish`].
    pub(crate) fn push_polygon(
        &mut self,
        poly: &[u64],
        limit: Option<usize>,
    ) -> std::result::Result<(), String> {
        let id = self.polygons;
        self.polygons += 1;
        if poly.len() < 3 {
            return Err(format!(
                "face {id} has {} corner(s); a face needs at least 3",
                poly.len()
            ));
        }
        let bound = limit.map_or(u32::MAX as u64 + 1, |l| l as u64);
        if let Some(&bad) = poly.iter().find(|&&i| i >= bound) {
            return Err(match limit {
                Some(l) => format!(
                    "face {id} refers to vertex {bad} but there are only {l} vertices (indices are 0-based here)"
                ),
                None => format!("face {id} refers to vertex {bad}, beyond 32-bit indices"),
            });
        }
        let a = poly[0] as u32;
        for w in poly[1..].windows(2) {
            self.faces.push([a, w[0] as u32, w[1] as u32]);
        }
        Ok(())
    }

    /// The mesh, checking every index against the final vertex count.
    pub(crate) fn finish(self) -> std::result::Result<TriMesh, String> {
        TriMesh::new(self.vertices, self.faces)
    }
}

/// Parses a decimal number token as `f64` (Rust syntax, which also accepts `inf` and `nan`;
/// those are rejected later by the finiteness checks).
pub(crate) fn parse_f64(tok: &str) -> Option<f64> {
    tok.parse::<f64>().ok()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn parallel_lines_are_the_sequential_text() {
        use std::io::Write;
        // Sizes around the block (8192) and the group of blocks, so the order across both
        // is exercised.
        for n in [0usize, 1, 8191, 8193, 70_001, 200_000] {
            let items: Vec<[f64; 2]> = (0..n)
                .map(|i| [i as f64 / 7.0, (i as f64).sqrt()])
                .collect();
            let mut seq = Vec::new();
            for it in &items {
                writeln!(seq, "{:?} {:?}", it[0], it[1]).unwrap();
            }
            let mut par = Vec::new();
            write_lines_par(&mut par, &items, |o, it| {
                writeln!(o, "{:?} {:?}", it[0], it[1])
            })
            .unwrap();
            assert!(par == seq, "{n} items");
        }
        // An error of the writer comes back.
        let mut full = [0u8; 10];
        let items = vec![1.5f64; 100];
        let err = write_lines_par(&mut &mut full[..], &items, |o, x| writeln!(o, "{x:?}"));
        assert_eq!(
            err.map_err(|e| e.kind()),
            Err(std::io::ErrorKind::WriteZero)
        );
    }

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

    #[test]
    fn builder_fans_and_checks() {
        let mut b = MeshBuilder::default();
        for i in 0..5 {
            b.push_vertex([i as f64, 0.0, 0.0]).unwrap();
        }
        b.push_polygon(&[0, 1, 2, 3, 4], Some(5)).unwrap();
        assert!(b.push_polygon(&[0, 1], Some(5)).is_err());
        assert!(b.push_polygon(&[0, 1, 5], Some(5)).is_err());
        assert!(b.push_vertex([f64::NAN, 0.0, 0.0]).is_err());
        let m = b.finish().unwrap();
        assert_eq!(m.faces, vec![[0, 1, 2], [0, 2, 3], [0, 3, 4]]);
        let mut b = MeshBuilder::default();
        b.push_polygon(&[0, 1, 2], None).unwrap();
        assert!(b.finish().is_err());
    }

    #[test]
    fn capacity_is_capped() {
        assert_eq!(capped_capacity(u64::MAX, 12, 120), 10);
        assert_eq!(capped_capacity(5, 12, 1200), 5);
        assert_eq!(capped_capacity(u64::MAX, 1, usize::MAX), MAX_PREALLOC);
    }
}
