//! Library errors.

/// Everything the effect can fail with.
#[derive(Debug, thiserror::Error)]
pub enum Error {
    /// No GPU adapter could be found.
    #[error("no GPU adapter found ({0}); use the CPU backend")]
    NoAdapter(String),
    /// The adapter refused the device.
    #[error("could not create a GPU device: {0}")]
    Device(String),
    /// A size the device cannot hold.
    #[error("{what} of {value} exceeds the adapter limit of {limit}")]
    Limit {
        /// What was too large.
        what: String,
        /// Requested value.
        value: u64,
        /// The adapter's limit.
        limit: u64,
    },
    /// The GPU reported a validation, out-of-memory or device-lost error.
    #[error("GPU error during {context}: {message}")]
    Gpu {
        /// The operation.
        context: String,
        /// wgpu's message.
        message: String,
    },
    /// A setting or input out of range.
    #[error("invalid {key} = {value}: {reason}")]
    Invalid {
        /// The setting or input.
        key: String,
        /// Its value, printed.
        value: String,
        /// Why it is rejected.
        reason: String,
    },
}

impl Error {
    /// Shorthand for [`Error::Invalid`].
    pub fn invalid(key: impl Into<String>, value: impl std::fmt::Display, reason: impl Into<String>) -> Self {
        Error::Invalid { key: key.into(), value: value.to_string(), reason: reason.into() }
    }
}
