//! Error type of the crate.

/// Errors of `ponq-data`.
#[derive(Debug, thiserror::Error)]
pub enum DataError {
    /// An error from the mesh library (I/O, formats, meshing).
    #[error(transparent)]
    Mesh(#[from] ponq_mesh::Error),
    /// Input that cannot be processed (empty mesh, zero-size box, bad option).
    #[error("{0}")]
    Invalid(String),
}

/// Result alias of the crate.
pub type Result<T, E = DataError> = std::result::Result<T, E>;
