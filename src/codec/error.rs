//! The one error type of the codec layer.

/// Errors of encoding and decoding. Decoding untrusted bytes yields only these, never a
/// panic: `Malformed` for structure that does not parse, `Checksum` for bytes that parse but
/// were altered, `Unsupported` for versions or codecs we do not know, `Limit` for sizes past
/// what we agree to allocate.
#[derive(Debug, thiserror::Error, Clone, PartialEq)]
pub enum Error {
    #[error("malformed bitstream: {0}")]
    Malformed(String),
    #[error("checksum mismatch in {0}")]
    Checksum(String),
    #[error("unsupported: {0}")]
    Unsupported(String),
    #[error("{what} is {actual}, over the limit of {limit}")]
    Limit {
        what: &'static str,
        actual: u64,
        limit: u64,
    },
    /// The caller's mistake: arguments that cannot be encoded (no points, a negative bound,
    /// a codec that does not fit the take, a range outside it). HTTP answers 400.
    #[error("invalid: {0}")]
    Invalid(String),
    /// Our fault: a promise broken inside the service (a chunk the reader was promised and
    /// not given, shapes that disagree between an encoder and its decoder). Never the
    /// request's doing, so HTTP answers 500 and logs it.
    #[error("internal fault: {0}")]
    Fault(String),
    /// A shared basis is missing, of the wrong kind or shape, or not the one the header names.
    #[error("shared basis: {0}")]
    Basis(String),
    /// The encoder could not meet the bound; a bug in a codec, reported rather than hidden.
    #[error("codec {codec} missed the bound: {detail}")]
    BoundMissed { codec: String, detail: String },
}

pub type Result<T, E = Error> = std::result::Result<T, E>;

pub(crate) fn malformed(msg: impl Into<String>) -> Error {
    Error::Malformed(msg.into())
}
