//! Errors of this crate.

/// Errors of model building, loading and prediction conversion.
#[derive(Debug, thiserror::Error)]
pub enum ModelError {
    /// Inconsistent sizes or values.
    #[error("{0}")]
    Invalid(String),
    /// A tensor could not be read back from the device.
    #[error("tensor read-back failed: {0}")]
    Tensor(String),
    /// Reading or writing weights failed.
    #[error("weights file {path}: {message}")]
    Weights {
        /// The file.
        path: String,
        /// What went wrong.
        message: String,
    },
}

/// Result of this crate.
pub type Result<T> = std::result::Result<T, ModelError>;
