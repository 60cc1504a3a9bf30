//! Wavefront OBJ meshes.
//!
//! Reading keeps exactly the `v` statements of the file, in order (also vertices no face uses),
//! and fan-triangulates the `f` statements of every object and group into one mesh, so
//! vertices shared between groups stay shared. Face corners may be `v`, `v/vt`, `v//vn` or
//! `v/vt/vn`, with 1-based or negative (relative) indices; normals, groups, lines and points
//! are ignored. Colours (`v x y z r g b`, `vt`, `usemtl`, `mtllib`) are read by
//! [`parse_with_extras`]. `#` starts a comment and a `\` at the end
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
    parse_with_extras(bytes).map(|(m, _)| m)
}

/// What an OBJ file says about colours, beside its geometry ([`parse_with_extras`]).
#[derive(Debug, Clone, Default, PartialEq)]
pub struct ObjExtras {
    /// Per-vertex colours (`v x y z r g b`), when every vertex has one.
    pub vertex_colours: Option<Vec<[f32; 3]>>,
    /// Texture coordinates (`vt u v`).
    pub texcoords: Vec<[f32; 2]>,
    /// Per triangle (in the order of the mesh's faces), its corners' `vt` indices (0-based;
    /// -1 where a corner has none).
    pub face_texcoords: Vec<[i64; 3]>,
    /// Per triangle, its material: an index into `material_names` (`usemtl`), or -1 before
    /// any.
    pub face_material: Vec<i64>,
    /// The materials named by `usemtl`, in order of first use.
    pub material_names: Vec<String>,
    /// The material libraries (`mtllib`), as written.
    pub mtllibs: Vec<String>,
}

/// [`parse`], and what the file says about colours ([`ObjExtras`]).
pub fn parse_with_extras(bytes: &[u8]) -> std::result::Result<(TriMesh, ObjExtras), String> {
    if let Some(p) = bytes.iter().position(|&b| b == 0) {
        return Err(format!(
            "byte {p} is a NUL byte: this is binary data, not an OBJ file"
        ));
    }
    let text = String::from_utf8_lossy(bytes);
    let mut builder = MeshBuilder::default();
    let mut extras = ObjExtras::default();
    let mut colours: Vec<[f32; 3]> = Vec::new();
    let mut uncoloured = false;
    let mut material: i64 = -1;
    let mut vts: Vec<i64> = Vec::new();
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
                // `v x y z r g b` (and an alpha after): a colour per vertex.
                let rest: Vec<f64> = toks.filter_map(parse_f64).collect();
                if rest.len() >= 3 && rest[..3].iter().all(|c| c.is_finite()) {
                    colours.push([rest[0] as f32, rest[1] as f32, rest[2] as f32]);
                } else {
                    uncoloured = true;
                }
            }
            "vt" => {
                let uv: Vec<f64> = toks.take(2).filter_map(parse_f64).collect();
                extras.texcoords.push([
                    uv.first().copied().unwrap_or(0.0) as f32,
                    uv.get(1).copied().unwrap_or(0.0) as f32,
                ]);
            }
            "usemtl" => {
                let name = toks.collect::<Vec<_>>().join(" ");
                material = match extras.material_names.iter().position(|n| *n == name) {
                    Some(i) => i as i64,
                    None => {
                        extras.material_names.push(name);
                        extras.material_names.len() as i64 - 1
                    }
                };
            }
            // The rest of the line: a file name may hold spaces (resolved by the reader).
            "mtllib" => extras.mtllibs.push(toks.collect::<Vec<_>>().join(" ")),
            "f" => {
                poly.clear();
                vts.clear();
                let n = builder.vertex_count() as i64;
                let nt = extras.texcoords.len() as i64;
                for tok in toks {
                    let mut parts = tok.split('/');
                    let vtok = parts.next().unwrap_or("");
                    // The corner's texture coordinate, when it names one that exists.
                    let vt = parts
                        .next()
                        .and_then(|t| t.parse::<i64>().ok())
                        .map(|t| if t > 0 { t - 1 } else { nt + t })
                        .filter(|&t| t >= 0 && t < nt)
                        .unwrap_or(-1);
                    vts.push(vt);
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
                // The same fan as the builder's.
                for k in 1..vts.len() - 1 {
                    extras.face_texcoords.push([vts[0], vts[k], vts[k + 1]]);
                    extras.face_material.push(material);
                }
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
    let mesh = builder
        .finish()
        .map_err(|m| format!("{m} (vertex indices are 0-based in this message)"))?;
    if !uncoloured && !colours.is_empty() && colours.len() == mesh.vertices.len() {
        // Colours written as bytes (0 to 255) rather than fractions; a float a little over 1
        // (1.0000001, rounding) is a fraction.
        let scale = if colours.iter().flatten().any(|&c| c > 1.5) {
            1.0 / 255.0
        } else {
            1.0
        };
        extras.vertex_colours = Some(
            colours
                .into_iter()
                .map(|c| c.map(|x| (x * scale).clamp(0.0, 1.0)))
                .collect(),
        );
    }
    Ok((mesh, extras))
}

/// Writes `mesh` as OBJ text with a colour per vertex (`v x y z r g b`, in `[0, 1]`).
///
/// # Errors
/// As [`write_to`]; colours of another count than the vertices.
pub fn write_coloured_to<W: Write>(
    mut w: W,
    mesh: &TriMesh,
    colours: &[[f32; 3]],
) -> std::io::Result<()> {
    super::file::check_coloured_writable(mesh, colours)?;
    writeln!(
        w,
        "# {} vertices, {} triangles, written by ponq-mesh",
        mesh.vertices.len(),
        mesh.faces.len()
    )?;
    let rows: Vec<([f64; 3], [f32; 3])> = mesh
        .vertices
        .iter()
        .copied()
        .zip(colours.iter().copied())
        .collect();
    write_lines_par(&mut w, &rows, |o, (v, c)| {
        writeln!(
            o,
            "v {:?} {:?} {:?} {:.6} {:.6} {:.6}",
            v[0], v[1], v[2], c[0], c[1], c[2]
        )
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
    fn colours_texture_coordinates_and_materials() {
        let src = b"mtllib a.mtl\nv 0 0 0 1 0 0\nv 1 0 0 0 1 0\nv 1 1 0 0 0 1\nv 0 1 0 1 1 1\n\
            vt 0 0\nvt 1 0\nvt 1 1\nvt 0 1\nusemtl red\nf 1/1 2/2 3/3 4/4\nusemtl blue\n\
            f 1 3 4\nusemtl red\nf 1/-4 2/-3 3/-2\n";
        let (m, x) = parse_with_extras(src).unwrap();
        assert_eq!(m.faces.len(), 4);
        assert_eq!(x.vertex_colours.as_ref().unwrap()[1], [0.0, 1.0, 0.0]);
        assert_eq!(x.texcoords.len(), 4);
        assert_eq!(
            x.face_texcoords,
            vec![[0, 1, 2], [0, 2, 3], [-1, -1, -1], [0, 1, 2]]
        );
        assert_eq!(x.face_material, vec![0, 0, 1, 0]);
        assert_eq!(x.material_names, ["red", "blue"]);
        assert_eq!(x.mtllibs, ["a.mtl"]);
        // Colours on some vertices only: none. Bytes: scaled.
        let (_, x) = parse_with_extras(b"v 0 0 0 1 0 0\nv 1 0 0\n").unwrap();
        assert!(x.vertex_colours.is_none());
        let (_, x) = parse_with_extras(b"v 0 0 0 255 0 0\n").unwrap();
        assert_eq!(x.vertex_colours.unwrap()[0], [1.0, 0.0, 0.0]);
        // Written and read back.
        let mut out = Vec::new();
        write_coloured_to(&mut out, &m, &[[0.25, 0.5, 1.0]; 4]).unwrap();
        let (m2, x2) = parse_with_extras(&out).unwrap();
        assert_eq!(m2, m);
        assert_eq!(x2.vertex_colours.unwrap()[3], [0.25, 0.5, 1.0]);
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
