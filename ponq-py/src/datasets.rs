//! `ponq.prepare_meshes`: dataset records of mesh files, as `ponq-prep meshes` writes them
//! (the same files, byte for byte), with the same shards and log: what a Ray task, a Slurm
//! array task or a notebook calls on its part of a dataset.

use std::path::PathBuf;

use ponq_data::prep::{BatchRun, PrepOptions, mesh_jobs, run_batch_with};
use ponq_data::records::{RecordLog, Shard, default_log};
use pyo3::prelude::*;
use pyo3::types::PyList;

use crate::errors::{Failure, run, value_err};

/// Prepares mesh files as dataset records into ``out``: ``out/NAME.npz`` per mesh with
/// ``pointcloud``, ``normals``, ``<res>_sdf`` and ``<res>_occupancy`` in the [-1,1] frame,
/// exactly as ``ponq-prep meshes`` writes them (the same bytes). Records already in ``out``
/// are skipped when whole (a re-run resumes; a file cut by a crash is redone); a bad mesh is
/// an error record, not an exception: check the ``status`` of the records (the Ray example
/// exits 2 when any is ``"error"``).
///
/// Args:
///     meshes: mesh file paths (.obj, .ply, .off, .stl). A mesh's output name is its path
///         below ``root`` without the extension (``a/model``: ``out/a/model.npz``); two files
///         that differ only by their extension or letter case raise ``ValueError`` before
///         any work.
///     root: the dataset's folder; default the deepest folder common to ``meshes`` (give
///         it when calling on parts of a dataset, so that every part names alike).
///     out: output folder (created).
///     res: grid resolutions (cells per side).
///     samples: surface samples per shape.
///     sample_seed: sampling seed.
///     repair: repair broken meshes first (``ponq-prep sdf --help``).
///     shard: ``(i, n)`` or ``"i/n"``: only the meshes whose name hashes to ``i`` modulo
///         ``n`` (the split of ``ponq-prep meshes --shard``).
///     log: the JSON-lines log to append one record per mesh to; default
///         ``out/log.jsonl`` (``out/log-shard-I-of-N.jsonl`` with ``shard``); ``False``: none.
///         Give each concurrent worker its own file.
///     threads: worker threads (a pool of that size for this call); default all cores.
///
/// Returns:
///     A list of dicts, one per mesh of the shard: ``name``, ``time`` (UTC), ``shards``
///     (the shard count, 1 unsharded), ``input``, ``status``
///     (``"done"``, ``"already"`` or ``"error"``), ``error``, ``stages`` (seconds per
///     stage), ``seconds``, ``peak_rss_mb``, ``warning``, ``report`` (the repair's).
///
/// Raises:
///     ValueError: bad options. OSError-like failures of the output folder or the log
///     raise ``RuntimeError``.
#[pyfunction]
#[pyo3(
    signature = (meshes, out, *, root=None, res=vec![32, 64], samples=1_000_000, sample_seed=0, repair=true, shard=None, log=None, threads=None),
    text_signature = "(meshes, out, *, root=None, res=[32, 64], samples=1000000, sample_seed=0, repair=True, shard=None, log=None, threads=None)"
)]
#[allow(clippy::too_many_arguments)]
pub(crate) fn prepare_meshes<'py>(
    py: Python<'py>,
    meshes: Vec<PathBuf>,
    out: PathBuf,
    root: Option<PathBuf>,
    res: Vec<usize>,
    samples: usize,
    sample_seed: u64,
    repair: bool,
    shard: Option<Bound<'py, PyAny>>,
    log: Option<Bound<'py, PyAny>>,
    threads: Option<usize>,
) -> PyResult<Bound<'py, PyList>> {
    if res.is_empty() || res.iter().any(|r| !(2..=1024).contains(r)) {
        return Err(value_err(format!(
            "res values must be in 2..=1024, got {res:?}"
        )));
    }
    if samples == 0 {
        return Err(value_err("samples must be positive"));
    }
    let shard: Option<Shard> = match shard {
        None => None,
        Some(s) if s.is_none() => None,
        Some(s) => Some(if let Ok(text) = s.extract::<String>() {
            text.parse().map_err(value_err)?
        } else {
            let (i, n): (u64, u64) = s
                .extract()
                .map_err(|_| value_err("shard takes (i, n) or \"i/n\""))?;
            Shard::new(i, n)
                .ok_or_else(|| value_err(format!("shard {i}/{n}: i must be below n")))?
        }),
    };
    let log_path: Option<PathBuf> = match log {
        Some(l) if !l.is_none() => match l.extract::<bool>() {
            Ok(false) => None,
            Ok(true) => Some(default_log(&out, shard)),
            Err(_) => Some(l.extract::<PathBuf>()?),
        },
        _ => Some(default_log(&out, shard)),
    };
    let opts = PrepOptions {
        resolutions: res,
        samples,
        seed: sample_seed,
        repair,
    };
    let lines: Vec<String> = run(py, threads, move || {
        // Named (and refused when two would share an output) before anything is written.
        let root = root.unwrap_or_else(|| ponq_data::names::common_folder(&meshes));
        let jobs = mesh_jobs(meshes, &root)?;
        std::fs::create_dir_all(&out)
            .map_err(|e| Failure::Runtime(format!("creating {}: {e}", out.display())))?;
        let log = match &log_path {
            Some(p) => Some(RecordLog::append(p)?),
            None => None,
        };
        let batch = BatchRun {
            shard,
            log: log.as_ref(),
        };
        let s = run_batch_with(&jobs, &out, &opts, &batch, || {})?;
        Ok(s.records.iter().map(|r| r.to_json()).collect())
    })?;
    let json = py.import("json")?;
    let list = PyList::empty(py);
    for l in lines {
        list.append(json.call_method1("loads", (l,))?)?;
    }
    Ok(list)
}

/// The mesh files of a dataset as ``ponq-prep meshes`` lists them: a folder searched
/// recursively (.obj, .ply, .off, .stl, sorted), or a text file of paths (one per line,
/// relative to its folder; ``#`` starts a comment), and the dataset's root (the folder, or the
/// list's folder): give both to ``prepare_meshes(files, out, root=root)`` so that its names
/// and shards are those of ``ponq-prep meshes``.
///
/// Returns:
///     ``(files, root)``: a list of paths (str) and the root (str).
///
/// Raises:
///     ValueError: a folder or list that cannot be read.
#[pyfunction]
#[pyo3(text_signature = "(dir_or_list)")]
pub(crate) fn mesh_files(dir_or_list: PathBuf) -> PyResult<(Vec<String>, String)> {
    let files = ponq_data::prep::mesh_inputs(&dir_or_list)
        .map_err(|e| value_err(format!("listing {}: {e}", dir_or_list.display())))?;
    let root = ponq_data::prep::input_root(&dir_or_list);
    Ok((
        files
            .iter()
            .map(|p| p.to_string_lossy().into_owned())
            .collect(),
        root.to_string_lossy().into_owned(),
    ))
}

/// The output names ``prepare_meshes`` and ``ponq-prep meshes`` give ``meshes``: each one's
/// path below ``root`` (default their deepest common folder) without its extension.
///
/// Raises:
///     ValueError: two meshes that would share an output (they differ only by their
///         extension or letter case, or one is listed twice).
#[pyfunction]
#[pyo3(signature = (meshes, *, root=None), text_signature = "(meshes, *, root=None)")]
pub(crate) fn output_names(meshes: Vec<PathBuf>, root: Option<PathBuf>) -> PyResult<Vec<String>> {
    let root = root.unwrap_or_else(|| ponq_data::names::common_folder(&meshes));
    ponq_data::names::output_names(&meshes, &root).map_err(|e| value_err(e.to_string()))
}
