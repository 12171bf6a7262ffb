//! A stream sent to any server of those sharing one database.
//!
//! One server codes a stream: its coder state (the unfinished chunk, the frames kept for
//! re-encoding, the watchers) is in that server's memory, and the take's row names it
//! (`stream_server`) with the address the others reach it at (`stream_url`, `serve
//! --advertise-url`). A request for the stream that reaches another server is forwarded
//! there ([`Route::Owner`]; the HTTP layer forwards it as it came, token included, and
//! passes the answer back, a watcher's event stream too), so a producer behind a
//! round-robin balancer codes one stream on one server, chunk after chunk, as if it had
//! sent every request there.
//!
//! Why forward rather than hand the stream to whichever server an append reaches: a handover
//! must end the current chunk (the next server starts with an intra frame), so behind a
//! round-robin balancer every append would end a chunk, and a stream would cost as much as
//! if it flushed every append; and the watchers, connected to one server, would move. A
//! redirect (307 to the owner) was the other choice: it needs every server reachable by
//! every client, which a balancer in front of private addresses does not give.
//!
//! When the owner stops (kill -9, a crash, a machine gone), its lease (`live_until`, renewed
//! by every append and by maintenance) runs out; the next request for the stream that finds
//! it unreachable takes it over ([`Streams::owner_unreachable`], [`Streams::take_over`]): the
//! new owner claims the row (one conditional update: one server wins), goes on after the
//! last committed chunk with a coder opened afresh (its first chunk intra, as every chunk
//! decodes alone), and counts the frames the stopped server had accepted but never
//! committed (`frames_received`, written with every append, minus the committed frames):
//! they are lost, recorded on the take (`meta.frames_lost`, `meta.handovers`) and in every
//! answer (`frames_lost`), and a producer that numbers its appends is told to send again
//! from the first of them.
//!
//! A server that answers is never taken over, however late its lease: it may only have
//! lost the database for a while, holding frames it answered for. It, in turn, takes no
//! frame once the lease it last wrote is about to run out until it has written it again
//! ([`Streams::append`]), so what it answered for is either stored or counted. Every write
//! an owner makes names it: one that lost its stream anyway (cut off from the other servers
//! as well as the database) is refused, and lets the stream go ([`crate::service::Error::Moved`]).

use std::sync::Arc;
use std::time::Instant;

use serde::{Deserialize, Serialize};
use tokio::sync::broadcast;

use super::{Live, Streams};
use crate::codec::stream::{StreamEncoder, StreamSpec};
use crate::codec::ErrorBound;
use crate::limits::STREAM_WATCH_QUEUE;
use crate::motion::metrics::Accumulator;
use crate::service::budget::{Holder, Shares};
use crate::service::take::StreamHandover;
use crate::service::{blocking, fetch, now_ms, Error, Result};
use crate::store::{Store, StreamClaim, StreamOwnerRow, StreamRow};

/// Where a request for a stream is answered.
#[derive(Debug, Clone, PartialEq)]
pub enum Route {
    /// This server codes the stream, or no server does (it is finished, or unknown): the
    /// request is answered here.
    Here,
    /// Another server codes it: forward the request to `url`.
    Owner { url: String },
}

/// Chunks absorbed per blocking call when a stream is taken over.
const ABSORB_BATCH: usize = 64;

/// What a server taking a stream over needs beyond the take as stored, written with the
/// take when the stream opens and with every chunk (`stream_state`).
#[derive(Debug, Clone, Serialize, Deserialize)]
pub(super) struct Resumable {
    pub chunk_frames: usize,
    /// The client asked for re-encoding on finish (the frames as sent for it are lost with
    /// their server).
    pub reencode_on_finish: bool,
    /// Error sums over the committed chunks; none before the first.
    pub errors: Option<Accumulator>,
}

impl Resumable {
    pub fn to_text(&self) -> Result<String> {
        serde_json::to_string(self).map_err(|e| Error::Internal(format!("stream state: {e}")))
    }
}

impl Streams {
    /// This server as a stream row names its owner.
    pub(super) fn owner_row(&self) -> StreamOwnerRow {
        StreamOwnerRow {
            server: self.node.id.clone(),
            url: self.node.url.clone(),
        }
    }

    /// Where a request for stream `id` is answered. A stream another server codes is
    /// answered there ([`Route::Owner`]), even past its lease: that server may be alive and
    /// only slow to reach the database, holding frames it answered for. It is taken over
    /// only when it cannot be reached ([`Streams::owner_unreachable`]), or when its owner
    /// was an earlier run of this server (the same address). `forwarded`: the request comes
    /// from another server, which found this one named as the owner; it is never sent on.
    pub async fn route(
        &self,
        store: &Store,
        id: &str,
        holder: &Holder,
        forwarded: bool,
    ) -> Result<Route> {
        // Twice: a server that loses a race to take the stream over reads who won.
        for _ in 0..2 {
            if self.entry(id).is_some() {
                return Ok(Route::Here);
            }
            let Some(row) = store.stream(id).await? else {
                return Ok(Route::Here);
            };
            let left_ms = row.live_until - now_ms();
            match &row.owner {
                // Ours, though not open here (a close or a claim that did not complete).
                Some(o) if o.server == self.node.id => {}
                // An earlier run of this server, at its address: it stopped.
                Some(o) if o.url == self.node.url && left_ms < 0 => {}
                Some(o) if o.url == self.node.url => return Err(Self::wait_for_lease(id, left_ms)),
                Some(o) if !forwarded => return Ok(Route::Owner { url: o.url.clone() }),
                Some(_) => {
                    return Err(Error::Busy(format!(
                        "stream {id} is moving between servers; retry"
                    )))
                }
                // Opened by a server from before streams had owners.
                None => return Err(Self::not_open(store, id).await),
            }
            if self.take_over(store, id, &row, holder).await? {
                return Ok(Route::Here);
            }
        }
        Err(Error::Busy(format!(
            "stream {id} is being taken over by another server; retry"
        )))
    }

    /// The server at `url`, named as the owner of stream `id`, could not be reached: if
    /// its lease has run out (it stopped), this server takes the stream over
    /// ([`Route::Here`]); if not, the caller is told when to retry.
    pub async fn owner_unreachable(
        &self,
        store: &Store,
        id: &str,
        holder: &Holder,
        url: &str,
    ) -> Result<Route> {
        let Some(row) = store.stream(id).await? else {
            return Ok(Route::Here);
        };
        match &row.owner {
            // Moved meanwhile: ask again.
            Some(o) if o.url != url => {
                return Err(Error::Busy(format!(
                    "stream {id} is moving between servers; retry"
                )))
            }
            _ => {}
        }
        let left_ms = row.live_until - now_ms();
        if left_ms >= 0 {
            tracing::warn!(
                stream = id,
                owner = url,
                "the server coding a stream does not answer"
            );
            return Err(Self::wait_for_lease(id, left_ms));
        }
        if self.take_over(store, id, &row, holder).await? {
            return Ok(Route::Here);
        }
        Err(Error::Busy(format!(
            "stream {id} is being taken over by another server; retry"
        )))
    }

    /// A stream whose server does not answer, its lease running `left_ms` more.
    fn wait_for_lease(id: &str, left_ms: i64) -> Error {
        Error::Busy(format!(
            "the server coding stream {id} does not answer; if it stopped, the next request \
             after its lease runs out (in {} s) takes the stream over",
            left_ms / 1000 + 1
        ))
    }

    /// Take stream `id` over from the server that stopped coding it (as `row` was read):
    /// go on after its last committed chunk, the frames it had accepted after that counted
    /// as lost. False if another server claimed it first.
    async fn take_over(
        &self,
        store: &Store,
        id: &str,
        row: &StreamRow,
        holder: &Holder,
    ) -> Result<bool> {
        // One take-over at a time on this server: two requests for the stream must not
        // both build it.
        let _one = self.taking_over.lock().await;
        if self.entry(id).is_some() {
            return Ok(true);
        }
        let (slot, share) = self.places(holder)?;
        let state: Resumable = match &row.state {
            Some(s) => serde_json::from_str(s)
                .map_err(|e| Error::Corrupt(format!("stream {id}: stored state: {e}")))?,
            None => {
                return Err(Error::Conflict(format!(
                    "stream {id} was opened by an older server and cannot be taken over; it is \
                     closed when its lease runs out"
                )))
            }
        };
        let take = fetch::take(store, id).await?;
        let (header, _) = fetch::header_of(store, &take).await?;
        let basis = fetch::shared(store, &header).await?.basis;
        let chunks = header.chunks.clone();
        let live_header = crate::codec::container::Header {
            frames: 0,
            chunks: Vec::new(),
            ..header
        };
        let bound: ErrorBound = take.bound;
        let (codec, points, fps, to_m) = (take.codec, take.points, take.fps, take.metres_per_unit);
        let chunk_frames = state.chunk_frames;
        let errors = state
            .errors
            .clone()
            .unwrap_or_else(|| Accumulator::new(points));
        let b = basis.clone();
        let mut encoder = blocking(move || {
            let spec = StreamSpec {
                points,
                fps,
                metres_per_unit: to_m,
                bound,
                chunk_frames,
                shared: b.as_ref(),
            };
            StreamEncoder::resume(codec, &spec, &live_header, errors)
        })
        .await?
        .map_err(|e| Error::Corrupt(format!("stream {id} cannot go on: {e}")))?;
        // The committed chunks, decoded for the take's digest, a batch at a time.
        let mut next = 0;
        while next < chunks.len() {
            let end = (next + ABSORB_BATCH).min(chunks.len());
            let rows = store.chunks(id, next as i64, end as i64).await?;
            let metas = chunks[next..end].to_vec();
            let same = rows.len() == metas.len()
                && rows.iter().zip(&metas).enumerate().all(|(k, (r, m))| {
                    r.idx == (next + k) as i64
                        && r.first_frame == i64::from(m.first_frame)
                        && r.crc32c == m.crc32c
                });
            if !same {
                // The chunks changed while they were read (committed, deleted): read again.
                return Ok(false);
            }
            next = end;
            encoder = blocking(move || {
                for (meta, r) in metas.into_iter().zip(&rows) {
                    encoder.absorb(meta, &r.payload)?;
                }
                Ok::<_, crate::codec::Error>(encoder)
            })
            .await?
            .map_err(|e| Error::Corrupt(format!("stream {id}: a stored chunk: {e}")))?;
        }
        let committed = encoder.committed();
        if committed.frames as i64 != row.frames {
            // A chunk was committed since the row was read: read again.
            return Ok(false);
        }
        let lost = (row.frames_received - row.frames).max(0) as usize;
        let now = now_ms();
        let mut meta = take.meta.clone();
        // Taken back by this very process (a close or a claim that did not complete):
        // not a handover unless frames were lost.
        let ours = row.owner.as_ref().is_some_and(|o| o.server == self.node.id);
        if lost > 0 || !ours {
            meta.frames_lost += lost;
            meta.handovers.push(StreamHandover {
                frame: committed.frames,
                frames_lost: lost,
                at_ms: now,
            });
        }
        let owner = self.owner_row();
        let live_until = self.lease_end();
        let claimed = store
            .claim_stream(
                id,
                &StreamClaim {
                    owner: &owner,
                    now,
                    live_until,
                    frames: row.frames,
                    frames_received: row.frames_received,
                    meta: &meta.to_record(id)?,
                },
            )
            .await?;
        if !claimed {
            return Ok(false);
        }
        tracing::warn!(
            stream = id,
            frame = committed.frames,
            frames_lost = lost,
            "took over a stream whose server stopped"
        );
        let mut warnings = Vec::new();
        if !ours {
            warnings.push(format!(
                "taken over at frame {} by another server after the one coding it stopped; \
                 {lost} frames it had accepted were never committed",
                committed.frames
            ));
        }
        if state.reencode_on_finish {
            warnings.push(
                "re-encoding on finish dropped: the frames as sent before the handover were \
                 lost with the server that held them"
                    .into(),
            );
        }
        let mut take = take;
        take.meta = meta;
        take.live_until = Some(live_until);
        let live = Live {
            take,
            encoder: Some(encoder),
            basis_id: basis.map(|b| b.id()),
            chunk_frames,
            received: committed.frames,
            persisted: committed.frames,
            lease_until: live_until,
            unsaved: Default::default(),
            failed: None,
            last_activity: Instant::now(),
            archive: None,
            opening: Vec::new(),
            warnings,
            watchers: broadcast::Sender::new(STREAM_WATCH_QUEUE),
            latest: None,
            watchers_by: Shares::new(self.limits.watchers_per_caller as usize),
            _slot: slot,
            _share: share,
        };
        self.open
            .lock()
            .expect("streams lock")
            .insert(id.to_string(), Arc::new(tokio::sync::Mutex::new(live)));
        Ok(true)
    }
}
