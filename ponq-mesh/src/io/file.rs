//! File access every format shares: whole files read and written with the file named in
//! every error, the checks a mesh must pass to be written, and text lines formatted in
//! parallel.

use std::path::Path;

use crate::error::{Error, Result};
use crate::trimesh::TriMesh;

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

/// Checks that `mesh` can be written ([`check_writable`]: no file is created for one that
/// cannot), then writes it to `path` with a format's writer `to`, naming the file in every
/// error.
pub(crate) fn write_mesh_file(
    path: &Path,
    mesh: &TriMesh,
    to: impl FnOnce(&mut std::io::BufWriter<std::fs::File>, &TriMesh) -> std::io::Result<()>,
) -> Result<()> {
    check_writable(mesh)?;
    write_file(path, |w| to(w, mesh))
}

/// Creates `path` and lets `f` write into it ([`write_file`] for writers that check their
/// input first).
pub(crate) fn write_with(
    path: &Path,
    f: impl FnOnce(&mut std::io::BufWriter<std::fs::File>) -> std::io::Result<()>,
) -> Result<()> {
    let r = write_file(path, f);
    if r.is_err() {
        let _ = std::fs::remove_file(path);
    }
    r
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

/// [`check_writable`] for a writer of a colour per vertex: the mesh, and as many colours as
/// vertices; as an I/O error of kind `InvalidInput` (the writers' error type).
pub(crate) fn check_coloured_writable(mesh: &TriMesh, colours: &[[f32; 3]]) -> std::io::Result<()> {
    let invalid = |m: String| std::io::Error::new(std::io::ErrorKind::InvalidInput, m);
    check_writable(mesh).map_err(|e| invalid(e.to_string()))?;
    if colours.len() != mesh.vertices.len() {
        return Err(invalid(format!(
            "{} colours for {} vertices",
            colours.len(),
            mesh.vertices.len()
        )));
    }
    Ok(())
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
}
