//! `/v1/streams`: live takes. Open, append frames (JSON or little-endian f32), finish.

use axum::body::Bytes;
use axum::extract::rejection::{JsonRejection, QueryRejection};
use axum::extract::{Path, Query, State};
use axum::http::{header, HeaderMap, StatusCode};
use axum::response::IntoResponse;
use axum::Json;
use serde::Deserialize;
use serde_json::Value;

use super::error::ApiError;
use super::AppState;
use crate::service::streams::{OpenRequest, StreamInfo};
use crate::store::SequenceRow;

pub async fn open(
    State(state): State<AppState>,
    body: Result<Json<OpenRequest>, JsonRejection>,
) -> Result<impl IntoResponse, ApiError> {
    let Json(req) = body.map_err(|r| ApiError::bad_request(r.body_text()))?;
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
    Path(id): Path<String>,
) -> Result<Json<StreamInfo>, ApiError> {
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
fn parse_frames(headers: &HeaderMap, body: &[u8]) -> Result<Vec<f32>, ApiError> {
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
    let v: Value = serde_json::from_slice(body)
        .map_err(|e| ApiError::bad_request(format!("frames JSON: {e}")))?;
    let frames = match &v {
        Value::Array(_) => &v,
        Value::Object(o) => o
            .get("frames")
            .ok_or_else(|| ApiError::bad_request("frames JSON needs a \"frames\" array"))?,
        _ => {
            return Err(ApiError::bad_request(
                "frames JSON must be an array or object",
            ))
        }
    };
    let frames = frames
        .as_array()
        .ok_or_else(|| ApiError::bad_request("\"frames\" must be an array of frames"))?;
    let mut out = Vec::new();
    for (i, f) in frames.iter().enumerate() {
        let f = f
            .as_array()
            .ok_or_else(|| ApiError::bad_request(format!("frame {i} is not an array")))?;
        for x in f {
            out.push(match x {
                Value::Null => f32::NAN,
                Value::Number(n) => n.as_f64().unwrap_or(f64::NAN) as f32,
                other => {
                    return Err(ApiError::bad_request(format!(
                        "frame {i}: {other} is not a number or null"
                    )))
                }
            });
        }
    }
    Ok(out)
}

pub async fn append(
    State(state): State<AppState>,
    Path(id): Path<String>,
    query: Result<Query<AppendQuery>, QueryRejection>,
    headers: HeaderMap,
    body: Bytes,
) -> Result<Json<StreamInfo>, ApiError> {
    let Query(q) = query?;
    let frames = parse_frames(&headers, &body)?;
    let info = state
        .streams
        .append(&state.store, &state.caches, &id, frames, q.flush)
        .await?;
    Ok(Json(info))
}

pub async fn finish(
    State(state): State<AppState>,
    Path(id): Path<String>,
) -> Result<Json<SequenceRow>, ApiError> {
    Ok(Json(
        state
            .streams
            .finish(&state.store, &state.caches, &id)
            .await?,
    ))
}
