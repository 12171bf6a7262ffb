//! Skeletons: content-addressed rows, and the references takes hold on them (a take's
//! `skeleton_id` column, a foreign key that refuses deleting one still in use).

use serde::Serialize;
use sqlx::Row;

use super::{Deletion, Result, Store};

/// A stored skeleton. `payload` (the `codec::Skeleton` bytes) is empty in listings.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct SkeletonRow {
    /// BLAKE3 of the payload, hex.
    pub id: String,
    /// Layout signature of the takes of this skeleton.
    pub layout: String,
    /// Joints, End Sites included.
    pub joints: i64,
    #[serde(skip)]
    pub payload: Vec<u8>,
    /// Milliseconds since the Unix epoch.
    pub created_at: i64,
    /// How many takes reference it.
    pub used_by: i64,
    /// The format of the file it was uploaded from (`POST /v1/skeletons`); `None` for a
    /// take's skeleton, stored with the take.
    pub uploaded_as: Option<String>,
}

const COLUMNS: &str = "id, layout, joints, created_at, uploaded_as, \
    (SELECT COUNT(*) FROM takes s WHERE s.skeleton_id = skeletons.id) AS used_by";

pub(super) const INSERT: &str = "INSERT INTO skeletons (id, layout, joints, payload, created_at) \
    VALUES ($1, $2, $3, $4, $5) ON CONFLICT (id) DO NOTHING";

fn skeleton_from_row<R: Row>(r: &R, with_payload: bool) -> Result<SkeletonRow>
where
    for<'a> &'a str: sqlx::ColumnIndex<R>,
    for<'a> String: sqlx::Decode<'a, R::Database> + sqlx::Type<R::Database>,
    for<'a> i64: sqlx::Decode<'a, R::Database> + sqlx::Type<R::Database>,
    for<'a> Vec<u8>: sqlx::Decode<'a, R::Database> + sqlx::Type<R::Database>,
    for<'a> Option<String>: sqlx::Decode<'a, R::Database> + sqlx::Type<R::Database>,
{
    Ok(SkeletonRow {
        id: r.try_get("id")?,
        layout: r.try_get("layout")?,
        joints: r.try_get("joints")?,
        payload: if with_payload {
            r.try_get("payload")?
        } else {
            Vec::new()
        },
        created_at: r.try_get("created_at")?,
        used_by: r.try_get("used_by")?,
        uploaded_as: r.try_get("uploaded_as")?,
    })
}

impl Store {
    /// A skeleton with its payload.
    pub async fn skeleton(&self, id: &str) -> Result<Option<SkeletonRow>> {
        let sql = format!("SELECT {COLUMNS}, payload FROM skeletons WHERE id = $1");
        dispatch!(self, pool => {
            sqlx::query(&sql)
                .bind(id)
                .fetch_optional(pool)
                .await?
                .map(|r| skeleton_from_row(&r, true))
                .transpose()
        })
    }

    /// Store an uploaded skeleton (`row.uploaded_as` set) and the character file it skins,
    /// unless one of its id is stored already: whether it was new.
    pub async fn insert_skeleton(
        &self,
        row: &SkeletonRow,
        character: Option<&[u8]>,
    ) -> Result<bool> {
        const SQL: &str = "INSERT INTO skeletons \
            (id, layout, joints, payload, created_at, uploaded_as, character_file) \
            VALUES ($1, $2, $3, $4, $5, $6, $7) ON CONFLICT (id) DO NOTHING";
        dispatch!(self, pool => {
            let done = sqlx::query(SQL)
                .bind(&row.id)
                .bind(&row.layout)
                .bind(row.joints)
                .bind(&row.payload)
                .bind(row.created_at)
                .bind(&row.uploaded_as)
                .bind(character)
                .execute(pool)
                .await?;
            Ok(done.rows_affected() == 1)
        })
    }

    /// The character file an uploaded skeleton skins, if it has one.
    pub async fn skeleton_character(&self, id: &str) -> Result<Option<Vec<u8>>> {
        const SQL: &str = "SELECT character_file FROM skeletons WHERE id = $1";
        dispatch!(self, pool => {
            Ok(sqlx::query_scalar::<_, Option<Vec<u8>>>(SQL)
                .bind(id)
                .fetch_optional(pool)
                .await?
                .flatten())
        })
    }

    /// Skeletons (without payloads), newest first, optionally of one layout.
    pub async fn skeletons(&self, layout: Option<&str>) -> Result<Vec<SkeletonRow>> {
        let sql = format!(
            "SELECT {COLUMNS} FROM skeletons WHERE ($1 = '' OR layout = $2) \
             ORDER BY created_at DESC, id"
        );
        let l = layout.unwrap_or("");
        dispatch!(self, pool => {
            sqlx::query(&sql)
                .bind(l)
                .bind(l)
                .fetch_all(pool)
                .await?
                .iter()
                .map(|r| skeleton_from_row(r, false))
                .collect()
        })
    }

    /// For each skeleton of takes of `libraries`, how many of those takes have it.
    pub async fn skeleton_use_within(
        &self,
        libraries: &[String],
    ) -> Result<std::collections::HashMap<String, i64>> {
        let sql = format!(
            "SELECT skeleton_id AS id, COUNT(*) AS n FROM takes \
             WHERE skeleton_id IS NOT NULL AND library IN ({}) GROUP BY skeleton_id",
            super::marks(1, libraries.len())
        );
        self.counts_by_id(&sql, libraries).await
    }

    /// Delete a skeleton unless a take references it.
    pub async fn delete_skeleton(&self, id: &str) -> Result<Deletion> {
        self.delete_unreferenced(
            "SELECT COUNT(*) AS n FROM takes WHERE skeleton_id = $1",
            "DELETE FROM skeletons WHERE id = $1",
            id,
        )
        .await
    }
}
