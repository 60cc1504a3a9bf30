//! Data from meshes: `ponq.sdf` (the exact signed distance grid, `ponq-prep sdf`),
//! `ponq.sample` (surface samples) and `ponq.fit` (optimisation PoNQ, `ponq-fit`).

use numpy::{PyArray1, PyArrayMethods};
use ponq_data::normalize::Normalization;
use ponq_mesh::validity;
use pyo3::prelude::*;
use pyo3::types::PyTuple;

use crate::arrays::{mesh_in, mesh_out, ponq_out, tuple, vec3_out};
use crate::errors::{Failure, bad, run, value_err, warn};
use crate::options::{open_arg, warn_invalid};

/// The exact signed distance grid of a triangle mesh: what ``ponq-prep sdf`` writes.
///
/// The mesh is first repaired (``repair=True``: vertices within 1e-4 of the diagonal welded,
/// degenerate and duplicate faces dropped, faces and parts oriented, holes closed, faces that
/// separate no inside from an outside removed; a clean mesh is used unchanged), then
/// normalised to the [-1, 1] convention (bounding-box centre at the origin, bounding-box
/// diagonal 2) unless ``normalize=False``. The grid has
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
///     repair: repair the mesh first (``False``: the program's ``--no-repair``, the mesh as
///         it is).
///     return_report: also return the defect report: a dict of what the repair found and
///         did (the keys of ``ponq-prep sdf --json``).
///     threads: worker threads (a pool of that size for this call); default all cores.
///
/// Returns:
///     float32 array (res+1, res+1, res+1); with ``return_transform=True`` followed by
///     ``centre`` and ``scale``, with ``return_report=True`` by the report, in a tuple.
#[pyfunction]
#[pyo3(
    signature = (vertices, faces, res, *, normalize=true, return_transform=false, repair=true, return_report=false, threads=None),
    text_signature = "(vertices, faces, res, *, normalize=True, return_transform=False, repair=True, return_report=False, threads=None)"
)]
#[allow(clippy::too_many_arguments)]
pub(crate) fn sdf<'py>(
    py: Python<'py>,
    vertices: &Bound<'py, PyAny>,
    faces: &Bound<'py, PyAny>,
    res: usize,
    normalize: bool,
    return_transform: bool,
    repair: bool,
    return_report: bool,
    threads: Option<usize>,
) -> PyResult<Bound<'py, PyAny>> {
    if !(2..=1024).contains(&res) {
        return Err(value_err(format!("res must be in 2..=1024, got {res}")));
    }
    let mesh = mesh_in(vertices, faces, "")?;
    if mesh.faces.is_empty() {
        return Err(value_err("the mesh has no triangle"));
    }
    if return_report && !repair {
        return Err(value_err("return_report needs repair=True"));
    }
    let (grid, norm, open_report, defects) = run(py, threads, move || {
        let repaired = if repair {
            Some(ponq_data::repair::repair_with_solid(
                &mesh,
                &ponq_data::repair::RepairOptions::default(),
            )?)
        } else {
            None
        };
        let source = repaired.as_ref().map_or(&mesh, |r| &r.mesh);
        let norm = if normalize {
            Normalization::of(source)
                .map_err(|e| Failure::Value(format!("normalising the mesh: {e}")))?
        } else {
            Normalization {
                centre: [0.0; 3],
                scale: 1.0,
            }
        };
        let mesh = norm.apply_mesh(source);
        let grid = match &repaired {
            Some(r) => r.grid(|m| norm.apply_mesh(m), res, |_| {}),
            None => ponq_data::sdf::signed_distance_grid(&mesh, res, |_| {}),
        }
        .map_err(|e| Failure::from(anyhow::Error::from(e).context("computing the SDF")))?;
        let defects = repaired.map(|r| r.report);
        let open = grid
            .open
            .then(|| validity::check_topology(&mesh).to_string());
        let defects = defects.map(|mut r| {
            if grid.open {
                r.ambiguous_node_share =
                    Some(grid.ambiguous_nodes as f64 / grid.values.len() as f64);
            }
            r
        });
        Ok((grid, norm, open, defects))
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
    if !return_transform && !return_report {
        return Ok(g.into_any());
    }
    let mut items = vec![g.into_any()];
    if return_transform {
        items.push(PyArray1::from_vec(py, norm.centre.to_vec()).into_any());
        items.push(norm.scale.into_pyobject(py)?.into_any());
    }
    if let Some(r) = defects.filter(|_| return_report) {
        items.push(report_dict(py, &r)?);
    }
    Ok(tuple(py, items)?.into_any())
}

/// A defect report as a dict (the keys of its JSON form; `None` for a check not run).
pub(crate) fn report_dict<'py>(
    py: Python<'py>,
    r: &ponq_data::repair::DefectReport,
) -> PyResult<Bound<'py, PyAny>> {
    let json = py.import("json")?;
    json.call_method1("loads", (r.to_json(),))
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
pub(crate) fn sample<'py>(
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
pub(crate) fn fit<'py>(
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
