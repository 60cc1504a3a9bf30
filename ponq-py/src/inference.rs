//! `ponq.infer`: the network on an SDF grid (the `ponq-infer` program).

use std::collections::HashMap;
use std::path::{Path, PathBuf};
use std::sync::{Mutex, OnceLock};

use burn::prelude::Device;
use ponq_infer::{Frame, infer as infer_grid};
use ponq_mesh::validity;
use ponq_model::{PonqNet, PonqNetConfig};
use pyo3::prelude::*;
use pyo3::types::PyTuple;

use crate::arrays::{colours_out, grid_colours, grid3, mesh_out, ponq_out, tuple};
use crate::errors::{Failure, run, value_err, warn};
use crate::options::{check_open, condition_options, infer_options, open_arg, warn_invalid};

/// The network of `model` (a `.bpk` file) or the shipped one, loaded once and kept.
pub(crate) fn network(
    model: Option<&Path>,
    dev: &Device,
) -> anyhow::Result<(PonqNet, PonqNetConfig)> {
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

/// Reconstructs a mesh from a signed distance grid with the PoNQ network: what the
/// ``ponq-infer`` program does with the same options (the same mesh, bit for bit).
///
/// Args:
///     sdf: 3D array (nx, ny, nz) of signed distances (negative inside, in the units of
///         ``bounds``), or any field whose ``level`` set is the surface: a distance in other
///         units (voxels, a normalised TSDF), inside positive, an occupancy or another
///         monotone function of a distance; its values are read into distances first, as
///         ``ponq-infer`` reads a grid (``level``, ``inside``, ``field``). Any float dtype, C or
///         Fortran order (a NumPy array, or anything ``numpy.asarray`` takes, e.g.
///         ``tensor.numpy()``). Node (i, j, k) is at ``lo + (i, j, k) * h``; the cells must be
///         cubes. At least 2 nodes per axis.
///     bounds: the box spanned by the grid nodes, 6 floats
///         ``(xmin, ymin, zmin, xmax, ymax, zmax)``; default ``[-1, 1]^3`` (with unequal node
///         counts: the longest axis over [-1, 1], the others centred, cubic cells).
///     level: the iso-level of the surface; default 0 (0.5 for a saturated field in [0, 1]
///         without a sign change at 0: an occupancy, with a ``UserWarning``).
///     inside: ``"auto"`` (the side the grid's boundary lies on is outside), ``"negative"``
///         or ``"positive"``.
///     field: ``"auto"`` (measured: rescaled or mapped into distances when it is not one, or
///         re-distanced to its zero set), ``"distance"`` (the values as distances in the
///         units of ``bounds``) or ``"redistance"`` (exact distances to its zero set). What
///         was done when the values are not used as they are comes as a ``UserWarning``.
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
///     colours: a colour per grid node, ``(nx, ny, nz, 3)``: floats in [0, 1] or bytes; each
///         output vertex gets the trilinear colour at its place, returned after the faces.
///     return_ponq: also return the PoNQ that was meshed (in the grid's coordinates).
///     check: check the output's validity (closed, oriented, manifold, no
///         self-intersection) as the program does; a failure gives a ``RuntimeWarning``.
///
/// Returns:
///     ``(vertices, faces)``: float64 (V, 3) in the coordinates of ``bounds``, int64 (F, 3)
///     (0-based, counter-clockwise seen from outside); with ``colours``, then float64 (V, 3)
///     colours in [0, 1]. With ``return_ponq=True`` a last element: a dict of float64 arrays ``points`` (M, 3), ``normals`` (M, 3),
///     ``quadrics`` (M, 4, 4) (``[[A, -b], [-b^T, c]]``) and ``vstars`` (M, 3).
///     When the network keeps no cell the mesh is empty and a ``UserWarning`` says so.
///
/// Raises:
///     ValueError: a bad input (not rank 3, NaN or inf, fewer than 2 nodes per axis,
///         non-cubic cells, no sign change, a bad option), with the program's message.
///     RuntimeError: a failure of the computation.
#[pyfunction]
#[pyo3(
    signature = (sdf, *, bounds=None, level=None, inside="auto", field="auto", colours=None, model=None, lite=false, coarsen=0, merge_smooth=Some(ponq_infer::reconstruct::DEFAULT_MERGE_SMOOTH_DEG), open=None, refine="auto", threads=None, return_ponq=false, check=true),
    text_signature = "(sdf, *, bounds=None, level=None, inside='auto', field='auto', colours=None, model=None, lite=False, coarsen=0, merge_smooth=15.0, open=None, refine='auto', threads=None, return_ponq=False, check=True)"
)]
#[allow(clippy::too_many_arguments)]
pub(crate) fn infer<'py>(
    py: Python<'py>,
    sdf: &Bound<'py, PyAny>,
    bounds: Option<Vec<f64>>,
    level: Option<f64>,
    inside: &str,
    field: &str,
    colours: Option<Bound<'py, PyAny>>,
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
    let condition = condition_options(level, inside, field)?;
    let opts = infer_options(bounds, lite, coarsen, merge_smooth, open, refine, condition)?;
    let grid = grid3(sdf)?;
    let rgb = match colours.as_ref().filter(|c| !c.is_none()) {
        Some(c) => Some(grid_colours(c, grid.dims)?),
        None => None,
    };
    let dims = grid.dims;
    let bounds = opts.bounds;
    let (res, report) = run(py, threads, move || {
        // The checks of `predict`, first, so that their errors are input errors.
        Frame::of(&grid, opts.bounds).map_err(|e| Failure::Value(format!("{e:#}")))?;
        let dev = ponq_model::backend::cpu();
        let (net, cfg) = network(model.as_deref(), &dev)?;
        let res = infer_grid(&net, cfg.encoder_layers, &grid, &opts, &dev, |_, _| {})?;
        let report = (check && !res.mesh.faces.is_empty()).then(|| validity::check(&res.mesh));
        Ok((res, report))
    })?;
    warn_conditioning(py, res.conditioning.as_ref())?;
    if let Some(m) = &res.message {
        warn(py, "UserWarning", m)?;
    }
    warn_invalid(py, report.as_ref(), open.is_some())?;
    let mut out = mesh_out(py, &res.mesh)?;
    if let Some(rgb) = &rgb {
        let frame = Frame::of_dims(dims, bounds).map_err(|e| value_err(format!("{e:#}")))?;
        let c = ponq_data::colour_transfer::grid_colours(
            rgb,
            dims,
            frame.lo,
            frame.h,
            &res.mesh.vertices,
        );
        out.push(colours_out(py, &c)?);
    }
    if return_ponq {
        out.push(ponq_out(py, &res.ponq)?);
    }
    tuple(py, out)
}

/// A `UserWarning` with what the conditioning did when the values were not used as they are
/// (the factor, the map, the level or the sign it chose), as `ponq-infer` prints it.
pub(crate) fn warn_conditioning(
    py: Python<'_>,
    c: Option<&ponq_data::condition::Conditioning>,
) -> PyResult<()> {
    if let Some(c) = c
        && (!c.notes.is_empty() || !c.is_identity())
    {
        warn(py, "UserWarning", &c.summary())?;
    }
    Ok(())
}
