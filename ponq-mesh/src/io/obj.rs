//! Wavefront OBJ meshes.
//!
//! Reading keeps exactly the `v` statements of the file, in order (also vertices no face uses),
//! and fan-triangulates the `f` statements of every object and group into one mesh, so
//! vertices shared between groups stay shared. Face corners may be `v`, `v/vt`, `v//vn` or
//! `v/vt/vn`, with 1-based or negative (relative) indices; texture coordinates, normals,
//! materials, groups, lines and points are ignored. `#` starts a comment and a `\` at the end
//! of a line continues it on the next one.
//!
//! Writing gives plain `v x y z` / `f a b c` lines (1-based) with the shortest decimal form
//! that reads back to the same `f64`, so a write/read round trip is exact.
//!
//! (The `tobj` crate is not used for reading: it renumbers vertices in order of first use,
//! drops unreferenced vertices, duplicates vertices shared between groups and parses `f32` by
//! default, none of which suits a geometry tool that must round-trip meshes exactly.)

use std::io::Write;
use std::path::Path;

use super::builder::{MeshBuilder, parse_f64};
use super::file::{check_writable, read_file, write_lines_par, write_mesh_file};
use crate::error::{Error, Result};
use crate::trimesh::TriMesh;

/// Reads an OBJ file; see the [module documentation](self) for what is understood.
pub fn read(path: impl AsRef<Path>) -> Result<TriMesh> {
    let path = path.as_ref();
    let bytes = read_file(path)?;
    parse(&bytes).map_err(|m| Error::format(path, m))
}

/// True for a plausible OBJ keyword: ASCII letters, digits and `_`, starting with a letter.
fn is_keyword(s: &str) -> bool {
    s.len() <= 32
        && s.as_bytes()[0].is_ascii_alphabetic()
        && s.bytes().all(|b| b.is_ascii_alphanumeric() || b == b'_')
}

/// Parses the content of an OBJ file; errors are plain messages with the line number.
///
/// Unknown statements with a keyword-like name are ignored (extensions); anything else, and
/// a NUL byte anywhere, is an error, so binary garbage is rejected.
pub fn parse(bytes: &[u8]) -> std::result::Result<TriMesh, String> {
    if let Some(p) = bytes.iter().position(|&b| b == 0) {
        return Err(format!(
            "byte {p} is a NUL byte: this is binary data, not an OBJ file"
        ));
    }
    let text = String::from_utf8_lossy(bytes);
    let mut builder = MeshBuilder::default();
    let mut lines = text.lines().enumerate();
    let mut joined = String::new();
    let mut poly: Vec<u64> = Vec::new();
    while let Some((i, first)) = lines.next() {
        let lineno = i + 1;
        // Join continuation lines.
        joined.clear();
        let mut cur = first;
        loop {
            let t = cur.trim_end();
            match t.strip_suffix('\\') {
                Some(head) => {
                    joined.push_str(head);
                    joined.push(' ');
                    match lines.next() {
                        Some((_, next)) => cur = next,
                        None => break,
                    }
                }
                None => {
                    joined.push_str(t);
                    break;
                }
            }
        }
        let line = match joined.find('#') {
            Some(p) => &joined[..p],
            None => joined.as_str(),
        };
        let mut toks = line.split_whitespace();
        let Some(kw) = toks.next() else { continue };
        match kw {
            "v" => {
                let mut v = [0.0; 3];
                for c in &mut v {
                    let tok = toks
                        .next()
                        .ok_or_else(|| format!("line {lineno}: a vertex needs 3 coordinates"))?;
                    *c = parse_f64(tok).ok_or_else(|| {
                        format!("line {lineno}: invalid vertex coordinate '{tok}'")
                    })?;
                }
                builder
                    .push_vertex(v)
                    .map_err(|m| format!("line {lineno}: {m}"))?;
            }
            "f" => {
                poly.clear();
                let n = builder.vertex_count() as i64;
                for tok in toks {
                    let vtok = tok.split('/').next().unwrap_or("");
                    let idx: i64 = vtok
                        .parse()
                        .map_err(|_| format!("line {lineno}: invalid face corner '{tok}'"))?;
                    let zero_based = if idx > 0 {
                        idx - 1
                    } else if idx < 0 {
                        n + idx
                    } else {
                        return Err(format!(
                            "line {lineno}: face index 0 is invalid (OBJ indices start at 1)"
                        ));
                    };
                    if zero_based < 0 {
                        return Err(format!(
                            "line {lineno}: relative face index {idx} points before the first vertex ({n} vertices so far)"
                        ));
                    }
                    poly.push(zero_based as u64);
                }
                builder
                    .push_polygon(&poly, None)
                    .map_err(|m| format!("line {lineno}: {m}"))?;
            }
            _ if is_keyword(kw) => {}
            _ => {
                let shown: String = kw.chars().take(20).collect();
                return Err(format!(
                    "line {lineno}: '{shown}' does not start an OBJ statement"
                ));
            }
        }
    }
    builder
        .finish()
        .map_err(|m| format!("{m} (vertex indices are 0-based in this message)"))
}

/// Writes `mesh` as OBJ text to `w`: `v x y z` lines then `f a b c` lines (1-based).
///
/// Returns an error of kind [`std::io::ErrorKind::InvalidInput`] if a face index is out of
/// range or a coordinate is not finite.
pub fn write_to<W: Write>(mut w: W, mesh: &TriMesh) -> std::io::Result<()> {
    check_writable(mesh)
        .map_err(|e| std::io::Error::new(std::io::ErrorKind::InvalidInput, e.to_string()))?;
    writeln!(
        w,
        "# {} vertices, {} triangles, written by ponq-mesh",
        mesh.vertices.len(),
        mesh.faces.len()
    )?;
    write_lines_par(&mut w, &mesh.vertices, |o, v| {
        writeln!(o, "v {:?} {:?} {:?}", v[0], v[1], v[2])
    })?;
    write_lines_par(&mut w, &mesh.faces, |o, f| {
        writeln!(
            o,
            "f {} {} {}",
            f[0] as u64 + 1,
            f[1] as u64 + 1,
            f[2] as u64 + 1
        )
    })
}

/// Writes `mesh` to the OBJ file `path`; errors name the file. A mesh with a face index out
/// of range or a non-finite coordinate gives [`Error::InvalidInput`] and no file.
pub fn write(path: impl AsRef<Path>, mesh: &TriMesh) -> Result<()> {
    write_mesh_file(path.as_ref(), mesh, |w, m| write_to(w, m))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn parses_polygons_groups_and_relative_indices() {
        let src = b"# comment\nv 0 0 0\nv 1 0 0\nv 1 1 0 1.0\nv 0 1 0\ng a\nf 1/1/1 2//2 3 4\no b\nf -4 -2 \\\n -1\nvn 0 0 1\nusemtl x\n";
        let m = parse(src).unwrap();
        assert_eq!(m.vertices.len(), 4);
        assert_eq!(m.faces, vec![[0, 1, 2], [0, 2, 3], [0, 2, 3]]);
    }

    #[test]
    fn rejects_bad_content() {
        assert!(parse(b"v 0 0 0\nf 1 2 3\n").is_err());
        assert!(parse(b"v 0 0 nan\n").is_err());
        assert!(parse(b"v 0 0\n").is_err());
        assert!(parse(b"v 0 0 0\nv 0 0 0\nv 0 0 0\nf 0 1 2\n").is_err());
        assert!(parse(b"v 0 0 0\nf -2 -1 -1\n").is_err());
        assert!(parse(b"\x01\x02\x03\xff\xfe garbage").is_err());
        assert!(parse(b"v 0 0 0\0").is_err());
        assert!(parse(b"").unwrap().vertices.is_empty());
    }
}
