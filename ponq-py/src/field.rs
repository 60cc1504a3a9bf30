//! `ponq.infer_field`: the network on a signed distance function (a neural field), evaluated
//! near its surface only (`ponq_infer::field`).

use std::path::PathBuf;

use numpy::{PyArray2, PyArrayMethods};
use ponq_infer::field::field_band_conditioned;
use ponq_infer::{finish, predict_band};
use ponq_mesh::validity;
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyTuple};

use crate::arrays::{mesh_out, tuple};
use crate::errors::{Failure, run, value_err, warn};
use crate::inference::{network, warn_conditioning};
use crate::options::{condition_options, infer_options, warn_invalid};

/// Reconstructs a mesh from a signed distance *function* with the PoNQ network, evaluating
/// it only where the surface can be: the grid of ``res`` cells per side over ``bounds`` is
/// never built. Blocks of nodes are tested at their centres, coarse to fine (as MISE and
/// SDFStudio do): a block whose value is farther from zero than the field can change over
/// it holds no surface and keeps its sign; the bricks of 8^3 nodes near the surface are
/// evaluated at every node. At 1024 cells per side that is 3-4% of the dense grid's billion
/// points. For a field that changes no faster than ``lipschitz`` (1 for a true
/// distance) the mesh is the dense grid's, bit for bit.
///
/// The field need not be a distance: as ``ponq.infer`` reads a grid, its values are read into
/// distances first (``level``, ``inside``, ``field``), measured from its first evaluations (a
/// probe grid of at most 33^3 points, then windows at the full resolution around the surface).
/// Where the evaluated bricks show the conditioned field changing faster than ``lipschitz``,
/// the bound is widened and the field evaluated again (``stats["lipschitz"]``).
///
/// Args:
///     f: a callable taking a float64 array (N, 3) of points and returning N signed
///         distances (negative inside; any array-like, e.g. a NumPy array). For a PyTorch
///         module: ``lambda p: net(torch.from_numpy(p).float()).detach().numpy().ravel()``.
///     res: cells per side (``res + 1`` nodes; node (i, j, k) at ``lo + (i, j, k) * h``,
///         ``h = (hi - lo) / res``).
///     bounds: the box of the grid, 6 floats ``(xmin, ymin, zmin, xmax, ymax, zmax)``; a cube
///         (the cells must be cubes); default ``[-1, 1]^3``.
///     level, inside, field: how the values are read, as in ``ponq.infer``.
///     colour: a callable taking the output's vertices, a float64 array (N, 3), and returning
///         their colours (N, 3) in [0, 1] (a colour field); called once, in batches of
///         ``batch`` points. The colours are returned after the faces.
///     lipschitz: how fast the conditioned field may change (distance per unit length); raise
///         it for a neural field that is not quite a distance (more points are evaluated); it
///         is widened where the evaluated bricks show faster slopes.
///     batch: the most points per call of ``f``.
///     model, lite, coarsen, merge_smooth, refine, threads, check: as in ``ponq.infer``.
///
/// Returns:
///     ``(vertices, faces, stats)``, or ``(vertices, faces, colours, stats)`` with ``colour``:
///     the mesh as ``ponq.infer`` returns it, and a dict with
///     ``calls`` (calls of ``f``), ``points`` (points evaluated), ``dense_points`` (the
///     grid's nodes), ``stored_bricks``, ``lipschitz`` (the bound the last pass used) and
///     ``field`` (how the values were read, a line).
///
/// Raises:
///     ValueError: bad options, a field without a sign change, ``f`` returning the wrong
///         number of values or a NaN.
///     Any exception ``f`` raises.
#[pyfunction]
#[pyo3(
    signature = (f, res, *, bounds=None, level=None, inside="auto", field="auto", colour=None, lipschitz=1.0, batch=65536, model=None, lite=false, coarsen=0, merge_smooth=Some(ponq_infer::reconstruct::DEFAULT_MERGE_SMOOTH_DEG), refine="auto", threads=None, check=true),
    text_signature = "(f, res, *, bounds=None, level=None, inside='auto', field='auto', colour=None, lipschitz=1.0, batch=65536, model=None, lite=False, coarsen=0, merge_smooth=15.0, refine='auto', threads=None, check=True)"
)]
#[allow(clippy::too_many_arguments)]
pub(crate) fn infer_field<'py>(
    py: Python<'py>,
    f: &Bound<'py, PyAny>,
    res: usize,
    bounds: Option<Vec<f64>>,
    level: Option<f64>,
    inside: &str,
    field: &str,
    colour: Option<Bound<'py, PyAny>>,
    lipschitz: f64,
    batch: usize,
    model: Option<PathBuf>,
    lite: bool,
    coarsen: u32,
    merge_smooth: Option<f64>,
    refine: &str,
    threads: Option<usize>,
    check: bool,
) -> PyResult<Bound<'py, PyTuple>> {
    if !(2..=4096).contains(&res) {
        return Err(value_err(format!("res must be in 2..=4096, got {res}")));
    }
    if batch == 0 {
        return Err(value_err("batch must be at least 1"));
    }
    if !f.is_callable() {
        return Err(value_err(
            "f must be a callable: points (N, 3) -> distances (N,)",
        ));
    }
    let colour = colour.filter(|c| !c.is_none());
    if colour.as_ref().is_some_and(|c| !c.is_callable()) {
        return Err(value_err(
            "colour must be a callable: points (N, 3) -> colours (N, 3) in [0, 1]",
        ));
    }
    let condition = condition_options(level, inside, field)?;
    let opts = infer_options(bounds, lite, coarsen, merge_smooth, None, refine, condition)?;
    let dev = ponq_model::backend::cpu();
    let (net, cfg) = network(model.as_deref(), &dev)
        .map_err(|e| pyo3::exceptions::PyRuntimeError::new_err(format!("{e:#}")))?;
    // The field is Python: the band is built holding the interpreter.
    let np = py.import("numpy")?;
    let mut py_error: Option<PyErr> = None;
    let built = field_band_conditioned(
        res,
        cfg.encoder_layers,
        &opts,
        lipschitz,
        batch,
        |pts| {
            let flat: Vec<f64> = pts.iter().flatten().copied().collect();
            let call = || -> PyResult<Vec<f64>> {
                let arr = numpy::PyArray1::from_vec(py, flat).reshape([pts.len(), 3])?;
                let arr: Bound<'_, PyArray2<f64>> = arr;
                let out = f.call1((arr,))?;
                let kw = PyDict::new(py);
                kw.set_item("dtype", "float64")?;
                let v = np.call_method("asarray", (out,), Some(&kw))?;
                let v = v.call_method0("ravel")?;
                v.extract::<Vec<f64>>()
            };
            call().map_err(|e| {
                py_error = Some(e);
                anyhow::anyhow!("the field raised an exception")
            })
        },
        |_| {},
    );
    let built = match built {
        Ok(x) => x,
        Err(e) => {
            return Err(match py_error {
                Some(pe) => pe,
                None => value_err(format!("{e:#}")),
            });
        }
    };
    let (band, stats, conditioning, bound) =
        (built.band, built.stats, built.conditioning, built.lipschitz);
    let summary = conditioning.summary();
    let (res_, report) = run(py, threads, move || {
        let mut p =
            predict_band(&net, cfg.encoder_layers, band, &opts, &dev, |_, _| {}).map_err(|e| {
                if e.to_string().contains("no sign change") {
                    Failure::Value(format!("{e:#}"))
                } else {
                    Failure::from(e)
                }
            })?;
        p.conditioning = Some(conditioning);
        let res = finish(&p, &opts)?;
        let report = (check && !res.mesh.faces.is_empty()).then(|| validity::check(&res.mesh));
        Ok((res, report))
    })?;
    warn_conditioning(py, res_.conditioning.as_ref())?;
    if let Some(m) = &res_.message {
        warn(py, "UserWarning", m)?;
    }
    warn_invalid(py, report.as_ref(), false)?;
    let mut out = mesh_out(py, &res_.mesh)?;
    if let Some(g) = &colour {
        out.push(call_colours(py, g, &res_.mesh.vertices, batch)?);
    }
    let d = PyDict::new(py);
    d.set_item("calls", stats.calls)?;
    d.set_item("points", stats.points)?;
    d.set_item("dense_points", stats.dense_points)?;
    d.set_item("stored_bricks", stats.stored_bricks)?;
    d.set_item("lipschitz", bound)?;
    d.set_item("field", summary)?;
    out.push(d.into_any());
    tuple(py, out)
}

/// The colour field `g` at `points`, called in batches of `batch`: a float64 `(N, 3)` array.
fn call_colours<'py>(
    py: Python<'py>,
    g: &Bound<'py, PyAny>,
    points: &[[f64; 3]],
    batch: usize,
) -> PyResult<Bound<'py, PyAny>> {
    let mut all: Vec<[f32; 3]> = Vec::with_capacity(points.len());
    for chunk in points.chunks(batch.max(1)) {
        let flat: Vec<f64> = chunk.iter().flatten().copied().collect();
        let arr = numpy::PyArray1::from_vec(py, flat).reshape([chunk.len(), 3])?;
        let got = g.call1((arr,))?;
        let (shape, data) = crate::arrays::floats(&got, "colour")?;
        if shape != [chunk.len(), 3] {
            return Err(value_err(format!(
                "colour returned an array of shape {shape:?} for {} points; expected ({}, 3)",
                chunk.len(),
                chunk.len()
            )));
        }
        if let Some(v) = data
            .iter()
            .find(|v| !(v.is_finite() && **v >= 0.0 && **v <= 1.0))
        {
            return Err(value_err(format!(
                "colour returned {v}: colours are in [0, 1]"
            )));
        }
        all.extend(
            data.chunks_exact(3)
                .map(|c| [c[0] as f32, c[1] as f32, c[2] as f32]),
        );
    }
    crate::arrays::colours_out(py, &all)
}
