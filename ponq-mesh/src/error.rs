//! Error type of the crate.

use std::path::PathBuf;

/// Everything that can go wrong in `ponq-mesh`.
#[derive(Debug, thiserror::Error)]
pub enum Error {
    /// An I/O error while reading or writing `path` (the message includes the cause, so the
    /// error is not chained a second time).
    #[error("{path}: {err}")]
    Io { path: PathBuf, err: std::io::Error },
    /// A file that exists but whose content cannot be understood.
    #[error("{path}: {msg}")]
    Format { path: PathBuf, msg: String },
    /// Input data with the wrong shape, NaN/Inf values or inconsistent sizes.
    #[error("invalid input: {0}")]
    InvalidInput(String),
    /// An unsupported file extension or format.
    #[error("unsupported format: {0}")]
    Unsupported(String),
}

/// Result alias of the crate.
pub type Result<T, E = Error> = std::result::Result<T, E>;

impl Error {
    /// Shorthand for a [`Error::Format`] error.
    pub fn format(path: impl Into<PathBuf>, msg: impl Into<String>) -> Self {
        Error::Format {
            path: path.into(),
            msg: msg.into(),
        }
    }
    /// Shorthand for an [`Error::Io`] error.
    pub fn io(path: impl Into<PathBuf>, source: std::io::Error) -> Self {
        Error::Io {
            path: path.into(),
            err: source,
        }
    }
}
