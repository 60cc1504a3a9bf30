//! Standalone NumPy `.npy` arrays of floats, and 3D grids ([`Grid3`]).
//!
//! Arrays of dtype `float32` or `float64` (either byte order), in C or Fortran order, are
//! read into `f64` values in C order (last axis fastest). The header is checked by this
//! module before the `npyz` crate reads the data, so that malformed or hostile headers
//! (absurd shapes, structured or object dtypes, deep nesting) give errors, not panics, and no
//! memory is reserved beyond what the data actually present can fill.

use std::io::{BufReader, Cursor, Read};
use std::path::Path;

use npyz::WriterBuilder;

use super::builder::MAX_PREALLOC;
use super::file::write_file;
use crate::band::{BandBuilder, BandGrid};
use crate::error::{Error, Result};

/// A 3D grid of values stored in C order: `data[(i * dims[1] + j) * dims[2] + k]` is the
/// value at `(i, j, k)` (x slowest, z fastest).
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Grid3 {
    /// Sizes along x, y, z.
    pub dims: [usize; 3],
    /// `dims[0] * dims[1] * dims[2]` values in C order.
    pub data: Vec<f64>,
}

impl Grid3 {
    /// A grid; an [`Error::InvalidInput`] when `data.len()` is not the product of `dims`.
    pub fn new(dims: [usize; 3], data: Vec<f64>) -> Result<Self> {
        let n = dims
            .iter()
            .try_fold(1usize, |a, &d| a.checked_mul(d))
            .ok_or_else(|| Error::InvalidInput(format!("grid dimensions {dims:?} overflow")))?;
        if n != data.len() {
            return Err(Error::InvalidInput(format!(
                "a grid of dimensions {dims:?} needs {n} values, got {}",
                data.len()
            )));
        }
        Ok(Self { dims, data })
    }

    /// Index in `data` of the value at `(i, j, k)`.
    #[inline]
    pub fn index(&self, i: usize, j: usize, k: usize) -> usize {
        (i * self.dims[1] + j) * self.dims[2] + k
    }

    /// The value at `(i, j, k)`; panics when out of range.
    #[inline]
    pub fn get(&self, i: usize, j: usize, k: usize) -> f64 {
        self.data[self.index(i, j, k)]
    }
}

/// An n-dimensional array of floats read from a `.npy` file, in C order.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct NpyArray {
    /// The shape.
    pub shape: Vec<usize>,
    /// The product of `shape` values in C order (last axis fastest).
    pub data: Vec<f64>,
    /// True when the file stored `float32` values (converted exactly to `f64` here).
    pub was_f32: bool,
    /// True when the file stored bytes (`uint8` or `bool`): colours in `0..=255`, occupancies.
    pub was_bytes: bool,
}

/// Reads a `.npy` file holding a float32 or float64 array of any rank (NaN and infinities
/// are kept; see [`read_npy_grid`] for a checked 3D grid).
pub fn read_npy(path: impl AsRef<Path>) -> Result<NpyArray> {
    let path = path.as_ref();
    let file = std::fs::File::open(path).map_err(|e| Error::io(path, e))?;
    // The file size bounds the data (not for pipes and other special files).
    let len = match file.metadata() {
        Ok(m) if m.is_file() => m.len(),
        _ => u64::MAX,
    };
    read_array(BufReader::new(file), len).map_err(|m| Error::format(path, m))
}

/// Reads a `.npy` file holding a rank-3 float32 or float64 array (C or Fortran order) as a
/// [`Grid3`] in C order. Errors name the file and say what is wrong: wrong rank, non-float
/// dtype, a NaN or infinite value (with its index), truncated data.
pub fn read_npy_grid(path: impl AsRef<Path>) -> Result<Grid3> {
    let path = path.as_ref();
    let a = read_npy(path)?;
    if a.shape.len() != 3 {
        return Err(Error::format(
            path,
            format!(
                "expected a 3D grid (rank 3), found an array of shape {}",
                shape_str(&a.shape)
            ),
        ));
    }
    let dims = [a.shape[0], a.shape[1], a.shape[2]];
    if let Some(p) = a.data.iter().position(|v| !v.is_finite()) {
        let k = p % dims[2];
        let j = (p / dims[2]) % dims[1];
        let i = p / (dims[2] * dims[1]);
        return Err(Error::format(
            path,
            format!("grid value at [{i}, {j}, {k}] is {}", a.data[p]),
        ));
    }
    Ok(Grid3 { dims, data: a.data })
}

/// A value map applied to every value of a grid as it is read ([`read_npy_band_mapped`]).
pub type ValueMap<'a> = &'a (dyn Fn(f64) -> f64 + Sync);

/// Reads a rank-3 float32 or float64 `.npy` grid (C or Fortran order) into a
/// [`BandGrid`] plane by plane, never holding more than a few planes of the whole grid.
/// `band(dims)` gives, from the grid's node counts, the scale applied to every value, the
/// threshold (in scaled units), the reach of the band (see [`BandBuilder::new`]) and the
/// most bytes its values may take ([`BandBuilder::with_limit`]); it may refuse the grid.
/// `progress(done, total)` counts planes.
///
/// Errors are those of [`read_npy_grid`] (naming the file and the node of a non-finite
/// value), and `band`'s.
pub fn read_npy_band(
    path: impl AsRef<Path>,
    band: impl FnOnce([usize; 3]) -> Result<(f64, f64, usize, Option<usize>)>,
    progress: impl FnMut(usize, usize),
) -> Result<BandGrid> {
    read_npy_band_mapped(path, band, None, progress)
}

/// [`read_npy_band`] with every value passed through `map` before it is scaled (a field
/// conditioned into a signed distance as it is read).
///
/// # Errors
/// As [`read_npy_band`]; a value the map makes non-finite.
pub fn read_npy_band_mapped(
    path: impl AsRef<Path>,
    band: impl FnOnce([usize; 3]) -> Result<(f64, f64, usize, Option<usize>)>,
    map: Option<ValueMap<'_>>,
    mut progress: impl FnMut(usize, usize),
) -> Result<BandGrid> {
    let path = path.as_ref();
    let mut b: Option<BandBuilder> = None;
    let mut band = Some(band);
    let (_, fortran) = for_each_npy_plane(path, |stored, info_fortran, p, values| {
        if b.is_none() {
            let dims = if info_fortran {
                [stored[2], stored[1], stored[0]]
            } else {
                stored
            };
            let f = band
                .take()
                .ok_or_else(|| Error::InvalidInput("band read twice".into()))?;
            let (scale, threshold, reach, limit) = f(dims)?;
            b = Some(BandBuilder::new(stored, scale, threshold, reach)?.with_limit(limit));
        }
        let builder = b
            .as_mut()
            .ok_or_else(|| Error::InvalidInput("no band builder".into()))?;
        let mapped;
        let values = match map {
            Some(m) => {
                mapped = values.iter().map(|&v| m(v)).collect::<Vec<f64>>();
                &mapped
            }
            None => values,
        };
        builder.push_plane(values).map_err(|e| match e {
            Error::InvalidInput(m) if info_fortran => {
                Error::format(path, format!("{m} (of the reversed axes: Fortran order)"))
            }
            Error::InvalidInput(m) => Error::format(path, m),
            e => e,
        })?;
        progress(p + 1, stored[0]);
        Ok(())
    })?;
    let g = b
        .ok_or_else(|| Error::format(path, "a grid without planes"))?
        .finish()?;
    Ok(if fortran { g.reversed() } else { g })
}

/// Calls `f(stored_dims, fortran, index, plane)` for every plane of a rank-3 float32 or
/// float64 `.npy` grid, in the file's order: a C-order file's planes along its first axis, a
/// Fortran-order file's along its last (`stored_dims` are then the reversed axes). Returns the
/// grid's dims (in C order) and whether the file is in Fortran order. Holds one plane at a
/// time.
///
/// # Errors
/// As [`read_npy_grid`] (a file that is not a rank-3 float grid, a cut file); `f`'s errors.
pub fn for_each_npy_plane(
    path: impl AsRef<Path>,
    mut f: impl FnMut([usize; 3], bool, usize, &[f64]) -> Result<()>,
) -> Result<([usize; 3], bool)> {
    let path = path.as_ref();
    let file = std::fs::File::open(path).map_err(|e| Error::io(path, e))?;
    let len = match file.metadata() {
        Ok(m) if m.is_file() => m.len(),
        _ => u64::MAX,
    };
    let mut r = BufReader::with_capacity(1 << 20, file);
    let (info, size, _, shape) = read_header(&mut r, len).map_err(|m| Error::format(path, m))?;
    if shape.len() != 3 {
        return Err(Error::format(
            path,
            format!(
                "expected a 3D grid (rank 3), found an array of shape {}",
                shape_str(&shape)
            ),
        ));
    }
    let dims = [shape[0], shape[1], shape[2]];
    let stored = if info.fortran {
        [dims[2], dims[1], dims[0]]
    } else {
        dims
    };
    let big = is_big_endian(&info.descr);
    let plane = stored[1] * stored[2];
    for p in 0..stored[0] {
        let values = read_values(&mut r, plane, size, big)
            .map_err(|m| Error::format(path, format!("plane {p} of {}: {m}", stored[0])))?;
        f(stored, info.fortran, p, &values)?;
    }
    Ok((dims, info.fortran))
}

/// Writes `grid` to `path` as a C-order `float32` `.npy` file of shape `dims`.
///
/// Errors: [`Error::InvalidInput`] when `data.len()` does not match `dims` or a value is
/// not finite or overflows `f32`; [`Error::Io`] (naming the file) when writing fails.
pub fn write_npy_grid_f32(path: impl AsRef<Path>, grid: &Grid3) -> Result<()> {
    let path = path.as_ref();
    let n = grid.dims.iter().try_fold(1usize, |a, &d| a.checked_mul(d));
    if n != Some(grid.data.len()) {
        return Err(Error::InvalidInput(format!(
            "a grid of dimensions {:?} cannot hold {} values",
            grid.dims,
            grid.data.len()
        )));
    }
    if let Some(p) = grid
        .data
        .iter()
        .position(|&v| !v.is_finite() || !(v as f32).is_finite())
    {
        return Err(Error::InvalidInput(format!(
            "grid value {p} = {} is not finite or overflows f32",
            grid.data[p]
        )));
    }
    let shape = grid.dims.map(|d| d as u64);
    write_file(path, |w| {
        let mut npy = npyz::WriteOptions::<f32>::new()
            .default_dtype()
            .shape(&shape)
            .writer(w)
            .begin_nd()?;
        npy.extend(grid.data.iter().map(|&v| v as f32))?;
        npy.finish()
    })
}

/// Writes a [`BandGrid`] to `path` as a dense C-order `float32` `.npy` file, plane by plane
/// (no dense copy in memory), each value clamped to `[-clamp, clamp]` when given: with the
/// band's threshold, a truncated signed distance.
///
/// Errors: [`Error::InvalidInput`] when a value overflows `f32`; [`Error::Io`] (naming the
/// file) when writing fails.
pub fn write_npy_band_f32(
    path: impl AsRef<Path>,
    grid: &BandGrid,
    clamp: Option<f64>,
) -> Result<()> {
    let path = path.as_ref();
    let [d0, d1, d2] = grid.dims();
    let big = grid.stats().min.abs().max(grid.stats().max.abs());
    if !(big as f32).is_finite() {
        return Err(Error::InvalidInput(format!(
            "a grid value ({big}) overflows f32"
        )));
    }
    let shape = grid.dims().map(|d| d as u64);
    let c = clamp.unwrap_or(f64::INFINITY);
    write_file(path, |w| {
        let mut npy = npyz::WriteOptions::<f32>::new()
            .default_dtype()
            .shape(&shape)
            .writer(w)
            .begin_nd()?;
        for i in 0..d0 {
            let plane = grid.block([i, 0, 0], [i, d1 - 1, d2 - 1]);
            npy.extend(plane.iter().map(|&v| v.clamp(-c, c) as f32))?;
        }
        npy.finish()
    })
}

/// Formats a shape like NumPy: `(3,)`, `(2, 3)`.
pub fn shape_str(shape: &[usize]) -> String {
    match shape {
        [n] => format!("({n},)"),
        _ => format!(
            "({})",
            shape
                .iter()
                .map(|d| d.to_string())
                .collect::<Vec<_>>()
                .join(", ")
        ),
    }
}

// ---------------------------------------------------------------------------------------------
// Header validation: a tiny parser for the Python literal of the header.

/// Largest header accepted (NumPy itself refuses headers above 10 KB by default).
const MAX_HEADER: usize = 1 << 20;
/// Deepest nesting of brackets accepted in a header.
const MAX_DEPTH: usize = 4;

#[derive(Debug, Clone, PartialEq)]
enum Lit {
    Str(String),
    Bool(bool),
    Int(u64),
    Seq(Vec<Lit>),
}

struct LitParser<'a> {
    s: &'a [u8],
    i: usize,
}

impl LitParser<'_> {
    fn ws(&mut self) {
        while self.i < self.s.len() && self.s[self.i].is_ascii_whitespace() {
            self.i += 1;
        }
    }

    fn peek(&self) -> Option<u8> {
        self.s.get(self.i).copied()
    }

    fn err(&self, what: &str) -> String {
        format!("malformed npy header ({what} at character {})", self.i)
    }

    fn value(&mut self, depth: usize) -> std::result::Result<Lit, String> {
        self.ws();
        match self.peek() {
            Some(q @ (b'\'' | b'"')) => {
                self.i += 1;
                let mut out = Vec::new();
                loop {
                    match self.peek() {
                        None => return Err(self.err("unterminated string")),
                        Some(c) if c == q => {
                            self.i += 1;
                            break;
                        }
                        Some(b'\\') => {
                            return Err(self.err("escape sequences are not supported"));
                        }
                        Some(c) => {
                            out.push(c);
                            self.i += 1;
                        }
                    }
                }
                Ok(Lit::Str(String::from_utf8_lossy(&out).into_owned()))
            }
            Some(b'T') if self.s[self.i..].starts_with(b"True") => {
                self.i += 4;
                Ok(Lit::Bool(true))
            }
            Some(b'F') if self.s[self.i..].starts_with(b"False") => {
                self.i += 5;
                Ok(Lit::Bool(false))
            }
            Some(c) if c.is_ascii_digit() => {
                let start = self.i;
                while self.peek().is_some_and(|c| c.is_ascii_digit()) {
                    self.i += 1;
                }
                let digits = std::str::from_utf8(&self.s[start..self.i]).unwrap_or("");
                let v = digits
                    .parse::<u64>()
                    .map_err(|_| format!("npy header: the number {digits} is too large"))?;
                if matches!(self.peek(), Some(b'L' | b'l')) {
                    self.i += 1;
                }
                Ok(Lit::Int(v))
            }
            Some(open @ (b'(' | b'[')) => {
                if depth >= MAX_DEPTH {
                    return Err(self.err("nesting too deep"));
                }
                let close = if open == b'(' { b')' } else { b']' };
                self.i += 1;
                let mut items = Vec::new();
                loop {
                    self.ws();
                    if self.peek() == Some(close) {
                        self.i += 1;
                        break;
                    }
                    items.push(self.value(depth + 1)?);
                    self.ws();
                    match self.peek() {
                        Some(b',') => self.i += 1,
                        Some(c) if c == close => {
                            self.i += 1;
                            break;
                        }
                        _ => return Err(self.err("expected ',' or a closing bracket")),
                    }
                }
                Ok(Lit::Seq(items))
            }
            _ => Err(self.err("unexpected character")),
        }
    }
}

/// What the header of a `.npy` says.
#[derive(Debug, Clone, PartialEq)]
struct HeaderInfo {
    descr: String,
    fortran: bool,
    shape: Vec<u64>,
}

fn parse_header_text(text: &[u8]) -> std::result::Result<HeaderInfo, String> {
    let mut p = LitParser { s: text, i: 0 };
    p.ws();
    if p.peek() != Some(b'{') {
        return Err(p.err("expected '{'"));
    }
    p.i += 1;
    let (mut descr, mut fortran, mut shape) = (None, None, None);
    loop {
        p.ws();
        if p.peek() == Some(b'}') {
            p.i += 1;
            break;
        }
        let Lit::Str(key) = p.value(1)? else {
            return Err(p.err("a key that is not a string"));
        };
        p.ws();
        if p.peek() != Some(b':') {
            return Err(p.err("expected ':'"));
        }
        p.i += 1;
        let val = p.value(1)?;
        match (key.as_str(), val) {
            ("descr", Lit::Str(s)) => descr = Some(s),
            ("descr", Lit::Seq(_)) => {
                return Err("unsupported dtype: structured arrays are not supported, expected float32 or float64".to_string());
            }
            ("fortran_order", Lit::Bool(b)) => fortran = Some(b),
            ("shape", Lit::Seq(items)) => {
                let mut dims = Vec::with_capacity(items.len());
                for it in items {
                    match it {
                        Lit::Int(d) => dims.push(d),
                        _ => return Err("npy header: 'shape' holds a non-integer".to_string()),
                    }
                }
                shape = Some(dims);
            }
            (k @ ("descr" | "fortran_order" | "shape"), v) => {
                return Err(format!("npy header: invalid value {v:?} for '{k}'"));
            }
            (k, _) => return Err(format!("npy header: unexpected key '{k}'")),
        }
        p.ws();
        match p.peek() {
            Some(b',') => p.i += 1,
            Some(b'}') => {
                p.i += 1;
                break;
            }
            _ => return Err(p.err("expected ',' or '}'")),
        }
    }
    p.ws();
    if p.i != text.len() {
        return Err(p.err("unexpected text after the header dictionary"));
    }
    let descr = descr.ok_or("npy header: missing 'descr'")?;
    let fortran = fortran.ok_or("npy header: missing 'fortran_order'")?;
    let shape = shape.ok_or("npy header: missing 'shape'")?;
    Ok(HeaderInfo {
        descr,
        fortran,
        shape,
    })
}

/// Element size (1, 4 or 8) of an accepted dtype description.
fn float_size(descr: &str) -> std::result::Result<usize, String> {
    let body = descr.strip_prefix(['<', '>', '=', '|']).unwrap_or(descr);
    match body {
        "f4" => Ok(4),
        "f8" => Ok(8),
        // Bytes (uint8, bool): colours, voxel occupancies.
        "u1" | "b1" => Ok(1),
        _ => Err(format!(
            "unsupported dtype '{}': expected float32 ('<f4', '>f4'), float64 ('<f8', '>f8') \
             or bytes ('|u1', '|b1')",
            descr.chars().take(32).collect::<String>()
        )),
    }
}

fn eof_to_msg(e: std::io::Error, what: &str) -> String {
    if e.kind() == std::io::ErrorKind::UnexpectedEof {
        format!("truncated {what}")
    } else {
        format!("cannot read {what}: {e}")
    }
}

/// Reads a whole `.npy` stream of float32/float64 values into C order. `max_bytes` bounds
/// the size of the stream (the file size or the zip entry size) and caps preallocation.
pub(crate) fn read_array<R: Read>(
    mut r: R,
    max_bytes: u64,
) -> std::result::Result<NpyArray, String> {
    let (info, size, n, shape) = read_header(&mut r, max_bytes)?;
    let big = is_big_endian(&info.descr);
    let data = read_values(&mut r, n as usize, size, big)?;
    let data = if info.fortran && shape.len() > 1 {
        fortran_to_c(&data, &shape)
    } else {
        data
    };
    Ok(NpyArray {
        shape,
        data,
        was_f32: size == 4,
        was_bytes: size == 1,
    })
}

fn is_big_endian(descr: &str) -> bool {
    descr.starts_with('>') || (descr.starts_with('=') && cfg!(target_endian = "big"))
}

/// Reads and checks a `.npy` header: what it says, the element size, the value count and
/// the shape. `max_bytes` bounds the stream's size (the data must fit in it).
fn read_header<R: Read>(
    mut r: R,
    max_bytes: u64,
) -> std::result::Result<(HeaderInfo, usize, u64, Vec<usize>), String> {
    let mut pre = [0u8; 8];
    r.read_exact(&mut pre)
        .map_err(|e| eof_to_msg(e, "npy header"))?;
    if &pre[..6] != b"\x93NUMPY" {
        return Err("not a .npy array (bad magic bytes)".to_string());
    }
    let mut prefix = pre.to_vec();
    let hlen = match pre[6] {
        1 => {
            let mut b = [0u8; 2];
            r.read_exact(&mut b)
                .map_err(|e| eof_to_msg(e, "npy header"))?;
            prefix.extend_from_slice(&b);
            u16::from_le_bytes(b) as usize
        }
        2 | 3 => {
            let mut b = [0u8; 4];
            r.read_exact(&mut b)
                .map_err(|e| eof_to_msg(e, "npy header"))?;
            prefix.extend_from_slice(&b);
            u32::from_le_bytes(b) as usize
        }
        v => return Err(format!("unsupported .npy format version {v}.{}", pre[7])),
    };
    if hlen > MAX_HEADER {
        return Err(format!("npy header of {hlen} bytes is implausibly large"));
    }
    let mut text = vec![0u8; hlen];
    r.read_exact(&mut text)
        .map_err(|e| eof_to_msg(e, "npy header"))?;
    let info = parse_header_text(&text)?;
    let size = float_size(&info.descr)?;
    let n = info
        .shape
        .iter()
        .try_fold(1u64, |a, &d| a.checked_mul(d))
        .filter(|&n| n.checked_mul(size as u64).is_some() && usize::try_from(n).is_ok())
        .ok_or_else(|| format!("the array shape {:?} is too large", info.shape))?;
    let shape: Vec<usize> = info.shape.iter().map(|&d| d as usize).collect();
    prefix.extend_from_slice(&text);
    let data_bytes = max_bytes.saturating_sub(prefix.len() as u64);
    if n.saturating_mul(size as u64) > data_bytes {
        return Err(format!(
            "truncated data: shape {} needs {} bytes of data but at most {data_bytes} are present",
            shape_str(&shape),
            n * size as u64
        ));
    }
    // npyz checks the header; the data is read here in blocks (npyz's value-by-value reader
    // took 30-50 ms for the 19 MB of a 100k-point PoNQ, most of `ponq-mesh`'s reading).
    let npy =
        npyz::NpyFile::new(Cursor::new(prefix)).map_err(|e| format!("invalid npy header: {e}"))?;
    if npy.shape() != info.shape.as_slice() {
        return Err("inconsistent npy header".to_string());
    }
    Ok((info, size, n, shape))
}

/// Reads `n` floats of `size` bytes (4 or 8; big-endian if `big`, else little-endian) from
/// `r`, as f64, in blocks. A short stream is
/// an error that says how many values it held.
fn read_values<R: Read>(
    r: &mut R,
    n: usize,
    size: usize,
    big: bool,
) -> std::result::Result<Vec<f64>, String> {
    let mut data = Vec::with_capacity(n.min(MAX_PREALLOC));
    read_values_into(r, n, size, big, &mut data)?;
    Ok(data)
}

/// [`read_values`] appending to `data` (which should be empty: counts in errors are its
/// length).
fn read_values_into<R: Read>(
    r: &mut R,
    n: usize,
    size: usize,
    big: bool,
    data: &mut Vec<f64>,
) -> std::result::Result<(), String> {
    const BLOCK: usize = 1 << 16;
    let mut buf = [0u8; BLOCK];
    while data.len() < n {
        let want = ((n - data.len()) * size).min(BLOCK);
        let mut got = 0;
        while got < want {
            match r.read(&mut buf[got..want]) {
                Ok(0) => {
                    return Err(format!(
                        "truncated data: the header announces {n} values but the data ends \
                         after {}",
                        data.len() + got / size
                    ));
                }
                Ok(k) => got += k,
                Err(e) if e.kind() == std::io::ErrorKind::Interrupted => {}
                Err(e) => {
                    return Err(format!(
                        "cannot read value {}: {e}",
                        data.len() + got / size
                    ));
                }
            }
        }
        let bytes = &buf[..want];
        match (size, big) {
            (1, _) => data.extend(bytes.iter().map(|&b| f64::from(b))),
            (4, false) => data.extend(
                bytes
                    .chunks_exact(4)
                    .map(|c| f32::from_le_bytes([c[0], c[1], c[2], c[3]]) as f64),
            ),
            (4, true) => data.extend(
                bytes
                    .chunks_exact(4)
                    .map(|c| f32::from_be_bytes([c[0], c[1], c[2], c[3]]) as f64),
            ),
            (_, false) => data.extend(
                bytes
                    .chunks_exact(8)
                    .map(|c| f64::from_le_bytes([c[0], c[1], c[2], c[3], c[4], c[5], c[6], c[7]])),
            ),
            (_, true) => data.extend(
                bytes
                    .chunks_exact(8)
                    .map(|c| f64::from_be_bytes([c[0], c[1], c[2], c[3], c[4], c[5], c[6], c[7]])),
            ),
        }
    }
    Ok(())
}

/// Reorders values stored in Fortran order (first axis fastest) into C order.
fn fortran_to_c(data: &[f64], shape: &[usize]) -> Vec<f64> {
    let rank = shape.len();
    // Fortran strides.
    let mut fstride = vec![1usize; rank];
    for a in 1..rank {
        fstride[a] = fstride[a - 1] * shape[a - 1];
    }
    let mut out = Vec::with_capacity(data.len());
    let mut idx = vec![0usize; rank];
    for _ in 0..data.len() {
        let off: usize = idx.iter().zip(&fstride).map(|(i, s)| i * s).sum();
        out.push(data[off]);
        // Increment the C-order multi-index (last axis fastest).
        for a in (0..rank).rev() {
            idx[a] += 1;
            if idx[a] < shape[a] {
                break;
            }
            idx[a] = 0;
        }
    }
    out
}

/// Parses a `.npy` file already in memory (float32/float64, any rank, C order result);
/// errors are plain messages.
pub fn parse(bytes: &[u8]) -> std::result::Result<NpyArray, String> {
    read_array(bytes, bytes.len() as u64)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn npy_bytes(header: &str, data: &[u8]) -> Vec<u8> {
        let mut h = header.to_string();
        while !(10 + h.len() + 1).is_multiple_of(64) {
            h.push(' ');
        }
        h.push('\n');
        let mut b = b"\x93NUMPY\x01\x00".to_vec();
        b.extend_from_slice(&(h.len() as u16).to_le_bytes());
        b.extend_from_slice(h.as_bytes());
        b.extend_from_slice(data);
        b
    }

    #[test]
    fn header_parser() {
        let h =
            parse_header_text(b"{'descr': '<f8', 'fortran_order': False, 'shape': (2, 3L), }   \n")
                .unwrap();
        assert_eq!(h.shape, vec![2, 3]);
        assert!(!h.fortran);
        assert!(parse_header_text(b"{'descr': '<f8', 'fortran_order': False}").is_err());
        assert!(
            parse_header_text(
                b"{'descr': '<f8', 'fortran_order': False, 'shape': ((((((1,),),),),),)}"
            )
            .is_err()
        );
        assert!(
            parse_header_text(
                b"{'descr': '<f8', 'fortran_order': False, 'shape': (99999999999999999999999,)}"
            )
            .is_err()
        );
        assert!(
            parse_header_text(b"{'descr': [('a', '<f8')], 'fortran_order': False, 'shape': ()}")
                .is_err()
        );
    }

    #[test]
    fn fortran_and_big_endian() {
        // shape (2, 3) Fortran order: memory holds columns.
        let vals = [0.0f64, 3.0, 1.0, 4.0, 2.0, 5.0];
        let mut d = Vec::new();
        for v in vals {
            d.extend_from_slice(&v.to_be_bytes());
        }
        let b = npy_bytes(
            "{'descr': '>f8', 'fortran_order': True, 'shape': (2, 3), }",
            &d,
        );
        let a = parse(&b).unwrap();
        assert_eq!(a.shape, vec![2, 3]);
        assert_eq!(a.data, vec![0.0, 1.0, 2.0, 3.0, 4.0, 5.0]);
    }

    #[test]
    fn rejects_bad_arrays() {
        let b = npy_bytes(
            "{'descr': '<i8', 'fortran_order': False, 'shape': (1,), }",
            &[0; 8],
        );
        assert!(parse(&b).unwrap_err().contains("dtype"));
        let b = npy_bytes(
            "{'descr': '<f8', 'fortran_order': False, 'shape': (2,), }",
            &[0; 12],
        );
        assert!(parse(&b).unwrap_err().contains("truncated"));
        let b = npy_bytes(
            "{'descr': '<f8', 'fortran_order': False, 'shape': (4294967296, 4294967296, 4294967296), }",
            &[],
        );
        assert!(parse(&b).is_err());
        assert!(parse(b"\x93NUMPY").is_err());
        assert!(parse(b"garbage garbage garbage").is_err());
    }

    /// The streamed band reading holds exactly the values of the dense reading where it
    /// stores them, in C and Fortran order, float32 and float64.
    #[test]
    fn band_reading_matches_the_dense_reading() {
        let dims = [13usize, 9, 22];
        let n = dims.iter().product::<usize>();
        let val = |i: usize, j: usize, k: usize| {
            ((i as f64 - 6.0).powi(2) + (j as f64 - 4.0).powi(2) + (k as f64 - 11.0).powi(2)).sqrt()
                - 3.7
        };
        for (descr, fortran) in [("<f8", false), ("<f4", false), ("<f8", true), (">f4", true)] {
            let mut d = Vec::new();
            let mut push = |v: f64| match descr {
                "<f8" => d.extend_from_slice(&v.to_le_bytes()),
                "<f4" => d.extend_from_slice(&(v as f32).to_le_bytes()),
                _ => d.extend_from_slice(&(v as f32).to_be_bytes()),
            };
            if fortran {
                for k in 0..dims[2] {
                    for j in 0..dims[1] {
                        for i in 0..dims[0] {
                            push(val(i, j, k));
                        }
                    }
                }
            } else {
                for i in 0..dims[0] {
                    for j in 0..dims[1] {
                        for k in 0..dims[2] {
                            push(val(i, j, k));
                        }
                    }
                }
            }
            let b = npy_bytes(
                &format!(
                    "{{'descr': '{descr}', 'fortran_order': {}, 'shape': (13, 9, 22), }}",
                    if fortran { "True" } else { "False" }
                ),
                &d,
            );
            let dir = std::env::temp_dir().join(format!("ponq-band-{}", std::process::id()));
            std::fs::create_dir_all(&dir).unwrap();
            let p = dir.join(format!("g{descr}{fortran}.npy").replace(['<', '>'], "_"));
            std::fs::write(&p, &b).unwrap();
            let dense = read_npy_grid(&p).unwrap();
            let mut planes = 0;
            let band = read_npy_band(
                &p,
                |d| {
                    assert_eq!(d, dims);
                    Ok((2.0, 3.0, 1, None))
                },
                |done, _| planes = done,
            )
            .unwrap();
            assert_eq!(planes, if fortran { 22 } else { 13 });
            assert_eq!(band.dims(), dims);
            assert!(band.stored_bricks() > 0);
            for f in 0..n {
                let [i, j, k] = band.coords(f);
                let v = dense.data[f] * 2.0;
                if band.is_stored(i, j, k) {
                    assert_eq!(
                        band.get(i, j, k).to_bits(),
                        v.to_bits(),
                        "{descr} {fortran}"
                    );
                } else {
                    assert!(v.abs() >= 3.0 && band.get(i, j, k) == 3.0f64.copysign(v));
                }
            }
            // A cut file says where it ends.
            std::fs::write(&p, &b[..b.len() - 100]).unwrap();
            let e = read_npy_band(&p, |_| Ok((1.0, 1.0, 0, None)), |_, _| {}).unwrap_err();
            assert!(e.to_string().contains("truncated"), "{e}");
            std::fs::remove_dir_all(&dir).ok();
        }
    }

    /// The block reader gives npyz's values (what it replaced) for both float sizes and byte
    /// orders, lengths around the block size, and a clear error wherever the data is cut.
    #[test]
    fn block_reader_matches_npyz() {
        use rand::{Rng, SeedableRng};
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(3);
        for (descr, size) in [("<f8", 8), (">f8", 8), ("<f4", 4), (">f4", 4)] {
            for n in [0usize, 1, 7, 8191, 8192, 8193, 16384, 40_000] {
                let vals: Vec<f64> = (0..n)
                    .map(|_| rng.random_range(-1e6..1e6) * rng.random_range(0.0..1.0))
                    .collect();
                let mut d = Vec::new();
                for &v in &vals {
                    match descr {
                        "<f8" => d.extend_from_slice(&v.to_le_bytes()),
                        ">f8" => d.extend_from_slice(&v.to_be_bytes()),
                        "<f4" => d.extend_from_slice(&(v as f32).to_le_bytes()),
                        _ => d.extend_from_slice(&(v as f32).to_be_bytes()),
                    }
                }
                let b = npy_bytes(
                    &format!("{{'descr': '{descr}', 'fortran_order': False, 'shape': ({n},), }}"),
                    &d,
                );
                let ours = parse(&b).unwrap().data;
                let npy = npyz::NpyFile::new(&b[..]).unwrap();
                let reference: Vec<f64> = if size == 4 {
                    npy.data::<f32>()
                        .unwrap()
                        .map(|v| v.unwrap() as f64)
                        .collect()
                } else {
                    npy.data::<f64>().unwrap().map(|v| v.unwrap()).collect()
                };
                assert_eq!(ours.len(), n);
                assert!(
                    ours.iter()
                        .zip(&reference)
                        .all(|(a, b)| a.to_bits() == b.to_bits()),
                    "{descr}, {n} values"
                );
                // A stream cut short (its declared size still the full one) says where it ends.
                if n > 0 {
                    let cut = b.len() - 1 - rng.random_range(0..d.len());
                    let err = read_array(&b[..cut], b.len() as u64).unwrap_err();
                    let held = (d.len() - (b.len() - cut)) / size;
                    assert!(
                        err.contains("truncated") && err.ends_with(&format!("after {held}")),
                        "{descr}, {n} values cut at {cut}: {err}"
                    );
                }
            }
        }
    }
}
