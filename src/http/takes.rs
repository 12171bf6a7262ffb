//! `/v1/takes`: ingest, metadata, frame ranges, delete. Handlers parse the request into
//! domain types and call the service; no math, no SQL.

use axum::body::{Body, Bytes};
use axum::extract::rejection::{BytesRejection, QueryRejection};
use axum::extract::{Path, Query, State};
use axum::http::{header, HeaderMap, HeaderName, HeaderValue, StatusCode};
use axum::response::{IntoResponse, Response};
use axum::Extension;
use axum::Json;
use futures_util::StreamExt;
use serde::Deserialize;
use std::sync::Arc;

use super::error::ApiError;
use super::metrics::Metrics;
use super::views::TakeView;
use super::AppState;
use crate::codec::{CodecId, ErrorBound, Hints, Latency};
use crate::labels::Labels;
use crate::limits::Limits;
use crate::motion::formats::{self, Format};
use crate::motion::transform::Options;
use crate::motion::units::parse_unit;
use crate::service::access::Caller;
use crate::service::analog;
use crate::service::answer::{self, Answer, Pieces, RangeRequest};
use crate::service::body;
use crate::service::budget::Holder;
use crate::service::choose::{CodecRequest, Keep};
use crate::service::fetch::{self, TimeRange};
use crate::service::ingest::{self, IngestRequest};
use crate::service::ranges::{self, Part, Ranges, RangesRequest};
use crate::service::retarget::{self, Onto};
use crate::service::take::Label;

#[derive(Debug, Default, PartialEq, Deserialize)]
pub struct IngestQuery {
    name: Option<String>,
    library: Option<String>,
    tags: Option<String>,
    /// `content:walk,style:happy`, or a JSON object.
    labels: Option<String>,
    unit: Option<String>,
    fps: Option<f64>,
    codec: Option<String>,
    max_error_mm: Option<f64>,
    mean_error_mm: Option<f64>,
    latency: Option<String>,
    keep: Option<String>,
    /// The torso points for `spca`: origin, left shoulder, right shoulder, by name.
    torso: Option<String>,
    lenient: Option<bool>,
    /// Bounds on analog channels, each in its own unit: `0.5`, or `Fz1=0.5,EMG1=1e-6`
    /// (`*=` for the rest). None: analog values are kept exactly.
    analog_bound: Option<String>,
    /// The take's up and forward axes (signed: `y`, `-z`), winning over anatomy.
    up: Option<String>,
    forward: Option<String>,
    /// Which of the file's animations (FBX stacks, glTF animations) to store, by its place
    /// (from 0) or name; none: every one, each a take of its own.
    animation: Option<String>,
}

/// Format named by `Content-Type` (e.g. `application/x-bvh`, `text/x-trc`), used only when
/// the content itself does not say.
pub(super) fn content_type_format(headers: &HeaderMap) -> Option<Format> {
    let ct = headers
        .get(header::CONTENT_TYPE)?
        .to_str()
        .ok()?
        .to_ascii_lowercase();
    let sub = ct
        .split(';')
        .next()?
        .rsplit('/')
        .next()?
        .trim_start_matches("x-");
    sub.parse::<Format>().ok().filter(|f| f.can_read())
}

/// Fills one field of an [`IngestQuery`] from its header's value, where the query left it out.
type FromHeader = fn(&mut IngestQuery, &str) -> Result<(), ApiError>;

/// The ingest fields a client may send as `x-mocap-<field>` headers (a browser's upload,
/// where a long query is awkward), each with how it fills the query: what
/// [`IngestQuery::with_headers`] reads and what CORS lets a page send, declared once.
pub const HEADER_FIELDS: &[(&str, FromHeader)] = &[
    ("name", |q, v| text(&mut q.name, v)),
    ("library", |q, v| text(&mut q.library, v)),
    ("tags", |q, v| text(&mut q.tags, v)),
    ("labels", |q, v| text(&mut q.labels, v)),
    ("unit", |q, v| text(&mut q.unit, v)),
    ("fps", |q, v| number(&mut q.fps, "fps", v)),
    ("codec", |q, v| text(&mut q.codec, v)),
    ("max-error-mm", |q, v| {
        number(&mut q.max_error_mm, "max-error-mm", v)
    }),
    ("mean-error-mm", |q, v| {
        number(&mut q.mean_error_mm, "mean-error-mm", v)
    }),
    ("latency", |q, v| text(&mut q.latency, v)),
    ("keep", |q, v| text(&mut q.keep, v)),
    ("torso", |q, v| text(&mut q.torso, v)),
    ("lenient", |q, v| {
        if q.lenient.is_none() {
            q.lenient = Some(match v.trim() {
                "true" => true,
                "false" => false,
                _ => {
                    return Err(ApiError::bad_request(format!(
                        "header x-mocap-lenient: {v:?} is not true or false"
                    )))
                }
            });
        }
        Ok(())
    }),
    ("analog-bound", |q, v| text(&mut q.analog_bound, v)),
    ("up", |q, v| text(&mut q.up, v)),
    ("forward", |q, v| text(&mut q.forward, v)),
    ("animation", |q, v| text(&mut q.animation, v)),
];

fn text(slot: &mut Option<String>, v: &str) -> Result<(), ApiError> {
    slot.get_or_insert_with(|| v.to_string());
    Ok(())
}

fn number(slot: &mut Option<f64>, name: &str, v: &str) -> Result<(), ApiError> {
    if slot.is_none() {
        let n = v.trim().parse::<f64>().map_err(|_| {
            ApiError::bad_request(format!("header x-mocap-{name}: {v:?} is not a number"))
        })?;
        *slot = Some(n);
    }
    Ok(())
}

impl IngestQuery {
    /// Fields may also come as `x-mocap-<field>` headers ([`HEADER_FIELDS`], e.g.
    /// `x-mocap-max-error-mm`); the query wins where both are given.
    fn with_headers(mut self, h: &HeaderMap) -> Result<Self, ApiError> {
        for (name, fill) in HEADER_FIELDS {
            if let Some(v) = h
                .get(format!("x-mocap-{name}"))
                .and_then(|v| v.to_str().ok())
            {
                fill(&mut self, v)?;
            }
        }
        Ok(self)
    }

    /// Parse, don't validate: the query becomes an [`IngestRequest`] or a 400.
    fn into_request(self, body: Bytes, limits: &Limits) -> Result<IngestRequest, ApiError> {
        let bad = |e: &dyn std::fmt::Display| ApiError::bad_request(e.to_string());
        let bound =
            ErrorBound::from_request(self.max_error_mm, self.mean_error_mm).map_err(|e| bad(&e))?;
        let codec = match self.codec.as_deref().map(str::trim) {
            None | Some("") | Some("auto") => CodecRequest::Auto,
            Some(c) => match c.parse::<CodecId>().map_err(|e| bad(&e))? {
                c if c.is_analog() => {
                    return Err(ApiError::bad_request(format!(
                        "{c} codes analog channels, not points: it is chosen for them (state \
                         analog_bound for analog-bounded)"
                    )))
                }
                c => CodecRequest::Only(c),
            },
        };
        let analog_bounds = self
            .analog_bound
            .as_deref()
            .map(str::parse)
            .transpose()
            .map_err(|e: String| ApiError::bad_request(format!("analog_bound: {e}")))?
            .unwrap_or_default();
        let latency = match self.latency.as_deref() {
            None => Latency::Sequence,
            Some(l) => l.parse::<Latency>().map_err(|e| bad(&e))?,
        };
        let keep = match self.keep.as_deref() {
            None => Keep::default(),
            Some(k) => k.parse::<Keep>().map_err(|e| bad(&e))?,
        };
        let hints = Hints {
            torso: self.torso.as_deref().map(parse_torso).transpose()?,
        };
        let unit = match self.unit.as_deref() {
            None => None,
            Some(u) => Some(parse_unit(u).map_err(|e| bad(&e))?),
        };
        if let Some(f) = self.fps {
            crate::limits::fps(f).map_err(ApiError::bad_request)?;
        }
        let axis = |name: &str, v: Option<&str>| {
            v.map(|a| {
                a.parse::<crate::motion::body::Axis>()
                    .map_err(|e| ApiError::bad_request(format!("{name}: {e}")))
            })
            .transpose()
        };
        let axes = crate::motion::body::Given {
            up: axis("up", self.up.as_deref())?,
            forward: axis("forward", self.forward.as_deref())?,
        };
        axes.check().map_err(ApiError::bad_request)?;
        if body.is_empty() {
            return Err(ApiError::bad_request(
                "empty body: send the file as the request body",
            ));
        }
        let animation = match self.animation.as_deref().map(str::trim) {
            None => None,
            Some("") => return Err(ApiError::bad_request("animation: empty")),
            Some(a) => Some(a.parse::<formats::Pick>().unwrap_or_else(|e| match e {})),
        };
        Ok(IngestRequest {
            animation,
            axes,
            bytes: body,
            label: Label {
                name: self.name,
                library: self.library.unwrap_or_default(),
                tags: self
                    .tags
                    .map(|t| t.split(',').map(str::to_string).collect())
                    .unwrap_or_default(),
                labels: self
                    .labels
                    .as_deref()
                    .map(Labels::parse)
                    .transpose()
                    .map_err(ApiError::bad_request)?
                    .unwrap_or_default(),
            },
            unit,
            fps: self.fps,
            codec,
            bound,
            latency,
            keep,
            limits: formats::ReadLimits::from(limits),
            format_hint: None,
            lenient: self.lenient.unwrap_or(false),
            hints,
            analog_bounds,
        })
    }
}

/// `torso=C7,LSHO,RSHO`: three different point names, origin first.
fn parse_torso(v: &str) -> Result<[String; 3], ApiError> {
    let names: Vec<String> = v.split(',').map(|n| n.trim().to_string()).collect();
    match <[String; 3]>::try_from(names) {
        Ok(t)
            if t.iter().all(|n| !n.is_empty()) && t[0] != t[1] && t[0] != t[2] && t[1] != t[2] =>
        {
            Ok(t)
        }
        _ => Err(ApiError::bad_request(format!(
            "torso: {v:?} is not three different point names (origin, left shoulder, right \
             shoulder), comma-separated"
        ))),
    }
}

/// An upload's query, `x-mocap-*` headers and body as the [`IngestRequest`] they make.
pub fn ingest_request(
    q: IngestQuery,
    headers: &HeaderMap,
    body: Bytes,
    limits: &Limits,
) -> Result<IngestRequest, ApiError> {
    let mut req = q.with_headers(headers)?.into_request(body, limits)?;
    req.format_hint = content_type_format(headers);
    Ok(req)
}

pub async fn create(
    State(state): State<AppState>,
    Extension(caller): Extension<Caller>,
    headers: HeaderMap,
    query: Result<Query<IngestQuery>, QueryRejection>,
    body: Result<Bytes, BytesRejection>,
) -> Result<Response, ApiError> {
    let Query(q) = query?;
    let mut req = ingest_request(q, &headers, body?, &state.limits)?;
    req.label.library = caller.grant.library_for_new(&req.label.library)?;
    let uploaded = req.bytes.len();
    let report = ingest::ingest(
        &state.store,
        state.histories.as_deref(),
        Some(&state.index),
        req,
    )
    .await?;
    state
        .metrics
        .ingested(report.frames, uploaded, report.stored_bytes);
    let location = format!("/v1/takes/{}", report.id);
    Ok((
        StatusCode::CREATED,
        [(header::LOCATION, location)],
        Json(report),
    )
        .into_response())
}

pub async fn get(
    State(state): State<AppState>,
    Path(id): Path<String>,
) -> Result<Response, ApiError> {
    let take = body::take(&state.store, &id).await?;
    Ok(Json(TakeView::from(&take)).into_response())
}

pub async fn delete(
    State(state): State<AppState>,
    Path(id): Path<String>,
) -> Result<Response, ApiError> {
    crate::service::library::delete(&state.store, &id).await?;
    Ok(StatusCode::NO_CONTENT.into_response())
}

/// `GET /v1/takes/{id}/errors`: the take's error second by second and its bound.
pub async fn errors(
    State(state): State<AppState>,
    Path(id): Path<String>,
) -> Result<Response, ApiError> {
    Ok(Json(fetch::errors(&state.store, &id).await?).into_response())
}

#[derive(Deserialize, Default)]
pub struct FramesQuery {
    start: Option<usize>,
    end: Option<usize>,
    t0: Option<f64>,
    t1: Option<f64>,
    points: Option<String>,
    format: Option<String>,
    /// Output frame rate (resampling).
    fps: Option<f64>,
    /// keep, in-place or extract.
    root: Option<String>,
    /// y or z.
    up: Option<String>,
    /// mm, cm, m, in, …
    unit: Option<String>,
    /// The skeleton to put the take on: a standard rig's name, a stored skeleton's id or
    /// `take:ID`.
    skeleton: Option<String>,
    /// free or lock (with `skeleton`).
    feet: Option<String>,
}

/// A range request's query as the range, output format, points and transforms it asks for.
pub fn frames_request(q: FramesQuery) -> Result<RangeRequest, ApiError> {
    let range = match (q.start, q.end, q.t0, q.t1) {
        (None, None, None, None) => TimeRange::All,
        (s, e, None, None) => TimeRange::Frames {
            start: s.unwrap_or(0),
            end: e,
        },
        (None, None, t0, t1) => TimeRange::Seconds {
            t0: t0.unwrap_or(0.0),
            t1,
        },
        _ => {
            return Err(ApiError::bad_request(
                "give start/end (frames) or t0/t1 (seconds), not both",
            ))
        }
    };
    let format = format_of(q.format.as_deref())?;
    let points = q.points.map(|p| p.split(',').map(str::to_string).collect());
    if format == Format::Bvh && points.is_some() {
        return Err(ApiError::bad_request(
            "BVH output is the whole skeleton: leave out points",
        ));
    }
    let transform = transform_of(q.fps, q.root.as_deref(), q.up.as_deref(), q.unit.as_deref())?;
    Ok(RangeRequest {
        range,
        format,
        points,
        transform,
        onto: None,
        feet: feet_of(q.feet.as_deref())?,
    })
}

/// `feet=`, parsed (free when absent).
pub fn feet_of(feet: Option<&str>) -> Result<retarget::Feet, ApiError> {
    Ok(feet
        .map(str::parse)
        .transpose()
        .map_err(ApiError::bad_request)?
        .unwrap_or_default())
}

/// `skeleton=`, parsed.
pub fn onto_of(skeleton: Option<&str>) -> Result<Option<Onto>, ApiError> {
    skeleton
        .map(str::parse)
        .transpose()
        .map_err(ApiError::bad_request)
}

/// The transforms a query asks for (`fps`, `root`, `up`, `unit`), parsed.
pub fn transform_of(
    fps: Option<f64>,
    root: Option<&str>,
    up: Option<&str>,
    unit: Option<&str>,
) -> Result<Options, ApiError> {
    let bad = |e: String| ApiError::bad_request(e);
    Ok(Options {
        fps,
        root: root
            .map(str::parse)
            .transpose()
            .map_err(bad)?
            .unwrap_or_default(),
        up: up.map(str::parse).transpose().map_err(bad)?,
        metres_per_unit: unit
            .map(parse_unit)
            .transpose()
            .map_err(|e| ApiError::bad_request(e.to_string()))?,
    })
}

pub async fn frames(
    State(state): State<AppState>,
    Extension(holder): Extension<Holder>,
    Extension(caller): Extension<Caller>,
    Path(id): Path<String>,
    query: Result<Query<FramesQuery>, QueryRejection>,
) -> Result<Response, ApiError> {
    let Query(mut q) = query?;
    let onto = onto_of(q.skeleton.take().as_deref())?;
    let mut request = frames_request(q)?;
    if let Some(onto) = onto {
        retarget::check_format(request.format)?;
        request.onto = Some(retarget::target(&state.store, &caller.grant, &onto).await?);
    }
    let a = answer::open(
        &state.store,
        &state.caches,
        &state.answers,
        holder,
        &state.limits,
        &id,
        request,
    )
    .await?;
    state
        .metrics
        .decoded(a.frames(), a.frames() * a.points.unwrap_or(0) * 12);
    // Sized for these and what the outer layers add, so that the map never grows.
    let mut headers = HeaderMap::with_capacity(16);
    answer_headers(&a, &mut headers);
    let mut response = Response::new(streamed(a).await?);
    *response.headers_mut() = headers;
    Ok(response)
}

/// What an answer's headers say of it: its frames and where they start, its rate and the
/// take's, its points and unit, its length where the format fixes it, its content type.
/// The same for a whole answer and for each part of a batch ([`ranges`]).
fn answer_headers(a: &Answer, headers: &mut HeaderMap) {
    const FRAMES: HeaderName = HeaderName::from_static("x-frames");
    const START: HeaderName = HeaderName::from_static("x-start-frame");
    const FPS: HeaderName = HeaderName::from_static("x-fps");
    const SOURCE_FPS: HeaderName = HeaderName::from_static("x-source-fps");
    const METRES: HeaderName = HeaderName::from_static("x-metres-per-unit");
    const POINTS: HeaderName = HeaderName::from_static("x-points");
    headers.insert(FRAMES, HeaderValue::from(a.frames_out));
    headers.insert(START, HeaderValue::from(a.start));
    headers.insert(FPS, number_value(a.fps));
    headers.insert(SOURCE_FPS, number_value(a.source_fps));
    headers.insert(METRES, number_value(a.metres_per_unit));
    if let Some(points) = a.points {
        headers.insert(POINTS, HeaderValue::from(points));
    }
    if let Some(n) = a.length {
        headers.insert(header::CONTENT_LENGTH, HeaderValue::from(n));
    }
    let content_type = match a.format {
        Format::Json | Format::Gltf => "application/json",
        Format::Glb => "model/gltf-binary",
        Format::C3d => "application/octet-stream",
        Format::Csv => "text/csv",
        Format::Trc | Format::Bvh => "text/plain",
        _ => "application/octet-stream",
    };
    headers.insert(header::CONTENT_TYPE, HeaderValue::from_static(content_type));
}

/// A number as a header value, as `f64`'s `Display` writes it (whole numbers without a
/// fraction: `120`, not `120.0`); whole ones, the usual rates, without float formatting.
fn number_value(v: f64) -> HeaderValue {
    const WHOLE: f64 = 9_007_199_254_740_992.0; // 2^53: every integer below is exact
    if v.fract() == 0.0 && v.abs() < WHOLE && !(v == 0.0 && v.is_sign_negative()) {
        return HeaderValue::from(v as i64);
    }
    HeaderValue::from_str(&v.to_string()).expect("numbers are valid header values")
}

#[derive(Deserialize, Default)]
pub struct RangesQuery {
    /// `ID:START-END,…`: frames `START..END` (the take's own, end excluded) of take `ID`.
    ranges: Option<String>,
    points: Option<String>,
    format: Option<String>,
    fps: Option<f64>,
    root: Option<String>,
    up: Option<String>,
    unit: Option<String>,
    /// The skeleton every part is put on, as `skeleton=` on a range.
    skeleton: Option<String>,
    feet: Option<String>,
}

/// A batch query as the parts and the shared points, format (f32 unless named) and
/// transforms it asks for.
fn ranges_request(q: RangesQuery) -> Result<RangesRequest, ApiError> {
    let list = q.ranges.as_deref().unwrap_or("");
    let bad = |r: &str| {
        ApiError::bad_request(format!(
            "ranges: {r:?} is not ID:START-END (frames START to END, END excluded)"
        ))
    };
    // The list is as long as the URL (hyper refuses one past 64 KiB); the service bounds
    // the parts.
    let mut parts = Vec::new();
    for r in list.split(',').map(str::trim).filter(|r| !r.is_empty()) {
        let (id, span) = r.rsplit_once(':').ok_or_else(|| bad(r))?;
        let (start, end) = span.split_once('-').ok_or_else(|| bad(r))?;
        let (Ok(start), Ok(end)) = (start.parse::<usize>(), end.parse::<usize>()) else {
            return Err(bad(r));
        };
        if id.is_empty() {
            return Err(bad(r));
        }
        parts.push(Part {
            id: id.to_string(),
            start,
            end,
        });
    }
    let format = match q.format.as_deref() {
        None => Format::F32,
        f => format_of(f)?,
    };
    Ok(RangesRequest {
        parts,
        points: q.points.map(|p| p.split(',').map(str::to_string).collect()),
        format,
        transform: transform_of(q.fps, q.root.as_deref(), q.up.as_deref(), q.unit.as_deref())?,
        onto: None,
        feet: feet_of(q.feet.as_deref())?,
    })
}

/// `GET /v1/ranges`: several ranges, of one take or many, as one `multipart/mixed` answer
/// (RFC 2046): each part has the headers and the body `/v1/takes/{id}/frames` gives
/// for its range, and `x-take` (and its older name `x-sequence`) naming its take, in the
/// order asked.
pub async fn ranges(
    State(state): State<AppState>,
    Extension(caller): Extension<Caller>,
    Extension(holder): Extension<Holder>,
    query: Result<Query<RangesQuery>, QueryRejection>,
) -> Result<Response, ApiError> {
    let Query(mut q) = query?;
    let onto = onto_of(q.skeleton.take().as_deref())?;
    let mut request = ranges_request(q)?;
    if let Some(onto) = onto {
        request.onto = Some(retarget::target(&state.store, &caller.grant, &onto).await?);
    }
    let batch = ranges::open(
        &state.store,
        &state.caches,
        &state.answers,
        holder,
        &state.limits,
        &caller.grant,
        request,
    )
    .await?;
    let mut random = [0u8; 16];
    getrandom::fill(&mut random)
        .map_err(|e| crate::service::Error::Internal(format!("no random boundary: {e}")))?;
    let boundary: String = random.iter().map(|b| format!("{b:02x}")).collect();
    let content_type = format!("multipart/mixed; boundary={boundary}");
    let body = Multipart {
        batch,
        boundary,
        part: None,
        first: None,
        done: false,
        metrics: state.metrics.clone(),
    };
    Ok((
        [(header::CONTENT_TYPE, content_type)],
        streamed(body).await?,
    )
        .into_response())
}

/// The largest first piece of a part copied into its head's buffer (outside the answer
/// budget, so small: a one-second window of a few hundred points).
const MERGED_PIECE: usize = 16 << 10;

/// A batch written as `multipart/mixed`: each part's head (its boundary and headers), then
/// its answer's pieces; the closing boundary last.
struct Multipart {
    batch: Ranges,
    boundary: String,
    part: Option<(String, Answer)>,
    /// The open part's first piece, when it was too large to join its head.
    first: Option<Bytes>,
    done: bool,
    metrics: Arc<Metrics>,
}

impl Multipart {
    async fn next(&mut self) -> Result<Option<Bytes>, crate::service::Error> {
        if let Some(piece) = self.first.take() {
            return Ok(Some(piece));
        }
        if let Some((_, a)) = &mut self.part {
            if let Some(piece) = a.next().await? {
                return Ok(Some(piece));
            }
            self.part = None;
        }
        if self.done {
            return Ok(None);
        }
        // A part's body ends with the line break before the next boundary.
        let mut head = format!("\r\n--{}", self.boundary).into_bytes();
        let Some(mut a) = self.batch.next_part().await? else {
            head.extend_from_slice(b"--\r\n");
            self.done = true;
            return Ok(Some(Bytes::from(head)));
        };
        self.metrics
            .decoded(a.frames(), a.frames() * a.points.unwrap_or(0) * 12);
        let mut headers = HeaderMap::with_capacity(10);
        answer_headers(&a, &mut headers);
        let id = HeaderValue::from_str(&a.id).map_err(|_| {
            crate::service::Error::Corrupt(format!("take id {:?} is no header value", a.id))
        })?;
        // `x-sequence` is the header's older name, kept for clients that read it.
        headers.insert("x-sequence", id.clone());
        headers.insert("x-take", id);
        for (name, value) in &headers {
            head.extend_from_slice(b"\r\n");
            head.extend_from_slice(name.as_str().as_bytes());
            head.extend_from_slice(b": ");
            head.extend_from_slice(value.as_bytes());
        }
        head.extend_from_slice(b"\r\n\r\n");
        // The part's first piece is made with its head: a first part that fails to decode at
        // its start fails the answer before its status. A small piece (a window) goes in the
        // head's buffer; a larger one is handed on as it is, counted in the part's budget.
        let first = a.next().await?;
        self.part = Some((a.id.clone(), a));
        match first {
            Some(piece) if piece.len() <= MERGED_PIECE => head.extend_from_slice(&piece),
            Some(piece) => self.first = Some(piece),
            None => {}
        }
        Ok(Some(Bytes::from(head)))
    }
}

impl Pieces for Multipart {
    fn next_piece(
        &mut self,
    ) -> impl std::future::Future<Output = Result<Option<Bytes>, crate::service::Error>> + Send
    {
        self.next()
    }

    fn what(&self) -> String {
        match &self.part {
            Some((id, _)) => format!("batch of {} ranges, at take {id}", self.batch.len()),
            None => format!("batch of {} ranges", self.batch.len()),
        }
    }
}

/// The body of an answer written piece by piece. The first piece is made before the
/// status: what fails at the start (a stored chunk that does not decode) is still an error
/// answer, not a cut-off one. Past it, a failure can only cut the body short, which a
/// client sees as a body shorter than its length or an unfinished chunking.
pub async fn streamed<P: Pieces>(mut a: P) -> Result<Body, ApiError> {
    let first = a.next_piece().await?;
    if a.finished() {
        return Ok(Body::from(first.unwrap_or_default()));
    }
    let rest = futures_util::stream::unfold(Some(a), |a| async move {
        let mut a = a?;
        match a.next_piece().await {
            Ok(Some(piece)) => Some((Ok(piece), Some(a))),
            Ok(None) => None,
            Err(e) => {
                tracing::error!(answer = %a.what(), error = %e, "an answer failed part way");
                Some((Err(e), None))
            }
        }
    });
    Ok(Body::from_stream(
        futures_util::stream::iter(first.map(Ok)).chain(rest),
    ))
}

/// The output format a query names; JSON when it names none.
pub fn format_of(format: Option<&str>) -> Result<Format, ApiError> {
    format.map_or(Ok(Format::Json), |f| {
        f.parse::<Format>()
            .map_err(|e| ApiError::bad_request(e.to_string()))
    })
}

#[derive(Deserialize)]
pub struct AnalogQuery {
    start: Option<usize>,
    end: Option<usize>,
    t0: Option<f64>,
    t1: Option<f64>,
    /// Channel labels, comma-separated; all when absent.
    channels: Option<String>,
    format: Option<String>,
}

/// `GET /v1/takes/{id}/analog`: analog channels over a range, in their units.
pub async fn analog(
    State(state): State<AppState>,
    Extension(holder): Extension<Holder>,
    Path(id): Path<String>,
    query: Result<Query<AnalogQuery>, QueryRejection>,
) -> Result<Response, ApiError> {
    let Query(q) = query?;
    let (frames, labels) = columns_request(
        "analog channels",
        FramesQuery {
            start: q.start,
            end: q.end,
            t0: q.t0,
            t1: q.t1,
            format: q.format,
            ..FramesQuery::default()
        },
        q.channels,
    )?;
    let a = analog::answer(
        &state.store,
        &state.answers,
        holder,
        &state.limits,
        &id,
        frames.range,
        &labels,
    )
    .await?;
    columns_response(a, frames.format)
}

/// A request for columns over a range (`what`: analog channels, model outputs): its frames,
/// a format columns are written in (json, csv, npy, f32), and the comma-separated names
/// asked for (all when none).
fn columns_request(
    what: &str,
    range: FramesQuery,
    names: Option<String>,
) -> Result<(RangeRequest, Vec<String>), ApiError> {
    if let Some(f) = range.format.as_deref() {
        if !matches!(f, "json" | "csv" | "npy" | "f32") {
            return Err(ApiError::bad_request(format!(
                "{what} are answered as json, csv, npy or f32, not {f:?}"
            )));
        }
    }
    let names = names
        .map(|c| c.split(',').map(|l| l.trim().to_string()).collect())
        .unwrap_or_default();
    Ok((frames_request(range)?, names))
}

/// Columns over a range (analog channels, model outputs) as `format`, with headers that
/// say where they start, how many frames and columns and at what rate.
fn columns_response(a: analog::AnalogAnswer, format: Format) -> Result<Response, ApiError> {
    let content_type = match format {
        Format::Json => "application/json",
        Format::Csv => "text/csv",
        _ => "application/octet-stream",
    };
    let body = formats::columns::write(
        &formats::columns::Columns {
            rate: a.rate,
            t0: a.t0,
            columns: &a.columns,
            values: &a.values,
        },
        format,
    )
    .map_err(|e| ApiError::bad_request(e.to_string()))?;
    let mut headers = HeaderMap::new();
    let hv = |v: String| HeaderValue::from_str(&v).expect("numbers are valid header values");
    headers.insert("x-start-frame", hv(a.start_frame.to_string()));
    headers.insert("x-frames", hv(a.frames.to_string()));
    headers.insert("x-rate", hv(a.rate.to_string()));
    headers.insert("x-channels", hv(a.columns.len().to_string()));
    headers.insert(header::CONTENT_TYPE, HeaderValue::from_static(content_type));
    headers.insert(header::CONTENT_LENGTH, hv(body.len().to_string()));
    Ok((headers, held_body(body, a.reservation)).into_response())
}

#[derive(Deserialize)]
pub struct OutputsQuery {
    start: Option<usize>,
    end: Option<usize>,
    t0: Option<f64>,
    t1: Option<f64>,
    /// Output names, comma-separated; all when absent.
    names: Option<String>,
    format: Option<String>,
}

/// `GET /v1/takes/{id}/outputs`: model outputs (joint angles, forces, moments, powers)
/// over a range, three columns each in the output's own unit.
pub async fn outputs(
    State(state): State<AppState>,
    Extension(holder): Extension<Holder>,
    Path(id): Path<String>,
    query: Result<Query<OutputsQuery>, QueryRejection>,
) -> Result<Response, ApiError> {
    let Query(q) = query?;
    let (frames, names) = columns_request(
        "model outputs",
        FramesQuery {
            start: q.start,
            end: q.end,
            t0: q.t0,
            t1: q.t1,
            format: q.format,
            ..FramesQuery::default()
        },
        q.names,
    )?;
    let a = crate::service::outputs::answer(
        &state.store,
        &state.answers,
        holder,
        &state.limits,
        &id,
        frames.range,
        &names,
    )
    .await?;
    columns_response(a, frames.format)
}

/// A body of `bytes` that keeps `reservation` (what it holds of the answer budget) until
/// it has been handed to the connection whole.
fn held_body(bytes: Vec<u8>, reservation: crate::service::budget::Reservation) -> Body {
    let state = (Some(Bytes::from(bytes)), Some(reservation));
    Body::from_stream(futures_util::stream::unfold(
        state,
        |(bytes, reservation)| async move {
            match bytes {
                Some(b) => Some((Ok::<_, std::io::Error>(b), (None, reservation))),
                // Asked for more: the bytes are written; the reservation goes.
                None => {
                    drop(reservation);
                    None
                }
            }
        },
    ))
}

/// `GET /v1/takes/{id}/parameters`: the uploaded file's parameter section as a typed
/// tree (groups of typed, dimensioned parameters), with its force plates read out.
pub async fn parameters(
    State(state): State<AppState>,
    Path(id): Path<String>,
) -> Result<Response, ApiError> {
    let view = analog::parameters_view(&state.store, &id).await?;
    Ok(Json(view).into_response())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A number's header value is what `Display` writes, whole or not.
    #[test]
    fn numbers_in_headers_read_as_display_writes_them() {
        for v in [
            120.0,
            29.97,
            0.001,
            0.0,
            -0.0,
            -3.0,
            1e15,
            9_007_199_254_740_992.0,
            1e300,
            f64::INFINITY,
            f64::NAN,
            1.0 / 3.0,
            9_007_199_254_740_991.0,
            -2.5,
            f64::NEG_INFINITY,
            2f64.powi(60),
            f64::MIN_POSITIVE / 4.0,
        ] {
            assert_eq!(number_value(v).to_str().unwrap(), v.to_string(), "{v:?}");
        }
    }

    /// Each header field fills its own field of the query (and CORS allows exactly these):
    /// a field added to the table but wired to nothing, or twice, fails here.
    #[test]
    fn every_header_field_fills_its_own_field() {
        let mut filled = Vec::new();
        for (name, _) in HEADER_FIELDS {
            let value = match *name {
                "lenient" => "true",
                _ => "1",
            };
            let mut h = HeaderMap::new();
            h.insert(
                header::HeaderName::from_bytes(format!("x-mocap-{name}").as_bytes()).unwrap(),
                value.parse().unwrap(),
            );
            let q = IngestQuery::default().with_headers(&h).unwrap();
            assert_ne!(q, IngestQuery::default(), "{name} fills nothing");
            assert!(
                !filled.contains(&format!("{q:?}")),
                "{name} fills another's field"
            );
            filled.push(format!("{q:?}"));
            // The query wins where both are given.
            let asked = || IngestQuery {
                name: Some("asked".into()),
                fps: Some(30.0),
                lenient: Some(false),
                ..IngestQuery::default()
            };
            if ["name", "fps", "lenient"].contains(name) {
                assert_eq!(asked().with_headers(&h).unwrap(), asked(), "{name}");
            }
        }
        let bad = |name: &str, v: &str| {
            let mut h = HeaderMap::new();
            h.insert(
                header::HeaderName::from_bytes(format!("x-mocap-{name}").as_bytes()).unwrap(),
                v.parse().unwrap(),
            );
            IngestQuery::default().with_headers(&h).is_err()
        };
        assert!(bad("fps", "fast") && bad("max-error-mm", "x") && bad("lenient", "yes"));
    }
}
