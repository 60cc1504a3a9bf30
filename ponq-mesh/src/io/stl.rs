//! STL meshes (ASCII and binary), read with the `stl_io` crate.
//!
//! STL stores every triangle with its own three corners; vertices with exactly equal
//! coordinates (the same `f32` values, `-0.0` counting as `0.0`) are welded into one vertex,
//! numbered in order of first appearance, so the result is an indexed mesh. Facet normals are
//! ignored. A file is read as binary when its size is exactly `84 + 50 * count` for the
//! triangle count of its header (even when the 80-byte header starts with `solid`), as ASCII
//! when it starts with `solid`, and as binary otherwise.

use std::collections::HashMap;
use std::io::Cursor;
use std::path::Path;

use super::builder::MeshBuilder;
use super::file::read_file;
use crate::error::{Error, Result};
use crate::trimesh::TriMesh;

/// Reads an STL file (ASCII or binary); see the [module documentation](self).
pub fn read(path: impl AsRef<Path>) -> Result<TriMesh> {
    let path = path.as_ref();
    let bytes = read_file(path)?;
    parse(&bytes).map_err(|m| Error::format(path, m))
}

fn is_exact_binary(bytes: &[u8]) -> bool {
    if bytes.len() < 84 {
        return false;
    }
    let count = u32::from_le_bytes([bytes[80], bytes[81], bytes[82], bytes[83]]) as u64;
    84 + 50 * count == bytes.len() as u64
}

/// Parses the content of an STL file; errors are plain messages.
pub fn parse(bytes: &[u8]) -> std::result::Result<TriMesh, String> {
    let mut data: Vec<u8>;
    let binary;
    if is_exact_binary(bytes) {
        binary = true;
        // `stl_io` takes a header starting with "solid " for ASCII; blank the (ignored) header.
        data = bytes.to_vec();
        data[..80].fill(0);
    } else {
        let start = bytes
            .iter()
            .position(|b| !b.is_ascii_whitespace())
            .unwrap_or(bytes.len());
        let rest = &bytes[start..];
        if rest.starts_with(b"solid") {
            binary = false;
            // `stl_io` wants "solid " with a space, even without a name.
            data = b"solid ".to_vec();
            data.extend_from_slice(&rest[5..]);
        } else {
            if bytes.len() < 84 {
                return Err(format!(
                    "{} bytes: too short for a binary STL (84-byte header) and not an ASCII STL (no 'solid')",
                    bytes.len()
                ));
            }
            binary = true;
            data = bytes.to_vec();
            data[..80].fill(0);
        }
    }
    let kind = if binary { "binary" } else { "ASCII" };
    let mut cursor = Cursor::new(data);
    let triangles =
        stl_io::create_stl_reader(&mut cursor).map_err(|e| format!("invalid {kind} STL: {e}"))?;
    let mut builder = MeshBuilder::default();
    let mut index: HashMap<[u32; 3], u64> = HashMap::new();
    let mut corners = [0u64; 3];
    for (t, tri) in triangles.enumerate() {
        let tri = tri.map_err(|e| format!("invalid {kind} STL at triangle {t}: {e}"))?;
        for (corner, v) in corners.iter_mut().zip(tri.vertices.iter()) {
            // +0.0 for -0.0 so that equal coordinates weld.
            let p = v.0.map(|c| c + 0.0);
            if p.iter().any(|c| !c.is_finite()) {
                return Err(format!(
                    "triangle {t} has a corner with a non-finite coordinate {p:?}"
                ));
            }
            let key = p.map(f32::to_bits);
            let next = builder.vertex_count() as u64;
            let id = *index.entry(key).or_insert(next);
            if id == next {
                builder.push_vertex(p.map(f64::from))?;
            }
            *corner = id;
        }
        let n = builder.vertex_count();
        builder.push_polygon(&corners, Some(n))?;
    }
    builder.finish()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn binary(tris: &[[[f32; 3]; 3]], header: &[u8]) -> Vec<u8> {
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

    #[test]
    fn binary_with_solid_header_welds() {
        let tris = [
            [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]],
            [[1.0, 0.0, 0.0], [1.0, 1.0, 0.0], [0.0, 1.0, -0.0]],
        ];
        let m = parse(&binary(&tris, b"solid trap")).unwrap();
        assert_eq!(m.vertices.len(), 4);
        assert_eq!(m.faces, vec![[0, 1, 2], [1, 3, 2]]);
    }

    #[test]
    fn ascii_without_name() {
        let src = b"solid\nfacet normal 0 0 1\nouter loop\nvertex 0 0 0\nvertex 1 0 0\nvertex 0 1 0\nendloop\nendfacet\nendsolid\n";
        let m = parse(src).unwrap();
        assert_eq!(m.faces, vec![[0, 1, 2]]);
    }

    #[test]
    fn rejects_bad_content() {
        assert!(parse(b"").is_err());
        assert!(parse(b"solid x\nfacet normal 0 0 1\nouter loop\nvertex 0 0 0\n").is_err());
        let mut b = binary(&[[[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]]], b"");
        b.truncate(100);
        assert!(parse(&b).is_err());
        let b = binary(
            &[[[0.0, 0.0, 0.0], [f32::NAN, 0.0, 0.0], [0.0, 1.0, 0.0]]],
            b"",
        );
        assert!(parse(&b).is_err());
    }
}
