//! # ponq-py
//!
//! The Python module `ponq` (PyO3 + NumPy, built by maturin): the command-line programs of
//! PoNQ-rs as functions on NumPy arrays. Each function does what its program does with the
//! same options, gives the same error messages (as `ValueError`; flags are named as the
//! keyword arguments), and releases the GIL while it works. See `ponq-py/README.md`.
//!
//! The modules: `errors` (why a call failed, running work without the GIL), `arrays` (NumPy
//! arrays in and out, checked as the programs check files), `options` (shared keyword
//! arguments), then one module per family of functions: `inference` (`infer`), `field`
//! (`infer_field`: a signed distance function evaluated near its surface only), `meshing`
//! (`mesh`, `marching_cubes`), `data` (`sdf`, `sample`, `fit`), `datasets` (`prepare_meshes`: dataset records as
//! `ponq-prep meshes` writes them, shards, logs), `evaluation` (`metrics`,
//! `check`).

mod arrays;
mod data;
mod datasets;
mod errors;
mod evaluation;
mod field;
mod inference;
mod meshing;
mod options;

use pyo3::prelude::*;

/// PoNQ-rs for Python: sharp, watertight meshes from signed distance grids with the PoNQ
/// network (CVPR 2024), and the tools around it, on NumPy arrays.
///
/// Functions: ``infer`` (SDF grid -> mesh, the ``ponq-infer`` program), ``infer_field``
/// (a signed distance function, e.g. a neural field -> mesh), ``mesh`` (PoNQ
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
    m.add_function(wrap_pyfunction!(inference::infer, m)?)?;
    m.add_function(wrap_pyfunction!(field::infer_field, m)?)?;
    m.add_function(wrap_pyfunction!(meshing::mesh, m)?)?;
    m.add_function(wrap_pyfunction!(data::sdf, m)?)?;
    m.add_function(wrap_pyfunction!(datasets::prepare_meshes, m)?)?;
    m.add_function(wrap_pyfunction!(datasets::mesh_files, m)?)?;
    m.add_function(wrap_pyfunction!(datasets::output_names, m)?)?;
    m.add_function(wrap_pyfunction!(data::sample, m)?)?;
    m.add_function(wrap_pyfunction!(data::fit, m)?)?;
    m.add_function(wrap_pyfunction!(evaluation::metrics, m)?)?;
    m.add_function(wrap_pyfunction!(evaluation::check, m)?)?;
    m.add_function(wrap_pyfunction!(meshing::marching_cubes, m)?)?;
    // maturin's `__init__.py` re-exports `*`: the list makes it take `__version__` too.
    m.add(
        "__all__",
        vec![
            "__version__",
            "DEFAULT_MERGE_SMOOTH",
            "infer",
            "infer_field",
            "mesh",
            "sdf",
            "prepare_meshes",
            "mesh_files",
            "output_names",
            "sample",
            "fit",
            "metrics",
            "check",
            "marching_cubes",
        ],
    )?;
    Ok(())
}
