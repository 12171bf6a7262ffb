//! `/v1/streams`: live takes. Open, append frames (JSON or little-endian f32), finish.

use axum::body::Bytes;
use axum::extract::rejection::{JsonRejection, QueryRejection};
use axum::extract::{Path, Query, State};
use axum::http::{header, HeaderMap, StatusCode};
use axum::response::{IntoResponse, Response};
use axum::Extension;
use axum::Json;
use serde::de::{DeserializeSeed, Deserializer, MapAccess, SeqAccess, Visitor};
use serde::Deserialize;

use super::error::ApiError;
use super::views::TakeView;
use super::AppState;
use crate::service::access::{self, Caller};
use crate::service::streams::{OpenRequest, StreamInfo};

pub async fn open(
    State(state): State<AppState>,
    Extension(caller): Extension<Caller>,
    body: Result<Json<OpenRequest>, JsonRejection>,
) -> Result<impl IntoResponse, ApiError> {
    let Json(mut req) = body.map_err(|r| ApiError::bad_request(r.body_text()))?;
    req.library = caller.grant.library_for_new(&req.library)?;
    let info = state.streams.open(&state.store, req).await?;
    let location = format!("/v1/streams/{}", info.id);
    Ok((
        StatusCode::CREATED,
        [(header::LOCATION, location)],
        Json(info),
    ))
}

pub async fn get(
    State(state): State<AppState>,
    Extension(caller): Extension<Caller>,
    Path(id): Path<String>,
) -> Result<Json<StreamInfo>, ApiError> {
    access::check_take(&state.store, &caller.grant, &id).await?;
    Ok(Json(state.streams.info(&state.store, &id).await?))
}

#[derive(Deserialize)]
pub struct AppendQuery {
    /// Commit the frames still pending in an unfinished chunk now.
    #[serde(default)]
    flush: bool,
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

pub async fn append(
    State(state): State<AppState>,
    Extension(caller): Extension<Caller>,
    Path(id): Path<String>,
    query: Result<Query<AppendQuery>, QueryRejection>,
    headers: HeaderMap,
    body: Bytes,
) -> Result<Json<StreamInfo>, ApiError> {
    let Query(q) = query?;
    access::check_take(&state.store, &caller.grant, &id).await?;
    let frames = parse_frames(&headers, &body)?;
    let info = state
        .streams
        .append(&state.store, &state.caches, &id, frames, q.flush)
        .await?;
    Ok(Json(info))
}

pub async fn finish(
    State(state): State<AppState>,
    Extension(caller): Extension<Caller>,
    Path(id): Path<String>,
) -> Result<Response, ApiError> {
    access::check_take(&state.store, &caller.grant, &id).await?;
    let take = state
        .streams
        .finish(&state.store, &state.caches, &id)
        .await?;
    Ok(Json(TakeView::from(&take)).into_response())
}
