//! Live streams: a take stored while it is being recorded. Frames are coded as they arrive
//! (`lsdt-frame`, or `lsdt-clip` clip by clip) and committed chunk by chunk, each commit one
//! transaction that adds the chunk and updates the take's header and statistics, so a range
//! of a take still being recorded can be fetched as soon as its chunk is in.
//!
//! A stream's coder state lives in this server's memory. If a client goes away, what was
//! committed stays; frames still pending in an unfinished chunk are committed when the
//! stream is finished, or when it has been idle too long ([`Streams::reap_idle`]). A server
//! restart loses only those pending frames.
//!
//! With no search possible frame by frame, a stream codes to its bound as a max bound (a
//! mean bound is then met too) with the residual layer, and checks every chunk on its decoded
//! output before committing it. `finish` can re-encode the whole take with per-take choice.

use std::collections::HashMap;
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use serde::{Deserialize, Serialize};

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
use crate::motion::metrics::Accumulator;
use crate::motion::units::{parse_unit, Unit, UnitSource};
use crate::motion::Motion;
use crate::store::{BasisRow, ChunkRow, NewSequence, SequenceRow, Store};

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
}

enum Coder {
    Frame(Box<FrameEncoder>),
    Clip(ClipParams),
}

struct Live {
    row: SequenceRow,
    header: Header,
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
            frames_committed: self.header.frames as usize,
            chunks_committed: self.header.chunks.len(),
            live,
            max_mm: self.row.max_mm,
            mean_mm: self.row.mean_mm,
        }
    }
}

type Entry = Arc<tokio::sync::Mutex<Live>>;

/// The open streams of this server.
pub struct Streams {
    open: Mutex<HashMap<String, Entry>>,
    /// A stream with no request for this long is finished by [`Streams::reap_idle`].
    pub idle: Duration,
}

impl Default for Streams {
    fn default() -> Self {
        Streams {
            open: Mutex::new(HashMap::new()),
            idle: Duration::from_secs(300),
        }
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
    let b = dct_basis(points);
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
        if !(req.fps.is_finite() && req.fps > 0.0 && req.fps <= 100_000.0) {
            return bad(format!("fps must be in (0, 100000], got {}", req.fps));
        }
        let names: Vec<String> = match req.points {
            PointsSpec::Names(n) => n,
            PointsSpec::Count(n) => (0..n).map(|i| format!("p{i}")).collect(),
        };
        if names.is_empty() || names.len() > 10_000 {
            return bad(format!(
                "a stream needs 1..=10000 points, got {}",
                names.len()
            ));
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
        };
        store
            .insert(&NewSequence {
                row: row.clone(),
                chunks: Vec::new(),
                basis: Some(basis.id()),
            })
            .await?;
        let live = Live {
            row,
            header,
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

    /// Why a stream id is not open: finished (409) or unknown (404).
    async fn not_open(store: &Store, id: &str) -> Error {
        match store.exists(id).await {
            Ok(true) => Error::Conflict(format!("stream {id} is finished")),
            Ok(false) => Error::NotFound(format!("stream {id}")),
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
        live.last_activity = Instant::now();
        live.received += frames.len() / w;
        if let Some(a) = &mut live.archive {
            a.extend_from_slice(&frames);
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

    /// Check one coded chunk on its decoded output and commit it with the updated header.
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
            first_frame: live.header.frames,
            frames: n as u32,
            len: payload.len() as u32,
            crc32c: crc32c::crc32c(&payload),
        };
        let mut header = live.header.clone();
        header.chunks.push(meta);
        header.frames += n as u32;
        let index = header.chunks.len() - 1;
        let (decoder, h2, p2) = (live.decoder.clone(), header.clone(), payload.clone());
        let decoded =
            blocking(move || codec::decode_chunk(&h2, decoder.as_ref(), index, &p2)).await??;
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
        let mut row = live.row.clone();
        let frames = header.frames as i64;
        row.frames = frames;
        row.duration_s = frames as f64 / row.fps;
        row.raw_bytes = frames * live.points as i64 * 12;
        row.header = header.to_bytes();
        row.stored_bytes =
            row.header.len() as i64 + header.chunks.iter().map(|c| i64::from(c.len)).sum::<i64>();
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
            .update_encoding(&row, &[chunk_row], false, None)
            .await?
        {
            return Err(Error::NotFound(format!("sequence {}", row.id)));
        }
        live.row = row;
        live.header = header;
        live.stats = stats;
        live.pending.drain(..n * w);
        Ok(())
    }

    /// Close a stream: commit what is pending, mark the take finished, and if the stream
    /// kept its frames, code the whole take again with per-take choice, keeping that if it
    /// is smaller.
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
            }
        }
        let mut row = live.row.clone();
        row.meta["live"] = serde_json::Value::Bool(false);
        store.update_encoding(&row, &[], false, None).await?;
        caches.forget(id);
        if let Some(frames) = live.archive.take().filter(|_| row.frames > 0) {
            let committed = row.frames as usize * live.points * 3;
            if frames.len() >= committed {
                reencode_take(store, &row, frames[..committed].to_vec(), live.bound).await?;
                caches.forget(id);
            }
        }
        super::fetch::sequence(store, id).await
    }

    /// Finish every stream idle for longer than [`Streams::idle`].
    pub async fn reap_idle(&self, store: &Store, caches: &ReadCaches) {
        let ids: Vec<String> = self
            .open
            .lock()
            .expect("streams lock")
            .keys()
            .cloned()
            .collect();
        for id in ids {
            let Some(e) = self.entry(&id) else { continue };
            let idle = match e.try_lock() {
                Ok(l) => l.last_activity.elapsed() > self.idle,
                Err(_) => false,
            };
            if idle {
                if let Err(err) = self.finish(store, caches, &id).await {
                    tracing::warn!(stream = %id, error = %err, "finishing an idle stream failed");
                }
            }
        }
    }
}

/// Code a finished stream's take again, from the frames as sent, with every candidate
/// codec; keep the result if it is smaller than the live coding.
async fn reencode_take(
    store: &Store,
    row: &SequenceRow,
    positions: Vec<f32>,
    bound: ErrorBound,
) -> Result<()> {
    let names = super::fetch::point_names(row);
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
    new.meta["reencoded_from"] = serde_json::Value::String(row.codec.clone());
    let basis = enc.container.header.basis.as_ref().map(codec::basis::hex);
    let chunks = super::ingest::chunk_rows(&enc.container);
    store
        .update_encoding(&new, &chunks, true, basis.as_deref())
        .await?;
    Ok(())
}
