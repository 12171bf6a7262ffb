//! `/v1/skeletons`: the stored joint hierarchies takes reference (list, show, delete), rigs
//! uploaded to put takes on (a glTF or FBX character, a BVH hierarchy), and how one maps
//! onto another skeleton (`/map`).

use axum::body::Bytes;
use axum::extract::rejection::{BytesRejection, QueryRejection};
use axum::extract::{Path, Query, State};
use axum::http::{header, StatusCode};
use axum::response::{IntoResponse, Response};
use axum::{Extension, Json};
use serde::Deserialize;

use super::error::ApiError;
use super::views::SkeletonView;
use super::AppState;
use crate::service::access::Caller;
use crate::service::{retarget, skeletons};

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ListQuery {
    layout: Option<String>,
}

pub async fn list(
    State(state): State<AppState>,
    Extension(caller): Extension<Caller>,
    query: Result<Query<ListQuery>, QueryRejection>,
) -> Result<Json<serde_json::Value>, ApiError> {
    let Query(q) = query?;
    let rows = skeletons::list(&state.store, q.layout.as_deref(), &caller.grant).await?;
    let items: Vec<SkeletonView> = rows.iter().map(|r| SkeletonView::of(r, None)).collect();
    Ok(Json(serde_json::json!({ "items": items })))
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
pub struct UploadQuery {
    /// The file's format (`glb`, `gltf`, `fbx`, `bvh`) where its content should not tell.
    format: Option<String>,
}

/// `POST /v1/skeletons`: a character or rig file in, its skeleton stored (201, or 200 when
/// the same rig was stored already) and shown with its hierarchy and roles.
pub async fn upload(
    State(state): State<AppState>,
    query: Result<Query<UploadQuery>, QueryRejection>,
    body: Result<Bytes, BytesRejection>,
) -> Result<Response, ApiError> {
    let Query(q) = query?;
    let body = body?;
    let format = match q.format.as_deref() {
        None => None,
        Some(f) => Some(f.parse::<crate::motion::format::Format>().map_err(|_| {
            ApiError::bad_request(format!(
                "format={f:?}: a rig is read from glb, gltf, fbx or bvh"
            ))
        })?),
    };
    if body.is_empty() {
        return Err(ApiError::bad_request(
            "the body is empty: send a glTF or FBX character or a BVH file",
        ));
    }
    let limits = crate::motion::formats::ReadLimits::from(&state.limits);
    let up = skeletons::upload(&state.store, body, format, limits).await?;
    let roles = skeletons::roles(&up.rig);
    let rest = up.rig.rest();
    let mut view = serde_json::to_value(SkeletonView::uploaded(
        &up.row,
        (up.rig.joints(), roles),
        &rest,
        up.rig.character().is_some(),
    ))
    .map_err(|e| ApiError::from(crate::service::Error::Corrupt(e.to_string())))?;
    view["warnings"] = serde_json::json!(up.warnings);
    let status = if up.created {
        StatusCode::CREATED
    } else {
        StatusCode::OK
    };
    let location = format!("/v1/skeletons/{}", up.row.id);
    Ok((status, [(header::LOCATION, location)], Json(view)).into_response())
}

pub async fn get(
    State(state): State<AppState>,
    Extension(caller): Extension<Caller>,
    Path(id): Path<String>,
) -> Result<Response, ApiError> {
    let (row, rig) = skeletons::get(&state.store, &id, &caller.grant).await?;
    let roles = skeletons::roles(&rig);
    if row.uploaded_as.is_some() {
        let rest = rig.rest();
        let view = SkeletonView::uploaded(
            &row,
            (rig.joints(), roles),
            &rest,
            rig.character().is_some(),
        );
        return Ok(Json(view).into_response());
    }
    Ok(Json(SkeletonView::of(&row, Some((rig.joints(), roles)))).into_response())
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
pub struct MapQuery {
    to: Option<String>,
}

/// `GET /v1/skeletons/{id}/map?to=…`: how the skeleton's takes are put on `to`.
pub async fn map(
    State(state): State<AppState>,
    Extension(caller): Extension<Caller>,
    Path(id): Path<String>,
    query: Result<Query<MapQuery>, QueryRejection>,
) -> Result<Response, ApiError> {
    let Query(q) = query?;
    let onto = super::takes::onto_of(q.to.as_deref())?.ok_or_else(|| {
        ApiError::bad_request("give to= (a standard rig, a skeleton id or take:ID)")
    })?;
    Ok(Json(retarget::map(&state.store, &caller.grant, &id, &onto).await?).into_response())
}

/// 204, 404, or 409 while takes still reference the skeleton.
pub async fn delete(
    State(state): State<AppState>,
    Path(id): Path<String>,
) -> Result<StatusCode, ApiError> {
    skeletons::delete(&state.store, &id).await?;
    Ok(StatusCode::NO_CONTENT)
}
