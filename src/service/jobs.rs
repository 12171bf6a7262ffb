//! Background jobs (training bases), kept in the database so that every server sharing it
//! sees them: `GET /v1/jobs/{id}` answers the same on any server, whichever runs the job.
//!
//! # One job, one runner, and who takes over
//! A job is a row ([`crate::store::JobRow`]) with the server running it (`owner`, a random
//! id per process) and a lease. The runner renews the lease with its progress every
//! [`FLUSH_EVERY`]; its result or error is written only while it still owns the job. When a
//! server dies mid-job its lease runs out, and the next server whose maintenance looks
//! ([`Jobs::take_over`], every few seconds) takes the job and runs it again from the start
//! (training is not resumable part way; `attempts` counts the starts).
//!
//! While a job runs, an identical request (the same kind and request: its `dedup_key`)
//! returns that job instead of starting a second: a unique index on running jobs' keys
//! decides, so two servers racing insert one.

use std::sync::{Arc, Mutex};
use std::time::Duration;

use serde::Serialize;

use super::access::Grant;
use super::{now_ms, Error, Result};
use crate::limits::MAX_JOBS_LISTED;
use crate::store::{JobRow, Store};

/// How often a runner writes its progress and renews its lease.
pub const FLUSH_EVERY: Duration = Duration::from_secs(1);

/// How long a job's lease lasts by default: a server that has not renewed it for this long
/// is taken for dead, and its job is run again by another.
pub const DEFAULT_LEASE: Duration = Duration::from_secs(30);

/// The shortest lease a server may be given: several renewals, and a wait for a database
/// connection (5 s), must fit in it, or a live runner would be taken for dead.
pub const MIN_LEASE: Duration = Duration::from_secs(5);

/// Finished jobs are kept this long for inspection, then forgotten (what they made stays).
pub const KEEP_FINISHED: Duration = Duration::from_secs(7 * 24 * 3600);

#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum JobState {
    Running,
    Succeeded,
    Failed,
}

impl JobState {
    fn name(self) -> &'static str {
        match self {
            JobState::Running => "running",
            JobState::Succeeded => "succeeded",
            JobState::Failed => "failed",
        }
    }
}

impl std::str::FromStr for JobState {
    type Err = String;
    fn from_str(s: &str) -> std::result::Result<Self, String> {
        match s {
            "running" => Ok(JobState::Running),
            "succeeded" => Ok(JobState::Succeeded),
            "failed" => Ok(JobState::Failed),
            _ => Err(format!(
                "job state {s:?} is not running, succeeded or failed"
            )),
        }
    }
}

/// A job as the API shows it.
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
    /// Times it was started: more than 1 when a server died running it and another took
    /// it over.
    pub attempts: i64,
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

    /// A stored row as a job; a row that does not parse is an error, not a default.
    fn from_row(r: JobRow) -> Result<Job> {
        let corrupt = |what: &str, e: &dyn std::fmt::Display| {
            Error::Corrupt(format!("job {}: {what}: {e}", r.id))
        };
        Ok(Job {
            state: r.state.parse().map_err(|e: String| corrupt("state", &e))?,
            result: r
                .result
                .as_deref()
                .map(serde_json::from_str)
                .transpose()
                .map_err(|e| corrupt("result", &e))?,
            libraries: serde_json::from_str(&r.libraries).map_err(|e| corrupt("libraries", &e))?,
            id: r.id,
            kind: r.kind,
            progress: r.progress,
            message: r.message,
            error: r.error,
            created_at: r.created_at,
            finished_at: r.finished_at,
            attempts: r.attempts,
        })
    }
}

/// A job to start: what it is, how to tell an identical one, and who may see it.
pub struct NewJob {
    pub kind: String,
    /// The request, as it will be stored and run again on takeover.
    pub request: serde_json::Value,
    pub libraries: Vec<String>,
}

/// The jobs of the database, as this server (`server`, an id of its own) runs them.
pub struct Jobs {
    store: Store,
    server: String,
    lease: Duration,
}

impl Jobs {
    /// Jobs run by `server` ([`super::Node::id`]) under leases of `lease` ([`MIN_LEASE`]
    /// at least).
    pub fn new(store: Store, lease: Duration, server: &str) -> Jobs {
        Jobs {
            store,
            server: server.to_string(),
            lease: lease.max(MIN_LEASE),
        }
    }

    /// How long a job's lease lasts.
    pub fn lease(&self) -> Duration {
        self.lease
    }

    /// This server's id as the job rows name it (`owner`).
    pub fn server(&self) -> &str {
        &self.server
    }

    fn lease_until(&self) -> i64 {
        now_ms() + self.lease.as_millis() as i64
    }

    /// Start `job` run by this server, or find the identical job running already: the job,
    /// and the handle to run it with when it is new (`None`: someone runs it).
    pub async fn start(self: &Arc<Self>, job: NewJob) -> Result<(Job, Option<Progress>)> {
        let request = job.request.to_string();
        let dedup_key = format!(
            "{}:{}",
            job.kind,
            crate::codec::basis::hex(blake3::hash(request.as_bytes()).as_bytes())
        );
        let row = JobRow {
            id: uuid::Uuid::now_v7().to_string(),
            kind: job.kind,
            dedup_key: dedup_key.clone(),
            request,
            libraries: serde_json::to_string(&job.libraries)
                .map_err(|e| Error::Internal(e.to_string()))?,
            state: JobState::Running.name().into(),
            progress: 0.0,
            message: "queued".into(),
            result: None,
            error: None,
            owner: self.server.clone(),
            lease_until: self.lease_until(),
            attempts: 1,
            created_at: now_ms(),
            finished_at: None,
        };
        if self.store.insert_job(&row).await? {
            let progress = self.runner(&row.id);
            return Ok((Job::from_row(row)?, Some(progress)));
        }
        match self.store.running_job(&dedup_key).await? {
            Some(running) => Ok((Job::from_row(running)?, None)),
            // It finished between the insert and the look: start it again.
            None => {
                Box::pin(
                    self.start(NewJob {
                        kind: row.kind,
                        request: serde_json::from_str(&row.request)
                            .map_err(|e| Error::Internal(e.to_string()))?,
                        libraries: job.libraries,
                    }),
                )
                .await
            }
        }
    }

    /// A handle on job `id`, run by this server, that writes its progress and renews its
    /// lease every [`FLUSH_EVERY`] until it finishes.
    fn runner(self: &Arc<Self>, id: &str) -> Progress {
        let progress = Progress {
            jobs: self.clone(),
            id: id.to_string(),
            latest: Arc::new(Mutex::new(Latest {
                progress: 0.0,
                message: "started".into(),
                done: false,
                lost: false,
                renewed: std::time::Instant::now(),
            })),
        };
        // The task holds the runner's state weakly: a runner gone without finishing (its
        // task panicked) stops renewing, so its lease runs out and the job is run again.
        let (jobs, id, latest) = (
            self.clone(),
            id.to_string(),
            Arc::downgrade(&progress.latest),
        );
        tokio::spawn(async move {
            let mut tick = tokio::time::interval(FLUSH_EVERY);
            loop {
                tick.tick().await;
                let Some(latest) = latest.upgrade() else {
                    return;
                };
                let p = Progress {
                    jobs: jobs.clone(),
                    id: id.clone(),
                    latest,
                };
                if !p.flush().await {
                    return;
                }
            }
        });
        progress
    }

    /// Take over one job whose server died (its lease ran out), if there is one: its kind,
    /// its stored request, and the handle to run it with.
    pub async fn take_over(self: &Arc<Self>) -> Result<Option<(String, String, Progress)>> {
        let Some(row) = self
            .store
            .take_over_job(&self.server, now_ms(), self.lease_until())
            .await?
        else {
            return Ok(None);
        };
        tracing::warn!(
            job = %row.id,
            kind = %row.kind,
            attempt = row.attempts,
            "taking over a job whose server stopped renewing it; running it again"
        );
        Ok(Some((
            row.kind.clone(),
            row.request.clone(),
            self.runner(&row.id),
        )))
    }

    /// Forget jobs finished more than [`KEEP_FINISHED`] ago.
    pub async fn prune(&self) -> Result<u64> {
        let before = now_ms() - KEEP_FINISHED.as_millis() as i64;
        Ok(self.store.prune_jobs(before).await?)
    }

    pub async fn get(&self, id: &str) -> Result<Option<Job>> {
        self.store.job(id).await?.map(Job::from_row).transpose()
    }

    /// Jobs `grant` may see, newest first, at most `limit`, of one state or every one.
    pub async fn list(
        &self,
        grant: &Grant,
        state: Option<JobState>,
        limit: usize,
    ) -> Result<Vec<Job>> {
        let limit = limit.min(MAX_JOBS_LISTED);
        let mut out = Vec::new();
        // A limited token sees a part of the rows: read more than asked, up to the cap.
        let rows = self
            .store
            .jobs(state.map(JobState::name), MAX_JOBS_LISTED)
            .await?;
        for r in rows {
            let job = Job::from_row(r)?;
            if job.visible_to(grant) {
                out.push(job);
                if out.len() == limit {
                    break;
                }
            }
        }
        Ok(out)
    }

    /// The job once it has finished, or as it is after `timeout` (a long poll: clients wait
    /// for a job without polling in a loop; the server polls the row, which any server may
    /// finish); `None` when there is no such job or `grant` may not see it (the same answer,
    /// so that a limited token learns nothing).
    pub async fn wait_for(
        &self,
        id: &str,
        timeout: Duration,
        grant: &Grant,
    ) -> Result<Option<Job>> {
        let deadline = tokio::time::Instant::now() + timeout;
        let mut poll = Duration::from_millis(20);
        loop {
            let Some(job) = self.get(id).await? else {
                return Ok(None);
            };
            if !job.visible_to(grant) {
                return Ok(None);
            }
            if job.state != JobState::Running || tokio::time::Instant::now() >= deadline {
                return Ok(Some(job));
            }
            tokio::time::sleep_until((tokio::time::Instant::now() + poll).min(deadline)).await;
            poll = (poll * 2).min(Duration::from_millis(250));
        }
    }
}

/// What a runner reported last, not yet written.
struct Latest {
    progress: f64,
    message: String,
    done: bool,
    /// Another server took the job over: this runner's writes are refused.
    lost: bool,
    /// When the lease was last renewed: past it by a lease, another server may have taken
    /// the job (the database away meanwhile), so the runner must not store its result.
    renewed: std::time::Instant,
}

/// A runner's handle on its job. [`Progress::report`] is cheap and synchronous (training
/// calls it from its worker threads); the handle's task writes the newest report.
#[derive(Clone)]
pub struct Progress {
    jobs: Arc<Jobs>,
    pub id: String,
    latest: Arc<Mutex<Latest>>,
}

impl Progress {
    /// Whether this runner may no longer own its job: another server took it over, or its
    /// lease has not been renewed for a lease's time. Checked before a result is stored.
    pub fn is_lost(&self) -> bool {
        let l = self.latest.lock().expect("progress lock");
        l.lost || l.renewed.elapsed() > self.jobs.lease
    }

    pub fn report(&self, progress: f64, message: impl Into<String>) {
        let mut l = self.latest.lock().expect("progress lock");
        l.progress = progress.clamp(0.0, 1.0);
        l.message = message.into();
    }

    /// Write the newest report and renew the lease; `false` once the job is finished here
    /// or owned by another server (the task stops).
    async fn flush(&self) -> bool {
        let (progress, message) = {
            let l = self.latest.lock().expect("progress lock");
            if l.done || l.lost {
                return false;
            }
            (l.progress, l.message.clone())
        };
        let j = &self.jobs;
        match j
            .store
            .job_progress(&self.id, &j.server, progress, &message, j.lease_until())
            .await
        {
            Ok(true) => {
                self.latest.lock().expect("progress lock").renewed = std::time::Instant::now();
                true
            }
            Ok(false) => {
                tracing::warn!(job = %self.id, "another server runs this job now");
                self.latest.lock().expect("progress lock").lost = true;
                false
            }
            // The database is away: keep trying; the lease says how long we may.
            Err(e) => {
                tracing::warn!(job = %self.id, error = %e, "could not renew a job's lease");
                true
            }
        }
    }

    async fn finish(&self, state: JobState, result: Option<String>, error: Option<&str>) {
        self.latest.lock().expect("progress lock").done = true;
        let j = &self.jobs;
        match j
            .store
            .finish_job(
                &self.id,
                &j.server,
                state.name(),
                result.as_deref(),
                error,
                now_ms(),
            )
            .await
        {
            Ok(true) => {}
            Ok(false) => tracing::warn!(job = %self.id, "finished a job another server runs now"),
            Err(e) => tracing::error!(job = %self.id, error = %e, "could not record a job's end"),
        }
    }

    pub async fn succeed(&self, result: serde_json::Value) {
        self.finish(JobState::Succeeded, Some(result.to_string()), None)
            .await;
    }

    pub async fn fail(&self, error: String) {
        self.finish(JobState::Failed, None, Some(&error)).await;
    }

    /// The job as stored now.
    pub async fn job(&self) -> Result<Job> {
        self.jobs
            .get(&self.id)
            .await?
            .ok_or_else(|| Error::Internal(format!("job {} vanished", self.id)))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn job(libraries: &[&str]) -> Job {
        Job {
            id: "j".into(),
            kind: "train-bases".into(),
            state: JobState::Running,
            progress: 0.0,
            message: String::new(),
            result: None,
            error: None,
            created_at: 0,
            finished_at: None,
            libraries: libraries.iter().map(|l| l.to_string()).collect(),
            attempts: 1,
        }
    }

    #[test]
    fn a_limited_token_sees_jobs_whose_takes_all_lie_in_its_libraries() {
        let grant = |libs: Option<&[&str]>| Grant {
            libraries: libs.map(|l| l.iter().map(|s| s.to_string()).collect()),
            ..Grant::everything()
        };
        assert!(job(&["a", "b"]).visible_to(&grant(None)));
        assert!(job(&["a"]).visible_to(&grant(Some(&["a", "b"]))));
        assert!(!job(&["a", "c"]).visible_to(&grant(Some(&["a", "b"]))));
        assert!(!job(&[]).visible_to(&grant(Some(&["a"]))));
    }

    #[test]
    fn states_read_back_as_they_are_written() {
        for s in [JobState::Running, JobState::Succeeded, JobState::Failed] {
            assert_eq!(s.name().parse::<JobState>(), Ok(s));
        }
        assert!("queued".parse::<JobState>().is_err());
    }
}
