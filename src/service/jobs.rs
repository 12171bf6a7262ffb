//! Background jobs (training bases): their state and progress, as `GET /v1/jobs/{id}` reports
//! it. Jobs live in the server's memory: a restart forgets a job's record (what it made — a
//! stored basis — stays), and a job that was running when the server stopped is simply gone.

use std::collections::{HashMap, VecDeque};
use std::sync::{Arc, Mutex};

use serde::Serialize;

use super::access::Grant;

/// Finished jobs kept for inspection before the oldest are forgotten.
const KEEP_FINISHED: usize = 256;

#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum JobState {
    Running,
    Succeeded,
    Failed,
}

#[derive(Debug, Clone, Serialize)]
pub struct Job {
    pub id: String,
    pub kind: String,
    pub state: JobState,
    /// 0 to 1.
    pub progress: f64,
    /// What it is doing now, or did last.
    pub message: String,
    /// What it made (for training: the basis).
    pub result: Option<serde_json::Value>,
    pub error: Option<String>,
    /// Milliseconds since the Unix epoch.
    pub created_at: i64,
    pub finished_at: Option<i64>,
    /// The libraries of the takes it works on: a token limited to libraries sees the job
    /// only if it reaches every one of them.
    pub libraries: Vec<String>,
}

impl Job {
    /// Whether `grant` may see this job: over every library, or over all of the job's.
    pub fn visible_to(&self, grant: &Grant) -> bool {
        match &grant.libraries {
            None => true,
            Some(mine) => {
                !self.libraries.is_empty() && self.libraries.iter().all(|l| mine.contains(l))
            }
        }
    }
}

#[derive(Default)]
pub struct Jobs {
    inner: Mutex<(HashMap<String, Job>, VecDeque<String>)>,
    /// Woken whenever a job finishes, for [`Jobs::wait`].
    finished: tokio::sync::Notify,
}

/// The longest a client may ask [`Jobs::wait`] to wait, seconds.
pub const MAX_WAIT_S: u64 = 600;

impl Jobs {
    /// Register a running job on takes of `libraries` and return the handle its worker
    /// reports through.
    pub fn start(self: &Arc<Self>, kind: &str, libraries: Vec<String>) -> Progress {
        let id = uuid::Uuid::now_v7().to_string();
        let job = Job {
            id: id.clone(),
            kind: kind.to_string(),
            state: JobState::Running,
            progress: 0.0,
            message: "queued".into(),
            result: None,
            error: None,
            created_at: super::now_ms(),
            finished_at: None,
            libraries,
        };
        self.inner
            .lock()
            .expect("jobs lock")
            .0
            .insert(id.clone(), job);
        Progress {
            jobs: self.clone(),
            id,
        }
    }

    pub fn get(&self, id: &str) -> Option<Job> {
        self.inner.lock().expect("jobs lock").0.get(id).cloned()
    }

    /// The job once it has finished, or as it is after `timeout` (a long poll: clients and
    /// tests wait for a job without polling in a loop); `None` when there is no such job or
    /// `grant` may not see it (the same answer, so that a limited token learns nothing).
    pub async fn wait_for(
        &self,
        id: &str,
        timeout: std::time::Duration,
        grant: &Grant,
    ) -> Option<Job> {
        if !self.get(id)?.visible_to(grant) {
            return None;
        }
        self.wait(id, timeout).await
    }

    /// [`Jobs::wait_for`] over every library.
    pub async fn wait(&self, id: &str, timeout: std::time::Duration) -> Option<Job> {
        let deadline = tokio::time::Instant::now() + timeout;
        loop {
            // Registered before the state is read, so a finish in between is not missed.
            let woken = self.finished.notified();
            tokio::pin!(woken);
            woken.as_mut().enable();
            let job = self.get(id)?;
            if job.state != JobState::Running {
                return Some(job);
            }
            if tokio::time::timeout_at(deadline, woken).await.is_err() {
                return Some(job);
            }
        }
    }

    fn update(&self, id: &str, f: impl FnOnce(&mut Job)) {
        let mut g = self.inner.lock().expect("jobs lock");
        let (map, finished) = &mut *g;
        let Some(job) = map.get_mut(id) else { return };
        f(job);
        if job.state != JobState::Running && job.finished_at.is_none() {
            job.finished_at = Some(super::now_ms());
            self.finished.notify_waiters();
            finished.push_back(id.to_string());
            while finished.len() > KEEP_FINISHED {
                if let Some(old) = finished.pop_front() {
                    map.remove(&old);
                }
            }
        }
    }
}

/// A worker's handle on its job.
#[derive(Clone)]
pub struct Progress {
    jobs: Arc<Jobs>,
    pub id: String,
}

impl Progress {
    pub fn report(&self, progress: f64, message: impl Into<String>) {
        let message = message.into();
        self.jobs.update(&self.id, |j| {
            j.progress = progress.clamp(0.0, 1.0);
            j.message = message;
        });
    }

    pub fn succeed(&self, result: serde_json::Value) {
        self.jobs.update(&self.id, |j| {
            j.state = JobState::Succeeded;
            j.progress = 1.0;
            j.message = "done".into();
            j.result = Some(result);
        });
    }

    pub fn fail(&self, error: String) {
        self.jobs.update(&self.id, |j| {
            j.state = JobState::Failed;
            j.message = "failed".into();
            j.error = Some(error);
        });
    }

    pub fn job(&self) -> Option<Job> {
        self.jobs.get(&self.id)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_job_reports_progress_then_its_outcome() {
        let jobs = Arc::new(Jobs::default());
        let p = jobs.start("train-bases", vec!["lab".into()]);
        p.report(0.5, "training x");
        let j = jobs.get(&p.id).unwrap();
        assert_eq!(
            (j.state, j.progress, j.message.as_str()),
            (JobState::Running, 0.5, "training x")
        );
        p.succeed(serde_json::json!({"id": "abc"}));
        let j = jobs.get(&p.id).unwrap();
        assert_eq!(j.state, JobState::Succeeded);
        assert!(j.finished_at.is_some() && j.result.is_some());
        let q = jobs.start("train-bases", vec!["lab".into()]);
        q.fail("no takes".into());
        assert_eq!(jobs.get(&q.id).unwrap().error.as_deref(), Some("no takes"));
    }

    #[tokio::test]
    async fn waiting_returns_when_the_job_finishes_or_at_the_timeout() {
        use std::time::Duration;
        let jobs = Arc::new(Jobs::default());
        let p = jobs.start("train-bases", vec!["lab".into()]);
        let running = jobs.wait(&p.id, Duration::from_millis(1)).await.unwrap();
        assert_eq!(running.state, JobState::Running);
        let (j2, id) = (jobs.clone(), p.id.clone());
        let waiter = tokio::spawn(async move { j2.wait(&id, Duration::from_secs(600)).await });
        tokio::task::yield_now().await;
        p.succeed(serde_json::json!({}));
        let done = waiter.await.unwrap().unwrap();
        assert_eq!(done.state, JobState::Succeeded);
        assert!(jobs.wait("nope", Duration::from_secs(1)).await.is_none());
    }
}
