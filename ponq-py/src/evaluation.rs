//! Evaluation: `ponq.metrics` (`ponq-eval compare`) and `ponq.check` (validity).

use ponq_mesh::metrics::{MetricOptions, compare};
use ponq_mesh::validity;
use pyo3::prelude::*;
use pyo3::types::PyDict;

use crate::arrays::mesh_in;
use crate::errors::{run, value_err};

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
pub(crate) fn metrics<'py>(
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
    // `check_validity`: the prediction's exact validity check, as `ponq-eval compare` runs it.
    let m = run(py, threads, move || {
        Ok(compare(
            &p,
            &g,
            &MetricOptions {
                surface_samples: samples,
                edge_samples: samples,
                seed,
                sharp_angle_deg: sharp_angle,
                check_validity: true,
                ..Default::default()
            },
        ))
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
pub(crate) fn check<'py>(
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
