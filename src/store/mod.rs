//! Persistence: takes (metadata, codec header, chunks, tags) in SQLite — one file, zero set-up,
//! the default — or Postgres. Migrations for each live in `migrations/{sqlite,postgres}` and run
//! when the store opens.
//!
//! Both backends run the same SQL text (numbered `$n` placeholders, each used once in order,
//! which SQLite binds by position too); the `dispatch!` macro expands one body for either pool, so a
//! query is written once.
//!
//! A take and its chunks go in one transaction: readers never see half a take, and a failed
//! ingest leaves nothing behind. Chunk payloads are checked against their CRC-32C on read.

pub mod packed;
pub mod query;
mod rows;

use std::collections::HashMap;
use std::str::FromStr;
use std::time::Duration;

use sqlx::postgres::{PgPool, PgPoolOptions};
use sqlx::sqlite::{
    SqliteConnectOptions, SqliteJournalMode, SqlitePool, SqlitePoolOptions, SqliteSynchronous,
};
use sqlx::Row;

pub use query::{Cursor, Filter, Part, SortKey, StatRow, Totals};
pub use rows::{
    disk_bytes, AnalogRows, ChunkEntry, ChunkRow, LabelRow, NewTake, ParametersRow, StampRow,
    TakeRow, TakeTotals,
};

/// Errors of the store layer.
#[derive(Debug, thiserror::Error)]
pub enum Error {
    #[error("database: {0}")]
    Database(#[from] sqlx::Error),
    #[error("migration: {0}")]
    Migrate(#[from] sqlx::migrate::MigrateError),
    #[error("unsupported database URL {0:?}: use sqlite://FILE or postgres://…")]
    Url(String),
    /// Stored bytes that fail their checksum or do not parse.
    #[error("corrupt data in the store: {0}")]
    Corrupt(String),
    #[error("{0} already exists")]
    Conflict(String),
}

impl Error {
    /// Whether the database could not be reached or asked to wait (down, restarting, its
    /// connections all taken, a SQLite file locked past the busy timeout), rather than
    /// refusing this request: worth a retry later, not a fault of the request or the data.
    pub fn is_unavailable(&self) -> bool {
        let Error::Database(e) = self else {
            return false;
        };
        match e {
            sqlx::Error::Io(_)
            | sqlx::Error::Tls(_)
            | sqlx::Error::Protocol(_)
            | sqlx::Error::PoolTimedOut
            | sqlx::Error::PoolClosed
            | sqlx::Error::WorkerCrashed => true,
            sqlx::Error::Database(d) => match d.code().as_deref() {
                // Postgres: connection exceptions (class 08), shutting down or starting up
                // (57P01–57P03), too many connections (53300).
                Some(c) if c.starts_with("08") => true,
                Some("57P01" | "57P02" | "57P03" | "53300") => true,
                // SQLite: busy or locked past the busy timeout.
                Some("5" | "6" | "261" | "517" | "773") => true,
                _ => false,
            },
            _ => false,
        }
    }
}

pub type Result<T, E = Error> = std::result::Result<T, E>;

/// A connection pool to one of the two backends.
#[derive(Clone, Debug)]
pub enum Store {
    Sqlite(SqlitePool),
    Postgres(PgPool),
}

/// A transaction that writes. On SQLite it takes the write lock when it begins (`BEGIN
/// IMMEDIATE`), waiting for it under the busy timeout: a deferred transaction that reads and
/// then writes fails at once (`SQLITE_BUSY_SNAPSHOT`, "database is locked") when another
/// connection commits in between, which background writes (a token's last use, the audit
/// log's counts) made common. Postgres waits on row locks by itself.
pub(crate) trait BeginWrite {
    type Db: sqlx::Database;
    async fn begin_write(&self) -> Result<sqlx::Transaction<'static, Self::Db>>;
}

impl BeginWrite for SqlitePool {
    type Db = sqlx::Sqlite;
    async fn begin_write(&self) -> Result<sqlx::Transaction<'static, sqlx::Sqlite>> {
        Ok(self.begin_with("BEGIN IMMEDIATE").await?)
    }
}

impl BeginWrite for PgPool {
    type Db = sqlx::Postgres;
    async fn begin_write(&self) -> Result<sqlx::Transaction<'static, sqlx::Postgres>> {
        Ok(self.begin().await?)
    }
}

/// `$from, $from+1, …` (`n` of them): the placeholders of an `IN (…)` list.
pub(crate) fn marks(from: usize, n: usize) -> String {
    (from..from + n)
        .map(|i| format!("${i}"))
        .collect::<Vec<_>>()
        .join(", ")
}

/// Run `$body` with `$pool` bound to whichever pool the store holds.
macro_rules! dispatch {
    ($store:expr, $pool:ident => $body:expr) => {
        match $store {
            Store::Sqlite($pool) => $body,
            Store::Postgres($pool) => $body,
        }
    };
}

/// SQL: rows `c` of a chunk table are chunks `$first..=$last` (indices, SQL expressions)
/// of take `$take` (a row of `takes`). In the SQL here, 4294967296 is [`CHUNK_KEYS`] (a
/// test holds the two together).
macro_rules! chunks_of {
    ($take:literal, $first:literal, $last:literal) => {
        concat!(
            "c.key BETWEEN ",
            $take,
            ".key * 4294967296 + ",
            $first,
            " AND ",
            $take,
            ".key * 4294967296 + ",
            $last
        )
    };
}

/// Chunks `$2..=$3` (indices) of take `$1` from chunk table `$table`, with their indices.
macro_rules! chunk_range {
    ($table:literal) => {
        concat!(
            "SELECT c.key - t.key * 4294967296 AS idx, c.first_frame, c.frames, c.crc32c, \
             c.payload FROM takes t JOIN ",
            $table,
            " c ON ",
            chunks_of!("t", "$2", "$3"),
            " WHERE t.id = $1 ORDER BY c.key"
        )
    };
}

impl Store {
    /// Open (creating a SQLite file if needed) and migrate.
    pub async fn open(url: &str) -> Result<Store> {
        let store = if url.starts_with("sqlite:") {
            let opts = SqliteConnectOptions::from_str(url)?
                .create_if_missing(true)
                .journal_mode(SqliteJournalMode::Wal)
                .synchronous(SqliteSynchronous::Normal)
                .foreign_keys(true)
                .busy_timeout(Duration::from_secs(10));
            let pool = SqlitePoolOptions::new()
                .max_connections(8)
                // A connection to a file in this process cannot go stale as a network one
                // can: the ping sqlx sends before handing one out is a round trip to its
                // worker thread that tells nothing (a third of a range read's queries).
                .test_before_acquire(false)
                .connect_with(opts)
                .await?;
            let store = Store::Sqlite(pool.clone());
            migrate::migrate!(store, &pool, "migrations/sqlite");
            store
        } else if url.starts_with("postgres:") || url.starts_with("postgresql:") {
            let pool = PgPoolOptions::new()
                .max_connections(16)
                // A request waits this long for a connection before it is told to come back
                // (503): long enough for a burst, short enough that an outage fails fast.
                .acquire_timeout(Duration::from_secs(5))
                .connect(url)
                .await?;
            let store = Store::Postgres(pool.clone());
            migrate::migrate!(store, &pool, "migrations/postgres");
            store
        } else {
            return Err(Error::Url(url.to_string()));
        };
        Ok(store)
    }

    pub async fn close(&self) {
        dispatch!(self, pool => pool.close().await)
    }

    /// Insert a take, its tags, its chunks and its skeleton (unless stored already)
    /// atomically.
    pub async fn insert(&self, s: &NewTake) -> Result<()> {
        dispatch!(self, pool => {
            let mut tx = pool.begin_write().await?;
            if let Some(k) = &s.skeleton {
                sqlx::query(skeletons::INSERT)
                    .bind(&k.id)
                    .bind(&k.layout)
                    .bind(k.joints)
                    .bind(&k.payload)
                    .bind(k.created_at)
                    .execute(&mut *tx)
                    .await?;
            }
            let r = rows::bind_take(sqlx::query(rows::INSERT_TAKE), s)
                .bind(s.errors.as_deref())
                .fetch_one(&mut *tx)
                .await;
            let key: i64 = match r {
                Ok(r) => r.try_get("key")?,
                Err(e) => return Err(conflict_or(e, &format!("take {}", s.id))),
            };
            if let Some(n) = &s.stream {
                sqlx::query(
                    "UPDATE takes SET stream_server = $1, stream_url = $2, \
                     frames_received = 0, stream_state = $3 WHERE id = $4",
                )
                .bind(&n.owner.server)
                .bind(&n.owner.url)
                .bind(&n.state)
                .bind(&s.id)
                .execute(&mut *tx)
                .await?;
            }
            for tag in &s.tags {
                sqlx::query("INSERT INTO take_tags (take_key, tag) VALUES ($1, $2)")
                    .bind(key)
                    .bind(tag)
                    .execute(&mut *tx)
                    .await?;
            }
            for l in &s.labels {
                sqlx::query(INSERT_LABEL)
                    .bind(key)
                    .bind(&l.key)
                    .bind(&l.value)
                    .bind(l.number)
                    .execute(&mut *tx)
                    .await?;
            }
            for c in &s.chunks {
                bind_chunk(sqlx::query(INSERT_CHUNK), key, c)?.execute(&mut *tx).await?;
            }
            if let Some(b) = &s.basis {
                sqlx::query("INSERT INTO take_bases (take_key, basis_id) VALUES ($1, $2)")
                    .bind(key)
                    .bind(b)
                    .execute(&mut *tx)
                    .await?;
            }
            if let Some(a) = &s.analog {
                sqlx::query(
                    "INSERT INTO take_analog (take_key, header, raw_bytes, stored_bytes) \
                     VALUES ($1, $2, $3, $4)",
                )
                .bind(key)
                .bind(&a.header)
                .bind(a.raw_bytes)
                .bind(a.stored_bytes)
                .execute(&mut *tx)
                .await?;
                for c in &a.chunks {
                    bind_chunk(sqlx::query(INSERT_ANALOG_CHUNK), key, c)?
                        .execute(&mut *tx)
                        .await?;
                }
            }
            if let Some(p) = &s.parameters {
                sqlx::query(
                    "INSERT INTO take_parameters (take_key, format, payload) VALUES ($1, $2, $3)",
                )
                .bind(key)
                .bind(&p.format)
                .bind(&p.payload)
                .execute(&mut *tx)
                .await?;
            }
            if let Some(o) = &s.outputs {
                sqlx::query("INSERT INTO take_outputs (take_key, payload) VALUES ($1, $2)")
                    .bind(key)
                    .bind(o)
                    .execute(&mut *tx)
                    .await?;
            }
            tx.commit().await?;
            Ok(())
        })
    }

    /// A take's model outputs (`codec::outputs` bytes); `None` if it has none.
    pub async fn outputs(&self, id: &str) -> Result<Option<Vec<u8>>> {
        dispatch!(self, pool => {
            Ok(sqlx::query_scalar::<_, Vec<u8>>(
                "SELECT o.payload FROM take_outputs o JOIN takes t ON t.key = o.take_key \
                 WHERE t.id = $1",
            )
            .bind(id)
            .fetch_optional(pool)
            .await?)
        })
    }

    /// A take's error series bytes: `None` if it has none (or there is no such take).
    pub async fn error_series(&self, id: &str) -> Result<Option<Vec<u8>>> {
        dispatch!(self, pool => {
            Ok(sqlx::query_scalar::<_, Option<Vec<u8>>>("SELECT errors FROM takes WHERE id = $1")
                .bind(id)
                .fetch_optional(pool)
                .await?
                .flatten())
        })
    }

    /// Extend or replace a take's encoding in one transaction: its row's encoding columns
    /// (frames, codec, sizes, statistics, header, meta) take `row`'s values and `chunks` are
    /// added; with `replace`, its old chunks and basis reference go first (a finished
    /// stream's re-encoding). Only while its body is the one `row` was read with
    /// (`row.body_rev`): a body corrected meanwhile is not undone. False if there is no such
    /// take or its body changed.
    pub async fn update_encoding(
        &self,
        row: &TakeRow,
        chunks: &[ChunkRow],
        replace: bool,
        basis: Option<&str>,
    ) -> Result<bool> {
        dispatch!(self, pool => {
            let mut tx = pool.begin_write().await?;
            let sql = format!(
                "UPDATE takes SET {}, codec = $10, max_bound_mm = $11, mean_bound_mm = $12, \
                 header = $13, meta = $14 WHERE id = $15 AND body_rev = $16 RETURNING key",
                rows::SET_TOTALS
            );
            let r = rows::bind_totals(sqlx::query(&sql), &row.totals)
            .bind(&row.codec)
            .bind(row.max_bound_mm)
            .bind(row.mean_bound_mm)
            .bind(&row.header)
            .bind(&row.meta)
            .bind(&row.id)
            .bind(row.body_rev)
            .fetch_optional(&mut *tx)
            .await?;
            let Some(r) = r else {
                return Ok(false);
            };
            let key: i64 = r.try_get("key")?;
            if replace {
                let (from, to) = chunk_keys(key)?;
                sqlx::query("DELETE FROM chunks WHERE key BETWEEN $1 AND $2")
                    .bind(from)
                    .bind(to)
                    .execute(&mut *tx)
                    .await?;
                sqlx::query("DELETE FROM take_bases WHERE take_key = $1")
                    .bind(key)
                    .execute(&mut *tx)
                    .await?;
            }
            for c in chunks {
                bind_chunk(sqlx::query(INSERT_CHUNK), key, c)?.execute(&mut *tx).await?;
            }
            if let Some(b) = basis {
                sqlx::query(
                    "INSERT INTO take_bases (take_key, basis_id) VALUES ($1, $2) \
                     ON CONFLICT DO NOTHING",
                )
                .bind(key)
                .bind(b)
                .execute(&mut *tx)
                .await?;
            }
            tx.commit().await?;
            Ok(true)
        })
    }

    /// Add one chunk to a live take and update its running totals (frames, sizes,
    /// statistics) and lease, in one transaction; and its meta once, when it has a body
    /// ([`ChunkAppend::meta`]). Nothing else is rewritten: the cost of an append does not
    /// grow with the take. False if the take is gone or no longer live.
    ///
    /// Only `append.server`, the stream's owner, may: false too if another server took the
    /// stream over. The producer's count of frames and the coder's state go with the chunk
    /// ([`StreamRow`]), for a server that takes the stream over.
    pub async fn append_chunk(
        &self,
        id: &str,
        totals: &TakeTotals,
        chunk: &ChunkRow,
        append: &ChunkAppend<'_>,
    ) -> Result<bool> {
        dispatch!(self, pool => {
            let mut tx = pool.begin_write().await?;
            let sql = format!(
                "UPDATE takes SET {}, live_until = $10, frames_received = $11, \
                 stream_state = $12, meta = COALESCE($15, meta) \
                 WHERE id = $13 AND live_until IS NOT NULL AND stream_server = $14 RETURNING key",
                rows::SET_TOTALS
            );
            let r = rows::bind_totals(sqlx::query(&sql), totals)
            .bind(append.live_until)
            .bind(append.frames_received)
            .bind(append.state)
            .bind(id)
            .bind(append.server)
            .bind(append.meta)
            .fetch_optional(&mut *tx)
            .await?;
            let Some(r) = r else {
                return Ok(false);
            };
            let key: i64 = r.try_get("key")?;
            // Once: a commit whose answer was lost (the connection dropped as it committed)
            // is sent again, and finds its chunk stored, with the same bytes.
            let sql = format!("{INSERT_CHUNK} ON CONFLICT (key) DO NOTHING");
            let inserted = bind_chunk(sqlx::query(&sql), key, chunk)?.execute(&mut *tx).await?;
            if inserted.rows_affected() == 0 {
                let crc: i64 = sqlx::query_scalar("SELECT crc32c FROM chunks WHERE key = $1")
                    .bind(chunk_key(key, chunk.idx)?)
                    .fetch_one(&mut *tx)
                    .await?;
                if crc != i64::from(chunk.crc32c) {
                    return Err(Error::Conflict(format!(
                        "chunk {} of take {id}, stored already with other bytes",
                        chunk.idx
                    )));
                }
            }
            tx.commit().await?;
            Ok(true)
        })
    }

    /// Extend the lease of a live take `server` codes; false if it is not live any more, or
    /// another server took it over.
    pub async fn renew_lease(&self, id: &str, server: &str, live_until: i64) -> Result<bool> {
        dispatch!(self, pool => {
            let r = sqlx::query(
                "UPDATE takes SET live_until = $1 \
                 WHERE id = $2 AND live_until IS NOT NULL AND stream_server = $3",
            )
            .bind(live_until)
            .bind(id)
            .bind(server)
            .execute(pool)
            .await?;
            Ok(r.rows_affected() > 0)
        })
    }

    /// Live takes whose lease ran out before `now` (their server stopped mid-stream).
    pub async fn expired_live(&self, now: i64) -> Result<Vec<String>> {
        dispatch!(self, pool => {
            sqlx::query("SELECT id FROM takes WHERE live_until IS NOT NULL AND live_until < $1")
                .bind(now)
                .fetch_all(pool)
                .await?
                .iter()
                .map(|r| Ok(r.try_get::<String, _>("id")?))
                .collect()
        })
    }

    /// Close a live take: its final header and meta, and no lease, if `by` may (see
    /// [`Closer`]). False if not: it was closed, taken over or changed meanwhile.
    pub async fn close_live(
        &self,
        id: &str,
        header: &[u8],
        meta: &[u8],
        by: Closer<'_>,
    ) -> Result<bool> {
        dispatch!(self, pool => {
            const SET: &str = "UPDATE takes SET header = $1, meta = $2, live_until = NULL \
                 WHERE id = $3 AND live_until IS NOT NULL";
            let r = match by {
                Closer::Owner(server) => {
                    sqlx::query(&format!("{SET} AND stream_server = $4"))
                        .bind(header)
                        .bind(meta)
                        .bind(id)
                        .bind(server)
                        .execute(pool)
                        .await?
                }
                Closer::Orphan { before, frames } => {
                    sqlx::query(&format!("{SET} AND live_until < $4 AND frames = $5"))
                        .bind(header)
                        .bind(meta)
                        .bind(id)
                        .bind(before)
                        .bind(frames)
                        .execute(pool)
                        .await?
                }
            };
            Ok(r.rows_affected() > 0)
        })
    }

    /// Where each chunk of a take sits, from the chunk rows (payloads not read): the index
    /// of a live take, whose header carries none while it grows.
    pub async fn chunk_index(&self, id: &str) -> Result<Vec<ChunkEntry>> {
        dispatch!(self, pool => {
            sqlx::query(
                concat!(
                    "SELECT c.key - t.key * 4294967296 AS idx, c.first_frame, c.frames, \
                     c.crc32c, length(c.payload) AS len FROM takes t JOIN chunks c ON ",
                    chunks_of!("t", "0", "4294967295"),
                    " WHERE t.id = $1 ORDER BY c.key"
                ),
            )
            .bind(id)
            .fetch_all(pool)
            .await?
            .iter()
            .map(|r| {
                let crc: i64 = r.try_get("crc32c")?;
                let len: i64 = r.try_get::<i64, _>("len").or_else(|_| r.try_get::<i32, _>("len").map(i64::from))?;
                Ok(ChunkEntry {
                    idx: r.try_get("idx")?,
                    first_frame: r.try_get("first_frame")?,
                    frames: r.try_get("frames")?,
                    crc32c: u32::try_from(crc).map_err(|_| Error::Corrupt(format!("crc {crc}")))?,
                    len,
                })
            })
            .collect()
        })
    }

    /// A take's metadata, tags and labels, without chunks.
    pub async fn get(&self, id: &str) -> Result<Option<TakeRow>> {
        let row = dispatch!(self, pool => {
            let row = sqlx::query(&format!("SELECT {} FROM takes WHERE id = $1", rows::TAKE_COLUMNS))
                .bind(id)
                .fetch_optional(pool)
                .await?;
            match row {
                Some(row) => Some(rows::take_from_row(&row)?),
                None => None,
            }
        });
        let Some(row) = row else { return Ok(None) };
        let mut items = [row];
        self.attach_sets(&mut items).await?;
        let [row] = items;
        Ok(Some(row))
    }

    /// Chunks `first..end` (indices) of a take, checked against their CRC-32C.
    pub async fn chunks(&self, id: &str, first: i64, end: i64) -> Result<Vec<ChunkRow>> {
        self.chunk_range(CHUNK_RANGE, id, first, end).await
    }

    /// Chunks `first..end` of one take by `select` ([`CHUNK_RANGE`] or
    /// [`ANALOG_CHUNK_RANGE`]), each checked against its CRC-32C.
    async fn chunk_range(
        &self,
        select: &'static str,
        id: &str,
        first: i64,
        end: i64,
    ) -> Result<Vec<ChunkRow>> {
        // Indices outside what a take spans hold no chunk of it (and `last < first` holds
        // none at all).
        let (first, last) = (first.clamp(0, CHUNK_KEYS), end.clamp(0, CHUNK_KEYS) - 1);
        dispatch!(self, pool => {
            let rows = sqlx::query(select)
                .bind(id)
                .bind(first)
                .bind(last)
                .fetch_all(pool)
                .await?;
            rows.iter().map(rows::chunk_from_row).collect()
        })
    }

    /// A take's analog header and its raw and stored sizes; `None` if it has no analog
    /// channels.
    pub async fn analog(&self, id: &str) -> Result<Option<AnalogRows>> {
        dispatch!(self, pool => {
            let row = sqlx::query(
                "SELECT a.header, a.raw_bytes, a.stored_bytes FROM take_analog a \
                 JOIN takes t ON t.key = a.take_key WHERE t.id = $1",
            )
            .bind(id)
            .fetch_optional(pool)
            .await?;
            row.map(|r| {
                Ok(AnalogRows {
                    header: r.try_get("header")?,
                    raw_bytes: r.try_get("raw_bytes")?,
                    stored_bytes: r.try_get("stored_bytes")?,
                    chunks: Vec::new(),
                })
            })
            .transpose()
        })
    }

    /// Analog chunks `first..end` (indices) of a take, checked against their CRC-32C.
    pub async fn analog_chunks(&self, id: &str, first: i64, end: i64) -> Result<Vec<ChunkRow>> {
        self.chunk_range(ANALOG_CHUNK_RANGE, id, first, end).await
    }

    /// The parameters a take's file carried; `None` if it carried none.
    pub async fn parameters(&self, id: &str) -> Result<Option<ParametersRow>> {
        dispatch!(self, pool => {
            let row = sqlx::query(
                "SELECT p.format, p.payload FROM take_parameters p \
                 JOIN takes t ON t.key = p.take_key WHERE t.id = $1",
            )
            .bind(id)
            .fetch_optional(pool)
            .await?;
            row.map(|r| {
                Ok(ParametersRow {
                    format: r.try_get("format")?,
                    payload: r.try_get("payload")?,
                })
            })
            .transpose()
        })
    }

    /// One round trip to the database (`/readyz`): `Err` when it cannot be reached.
    pub async fn ping(&self) -> Result<()> {
        dispatch!(self, pool => {
            sqlx::query("SELECT 1").execute(pool).await?;
            Ok(())
        })
    }

    /// Whether a take exists (one indexed lookup).
    pub async fn exists(&self, id: &str) -> Result<bool> {
        dispatch!(self, pool => {
            Ok(sqlx::query("SELECT 1 AS one FROM takes WHERE id = $1")
                .bind(id)
                .fetch_optional(pool)
                .await?
                .is_some())
        })
    }

    /// What tells one coding of a take from another (its codec, stored bytes and frames),
    /// `None` if there is no such take: one indexed lookup, which a cached decoder is checked
    /// against before each use, as the take may have been re-encoded or deleted (here or
    /// through another server) since it was cached.
    pub async fn coding_stamp(&self, id: &str) -> Result<Option<StampRow>> {
        dispatch!(self, pool => {
            let row = sqlx::query(
                "SELECT codec, stored_bytes, frames, body_rev FROM takes WHERE id = $1",
            )
            .bind(id)
            .fetch_optional(pool)
            .await?;
            row.map(|r| {
                Ok(StampRow {
                    codec: r.try_get("codec")?,
                    stored_bytes: r.try_get("stored_bytes")?,
                    frames: r.try_get("frames")?,
                    body_rev: r.try_get("body_rev")?,
                })
            })
            .transpose()
        })
    }

    /// [`Store::coding_stamp`] of each of `ids`, [`STAMPS_AT_ONCE`] to a query; the takes
    /// that do not exist are left out.
    pub async fn coding_stamps(&self, ids: &[&str]) -> Result<Vec<(String, StampRow)>> {
        let mut out = Vec::with_capacity(ids.len());
        for group in ids.chunks(STAMPS_AT_ONCE) {
            let sql = format!(
                "SELECT id, codec, stored_bytes, frames, body_rev FROM takes WHERE id IN ({})",
                marks(1, group.len())
            );
            dispatch!(self, pool => {
                let mut q = sqlx::query(&sql);
                for id in group {
                    q = q.bind(*id);
                }
                for r in q.fetch_all(pool).await? {
                    out.push((
                        r.try_get("id")?,
                        StampRow {
                            codec: r.try_get("codec")?,
                            stored_bytes: r.try_get("stored_bytes")?,
                            frames: r.try_get("frames")?,
                            body_rev: r.try_get("body_rev")?,
                        },
                    ));
                }
            })
        }
        Ok(out)
    }

    /// The library a take is in, `None` if there is no such take (one indexed lookup: what
    /// access checks read on every request, as the take may have moved since it was cached).
    pub async fn library_of(&self, id: &str) -> Result<Option<String>> {
        dispatch!(self, pool => {
            Ok(sqlx::query_scalar::<_, String>("SELECT library FROM takes WHERE id = $1")
                .bind(id)
                .fetch_optional(pool)
                .await?)
        })
    }

    /// Of the takes `ids`, those in `libraries`, with their frame counts.
    pub async fn take_frames_within(
        &self,
        ids: &[String],
        libraries: &[String],
    ) -> Result<HashMap<String, i64>> {
        let mut out = HashMap::new();
        if libraries.is_empty() {
            return Ok(out);
        }
        // A few hundred ids per query: well within either database's bound on parameters.
        for part in ids.chunks(500) {
            let sql = format!(
                "SELECT id, frames AS n FROM takes WHERE library IN ({}) AND id IN ({})",
                marks(1, libraries.len()),
                marks(libraries.len() + 1, part.len())
            );
            let binds: Vec<String> = libraries.iter().chain(part).cloned().collect();
            out.extend(self.counts_by_id(&sql, &binds).await?);
        }
        Ok(out)
    }

    /// Rows of `(id, n)` from `sql`, with `binds` bound in order, as a map.
    pub(crate) async fn counts_by_id(
        &self,
        sql: &str,
        binds: &[String],
    ) -> Result<HashMap<String, i64>> {
        if binds.is_empty() {
            return Ok(HashMap::new());
        }
        dispatch!(self, pool => {
            let mut q = sqlx::query(sql);
            for b in binds {
                q = q.bind(b);
            }
            let mut out = HashMap::new();
            for r in q.fetch_all(pool).await? {
                out.insert(r.try_get::<String, _>("id")?, r.try_get::<i64, _>("n")?);
            }
            Ok(out)
        })
    }

    /// Delete a take, and its chunks with it, in one transaction (tags and the rest
    /// cascade); false if there was none. The take's row goes first: on Postgres that
    /// waits for a chunk being appended to it meanwhile, whose row the deletes then see.
    pub async fn delete(&self, id: &str) -> Result<bool> {
        dispatch!(self, pool => {
            let mut tx = pool.begin_write().await?;
            let key: Option<i64> = sqlx::query_scalar("DELETE FROM takes WHERE id = $1 RETURNING key")
                .bind(id)
                .fetch_optional(&mut *tx)
                .await?;
            let Some(key) = key else {
                return Ok(false);
            };
            let (from, to) = chunk_keys(key)?;
            for sql in [
                "DELETE FROM chunks WHERE key BETWEEN $1 AND $2",
                "DELETE FROM analog_chunks WHERE key BETWEEN $1 AND $2",
            ] {
                sqlx::query(sql).bind(from).bind(to).execute(&mut *tx).await?;
            }
            tx.commit().await?;
            Ok(true)
        })
    }

    /// Number of takes stored (operations and tests).
    pub async fn count(&self) -> Result<i64> {
        dispatch!(self, pool => {
            let row = sqlx::query("SELECT COUNT(*) AS n FROM takes").fetch_one(pool).await?;
            Ok(row.try_get::<i64, _>("n")?)
        })
    }

    /// Takes and chunk rows stored, read in one statement (one consistent snapshot).
    pub async fn counts(&self) -> Result<(i64, i64)> {
        dispatch!(self, pool => {
            let row = sqlx::query(
                "SELECT (SELECT COUNT(*) FROM takes) AS takes, (SELECT COUNT(*) FROM chunks) AS chunks",
            )
            .fetch_one(pool)
            .await?;
            Ok((row.try_get::<i64, _>("takes")?, row.try_get::<i64, _>("chunks")?))
        })
    }

    /// Number of chunk rows stored (tests check nothing is left behind).
    pub async fn chunk_count(&self) -> Result<i64> {
        dispatch!(self, pool => {
            let row = sqlx::query("SELECT COUNT(*) AS n FROM chunks").fetch_one(pool).await?;
            Ok(row.try_get::<i64, _>("n")?)
        })
    }
}

/// Takes whose stamps one query of [`Store::coding_stamps`] reads (well under SQLite's
/// and Postgres's limits on bound parameters).
pub const STAMPS_AT_ONCE: usize = 256;

const INSERT_LABEL: &str =
    "INSERT INTO take_labels (take_key, key, value, number) VALUES ($1, $2, $3, $4)";

const INSERT_CHUNK: &str =
    "INSERT INTO chunks (key, first_frame, frames, crc32c, payload) VALUES ($1, $2, $3, $4, $5)";

const INSERT_ANALOG_CHUNK: &str = "INSERT INTO analog_chunks (key, first_frame, frames, crc32c, \
    payload) VALUES ($1, $2, $3, $4, $5)";

/// Chunk keys one take spans (migration 0020): a chunk's row is keyed by its take's key
/// (`takes.key`) times this, plus its index; one B-tree, no second index.
const CHUNK_KEYS: i64 = 1 << 32;

/// Chunks of a take, the points' and the analog channels' ([`chunk_range!`]).
const CHUNK_RANGE: &str = chunk_range!("chunks");
const ANALOG_CHUNK_RANGE: &str = chunk_range!("analog_chunks");

/// The chunk rows `c` of the take `takes` in a query over the takes table.
const ALL_CHUNKS_OF_TAKES: &str = chunks_of!("takes", "0", "4294967295");

/// Take keys a chunk key holds: below 2^31 − 1, so that the SQL's `take key × 2^32 + end`
/// (an end index up to 2^32) stays within an i64.
const TAKE_KEYS: i64 = i64::MAX / CHUNK_KEYS;

/// The key of chunk `idx` of the take of key `take`; an index or a take past what a key
/// holds is an error, not another take's row.
fn chunk_key(take: i64, idx: i64) -> Result<i64> {
    if !(0..CHUNK_KEYS).contains(&idx) {
        return Err(Error::Corrupt(format!("chunk index {idx} out of range")));
    }
    if !(0..TAKE_KEYS).contains(&take) {
        return Err(Error::Corrupt(format!("take key {take} out of range")));
    }
    Ok(take * CHUNK_KEYS + idx)
}

/// The first and last chunk key of the take of key `take`, both included.
fn chunk_keys(take: i64) -> Result<(i64, i64)> {
    Ok((chunk_key(take, 0)?, chunk_key(take, CHUNK_KEYS - 1)?))
}

/// The key of take `$1` (`takes.key`), read in the transaction that writes what is keyed by it.
const TAKE_KEY: &str = "SELECT key FROM takes WHERE id = $1";

/// Bind a chunk's columns, in [`INSERT_CHUNK`] order, to a query of either backend: the
/// chunk of the take of key `take`.
fn bind_chunk<'q, DB: sqlx::Database>(
    q: sqlx::query::Query<'q, DB, <DB as sqlx::Database>::Arguments<'q>>,
    take: i64,
    c: &'q ChunkRow,
) -> Result<sqlx::query::Query<'q, DB, <DB as sqlx::Database>::Arguments<'q>>>
where
    i64: sqlx::Encode<'q, DB> + sqlx::Type<DB>,
    &'q [u8]: sqlx::Encode<'q, DB> + sqlx::Type<DB>,
{
    Ok(q.bind(chunk_key(take, c.idx)?)
        .bind(c.first_frame)
        .bind(c.frames)
        .bind(i64::from(c.crc32c))
        .bind(c.payload.as_slice()))
}

/// Bind `values` in order to a query of either backend.
macro_rules! bind_all {
    ($q:expr, $values:expr) => {{
        let mut q = $q;
        for v in $values {
            q = match v {
                query::Value::Int(i) => q.bind(*i),
                query::Value::Real(r) => q.bind(*r),
                query::Value::Text(t) => q.bind(t.clone()),
            };
        }
        q
    }};
}

mod bases;
pub use bases::{BasisRow, Deletion};
mod features;
pub use features::{Candidate, FeatureRow};
mod jobs;
mod skeletons;
mod streams;
pub use jobs::JobRow;
pub use skeletons::SkeletonRow;
pub use streams::{ChunkAppend, Closer, NewStream, StreamClaim, StreamOwnerRow, StreamRow};
mod access;
pub use access::{AuditRow, TokenRow};
mod migrate;
mod sizes;
pub use sizes::{DatabaseBytes, ObjectBytes};

/// One page of a listing.
#[derive(Debug, Clone)]
pub struct Page {
    pub items: Vec<TakeRow>,
    /// Pass back to get the next page; `None` on the last.
    pub next: Option<Cursor>,
}

impl Store {
    /// Takes matching `filter`, sorted, `limit` at a time after `cursor`.
    pub async fn list(
        &self,
        filter: &Filter,
        sort: SortKey,
        descending: bool,
        limit: usize,
        cursor: Option<&Cursor>,
    ) -> Result<Page> {
        let w = query::where_clause(filter, cursor);
        let sql = format!(
            "SELECT key, {} FROM takes {} {} LIMIT {}",
            rows::TAKE_COLUMNS,
            w.text,
            query::order_by(sort, descending),
            limit + 1
        );
        let (mut items, keys): (Vec<TakeRow>, Vec<i64>) = dispatch!(self, pool => {
            let rows = bind_all!(sqlx::query(&sql), &w.values).fetch_all(pool).await?;
            rows.iter()
                .map(|r| Ok((rows::take_from_row(r)?, r.try_get::<i64, _>("key")?)))
                .collect::<Result<Vec<_>>>()?
                .into_iter()
                .unzip()
        });
        let more = items.len() > limit;
        items.truncate(limit);
        self.attach_sets(&mut items).await?;
        let next = match (more, items.last()) {
            (true, Some(last)) => Some(Cursor {
                sort,
                descending,
                value: query::sort_value(sort, last),
                key: keys[items.len() - 1],
            }),
            _ => None,
        };
        Ok(Page { items, next })
    }

    /// The tags and labels of `items`, read in one query each.
    async fn attach_sets(&self, items: &mut [TakeRow]) -> Result<()> {
        if items.is_empty() {
            return Ok(());
        }
        let marks: Vec<String> = (1..=items.len()).map(|i| format!("${i}")).collect();
        let ids: Vec<query::Value> = items
            .iter()
            .map(|s| query::Value::Text(s.id.clone()))
            .collect();
        let tags_sql = format!(
            "SELECT t.id AS take_id, g.tag FROM take_tags g JOIN takes t ON t.key = g.take_key \
             WHERE t.id IN ({}) ORDER BY g.tag",
            marks.join(", ")
        );
        let labels_sql = format!(
            "SELECT t.id AS take_id, l.key, l.value, l.number FROM take_labels l \
             JOIN takes t ON t.key = l.take_key WHERE t.id IN ({}) ORDER BY l.key",
            marks.join(", ")
        );
        type ById<T> = Vec<(String, T)>;
        let (tags, labels): (ById<String>, ById<LabelRow>) = dispatch!(self, pool => {
            let rows = bind_all!(sqlx::query(&tags_sql), &ids).fetch_all(pool).await?;
            let tags = rows
                .iter()
                .map(|r| Ok((r.try_get::<String, _>("take_id")?, r.try_get::<String, _>("tag")?)))
                .collect::<Result<Vec<_>>>()?;
            let rows = bind_all!(sqlx::query(&labels_sql), &ids).fetch_all(pool).await?;
            let labels = rows
                .iter()
                .map(|r| {
                    Ok((
                        r.try_get::<String, _>("take_id")?,
                        LabelRow {
                            key: r.try_get("key")?,
                            value: r.try_get("value")?,
                            number: r.try_get("number")?,
                        },
                    ))
                })
                .collect::<Result<Vec<_>>>()?;
            (tags, labels)
        });
        for s in items.iter_mut() {
            s.tags = tags
                .iter()
                .filter(|(id, _)| *id == s.id)
                .map(|(_, t)| t.clone())
                .collect();
            s.labels = labels
                .iter()
                .filter(|(id, _)| *id == s.id)
                .map(|(_, l)| l.clone())
                .collect();
        }
        Ok(())
    }

    /// The numbers statistics aggregate, for every take matching `filter`.
    pub async fn stat_rows(&self, filter: &Filter) -> Result<Vec<StatRow>> {
        let w = query::where_clause(filter, None);
        let sql = format!(
            "SELECT library, codec, frames, points, duration_s, raw_bytes, stored_bytes, mean_mm, \
             max_mm, id, name, layout, source_format, CAST(LENGTH(meta) AS BIGINT) AS meta_bytes, \
             skeleton_id, \
             (SELECT COUNT(*) FROM chunks c WHERE {ALL_CHUNKS_OF_TAKES}) \
              + (SELECT COUNT(*) FROM analog_chunks c WHERE {ALL_CHUNKS_OF_TAKES}) AS chunk_rows, \
             (SELECT a.raw_bytes FROM take_analog a WHERE a.take_key = takes.key) \
              AS analog_raw_bytes, \
             (SELECT a.stored_bytes FROM take_analog a WHERE a.take_key = takes.key) \
              AS analog_stored_bytes, \
             (SELECT CAST(LENGTH(p.payload) AS BIGINT) FROM take_parameters p \
              WHERE p.take_key = takes.key) AS parameters_bytes, \
             (SELECT COALESCE(SUM(LENGTH(t.tag) + 8), 0) \
              FROM take_tags t WHERE t.take_key = takes.key) AS tag_bytes, \
             (SELECT COALESCE(SUM(LENGTH(l.key) + LENGTH(l.value) + 8), 0) \
              FROM take_labels l WHERE l.take_key = takes.key) AS label_bytes \
             FROM takes {}",
            w.text
        );
        dispatch!(self, pool => {
            let rows = bind_all!(sqlx::query(&sql), &w.values).fetch_all(pool).await?;
            rows.iter()
                .map(|r| {
                    let text = |c: &str| -> Result<i64> {
                        Ok(r.try_get::<Option<String>, _>(c)?.map_or(0, |v| v.len() as i64))
                    };
                    let library: String = r.try_get("library")?;
                    let codec: String = r.try_get("codec")?;
                    let id_len = text("id")?;
                    let text_bytes = id_len
                        + library.len() as i64
                        + codec.len() as i64
                        + text("name")?
                        + text("layout")?
                        + text("source_format")?
                        + r.try_get::<i64, _>("meta_bytes")?
                        + text("skeleton_id")?
                        + r.try_get::<i64, _>("tag_bytes")?
                        + r.try_get::<i64, _>("label_bytes")?;
                    let stored_bytes: i64 = r.try_get("stored_bytes")?;
                    Ok(StatRow {
                        disk_bytes: rows::disk_bytes(stored_bytes, text_bytes, r.try_get("chunk_rows")?),
                        library,
                        codec,
                        frames: r.try_get("frames")?,
                        points: r.try_get("points")?,
                        duration_s: r.try_get("duration_s")?,
                        raw_bytes: r.try_get("raw_bytes")?,
                        stored_bytes,
                        mean_mm: r.try_get("mean_mm")?,
                        max_mm: r.try_get("max_mm")?,
                        analog_raw_bytes: r
                            .try_get::<Option<i64>, _>("analog_raw_bytes")?
                            .unwrap_or(0),
                        analog_stored_bytes: r
                            .try_get::<Option<i64>, _>("analog_stored_bytes")?
                            .unwrap_or(0),
                        parameters_bytes: r
                            .try_get::<Option<i64>, _>("parameters_bytes")?
                            .unwrap_or(0),
                    })
                })
                .collect()
        })
    }

    /// Replace a closed take's meta when its body changed, if the record is still the one
    /// `row` was read from: the same coding (`codec`, `stored_bytes`: a re-encode meanwhile
    /// wrote a meta of its own, which this must not undo) and the same `body_rev` (a body
    /// derived or corrected meanwhile, by this server or another, wins). Counts the change
    /// in `body_rev`. False when the take is gone, live, re-encoded or its body changed.
    pub async fn set_meta(&self, row: &TakeRow) -> Result<bool> {
        dispatch!(self, pool => {
            let done = sqlx::query(
                "UPDATE takes SET meta = $1, body_rev = body_rev + 1 WHERE id = $2 AND codec = $3 \
                 AND stored_bytes = $4 AND body_rev = $5 AND live_until IS NULL",
            )
            .bind(&row.meta)
            .bind(&row.id)
            .bind(&row.codec)
            .bind(row.totals.stored_bytes)
            .bind(row.body_rev)
            .execute(pool)
            .await?;
            Ok(done.rows_affected() == 1)
        })
    }

    /// Change a take's name, library, tags and/or labels (each set given replaces the old
    /// one), in one transaction; false if no such take.
    pub async fn update(&self, id: &str, edit: &TakeEdit<'_>) -> Result<bool> {
        dispatch!(self, pool => {
            let mut tx = pool.begin_write().await?;
            let key: Option<i64> = sqlx::query_scalar(TAKE_KEY)
                .bind(id)
                .fetch_optional(&mut *tx)
                .await?;
            let Some(key) = key else {
                return Ok(false);
            };
            if let Some(n) = edit.name {
                sqlx::query("UPDATE takes SET name = $1 WHERE id = $2").bind(n).bind(id).execute(&mut *tx).await?;
            }
            if let Some(l) = edit.library {
                sqlx::query("UPDATE takes SET library = $1 WHERE id = $2").bind(l).bind(id).execute(&mut *tx).await?;
            }
            if let Some(tags) = edit.tags {
                sqlx::query("DELETE FROM take_tags WHERE take_key = $1").bind(key).execute(&mut *tx).await?;
                for t in tags {
                    sqlx::query("INSERT INTO take_tags (take_key, tag) VALUES ($1, $2)")
                        .bind(key)
                        .bind(t)
                        .execute(&mut *tx)
                        .await?;
                }
            }
            if let Some(labels) = edit.labels {
                sqlx::query("DELETE FROM take_labels WHERE take_key = $1").bind(key).execute(&mut *tx).await?;
                for l in labels {
                    sqlx::query(INSERT_LABEL)
                        .bind(key)
                        .bind(&l.key)
                        .bind(&l.value)
                        .bind(l.number)
                        .execute(&mut *tx)
                        .await?;
                }
            }
            tx.commit().await?;
            Ok(true)
        })
    }
}

/// What [`Store::update`] changes of a take: each field given, the rest kept.
#[derive(Debug, Clone, Copy, Default)]
pub struct TakeEdit<'a> {
    pub name: Option<&'a str>,
    pub library: Option<&'a str>,
    /// The take's tags, all of them.
    pub tags: Option<&'a [String]>,
    /// The take's labels, all of them.
    pub labels: Option<&'a [LabelRow]>,
}

/// A unique violation as a `Conflict` naming `what`; any other error as it is.
fn conflict_or(e: sqlx::Error, what: &str) -> Error {
    match &e {
        sqlx::Error::Database(d) if d.is_unique_violation() => Error::Conflict(what.to_string()),
        _ => Error::Database(e),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The SQL's chunk keys and [`chunk_key`]'s are one layout: the literal the queries
    /// multiply by is [`CHUNK_KEYS`], and a take's range runs from its first key to its last.
    #[test]
    fn the_sql_and_the_code_key_chunks_alike() {
        assert_eq!(CHUNK_KEYS.to_string(), "4294967296");
        for sql in [CHUNK_RANGE, ANALOG_CHUNK_RANGE, ALL_CHUNKS_OF_TAKES] {
            assert!(sql.contains(".key * 4294967296 + "), "{sql}");
        }
        assert!(ALL_CHUNKS_OF_TAKES.ends_with(&format!("+ {}", CHUNK_KEYS - 1)));
        assert_eq!(chunk_keys(3).unwrap(), (3 << 32, (4 << 32) - 1));
        assert!(chunk_key(1, CHUNK_KEYS).is_err());
        assert!(chunk_key(TAKE_KEYS, 0).is_err());
    }
}
