//! Takes' motion features (table `take_features`, one row a take): the stored descriptors
//! and the stamp of the coding and body they were taken from, which a search compares
//! with the take's own to know them current.

use sqlx::Row;

use super::query::{self, Filter};
use super::{Result, StampRow, Store};

/// A take's stored features: the stamp they were taken from, their bytes
/// (`codec::features`), or why the take gave none.
#[derive(Debug, Clone, PartialEq)]
pub struct FeatureRow {
    pub stamp: StampRow,
    pub payload: Vec<u8>,
    pub failed: Option<String>,
}

/// A take a search may compare: what an answer names, its stamp now, and whether its
/// stored features are current (taken from the coding and body it has now: the rule
/// [`STAMP_MATCHES`] states, here and for [`Store::stale_features`] alike).
#[derive(Debug, Clone, PartialEq)]
pub struct Candidate {
    pub id: String,
    pub name: String,
    pub library: String,
    pub fps: f64,
    pub live: bool,
    pub stamp: StampRow,
    pub current: bool,
}

/// Whether a take's features row `f` was taken from the coding and body take `t` has now.
const STAMP_MATCHES: &str = "f.codec = t.codec AND f.stored_bytes = t.stored_bytes \
    AND f.frames = t.frames AND f.body_rev = t.body_rev";

fn stamp<R: Row>(r: &R, prefix: &str) -> Result<Option<StampRow>>
where
    for<'a> &'a str: sqlx::ColumnIndex<R>,
    for<'a> Option<String>: sqlx::Decode<'a, R::Database> + sqlx::Type<R::Database>,
    for<'a> Option<i64>: sqlx::Decode<'a, R::Database> + sqlx::Type<R::Database>,
{
    let codec: Option<String> = r.try_get(format!("{prefix}codec").as_str())?;
    let Some(codec) = codec else {
        return Ok(None);
    };
    let int = |c: &str| -> Result<i64> {
        Ok(
            r.try_get::<Option<i64>, _>(format!("{prefix}{c}").as_str())?
                .unwrap_or(-1),
        )
    };
    Ok(Some(StampRow {
        codec,
        stored_bytes: int("stored_bytes")?,
        frames: int("frames")?,
        body_rev: int("body_rev")?,
    }))
}

impl Store {
    /// Store `row` as take `id`'s features, only while the take is as `row.stamp` says (a
    /// take changed or deleted meanwhile keeps what it has); false if it was not.
    pub async fn put_features(&self, id: &str, row: &FeatureRow) -> Result<bool> {
        let sql = "INSERT INTO take_features \
            (take_key, codec, stored_bytes, frames, body_rev, payload, failed) \
            SELECT key, $2, $3, $4, $5, $6, $7 FROM takes \
            WHERE id = $1 AND codec = $2 AND stored_bytes = $3 AND frames = $4 \
            AND body_rev = $5 \
            ON CONFLICT (take_key) DO UPDATE SET codec = excluded.codec, \
            stored_bytes = excluded.stored_bytes, frames = excluded.frames, \
            body_rev = excluded.body_rev, payload = excluded.payload, failed = excluded.failed";
        let s = &row.stamp;
        dispatch!(self, pool => {
            let r = sqlx::query(sql)
                .bind(id)
                .bind(&s.codec)
                .bind(s.stored_bytes)
                .bind(s.frames)
                .bind(s.body_rev)
                .bind(row.payload.as_slice())
                .bind(row.failed.as_deref())
                .execute(pool)
                .await?;
            Ok(r.rows_affected() > 0)
        })
    }

    /// Every take matching `filter`, oldest first, with its stamp and its features' (no
    /// payloads: a search keeps those it has read, by stamp).
    pub async fn candidates(&self, filter: &Filter) -> Result<Vec<Candidate>> {
        let w = query::where_clause(filter, None);
        let sql = format!(
            "SELECT t.id, t.name, t.library, t.fps, t.live_until, t.codec, t.stored_bytes, \
             t.frames, t.body_rev, \
             CASE WHEN f.take_key IS NOT NULL AND ({STAMP_MATCHES}) THEN 1 ELSE 0 END AS current \
             FROM (SELECT key, id, name, library, fps, live_until, codec, stored_bytes, frames, \
             body_rev, created_at FROM takes {}) t \
             LEFT JOIN take_features f ON f.take_key = t.key ORDER BY t.created_at, t.key",
            w.text
        );
        dispatch!(self, pool => {
            let rows = bind_all!(sqlx::query(&sql), &w.values).fetch_all(pool).await?;
            rows.iter()
                .map(|r| {
                    Ok(Candidate {
                        id: r.try_get("id")?,
                        name: r.try_get("name")?,
                        library: r.try_get("library")?,
                        fps: r.try_get("fps")?,
                        live: r.try_get::<Option<i64>, _>("live_until")?.is_some(),
                        stamp: stamp(r, "")?.unwrap_or_default(),
                        current: r.try_get::<i32, _>("current")? == 1,
                    })
                })
                .collect()
        })
    }

    /// The stored features of `ids` (those that have any), in one query.
    pub async fn features_of(&self, ids: &[String]) -> Result<Vec<(String, FeatureRow)>> {
        if ids.is_empty() {
            return Ok(Vec::new());
        }
        let marks: Vec<String> = (1..=ids.len()).map(|i| format!("${i}")).collect();
        let sql = format!(
            "SELECT t.id AS take_id, f.codec, f.stored_bytes, f.frames, f.body_rev, f.payload, \
             f.failed FROM take_features f JOIN takes t ON t.key = f.take_key WHERE t.id IN ({})",
            marks.join(", ")
        );
        let values: Vec<query::Value> = ids.iter().map(|i| query::Value::Text(i.clone())).collect();
        dispatch!(self, pool => {
            let rows = bind_all!(sqlx::query(&sql), &values).fetch_all(pool).await?;
            rows.iter()
                .map(|r| {
                    Ok((
                        r.try_get("take_id")?,
                        FeatureRow {
                            stamp: stamp(r, "")?.unwrap_or_default(),
                            payload: r.try_get("payload")?,
                            failed: r.try_get("failed")?,
                        },
                    ))
                })
                .collect()
        })
    }

    /// Up to `limit` finished takes whose features are missing or were taken from another
    /// coding or body than they have now, in the order of their ids, after `after` (a
    /// cursor: the last id of the page before), so that takes that stay stale do not hide
    /// the ones after them.
    pub async fn stale_features(&self, after: Option<&str>, limit: usize) -> Result<Vec<String>> {
        let sql = format!(
            "SELECT t.id FROM takes t LEFT JOIN take_features f ON f.take_key = t.key \
             WHERE t.live_until IS NULL AND (f.take_key IS NULL OR NOT ({STAMP_MATCHES})) \
             AND t.id > $1 ORDER BY t.id LIMIT {limit}"
        );
        let after = after.unwrap_or("").to_string();
        dispatch!(self, pool => {
            Ok(sqlx::query_scalar::<_, String>(&sql).bind(after).fetch_all(pool).await?)
        })
    }

    /// Bytes of stored features, and how many takes have them (statistics).
    pub async fn features_bytes(&self) -> Result<(i64, i64)> {
        dispatch!(self, pool => {
            let r = sqlx::query(
                "SELECT COUNT(*) AS n, COALESCE(SUM(LENGTH(payload)), 0) AS b FROM take_features",
            )
            .fetch_one(pool)
            .await?;
            Ok((r.try_get("b")?, r.try_get("n")?))
        })
    }
}
