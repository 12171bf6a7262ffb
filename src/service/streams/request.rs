//! What a stream's client sends and is answered: the open request and its checks (a
//! [`Plan`] is a request every count of which is within its limit), an append and its
//! checks, and the state a stream reports.

use serde::{Deserialize, Serialize};

use crate::codec::{self, CodecId, ErrorBound};
use crate::limits::{Limits, MAX_CAPTURE_MS, MAX_COORDINATE_M};
use crate::motion::units::{parse_unit, Unit, UnitSource};
use crate::service::take::Label;
use crate::service::{Error, Result};

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
    /// What the take is of ([`crate::labels`]): key → text or number.
    #[serde(default)]
    pub labels: Option<serde_json::Value>,
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
pub(super) struct Plan {
    pub(super) label: Label,
    pub(super) fps: f64,
    pub(super) names: Vec<String>,
    pub(super) unit: Unit,
    pub(super) bound: ErrorBound,
    pub(super) codec: CodecId,
    pub(super) chunk_frames: usize,
    pub(super) reencode_on_finish: bool,
}

impl Plan {
    pub(super) fn of(req: OpenRequest, limits: &Limits) -> Result<Plan> {
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
        let labels = match &req.labels {
            Some(v) => crate::labels::Labels::from_json(v).map_err(Error::InvalidRequest)?,
            None => Default::default(),
        };
        Ok(Plan {
            label: Label {
                name: req.name,
                library: req.library,
                tags: req.tags,
                labels,
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

impl Append {
    /// A capture time that is one: checked before the stream is looked up.
    pub(super) fn check_time(&self) -> Result<()> {
        if let Some(t) = self
            .captured_ms
            .filter(|t| !(0..=MAX_CAPTURE_MS).contains(t))
        {
            return Err(Error::InvalidRequest(format!(
                "captured_ms {t} is not a time in ms since the Unix epoch (0..={MAX_CAPTURE_MS})"
            )));
        }
        Ok(())
    }

    /// Check an append's frames against its stream (`points`, stored units of
    /// `metres_per_unit`): whole frames, finite values of a physical scale.
    pub(super) fn check_frames(&self, points: usize, metres_per_unit: f64) -> Result<()> {
        let frames = &self.frames;
        if !frames.len().is_multiple_of(points * 3) {
            return Err(Error::InvalidRequest(format!(
                "{} values are not whole frames of {points} points",
                frames.len(),
            )));
        }
        if let Some(i) = frames.iter().position(|v| {
            v.is_infinite() || (f64::from(v.abs()) * metres_per_unit) > MAX_COORDINATE_M
        }) {
            return Err(Error::InvalidRequest(format!(
                "value {i} ({}) is beyond any physical scale (|x| ≤ {MAX_COORDINATE_M} m); \
                 send null (JSON) or NaN (f32) for a missing sample",
                frames[i]
            )));
        }
        Ok(())
    }
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
