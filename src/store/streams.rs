//! Live streams' ownership: which server codes a live take, where other servers forward its
//! requests, how many frames its producer has had accepted, and what a server taking it over
//! goes on from ([`crate::service::streams`] decides; this keeps the rows). Every write by
//! an owner names it, so a server that lost its stream (another took it over after its
//! lease ran out) can no longer change the take: the write touches no row, and it knows.

use sqlx::Row;

use super::{Result, Store};

/// The server coding a live take, as a new stream's take is inserted with
/// ([`NewStream`]) or as a server taking it over claims it.
#[derive(Debug, Clone, PartialEq)]
pub struct StreamOwnerRow {
    /// A per-process id ([`crate::service::Node`]).
    pub server: String,
    /// Where other servers forward the stream's requests.
    pub url: String,
}

/// Who commits a live take's chunk, and what goes with it
/// ([`Store::append_chunk`](super::Store::append_chunk)).
#[derive(Debug, Clone)]
pub struct ChunkAppend<'a> {
    /// The stream's owner: nobody else may.
    pub server: &'a str,
    pub live_until: i64,
    pub frames_received: i64,
    /// [`StreamRow::state`] after this chunk.
    pub state: &'a str,
    /// The take's meta, when it changed (its body, derived from its first chunk's frames);
    /// `None` keeps it.
    pub meta: Option<&'a [u8]>,
}

/// A new stream's take's owner and coder state, inserted with it
/// ([`super::NewTake::stream`]).
#[derive(Debug, Clone, PartialEq)]
pub struct NewStream {
    pub owner: StreamOwnerRow,
    /// [`StreamRow::state`] before any chunk.
    pub state: String,
}

/// Who closes a live take ([`Store::close_live`]), and so on what condition.
#[derive(Debug, Clone, Copy)]
pub enum Closer<'a> {
    /// Its owner, finishing it: only while it still owns it.
    Owner(&'a str),
    /// Any server, for a take whose server stopped: only while its lease is still past
    /// `before` and it still has the `frames` read (nobody took it over meanwhile).
    Orphan { before: i64, frames: i64 },
}

/// A live take's stream as stored.
#[derive(Debug, Clone, PartialEq)]
pub struct StreamRow {
    /// None for a take made before streams had owners.
    pub owner: Option<StreamOwnerRow>,
    pub live_until: i64,
    /// Frames committed (the take's frames).
    pub frames: i64,
    /// Frames the producer had accepted (at least `frames`).
    pub frames_received: i64,
    /// What a coder needs to go on after the last committed chunk (JSON), if a chunk was
    /// committed since streams kept it.
    pub state: Option<String>,
}

/// A server's claim on a live take whose owner stopped, made only if the row is still as
/// it read it (`frames`, `frames_received`): another claim in between wins instead.
#[derive(Debug, Clone)]
pub struct StreamClaim<'a> {
    pub owner: &'a StreamOwnerRow,
    /// Now, ms since the epoch: the old lease must have run out before it (or be ours).
    pub now: i64,
    pub live_until: i64,
    pub frames: i64,
    pub frames_received: i64,
    /// The take's metadata with the handover recorded.
    pub meta: &'a [u8],
}

impl Store {
    /// The stream of a live take; None if the take is gone or not live.
    pub async fn stream(&self, id: &str) -> Result<Option<StreamRow>> {
        dispatch!(self, pool => {
            let row = sqlx::query(
                "SELECT stream_server, stream_url, live_until, frames, \
                 COALESCE(frames_received, frames) AS received, stream_state \
                 FROM takes WHERE id = $1 AND live_until IS NOT NULL",
            )
            .bind(id)
            .fetch_optional(pool)
            .await?;
            let Some(r) = row else { return Ok(None) };
            let server: Option<String> = r.try_get("stream_server")?;
            let url: Option<String> = r.try_get("stream_url")?;
            Ok(Some(StreamRow {
                owner: server.zip(url).map(|(server, url)| StreamOwnerRow { server, url }),
                live_until: r.try_get("live_until")?,
                frames: r.try_get("frames")?,
                frames_received: r.try_get("received")?,
                state: r.try_get("stream_state")?,
            }))
        })
    }

    /// Take a live take's stream over: true if this claim won (the lease had run out, or
    /// the take was already `claim.owner`'s, and nobody changed it since it was read).
    /// The frames received and not committed are forgotten here: the handover in
    /// `claim.meta` counts them.
    pub async fn claim_stream(&self, id: &str, claim: &StreamClaim<'_>) -> Result<bool> {
        dispatch!(self, pool => {
            let r = sqlx::query(
                "UPDATE takes SET stream_server = $1, stream_url = $2, live_until = $3, \
                 frames_received = frames, meta = $4 \
                 WHERE id = $5 AND live_until IS NOT NULL \
                 AND (live_until < $6 OR stream_server = $1) \
                 AND frames = $7 AND COALESCE(frames_received, frames) = $8",
            )
            .bind(&claim.owner.server)
            .bind(&claim.owner.url)
            .bind(claim.live_until)
            .bind(claim.meta)
            .bind(id)
            .bind(claim.now)
            .bind(claim.frames)
            .bind(claim.frames_received)
            .execute(pool)
            .await?;
            Ok(r.rows_affected() > 0)
        })
    }

    /// Record the frames a live take's producer has had accepted, and extend its lease:
    /// false if `server` no longer codes it (taken over, closed or deleted).
    pub async fn note_received(
        &self,
        id: &str,
        server: &str,
        frames_received: i64,
        live_until: i64,
    ) -> Result<bool> {
        dispatch!(self, pool => {
            let r = sqlx::query(
                "UPDATE takes SET frames_received = $1, live_until = $2 \
                 WHERE id = $3 AND live_until IS NOT NULL AND stream_server = $4",
            )
            .bind(frames_received)
            .bind(live_until)
            .bind(id)
            .bind(server)
            .execute(pool)
            .await?;
            Ok(r.rows_affected() > 0)
        })
    }
}
