//! What a migration does that SQL cannot: migration 0018's packing of every take's record
//! ([`super::packed`]). [`Store::open`] runs the SQL migrations up to 0018, then this, then
//! the rest, so that a later migration never meets a store half packed; and it runs this
//! at every open, where a store with nothing left to pack answers one catalogue query.

use sqlx::Row;

use super::{packed, BeginWrite, Error, Result, Store};

/// Rows packed per round trip.
const PACK_AT_ONCE: i64 = 256;

/// The migration after which [`Store::pack_records`] runs.
pub(crate) const PACKED_RECORDS: i64 = 18;

/// SQLite's and Postgres's question: is `takes.meta_text` (0018's JSON text) still there?
const SQLITE_LEFT: &str = "SELECT 1 FROM pragma_table_info('takes') WHERE name = 'meta_text'";
const POSTGRES_LEFT: &str = "SELECT 1::BIGINT FROM information_schema.columns WHERE \
    table_schema = current_schema() AND table_name = 'takes' AND column_name = 'meta_text'";

/// Run the migrations in `$dir` over `$store`'s `$pool`: those up to [`PACKED_RECORDS`],
/// the packing, then the rest.
macro_rules! migrate {
    ($store:expr, $pool:expr, $dir:literal) => {{
        let mut first = sqlx::migrate!($dir);
        first.migrations = first
            .migrations
            .iter()
            .filter(|m| m.version <= $crate::store::migrate::PACKED_RECORDS)
            .cloned()
            .collect::<Vec<_>>()
            .into();
        // A store already past them has the later ones applied: not this run's business.
        first.set_ignore_missing(true);
        first.run($pool).await?;
        $store.pack_records().await?;
        sqlx::migrate!($dir).run($pool).await?;
    }};
}
pub(crate) use migrate;

impl Store {
    /// Pack the records migration 0018 set aside as JSON text (`meta_text`) into `meta`, then
    /// drop `meta_text`, in one transaction: a store is either all packed or as it was. On
    /// Postgres the table is locked against writes, and the question asked again, only when
    /// there is something to pack: a server that opens while another packs waits, then
    /// finds it done.
    ///
    /// A text that is not UTF-8 (SQLite keeps what it was given) is kept as it was, not
    /// packed: that take then reads as corrupt, which `verify` reports, and its bytes are
    /// there to mend; the rest of the store opens.
    pub(crate) async fn pack_records(&self) -> Result<()> {
        // The text as bytes: SQLite keeps whatever a column was given.
        let (left, select) = match self {
            Store::Sqlite(_) => (
                SQLITE_LEFT,
                "SELECT id, CAST(meta_text AS BLOB) AS text FROM takes WHERE meta IS NULL \
                 ORDER BY id LIMIT $1",
            ),
            Store::Postgres(_) => (
                POSTGRES_LEFT,
                "SELECT id, convert_to(meta_text, 'UTF8') AS text FROM takes WHERE meta IS NULL \
                 ORDER BY id LIMIT $1",
            ),
        };
        dispatch!(self, pool => {
            if sqlx::query_scalar::<_, i64>(left).fetch_optional(pool).await?.is_none() {
                return Ok(());
            }
            let mut tx = pool.begin_write().await?;
            if let Store::Postgres(_) = self {
                sqlx::query("LOCK TABLE takes IN EXCLUSIVE MODE").execute(&mut *tx).await?;
                if sqlx::query_scalar::<_, i64>(left).fetch_optional(&mut *tx).await?.is_none() {
                    tx.commit().await?;
                    return Ok(());
                }
            }
            loop {
                let rows = sqlx::query(select)
                .bind(PACK_AT_ONCE)
                .fetch_all(&mut *tx)
                .await?;
                if rows.is_empty() {
                    break;
                }
                for r in &rows {
                    let id: String = r.try_get("id")?;
                    let text: Vec<u8> = r.try_get("text")?;
                    let meta = match std::str::from_utf8(&text) {
                        Ok(text) => packed::pack(text).map_err(|e| match e {
                            Error::Corrupt(m) => Error::Corrupt(format!("take {id}: {m}")),
                            e => e,
                        })?,
                        Err(_) => text,
                    };
                    sqlx::query("UPDATE takes SET meta = $1 WHERE id = $2")
                        .bind(meta)
                        .bind(&id)
                        .execute(&mut *tx)
                        .await?;
                }
            }
            sqlx::query("ALTER TABLE takes DROP COLUMN meta_text").execute(&mut *tx).await?;
            if let Store::Postgres(_) = self {
                sqlx::query("ALTER TABLE takes ALTER COLUMN meta SET NOT NULL")
                    .execute(&mut *tx)
                    .await?;
            }
            tx.commit().await?;
            Ok(())
        })
    }
}
