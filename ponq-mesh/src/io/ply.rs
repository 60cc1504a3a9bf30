//! Stanford PLY meshes: own reader and writer, no external crate.
//!
//! Reading understands the `ascii`, `binary_little_endian` and `binary_big_endian` formats.
//! The first `vertex` element must have the scalar properties `x`, `y`, `z` (of any scalar
//! type: `char`/`int8`, `uchar`/`uint8`, `short`/`int16`, `ushort`/`uint16`, `int`/`int32`,
//! `uint`/`uint32`, `float`/`float32`, `double`/`float64`); its other properties are skipped.
//! The first `face` element must have a list property `vertex_indices` (or `vertex_index`)
//! with integer count and index types; its other properties are skipped, and its polygons are
//! fan-triangulated. Every other element (edges, materials, ...) is skipped, list properties
//! included. A file without a `face` element gives a mesh without faces. Data after the last
//! element is ignored.
//!
//! Writing gives either binary little-endian ([`write()`], [`write_to`]) or ASCII
//! ([`write_ascii`], [`write_ascii_to`]) PLY with `double` coordinates and a
//! `list uchar int vertex_indices` face property (`uint` indices beyond `i32::MAX`), so a
//! write/read round trip is exact.

use std::io::Write;
use std::path::Path;

use super::builder::{MeshBuilder, capped_capacity};
use super::file::{check_writable, read_file, write_mesh_file};
use crate::error::{Error, Result};
use crate::trimesh::TriMesh;

/// Reads a PLY file (ASCII or binary); see the [module documentation](self).
pub fn read(path: impl AsRef<Path>) -> Result<TriMesh> {
    let path = path.as_ref();
    let bytes = read_file(path)?;
    parse(&bytes).map_err(|m| Error::format(path, m))
}

/// A PLY scalar type.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Scalar {
    I8,
    U8,
    I16,
    U16,
    I32,
    U32,
    F32,
    F64,
}

impl Scalar {
    fn from_name(s: &str) -> Option<Self> {
        Some(match s {
            "char" | "int8" => Self::I8,
            "uchar" | "uint8" => Self::U8,
            "short" | "int16" => Self::I16,
            "ushort" | "uint16" => Self::U16,
            "int" | "int32" => Self::I32,
            "uint" | "uint32" => Self::U32,
            "float" | "float32" => Self::F32,
            "double" | "float64" => Self::F64,
            _ => return None,
        })
    }

    fn size(self) -> usize {
        match self {
            Self::I8 | Self::U8 => 1,
            Self::I16 | Self::U16 => 2,
            Self::I32 | Self::U32 | Self::F32 => 4,
            Self::F64 => 8,
        }
    }

    fn is_int(self) -> bool {
        !matches!(self, Self::F32 | Self::F64)
    }

    /// The range of an integer type.
    fn int_range(self) -> (i64, i64) {
        match self {
            Self::I8 => (i8::MIN as i64, i8::MAX as i64),
            Self::U8 => (0, u8::MAX as i64),
            Self::I16 => (i16::MIN as i64, i16::MAX as i64),
            Self::U16 => (0, u16::MAX as i64),
            Self::I32 => (i32::MIN as i64, i32::MAX as i64),
            Self::U32 => (0, u32::MAX as i64),
            Self::F32 | Self::F64 => (i64::MIN, i64::MAX),
        }
    }
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum PropKind {
    Scalar(Scalar),
    List { count: Scalar, item: Scalar },
}

#[derive(Debug, Clone)]
struct Property {
    name: String,
    kind: PropKind,
}

#[derive(Debug, Clone)]
struct Element {
    name: String,
    count: u64,
    props: Vec<Property>,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Format {
    Ascii,
    BinaryLe,
    BinaryBe,
}

#[derive(Debug)]
struct Header {
    format: Format,
    elements: Vec<Element>,
    /// Byte offset of the data section.
    data_start: usize,
}

fn parse_header(bytes: &[u8]) -> std::result::Result<Header, String> {
    let mut pos = 0usize;
    let mut lineno = 0usize;
    let mut format = None;
    let mut elements: Vec<Element> = Vec::new();
    let next_line = |pos: &mut usize| -> Option<String> {
        if *pos >= bytes.len() {
            return None;
        }
        let rest = &bytes[*pos..];
        let (line, adv) = match rest.iter().position(|&b| b == b'\n') {
            Some(p) => (&rest[..p], p + 1),
            None => (rest, rest.len()),
        };
        *pos += adv;
        Some(String::from_utf8_lossy(line).trim().to_string())
    };
    match next_line(&mut pos) {
        Some(l) if l == "ply" => {}
        _ => return Err("not a PLY file: the first line is not 'ply'".to_string()),
    }
    lineno += 1;
    loop {
        let Some(line) = next_line(&mut pos) else {
            return Err("the header has no 'end_header' line".to_string());
        };
        lineno += 1;
        let toks: Vec<&str> = line.split_whitespace().collect();
        let Some(&kw) = toks.first() else { continue };
        let bad = |what: &str| format!("header line {lineno}: {what}: '{line}'");
        match kw {
            "end_header" => break,
            "comment" | "obj_info" => {}
            "format" => {
                if format.is_some() {
                    return Err(bad("a second format line"));
                }
                format = Some(match toks.get(1).copied() {
                    Some("ascii") => Format::Ascii,
                    Some("binary_little_endian") => Format::BinaryLe,
                    Some("binary_big_endian") => Format::BinaryBe,
                    _ => return Err(bad("unknown format")),
                });
            }
            "element" => {
                if toks.len() != 3 {
                    return Err(bad("expected 'element <name> <count>'"));
                }
                let count: u64 = toks[2].parse().map_err(|_| bad("invalid element count"))?;
                elements.push(Element {
                    name: toks[1].to_string(),
                    count,
                    props: Vec::new(),
                });
            }
            "property" => {
                let Some(el) = elements.last_mut() else {
                    return Err(bad("a property before any element"));
                };
                let prop = if toks.get(1) == Some(&"list") {
                    if toks.len() != 5 {
                        return Err(bad(
                            "expected 'property list <count type> <item type> <name>'",
                        ));
                    }
                    let count = Scalar::from_name(toks[2]).ok_or_else(|| bad("unknown type"))?;
                    let item = Scalar::from_name(toks[3]).ok_or_else(|| bad("unknown type"))?;
                    if !count.is_int() {
                        return Err(bad("a list count type must be an integer type"));
                    }
                    Property {
                        name: toks[4].to_string(),
                        kind: PropKind::List { count, item },
                    }
                } else {
                    if toks.len() != 3 {
                        return Err(bad("expected 'property <type> <name>'"));
                    }
                    let ty = Scalar::from_name(toks[1]).ok_or_else(|| bad("unknown type"))?;
                    Property {
                        name: toks[2].to_string(),
                        kind: PropKind::Scalar(ty),
                    }
                };
                el.props.push(prop);
            }
            _ => return Err(bad("unknown header keyword")),
        }
    }
    let format = format.ok_or_else(|| "the header has no 'format' line".to_string())?;
    Ok(Header {
        format,
        elements,
        data_start: pos,
    })
}

/// Reads scalars from the data section.
enum Data<'a> {
    Binary {
        bytes: &'a [u8],
        pos: usize,
        big_endian: bool,
    },
    Ascii {
        tokens: std::str::SplitAsciiWhitespace<'a>,
    },
}

const EOF: &str = "unexpected end of data";

impl Data<'_> {
    /// Bytes left (for ASCII: an upper bound, the length of the data section).
    fn remaining_bytes(&self, body_len: usize) -> usize {
        match self {
            Data::Binary { bytes, pos, .. } => bytes.len() - pos,
            Data::Ascii { .. } => body_len,
        }
    }

    fn is_binary(&self) -> bool {
        matches!(self, Data::Binary { .. })
    }

    fn take(&mut self, n: usize) -> std::result::Result<&[u8], String> {
        match self {
            Data::Binary { bytes, pos, .. } => {
                if bytes.len() - *pos < n {
                    return Err(EOF.to_string());
                }
                let s = &bytes[*pos..*pos + n];
                *pos += n;
                Ok(s)
            }
            Data::Ascii { .. } => {
                Err("internal error: raw bytes requested from ASCII data".to_string())
            }
        }
    }

    /// Reads one value of type `ty`, exactly representable as `f64` for every PLY type.
    fn read(&mut self, ty: Scalar) -> std::result::Result<f64, String> {
        match self {
            Data::Binary { big_endian, .. } => {
                let be = *big_endian;
                let b = self.take(ty.size())?;
                macro_rules! get {
                    ($t:ty, $n:expr) => {{
                        let mut a = [0u8; $n];
                        a.copy_from_slice(b);
                        if be {
                            <$t>::from_be_bytes(a) as f64
                        } else {
                            <$t>::from_le_bytes(a) as f64
                        }
                    }};
                }
                Ok(match ty {
                    Scalar::I8 => get!(i8, 1),
                    Scalar::U8 => get!(u8, 1),
                    Scalar::I16 => get!(i16, 2),
                    Scalar::U16 => get!(u16, 2),
                    Scalar::I32 => get!(i32, 4),
                    Scalar::U32 => get!(u32, 4),
                    Scalar::F32 => get!(f32, 4),
                    Scalar::F64 => get!(f64, 8),
                })
            }
            Data::Ascii { tokens } => {
                let tok = tokens.next().ok_or_else(|| EOF.to_string())?;
                let short = || tok.chars().take(24).collect::<String>();
                if ty.is_int() {
                    let v = match tok.parse::<i64>() {
                        Ok(v) => v,
                        Err(_) => match tok.parse::<f64>() {
                            Ok(f) if f.fract() == 0.0 && f.abs() < 9.0e15 => f as i64,
                            _ => return Err(format!("invalid integer '{}'", short())),
                        },
                    };
                    let (lo, hi) = ty.int_range();
                    if v < lo || v > hi {
                        return Err(format!("{v} is out of range for its type {ty:?}"));
                    }
                    Ok(v as f64)
                } else {
                    tok.parse::<f64>()
                        .map_err(|_| format!("invalid number '{}'", short()))
                }
            }
        }
    }

    /// Reads a list count (a non-negative integer).
    fn read_count(&mut self, ty: Scalar) -> std::result::Result<u64, String> {
        let c = self.read(ty)?;
        if c < 0.0 {
            return Err(format!("negative list length {c}"));
        }
        Ok(c as u64)
    }

    /// Skips `n` values of type `ty`.
    fn skip(&mut self, ty: Scalar, n: u64) -> std::result::Result<(), String> {
        match self {
            Data::Binary { .. } => {
                let total = n.checked_mul(ty.size() as u64).ok_or(EOF)?;
                let total = usize::try_from(total).map_err(|_| EOF.to_string())?;
                self.take(total).map(|_| ())
            }
            Data::Ascii { .. } => {
                for _ in 0..n {
                    self.read(ty)?;
                }
                Ok(())
            }
        }
    }

    /// Skips one property value.
    fn skip_prop(&mut self, kind: PropKind) -> std::result::Result<(), String> {
        match kind {
            PropKind::Scalar(ty) => self.skip(ty, 1),
            PropKind::List { count, item } => {
                let n = self.read_count(count)?;
                self.skip(item, n)
            }
        }
    }
}

/// Bytes (binary) or tokens (ASCII) a record takes at least.
fn min_record_len(el: &Element, format: Format) -> usize {
    match format {
        Format::Ascii => el.props.len(),
        _ => el
            .props
            .iter()
            .map(|p| match p.kind {
                PropKind::Scalar(t) => t.size(),
                PropKind::List { count, .. } => count.size(),
            })
            .sum(),
    }
}

fn scalar_prop(el: &Element, name: &str) -> std::result::Result<(usize, Scalar), String> {
    let i = el
        .props
        .iter()
        .position(|p| p.name == name)
        .ok_or_else(|| format!("element '{}' has no property '{name}'", el.name))?;
    match el.props[i].kind {
        PropKind::Scalar(t) => Ok((i, t)),
        PropKind::List { .. } => Err(format!(
            "property '{name}' of element '{}' is a list, expected a scalar",
            el.name
        )),
    }
}

/// The colour properties of an element: `red green blue` (or `r g b`, `diffuse_red ..`),
/// their places and types, and the scale to `[0, 1]` (1/255 for integer types).
fn colour_props(el: &Element) -> Option<[(usize, Scalar); 3]> {
    let find = |names: &[&str]| {
        el.props.iter().enumerate().find_map(|(i, p)| match p.kind {
            PropKind::Scalar(t) if names.contains(&p.name.as_str()) => Some((i, t)),
            _ => None,
        })
    };
    Some([
        find(&["red", "r", "diffuse_red"])?,
        find(&["green", "g", "diffuse_green"])?,
        find(&["blue", "b", "diffuse_blue"])?,
    ])
}

/// A colour value as stored (NaN read as 0); [`to_fractions`] scales a whole column.
fn colour_value(v: f64) -> f32 {
    if v.is_nan() { 0.0 } else { v as f32 }
}

/// Scales raw colour values of types `types` into `[0, 1]`. Bytes are `0..=255`; wider
/// integers holding at most 255 are bytes too (files that store `int red` as `0..=255`),
/// else fractions of their type's range; floats above 1.5 are bytes written as floats, else
/// fractions.
fn to_fractions(cols: &mut [[f32; 3]], types: [Scalar; 3]) {
    let top = cols.iter().flatten().fold(0.0f32, |m, &c| m.max(c));
    let scale: [f32; 3] = std::array::from_fn(|k| {
        let t = types[k];
        if t.is_int() {
            let full = t.int_range().1 as f32;
            if full > 255.0 && top <= 255.0 {
                1.0 / 255.0
            } else {
                1.0 / full
            }
        } else if top > 1.5 {
            1.0 / 255.0
        } else {
            1.0
        }
    });
    for c in cols {
        for k in 0..3 {
            c[k] = (c[k] * scale[k]).clamp(0.0, 1.0);
        }
    }
}

/// Parses the content of a PLY file; errors are plain messages.
pub fn parse(bytes: &[u8]) -> std::result::Result<TriMesh, String> {
    parse_with_colours(bytes).map(|(m, _)| m)
}

/// [`parse`], and the colours the file gives: per vertex (`red green blue` of the vertex
/// element), else per face (those of the face element; each triangle of a polygon takes its
/// colour).
pub fn parse_with_colours(
    bytes: &[u8],
) -> std::result::Result<(TriMesh, Option<crate::colour::Colours>), String> {
    let header = parse_header(bytes)?;
    let body = &bytes[header.data_start..];
    let mut data = match header.format {
        Format::Ascii => {
            if body.contains(&0) {
                return Err("an ASCII PLY data section contains a NUL byte".to_string());
            }
            let text = std::str::from_utf8(body)
                .map_err(|e| format!("the ASCII data section is not valid text: {e}"))?;
            Data::Ascii {
                tokens: text.split_ascii_whitespace(),
            }
        }
        Format::BinaryLe | Format::BinaryBe => Data::Binary {
            bytes: body,
            pos: 0,
            big_endian: header.format == Format::BinaryBe,
        },
    };
    let vertex_el = header
        .elements
        .iter()
        .position(|e| e.name == "vertex")
        .ok_or_else(|| "the header declares no 'vertex' element".to_string())?;
    let face_el = header.elements.iter().position(|e| e.name == "face");
    {
        let v = &header.elements[vertex_el];
        if v.count > u32::MAX as u64 + 1 {
            return Err(format!(
                "{} vertices is more than 32-bit indices can address",
                v.count
            ));
        }
    }

    let mut builder = MeshBuilder::default();
    let mut vertices_read = false;
    let mut poly: Vec<u64> = Vec::new();
    let mut vertex_colours: Vec<[f32; 3]> = Vec::new();
    let mut face_colours: Vec<[f32; 3]> = Vec::new();
    let (mut vertex_types, mut face_types) = (None, None);
    for (ei, el) in header.elements.iter().enumerate() {
        let ctx = |r: u64, m: String| format!("element '{}' record {r}: {m}", el.name);
        let cap = capped_capacity(
            el.count,
            min_record_len(el, header.format),
            data.remaining_bytes(body.len()),
        );
        if ei == vertex_el {
            let (ix, tx) = scalar_prop(el, "x")?;
            let (iy, ty) = scalar_prop(el, "y")?;
            let (iz, tz) = scalar_prop(el, "z")?;
            let rgb = colour_props(el);
            vertex_types = rgb.map(|cs| cs.map(|(_, t)| t));
            builder = MeshBuilder::with_capacity(cap, 0);
            for r in 0..el.count {
                let mut v = [0.0; 3];
                let mut c = [0.0f32; 3];
                for (pi, p) in el.props.iter().enumerate() {
                    let slot = if pi == ix {
                        Some((0, tx))
                    } else if pi == iy {
                        Some((1, ty))
                    } else if pi == iz {
                        Some((2, tz))
                    } else {
                        None
                    };
                    let channel = rgb.and_then(|cs| cs.iter().position(|&(i, _)| i == pi));
                    match (slot, channel) {
                        (Some((k, t)), _) => v[k] = data.read(t).map_err(|m| ctx(r, m))?,
                        (None, Some(k)) => {
                            let t = rgb.map_or(Scalar::F32, |cs| cs[k].1);
                            c[k] = colour_value(data.read(t).map_err(|m| ctx(r, m))?);
                        }
                        (None, None) => data.skip_prop(p.kind).map_err(|m| ctx(r, m))?,
                    }
                }
                builder.push_vertex(v).map_err(|m| ctx(r, m))?;
                if rgb.is_some() {
                    vertex_colours.push(c);
                }
            }
            vertices_read = true;
        } else if Some(ei) == face_el {
            if el.count == 0 {
                continue;
            }
            let li = el
                .props
                .iter()
                .position(|p| p.name == "vertex_indices" || p.name == "vertex_index")
                .ok_or_else(|| {
                    "element 'face' has no list property 'vertex_indices' or 'vertex_index'"
                        .to_string()
                })?;
            let PropKind::List {
                count: ct,
                item: it,
            } = el.props[li].kind
            else {
                return Err(format!(
                    "property '{}' of element 'face' is not a list",
                    el.props[li].name
                ));
            };
            if !it.is_int() {
                return Err(format!(
                    "face indices must have an integer type, found {it:?}"
                ));
            }
            let limit = vertices_read.then(|| builder.vertex_count());
            let rgb = colour_props(el);
            face_types = rgb.map(|cs| cs.map(|(_, t)| t));
            for r in 0..el.count {
                poly.clear();
                let mut c = [0.0f32; 3];
                for (pi, p) in el.props.iter().enumerate() {
                    let channel = rgb.and_then(|cs| cs.iter().position(|&(i, _)| i == pi));
                    if pi == li {
                        let n = data.read_count(ct).map_err(|m| ctx(r, m))?;
                        for _ in 0..n {
                            let idx = data.read(it).map_err(|m| ctx(r, m))?;
                            if idx < 0.0 {
                                return Err(ctx(r, format!("negative vertex index {idx}")));
                            }
                            poly.push(idx as u64);
                        }
                    } else if let (Some(k), Some(cs)) = (channel, rgb) {
                        c[k] = colour_value(data.read(cs[k].1).map_err(|m| ctx(r, m))?);
                    } else {
                        data.skip_prop(p.kind).map_err(|m| ctx(r, m))?;
                    }
                }
                builder.push_polygon(&poly, limit).map_err(|m| ctx(r, m))?;
                if rgb.is_some() {
                    // One colour for each triangle of the polygon's fan.
                    face_colours.extend(std::iter::repeat_n(c, poly.len().saturating_sub(2)));
                }
            }
        } else if el.props.is_empty() {
            // Records without properties take no room.
        } else {
            let fixed = el
                .props
                .iter()
                .all(|p| matches!(p.kind, PropKind::Scalar(_)));
            if fixed && data.is_binary() {
                let rec = min_record_len(el, header.format) as u64;
                let total = el.count.saturating_mul(rec);
                let total = usize::try_from(total).unwrap_or(usize::MAX);
                data.take(total)
                    .map_err(|m| format!("element '{}': {m}", el.name))?;
            } else {
                for r in 0..el.count {
                    for p in &el.props {
                        data.skip_prop(p.kind).map_err(|m| ctx(r, m))?;
                    }
                }
            }
        }
    }
    let mesh = builder.finish()?;
    if let Some(t) = vertex_types {
        to_fractions(&mut vertex_colours, t);
    }
    if let Some(t) = face_types {
        to_fractions(&mut face_colours, t);
    }
    let colours = if !vertex_colours.is_empty() && vertex_colours.len() == mesh.vertices.len() {
        Some(crate::colour::Colours::Vertex(vertex_colours))
    } else if !face_colours.is_empty() && face_colours.len() == mesh.faces.len() {
        Some(crate::colour::Colours::Face(face_colours))
    } else {
        None
    };
    Ok((mesh, colours))
}

/// Writes `mesh` as a binary little-endian PLY with a colour per vertex (`uchar red green
/// blue`).
///
/// # Errors
/// As [`write_to`]; colours of another count than the vertices.
pub fn write_coloured_to<W: Write>(
    mut w: W,
    mesh: &TriMesh,
    colours: &[[f32; 3]],
) -> std::io::Result<()> {
    super::file::check_coloured_writable(mesh, colours)?;
    let index_type = if mesh.vertices.len() > i32::MAX as usize + 1 {
        "uint"
    } else {
        "int"
    };
    write!(
        w,
        "ply\nformat binary_little_endian 1.0\ncomment written by ponq-mesh\n\
         element vertex {}\nproperty double x\nproperty double y\nproperty double z\n\
         property uchar red\nproperty uchar green\nproperty uchar blue\n\
         element face {}\nproperty list uchar {index_type} vertex_indices\nend_header\n",
        mesh.vertices.len(),
        mesh.faces.len()
    )?;
    let mut buf = Vec::with_capacity(mesh.vertices.len() * 27);
    for (v, c) in mesh.vertices.iter().zip(colours) {
        for x in v {
            buf.extend_from_slice(&x.to_le_bytes());
        }
        buf.extend_from_slice(&crate::colour::to_bytes(*c));
    }
    w.write_all(&buf)?;
    buf.clear();
    for f in &mesh.faces {
        buf.push(3);
        for &i in f {
            buf.extend_from_slice(&i.to_le_bytes());
        }
    }
    w.write_all(&buf)
}

fn write_header<W: Write>(w: &mut W, mesh: &TriMesh, format: &str) -> std::io::Result<()> {
    let index_type = if mesh.vertices.len() > i32::MAX as usize + 1 {
        "uint"
    } else {
        "int"
    };
    write!(
        w,
        "ply\nformat {format} 1.0\ncomment written by ponq-mesh\n\
         element vertex {}\nproperty double x\nproperty double y\nproperty double z\n\
         element face {}\nproperty list uchar {index_type} vertex_indices\nend_header\n",
        mesh.vertices.len(),
        mesh.faces.len()
    )
}

fn invalid(e: Error) -> std::io::Error {
    std::io::Error::new(std::io::ErrorKind::InvalidInput, e.to_string())
}

/// Writes `mesh` as binary little-endian PLY to `w` (`double` x, y, z and
/// `list uchar int vertex_indices`).
///
/// Returns an error of kind [`std::io::ErrorKind::InvalidInput`] if a face index is out of
/// range or a coordinate is not finite.
pub fn write_to<W: Write>(mut w: W, mesh: &TriMesh) -> std::io::Result<()> {
    check_writable(mesh).map_err(invalid)?;
    write_header(&mut w, mesh, "binary_little_endian")?;
    for v in &mesh.vertices {
        for c in v {
            w.write_all(&c.to_le_bytes())?;
        }
    }
    for f in &mesh.faces {
        let mut rec = [0u8; 13];
        rec[0] = 3;
        for (k, &i) in f.iter().enumerate() {
            rec[1 + 4 * k..5 + 4 * k].copy_from_slice(&i.to_le_bytes());
        }
        w.write_all(&rec)?;
    }
    Ok(())
}

/// Writes `mesh` as ASCII PLY to `w`, coordinates in the shortest form that reads back to
/// the same `f64`.
///
/// Returns an error of kind [`std::io::ErrorKind::InvalidInput`] if a face index is out of
/// range or a coordinate is not finite.
pub fn write_ascii_to<W: Write>(mut w: W, mesh: &TriMesh) -> std::io::Result<()> {
    check_writable(mesh).map_err(invalid)?;
    write_header(&mut w, mesh, "ascii")?;
    for v in &mesh.vertices {
        writeln!(w, "{:?} {:?} {:?}", v[0], v[1], v[2])?;
    }
    for f in &mesh.faces {
        writeln!(w, "3 {} {} {}", f[0], f[1], f[2])?;
    }
    Ok(())
}

/// Writes `mesh` to `path` as binary little-endian PLY; errors name the file. A mesh with a
/// face index out of range or a non-finite coordinate gives [`Error::InvalidInput`].
pub fn write(path: impl AsRef<Path>, mesh: &TriMesh) -> Result<()> {
    write_mesh_file(path.as_ref(), mesh, |w, m| write_to(w, m))
}

/// Writes `mesh` to `path` as ASCII PLY; errors name the file. A mesh with a face index out
/// of range or a non-finite coordinate gives [`Error::InvalidInput`].
pub fn write_ascii(path: impl AsRef<Path>, mesh: &TriMesh) -> Result<()> {
    write_mesh_file(path.as_ref(), mesh, |w, m| write_ascii_to(w, m))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn quad() -> TriMesh {
        TriMesh::new(
            vec![
                [0.0, 0.0, 0.0],
                [1.0, 0.0, 0.0],
                [1.0, 1.0, 0.1],
                [0.0, 1.0, -1e-300],
            ],
            vec![[0, 1, 2], [0, 2, 3]],
        )
        .unwrap()
    }

    #[test]
    fn roundtrip_in_memory() {
        let m = quad();
        let mut b = Vec::new();
        write_to(&mut b, &m).unwrap();
        assert_eq!(parse(&b).unwrap(), m);
        let mut a = Vec::new();
        write_ascii_to(&mut a, &m).unwrap();
        assert_eq!(parse(&a).unwrap(), m);
    }

    #[test]
    fn big_endian_with_extra_properties_and_elements() {
        let mut b = b"ply\r\nformat binary_big_endian 1.0\r\nelement vertex 3\r\nproperty uchar red\r\nproperty float x\r\nproperty float y\r\nproperty list uchar int junk\r\nproperty float z\r\nelement face 1\r\nproperty uchar flags\r\nproperty list uint8 uint32 vertex_index\r\nelement edge 1\r\nproperty list uchar int e\r\nend_header\r\n".to_vec();
        for (i, p) in [[0.0f32, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.5]]
            .iter()
            .enumerate()
        {
            b.push(7);
            b.extend_from_slice(&p[0].to_be_bytes());
            b.extend_from_slice(&p[1].to_be_bytes());
            b.push(i as u8);
            for _ in 0..i {
                b.extend_from_slice(&(-1i32).to_be_bytes());
            }
            b.extend_from_slice(&p[2].to_be_bytes());
        }
        b.push(9);
        b.push(3);
        for i in [2u32, 1, 0] {
            b.extend_from_slice(&i.to_be_bytes());
        }
        b.push(1);
        b.extend_from_slice(&5i32.to_be_bytes());
        let m = parse(&b).unwrap();
        assert_eq!(
            m.vertices,
            vec![[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.5]]
        );
        assert_eq!(m.faces, vec![[2, 1, 0]]);
    }

    #[test]
    fn rejects_bad_content() {
        let m = quad();
        let mut b = Vec::new();
        write_to(&mut b, &m).unwrap();
        for cut in [0, 10, b.len() - 1] {
            assert!(parse(&b[..cut]).is_err(), "cut {cut}");
        }
        let huge = b"ply\nformat binary_little_endian 1.0\nelement vertex 4000000000\nproperty float x\nproperty float y\nproperty float z\nelement junk 18446744073709551615\nend_header\n";
        assert!(parse(huge).is_err());
        let oob = b"ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\nelement face 1\nproperty list uchar int vertex_indices\nend_header\n0 0 0\n1 0 0\n0 1 0\n3 0 1 3\n";
        assert!(parse(oob).is_err());
        let nan = b"ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nproperty float y\nproperty float z\nend_header\n0 nan 0\n";
        assert!(parse(nan).is_err());
        let noz = b"ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nproperty float y\nend_header\n0 0\n";
        assert!(parse(noz).is_err());
    }
}

#[cfg(test)]
mod colour_tests {
    use super::parse_with_colours;
    use crate::colour::Colours;

    fn first_colour(ty: &str, values: &str) -> [f32; 3] {
        let src = format!(
            "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\n\
             property float z\nproperty {ty} red\nproperty {ty} green\nproperty {ty} blue\n\
             element face 1\nproperty list uchar int vertex_indices\nend_header\n\
             0 0 0 {values}\n1 0 0 0 0 0\n0 1 0 0 0 0\n3 0 1 2\n"
        );
        match parse_with_colours(src.as_bytes()).unwrap().1 {
            Some(Colours::Vertex(c)) => c[0],
            other => panic!("{other:?}"),
        }
    }

    fn close(a: [f32; 3], b: [f32; 3]) {
        assert!((0..3).all(|k| (a[k] - b[k]).abs() < 1e-6), "{a:?} != {b:?}");
    }

    /// Bytes in every type files use for them, fractions, and NaN (read as 0).
    #[test]
    fn colour_types() {
        close(first_colour("uchar", "255 0 51"), [1.0, 0.0, 0.2]);
        // `int red` holding 0..=255: bytes, not fractions of 2^31.
        close(first_colour("int", "255 0 51"), [1.0, 0.0, 0.2]);
        close(first_colour("ushort", "65535 0 0"), [1.0, 0.0, 0.0]);
        close(first_colour("float", "1 0 0.5"), [1.0, 0.0, 0.5]);
        // Floats holding bytes.
        close(first_colour("float", "255 0 51"), [1.0, 0.0, 0.2]);
        close(first_colour("float", "nan 1 0"), [0.0, 1.0, 0.0]);
    }
}
