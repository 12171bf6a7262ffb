//! Live streams: a take stored while it is being recorded. Frames are coded as they arrive
//! (`lsdt-frame`, or `lsdt-clip` clip by clip) and committed chunk by chunk, each commit one
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
//! With no search possible frame by frame, a stream codes to its bound as a max bound (a
//! mean bound is then met too) with the residual layer, and checks every chunk on its decoded
//! output before committing it. `finish` can re-encode the whole take with per-take choice.

use std::collections::HashMap;
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use serde::{Deserialize, Serialize};
use tokio::sync::{OwnedSemaphorePermit, Semaphore};

use super::choose::{CodecRequest, Decision};
use super::prepared::ReadCaches;
use super::{blocking, Error, Result};
use crate::codec::container::{pack_chunk, ChunkMeta};
use crate::codec::lsdt::clip::{self, ClipParams};
use crate::codec::lsdt::frame::{self, FrameEncoder};
use crate::codec::lsdt::spatial::dct_basis;
use crate::codec::{
    self, Basis, BasisKind, ChunkDecoder, ChunkOut, CodecId, ErrorBound, Header, Input, Latency,
};
use crate::limits::{Limits, MAX_COORDINATE_M, MAX_FPS};
use crate::motion::metrics::Accumulator;
use crate::motion::units::{parse_unit, Unit, UnitSource};
use crate::motion::Motion;
use crate::store::{BasisRow, ChunkEntry, ChunkRow, NewSequence, SequenceRow, Store};

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
    /// `lsdt-frame` (default) or `lsdt-clip`.
    pub codec: Option<CodecId>,
    /// Seconds per chunk: the intra period of `lsdt-frame`, the clip of `lsdt-clip`.
    pub chunk_seconds: Option<f64>,
    /// Keep the frames as sent until the stream finishes, then code the whole take with
    /// per-take choice and keep that if smaller. Costs 12 bytes per point per frame of
    /// server memory while the stream is open.
    #[serde(default)]
    pub reencode_on_finish: bool,
}

/// What a stream reports after each call.
#[derive(Debug, Clone, Serialize)]
pub struct StreamInfo {
    pub id: String,
    pub codec: CodecId,
    pub basis: String,
    pub fps: f64,
    pub points: usize,
    pub chunk_frames: usize,
    pub frames_received: usize,
    pub frames_committed: usize,
    pub chunks_committed: usize,
    pub live: bool,
    pub max_mm: f64,
    pub mean_mm: f64,
    /// What the stream gave up to stay within its limits (e.g. re-encoding on finish).
    pub warnings: Vec<String>,
}

enum Coder {
    Frame(Box<FrameEncoder>),
    Clip(ClipParams),
}

struct Live {
    row: SequenceRow,
    /// The take's header without its chunk index (what is stored while it is live).
    header: Header,
    /// The chunks committed so far; written into the header when the stream closes.
    index: Vec<ChunkMeta>,
    /// Stored bytes of the header without its index.
    header_len: usize,
    payload_bytes: usize,
    /// Running digest of the committed chunks' decoded frames (see `codec::decoded_digest`).
    digest: blake3::Hasher,
    coder: Option<Coder>,
    basis: Arc<Basis>,
    decoder: Arc<dyn ChunkDecoder>,
    points: usize,
    to_mm: f64,
    bound: ErrorBound,
    chunk_frames: usize,
    received: usize,
    /// Frames received and not yet committed, as sent (NaN for missing samples).
    pending: Vec<f32>,
    stats: Accumulator,
    failed: Option<String>,
    last_activity: Instant,
    /// Every frame as sent, for re-encoding on finish (if asked for).
    archive: Option<Vec<f32>>,
    warnings: Vec<String>,
    /// This stream's place among the server's open streams, given back when it closes.
    _slot: OwnedSemaphorePermit,
}

impl Live {
    fn info(&self, live: bool) -> StreamInfo {
        StreamInfo {
            id: self.row.id.clone(),
            codec: self.header.codec,
            basis: self.basis.id(),
            fps: self.row.fps,
            points: self.points,
            chunk_frames: self.chunk_frames,
            frames_received: self.received,
            frames_committed: self.row.frames as usize,
            chunks_committed: self.index.len(),
            live,
            max_mm: self.row.max_mm,
            mean_mm: self.row.mean_mm,
            warnings: self.warnings.clone(),
        }
    }

    /// The header with the committed chunks as its index: what the take is once closed.
    fn closed_header(&self) -> Header {
        Header {
            frames: self.row.frames as u32,
            chunks: self.index.clone(),
            ..self.header.clone()
        }
    }
}

type Entry = Arc<tokio::sync::Mutex<Live>>;

/// The open streams of this server.
pub struct Streams {
    open: Mutex<HashMap<String, Entry>>,
    /// One permit per stream that may be open at once.
    slots: Arc<Semaphore>,
    limits: Limits,
    /// A stream with no request for this long is finished by [`Streams::maintain`].
    pub idle: Duration,
    /// How long a live take stays live without its server renewing it. Servers renew the
    /// leases of their open streams at every [`Streams::maintain`]; run that more often.
    pub lease: Duration,
}

impl Streams {
    /// `limits.stream_points` is capped at [`crate::limits::LSDT_MAX_POINTS`]: a stream codes
    /// with an LSDT basis of its layout.
    pub fn new(mut limits: Limits, lease: Duration) -> Self {
        limits.stream_points = limits
            .stream_points
            .min(crate::limits::LSDT_MAX_POINTS as u64);
        Streams {
            open: Mutex::new(HashMap::new()),
            slots: Arc::new(Semaphore::new(limits.open_streams as usize)),
            limits,
            idle: Duration::from_secs(300),
            lease,
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

/// The basis a stream of this layout codes with: the newest trained one, or else the DCT
/// (stored as a basis too, so the take references what decodes it).
async fn stream_basis(store: &Store, layout: &str, points: usize) -> Result<Arc<Basis>> {
    if let Some(b) = super::bases::latest_for(store, layout)
        .await?
        .into_iter()
        .find(|b| b.kind() == BasisKind::Lsdt)
    {
        return Ok(b);
    }
    let b = super::blocking(move || dct_basis(points)).await?;
    if store.basis_exists(&b.id()).await? {
        return Ok(Arc::new(b));
    }
    let m = &b.matrices()[0];
    store
        .insert_basis(&BasisRow {
            id: b.id(),
            kind: BasisKind::Lsdt.name().into(),
            layout: layout.to_string(),
            points: points as i64,
            dims: format!("3×{}×{}", m.rows, m.cols),
            payload: b.bytes().to_vec(),
            provenance: serde_json::json!({
                "algorithm": "DCT-II, untrained: no lsdt basis was trained for this layout",
            }),
            // Dated at the epoch, so that any basis trained later is the layout's newest.
            created_at: 0,
            used_by: 0,
        })
        .await?;
    Ok(Arc::new(b))
}

impl Streams {
    fn entry(&self, id: &str) -> Option<Entry> {
        self.open.lock().expect("streams lock").get(id).cloned()
    }

    /// Open a stream: the take exists (with no frames) from now on.
    pub async fn open(&self, store: &Store, req: OpenRequest) -> Result<StreamInfo> {
        let bad = |m: String| Err(Error::InvalidRequest(m));
        if !(req.fps.is_finite() && req.fps > 0.0 && req.fps <= MAX_FPS) {
            return bad(format!("fps must be in (0, {MAX_FPS}], got {}", req.fps));
        }
        // The count is checked before anything is made from it: a client may ask for 2e10.
        let count = match &req.points {
            PointsSpec::Names(n) => n.len(),
            PointsSpec::Count(n) => *n,
        };
        let max_points = self.limits.stream_points;
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
        let metres = match &req.unit {
            Some(u) => parse_unit(u).map_err(|e| Error::InvalidRequest(e.to_string()))?,
            None => 0.001,
        };
        let unit = Unit::new(metres, UnitSource::Explicit)
            .map_err(|e| Error::InvalidRequest(e.to_string()))?;
        let bound = match (req.max_error_mm, req.mean_error_mm) {
            (Some(_), Some(_)) => return bad("give max_error_mm or mean_error_mm, not both".into()),
            (_, Some(v)) => ErrorBound::new_mean(v),
            (m, None) => ErrorBound::new_max(m.unwrap_or(1.0)),
        }
        .map_err(|e| Error::InvalidRequest(e.to_string()))?;
        let codec = req.codec.unwrap_or(CodecId::LsdtFrame);
        if !matches!(codec, CodecId::LsdtFrame | CodecId::LsdtClip) {
            return bad(format!(
                "streams are coded with lsdt-frame or lsdt-clip, not {codec}"
            ));
        }
        let chunk_frames = match req.chunk_seconds {
            Some(s) if !(s.is_finite() && s > 0.0 && s <= 60.0) => {
                return bad(format!("chunk_seconds must be in (0, 60], got {s}"))
            }
            Some(s) => ((s * req.fps).round() as usize).max(1),
            None => codec::default_chunk_frames(req.fps),
        };
        let points = names.len();
        if codec == CodecId::LsdtClip && chunk_frames > codec::MAX_CLIP {
            return bad(format!(
                "lsdt-clip codes clips of at most {} frames; ask for shorter chunk_seconds",
                codec::MAX_CLIP
            ));
        }
        if let Err(why) = crate::limits::check(
            "frames × points of one chunk",
            (chunk_frames * points) as u64,
            self.limits.stream_chunk_samples,
        ) {
            return bad(format!("{why}: ask for shorter chunk_seconds"));
        }
        // A place among the open streams, held until the stream closes.
        let slot = self.slots.clone().try_acquire_owned().map_err(|_| {
            Error::Busy(format!(
                "{} streams are open, the most this server takes at once; finish one or retry later",
                self.limits.open_streams
            ))
        })?;
        let shape = Motion::new(req.fps, unit.clone(), names.clone(), Vec::new(), None)
            .map_err(|e| Error::InvalidRequest(e.to_string()))?;
        let layout = shape.layout_signature().to_hex();
        let basis = stream_basis(store, &layout, points).await?;
        // A hair inside the bound, as batch encoding aims, so unit conversion cannot cross it.
        let t = bound.mm() / unit.to_mm() * (1.0 - 1e-6);
        let (coder, params) = match codec {
            CodecId::LsdtFrame => {
                let p = frame::FrameParams {
                    intra_period: chunk_frames,
                    ..frame::stream_params(t, req.fps)
                };
                let e = FrameEncoder::new(p, &basis)?;
                (Coder::Frame(Box::new(e)), p.to_bytes())
            }
            _ => {
                let p = ClipParams {
                    clip: chunk_frames,
                    ..clip::stream_params(t, req.fps)
                };
                (Coder::Clip(p), p.to_bytes())
            }
        };
        let header = Header {
            codec,
            frames: 0,
            points: points as u32,
            fps: req.fps,
            metres_per_unit: unit.metres_per_unit,
            params,
            basis: Some(basis.hash()),
            chunks: Vec::new(),
        };
        let decoder: Arc<dyn ChunkDecoder> =
            Arc::from(codec::decoder(&header, Some(basis.clone()))?);
        let id = uuid::Uuid::now_v7().to_string();
        let decision = Decision {
            winner: codec,
            reason: format!(
                "live stream: coded with {codec} as frames arrived, committed every {chunk_frames} frames"
            ),
            tried: Vec::new(),
            skipped: Vec::new(),
        };
        let (bound_kind, bound_mm) = match bound {
            ErrorBound::MaxMm(v) => ("max", v),
            ErrorBound::MeanMm(v) => ("mean", v),
        };
        let row = SequenceRow {
            id: id.clone(),
            name: req
                .name
                .clone()
                .filter(|n| !n.trim().is_empty())
                .unwrap_or_else(|| id.clone()),
            library: req.library.clone(),
            tags: super::normalise_tags(&req.tags),
            fps: req.fps,
            frames: 0,
            points: points as i64,
            duration_s: 0.0,
            metres_per_unit: unit.metres_per_unit,
            layout,
            source_format: "stream".into(),
            codec: codec.to_string(),
            bound_kind: bound_kind.into(),
            bound_mm,
            raw_bytes: 0,
            stored_bytes: header.to_bytes().len() as i64,
            ratio: 0.0,
            mean_mm: 0.0,
            rms_mm: 0.0,
            max_mm: 0.0,
            kg_percent: 0.0,
            header: header.to_bytes(),
            meta: serde_json::json!({
                "point_names": names,
                "unit": unit,
                "skeleton": null,
                "warnings": [],
                "decision": decision,
                "live": true,
            }),
            created_at: super::now_ms(),
            live_until: Some(self.lease_end()),
        };
        store
            .insert(&NewSequence {
                row: row.clone(),
                chunks: Vec::new(),
                basis: Some(basis.id()),
            })
            .await?;
        let header_len = row.header.len();
        let live = Live {
            row,
            header,
            index: Vec::new(),
            header_len,
            payload_bytes: 0,
            digest: blake3::Hasher::new(),
            coder: Some(coder),
            basis,
            decoder,
            points,
            to_mm: unit.to_mm(),
            bound,
            chunk_frames,
            received: 0,
            pending: Vec::new(),
            stats: Accumulator::new(points),
            failed: None,
            last_activity: Instant::now(),
            archive: req.reencode_on_finish.then(Vec::new),
            warnings: Vec::new(),
            _slot: slot,
        };
        let info = live.info(true);
        self.open
            .lock()
            .expect("streams lock")
            .insert(id, Arc::new(tokio::sync::Mutex::new(live)));
        Ok(info)
    }

    /// The state of an open stream.
    pub async fn info(&self, store: &Store, id: &str) -> Result<StreamInfo> {
        match self.entry(id) {
            Some(e) => Ok(e.lock().await.info(true)),
            None => Err(Self::not_open(store, id).await),
        }
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

    /// Append frames (`n × points × 3`, NaN for missing samples); commits every chunk they
    /// complete, and with `flush` the frames still pending too (the next chunk then starts
    /// with an intra frame: lower delay, a few more bytes).
    pub async fn append(
        &self,
        store: &Store,
        caches: &ReadCaches,
        id: &str,
        frames: Vec<f32>,
        flush: bool,
    ) -> Result<StreamInfo> {
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
        let w = live.points * 3;
        if !frames.len().is_multiple_of(w) {
            return Err(Error::InvalidRequest(format!(
                "{} values are not whole frames of {} points",
                frames.len(),
                live.points
            )));
        }
        let to_m = live.row.metres_per_unit;
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
        live.last_activity = Instant::now();
        live.received += frames.len() / w;
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
        let r = self.code_and_commit(store, &mut live, frames, flush).await;
        caches.forget(id);
        if let Err(e) = &r {
            live.failed = Some(e.to_string());
        }
        r?;
        Ok(live.info(true))
    }

    async fn code_and_commit(
        &self,
        store: &Store,
        live: &mut Live,
        frames: Vec<f32>,
        flush: bool,
    ) -> Result<()> {
        let coder = live
            .coder
            .take()
            .ok_or_else(|| Error::Internal("stream coder missing".into()))?;
        let points = live.points;
        let w = points * 3;
        let basis = live.basis.clone();
        let fps = live.row.fps;
        // A clip is coded only when whole (or flushed), so every pending frame is uncoded:
        // the clip coder sees them followed by the new ones.
        let uncoded_clip: Vec<f32> = match &coder {
            Coder::Clip(_) => live
                .pending
                .iter()
                .copied()
                .chain(frames.iter().copied())
                .collect(),
            Coder::Frame(_) => Vec::new(),
        };
        let new_frames = frames.clone();
        let (coder, chunks) = blocking(move || -> Result<(Coder, Vec<ChunkOut>)> {
            let mut out = Vec::new();
            match coder {
                Coder::Frame(mut e) => {
                    for f in new_frames.chunks_exact(w) {
                        let (_, c) = e.push(f, None);
                        out.extend(c);
                    }
                    if flush {
                        out.extend(e.flush());
                    }
                    Ok((Coder::Frame(e), out))
                }
                Coder::Clip(p) => {
                    let n = uncoded_clip.len() / w;
                    let whole = if flush { n } else { n / p.clip * p.clip };
                    if whole > 0 {
                        let data = &uncoded_clip[..whole * w];
                        let valid: Vec<bool> =
                            data.chunks_exact(3).map(|s| !s[0].is_nan()).collect();
                        let filled = codec::gaps::fill(data, points);
                        let input = Input {
                            data: &filled,
                            valid: Some(&valid),
                            frames: whole,
                            points,
                            fps,
                            shared: Some(&basis),
                        };
                        out = clip::encode_fixed(&input, p)?;
                    }
                    Ok((Coder::Clip(p), out))
                }
            }
        })
        .await??;
        live.coder = Some(coder);
        live.pending.extend_from_slice(&frames);
        for chunk in chunks {
            self.commit(store, live, chunk).await?;
        }
        Ok(())
    }

    /// Check one coded chunk on its decoded output and commit it: one chunk row and the
    /// take's running totals, nothing that grows with the stream.
    async fn commit(&self, store: &Store, live: &mut Live, chunk: ChunkOut) -> Result<()> {
        let w = live.points * 3;
        let n = chunk.frames;
        if n * w > live.pending.len() {
            return Err(Error::Internal(
                "a chunk longer than the pending frames".into(),
            ));
        }
        let original: Vec<f32> = live.pending[..n * w].to_vec();
        let valid: Vec<bool> = original.chunks_exact(3).map(|s| !s[0].is_nan()).collect();
        let payload = pack_chunk(Some(&valid), &chunk.bytes);
        let meta = ChunkMeta {
            first_frame: live.row.frames as u32,
            frames: n as u32,
            len: payload.len() as u32,
            crc32c: crc32c::crc32c(&payload),
        };
        // The chunk decodes on its own: check it with a header that holds only it.
        let alone = Header {
            frames: n as u32,
            chunks: vec![ChunkMeta {
                first_frame: 0,
                ..meta
            }],
            ..live.header.clone()
        };
        let (decoder, p2) = (live.decoder.clone(), payload.clone());
        let decoded =
            blocking(move || codec::decode_chunk(&alone, decoder.as_ref(), 0, &p2)).await??;
        let index = live.index.len();
        let mut stats = live.stats.clone();
        stats.add(&original, &decoded);
        let chunk_stats = {
            let mut a = Accumulator::new(live.points);
            a.add(&original, &decoded);
            a.finish(live.to_mm)
        };
        if chunk_stats.max_mm > live.bound.mm() {
            return Err(Error::Internal(format!(
                "chunk {index} decodes {:.4} mm from its input, over the bound {}",
                chunk_stats.max_mm, live.bound
            )));
        }
        let s = stats.finish(live.to_mm);
        let frames = live.row.frames + n as i64;
        let payload_bytes = live.payload_bytes + payload.len();
        let row = &mut live.row;
        row.frames = frames;
        row.duration_s = frames as f64 / row.fps;
        row.raw_bytes = frames * live.points as i64 * 12;
        row.stored_bytes =
            (live.header_len + (index + 1) * ChunkMeta::INDEX_BYTES + payload_bytes) as i64;
        row.ratio = row.raw_bytes as f64 / row.stored_bytes.max(1) as f64;
        row.mean_mm = s.mean_mm;
        row.rms_mm = s.rms_mm;
        row.max_mm = s.max_mm;
        row.kg_percent = if s.kg_percent.is_finite() {
            s.kg_percent
        } else {
            0.0
        };
        let chunk_row = ChunkRow {
            idx: index as i64,
            first_frame: i64::from(meta.first_frame),
            frames: n as i64,
            crc32c: meta.crc32c,
            payload,
        };
        if !store
            .append_chunk(&live.row, &chunk_row, self.lease_end())
            .await?
        {
            return Err(Error::Conflict(format!(
                "take {} is no longer live (deleted, or closed by another server after its \
                 lease ran out)",
                live.row.id
            )));
        }
        live.index.push(meta);
        codec::digest_update(&mut live.digest, &decoded);
        live.payload_bytes = payload_bytes;
        live.stats = stats;
        live.pending.drain(..n * w);
        Ok(())
    }

    /// Close a stream: commit what is pending, write the chunk index into the take's header
    /// and mark it finished, and if the stream kept its frames, code the whole take again
    /// with per-take choice, keeping that if it is smaller.
    pub async fn finish(
        &self,
        store: &Store,
        caches: &ReadCaches,
        id: &str,
    ) -> Result<SequenceRow> {
        let entry = match self.entry(id) {
            Some(e) => e,
            None => return Err(Self::not_open(store, id).await),
        };
        let mut live = entry.lock_owned().await;
        self.open.lock().expect("streams lock").remove(id);
        if live.failed.is_none() {
            if let Err(e) = self
                .code_and_commit(store, &mut live, Vec::new(), true)
                .await
            {
                tracing::warn!(stream = id, error = %e, "pending frames of a finished stream were lost");
                live.warnings
                    .push(format!("frames pending at finish were lost: {e}"));
            }
        }
        let mut meta = live.row.meta.clone();
        meta["live"] = serde_json::Value::Bool(false);
        meta["decoded_blake3"] = live.digest.finalize().to_hex().to_string().into();
        if !live.warnings.is_empty() {
            meta["warnings"] = serde_json::json!(live.warnings);
        }
        if !store
            .close_live(id, &live.closed_header().to_bytes(), &meta)
            .await?
        {
            // Closed from its chunk rows by another server after the lease ran out (or
            // deleted): what it stored is what was committed, the same chunks.
            tracing::warn!(
                stream = id,
                "stream was closed elsewhere before it finished"
            );
        }
        caches.forget(id);
        let row = super::fetch::sequence(store, id).await?;
        if let Some(frames) = live.archive.take().filter(|_| row.frames > 0) {
            let committed = row.frames as usize * live.points * 3;
            if frames.len() >= committed {
                reencode_take(store, &row, frames[..committed].to_vec(), live.bound).await?;
                caches.forget(id);
            }
        }
        super::fetch::sequence(store, id).await
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
        for (id, e) in entries {
            // A stream busy with a request renews its lease by committing.
            let idle = match e.try_lock() {
                Ok(l) => l.last_activity.elapsed() > self.idle,
                Err(_) => continue,
            };
            if idle {
                if let Err(err) = self.finish(store, caches, &id).await {
                    tracing::warn!(stream = %id, error = %err, "finishing an idle stream failed");
                }
            } else if let Err(err) = store.renew_lease(&id, self.lease_end()).await {
                tracing::warn!(stream = %id, error = %err, "renewing a stream's lease failed");
            }
        }
        if let Err(err) = self.close_orphans(store, caches).await {
            tracing::warn!(error = %err, "closing orphaned live takes failed");
        }
    }

    /// Close every live take whose lease has run out and that no stream here codes: its
    /// server stopped mid-stream. What it committed stays, indexed from its chunk rows;
    /// frames that were pending on that server are lost, and the take says so.
    pub async fn close_orphans(&self, store: &Store, caches: &ReadCaches) -> Result<usize> {
        let mut closed = 0;
        for id in store.expired_live(super::now_ms()).await? {
            if self.entry(&id).is_some() {
                continue;
            }
            let Some(row) = store.get(&id).await? else {
                continue;
            };
            let header = header_from_index(&row, &store.chunk_index(&id).await?)?;
            let mut meta = row.meta.clone();
            meta["live"] = serde_json::Value::Bool(false);
            meta["interrupted"] = serde_json::Value::String(
                "the server coding this stream stopped before it finished; the take keeps the \
                 chunks it had committed"
                    .into(),
            );
            if store.close_live(&id, &header.to_bytes(), &meta).await? {
                tracing::warn!(stream = %id, frames = row.frames, "closed a stream whose server stopped");
                caches.forget(&id);
                closed += 1;
            }
        }
        Ok(closed)
    }
}

/// A live take's header with the chunk rows as its index (and frames), checked as any
/// stored header is.
pub(crate) fn header_from_index(row: &SequenceRow, index: &[ChunkEntry]) -> Result<Header> {
    let id = &row.id;
    let corrupt = |e: &dyn std::fmt::Display| Error::Internal(format!("stored take {id}: {e}"));
    let (mut header, _) =
        Header::parse(&row.header, &codec::Limits::default()).map_err(|e| corrupt(&e))?;
    let mut chunks = Vec::with_capacity(index.len());
    for c in index {
        let as_u32 = |v: i64| u32::try_from(v).map_err(|_| corrupt(&format!("chunk {c:?}")));
        chunks.push(ChunkMeta {
            first_frame: as_u32(c.first_frame)?,
            frames: as_u32(c.frames)?,
            len: as_u32(c.len)?,
            crc32c: c.crc32c,
        });
    }
    header.frames = chunks.iter().map(|c| c.frames).sum();
    header.chunks = chunks;
    // Round-trip through the parser: the index must tile the frames in order.
    Header::parse(&header.to_bytes(), &codec::Limits::default())
        .map(|(h, _)| h)
        .map_err(|e| corrupt(&e))
}

/// Code a finished stream's take again, from the frames as sent, with every candidate
/// codec; keep the result if it is smaller than the live coding.
async fn reencode_take(
    store: &Store,
    row: &SequenceRow,
    positions: Vec<f32>,
    bound: ErrorBound,
) -> Result<()> {
    let names = super::fetch::point_names(row)?;
    let unit = Unit::new(row.metres_per_unit, UnitSource::Explicit)
        .map_err(|e| Error::Internal(e.to_string()))?;
    let motion = Arc::new(
        Motion::new(row.fps, unit, names, positions, None)
            .map_err(|e| Error::Internal(e.to_string()))?,
    );
    let (decision, enc) = super::ingest::encode_best(
        store,
        motion,
        &row.layout,
        CodecRequest::Auto,
        bound,
        Latency::Sequence,
    )
    .await?;
    if enc.stored_bytes as i64 >= row.stored_bytes {
        return Ok(());
    }
    let mut new = row.clone();
    new.codec = decision.winner.to_string();
    new.stored_bytes = enc.stored_bytes as i64;
    new.ratio = new.raw_bytes as f64 / new.stored_bytes.max(1) as f64;
    new.mean_mm = enc.stats.mean_mm;
    new.rms_mm = enc.stats.rms_mm;
    new.max_mm = enc.stats.max_mm;
    new.kg_percent = enc.stats.kg_percent;
    new.header = enc.container.header.to_bytes();
    new.meta["decision"] = serde_json::to_value(&decision).unwrap_or_default();
    new.meta["decoded_blake3"] = enc.decoded_digest.clone().into();
    new.meta["reencoded_from"] = serde_json::Value::String(row.codec.clone());
    let basis = enc.container.header.basis.as_ref().map(codec::basis::hex);
    let chunks = super::ingest::chunk_rows(&enc.container);
    store
        .update_encoding(&new, &chunks, true, basis.as_deref())
        .await?;
    Ok(())
}
