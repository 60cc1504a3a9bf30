//! The keyword arguments several functions share (`bounds=`, `open=`) and the validity
//! check's warning, as the programs' flags and checks are.

use ponq_mesh::mesher::MeshingOptions;
use ponq_mesh::validity::ValidityReport;
use pyo3::prelude::*;
use pyo3::types::PyBool;

use ponq_infer::{InferOptions, RefineMode};

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

/// How a grid's or a field's values are read (`level=`, `inside=`, `field=`), checked as
/// `ponq-infer` checks `--level`, `--inside` and `--field`.
pub(crate) fn condition_options(
    level: Option<f64>,
    inside: &str,
    field: &str,
) -> PyResult<ponq_data::condition::ConditionOptions> {
    if level.is_some_and(|l| !l.is_finite()) {
        return Err(value_err("level must be a finite number"));
    }
    Ok(ponq_data::condition::ConditionOptions {
        level,
        inside: inside
            .parse()
            .map_err(|e| value_err(format!("invalid value '{inside}' for inside: {e}")))?,
        field: field
            .parse()
            .map_err(|e| value_err(format!("invalid value '{field}' for field: {e}")))?,
    })
}

/// The inference options of the keyword arguments `ponq.infer` and `ponq.infer_field` share,
/// checked as `ponq-infer` checks its flags (`merge_smooth` `None` or 0 keeps every point;
/// `lite` / `coarsen` turn the refinement off, and refuse `refine='on'`).
#[allow(clippy::too_many_arguments)]
pub(crate) fn infer_options(
    bounds: Option<Vec<f64>>,
    lite: bool,
    coarsen: u32,
    merge_smooth: Option<f64>,
    open: Option<f64>,
    refine: &str,
    condition: ponq_data::condition::ConditionOptions,
) -> PyResult<InferOptions> {
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
    if (lite || coarsen > 0) && refine == RefineMode::On {
        return Err(value_err(
            "refine='on' works on the full PoNQ: not with lite or coarsen",
        ));
    }
    Ok(InferOptions {
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
        condition: ponq_data::condition::ConditionOptions {
            // An open surface's boundary lies on both sides: signed distances, unless told.
            inside: match (condition.inside, open) {
                (ponq_data::condition::Inside::Auto, Some(_)) => {
                    ponq_data::condition::Inside::Negative
                }
                (i, _) => i,
            },
            ..condition
        },
        ..Default::default()
    })
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
