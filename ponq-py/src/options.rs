//! The keyword arguments several functions share (`bounds=`, `open=`) and the validity
//! check's warning, as the programs' flags and checks are.

use ponq_mesh::mesher::MeshingOptions;
use ponq_mesh::validity::ValidityReport;
use pyo3::prelude::*;
use pyo3::types::PyBool;

use crate::errors::{value_err, warn};

/// The open-surface threshold that `open=True` stands for (the programs' `--open` without a
/// value).
const DEFAULT_OPEN: f64 = 0.35;

/// The domain box from `bounds` (6 numbers), or `[-1,1]^3`.
pub(crate) fn domain(bounds: Option<Vec<f64>>) -> PyResult<([f64; 3], [f64; 3])> {
    match bounds {
        None => Ok(([-1.0; 3], [1.0; 3])),
        Some(b) => MeshingOptions::domain_from(&b).map_err(|e| value_err(format!("bounds: {e}"))),
    }
}

/// `open=`: `None` / `False` (closed), `True` (the default threshold 0.35) or a threshold.
pub(crate) fn open_arg(v: Option<&Bound<'_, PyAny>>) -> PyResult<Option<f64>> {
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
pub(crate) fn check_open(open: Option<f64>) -> PyResult<()> {
    if let Some(t) = open {
        MeshingOptions::check_open_threshold(t).map_err(|e| value_err(format!("open: {e}")))?;
    }
    Ok(())
}

/// Whether a mesh passes the programs' check: a closed mesh must be valid, an open surface
/// needs no self-intersection and no non-manifold edge or vertex.
fn passes(r: &ValidityReport, open: bool) -> bool {
    if open {
        r.is_valid_open_surface()
    } else {
        r.is_valid()
    }
}

pub(crate) fn warn_invalid(py: Python<'_>, r: Option<&ValidityReport>, open: bool) -> PyResult<()> {
    match r {
        Some(r) if !passes(r, open) => warn(
            py,
            "RuntimeWarning",
            &format!("the output mesh failed the validity check: {r}"),
        ),
        _ => Ok(()),
    }
}
