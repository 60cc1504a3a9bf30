//! Meshing: `ponq.mesh` (a PoNQ's arrays, the `ponq-mesh` program) and
//! `ponq.marching_cubes` (the baseline).

use ponq_mesh::lite::simplify_by_position;
use ponq_mesh::mesher::{MeshingOptions, mesh_ponq};
use ponq_mesh::validity;
use pyo3::prelude::*;
use pyo3::types::PyTuple;

use crate::arrays::{grid3, mesh_out, ponq_in, tuple};
use crate::errors::{run, value_err, warn};
use crate::options::{check_open, domain, open_arg, warn_invalid};

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
pub(crate) fn mesh<'py>(
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
pub(crate) fn marching_cubes<'py>(
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
