//! Jobs a server takes over from one that died, each run again by the module of its kind.

use std::sync::Arc;

use super::jobs::Jobs;
use super::motion_index::{self, MotionIndex};
use super::{training, Result};

/// Take over one job whose server died, if there is one, and run it again here; false if
/// there was none.
pub async fn take_over(index: &Arc<MotionIndex>, jobs: &Arc<Jobs>) -> Result<bool> {
    let Some((kind, request, progress)) = jobs.take_over().await? else {
        return Ok(false);
    };
    match kind.as_str() {
        training::JOB_KIND => training::resume(index.store(), &request, progress).await,
        motion_index::JOB_KIND => motion_index::run(index.clone(), progress),
        other => {
            progress
                .fail(format!(
                    "a job of kind {other:?} is not one this server runs"
                ))
                .await
        }
    }
    Ok(true)
}
