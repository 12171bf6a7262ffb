//! Shared bases: content-addressed rows, and the references takes hold on them.

use serde::{Deserialize, Serialize};
use sqlx::Row;

use super::{BeginWrite, Error, Result, Store};

/// A stored basis. `payload` is empty in listings (it can be megabytes).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct BasisRow {
    /// BLAKE3 of the payload, hex.
    pub id: String,
    pub kind: String,
    pub layout: String,
    pub points: i64,
    /// Shape, e.g. `3×31×31` (matrices × rows × columns).
    pub dims: String,
    #[serde(skip)]
    pub payload: Vec<u8>,
    /// Which takes, which parameters, the objective per iteration: JSON.
    pub provenance: serde_json::Value,
    /// Milliseconds since the Unix epoch.
    pub created_at: i64,
    /// How many takes reference it.
    pub used_by: i64,
}

/// What deleting a stored object (a basis, a skeleton) did.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Deletion {
    Deleted,
    NotFound,
    /// Takes still reference it; nothing was deleted.
    InUse(i64),
}

const COLUMNS: &str = "id, kind, layout, points, dims, provenance, created_at, \
    (SELECT COUNT(*) FROM take_bases sb WHERE sb.basis_id = bases.id) AS used_by";

fn basis_from_row<R: Row>(r: &R, with_payload: bool) -> Result<BasisRow>
where
    for<'a> &'a str: sqlx::ColumnIndex<R>,
    for<'a> String: sqlx::Decode<'a, R::Database> + sqlx::Type<R::Database>,
    for<'a> i64: sqlx::Decode<'a, R::Database> + sqlx::Type<R::Database>,
    for<'a> Vec<u8>: sqlx::Decode<'a, R::Database> + sqlx::Type<R::Database>,
{
    let provenance: String = r.try_get("provenance")?;
    Ok(BasisRow {
        id: r.try_get("id")?,
        kind: r.try_get("kind")?,
        layout: r.try_get("layout")?,
        points: r.try_get("points")?,
        dims: r.try_get("dims")?,
        payload: if with_payload {
            r.try_get("payload")?
        } else {
            Vec::new()
        },
        provenance: serde_json::from_str(&provenance)
            .map_err(|e| Error::Corrupt(format!("basis provenance JSON: {e}")))?,
        created_at: r.try_get("created_at")?,
        used_by: r.try_get("used_by")?,
    })
}

impl Store {
    /// Store a basis. Content addressed, so storing the same bytes again changes nothing;
    /// returns whether it was new.
    pub async fn insert_basis(&self, b: &BasisRow) -> Result<bool> {
        dispatch!(self, pool => {
            let r = sqlx::query(
                "INSERT INTO bases (id, kind, layout, points, dims, payload, provenance, created_at) \
                 VALUES ($1, $2, $3, $4, $5, $6, $7, $8) ON CONFLICT (id) DO NOTHING",
            )
            .bind(&b.id)
            .bind(&b.kind)
            .bind(&b.layout)
            .bind(b.points)
            .bind(&b.dims)
            .bind(&b.payload)
            .bind(b.provenance.to_string())
            .bind(b.created_at)
            .execute(pool)
            .await?;
            Ok(r.rows_affected() > 0)
        })
    }

    /// Whether a basis with this id is stored (its payload not read).
    pub async fn basis_exists(&self, id: &str) -> Result<bool> {
        dispatch!(self, pool => {
            Ok(sqlx::query("SELECT 1 AS one FROM bases WHERE id = $1")
                .bind(id)
                .fetch_optional(pool)
                .await?
                .is_some())
        })
    }

    /// A basis with its payload.
    pub async fn basis(&self, id: &str) -> Result<Option<BasisRow>> {
        let sql = format!("SELECT {COLUMNS}, payload FROM bases WHERE id = $1");
        dispatch!(self, pool => {
            sqlx::query(&sql)
                .bind(id)
                .fetch_optional(pool)
                .await?
                .map(|r| basis_from_row(&r, true))
                .transpose()
        })
    }

    /// Bases (without payloads), newest first, optionally of one layout and kind.
    pub async fn bases(&self, layout: Option<&str>, kind: Option<&str>) -> Result<Vec<BasisRow>> {
        let sql = format!(
            "SELECT {COLUMNS} FROM bases WHERE ($1 = '' OR layout = $2) AND ($3 = '' OR kind = $4) \
             ORDER BY created_at DESC, id"
        );
        let (l, k) = (layout.unwrap_or(""), kind.unwrap_or(""));
        dispatch!(self, pool => {
            sqlx::query(&sql)
                .bind(l)
                .bind(l)
                .bind(k)
                .bind(k)
                .fetch_all(pool)
                .await?
                .iter()
                .map(|r| basis_from_row(r, false))
                .collect()
        })
    }

    /// The newest basis of `kind` for `layout`, with its payload: what takes of that layout
    /// are coded with.
    pub async fn latest_basis(&self, layout: &str, kind: &str) -> Result<Option<BasisRow>> {
        let sql = format!(
            "SELECT {COLUMNS}, payload FROM bases WHERE layout = $1 AND kind = $2 \
             ORDER BY created_at DESC, id LIMIT 1"
        );
        dispatch!(self, pool => {
            sqlx::query(&sql)
                .bind(layout)
                .bind(kind)
                .fetch_optional(pool)
                .await?
                .map(|r| basis_from_row(&r, true))
                .transpose()
        })
    }

    /// For each basis used by takes of `libraries`, how many of those takes use it.
    pub async fn basis_use_within(
        &self,
        libraries: &[String],
    ) -> Result<std::collections::HashMap<String, i64>> {
        let sql = format!(
            "SELECT sb.basis_id AS id, COUNT(*) AS n FROM take_bases sb \
             JOIN takes s ON s.key = sb.take_key \
             WHERE s.library IN ({}) GROUP BY sb.basis_id",
            super::marks(1, libraries.len())
        );
        self.counts_by_id(&sql, libraries).await
    }

    /// Delete a basis unless a take references it.
    pub async fn delete_basis(&self, id: &str) -> Result<Deletion> {
        self.delete_unreferenced(
            "SELECT COUNT(*) AS n FROM take_bases WHERE basis_id = $1",
            "DELETE FROM bases WHERE id = $1",
            id,
        )
        .await
    }

    /// Delete a shared object (`delete`, by id) unless `count` finds takes referencing it:
    /// checked and deleted in one transaction, and the foreign key refuses it too, should
    /// another writer race us.
    pub(super) async fn delete_unreferenced(
        &self,
        count: &str,
        delete: &str,
        id: &str,
    ) -> Result<Deletion> {
        dispatch!(self, pool => {
            let mut tx = pool.begin_write().await?;
            let used: i64 = sqlx::query(count)
                .bind(id)
                .fetch_one(&mut *tx)
                .await?
                .try_get("n")?;
            if used > 0 {
                return Ok(Deletion::InUse(used));
            }
            let r = sqlx::query(delete).bind(id).execute(&mut *tx).await;
            match r {
                Ok(r) if r.rows_affected() == 0 => Ok(Deletion::NotFound),
                Ok(_) => {
                    tx.commit().await?;
                    Ok(Deletion::Deleted)
                }
                Err(sqlx::Error::Database(d)) if d.is_foreign_key_violation() => {
                    Ok(Deletion::InUse(1))
                }
                Err(e) => Err(e.into()),
            }
        })
    }
}
