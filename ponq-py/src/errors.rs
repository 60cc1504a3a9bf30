//! Errors and running the work: why a call failed ([`Failure`]: `ValueError` for bad input,
//! `RuntimeError` otherwise) and [`run`], which runs a call's work with the GIL released, in a
//! thread pool of the asked size, a panic turned into a `RuntimeError`.

use std::collections::HashMap;
use std::panic::{AssertUnwindSafe, catch_unwind};
use std::sync::{Arc, Mutex, OnceLock};

use pyo3::exceptions::{PyRuntimeError, PyValueError};
use pyo3::prelude::*;

/// Why a call failed: bad input (`ValueError`) or a failure of the computation
/// (`RuntimeError`).
pub(crate) enum Failure {
    Value(String),
    Runtime(String),
}

pub(crate) type Work<T> = Result<T, Failure>;

pub(crate) fn bad<T>(msg: impl Into<String>) -> Work<T> {
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

pub(crate) fn value_err(msg: impl Into<String>) -> PyErr {
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
pub(crate) fn run<T: Send>(
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
pub(crate) fn warn(py: Python<'_>, category: &str, msg: &str) -> PyResult<()> {
    let cat = py.import("builtins")?.getattr(category)?;
    py.import("warnings")?
        .call_method1("warn", (msg, cat, 2))
        .map(|_| ())
}
