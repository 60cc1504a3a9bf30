//! # ponq-py
//!
//! The Python module `ponq` (PyO3 + NumPy, built by maturin): the command-line programs of
//! PoNQ-rs as functions on NumPy arrays. Each function does what its program does with the
//! same options, gives the same error messages (as `ValueError`; flags are named as the
//! keyword arguments), and releases the GIL while it works. See `ponq-py/README.md`.

use std::collections::HashMap;
use std::panic::{AssertUnwindSafe, catch_unwind};
use std::path::{Path, PathBuf};
use std::sync::{Arc, Mutex, OnceLock};

use burn::prelude::Device;
use nalgebra::Matrix4;
use numpy::{PyArray1, PyArrayMethods, PyReadonlyArrayDyn, PyUntypedArrayMethods};
use ponq_data::normalize::Normalization;
use ponq_infer::{Frame, InferOptions, RefineMode, finish, predict};
use ponq_mesh::io::npy::{Grid3, shape_str};
use ponq_mesh::lite::simplify_by_position;
use ponq_mesh::mesher::{MeshingOptions, mesh_ponq};
use ponq_mesh::metrics::{MetricOptions, compare};
use ponq_mesh::validity::{self, ValidityReport};
use ponq_mesh::{Ponq, Quadric, TriMesh};
use ponq_model::{PonqNet, PonqNetConfig};
use pyo3::exceptions::{PyRuntimeError, PyValueError};
use pyo3::prelude::*;
use pyo3::types::{PyBool, PyDict, PyTuple};

/// The open-surface threshold that `open=True` stands for (the programs' `--open` without a
/// value).
const DEFAULT_OPEN: f64 = 0.35;

// ---------------------------------------------------------------------------------------------
// Errors and running the work without the GIL.

/// Why a call failed: bad input (`ValueError`) or a failure of the computation
/// (`RuntimeError`).
enum Failure {
    Value(String),
    Runtime(String),
}

type Work<T> = Result<T, Failure>;

fn bad<T>(msg: impl Into<String>) -> Work<T> {
    Err(Failure::Value(msg.into()))
}

impl From<anyhow::Error> for Failure {
    /// Bad input when some error of the chain says so (the crates' invalid-input and format
    /// errors, an unreadable model file), a runtime failure otherwise; the message is the
    /// programs' (`{:#}`, the chain joined by colons).
    fn from(e: anyhow::Error) -> Self {
        let input = e.chain().any(|c| {
            matches!(
                c.downcast_ref::<ponq_mesh::Error>(),
                Some(
                    ponq_mesh::Error::InvalidInput(_)
                        | ponq_mesh::Error::Format { .. }
                        | ponq_mesh::Error::Io { .. }
                )
            ) || matches!(
                c.downcast_ref::<ponq_data::DataError>(),
                Some(ponq_data::DataError::Invalid(_))
            ) || matches!(
                c.downcast_ref::<ponq_model::ModelError>(),
                Some(ponq_model::ModelError::Weights { .. })
            )
        });
        let msg = format!("{e:#}");
        if input {
            Failure::Value(msg)
        } else {
            Failure::Runtime(msg)
        }
    }
}

impl From<ponq_mesh::Error> for Failure {
    fn from(e: ponq_mesh::Error) -> Self {
        anyhow::Error::from(e).into()
    }
}

impl From<ponq_data::DataError> for Failure {
    fn from(e: ponq_data::DataError) -> Self {
        anyhow::Error::from(e).into()
    }
}

fn to_pyerr(f: Failure) -> PyErr {
    match f {
        Failure::Value(m) => PyValueError::new_err(m),
        Failure::Runtime(m) => PyRuntimeError::new_err(m),
    }
}

fn value_err(msg: impl Into<String>) -> PyErr {
    PyValueError::new_err(msg.into())
}

/// Thread pools by size, built once (a `threads=` argument runs the work in one).
fn pool(threads: usize) -> PyResult<Arc<rayon::ThreadPool>> {
    static POOLS: OnceLock<Mutex<HashMap<usize, Arc<rayon::ThreadPool>>>> = OnceLock::new();
    let mut pools = POOLS
        .get_or_init(Default::default)
        .lock()
        .unwrap_or_else(|e| e.into_inner());
    if let Some(p) = pools.get(&threads) {
        return Ok(p.clone());
    }
    let p = Arc::new(
        rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .map_err(|e| PyRuntimeError::new_err(format!("cannot set the thread count: {e}")))?,
    );
    pools.insert(threads, p.clone());
    Ok(p)
}

/// The text of a panic's payload.
fn panic_text(p: &(dyn std::any::Any + Send)) -> String {
    if let Some(s) = p.downcast_ref::<&str>() {
        (*s).to_string()
    } else if let Some(s) = p.downcast_ref::<String>() {
        s.clone()
    } else {
        "(no message)".to_string()
    }
}

/// Runs `f` with the GIL released, in a pool of `threads` workers (the global pool when
/// `None`); a panic becomes a `RuntimeError`.
fn run<T: Send>(
    py: Python<'_>,
    threads: Option<usize>,
    f: impl FnOnce() -> Work<T> + Send,
) -> PyResult<T> {
    let pool = match threads {
        Some(0) => return Err(value_err("threads must be at least 1")),
        Some(n) => Some(pool(n)?),
        None => None,
    };
    let out = py.detach(move || {
        catch_unwind(AssertUnwindSafe(move || match &pool {
            Some(p) => p.install(f),
            None => f(),
        }))
    });
    match out {
        Ok(Ok(v)) => Ok(v),
        Ok(Err(e)) => Err(to_pyerr(e)),
        Err(p) => Err(PyRuntimeError::new_err(format!(
            "internal error (a Rust panic; please report it): {}",
            panic_text(p.as_ref())
        ))),
    }
}

/// `warnings.warn(msg, category)` (`category` a builtin warning class name).
fn warn(py: Python<'_>, category: &str, msg: &str) -> PyResult<()> {
    let cat = py.import("builtins")?.getattr(category)?;
    py.import("warnings")?
        .call_method1("warn", (msg, cat, 2))
        .map(|_| ())
}

// ---------------------------------------------------------------------------------------------
// Arrays in.

/// An array-like as C-order values of `dtype` (`"float64"` or `"int64"`) with its shape,
/// after checking that its dtype kind is one of `kinds` (NumPy's `dtype.kind` letters).
fn array_as<'py, T: numpy::Element + Copy>(
    obj: &Bound<'py, PyAny>,
    name: &str,
    dtype: &str,
    kinds: &str,
    what: &str,
) -> PyResult<(Vec<usize>, Vec<T>)> {
    let py = obj.py();
    let np = py.import("numpy")?;
    let arr = np.call_method1("asarray", (obj,))?;
    let dt = arr.getattr("dtype")?;
    let kind: String = dt.getattr("kind")?.extract()?;
    let size: usize = arr.getattr("size")?.extract()?;
    // An empty list comes in as float64: any dtype will do for no values.
    if size > 0 && !kinds.contains(kind.as_str()) {
        return Err(value_err(format!(
            "{name}: expected {what}, got an array of dtype {}",
            dt.str()?
        )));
    }
    let kw = PyDict::new(py);
    kw.set_item("dtype", dtype)?;
    let c = np.call_method("ascontiguousarray", (arr,), Some(&kw))?;
    let ro: PyReadonlyArrayDyn<'py, T> = c.extract()?;
    let shape = ro.shape().to_vec();
    let data = ro
        .as_slice()
        .map_err(|e| PyRuntimeError::new_err(format!("{name}: {e}")))?
        .to_vec();
    Ok((shape, data))
}

/// Real values (any float, int or unsigned dtype, any memory order) as `f64`, C order.
fn floats(obj: &Bound<'_, PyAny>, name: &str) -> PyResult<(Vec<usize>, Vec<f64>)> {
    array_as::<f64>(obj, name, "float64", "fiu", "an array of real numbers")
}

/// Integers (any int or unsigned dtype) as `i64`, C order.
fn ints(obj: &Bound<'_, PyAny>, name: &str) -> PyResult<(Vec<usize>, Vec<i64>)> {
    array_as::<i64>(obj, name, "int64", "iu", "an array of integers")
}

/// An `(M, 3)` array's rows; `letter` names `M` in the message.
fn rows3(shape: &[usize], data: &[f64], name: &str, letter: &str) -> PyResult<Vec<[f64; 3]>> {
    if shape.len() != 2 || shape[1] != 3 {
        return Err(value_err(format!(
            "array '{name}': expected shape ({letter}, 3), found {}",
            shape_str(shape)
        )));
    }
    Ok(data.chunks_exact(3).map(|c| [c[0], c[1], c[2]]).collect())
}

/// A 3D grid (rank 3, finite values), checked as `ponq-infer` checks a `.npy` grid.
fn grid3(obj: &Bound<'_, PyAny>) -> PyResult<Grid3> {
    let (shape, data) = floats(obj, "sdf")?;
    if shape.len() != 3 {
        return Err(value_err(format!(
            "expected a 3D grid (rank 3), found an array of shape {}",
            shape_str(&shape)
        )));
    }
    let dims = [shape[0], shape[1], shape[2]];
    if let Some(p) = data.iter().position(|v| !v.is_finite()) {
        let k = p % dims[2];
        let j = (p / dims[2]) % dims[1];
        let i = p / (dims[2] * dims[1]);
        return Err(value_err(format!(
            "grid value at [{i}, {j}, {k}] is {}",
            data[p]
        )));
    }
    Ok(Grid3 { dims, data })
}

/// A triangle mesh from `(V, 3)` vertices and `(F, 3)` faces (0-based), checked as the mesh
/// readers check a file.
fn mesh_in(vertices: &Bound<'_, PyAny>, faces: &Bound<'_, PyAny>, name: &str) -> PyResult<TriMesh> {
    let vname = format!("{name}vertices");
    let fname = format!("{name}faces");
    let (vs, vd) = floats(vertices, &vname)?;
    let vertices = rows3(&vs, &vd, &vname, "V")?;
    if let Some(i) = vertices
        .iter()
        .position(|v| v.iter().any(|c| !c.is_finite()))
    {
        return Err(value_err(format!(
            "vertex {i} = {:?} has a non-finite coordinate",
            vertices[i]
        )));
    }
    let (fs, fd) = ints(faces, &fname)?;
    // An empty list of faces comes in as shape (0,).
    let fs = if fs == [0] { vec![0, 3] } else { fs };
    if fs.len() != 2 || fs[1] != 3 {
        return Err(value_err(format!(
            "array '{fname}': expected shape (F, 3), found {}",
            shape_str(&fs)
        )));
    }
    let n = vertices.len();
    let mut out = Vec::with_capacity(fd.len() / 3);
    for (id, f) in fd.chunks_exact(3).enumerate() {
        if let Some(&b) = f.iter().find(|&&i| i < 0 || i as u64 >= n as u64) {
            return Err(value_err(format!(
                "face {id} refers to vertex {b} but there are only {n} vertices (indices are 0-based here)"
            )));
        }
        out.push([f[0] as u32, f[1] as u32, f[2] as u32]);
    }
    if n > u32::MAX as usize {
        return Err(value_err("more vertices than 32-bit indices can address"));
    }
    Ok(TriMesh {
        vertices,
        faces: out,
    })
}

/// The domain box from `bounds` (6 numbers), or `[-1,1]^3`.
fn domain(bounds: Option<Vec<f64>>) -> PyResult<([f64; 3], [f64; 3])> {
    match bounds {
        None => Ok(([-1.0; 3], [1.0; 3])),
        Some(b) => MeshingOptions::domain_from(&b).map_err(|e| value_err(format!("bounds: {e}"))),
    }
}

/// `open=`: `None` / `False` (closed), `True` (the default threshold 0.35) or a threshold.
fn open_arg(v: Option<&Bound<'_, PyAny>>) -> PyResult<Option<f64>> {
    let Some(o) = v else { return Ok(None) };
    if o.is_none() {
        return Ok(None);
    }
    if o.is_instance_of::<PyBool>() {
        return Ok(o.extract::<bool>()?.then_some(DEFAULT_OPEN));
    }
    Ok(Some(o.extract::<f64>()?))
}

/// Checks an open-surface threshold as `ponq-infer` / `ponq-mesh` do.
fn check_open(open: Option<f64>) -> PyResult<()> {
    if let Some(t) = open {
        MeshingOptions::check_open_threshold(t).map_err(|e| value_err(format!("open: {e}")))?;
    }
    Ok(())
}

// ---------------------------------------------------------------------------------------------
// Arrays out.

fn vec3_out<'py>(py: Python<'py>, v: &[[f64; 3]]) -> PyResult<Bound<'py, PyAny>> {
    let flat: Vec<f64> = v.iter().flatten().copied().collect();
    Ok(PyArray1::from_vec(py, flat)
        .reshape([v.len(), 3])?
        .into_any())
}

fn faces_out<'py>(py: Python<'py>, f: &[[u32; 3]]) -> PyResult<Bound<'py, PyAny>> {
    let flat: Vec<i64> = f.iter().flatten().map(|&i| i64::from(i)).collect();
    Ok(PyArray1::from_vec(py, flat)
        .reshape([f.len(), 3])?
        .into_any())
}

fn mesh_out<'py>(py: Python<'py>, m: &TriMesh) -> PyResult<Vec<Bound<'py, PyAny>>> {
    Ok(vec![vec3_out(py, &m.vertices)?, faces_out(py, &m.faces)?])
}

/// The PoNQ as a dict of float64 arrays `points`, `normals`, `quadrics` (M, 4, 4), `vstars`.
fn ponq_out<'py>(py: Python<'py>, p: &Ponq) -> PyResult<Bound<'py, PyAny>> {
    let d = PyDict::new(py);
    d.set_item("points", vec3_out(py, &p.points)?)?;
    d.set_item("normals", vec3_out(py, &p.normals)?)?;
    let mut q = Vec::with_capacity(16 * p.len());
    for m in p.quadrics.iter().map(Quadric::to_matrix4) {
        for r in 0..4 {
            for c in 0..4 {
                q.push(m[(r, c)]);
            }
        }
    }
    d.set_item(
        "quadrics",
        PyArray1::from_vec(py, q).reshape([p.len(), 4, 4])?,
    )?;
    d.set_item("vstars", vec3_out(py, &p.vstars())?)?;
    Ok(d.into_any())
}

fn tuple<'py>(py: Python<'py>, items: Vec<Bound<'py, PyAny>>) -> PyResult<Bound<'py, PyTuple>> {
    PyTuple::new(py, items)
}

/// Whether a mesh passes the programs' check: a closed mesh must be valid, an open surface
/// needs no self-intersection and no non-manifold edge.
fn passes(r: &ValidityReport, open: bool) -> bool {
    if open {
        r.self_intersections == 0 && r.nonmanifold_edges == 0
    } else {
        r.is_valid()
    }
}

fn warn_invalid(py: Python<'_>, r: Option<&ValidityReport>, open: bool) -> PyResult<()> {
    match r {
        Some(r) if !passes(r, open) => warn(
            py,
            "RuntimeWarning",
            &format!("the output mesh failed the validity check: {r}"),
        ),
        _ => Ok(()),
    }
}

// ---------------------------------------------------------------------------------------------
// The network, loaded once per model.

/// The network of `model` (a `.bpk` file) or the shipped one, loaded once and kept.
fn network(model: Option<&Path>, dev: &Device) -> anyhow::Result<(PonqNet, PonqNetConfig)> {
    static NETS: OnceLock<Mutex<HashMap<String, (PonqNet, PonqNetConfig)>>> = OnceLock::new();
    let key = match model {
        Some(p) => format!(
            "file:{}",
            std::fs::canonicalize(p)
                .unwrap_or_else(|_| p.to_path_buf())
                .display()
        ),
        None => format!("shipped:{:?}", std::env::var_os("PONQ_MODEL")),
    };
    let cache = NETS.get_or_init(Default::default);
    if let Some(n) = cache.lock().unwrap_or_else(|e| e.into_inner()).get(&key) {
        return Ok(n.clone());
    }
    let loaded = match model {
        Some(p) => ponq_model::weights::load(p, dev)?,
        None => ponq_infer::shipped::load(dev)?,
    };
    cache
        .lock()
        .unwrap_or_else(|e| e.into_inner())
        .insert(key, loaded.clone());
    Ok(loaded)
}

// ---------------------------------------------------------------------------------------------
// The functions.

/// Reconstructs a mesh from a signed distance grid with the PoNQ network: what the
/// ``ponq-infer`` program does with the same options (the same mesh, bit for bit).
///
/// Args:
///     sdf: 3D array (nx, ny, nz) of signed distances, negative inside, in the units of
///         ``bounds``; any float dtype, C or Fortran order (a NumPy array, or anything
///         ``numpy.asarray`` takes, e.g. ``tensor.numpy()``). Node (i, j, k) is at
///         ``lo + (i, j, k) * h``; the cells must be cubes. At least 2 nodes per axis.
///     bounds: the box spanned by the grid nodes, 6 floats
///         ``(xmin, ymin, zmin, xmax, ymax, zmax)``; default ``[-1, 1]^3``.
///     model: path of network weights (a ``.bpk`` file with its ``.json`` config beside it);
///         default: the shipped model (``$PONQ_MODEL`` if set). Loaded once and kept.
///     lite: PoNQ-lite: one point per cell (fewer vertices, the same sharp features).
///     coarsen: merge 2x2x2 blocks of cells this many times (implies ``lite``).
///     merge_smooth: adaptive PoNQ-lite: merge the points of each cell whose predicted
///         normals agree within this many degrees (0 to 180); ``None`` or 0 keeps every point.
///         Ignored with ``lite`` / ``coarsen``.
///     open: open surface: ``True`` (threshold 0.35) or a threshold in [0, 1] on the quadric
///         anisotropy; triangles away from sharp, planar-like quadrics are dropped and the
///         output has a boundary. ``None`` / ``False``: closed output.
///     refine: ``"auto"`` (refine the PoNQ against the grid's exact distances when the grid
///         passes a check of a true signed distance), ``"on"`` or ``"off"``. Not with
///         ``open``; ``"on"`` not with ``lite`` / ``coarsen``.
///     threads: worker threads (a pool of that size for this call); default all cores.
///     return_ponq: also return the PoNQ that was meshed (in the grid's coordinates).
///     check: check the output's validity (closed, oriented, manifold, no
///         self-intersection) as the program does; a failure gives a ``RuntimeWarning``.
///
/// Returns:
///     ``(vertices, faces)``: float64 (V, 3) in the coordinates of ``bounds``, int64 (F, 3)
///     (0-based, counter-clockwise seen from outside). With ``return_ponq=True`` a third
///     element: a dict of float64 arrays ``points`` (M, 3), ``normals`` (M, 3),
///     ``quadrics`` (M, 4, 4) (``[[A, -b], [-b^T, c]]``) and ``vstars`` (M, 3).
///     When the network keeps no cell the mesh is empty and a ``UserWarning`` says so.
///
/// Raises:
///     ValueError: a bad input (not rank 3, NaN or inf, fewer than 2 nodes per axis,
///         non-cubic cells, no sign change, a bad option), with the program's message.
///     RuntimeError: a failure of the computation.
#[pyfunction]
#[pyo3(
    signature = (sdf, *, bounds=None, model=None, lite=false, coarsen=0, merge_smooth=Some(ponq_infer::reconstruct::DEFAULT_MERGE_SMOOTH_DEG), open=None, refine="auto", threads=None, return_ponq=false, check=true),
    text_signature = "(sdf, *, bounds=None, model=None, lite=False, coarsen=0, merge_smooth=15.0, open=None, refine='auto', threads=None, return_ponq=False, check=True)"
)]
#[allow(clippy::too_many_arguments)]
fn infer<'py>(
    py: Python<'py>,
    sdf: &Bound<'py, PyAny>,
    bounds: Option<Vec<f64>>,
    model: Option<PathBuf>,
    lite: bool,
    coarsen: u32,
    merge_smooth: Option<f64>,
    open: Option<Bound<'py, PyAny>>,
    refine: &str,
    threads: Option<usize>,
    return_ponq: bool,
    check: bool,
) -> PyResult<Bound<'py, PyTuple>> {
    if threads == Some(0) {
        return Err(value_err("threads must be at least 1"));
    }
    let open = open_arg(open.as_ref())?;
    check_open(open)?;
    let merge_smooth = merge_smooth.unwrap_or(0.0);
    if !(0.0..=180.0).contains(&merge_smooth) {
        return Err(value_err(format!(
            "merge_smooth takes an angle in [0, 180] degrees, got {merge_smooth}"
        )));
    }
    let refine: RefineMode = refine
        .parse()
        .map_err(|e| value_err(format!("invalid value '{refine}' for refine: {e}")))?;
    let bounds = domain(bounds)?;
    let grid = grid3(sdf)?;
    if (lite || coarsen > 0) && refine == RefineMode::On {
        return Err(value_err(
            "refine='on' works on the full PoNQ: not with lite or coarsen",
        ));
    }
    let opts = InferOptions {
        bounds,
        lite,
        coarsen,
        merge_smooth: (merge_smooth > 0.0).then_some(merge_smooth),
        open,
        refine: if lite || coarsen > 0 {
            RefineMode::Off
        } else {
            refine
        },
        ..Default::default()
    };
    let (res, report) = run(py, threads, move || {
        // The checks of `predict`, first, so that their errors are input errors.
        Frame::of(&grid, opts.bounds).map_err(|e| Failure::Value(format!("{e:#}")))?;
        let (min, max) = grid
            .data
            .iter()
            .fold((f64::MAX, f64::MIN), |(a, b), &v| (a.min(v), b.max(v)));
        if !(min < 0.0 && max > 0.0) {
            return bad(format!(
                "the SDF has no sign change (values in [{min}, {max}]): the surface is empty; nothing to mesh"
            ));
        }
        let dev = ponq_model::backend::cpu();
        let (net, cfg) = network(model.as_deref(), &dev)?;
        let p = predict(&net, cfg.encoder_layers, &grid, &opts, &dev, |_, _| {})?;
        let res = finish(&p, &opts)?;
        let report = (check && !res.mesh.faces.is_empty()).then(|| validity::check(&res.mesh));
        Ok((res, report))
    })?;
    if let Some(m) = &res.message {
        warn(py, "UserWarning", m)?;
    }
    warn_invalid(py, report.as_ref(), open.is_some())?;
    let mut out = mesh_out(py, &res.mesh)?;
    if return_ponq {
        out.push(ponq_out(py, &res.ponq)?);
    }
    tuple(py, out)
}

/// Meshes a PoNQ (points, normals, quadrics): what the ``ponq-mesh`` program does with an
/// ``.npz`` holding these arrays and the same options.
///
/// Args:
///     points: (M, 3) point positions, in the frame of the grid domain (``bounds``).
///     normals: (M, 3) normals.
///     quadrics: (M, 4, 4) quadric matrices ``[[A, -b], [-b^T, c]]`` (symmetrised).
///     vstars: optional (M, 3) QEM-optimal vertices; solved from the quadrics when absent.
///     grid_scale: the resolution N of the grid the PoNQ was made on (cells per side of
///         ``bounds``, >= 1): sets the face-score weight, the small-tet threshold and the
///         cells of ``lite`` / ``merge_smooth``. Required.
///     bounds: the domain box, 6 floats ``(xmin, ymin, zmin, xmax, ymax, zmax)``; default
///         ``[-1, 1]^3``.
///     lite: PoNQ-lite: merge the points of each grid cell (found from the point
///         positions) into one, quadrics summed.
///     coarsen: with ``lite``, merge 2x2x2 blocks of cells this many more times.
///     merge_smooth: adaptive PoNQ-lite: merge the points of each cell whose normals agree
///         within this many degrees; keep the other cells' points. Not with ``lite``.
///     open: open surface: ``True`` (threshold 0.35) or a threshold in [0, 1]: drop the
///         triangles whose three vertices all have quadric anisotropy above it.
///     crease_flips: flip quadrilateral diagonals onto the sharp edges the quadrics
///         describe, and flat caps (near-180-degree triangles on flat parts) away
///         (``False``: the program's ``--no-crease-flips``).
///     threads: worker threads (a pool of that size for this call); default all cores. The
///         mesh is the same for any count.
///     check: check the output's validity as the program does; a failure gives a
///         ``RuntimeWarning``.
///
/// Returns:
///     ``(vertices, faces)``: float64 (V, 3), int64 (F, 3).
///
/// Raises:
///     ValueError: wrong shapes, arrays disagreeing on M, non-finite values, a bad option.
#[pyfunction]
#[pyo3(
    signature = (points, normals, quadrics, *, vstars=None, grid_scale, bounds=None, lite=false, coarsen=0, merge_smooth=None, open=None, crease_flips=true, threads=None, check=true),
    text_signature = "(points, normals, quadrics, *, vstars=None, grid_scale, bounds=None, lite=False, coarsen=0, merge_smooth=None, open=None, crease_flips=True, threads=None, check=True)"
)]
#[allow(clippy::too_many_arguments)]
fn mesh<'py>(
    py: Python<'py>,
    points: &Bound<'py, PyAny>,
    normals: &Bound<'py, PyAny>,
    quadrics: &Bound<'py, PyAny>,
    vstars: Option<Bound<'py, PyAny>>,
    grid_scale: f64,
    bounds: Option<Vec<f64>>,
    lite: bool,
    coarsen: u32,
    merge_smooth: Option<f64>,
    open: Option<Bound<'py, PyAny>>,
    crease_flips: bool,
    threads: Option<usize>,
    check: bool,
) -> PyResult<Bound<'py, PyTuple>> {
    if threads == Some(0) {
        return Err(value_err("threads must be at least 1"));
    }
    let open = open_arg(open.as_ref())?;
    check_open(open)?;
    if coarsen > 0 && !lite {
        return Err(value_err("coarsen needs lite=True"));
    }
    if merge_smooth.is_some() && lite {
        return Err(value_err(
            "merge_smooth and lite exclude each other (lite merges every cell)",
        ));
    }
    let domain = domain(bounds)?;
    let ponq = ponq_in(points, normals, quadrics, vstars.as_ref())?;
    if !(grid_scale >= 1.0 && grid_scale.is_finite()) {
        return Err(value_err(format!(
            "grid_scale must be >= 1, got {grid_scale}"
        )));
    }
    let (mesh, report) = run(py, threads, move || {
        let (ponq, grid_scale) =
            simplify_by_position(&ponq, grid_scale, domain, lite, coarsen, merge_smooth)?;
        let opts = MeshingOptions {
            grid_scale,
            domain,
            open_threshold: open,
            align_creases: crease_flips,
            flat_caps: crease_flips,
            ..Default::default()
        };
        let out = mesh_ponq(&ponq, &opts)?;
        let report = check.then(|| validity::check(&out.mesh));
        Ok((out, report))
    })?;
    if let Some(m) = &mesh.message {
        warn(py, "UserWarning", m)?;
    }
    warn_invalid(py, report.as_ref(), open.is_some())?;
    tuple(py, mesh_out(py, &mesh.mesh)?)
}

/// A PoNQ from arrays, checked as `ponq_mesh::io::npz` checks a file.
fn ponq_in(
    points: &Bound<'_, PyAny>,
    normals: &Bound<'_, PyAny>,
    quadrics: &Bound<'_, PyAny>,
    vstars: Option<&Bound<'_, PyAny>>,
) -> PyResult<Ponq> {
    let shape_err = |name: &str, tail: &str, s: &[usize]| {
        value_err(format!(
            "array '{name}': expected shape (M, {tail}), found {}",
            shape_str(s)
        ))
    };
    let (ps, pd) = floats(points, "points")?;
    let (ns, nd) = floats(normals, "normals")?;
    let (qs, qd) = floats(quadrics, "quadrics")?;
    let vs = match vstars {
        Some(v) if !v.is_none() => Some(floats(v, "vstars")?),
        _ => None,
    };
    let p = rows3(&ps, &pd, "points", "M")?;
    let n = rows3(&ns, &nd, "normals", "M")?;
    if !(qs.len() == 3 && qs[1] == 4 && qs[2] == 4) {
        return Err(shape_err("quadrics", "4, 4", &qs));
    }
    let v = match &vs {
        Some((s, d)) => Some(rows3(s, d, "vstars", "M")?),
        None => None,
    };
    let mut ms = vec![
        ("points", p.len()),
        ("normals", n.len()),
        ("quadrics", qs[0]),
    ];
    if let Some(v) = &v {
        ms.push(("vstars", v.len()));
    }
    if ms.iter().any(|&(_, k)| k != p.len()) {
        let list = ms
            .iter()
            .map(|(n, k)| format!("{n} has {k}"))
            .collect::<Vec<_>>()
            .join(", ");
        return Err(value_err(format!(
            "the arrays disagree on the number of points M: {list}"
        )));
    }
    let q = qd
        .chunks_exact(16)
        .map(|c| Quadric::from_matrix4(&Matrix4::from_row_slice(c)))
        .collect();
    Ponq::new(p, n, q, v).map_err(|e| match e {
        ponq_mesh::Error::InvalidInput(m) => value_err(m),
        other => value_err(other.to_string()),
    })
}

/// The exact signed distance grid of a triangle mesh: what ``ponq-prep sdf`` writes.
///
/// The mesh is first normalised to the [-1, 1] convention (bounding-box centre at the
/// origin, bounding-box diagonal 2) unless ``normalize=False``. The grid has
/// ``(res+1)^3`` nodes spanning [-1, 1]^3, node (i, j, k) at ``-1 + 2 (i, j, k) / res``
/// (C order: x slowest, z fastest); values are exact distances to the triangles, negative
/// inside (the sign of the generalised winding number; an open mesh gives a
/// ``UserWarning``). Distances are computed in float64 and rounded to float32, so the
/// array equals the ``.npy`` file the program writes, value for value.
///
/// Args:
///     vertices: (V, 3) vertex positions (any real dtype).
///     faces: (F, 3) vertex indices (0-based, any integer dtype).
///     res: cells per axis, 2 to 1024 (``res + 1`` nodes per axis).
///     normalize: normalise the mesh first (``False``: the program's ``--no-normalize``;
///         the mesh should then lie in [-1, 1]^3).
///     return_transform: also return the normalisation, ``centre`` (3,) and ``scale``:
///         grid coordinates are ``(x - centre) * scale``, so a mesh reconstructed from the
///         grid maps back to the input's coordinates by ``v / scale + centre``
///         (``normalize=False``: centre 0, scale 1).
///     threads: worker threads (a pool of that size for this call); default all cores.
///
/// Returns:
///     float32 array (res+1, res+1, res+1), or ``(grid, centre, scale)`` with
///     ``return_transform=True``.
#[pyfunction]
#[pyo3(
    signature = (vertices, faces, res, *, normalize=true, return_transform=false, threads=None),
    text_signature = "(vertices, faces, res, *, normalize=True, return_transform=False, threads=None)"
)]
fn sdf<'py>(
    py: Python<'py>,
    vertices: &Bound<'py, PyAny>,
    faces: &Bound<'py, PyAny>,
    res: usize,
    normalize: bool,
    return_transform: bool,
    threads: Option<usize>,
) -> PyResult<Bound<'py, PyAny>> {
    if !(2..=1024).contains(&res) {
        return Err(value_err(format!("res must be in 2..=1024, got {res}")));
    }
    let mesh = mesh_in(vertices, faces, "")?;
    if mesh.faces.is_empty() {
        return Err(value_err("the mesh has no triangle"));
    }
    let (grid, norm, open_report) = run(py, threads, move || {
        let (mesh, norm) = if normalize {
            let n = Normalization::of(&mesh)
                .map_err(|e| Failure::Value(format!("normalising the mesh: {e}")))?;
            (n.apply_mesh(&mesh), n)
        } else {
            (
                mesh,
                Normalization {
                    centre: [0.0; 3],
                    scale: 1.0,
                },
            )
        };
        let grid = ponq_data::sdf::signed_distance_grid(&mesh, res, |_| {})
            .map_err(|e| Failure::from(anyhow::Error::from(e).context("computing the SDF")))?;
        let open = grid
            .open
            .then(|| validity::check_topology(&mesh).to_string());
        Ok((grid, norm, open))
    })?;
    if let Some(report) = open_report {
        warn(
            py,
            "UserWarning",
            &format!(
                "the mesh is not a closed, consistently oriented surface ({report}); the sign \
                 follows the generalised winding number (inside where |w| > 1/2) and may be \
                 meaningless away from the surface"
            ),
        )?;
    }
    let n1 = res + 1;
    let g = PyArray1::from_vec(py, grid.values).reshape([n1, n1, n1])?;
    if return_transform {
        let centre = PyArray1::from_vec(py, norm.centre.to_vec());
        Ok(tuple(
            py,
            vec![
                g.into_any(),
                centre.into_any(),
                norm.scale.into_pyobject(py)?.into_any(),
            ],
        )?
        .into_any())
    } else {
        Ok(g.into_any())
    }
}

/// Area-weighted random points on a mesh's surface with their face normals (the sampling of
/// the metrics and of ``ponq-fit``), reproducible for a given seed.
///
/// Args:
///     vertices: (V, 3) vertex positions.
///     faces: (F, 3) vertex indices (0-based).
///     n: number of samples.
///     seed: the random seed.
///
/// Returns:
///     ``(points, normals)``: float64 (n, 3) each, normals of unit length (zero on a
///     degenerate face).
#[pyfunction]
#[pyo3(
    signature = (vertices, faces, n, *, seed=0),
    text_signature = "(vertices, faces, n, *, seed=0)"
)]
fn sample<'py>(
    py: Python<'py>,
    vertices: &Bound<'py, PyAny>,
    faces: &Bound<'py, PyAny>,
    n: usize,
    seed: u64,
) -> PyResult<Bound<'py, PyTuple>> {
    let mesh = mesh_in(vertices, faces, "")?;
    if mesh.faces.is_empty() {
        return Err(value_err("the mesh has no triangle"));
    }
    let s = run(py, None, move || {
        let s = ponq_mesh::sampling::sample_surface(&mesh, n, seed);
        if n > 0 && s.points.is_empty() {
            return bad("the mesh has no area to sample");
        }
        Ok(s)
    })?;
    tuple(
        py,
        vec![vec3_out(py, &s.points)?, vec3_out(py, &s.normals)?],
    )
}

/// Fits a PoNQ to a mesh by optimisation (no network) and meshes it: what the ``ponq-fit``
/// program does (points optimised with Adam on the Chamfer distance to surface samples,
/// then normals and quadrics per Voronoi cell).
///
/// Args:
///     vertices: (V, 3) vertex positions.
///     faces: (F, 3) vertex indices (0-based).
///     grid: grid resolution (2 to 1024): initial points at the corners of the occupied
///         cells of a grid^3 grid over the normalised shape; also the meshing scale.
///     iterations: Adam iterations.
///     samples: surface samples (default ``100000 * (grid / 32)^2``).
///     seed: seed of the sampling and mini-batches.
///     lite: PoNQ-lite: one point per grid cell.
///     open: open surface: ``True`` (threshold 0.35) or a threshold in [0, 1] (boundary
///         samples with rotated normals, anisotropic triangles dropped).
///     normalized: return the mesh in the normalised [-1, 1] frame (bounding-box centre 0,
///         diagonal 2) instead of the input's coordinates (the default, the program's
///         ``--original-frame``).
///     return_ponq: also return the fitted PoNQ as a dict (``points``, ``normals``,
///         ``quadrics``, ``vstars``), in the [-1, 1] frame, as ``--save-ponq`` writes it
///         (``ponq.mesh(..., grid_scale=grid)`` meshes it again).
///     threads: worker threads (a pool of that size for this call); default all cores.
///     check: check the output's validity as the program does; a failure gives a
///         ``RuntimeWarning``.
///
/// Returns:
///     ``(vertices, faces)`` (and the PoNQ dict with ``return_ponq=True``).
#[pyfunction]
#[pyo3(
    signature = (vertices, faces, *, grid=32, iterations=400, samples=None, seed=0, lite=false, open=None, normalized=false, return_ponq=false, threads=None, check=true),
    text_signature = "(vertices, faces, *, grid=32, iterations=400, samples=None, seed=0, lite=False, open=None, normalized=False, return_ponq=False, threads=None, check=True)"
)]
#[allow(clippy::too_many_arguments)]
fn fit<'py>(
    py: Python<'py>,
    vertices: &Bound<'py, PyAny>,
    faces: &Bound<'py, PyAny>,
    grid: usize,
    iterations: usize,
    samples: Option<usize>,
    seed: u64,
    lite: bool,
    open: Option<Bound<'py, PyAny>>,
    normalized: bool,
    return_ponq: bool,
    threads: Option<usize>,
    check: bool,
) -> PyResult<Bound<'py, PyTuple>> {
    let open = open_arg(open.as_ref())?;
    if let Some(t) = open
        && !(0.0..=1.0).contains(&t)
    {
        return Err(value_err(format!(
            "open threshold must be in [0, 1], got {t}"
        )));
    }
    let mesh = mesh_in(vertices, faces, "")?;
    let opts = ponq_data::fit::FitOptions {
        grid,
        samples,
        iterations,
        open,
        lite,
        seed,
        ..Default::default()
    };
    let (fitted, out, report) = run(py, threads, move || {
        let fitted = ponq_data::fit::fit_mesh(&mesh, &opts, |_| {})?;
        let out = if normalized {
            fitted.meshing.mesh.clone()
        } else {
            fitted.normalization.invert_mesh(&fitted.meshing.mesh)
        };
        let report = check.then(|| validity::check(&fitted.meshing.mesh));
        Ok((fitted, out, report))
    })?;
    if let Some(m) = &fitted.meshing.message {
        warn(py, "UserWarning", m)?;
    }
    warn_invalid(py, report.as_ref(), open.is_some())?;
    let mut items = mesh_out(py, &out)?;
    if return_ponq {
        items.push(ponq_out(py, &fitted.ponq)?);
    }
    tuple(py, items)
}

/// The paper's reconstruction metrics of a predicted mesh against a ground truth, both in
/// the ground truth's coordinates: what ``ponq-eval compare PRED GT --pred-frame gt``
/// computes (both meshes put at the ground truth's unit bounding-box diagonal, ``samples``
/// area-weighted surface samples and as many sharp-edge samples on each).
///
/// Args:
///     pred_v, pred_f: the predicted mesh, (V, 3) vertices and (F, 3) faces.
///     gt_v, gt_f: the ground-truth mesh.
///     samples: surface and sharp-edge samples per mesh (> 0).
///     seed: sampling seed.
///     sharp_angle: dihedral angle in degrees (0 to 180, exclusive) above which an edge is
///         sharp for ECD / EF1.
///     threads: worker threads (a pool of that size for this call); default all cores.
///
/// Returns:
///     dict with the keys of ``ponq-eval compare --json``: ``cd_x1e5`` (Chamfer distance,
///     squared, both ways, x 1e5), ``f1`` (F-score at 0.003), ``nc`` (normal consistency),
///     ``ecd_x1e2`` (edge Chamfer distance x 1e2), ``ef1`` (edge F-score at 0.005),
///     ``watertight`` (the prediction is closed, oriented, manifold, free of
///     self-intersections), ``vertices``, ``faces`` (counts of the prediction). A metric
///     that cannot be computed (an empty prediction) is ``inf`` (distances) or 0 (scores).
#[pyfunction]
#[pyo3(
    signature = (pred_v, pred_f, gt_v, gt_f, *, samples=100_000, seed=0, sharp_angle=30.0, threads=None),
    text_signature = "(pred_v, pred_f, gt_v, gt_f, *, samples=100000, seed=0, sharp_angle=30.0, threads=None)"
)]
#[allow(clippy::too_many_arguments)]
fn metrics<'py>(
    py: Python<'py>,
    pred_v: &Bound<'py, PyAny>,
    pred_f: &Bound<'py, PyAny>,
    gt_v: &Bound<'py, PyAny>,
    gt_f: &Bound<'py, PyAny>,
    samples: usize,
    seed: u64,
    sharp_angle: f64,
    threads: Option<usize>,
) -> PyResult<Bound<'py, PyDict>> {
    if samples == 0 {
        return Err(value_err("samples must be positive"));
    }
    if !(sharp_angle > 0.0 && sharp_angle < 180.0) {
        return Err(value_err(format!(
            "sharp_angle must be in (0, 180) degrees, got {sharp_angle}"
        )));
    }
    let p = mesh_in(pred_v, pred_f, "pred_")?;
    let g = mesh_in(gt_v, gt_f, "gt_")?;
    if g.faces.is_empty() {
        return Err(value_err("the ground truth has no face"));
    }
    let m = run(py, threads, move || {
        let watertight = validity::check(&p).is_valid();
        let m = compare(
            &p,
            &g,
            &MetricOptions {
                surface_samples: samples,
                edge_samples: samples,
                seed,
                sharp_angle_deg: sharp_angle,
                check_validity: false,
                ..Default::default()
            },
        );
        Ok(ponq_mesh::metrics::Metrics {
            watertight: Some(watertight),
            ..m
        })
    })?;
    let d = PyDict::new(py);
    d.set_item("cd_x1e5", m.cd_x1e5)?;
    d.set_item("f1", m.f1)?;
    d.set_item("nc", m.nc)?;
    d.set_item("ecd_x1e2", m.ecd_x1e2)?;
    d.set_item("ef1", m.ef1)?;
    d.set_item("watertight", m.watertight.unwrap_or(false))?;
    d.set_item("vertices", m.n_vertices)?;
    d.set_item("faces", m.n_faces)?;
    Ok(d)
}

/// Checks a mesh with exact predicates: what ``ponq-eval check`` reports.
///
/// Args:
///     vertices: (V, 3) vertex positions.
///     faces: (F, 3) vertex indices (0-based).
///
/// Returns:
///     dict: ``valid`` (closed, oriented, manifold, no degenerate face, no
///     self-intersection, no coincident vertices), ``closed`` (every edge has two faces),
///     ``oriented`` (every directed edge once, its twin once), ``manifold`` (closed and one
///     fan around every vertex), ``self_intersecting`` (bool), and the counts
///     ``boundary_edges``, ``nonmanifold_edges``, ``nonmanifold_vertices``,
///     ``degenerate_faces``, ``unreferenced_vertices`` (not a defect),
///     ``self_intersections`` (intersecting face pairs), ``coincident_vertices``; and
///     ``summary``, the program's one-line report. An empty mesh is valid.
#[pyfunction]
#[pyo3(signature = (vertices, faces), text_signature = "(vertices, faces)")]
fn check<'py>(
    py: Python<'py>,
    vertices: &Bound<'py, PyAny>,
    faces: &Bound<'py, PyAny>,
) -> PyResult<Bound<'py, PyDict>> {
    let mesh = mesh_in(vertices, faces, "")?;
    let r = run(py, None, move || Ok(validity::check(&mesh)))?;
    let d = PyDict::new(py);
    d.set_item("valid", r.is_valid())?;
    d.set_item("closed", r.closed)?;
    d.set_item("oriented", r.oriented)?;
    d.set_item("manifold", r.manifold)?;
    d.set_item("self_intersecting", r.self_intersections > 0)?;
    d.set_item("boundary_edges", r.boundary_edges)?;
    d.set_item("nonmanifold_edges", r.nonmanifold_edges)?;
    d.set_item("nonmanifold_vertices", r.nonmanifold_vertices)?;
    d.set_item("degenerate_faces", r.degenerate_faces)?;
    d.set_item("unreferenced_vertices", r.unreferenced_vertices)?;
    d.set_item("self_intersections", r.self_intersections)?;
    d.set_item("coincident_vertices", r.coincident_vertices)?;
    d.set_item("summary", r.to_string())?;
    Ok(d)
}

/// Marching cubes on a grid of signed values (the baseline ``ponq-eval mc`` runs): the
/// zero level set, faces oriented towards positive values (outside), vertices on grid
/// edges shared between cubes (no crack).
///
/// Args:
///     sdf: 3D array (nx, ny, nz), negative inside; any float dtype, any memory order.
///     bounds: the box spanned by the grid nodes, 6 floats; default ``[-1, 1]^3``.
///
/// Returns:
///     ``(vertices, faces)``: float64 (V, 3), int64 (F, 3).
#[pyfunction]
#[pyo3(signature = (sdf, *, bounds=None), text_signature = "(sdf, *, bounds=None)")]
fn marching_cubes<'py>(
    py: Python<'py>,
    sdf: &Bound<'py, PyAny>,
    bounds: Option<Vec<f64>>,
) -> PyResult<Bound<'py, PyTuple>> {
    let (lo, hi) = domain(bounds)?;
    let g = grid3(sdf)?;
    let m = run(py, None, move || {
        Ok(ponq_mesh::marching_cubes::marching_cubes(
            &g.data, g.dims, lo, hi,
        )?)
    })?;
    tuple(py, mesh_out(py, &m)?)
}

/// PoNQ-rs for Python: sharp, watertight meshes from signed distance grids with the PoNQ
/// network (CVPR 2024), and the tools around it, on NumPy arrays.
///
/// Functions: ``infer`` (SDF grid -> mesh, the ``ponq-infer`` program), ``mesh`` (PoNQ
/// arrays -> mesh, ``ponq-mesh``), ``sdf`` (mesh -> exact SDF grid, ``ponq-prep sdf``),
/// ``sample`` (surface samples), ``fit`` (mesh -> fitted PoNQ -> mesh, ``ponq-fit``),
/// ``metrics`` (``ponq-eval compare``), ``check`` (validity), ``marching_cubes``.
/// Meshes are ``(vertices float64 (V, 3), faces int64 (F, 3))``; inputs take any real
/// dtype and memory order. Every function releases the GIL while it works; bad input
/// raises ``ValueError`` with the programs' messages.
///
/// Example::
///
///     import numpy as np, ponq
///     g = np.linspace(-1, 1, 33)
///     x, y, z = np.meshgrid(g, g, g, indexing="ij")
///     sdf = np.maximum(np.abs(x), np.maximum(np.abs(y), np.abs(z))) - 0.6  # a cube
///     v, f = ponq.infer(sdf)          # bounds default to [-1, 1]^3
///     assert ponq.check(v, f)["valid"]
#[pymodule(name = "ponq")]
fn ponq_module(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add("__version__", env!("CARGO_PKG_VERSION"))?;
    m.add(
        "DEFAULT_MERGE_SMOOTH",
        ponq_infer::reconstruct::DEFAULT_MERGE_SMOOTH_DEG,
    )?;
    m.add_function(wrap_pyfunction!(infer, m)?)?;
    m.add_function(wrap_pyfunction!(mesh, m)?)?;
    m.add_function(wrap_pyfunction!(sdf, m)?)?;
    m.add_function(wrap_pyfunction!(sample, m)?)?;
    m.add_function(wrap_pyfunction!(fit, m)?)?;
    m.add_function(wrap_pyfunction!(metrics, m)?)?;
    m.add_function(wrap_pyfunction!(check, m)?)?;
    m.add_function(wrap_pyfunction!(marching_cubes, m)?)?;
    // maturin's `__init__.py` re-exports `*`: the list makes it take `__version__` too.
    m.add(
        "__all__",
        vec![
            "__version__",
            "DEFAULT_MERGE_SMOOTH",
            "infer",
            "mesh",
            "sdf",
            "sample",
            "fit",
            "metrics",
            "check",
            "marching_cubes",
        ],
    )?;
    Ok(())
}
