//! API tokens (by the hash of their secret, never the secret) and the audit log.

use serde::Serialize;
use sqlx::Row;

use super::{conflict_or, Result, Store};

/// A stored token. The secret itself is never stored; `secret_hash` is what lookups use.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct TokenRow {
    pub id: String,
    pub name: String,
    #[serde(skip)]
    pub secret_hash: Vec<u8>,
    /// `read`, `write` or `admin`, parsed by the service.
    pub scope: String,
    /// A JSON array of library names, or `None` for every library; parsed by the service.
    pub libraries: Option<String>,
    /// Milliseconds since the Unix epoch, as every time here.
    pub created_at: i64,
    pub expires_at: Option<i64>,
    pub revoked_at: Option<i64>,
    /// When a request last presented it (to the minute; see `service::access`).
    pub last_used_at: Option<i64>,
}

/// One audited request or command, or a count of like ones.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct AuditRow {
    /// Increasing; the cursor of the next page.
    pub seq: i64,
    pub at: i64,
    pub token_id: Option<String>,
    pub token_name: Option<String>,
    /// What was asked, e.g. `DELETE /v1/takes/{id}` or `token create`.
    pub action: String,
    /// What it was asked of: the request's path, or the token's id.
    pub target: String,
    /// The HTTP status it ended with (the CLI's commands record 200 or 500 likewise).
    pub status: i64,
    pub detail: String,
    /// How many requests the row stands for: 1 for a change, more for refused or failed
    /// requests counted together (same caller, status and minute; `target` is the first's).
    pub count: i64,
}

const TOKEN_COLUMNS: &str =
    "id, name, secret_hash, scope, libraries, created_at, expires_at, revoked_at, last_used_at";

fn token_from_row<R: Row>(r: &R) -> Result<TokenRow>
where
    for<'a> &'a str: sqlx::ColumnIndex<R>,
    for<'a> String: sqlx::Decode<'a, R::Database> + sqlx::Type<R::Database>,
    for<'a> i64: sqlx::Decode<'a, R::Database> + sqlx::Type<R::Database>,
    for<'a> Vec<u8>: sqlx::Decode<'a, R::Database> + sqlx::Type<R::Database>,
{
    Ok(TokenRow {
        id: r.try_get("id")?,
        name: r.try_get("name")?,
        secret_hash: r.try_get("secret_hash")?,
        scope: r.try_get("scope")?,
        libraries: r.try_get("libraries")?,
        created_at: r.try_get("created_at")?,
        expires_at: r.try_get("expires_at")?,
        revoked_at: r.try_get("revoked_at")?,
        last_used_at: r.try_get("last_used_at")?,
    })
}

fn audit_from_row<R: Row>(r: &R) -> Result<AuditRow>
where
    for<'a> &'a str: sqlx::ColumnIndex<R>,
    for<'a> String: sqlx::Decode<'a, R::Database> + sqlx::Type<R::Database>,
    for<'a> i64: sqlx::Decode<'a, R::Database> + sqlx::Type<R::Database>,
    for<'a> i32: sqlx::Decode<'a, R::Database> + sqlx::Type<R::Database>,
{
    Ok(AuditRow {
        seq: r.try_get("seq")?,
        at: r.try_get("at")?,
        token_id: r.try_get("token_id")?,
        token_name: r.try_get("token_name")?,
        action: r.try_get("action")?,
        target: r.try_get("target")?,
        status: i64::from(r.try_get::<i32, _>("status")?),
        detail: r.try_get("detail")?,
        count: r.try_get("count")?,
    })
}

impl Store {
    /// Store a new token; a name or secret hash already taken is a `Conflict`.
    pub async fn insert_token(&self, t: &TokenRow) -> Result<()> {
        dispatch!(self, pool => {
            sqlx::query(&format!(
                "INSERT INTO tokens ({TOKEN_COLUMNS}) VALUES ($1, $2, $3, $4, $5, $6, $7, $8, $9)"
            ))
            .bind(&t.id)
            .bind(&t.name)
            .bind(&t.secret_hash)
            .bind(&t.scope)
            .bind(&t.libraries)
            .bind(t.created_at)
            .bind(t.expires_at)
            .bind(t.revoked_at)
            .bind(t.last_used_at)
            .execute(pool)
            .await
            .map_err(|e| conflict_or(e, &format!("token {:?}", t.name)))?;
            Ok(())
        })
    }

    /// The token whose secret hashes to `hash`, revoked or not.
    pub async fn token_by_hash(&self, hash: &[u8]) -> Result<Option<TokenRow>> {
        let sql = format!("SELECT {TOKEN_COLUMNS} FROM tokens WHERE secret_hash = $1");
        dispatch!(self, pool => {
            sqlx::query(&sql)
                .bind(hash)
                .fetch_optional(pool)
                .await?
                .map(|r| token_from_row(&r))
                .transpose()
        })
    }

    /// The token with this id, revoked or not.
    pub async fn token_by_id(&self, id: &str) -> Result<Option<TokenRow>> {
        let sql = format!("SELECT {TOKEN_COLUMNS} FROM tokens WHERE id = $1");
        dispatch!(self, pool => {
            sqlx::query(&sql)
                .bind(id)
                .fetch_optional(pool)
                .await?
                .map(|r| token_from_row(&r))
                .transpose()
        })
    }

    /// Every token, oldest first.
    pub async fn tokens(&self) -> Result<Vec<TokenRow>> {
        let sql = format!("SELECT {TOKEN_COLUMNS} FROM tokens ORDER BY created_at, id");
        dispatch!(self, pool => {
            sqlx::query(&sql)
                .fetch_all(pool)
                .await?
                .iter()
                .map(token_from_row)
                .collect()
        })
    }

    /// Whether any token was ever created (revoked ones count: revoking the last token must
    /// not open the archive to everyone).
    pub async fn any_token(&self) -> Result<bool> {
        dispatch!(self, pool => {
            Ok(sqlx::query("SELECT 1 AS one FROM tokens LIMIT 1")
                .fetch_optional(pool)
                .await?
                .is_some())
        })
    }

    /// Mark the token with this id or name revoked at `now`; false if there is no such
    /// token or it was revoked already.
    pub async fn revoke_token(&self, id_or_name: &str, now: i64) -> Result<bool> {
        dispatch!(self, pool => {
            Ok(sqlx::query(
                "UPDATE tokens SET revoked_at = $1 \
                 WHERE (id = $2 OR name = $3) AND revoked_at IS NULL",
            )
            .bind(now)
            .bind(id_or_name)
            .bind(id_or_name)
            .execute(pool)
            .await?
            .rows_affected()
                > 0)
        })
    }

    /// Note that the token `id` was presented at `at`.
    pub async fn touch_token(&self, id: &str, at: i64) -> Result<()> {
        dispatch!(self, pool => {
            sqlx::query("UPDATE tokens SET last_used_at = $1 WHERE id = $2")
                .bind(at)
                .bind(id)
                .execute(pool)
                .await?;
            Ok(())
        })
    }

    /// Append to the audit log.
    pub async fn audit(&self, a: &AuditRow) -> Result<()> {
        dispatch!(self, pool => {
            sqlx::query(
                "INSERT INTO audit_log \
                 (at, token_id, token_name, action, target, status, detail, count) \
                 VALUES ($1, $2, $3, $4, $5, $6, $7, $8)",
            )
            .bind(a.at)
            .bind(&a.token_id)
            .bind(&a.token_name)
            .bind(&a.action)
            .bind(&a.target)
            .bind(a.status as i32)
            .bind(&a.detail)
            .bind(a.count)
            .execute(pool)
            .await?;
            Ok(())
        })
    }

    /// Delete audit entries from before `before` (ms since the epoch); how many.
    pub async fn prune_audit(&self, before: i64) -> Result<u64> {
        dispatch!(self, pool => {
            Ok(sqlx::query("DELETE FROM audit_log WHERE at < $1")
                .bind(before)
                .execute(pool)
                .await?
                .rows_affected())
        })
    }

    /// Audit entries newest first, `limit` at a time, before `before` (a `seq`) when given.
    pub async fn audit_log(&self, before: Option<i64>, limit: usize) -> Result<Vec<AuditRow>> {
        dispatch!(self, pool => {
            sqlx::query(
                "SELECT seq, at, token_id, token_name, action, target, status, detail, count \
                 FROM audit_log WHERE seq < $1 ORDER BY seq DESC LIMIT $2",
            )
            .bind(before.unwrap_or(i64::MAX))
            .bind(limit as i64)
            .fetch_all(pool)
            .await?
            .iter()
            .map(audit_from_row)
            .collect()
        })
    }
}
