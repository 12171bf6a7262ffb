//! `/v1/skeletons`: the stored joint hierarchies takes reference (list, show, delete).

use axum::extract::rejection::QueryRejection;
use axum::extract::{Path, Query, State};
use axum::http::StatusCode;
use axum::{Extension, Json};
use serde::{Deserialize, Serialize};

use super::error::ApiError;
use super::AppState;
use crate::motion::skeleton::Joint;
use crate::service::access::Caller;
use crate::service::skeletons;
use crate::store::SkeletonRow;

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
    let items = skeletons::list(&state.store, q.layout.as_deref(), &caller.grant).await?;
    Ok(Json(serde_json::json!({ "items": items })))
}

/// A skeleton's row and its hierarchy.
#[derive(Serialize)]
pub struct SkeletonView {
    #[serde(flatten)]
    row: SkeletonRow,
    hierarchy: Vec<Joint>,
}

pub async fn get(
    State(state): State<AppState>,
    Extension(caller): Extension<Caller>,
    Path(id): Path<String>,
) -> Result<Json<SkeletonView>, ApiError> {
    let (row, rig) = skeletons::get(&state.store, &id, &caller.grant).await?;
    Ok(Json(SkeletonView {
        row,
        hierarchy: rig.joints().to_vec(),
    }))
}

/// 204, 404, or 409 while takes still reference the skeleton.
pub async fn delete(
    State(state): State<AppState>,
    Path(id): Path<String>,
) -> Result<StatusCode, ApiError> {
    skeletons::delete(&state.store, &id).await?;
    Ok(StatusCode::NO_CONTENT)
}
