//! OFF (Object File Format) meshes, ASCII variant.
//!
//! Reading accepts the header keywords `OFF`, `COFF`, `NOFF`, `CNOFF`, `STOFF`, ... (any
//! combination of the `ST`, `C`, `N` prefixes), or no keyword at all; the counts
//! `nv nf [ne]` may follow the keyword on the same line. `#` starts a comment, blank lines are
//! skipped. Each vertex line holds `x y z` followed by optional extra values (colours,
//! normals, texture coordinates: ignored); each face line holds `n i_1 ... i_n` (0-based)
//! followed by an optional colour (ignored). Polygons are fan-triangulated. `4OFF`, `nOFF`
//! and binary OFF are not supported.

use std::io::Write;
use std::path::Path;

use super::builder::{MeshBuilder, capped_capacity, parse_f64};
use super::file::{check_writable, read_file, write_lines_par, write_mesh_file};
use crate::error::{Error, Result};
use crate::trimesh::TriMesh;

/// Reads an OFF file; see the [module documentation](self) for what is understood.
pub fn read(path: impl AsRef<Path>) -> Result<TriMesh> {
    let path = path.as_ref();
    let bytes = read_file(path)?;
    parse(&bytes).map_err(|m| Error::format(path, m))
}

fn parse_count(tok: &str, what: &str, lineno: usize) -> std::result::Result<u64, String> {
    tok.parse::<u64>()
        .map_err(|_| format!("line {lineno}: invalid {what} count '{tok}'"))
}

/// Parses the content of an OFF file; errors are plain messages with the line number.
pub fn parse(bytes: &[u8]) -> std::result::Result<TriMesh, String> {
    if let Some(p) = bytes.iter().position(|&b| b == 0) {
        return Err(format!(
            "byte {p} is a NUL byte: binary OFF (or binary data) is not supported"
        ));
    }
    let text = String::from_utf8_lossy(bytes);
    // Meaningful lines: comments stripped, blank lines skipped, with their 1-based number.
    let mut lines = text.lines().enumerate().filter_map(|(i, l)| {
        let l = match l.find('#') {
            Some(p) => &l[..p],
            None => l,
        };
        let l = l.trim();
        (!l.is_empty()).then_some((i + 1, l))
    });

    let (lineno, first) = lines
        .next()
        .ok_or_else(|| "empty file: no OFF header".to_string())?;
    let mut toks = first.split_whitespace();
    let mut count_toks: Vec<&str> = Vec::new();
    let first_tok = toks.next().unwrap_or("");
    let mut counts_line = lineno;
    if first_tok.parse::<u64>().is_ok() {
        // No keyword: the first line holds the counts.
        count_toks.push(first_tok);
        count_toks.extend(toks);
    } else {
        let kw = first_tok;
        let Some(prefix) = kw.strip_suffix("OFF") else {
            let shown: String = kw.chars().take(20).collect();
            return Err(format!(
                "line {lineno}: expected the OFF header keyword, found '{shown}'"
            ));
        };
        let mut p = prefix;
        for pre in ["ST", "C", "N"] {
            p = p.strip_prefix(pre).unwrap_or(p);
        }
        if !p.is_empty() {
            return Err(format!(
                "line {lineno}: unsupported OFF variant '{kw}' (only 3D [ST][C][N]OFF is supported)"
            ));
        }
        count_toks.extend(toks);
        if count_toks.first() == Some(&"BINARY") {
            return Err(format!("line {lineno}: binary OFF is not supported"));
        }
        if count_toks.is_empty() {
            let (l, t) = lines
                .next()
                .ok_or_else(|| "missing vertex and face counts".to_string())?;
            counts_line = l;
            count_toks.extend(t.split_whitespace());
        }
    }
    if count_toks.len() < 2 {
        return Err(format!(
            "line {counts_line}: expected the counts 'nv nf [ne]'"
        ));
    }
    let nv = parse_count(count_toks[0], "vertex", counts_line)?;
    let nf = parse_count(count_toks[1], "face", counts_line)?;
    if let Some(ne) = count_toks.get(2) {
        parse_count(ne, "edge", counts_line)?;
    }
    if nv > u32::MAX as u64 + 1 {
        return Err(format!(
            "line {counts_line}: {nv} vertices is more than 32-bit indices can address"
        ));
    }
    // A vertex line has at least 6 bytes ("0 0 0\n"), a face line at least 8.
    let mut builder = MeshBuilder::with_capacity(
        capped_capacity(nv, 6, bytes.len()),
        capped_capacity(nf, 8, bytes.len()),
    );
    for k in 0..nv {
        let (lineno, l) = lines
            .next()
            .ok_or_else(|| format!("the file ends after {k} of the {nv} announced vertices"))?;
        let mut v = [0.0; 3];
        let mut t = l.split_whitespace();
        for c in &mut v {
            let tok = t
                .next()
                .ok_or_else(|| format!("line {lineno}: a vertex needs 3 coordinates"))?;
            *c = parse_f64(tok)
                .ok_or_else(|| format!("line {lineno}: invalid vertex coordinate '{tok}'"))?;
        }
        builder
            .push_vertex(v)
            .map_err(|m| format!("line {lineno}: {m}"))?;
    }
    let nverts = builder.vertex_count();
    let mut poly: Vec<u64> = Vec::new();
    for k in 0..nf {
        let (lineno, l) = lines
            .next()
            .ok_or_else(|| format!("the file ends after {k} of the {nf} announced faces"))?;
        let mut t = l.split_whitespace();
        let ntok = t.next().unwrap_or("");
        let n: u64 = ntok
            .parse()
            .map_err(|_| format!("line {lineno}: invalid face corner count '{ntok}'"))?;
        poly.clear();
        for j in 0..n {
            let tok = t.next().ok_or_else(|| {
                format!("line {lineno}: the face announces {n} corners but has only {j}")
            })?;
            let idx: u64 = tok
                .parse()
                .map_err(|_| format!("line {lineno}: invalid vertex index '{tok}'"))?;
            poly.push(idx);
        }
        builder
            .push_polygon(&poly, Some(nverts))
            .map_err(|m| format!("line {lineno}: {m}"))?;
    }
    builder.finish()
}

/// Writes `mesh` as OFF text to `w` (`OFF`, counts, `x y z` lines, `3 a b c` lines).
///
/// Returns an error of kind [`std::io::ErrorKind::InvalidInput`] if a face index is out of
/// range or a coordinate is not finite.
pub fn write_to<W: Write>(mut w: W, mesh: &TriMesh) -> std::io::Result<()> {
    check_writable(mesh)
        .map_err(|e| std::io::Error::new(std::io::ErrorKind::InvalidInput, e.to_string()))?;
    writeln!(w, "OFF")?;
    writeln!(w, "{} {} 0", mesh.vertices.len(), mesh.faces.len())?;
    write_lines_par(&mut w, &mesh.vertices, |o, v| {
        writeln!(o, "{:?} {:?} {:?}", v[0], v[1], v[2])
    })?;
    write_lines_par(&mut w, &mesh.faces, |o, f| {
        writeln!(o, "3 {} {} {}", f[0], f[1], f[2])
    })
}

/// Writes `mesh` as `COFF` text to `w`, a colour per vertex (`x y z r g b a`, bytes 0 to 255).
///
/// # Errors
/// As [`write_to`]; colours of another count than the vertices.
pub fn write_coloured_to<W: Write>(
    mut w: W,
    mesh: &TriMesh,
    colours: &[[f32; 3]],
) -> std::io::Result<()> {
    super::file::check_coloured_writable(mesh, colours)?;
    writeln!(w, "COFF")?;
    writeln!(w, "{} {} 0", mesh.vertices.len(), mesh.faces.len())?;
    let rows: Vec<([f64; 3], [u8; 3])> = mesh
        .vertices
        .iter()
        .zip(colours)
        .map(|(v, c)| (*v, crate::colour::to_bytes(*c)))
        .collect();
    write_lines_par(&mut w, &rows, |o, (v, c)| {
        writeln!(
            o,
            "{:?} {:?} {:?} {} {} {} 255",
            v[0], v[1], v[2], c[0], c[1], c[2]
        )
    })?;
    write_lines_par(&mut w, &mesh.faces, |o, f| {
        writeln!(o, "3 {} {} {}", f[0], f[1], f[2])
    })
}

/// Writes `mesh` to the OFF file `path`; errors name the file. A mesh with a face index out
/// of range or a non-finite coordinate gives [`Error::InvalidInput`] and no file.
pub fn write(path: impl AsRef<Path>, mesh: &TriMesh) -> Result<()> {
    write_mesh_file(path.as_ref(), mesh, |w, m| write_to(w, m))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn parses_variants() {
        let m = parse(b"OFF 4 1 0\n0 0 0\n1 0 0\n1 1 0\n0 1 0\n4 0 1 2 3\n").unwrap();
        assert_eq!(m.faces, vec![[0, 1, 2], [0, 2, 3]]);
        let m = parse(
            b"# c\nCOFF\n\n3 1 3 # counts\n0 0 0 255 0 0 255\n1 0 0 1 2 3 4\n0 1 0 1 2 3 4\n3 0 1 2 1 1 1\n",
        )
        .unwrap();
        assert_eq!(m.faces, vec![[0, 1, 2]]);
        let m = parse(b"3 1\n0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n").unwrap();
        assert_eq!(m.vertices.len(), 3);
    }

    #[test]
    fn rejects_bad_content() {
        assert!(parse(b"").is_err());
        assert!(parse(b"OFF\n3 1 0\n0 0 0\n1 0 0\n").is_err());
        assert!(parse(b"OFF\n3 1 0\n0 0 0\n1 0 0\n0 1 0\n3 0 1 3\n").is_err());
        assert!(parse(b"OFF\n3 1 0\n0 0 0\n1 0 inf\n0 1 0\n3 0 1 2\n").is_err());
        assert!(parse(b"OFF\n18446744073709551615 1 0\n0 0 0\n").is_err());
        assert!(parse(b"4OFF\n1 0 0\n0 0 0 0\n").is_err());
        assert!(parse(b"OFF BINARY\n").is_err());
    }
}
