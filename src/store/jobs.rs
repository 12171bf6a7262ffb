//! Job rows: background work (training bases) every server sees, run by one server under a
//! lease ([`crate::service::jobs`] decides; this keeps the rows).

use sqlx::Row;

use super::{Result, Store};

/// A stored job. `request` and `result` are JSON text, `libraries` a JSON array.
#[derive(Debug, Clone, PartialEq)]
pub struct JobRow {
    pub id: String,
    pub kind: String,
    pub dedup_key: String,
    pub request: String,
    pub libraries: String,
    pub state: String,
    pub progress: f64,
    pub message: String,
    pub result: Option<String>,
    pub error: Option<String>,
    pub owner: String,
    pub lease_until: i64,
    pub attempts: i64,
    pub created_at: i64,
    pub finished_at: Option<i64>,
}

const COLUMNS: &str = "id, kind, dedup_key, request, libraries, state, progress, message, \
    result, error, owner, lease_until, attempts, created_at, finished_at";

fn job_from_row<R: Row>(r: &R) -> Result<JobRow>
where
    for<'a> &'a str: sqlx::ColumnIndex<R>,
    for<'a> String: sqlx::Decode<'a, R::Database> + sqlx::Type<R::Database>,
    for<'a> Option<String>: sqlx::Decode<'a, R::Database> + sqlx::Type<R::Database>,
    for<'a> i64: sqlx::Decode<'a, R::Database> + sqlx::Type<R::Database>,
    for<'a> Option<i64>: sqlx::Decode<'a, R::Database> + sqlx::Type<R::Database>,
    for<'a> f64: sqlx::Decode<'a, R::Database> + sqlx::Type<R::Database>,
{
    Ok(JobRow {
        id: r.try_get("id")?,
        kind: r.try_get("kind")?,
        dedup_key: r.try_get("dedup_key")?,
        request: r.try_get("request")?,
        libraries: r.try_get("libraries")?,
        state: r.try_get("state")?,
        progress: r.try_get("progress")?,
        message: r.try_get("message")?,
        result: r.try_get("result")?,
        error: r.try_get("error")?,
        owner: r.try_get("owner")?,
        lease_until: r.try_get("lease_until")?,
        attempts: r.try_get("attempts")?,
        created_at: r.try_get("created_at")?,
        finished_at: r.try_get("finished_at")?,
    })
}

impl Store {
    /// Insert a running job unless one with its `dedup_key` is running already: `false`
    /// then (the unique index on running jobs' keys decides, so two servers racing insert
    /// one).
    pub async fn insert_job(&self, j: &JobRow) -> Result<bool> {
        let sql = format!(
            "INSERT INTO jobs ({COLUMNS}) VALUES ($1, $2, $3, $4, $5, $6, $7, $8, $9, $10, \
             $11, $12, $13, $14, $15) ON CONFLICT DO NOTHING"
        );
        dispatch!(self, pool => {
            let done = sqlx::query(&sql)
                .bind(&j.id)
                .bind(&j.kind)
                .bind(&j.dedup_key)
                .bind(&j.request)
                .bind(&j.libraries)
                .bind(&j.state)
                .bind(j.progress)
                .bind(&j.message)
                .bind(&j.result)
                .bind(&j.error)
                .bind(&j.owner)
                .bind(j.lease_until)
                .bind(j.attempts)
                .bind(j.created_at)
                .bind(j.finished_at)
                .execute(pool)
                .await?;
            Ok(done.rows_affected() == 1)
        })
    }

    /// The running job of `dedup_key`, if any.
    pub async fn running_job(&self, dedup_key: &str) -> Result<Option<JobRow>> {
        let sql = format!("SELECT {COLUMNS} FROM jobs WHERE dedup_key = $1 AND state = 'running'");
        dispatch!(self, pool => {
            sqlx::query(&sql)
                .bind(dedup_key)
                .fetch_optional(pool)
                .await?
                .map(|r| job_from_row(&r))
                .transpose()
        })
    }

    pub async fn job(&self, id: &str) -> Result<Option<JobRow>> {
        let sql = format!("SELECT {COLUMNS} FROM jobs WHERE id = $1");
        dispatch!(self, pool => {
            sqlx::query(&sql)
                .bind(id)
                .fetch_optional(pool)
                .await?
                .map(|r| job_from_row(&r))
                .transpose()
        })
    }

    /// Jobs newest first, at most `limit`, of one state or every one.
    pub async fn jobs(&self, state: Option<&str>, limit: usize) -> Result<Vec<JobRow>> {
        let sql = format!(
            "SELECT {COLUMNS} FROM jobs WHERE ($1 = '' OR state = $2) \
             ORDER BY created_at DESC, id DESC LIMIT $3"
        );
        let s = state.unwrap_or("");
        dispatch!(self, pool => {
            sqlx::query(&sql)
                .bind(s)
                .bind(s)
                .bind(limit as i64)
                .fetch_all(pool)
                .await?
                .iter()
                .map(job_from_row)
                .collect()
        })
    }

    /// Record a running job's progress and renew its lease, if `owner` still runs it:
    /// `false` when another server has taken it over (or it has finished).
    pub async fn job_progress(
        &self,
        id: &str,
        owner: &str,
        progress: f64,
        message: &str,
        lease_until: i64,
    ) -> Result<bool> {
        const SQL: &str = "UPDATE jobs SET progress = $1, message = $2, lease_until = $3 \
            WHERE id = $4 AND owner = $5 AND state = 'running'";
        dispatch!(self, pool => {
            let done = sqlx::query(SQL)
                .bind(progress)
                .bind(message)
                .bind(lease_until)
                .bind(id)
                .bind(owner)
                .execute(pool)
                .await?;
            Ok(done.rows_affected() == 1)
        })
    }

    /// Finish a job `owner` runs (`succeeded` with `result`, or `failed` with `error`):
    /// `false` when it no longer runs it.
    pub async fn finish_job(
        &self,
        id: &str,
        owner: &str,
        state: &str,
        result: Option<&str>,
        error: Option<&str>,
        finished_at: i64,
    ) -> Result<bool> {
        const SQL: &str = "UPDATE jobs SET state = $1, result = $2, error = $3, \
            finished_at = $4, progress = CASE WHEN $5 = 'succeeded' THEN 1.0 ELSE progress END, \
            message = $6 WHERE id = $7 AND owner = $8 AND state = 'running'";
        dispatch!(self, pool => {
            let done = sqlx::query(SQL)
                .bind(state)
                .bind(result)
                .bind(error)
                .bind(finished_at)
                .bind(state)
                .bind(if state == "succeeded" { "done" } else { "failed" })
                .bind(id)
                .bind(owner)
                .execute(pool)
                .await?;
            Ok(done.rows_affected() == 1)
        })
    }

    /// Take over the oldest running job whose lease ran out before `now` (its server died),
    /// as `owner` until `lease_until`; the job as taken over, or `None`. The lease is checked
    /// again in the update, so of two servers racing for one job, one gets it.
    pub async fn take_over_job(
        &self,
        owner: &str,
        now: i64,
        lease_until: i64,
    ) -> Result<Option<JobRow>> {
        let sql = format!(
            "UPDATE jobs SET owner = $1, lease_until = $2, attempts = attempts + 1, \
             progress = 0, message = 'taken over after its server stopped; started again' \
             WHERE id = (SELECT id FROM jobs WHERE state = 'running' AND lease_until < $3 \
             ORDER BY created_at LIMIT 1) AND state = 'running' AND lease_until < $4 \
             RETURNING {COLUMNS}"
        );
        dispatch!(self, pool => {
            sqlx::query(&sql)
                .bind(owner)
                .bind(lease_until)
                .bind(now)
                .bind(now)
                .fetch_optional(pool)
                .await?
                .map(|r| job_from_row(&r))
                .transpose()
        })
    }

    /// Forget finished jobs older than `before` (ms since the epoch).
    pub async fn prune_jobs(&self, before: i64) -> Result<u64> {
        const SQL: &str = "DELETE FROM jobs WHERE state <> 'running' AND finished_at < $1";
        dispatch!(self, pool => {
            Ok(sqlx::query(SQL).bind(before).execute(pool).await?.rows_affected())
        })
    }
}
