//! Live streams: a take stored while it is being recorded. Frames are coded as they arrive
//! by the codec layer's stream encoder ([`crate::codec::stream`]: `lsdt-frame`, or
//! `lsdt-clip` clip by clip) and committed chunk by chunk, each commit one
//! transaction that adds the chunk and updates the take's header and statistics, so a range
//! of a take still being recorded can be fetched as soon as its chunk is in.
//!
//! A stream's coder state lives in this server's memory. If a client goes away, what was
//! committed stays; frames still pending in an unfinished chunk are committed when the
//! stream is finished, or when it has been idle too long ([`Streams::maintain`]). A server
//! that dies loses only those pending frames; its takes stay readable, and whichever server
//! next sees their lease run out closes them ([`Streams::close_orphans`]).
//!
//! Appends cost O(chunk), however long the stream: a commit adds one chunk row and updates
//! the take's running totals. A live take's stored header carries no chunk index (its
//! chunk rows are the index, [`crate::store::Store::chunk_index`]); the index is written
//! into the header once, when the stream closes. Memory is bounded per stream (points,
//! chunk length, the re-encoding copy) and per server (open streams), by [`crate::limits::Limits`].
//!
//! Watchers ([`Streams::watch`], the viewer's live page) get every append as it arrives,
//! before it is coded, through a bounded broadcast: one that reads too slowly skips appends
//! (and is told), so watching never holds the producer nor grows memory.
//!
//! With no search possible frame by frame, a stream codes to its bound as a max bound (a
//! mean bound is then met too) with the residual layer, and checks every chunk on its decoded
//! output before committing it. `finish` can re-encode the whole take with per-take choice.

mod coding;
mod handover;
mod registry;
mod request;
mod watchers;

pub use handover::Route;
pub use registry::Streams;
pub use request::{Append, OpenRequest, PointsSpec, StreamInfo};
pub use watchers::{Arrival, Watch};

use std::collections::VecDeque;
use std::sync::Arc;
use std::time::Instant;

use tokio::sync::{broadcast, OwnedSemaphorePermit};

use super::body;
use super::budget::{Holder, Share, Shares};
use super::choose::Decision;
use super::take::{Take, TakeMeta};
use super::{Error, Result};
use crate::codec;
use crate::codec::stream::{StreamChunk, StreamEncoder, StreamSpec};
use crate::limits::{STREAM_UNSAVED_BYTES, STREAM_WATCH_QUEUE};
use crate::motion::Motion;
use crate::store::{Closer, NewStream, NewTake, Store};
use coding::{reencode_take, stream_basis};
use handover::Resumable;
use registry::{unavailable, LEASE_MARGIN_MS};
use request::Plan;

/// An open stream, as the server that codes it holds it.
struct Live {
    take: Take,
    /// The codec layer's stream encoder: chunks, their checks, the take's index and totals.
    /// Taken out while it codes on the blocking pool.
    encoder: Option<StreamEncoder>,
    basis_id: Option<String>,
    chunk_frames: usize,
    received: usize,
    /// `received` as the take's row has it (written with each append, for a server that
    /// takes the stream over to count what was lost).
    persisted: usize,
    /// The end of the lease this server last wrote (ms since the epoch): past it, another
    /// server may take the stream over.
    lease_until: i64,
    /// Chunks coded but not yet stored because the database is away, oldest first: stored
    /// at the next append, flush or finish once it is back ([`Streams::save`]).
    unsaved: VecDeque<StreamChunk>,
    failed: Option<String>,
    last_activity: Instant,
    /// Every frame as sent, for re-encoding on finish (if asked for).
    archive: Option<Vec<f32>>,
    /// The frames sent since the stream opened, up to one chunk's worth, until the take
    /// has a body: its first commit derives the body from them ([`body::opening`]).
    opening: Vec<f32>,
    warnings: Vec<String>,
    /// Every append, to this stream's watchers; dropped (which ends them) when it closes.
    watchers: broadcast::Sender<Arc<Arrival>>,
    /// The newest frame received, for a watcher that joins between appends.
    latest: Option<Arc<Arrival>>,
    /// Watchers per caller ([`Limits::watchers_per_caller`]).
    watchers_by: Shares,
    /// This stream's place among the server's open streams, and among its caller's, given
    /// back when it closes.
    _slot: OwnedSemaphorePermit,
    _share: Share,
}

impl Live {
    fn info(&self) -> StreamInfo {
        StreamInfo {
            id: self.take.id.clone(),
            codec: self.take.codec,
            basis: self.basis_id.clone(),
            fps: self.take.fps,
            points: self.take.points,
            chunk_frames: self.chunk_frames,
            frames_received: self.received,
            frames_committed: self.take.frames,
            frames_lost: self.take.meta.frames_lost,
            chunks_committed: self.encoder.as_ref().map_or(0, StreamEncoder::chunks),
            live: true,
            max_mm: self.take.max_mm,
            mean_mm: self.take.mean_mm,
            warnings: self.warnings.clone(),
        }
    }

    fn encoder(&self) -> Result<&StreamEncoder> {
        self.encoder.as_ref().ok_or_else(encoder_missing)
    }

    fn encoder_mut(&mut self) -> Result<&mut StreamEncoder> {
        self.encoder.as_mut().ok_or_else(encoder_missing)
    }
}

type Entry = Arc<tokio::sync::Mutex<Live>>;

/// The encoder is taken out of a stream only while it codes, under the stream's lock.
fn encoder_missing() -> Error {
    Error::Internal("stream encoder missing".into())
}

impl Streams {
    /// Open a stream for `holder`: the take exists (with no frames) from now on.
    pub async fn open(
        &self,
        store: &Store,
        req: OpenRequest,
        holder: &Holder,
    ) -> Result<StreamInfo> {
        let plan = Plan::of(req, &self.limits)?;
        let (slot, share) = self.places(holder)?;
        let points = plan.names.len();
        let shape = Motion::new(
            plan.fps,
            plan.unit.clone(),
            plan.names.clone(),
            Vec::new(),
            None,
        )
        .map_err(|e| Error::InvalidRequest(e.to_string()))?;
        let layout = shape.layout_signature().to_hex();
        let basis = stream_basis(store, plan.codec, &layout, points).await?;
        let spec = StreamSpec {
            points,
            fps: plan.fps,
            metres_per_unit: plan.unit.metres_per_unit,
            bound: plan.bound,
            chunk_frames: plan.chunk_frames,
            shared: basis.as_ref(),
        };
        let encoder = match StreamEncoder::open(plan.codec, &spec) {
            Err(codec::Error::Invalid(why)) => {
                return Err(Error::InvalidRequest(format!(
                    "{why}; ask for shorter chunk_seconds"
                )))
            }
            r => r?,
        };
        let (codec, chunk_frames) = (plan.codec, plan.chunk_frames);
        let decision = Decision {
            winner: codec,
            reason: format!(
                "live stream: coded with {codec} as frames arrived, committed every {chunk_frames} frames"
            ),
            tried: Vec::new(),
            skipped: Vec::new(),
            keep: None,
            pruned: Vec::new(),
        };
        let meta = TakeMeta {
            point_names: plan.names,
            unit: plan.unit,
            warnings: Vec::new(),
            decision,
            decoded_blake3: None,
            interrupted: None,
            frames_lost: 0,
            handovers: Vec::new(),
            reencoded_from: None,
            events: Vec::new(),
            first_frame: None,
            analog: None,
            axes: None,
            roles_given: Default::default(),
            outputs: Vec::new(),
        };
        let mut take = Take::new(
            &plan.label,
            "stream",
            plan.fps,
            layout,
            codec,
            plan.bound,
            meta,
        );
        take.header = encoder.live_header().to_bytes();
        take.stored_bytes = take.header.len() as u64;
        let take_lease = self.lease_end();
        take.live_until = Some(take_lease);
        let state = Resumable {
            chunk_frames,
            reencode_on_finish: plan.reencode_on_finish,
            errors: None,
        };
        store
            .insert(&NewTake {
                row: take.to_row()?,
                chunks: Vec::new(),
                basis: basis.as_ref().map(|b| b.id()),
                skeleton: None,
                errors: None,
                analog: None,
                parameters: None,
                outputs: None,
                stream: Some(NewStream {
                    owner: self.owner_row(),
                    state: state.to_text()?,
                }),
            })
            .await?;
        let live = Live {
            take,
            encoder: Some(encoder),
            basis_id: basis.map(|b| b.id()),
            chunk_frames,
            received: 0,
            persisted: 0,
            lease_until: take_lease,
            unsaved: VecDeque::new(),
            failed: None,
            last_activity: Instant::now(),
            archive: plan.reencode_on_finish.then(Vec::new),
            opening: Vec::new(),
            warnings: Vec::new(),
            watchers: broadcast::Sender::new(STREAM_WATCH_QUEUE),
            latest: None,
            watchers_by: Shares::new(self.limits.watchers_per_caller as usize),
            _slot: slot,
            _share: share,
        };
        let info = live.info();
        let id = live.take.id.clone();
        self.open
            .lock()
            .expect("streams lock")
            .insert(id, Arc::new(tokio::sync::Mutex::new(live)));
        Ok(info)
    }

    /// The state of an open stream.
    pub async fn info(&self, store: &Store, id: &str) -> Result<StreamInfo> {
        match self.entry(id) {
            Some(e) => Ok(e.lock().await.info()),
            None => Err(Self::not_open(store, id).await),
        }
    }

    /// Append frames; commits every chunk they complete, and with `flush` the frames still
    /// pending too (the next chunk then starts with an intra frame: lower delay, a few more
    /// bytes).
    pub async fn append(&self, store: &Store, id: &str, append: Append) -> Result<StreamInfo> {
        append.check_time()?;
        let entry = match self.entry(id) {
            Some(e) => e,
            None => return Err(Self::not_open(store, id).await),
        };
        let mut live = entry.lock_owned().await;
        if let Some(why) = &live.failed {
            return Err(Error::Conflict(format!(
                "stream {id} failed ({why}); what was committed is kept: finish it"
            )));
        }
        append.check_frames(live.take.points, live.take.metres_per_unit)?;
        let Append {
            frames,
            first,
            flush,
            captured_ms,
        } = append;
        let w = live.take.points * 3;
        // While the database is away, coded chunks wait in memory; past a bound the stream
        // takes no more frames until they are stored. And once the lease this server last
        // wrote is about to run out, another server may take the stream over: no frame is
        // taken before the lease is written again (else frames answered for could be lost
        // uncounted).
        let held: usize = live.unsaved.iter().map(|c| c.payload.len()).sum();
        if held > STREAM_UNSAVED_BYTES || super::now_ms() + LEASE_MARGIN_MS >= live.lease_until {
            let r = match self.save(store, &mut live).await {
                Ok(()) => self.note_received(store, &mut live).await,
                Err(e) => Err(e),
            };
            if let Err(e) = r {
                if matches!(e, Error::Moved(_)) {
                    self.let_go(id);
                }
                return Err(e);
            }
        }
        let mut frames = frames;
        if let Some(first) = first {
            // A producer that numbers its appends sends each frame once, however often it
            // retries: the frames the stream has are dropped, a gap is refused.
            let have = live.received;
            if first > have {
                let lost = match live.take.meta.frames_lost {
                    0 => String::new(),
                    n => {
                        format!(" ({n} frames were lost when the server coding the stream stopped)")
                    }
                };
                return Err(Error::Conflict(format!(
                    "stream {id} has {have} frames; frames {have}..{first} were never \
                     received{lost}: send from frame {have}"
                )));
            }
            let skip = (have - first).min(frames.len() / w);
            frames.drain(..skip * w);
        }
        live.last_activity = Instant::now();
        let first = live.received;
        live.received += frames.len() / w;
        live.show_watchers(first, &frames, captured_ms);
        if live.take.meta.axes.is_none() {
            let room = (live.chunk_frames * w).saturating_sub(live.opening.len());
            live.opening
                .extend_from_slice(&frames[..room.min(frames.len())]);
        }
        let limit = self.limits.stream_archive_bytes as usize;
        if let Some(a) = &mut live.archive {
            if (a.len() + frames.len()) * 4 > limit {
                live.archive = None;
                live.warnings.push(format!(
                    "re-encoding on finish dropped: the frames passed {limit} bytes, the most \
                     a stream keeps for it; the take stays as coded live"
                ));
            } else {
                a.extend_from_slice(&frames);
            }
        }
        let held_before = live.unsaved.len();
        let mut r = self.code_and_commit(store, &mut live, frames, flush).await;
        if r.is_ok() && live.persisted != live.received {
            // No chunk carried the count: write it, for a server that takes over.
            r = self.note_received(store, &mut live).await;
        }
        match r {
            Ok(()) => {}
            // The frames are taken: coded and held until the database is back (the answer
            // says how many are committed).
            Err(e) if unavailable(&e) => {
                // Once per chunk held, not per append.
                if live.unsaved.len() > held_before {
                    tracing::warn!(stream = id, error = %e, held = live.unsaved.len(), "holding a stream's chunks until the database is back");
                }
            }
            Err(e @ Error::Moved(_)) => {
                self.let_go(id);
                return Err(e);
            }
            Err(e) => {
                live.failed = Some(e.to_string());
                return Err(e);
            }
        }
        Ok(live.info())
    }

    /// Close a stream: commit what is pending, write the chunk index into the take's header
    /// and mark it finished with its body derived from the whole take; and if the stream
    /// kept its frames, code the whole take again with per-take choice, keeping that if it
    /// is smaller.
    pub async fn finish(&self, store: &Store, id: &str) -> Result<Take> {
        let entry = match self.entry(id) {
            Some(e) => e,
            None => return Err(Self::not_open(store, id).await),
        };
        let mut live = entry.lock_owned().await;
        if live.failed.is_none() {
            match self
                .code_and_commit(store, &mut live, Vec::new(), true)
                .await
            {
                Ok(()) => {}
                // Not finished: the stream stays open, its chunks held, for a finish later.
                Err(e) if unavailable(&e) => return Err(e),
                // Another server codes it now: the finish is sent there.
                Err(e @ Error::Moved(_)) => {
                    self.let_go(id);
                    return Err(e);
                }
                Err(e) => {
                    tracing::warn!(stream = id, error = %e, "pending frames of a finished stream were lost");
                    live.warnings
                        .push(format!("frames pending at finish were lost: {e}"));
                }
            }
        }
        let encoder = live.encoder()?;
        let (closed, digest) = (encoder.closed_header(), encoder.decoded_digest());
        // The take as this stream closes it (what the store holds unless another server
        // closed it first, from the same committed chunks), its body derived from all of it.
        let mut take = live.take.clone();
        take.meta.decoded_blake3 = Some(digest);
        take.meta.warnings.extend(live.warnings.iter().cloned());
        take.header = closed.to_bytes();
        take.live_until = None;
        if take.frames > 0 {
            take.meta.axes = Some(body::closing(store, &take).await?);
        }
        let closed = store
            .close_live(
                id,
                &take.header,
                &take.meta.to_record(id)?,
                Closer::Owner(&self.node.id),
            )
            .await?;
        // Closed (or not ours to close): no longer open here. A close that failed (the
        // database away) leaves it open, for the finish to be sent again.
        self.open.lock().expect("streams lock").remove(id);
        if !closed {
            if store.stream(id).await?.is_some() {
                // Taken over by another server (this one could not renew its lease): the
                // finish is sent there.
                return Err(Self::lost(id));
            }
            // Closed from its chunk rows by another server after the lease ran out, or
            // deleted: what it stored is what was committed, the same chunks.
            tracing::warn!(
                stream = id,
                "stream was closed elsewhere before it finished"
            );
            return super::fetch::take(store, id).await;
        }
        if let Some(frames) = live.archive.take().filter(|_| take.frames > 0) {
            let committed = take.frames * take.points * 3;
            if frames.len() >= committed {
                let mut frames = frames;
                frames.truncate(committed);
                reencode_take(store, id, frames).await?;
            }
        }
        super::fetch::take(store, id).await
    }
}
