//! `/v1/skeletons`: the stored joint hierarchies takes reference (list, show, delete), and
//! how one maps onto another skeleton (`/map`).

use axum::extract::rejection::QueryRejection;
use axum::extract::{Path, Query, State};
use axum::http::StatusCode;
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

pub async fn get(
    State(state): State<AppState>,
    Extension(caller): Extension<Caller>,
    Path(id): Path<String>,
) -> Result<Response, ApiError> {
    let (row, rig) = skeletons::get(&state.store, &id, &caller.grant).await?;
    let roles = skeletons::roles(&rig);
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
