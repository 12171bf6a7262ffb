//! The one error type of the motion layer: everything that can go wrong while reading,
//! writing or checking a take.

use std::fmt;

use super::format::{Format, UnknownFormat};

/// Where in the input a problem was found, so that a user can open the file and look.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Location {
    /// 1-based line of a text format.
    Line(usize),
    /// Byte offset into a binary format.
    Offset(usize),
    /// The input as a whole (e.g. it is empty).
    Whole,
}

impl fmt::Display for Location {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Location::Line(n) => write!(f, "line {n}"),
            Location::Offset(n) => write!(f, "byte offset {n}"),
            Location::Whole => f.write_str("input"),
        }
    }
}

/// Errors of the motion layer.
#[derive(Debug, thiserror::Error, Clone, PartialEq)]
pub enum Error {
    /// The bytes are not a valid file of the given format.
    #[error("{format} {at}: {reason}")]
    Parse {
        format: Format,
        at: Location,
        reason: String,
    },
    /// The content is not any format we read.
    #[error("unrecognised input: {0}")]
    UnknownFormat(String),
    /// Untrusted input exceeds a configured limit; nothing past the limit was allocated.
    #[error("{what} is {actual}, over the limit of {limit}")]
    Limit {
        what: &'static str,
        actual: u64,
        limit: u64,
    },
    /// The data contradicts the file's own header or physical sense (strict reading), or
    /// a take's stored body contradicts the take (a pelvis beyond its points).
    #[error("{0}")]
    Contradiction(String),
    /// The request makes no sense for this take (e.g. BVH output without a skeleton).
    #[error("unsupported: {0}")]
    Unsupported(String),
    /// Arguments that break the model's invariants (mismatched shapes, bad fps, ...).
    #[error("invalid: {0}")]
    Invalid(String),
}

impl From<UnknownFormat> for Error {
    fn from(e: UnknownFormat) -> Self {
        Error::Unsupported(e.to_string())
    }
}

impl Error {
    pub(crate) fn parse(format: Format, at: Location, reason: impl Into<String>) -> Self {
        Error::Parse {
            format,
            at,
            reason: reason.into(),
        }
    }
}

pub type Result<T, E = Error> = std::result::Result<T, E>;
