//! Use-cases: what the HTTP layer and the CLI ask for, in terms of the layers below. Owns
//! transactions (through the store) and moves codec work off the async executor.
//!
//! # Layout
//! - [`access`]: tokens, scopes and libraries; who a request is; the audit log.
//! - [`answer`]: range answers in any output format, decoded and written a chunk at a time.
//! - [`budget`]: memory held for requests (bodies, answers): a total and a share per caller.
//! - [`archive`]: verify everything stored; export takes to open files and bitstreams,
//!   import them back.
//! - [`export`]: a library as files of one format, streamed as one ZIP with a manifest.
//! - [`bases`]: shared bases as stored objects — loading, the newest per layout, deleting.
//! - [`training`]: training shared bases from a selection of takes, as a background job.
//! - [`jobs`]: background jobs and their progress; [`background`]: a job taken over from a
//!   server that died, run again by its kind's module.
//! - [`motion_index`]: every take's motion features, taken through the read path, stored,
//!   kept current (the index job) and kept decoded; [`search`]: finding motion by motion.
//! - [`choose`]: which codecs compete for a take, and the decision record.
//! - [`history`]: what choice learns from a library's takes: candidates not worth encoding.
//! - [`ingest`]: parse, encode with every candidate, keep the smallest, store.
//! - [`fetch`]: metadata, error series, and the readers range answers decode with.
//! - [`library`]: listings, statistics, edits.
//! - [`streams`]: live takes coded and committed chunk by chunk as frames arrive.
//! - [`prepared`]: readers kept ready per take for range requests.
//! - [`take`]: a stored take as a typed record, parsed from its row once.

pub mod access;
pub mod analog;
pub mod answer;
pub mod approximate;
pub mod archive;
pub mod background;
pub mod bases;
pub mod body;
pub mod budget;
pub mod choose;
pub mod export;
pub mod fetch;
pub mod health;
pub mod history;
pub mod ingest;
pub mod jobs;
pub mod kept;
pub mod library;
pub mod motion_index;
pub mod motion_stats;
pub mod outputs;
pub mod prepared;
pub mod ranges;
pub mod retarget;
pub mod search;
pub mod shape;
pub mod skeletons;
pub mod stamps;
pub mod storage;
pub mod streams;
pub mod take;
pub mod training;

use crate::{codec, motion, store};

/// Errors of the service layer, each mapped to one HTTP status by the HTTP layer.
#[derive(Debug, thiserror::Error)]
pub enum Error {
    /// The upload is not a take we can read.
    #[error("{0}")]
    BadInput(#[from] motion::Error),
    /// The request's own fields make no sense (unknown codec, negative bound, bad range…).
    #[error("{0}")]
    InvalidRequest(String),
    #[error("{0} not found")]
    NotFound(String),
    /// The range asked for lies outside the take.
    #[error("{0}")]
    OutOfRange(String),
    /// The request is valid but this take cannot satisfy it (e.g. BVH of point data).
    #[error("{0}")]
    Unsatisfiable(String),
    /// The request clashes with what is stored (e.g. deleting a basis takes still use).
    #[error("{0}")]
    Conflict(String),
    /// The request has no valid token, and this server needs one.
    #[error("{0}")]
    Unauthorized(String),
    /// The token is valid but does not reach what was asked (scope or library).
    #[error("{0}")]
    Forbidden(String),
    /// The server is at a capacity limit (open streams); the same request may succeed later.
    #[error("{0}")]
    Busy(String),
    /// A live stream this server coded was taken over by another meanwhile (this one could
    /// not renew its lease): the same request sent again goes to the new owner.
    #[error("{0}")]
    Moved(String),
    #[error("codec: {0}")]
    Codec(#[from] codec::Error),
    #[error("store: {0}")]
    Store(#[from] store::Error),
    /// A stored record that does not parse: never read as a default.
    #[error("corrupt: {0}")]
    Corrupt(String),
    #[error("internal: {0}")]
    Internal(String),
}

pub type Result<T, E = Error> = std::result::Result<T, E>;

impl Error {
    /// Whether a take's answer failed for a reason of the take's own (the format cannot
    /// hold it, it is damaged, it was deleted meanwhile, it lacks what was asked): a reader
    /// of many takes (an export, motion statistics) skips it and says why. The others (the
    /// database, the server, a full budget) stop it.
    pub fn is_the_takes_own(&self) -> bool {
        match self {
            Error::Store(crate::store::Error::Corrupt(_)) => true,
            Error::Store(_) | Error::Internal(_) | Error::Busy(_) | Error::Moved(_) => false,
            _ => true,
        }
    }
}

/// Run CPU-heavy work on the blocking pool, never on the async executor.
pub(crate) async fn blocking<T: Send + 'static>(
    f: impl FnOnce() -> T + Send + 'static,
) -> Result<T> {
    tokio::task::spawn_blocking(f)
        .await
        .map_err(|e| Error::Internal(format!("worker failed: {e}")))
}

/// Tags as stored: trimmed, non-empty, sorted, unique.
pub(crate) fn normalise_tags(tags: &[String]) -> Vec<String> {
    let mut t: Vec<String> = tags
        .iter()
        .map(|s| s.trim().to_string())
        .filter(|s| !s.is_empty())
        .collect();
    t.sort();
    t.dedup();
    t
}

/// This server among those sharing the database: a per-process id, which job and stream
/// rows name their owner with, and the address other servers reach it at (where they
/// forward a stream's requests: `serve --advertise-url`).
#[derive(Debug, Clone)]
pub struct Node {
    pub id: String,
    pub url: String,
}

impl Node {
    /// A new process's identity, reached at `url`.
    pub fn new(url: impl Into<String>) -> Node {
        Node {
            id: uuid::Uuid::now_v7().to_string(),
            url: url.into(),
        }
    }
}

/// Milliseconds since the Unix epoch.
pub fn now_ms() -> i64 {
    std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map_or(0, |d| d.as_millis() as i64)
}
