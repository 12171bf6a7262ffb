//! Readiness: whether this server can serve requests now, which needs its database. A load
//! balancer sends traffic to a server only while `/readyz` says so; `/healthz` says only
//! that the process answers (for a supervisor deciding whether to restart it).

use std::time::Duration;

use super::{Error, Result};
use crate::store::Store;

/// How long readiness waits for the database: a balancer polls often and wants an answer
/// sooner than a request would wait.
pub const READY_TIMEOUT: Duration = Duration::from_secs(2);

/// `Ok` when the database answers within [`READY_TIMEOUT`]; `Busy` (503, `Retry-After`)
/// saying why otherwise.
pub async fn ready(store: &Store) -> Result<()> {
    match tokio::time::timeout(READY_TIMEOUT, store.ping()).await {
        Ok(Ok(())) => Ok(()),
        Ok(Err(e)) => {
            tracing::warn!(error = %e, "not ready: the database does not answer");
            Err(Error::Busy(
                "not ready: the database cannot be reached".into(),
            ))
        }
        Err(_) => Err(Error::Busy(format!(
            "not ready: the database did not answer within {} s",
            READY_TIMEOUT.as_secs()
        ))),
    }
}
