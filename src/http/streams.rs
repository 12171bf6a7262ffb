//! `/v1/streams`: live takes. Open, append frames (JSON or little-endian f32), watch them
//! arrive (server-sent events), finish.

use std::convert::Infallible;
use std::sync::Arc;

use axum::body::Bytes;
use axum::extract::rejection::QueryRejection;
use axum::extract::{Path, Query, State};
use axum::http::{header, HeaderMap, Method, StatusCode, Uri};
use axum::response::sse::{Event, KeepAlive, Sse};
use axum::response::{IntoResponse, Response};
use axum::Extension;
use axum::Json;
use base64::Engine;
use futures_util::StreamExt;
use serde::de::{DeserializeSeed, Deserializer, MapAccess, SeqAccess, Visitor};
use serde::{Deserialize, Serialize};
use tokio::sync::broadcast::error::RecvError;

use super::error::ApiError;
use super::object::Object;
use super::views::TakeView;
use super::AppState;
use crate::service::access::Caller;
use crate::service::budget::Holder;
use crate::service::streams::{Append, Arrival, OpenRequest, Route, StreamInfo, Watch};

/// The answer of the server that codes stream `id`, if that is another server: the
/// request forwarded there ([`super::forward`]). `None`: answer here — this server codes
/// it, took it over from one that stopped, or no server codes it (finished).
/// `method`, `uri`, `headers` and `body` are the request as it came.
async fn at_owner(
    state: &AppState,
    holder: &Holder,
    id: &str,
    method: Method,
    uri: &Uri,
    headers: &HeaderMap,
    body: Bytes,
) -> Result<Option<Response>, ApiError> {
    let forwarded = headers.contains_key(super::forward::FORWARDED);
    let Route::Owner { url } = state
        .streams
        .route(&state.store, id, holder, forwarded)
        .await?
    else {
        return Ok(None);
    };
    let answer = state
        .forwarder
        .send(&url, method, uri, headers, body, holder)
        .await;
    match answer {
        Ok(r) => {
            state.metrics.forwarded();
            Ok(Some(r))
        }
        Err(why) => {
            tracing::warn!(stream = id, owner = %url, error = %why, "forwarding a stream request failed");
            match state
                .streams
                .owner_unreachable(&state.store, id, holder, &url)
                .await?
            {
                Route::Here => Ok(None),
                Route::Owner { .. } => Err(ApiError::busy(format!(
                    "stream {id} is coded by another server that does not answer; retry"
                ))),
            }
        }
    }
}

pub async fn open(
    State(state): State<AppState>,
    Extension(caller): Extension<Caller>,
    Extension(holder): Extension<Holder>,
    body: Object<OpenRequest>,
) -> Result<impl IntoResponse, ApiError> {
    let Object(mut req) = body;
    req.library = caller.grant.library_for_new(&req.library)?;
    let info = state.streams.open(&state.store, req, &holder).await?;
    let location = format!("/v1/streams/{}", info.id);
    Ok((
        StatusCode::CREATED,
        [(header::LOCATION, location)],
        Json(info),
    ))
}

/// A read of a stream (its state, a watch): the owner's answer if another server codes the
/// stream (the route checked the caller's libraries).
async fn read_at_owner(
    state: &AppState,
    holder: &Holder,
    id: &str,
    uri: &Uri,
    headers: &HeaderMap,
) -> Result<Option<Response>, ApiError> {
    at_owner(state, holder, id, Method::GET, uri, headers, Bytes::new()).await
}

pub async fn get(
    State(state): State<AppState>,
    Extension(holder): Extension<Holder>,
    Path(id): Path<String>,
    uri: Uri,
    headers: HeaderMap,
) -> Result<Response, ApiError> {
    if let Some(r) = read_at_owner(&state, &holder, &id, &uri, &headers).await? {
        return Ok(r);
    }
    Ok(Json(state.streams.info(&state.store, &id).await?).into_response())
}

#[derive(Deserialize)]
pub struct AppendQuery {
    /// Commit the frames still pending in an unfinished chunk now.
    #[serde(default)]
    flush: bool,
    /// When the producer captured the last frame sent, in ms since the Unix epoch (its
    /// clock): watchers show the delay from capture to their screen.
    captured_ms: Option<i64>,
    /// The stream's frame index the body's first frame is: frames the stream has already
    /// (an append retried after its answer was lost) are not appended twice.
    first: Option<usize>,
}

/// Frames from the body: JSON (`{"frames": [[x, y, z, …], …]}` or a bare array of frames,
/// `null` for a missing coordinate) or, for any other content type, little-endian f32.
pub(super) fn parse_frames(headers: &HeaderMap, body: &[u8]) -> Result<Vec<f32>, ApiError> {
    let json = headers
        .get(header::CONTENT_TYPE)
        .and_then(|v| v.to_str().ok())
        .is_some_and(|t| t.starts_with("application/json"));
    if !json {
        if !body.len().is_multiple_of(4) {
            return Err(ApiError::bad_request(format!(
                "{} bytes are not whole f32 values",
                body.len()
            )));
        }
        return Ok(body
            .chunks_exact(4)
            .map(|b| f32::from_le_bytes([b[0], b[1], b[2], b[3]]))
            .collect());
    }
    let mut out = Vec::new();
    let mut de = serde_json::Deserializer::from_slice(body);
    FramesJson(&mut out)
        .deserialize(&mut de)
        .and_then(|()| de.end())
        .map_err(|e| ApiError::bad_request(format!("frames JSON: {e}")))?;
    Ok(out)
}

/// Reads JSON frames straight into a flat `Vec<f32>` (NaN for `null`): no tree of JSON
/// values, so an append costs at most four bytes of memory per coordinate it sends.
struct FramesJson<'a>(&'a mut Vec<f32>);

impl<'de> DeserializeSeed<'de> for FramesJson<'_> {
    type Value = ();
    fn deserialize<D: Deserializer<'de>>(self, d: D) -> Result<(), D::Error> {
        d.deserialize_any(self)
    }
}

impl<'de> Visitor<'de> for FramesJson<'_> {
    type Value = ();
    fn expecting(&self, f: &mut std::fmt::Formatter) -> std::fmt::Result {
        f.write_str("an array of frames, or an object with a \"frames\" array")
    }

    fn visit_seq<A: SeqAccess<'de>>(self, mut frames: A) -> Result<(), A::Error> {
        while frames.next_element_seed(Frame(&mut *self.0))?.is_some() {}
        Ok(())
    }

    fn visit_map<A: MapAccess<'de>>(self, mut map: A) -> Result<(), A::Error> {
        let mut seen = false;
        while let Some(key) = map.next_key::<std::borrow::Cow<'de, str>>()? {
            if key != "frames" || seen {
                return Err(serde::de::Error::custom(format!(
                    "unexpected field {key:?}: the object holds one \"frames\" array"
                )));
            }
            map.next_value_seed(FramesArray(&mut *self.0))?;
            seen = true;
        }
        if !seen {
            return Err(serde::de::Error::missing_field("frames"));
        }
        Ok(())
    }
}

/// The `"frames"` value: an array only.
struct FramesArray<'a>(&'a mut Vec<f32>);

impl<'de> DeserializeSeed<'de> for FramesArray<'_> {
    type Value = ();
    fn deserialize<D: Deserializer<'de>>(self, d: D) -> Result<(), D::Error> {
        d.deserialize_seq(FramesJson(self.0))
    }
}

/// One frame: an array of numbers or nulls.
struct Frame<'a>(&'a mut Vec<f32>);

impl<'de> DeserializeSeed<'de> for Frame<'_> {
    type Value = ();
    fn deserialize<D: Deserializer<'de>>(self, d: D) -> Result<(), D::Error> {
        d.deserialize_seq(self)
    }
}

impl<'de> Visitor<'de> for Frame<'_> {
    type Value = ();
    fn expecting(&self, f: &mut std::fmt::Formatter) -> std::fmt::Result {
        f.write_str("a frame: an array of numbers or nulls")
    }

    fn visit_seq<A: SeqAccess<'de>>(self, mut values: A) -> Result<(), A::Error> {
        while let Some(v) = values.next_element::<Option<f64>>()? {
            self.0.push(v.map_or(f32::NAN, |x| x as f32));
        }
        Ok(())
    }
}

#[allow(clippy::too_many_arguments)]
pub async fn append(
    State(state): State<AppState>,
    Extension(holder): Extension<Holder>,
    Path(id): Path<String>,
    query: Result<Query<AppendQuery>, QueryRejection>,
    uri: Uri,
    headers: HeaderMap,
    body: Bytes,
) -> Result<Response, ApiError> {
    let Query(q) = query?;
    let owner = at_owner(
        &state,
        &holder,
        &id,
        Method::POST,
        &uri,
        &headers,
        body.clone(),
    );
    if let Some(r) = owner.await? {
        return Ok(r);
    }
    let frames = parse_frames(&headers, &body)?;
    let info = state
        .streams
        .append(
            &state.store,
            &id,
            Append {
                frames,
                first: q.first,
                flush: q.flush,
                captured_ms: q.captured_ms,
            },
        )
        .await?;
    Ok(Json(info).into_response())
}

pub async fn finish(
    State(state): State<AppState>,
    Extension(holder): Extension<Holder>,
    Path(id): Path<String>,
    uri: Uri,
    headers: HeaderMap,
) -> Result<Response, ApiError> {
    let owner = at_owner(
        &state,
        &holder,
        &id,
        Method::POST,
        &uri,
        &headers,
        Bytes::new(),
    );
    if let Some(r) = owner.await? {
        return Ok(r);
    }
    let take = state.streams.finish(&state.store, &id).await?;
    Ok(Json(TakeView::from(&take)).into_response())
}

/// The first event of a watch: the stream, and this server's clock (for a watcher to
/// estimate its offset from it).
#[derive(Serialize)]
struct Hello<'a> {
    #[serde(flatten)]
    info: &'a StreamInfo,
    server_ms: i64,
}

/// A `frames` event: an append as it arrived.
#[derive(Serialize)]
struct Frames<'a> {
    first: usize,
    frames: usize,
    received_ms: i64,
    captured_ms: Option<i64>,
    /// `frames × points × 3` little-endian f32 in stored units (NaN: missing), base64.
    data: &'a str,
}

fn frames_event(a: &Arrival) -> Event {
    let bytes: Vec<u8> = a.positions.iter().flat_map(|v| v.to_le_bytes()).collect();
    let data = base64::engine::general_purpose::STANDARD.encode(bytes);
    json_event(
        "frames",
        &Frames {
            first: a.first,
            frames: a.frames,
            received_ms: a.received_ms,
            captured_ms: a.captured_ms,
            data: &data,
        },
    )
}

fn json_event(name: &str, value: &impl Serialize) -> Event {
    let data = serde_json::to_string(value).unwrap_or_else(|_| "{}".into());
    Event::default().event(name).data(data)
}

/// What a watch does next.
enum Next {
    Arrival(Arc<Arrival>),
    Skipped(u64),
    End(String),
    /// Time to ask again whether the watcher may still watch.
    Recheck,
}

async fn next(w: &mut Watch, tick: &mut tokio::time::Interval) -> Next {
    tokio::select! {
        r = w.arrivals.recv() => match r {
            Ok(a) => Next::Arrival(a),
            Err(RecvError::Lagged(n)) => Next::Skipped(n),
            Err(RecvError::Closed) => Next::End("finished".into()),
        },
        _ = w.stopping.wait_for(|s| *s) => Next::End("the server is shutting down".into()),
        _ = tick.tick() => Next::Recheck,
    }
}

/// A watch as its event stream goes: the watch, and who watches what.
struct Watching {
    watch: Watch,
    tick: tokio::time::Interval,
    state: AppState,
    caller: Caller,
    id: String,
}

/// How often a watch asks again whether its caller may still watch: a revoked or expired
/// token, or a take moved out of the token's libraries, ends it within this time and
/// [`crate::service::access::RECHECK_REUSE`].
pub const WATCH_RECHECK: std::time::Duration = std::time::Duration::from_secs(1);

/// `GET /v1/streams/{id}/events`: an open stream's frames as they arrive, as server-sent
/// events: `stream` (its state and the server's clock), then `frames` for the newest frame
/// and for every append after it (with when it was received and, if the producer said,
/// captured), `skipped` when this watcher fell behind, and `end` when the stream closes —
/// or when the watcher may no longer watch it (its token revoked or expired, the take moved
/// out of its libraries), asked again every [`WATCH_RECHECK`].
pub async fn events(
    State(state): State<AppState>,
    Extension(caller): Extension<Caller>,
    Extension(holder): Extension<Holder>,
    Path(id): Path<String>,
    uri: Uri,
    headers: HeaderMap,
) -> Result<Response, ApiError> {
    if let Some(r) = read_at_owner(&state, &holder, &id, &uri, &headers).await? {
        // Passed back as it comes, until this server shuts down (a watch here would end
        // then too; one held open would keep the server from stopping).
        let mut stopping = state.streams.stopping();
        let (parts, body) = r.into_parts();
        let stopped = async move {
            let _ = stopping.wait_for(|s| *s).await;
        };
        let body = body.into_data_stream().take_until(Box::pin(stopped));
        return Ok(Response::from_parts(
            parts,
            axum::body::Body::from_stream(body),
        ));
    }
    let mut watch = state.streams.watch(&state.store, &id, &holder).await?;
    let hello = json_event(
        "stream",
        &Hello {
            info: &watch.info,
            server_ms: crate::service::now_ms(),
        },
    );
    let head: Vec<Event> = std::iter::once(hello)
        .chain(watch.latest.take().map(|a| frames_event(&a)))
        .collect();
    let mut tick = tokio::time::interval(WATCH_RECHECK);
    tick.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Delay);
    tick.reset();
    let watching = Watching {
        watch,
        tick,
        state,
        caller,
        id,
    };
    let rest = futures_util::stream::unfold(Some(watching), |w| async move {
        let mut w = w?;
        loop {
            let event = match next(&mut w.watch, &mut w.tick).await {
                Next::Arrival(a) => frames_event(&a),
                Next::Skipped(n) => json_event("skipped", &serde_json::json!({ "appends": n })),
                Next::End(reason) => return Some((end_event(&reason), None)),
                Next::Recheck => {
                    use crate::service::Error as E;
                    let s = &w.state;
                    let why = match s.auth.recheck(&s.store, &w.caller, &w.id).await {
                        Ok(()) => continue,
                        Err(E::NotFound(_)) => {
                            "the take is no longer in this token's libraries".to_string()
                        }
                        Err(e @ E::Unauthorized(_)) => e.to_string(),
                        Err(e) => {
                            // The store could not be asked: ask again at the next tick.
                            tracing::warn!(stream = %w.id, error = %e, "rechecking a watcher failed");
                            continue;
                        }
                    };
                    return Some((end_event(&why), None));
                }
            };
            return Some((event, Some(w)));
        }
    });
    let events = futures_util::stream::iter(head)
        .chain(rest)
        .map(Ok::<_, Infallible>);
    Ok(Sse::new(events)
        .keep_alive(KeepAlive::default())
        .into_response())
}

fn end_event(reason: &str) -> Event {
    json_event("end", &serde_json::json!({ "reason": reason }))
}
