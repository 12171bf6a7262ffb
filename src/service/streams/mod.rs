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
//! chunk length, the re-encoding copy) and per server (open streams), by [`Limits`].
//!
//! Watchers ([`Streams::watch`], the viewer's live page) get every append as it arrives,
//! before it is coded, through a bounded broadcast: one that reads too slowly skips appends
//! (and is told), so watching never holds the producer nor grows memory.
//!
//! With no search possible frame by frame, a stream codes to its bound as a max bound (a
//! mean bound is then met too) with the residual layer, and checks every chunk on its decoded
//! output before committing it. `finish` can re-encode the whole take with per-take choice.

mod handover;

use handover::Resumable;
pub use handover::Route;

use std::collections::{HashMap, VecDeque};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use serde::{Deserialize, Serialize};
use tokio::sync::{broadcast, watch, OwnedSemaphorePermit, Semaphore};

use super::budget::{Holder, Share, Shares};
use super::choose::{CodecRequest, Decision, Keep};
use super::prepared::ReadCaches;
use super::take::{Label, Take, TakeMeta};
use super::{blocking, Error, Node, Result};
use crate::codec::stream::{StreamChunk, StreamEncoder, StreamSpec};
use crate::codec::{self, Basis, CodecId, ErrorBound, Latency};
use crate::limits::{
    Limits, MAX_CAPTURE_MS, MAX_COORDINATE_M, STREAM_UNSAVED_BYTES, STREAM_WATCHERS,
    STREAM_WATCH_QUEUE, STREAM_WATCH_SAMPLES,
};
use crate::motion::units::{parse_unit, Unit, UnitSource};
use crate::motion::Motion;
use crate::store::{BasisRow, ChunkAppend, ChunkRow, Closer, NewStream, NewTake, Store};

/// The points of a stream: their names, or just how many.
#[derive(Debug, Clone, Deserialize)]
#[serde(untagged)]
pub enum PointsSpec {
    Names(Vec<String>),
    Count(usize),
}

/// `POST /v1/streams`.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct OpenRequest {
    pub name: Option<String>,
    #[serde(default)]
    pub library: String,
    #[serde(default)]
    pub tags: Vec<String>,
    pub fps: f64,
    pub points: PointsSpec,
    /// mm (default), cm, m, in, cmu, or metres per unit.
    pub unit: Option<String>,
    pub max_error_mm: Option<f64>,
    pub mean_error_mm: Option<f64>,
    /// A codec that can stream ([`codec::stream::streaming_codecs`]); default
    /// [`codec::stream::DEFAULT_CODEC`].
    pub codec: Option<CodecId>,
    /// Seconds per chunk (an intra period, a clip).
    pub chunk_seconds: Option<f64>,
    /// Keep the frames as sent until the stream finishes, then code the whole take with
    /// per-take choice and keep that if smaller. Costs 12 bytes per point per frame of
    /// server memory while the stream is open.
    #[serde(default)]
    pub reencode_on_finish: bool,
}

/// An [`OpenRequest`] checked: every count within its limit before anything is made from it.
struct Plan {
    label: Label,
    fps: f64,
    names: Vec<String>,
    unit: Unit,
    bound: ErrorBound,
    codec: CodecId,
    chunk_frames: usize,
    reencode_on_finish: bool,
}

impl Plan {
    fn of(req: OpenRequest, limits: &Limits) -> Result<Plan> {
        let bad = |m: String| Err(Error::InvalidRequest(m));
        crate::limits::fps(req.fps).map_err(Error::InvalidRequest)?;
        // The count is checked before anything is made from it: a client may ask for 2e10.
        let count = match &req.points {
            PointsSpec::Names(n) => n.len(),
            PointsSpec::Count(n) => *n,
        };
        let max_points = limits.stream_points;
        if count == 0 || count as u64 > max_points {
            return bad(format!(
                "a stream needs 1..={max_points} points, got {count}"
            ));
        }
        let names: Vec<String> = match req.points {
            PointsSpec::Names(n) => n,
            PointsSpec::Count(n) => (0..n).map(|i| format!("p{i}")).collect(),
        };
        if let Some(i) = names.iter().position(|n| n.trim().is_empty()) {
            return bad(format!("point {i} has an empty name"));
        }
        let invalid = |e: &dyn std::fmt::Display| Error::InvalidRequest(e.to_string());
        let metres = match &req.unit {
            Some(u) => parse_unit(u).map_err(|e| invalid(&e))?,
            None => 0.001,
        };
        let unit = Unit::new(metres, UnitSource::Explicit).map_err(|e| invalid(&e))?;
        let bound = ErrorBound::from_request(req.max_error_mm, req.mean_error_mm)
            .map_err(|e| invalid(&e))?;
        let codec = req.codec.unwrap_or(codec::stream::DEFAULT_CODEC);
        let streaming = codec::stream::streaming_codecs();
        if !streaming.contains(&codec) {
            let names: Vec<String> = streaming.iter().map(|c| c.to_string()).collect();
            return bad(format!(
                "streams are coded with {}, not {codec}",
                names.join(" or ")
            ));
        }
        let chunk_frames = match req.chunk_seconds {
            Some(s) => {
                let s = crate::limits::chunk_seconds(s).map_err(Error::InvalidRequest)?;
                ((s * req.fps).round() as usize).max(1)
            }
            None => codec::default_chunk_frames(req.fps),
        };
        if let Err(why) = crate::limits::check(
            "frames × points of one chunk",
            (chunk_frames * names.len()) as u64,
            limits.stream_chunk_samples,
        ) {
            return bad(format!("{why}: ask for shorter chunk_seconds"));
        }
        Ok(Plan {
            label: Label {
                name: req.name,
                library: req.library,
                tags: req.tags,
            },
            fps: req.fps,
            names,
            unit,
            bound,
            codec,
            chunk_frames,
            reencode_on_finish: req.reencode_on_finish,
        })
    }
}

/// One append to a stream, as the producer sent it.
#[derive(Debug, Clone, Default)]
pub struct Append {
    /// `n × points × 3` values, NaN for missing samples.
    pub frames: Vec<f32>,
    /// The stream's index of the first frame, if the producer numbers its appends: frames
    /// the stream has already are dropped (a retried append), a gap is refused.
    pub first: Option<usize>,
    pub flush: bool,
    /// When the producer captured the last frame (ms since the epoch, its clock).
    pub captured_ms: Option<i64>,
}

/// What a stream reports after each call.
#[derive(Debug, Clone, Serialize)]
pub struct StreamInfo {
    pub id: String,
    pub codec: CodecId,
    /// The shared basis the stream codes with, if its codec uses one.
    pub basis: Option<String>,
    pub fps: f64,
    pub points: usize,
    pub chunk_frames: usize,
    pub frames_received: usize,
    pub frames_committed: usize,
    /// Frames accepted by a server that stopped before committing them (the stream was
    /// then taken over by another): not in the take. Their producer may send them again.
    pub frames_lost: usize,
    pub chunks_committed: usize,
    pub live: bool,
    pub max_mm: f64,
    pub mean_mm: f64,
    /// What the stream gave up to stay within its limits (e.g. re-encoding on finish).
    pub warnings: Vec<String>,
}

/// Frames as they arrived at an open stream, for its watchers: the newest frames of one
/// append (at most [`STREAM_WATCH_SAMPLES`] samples), as sent, before they are coded.
#[derive(Debug, Clone)]
pub struct Arrival {
    /// The index in the take of the first frame here.
    pub first: usize,
    pub frames: usize,
    /// When this server took the append (ms since the Unix epoch, server clock).
    pub received_ms: i64,
    /// When the producer captured the append's last frame, if it said (`captured_ms`,
    /// producer clock).
    pub captured_ms: Option<i64>,
    /// `frames × points × 3`, stored units, NaN where a sample is missing.
    pub positions: Vec<f32>,
}

/// A watcher of an open stream: its state now, its newest frame (so there is something
/// to show at once), and every append from here on.
pub struct Watch {
    pub info: StreamInfo,
    pub latest: Option<Arc<Arrival>>,
    pub arrivals: broadcast::Receiver<Arc<Arrival>>,
    /// Turns true when the server shuts down: watchers end then, not hold it open.
    pub stopping: watch::Receiver<bool>,
    /// This watcher's place among its caller's watchers of the stream.
    _share: Share,
}

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

    /// Pass an append on to the watchers (its newest frames) and keep its last frame.
    fn show_watchers(&mut self, first: usize, frames: &[f32], captured_ms: Option<i64>) {
        let w = self.take.points * 3;
        let n = frames.len() / w;
        if n == 0 {
            return;
        }
        let received_ms = super::now_ms();
        let newest = |k: usize| {
            Arc::new(Arrival {
                first: first + n - k,
                frames: k,
                received_ms,
                captured_ms,
                positions: frames[(n - k) * w..].to_vec(),
            })
        };
        let latest = newest(1);
        if self.watchers.receiver_count() > 0 {
            let kept = n.min((STREAM_WATCH_SAMPLES / self.take.points).max(1));
            let arrival = if kept == 1 {
                latest.clone()
            } else {
                newest(kept)
            };
            // Fails only when every watcher has gone since the count: nothing to do.
            let _ = self.watchers.send(arrival);
        }
        self.latest = Some(latest);
    }

    fn encoder(&self) -> Result<&StreamEncoder> {
        self.encoder
            .as_ref()
            .ok_or_else(|| Error::Internal("stream encoder missing".into()))
    }
}

type Entry = Arc<tokio::sync::Mutex<Live>>;

/// How long before the lease it last wrote runs out a server writes it again before it
/// takes more frames ([`Streams::append`]).
const LEASE_MARGIN_MS: i64 = 1_000;

/// Whether `e` is the database being away (worth holding on and trying again), not a fault.
fn unavailable(e: &Error) -> bool {
    matches!(e, Error::Store(s) if s.is_unavailable())
}

/// The open streams of this server.
pub struct Streams {
    open: Mutex<HashMap<String, Entry>>,
    /// One permit per stream that may be open at once.
    slots: Arc<Semaphore>,
    /// Streams open per caller ([`Limits::streams_per_caller`]).
    by_caller: Shares,
    limits: Limits,
    /// A stream with no request for this long is finished by [`Streams::maintain`].
    pub idle: Duration,
    /// How long a live take stays live without its server renewing it. Servers renew the
    /// leases of their open streams at every [`Streams::maintain`]; run that more often.
    pub lease: Duration,
    /// Set when the server shuts down ([`Streams::stop_watchers`]).
    stopping: watch::Sender<bool>,
    /// This server, as stream rows name their owner.
    node: Node,
    /// Held while a stream is taken over ([`handover`]).
    taking_over: tokio::sync::Mutex<()>,
}

impl Streams {
    /// `limits.stream_points` is capped at [`crate::limits::LSDT_MAX_POINTS`]: a stream codes
    /// with an LSDT basis of its layout.
    pub fn new(mut limits: Limits, lease: Duration, node: Node) -> Self {
        limits.stream_points = limits
            .stream_points
            .min(crate::limits::LSDT_MAX_POINTS as u64);
        Streams {
            open: Mutex::new(HashMap::new()),
            slots: Arc::new(Semaphore::new(limits.open_streams as usize)),
            by_caller: Shares::new(limits.streams_per_caller as usize),
            limits,
            idle: Duration::from_secs(300),
            lease,
            stopping: watch::Sender::new(false),
            node,
            taking_over: tokio::sync::Mutex::new(()),
        }
    }

    /// Streams open on this server now.
    pub fn open_count(&self) -> usize {
        self.open.lock().expect("streams lock").len()
    }

    fn lease_end(&self) -> i64 {
        super::now_ms() + self.lease.as_millis() as i64
    }
}

/// The shared basis a stream coded with `codec` codes with, if the codec uses one: the
/// newest of its kind trained for the layout, or else the codec's untrained basis (stored as
/// a basis too, so the take references what decodes it).
async fn stream_basis(
    store: &Store,
    codec: CodecId,
    layout: &str,
    points: usize,
) -> Result<Option<Arc<Basis>>> {
    let Some(kind) = codec::codec(codec)?.basis_kind() else {
        return Ok(None);
    };
    if let Some(b) = super::bases::latest_for(store, layout)
        .await?
        .into_iter()
        .find(|b| b.kind() == kind)
    {
        return Ok(Some(b));
    }
    let (b, provenance) = super::blocking(move || codec::stream::untrained_basis(codec, points))
        .await?
        .ok_or_else(|| {
            Error::Unsatisfiable(format!(
                "{codec} streams code with a trained {kind} basis and none is trained for \
                     this layout; train one first"
            ))
        })?;
    if !store.basis_exists(&b.id()).await? {
        let m = &b.matrices()[0];
        store
            .insert_basis(&BasisRow {
                id: b.id(),
                kind: kind.name().into(),
                layout: layout.to_string(),
                points: points as i64,
                dims: format!("{}×{}×{}", b.matrices().len(), m.rows, m.cols),
                payload: b.bytes().to_vec(),
                provenance: serde_json::json!({ "algorithm": provenance }),
                // Dated at the epoch, so that any basis trained later is the layout's newest.
                created_at: 0,
                used_by: 0,
            })
            .await?;
    }
    Ok(Some(Arc::new(b)))
}

impl Streams {
    fn entry(&self, id: &str) -> Option<Entry> {
        self.open.lock().expect("streams lock").get(id).cloned()
    }

    /// A place among `holder`'s and the server's open streams, held until the stream
    /// closes (or moves to another server).
    fn places(&self, holder: &Holder) -> Result<(OwnedSemaphorePermit, Share)> {
        let share = self.by_caller.take(holder).ok_or_else(|| {
            Error::Busy(format!(
                "this caller has {} streams open, the most one caller may have at once; \
                 finish one first",
                self.by_caller.most()
            ))
        })?;
        let slot = self.slots.clone().try_acquire_owned().map_err(|_| {
            Error::Busy(format!(
                "{} streams are open, the most this server takes at once; finish one or retry later",
                self.limits.open_streams
            ))
        })?;
        Ok((slot, share))
    }

    /// Drop a stream this server no longer codes (another server took it over): its
    /// requests go to the new owner from now on.
    fn let_go(&self, id: &str) {
        if self.open.lock().expect("streams lock").remove(id).is_some() {
            tracing::warn!(stream = id, "another server took this stream over");
        }
    }

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
            up: None,
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

    /// Watch an open stream for `holder`: every append from now on, as it arrives. At most
    /// [`STREAM_WATCHERS`] at once per stream, [`Limits::watchers_per_caller`] of them one
    /// caller's; the watch ends when the stream closes.
    pub async fn watch(&self, store: &Store, id: &str, holder: &Holder) -> Result<Watch> {
        let Some(entry) = self.entry(id) else {
            return Err(Self::not_open(store, id).await);
        };
        let live = entry.lock().await;
        if live.watchers.receiver_count() >= STREAM_WATCHERS {
            return Err(Error::Busy(format!(
                "stream {id} has {STREAM_WATCHERS} watchers, the most it takes at once"
            )));
        }
        let share = live.watchers_by.take(holder).ok_or_else(|| {
            Error::Busy(format!(
                "this caller watches stream {id} {} times, the most one caller may",
                live.watchers_by.most()
            ))
        })?;
        Ok(Watch {
            info: live.info(),
            latest: live.latest.clone(),
            arrivals: live.watchers.subscribe(),
            stopping: self.stopping.subscribe(),
            _share: share,
        })
    }

    /// End every watch: the server is shutting down, and open watches would hold it.
    pub fn stop_watchers(&self) {
        self.stopping.send_replace(true);
    }

    /// Turns true when the server shuts down ([`Streams::stop_watchers`]): what a watch
    /// forwarded to another server ends on.
    pub fn stopping(&self) -> watch::Receiver<bool> {
        self.stopping.subscribe()
    }

    /// Why a stream id is not open here: finished or coded elsewhere (409), or unknown (404).
    async fn not_open(store: &Store, id: &str) -> Error {
        match store.get(id).await {
            Ok(Some(row)) => match row.live_until {
                None => Error::Conflict(format!("stream {id} is finished")),
                Some(until) => Error::Conflict(format!(
                    "stream {id} is not open on this server: another server codes it, or its \
                     server stopped and the take is closed when its lease runs out \
                     ({until} ms since the epoch)"
                )),
            },
            Ok(None) => Error::NotFound(format!("stream {id}")),
            Err(e) => e.into(),
        }
    }

    /// Append frames; commits every chunk they complete, and with `flush` the frames still
    /// pending too (the next chunk then starts with an intra frame: lower delay, a few more
    /// bytes).
    pub async fn append(
        &self,
        store: &Store,
        caches: &ReadCaches,
        id: &str,
        append: Append,
    ) -> Result<StreamInfo> {
        let Append {
            frames,
            first,
            flush,
            captured_ms,
        } = append;
        if let Some(t) = captured_ms.filter(|t| !(0..=MAX_CAPTURE_MS).contains(t)) {
            return Err(Error::InvalidRequest(format!(
                "captured_ms {t} is not a time in ms since the Unix epoch (0..={MAX_CAPTURE_MS})"
            )));
        }
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
        let w = live.take.points * 3;
        if !frames.len().is_multiple_of(w) {
            return Err(Error::InvalidRequest(format!(
                "{} values are not whole frames of {} points",
                frames.len(),
                live.take.points
            )));
        }
        let to_m = live.take.metres_per_unit;
        if let Some(i) = frames
            .iter()
            .position(|v| v.is_infinite() || (f64::from(v.abs()) * to_m) > MAX_COORDINATE_M)
        {
            return Err(Error::InvalidRequest(format!(
                "value {i} ({}) is beyond any physical scale (|x| ≤ {MAX_COORDINATE_M} m); \
                 send null (JSON) or NaN (f32) for a missing sample",
                frames[i]
            )));
        }
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
        caches.forget(id);
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

    /// Write how many frames the producer has had accepted, renewing the lease:
    /// [`Error::Moved`] if another server took the stream over meanwhile.
    async fn note_received(&self, store: &Store, live: &mut Live) -> Result<()> {
        let received = live.received;
        let until = self.lease_end();
        if !store
            .note_received(&live.take.id, &self.node.id, received as i64, until)
            .await?
        {
            return Err(Self::lost(&live.take.id));
        }
        live.persisted = received;
        live.lease_until = until;
        Ok(())
    }

    /// Why this server may no longer write a stream's take: another server took it over
    /// (or it was finished or deleted meanwhile); the same request sent again is routed to
    /// wherever it is now.
    fn lost(id: &str) -> Error {
        Error::Moved(format!(
            "stream {id} is no longer coded by this server (another server took it over, or \
             it was finished or deleted); send the request again"
        ))
    }

    /// Store the chunks waiting for the database, in order; the first that cannot be stored
    /// (the database still away) stays first, and its error is returned.
    ///
    /// A chunk leaves the queue only once stored: a request dropped while it commits (its
    /// client gone) leaves it first in line, and storing it again is a no-op
    /// ([`Store::append_chunk`] stores a chunk once).
    async fn save(&self, store: &Store, live: &mut Live) -> Result<()> {
        while let Some(chunk) = live.unsaved.front().cloned() {
            self.commit(store, live, &chunk).await?;
            live.unsaved.pop_front();
            live.encoder
                .as_mut()
                .ok_or_else(|| Error::Internal("stream encoder missing".into()))?
                .confirm(chunk)?;
        }
        Ok(())
    }

    /// Code `frames` on the blocking pool and commit every chunk they finish, in order.
    async fn code_and_commit(
        &self,
        store: &Store,
        live: &mut Live,
        frames: Vec<f32>,
        flush: bool,
    ) -> Result<()> {
        let mut encoder = live
            .encoder
            .take()
            .ok_or_else(|| Error::Internal("stream encoder missing".into()))?;
        let (encoder, chunks) = blocking(move || {
            let chunks = encoder.push(&frames, flush);
            (encoder, chunks)
        })
        .await?;
        live.encoder = Some(encoder);
        live.unsaved.extend(chunks?);
        self.save(store, live).await
    }

    /// Commit one coded and checked chunk: one chunk row and the take's running totals,
    /// nothing that grows with the stream.
    async fn commit(&self, store: &Store, live: &mut Live, chunk: &StreamChunk) -> Result<()> {
        let totals = live.encoder()?.totals_with(chunk);
        let mut take = live.take.clone();
        take.set_frames(totals.frames);
        take.set_measured(totals.stored_bytes, &totals.stats);
        let chunk_row = ChunkRow {
            idx: chunk.index as i64,
            first_frame: i64::from(chunk.meta.first_frame),
            frames: i64::from(chunk.meta.frames),
            crc32c: chunk.meta.crc32c,
            payload: chunk.payload.clone(),
        };
        let state = Resumable {
            chunk_frames: live.chunk_frames,
            reencode_on_finish: live.archive.is_some(),
            errors: Some(chunk.running().clone()),
        }
        .to_text()?;
        let until = self.lease_end();
        let append = ChunkAppend {
            server: &self.node.id,
            live_until: until,
            frames_received: live.received as i64,
            state: &state,
        };
        if !store
            .append_chunk(&take.id, &take.totals(), &chunk_row, &append)
            .await?
        {
            return Err(Self::lost(&live.take.id));
        }
        live.take = take;
        live.persisted = live.received;
        live.lease_until = until;
        Ok(())
    }

    /// Close a stream: commit what is pending, write the chunk index into the take's header
    /// and mark it finished, and if the stream kept its frames, code the whole take again
    /// with per-take choice, keeping that if it is smaller.
    pub async fn finish(&self, store: &Store, caches: &ReadCaches, id: &str) -> Result<Take> {
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
        // closed it first, from the same committed chunks).
        let mut take = live.take.clone();
        take.meta.decoded_blake3 = Some(digest);
        take.meta.warnings.extend(live.warnings.iter().cloned());
        take.header = closed.to_bytes();
        take.live_until = None;
        let closed = store
            .close_live(
                id,
                &take.header,
                &meta_text(id, &take.meta)?,
                Closer::Owner(&self.node.id),
            )
            .await?;
        // Closed (or not ours to close): no longer open here. A close that failed (the
        // database away) leaves it open, for the finish to be sent again.
        self.open.lock().expect("streams lock").remove(id);
        caches.forget(id);
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
                reencode_take(store, &take, frames[..committed].to_vec()).await?;
                caches.forget(id);
            }
        }
        super::fetch::take(store, id).await
    }

    /// Housekeeping, run every few seconds by the server: renew the leases of this server's
    /// open streams, finish those idle longer than [`Streams::idle`], and close the takes of
    /// streams whose server died ([`Streams::close_orphans`]).
    pub async fn maintain(&self, store: &Store, caches: &ReadCaches) {
        let entries: Vec<(String, Entry)> = self
            .open
            .lock()
            .expect("streams lock")
            .iter()
            .map(|(k, v)| (k.clone(), v.clone()))
            .collect();
        // Leases first: finishing an idle stream may take a while (re-encoding), and must
        // not let the others' leases run out.
        let mut idle = Vec::new();
        for (id, e) in entries {
            // A stream busy with a request renews its lease by committing.
            match e.try_lock() {
                Ok(l) if l.last_activity.elapsed() > self.idle => {
                    idle.push(id);
                    continue;
                }
                Ok(_) => {}
                Err(_) => continue,
            }
            let until = self.lease_end();
            match store.renew_lease(&id, &self.node.id, until).await {
                Err(err) => {
                    tracing::warn!(stream = %id, error = %err, "renewing a stream's lease failed");
                    continue;
                }
                Ok(false) => {
                    self.let_go(&id);
                    continue;
                }
                Ok(true) => {}
            }
            if let Ok(mut live) = e.try_lock() {
                live.lease_until = until;
                // The database is back: store what a quiet stream held meanwhile.
                if !live.unsaved.is_empty() {
                    if let Err(err) = self.save(store, &mut live).await {
                        tracing::warn!(stream = %id, error = %err, "storing held chunks failed");
                    }
                    caches.forget(&id);
                }
            }
        }
        for id in idle {
            if let Err(err) = self.finish(store, caches, &id).await {
                tracing::warn!(stream = %id, error = %err, "finishing an idle stream failed");
            }
        }
        if let Err(err) = self.close_orphans(store, caches).await {
            tracing::warn!(error = %err, "closing orphaned live takes failed");
        }
    }

    /// Close every live take whose lease ran out a lease ago or more and that no stream
    /// here codes: its server stopped mid-stream, and no producer came back to go on
    /// through another server within that lease ([`handover`]). What it committed stays,
    /// indexed from its chunk rows; frames that were pending on that server are lost, and
    /// the take says so and how many.
    pub async fn close_orphans(&self, store: &Store, caches: &ReadCaches) -> Result<usize> {
        let mut closed = 0;
        let before = super::now_ms() - self.lease.as_millis() as i64;
        for id in store.expired_live(before).await? {
            if self.entry(&id).is_some() {
                continue;
            }
            let take = match super::fetch::take(store, &id).await {
                Ok(t) => t,
                Err(Error::NotFound(_)) => continue,
                Err(e) => {
                    // One bad record must not keep the others open; `verify` reports it.
                    tracing::error!(stream = %id, error = %e, "an orphaned live take does not parse");
                    continue;
                }
            };
            let header = super::fetch::header_from_index(&take, &store.chunk_index(&id).await?)?;
            let received = store.stream(&id).await?.map_or(0, |s| s.frames_received);
            let mut meta = take.meta.clone();
            meta.frames_lost += (received - take.frames as i64).max(0) as usize;
            meta.interrupted = Some(
                "the server coding this stream stopped before it finished; the take keeps the \
                 chunks it had committed"
                    .into(),
            );
            let orphan = Closer::Orphan {
                before,
                frames: take.frames as i64,
            };
            if store
                .close_live(&id, &header.to_bytes(), &meta_text(&id, &meta)?, orphan)
                .await?
            {
                tracing::warn!(stream = %id, frames = take.frames, "closed a stream whose server stopped");
                caches.forget(&id);
                closed += 1;
            }
        }
        Ok(closed)
    }
}

/// A take's metadata as stored.
fn meta_text(id: &str, meta: &TakeMeta) -> Result<String> {
    serde_json::to_string(meta).map_err(|e| Error::Internal(format!("take {id}: meta: {e}")))
}

/// Code a finished stream's take again, from the frames as sent, with every candidate
/// codec; keep the result if it is smaller than the live coding.
async fn reencode_take(store: &Store, take: &Take, positions: Vec<f32>) -> Result<()> {
    let (unit, names) = (take.meta.unit.clone(), take.meta.point_names.clone());
    let motion = Arc::new(
        Motion::new(take.fps, unit, names, positions, None)
            .map_err(|e| Error::Internal(e.to_string()))?,
    );
    let coding = super::ingest::Coding {
        codec: CodecRequest::Auto,
        bound: take.bound,
        latency: Latency::Sequence,
        keep: Keep::default(),
        hints: Default::default(),
    };
    let (decision, enc) =
        super::ingest::encode_best(store, motion, &take.layout, &coding, None).await?;
    if enc.stored_bytes as u64 >= take.stored_bytes {
        return Ok(());
    }
    let mut new = take.clone();
    new.codec = decision.winner;
    new.set_measured(enc.stored_bytes, &enc.stats);
    new.header = enc.container.header.to_bytes();
    new.meta.decision = decision;
    new.meta.decoded_blake3 = Some(enc.decoded_digest.clone());
    new.meta.reencoded_from = Some(take.codec);
    let basis = enc.container.header.basis.as_ref().map(codec::basis::hex);
    let chunks = super::take::chunk_rows(&enc.container);
    store
        .update_encoding(&new.to_row()?, &chunks, true, basis.as_deref())
        .await?;
    Ok(())
}
