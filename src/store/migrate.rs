//! What a migration does that SQL cannot: migration 0018's packing of every take's record
//! ([`super::packed`]). Run by [`Store::open`] after the SQL migrations, every time: a store
//! that has nothing left to pack answers one catalogue query.

use sqlx::Row;

use super::{packed, BeginWrite, Result, Store};

/// Rows packed per round trip.
const PACK_AT_ONCE: i64 = 256;

impl Store {
    /// Pack the records migration 0018 set aside as JSON text (`meta_text`) into `meta`, then
    /// drop `meta_text`, in one transaction: a store is either all packed or as it was. On
    /// Postgres the table is locked against writes first, and whether there is anything to
    /// pack asked after: a server that opens while another packs waits, then finds it done.
    pub(crate) async fn pack_records(&self) -> Result<()> {
        dispatch!(self, pool => {
            let mut tx = pool.begin_write().await?;
            if let Store::Postgres(_) = self {
                sqlx::query("LOCK TABLE takes IN EXCLUSIVE MODE").execute(&mut *tx).await?;
            }
            let left: Option<i64> = sqlx::query_scalar(match self {
                Store::Sqlite(_) => {
                    "SELECT 1 FROM pragma_table_info('takes') WHERE name = 'meta_text'"
                }
                Store::Postgres(_) => {
                    "SELECT 1::BIGINT FROM information_schema.columns WHERE table_schema = \
                     current_schema() AND table_name = 'takes' AND column_name = 'meta_text'"
                }
            })
            .fetch_optional(&mut *tx)
            .await?;
            if left.is_none() {
                tx.commit().await?;
                return Ok(());
            }
            let mut after = String::new();
            loop {
                let rows = sqlx::query(
                    "SELECT id, meta_text FROM takes WHERE id > $1 ORDER BY id LIMIT $2",
                )
                .bind(&after)
                .bind(PACK_AT_ONCE)
                .fetch_all(&mut *tx)
                .await?;
                let Some(last) = rows.last() else { break };
                after = last.try_get("id")?;
                for r in &rows {
                    let id: String = r.try_get("id")?;
                    let text: String = r.try_get("meta_text")?;
                    sqlx::query("UPDATE takes SET meta = $1 WHERE id = $2")
                        .bind(packed::pack(&text)?)
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
