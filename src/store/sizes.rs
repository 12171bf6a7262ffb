//! What each table and index of the database takes on disk, as the database itself counts
//! it: SQLite's `dbstat` (every page of every b-tree, and the free list), Postgres's size
//! functions. The service says what each table holds ([`crate::service::storage`]).

use sqlx::Row;

use super::{Result, Store};

/// One table or index and its bytes.
#[derive(Debug, Clone, PartialEq)]
pub struct ObjectBytes {
    /// The table's or index's name.
    pub name: String,
    /// The table it belongs to (its own name for a table).
    pub table: String,
    pub index: bool,
    /// Bytes of the pages it takes (with Postgres, its TOAST table's too).
    pub bytes: i64,
    /// Of those, bytes no row uses (SQLite: unused room in its pages); `None` where the
    /// database does not say without reading every row (Postgres).
    pub unused: Option<i64>,
}

/// The database's bytes, object by object.
#[derive(Debug, Clone, PartialEq)]
pub struct DatabaseBytes {
    pub objects: Vec<ObjectBytes>,
    /// Pages that hold nothing and are kept for reuse (SQLite's free list); `None` where
    /// the database does not say (Postgres: `VACUUM` keeps such room inside each table).
    pub free: Option<i64>,
    /// The whole database (SQLite: the file's pages; Postgres: the schema's relations).
    pub total: i64,
}

impl Store {
    /// What each table and index takes. On SQLite this reads every page once (`dbstat`):
    /// a fraction of a second for an archive of a few hundred megabytes.
    pub async fn database_bytes(&self) -> Result<DatabaseBytes> {
        match self {
            Store::Sqlite(pool) => {
                let mut c = pool.acquire().await?;
                let rows = sqlx::query(
                    "SELECT s.name AS name, COALESCE(m.tbl_name, s.name) AS tbl, \
                     COALESCE(m.type, 'table') = 'index' AS is_index, \
                     SUM(s.pgsize) AS bytes, SUM(s.unused) AS unused \
                     FROM dbstat AS s LEFT JOIN sqlite_schema AS m ON m.name = s.name \
                     AND m.type IN ('table', 'index') \
                     GROUP BY s.name ORDER BY s.name",
                )
                .fetch_all(&mut *c)
                .await?;
                let page: i64 = sqlx::query_scalar("PRAGMA page_size")
                    .fetch_one(&mut *c)
                    .await?;
                let pages: i64 = sqlx::query_scalar("PRAGMA page_count")
                    .fetch_one(&mut *c)
                    .await?;
                let free: i64 = sqlx::query_scalar("PRAGMA freelist_count")
                    .fetch_one(&mut *c)
                    .await?;
                let objects = rows
                    .iter()
                    .map(|r| object(r, Some(r.try_get("unused")?)))
                    .collect::<Result<Vec<_>>>()?;
                Ok(DatabaseBytes {
                    objects,
                    free: Some(free * page),
                    total: pages * page,
                })
            }
            Store::Postgres(pool) => {
                // Tables with their TOAST, and each index, of the schema in use.
                let rows = sqlx::query(
                    "SELECT c.relname::text AS name, \
                     COALESCE(t.relname, c.relname)::text AS tbl, c.relkind = 'i' AS is_index, \
                     (CASE WHEN c.relkind = 'i' THEN pg_relation_size(c.oid) \
                      ELSE pg_table_size(c.oid) END)::bigint AS bytes \
                     FROM pg_class c \
                     LEFT JOIN pg_index x ON x.indexrelid = c.oid \
                     LEFT JOIN pg_class t ON t.oid = x.indrelid \
                     WHERE c.relnamespace = current_schema()::regnamespace \
                     AND c.relkind IN ('r', 'i') ORDER BY c.relname",
                )
                .fetch_all(pool)
                .await?;
                let objects = rows
                    .iter()
                    .map(|r| object(r, None))
                    .collect::<Result<Vec<_>>>()?;
                let total = objects.iter().map(|o| o.bytes).sum();
                Ok(DatabaseBytes {
                    objects,
                    free: None,
                    total,
                })
            }
        }
    }
}

/// A row of either backend's size query (`name`, `tbl`, `is_index`, `bytes`).
fn object<'r, R: Row>(r: &'r R, unused: Option<i64>) -> Result<ObjectBytes>
where
    &'static str: sqlx::ColumnIndex<R>,
    String: sqlx::Decode<'r, R::Database> + sqlx::Type<R::Database>,
    bool: sqlx::Decode<'r, R::Database> + sqlx::Type<R::Database>,
    i64: sqlx::Decode<'r, R::Database> + sqlx::Type<R::Database>,
{
    Ok(ObjectBytes {
        name: r.try_get("name")?,
        table: r.try_get("tbl")?,
        index: r.try_get("is_index")?,
        bytes: r.try_get("bytes")?,
        unused,
    })
}
