//! `/v1/bases` (shared bases: train, list, show, delete) and `/v1/jobs/{id}`.

use axum::extract::rejection::QueryRejection;
use axum::extract::{Path, Query, State};
use axum::http::{header, StatusCode};
use axum::response::{IntoResponse, Response};
use axum::{Extension, Json};
use serde::Deserialize;

use super::error::ApiError;
use super::object::Object;
use super::views::BasisView;
use super::AppState;
use crate::codec::BasisKind;
use crate::limits::{MAX_JOBS_LISTED, MAX_JOB_WAIT_S};
use crate::service::access::Caller;
use crate::service::bases;
use crate::service::jobs::{Job, JobState};
use crate::service::training::{self, TrainRequest};
use crate::service::Error;

/// `POST /v1/bases`: 202 with the training job (and its address in `Location`).
pub async fn train(
    State(state): State<AppState>,
    body: Object<TrainRequest>,
) -> Result<impl IntoResponse, ApiError> {
    let Object(req) = body;
    let job = training::start_training(&state.store, &state.jobs, req).await?;
    let location = format!("/v1/jobs/{}", job.id);
    Ok((
        StatusCode::ACCEPTED,
        [(header::LOCATION, location)],
        Json(job),
    ))
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ListQuery {
    layout: Option<String>,
    kind: Option<BasisKind>,
}

pub async fn list(
    State(state): State<AppState>,
    Extension(caller): Extension<Caller>,
    query: Result<Query<ListQuery>, QueryRejection>,
) -> Result<Json<serde_json::Value>, ApiError> {
    let Query(q) = query?;
    let rows = bases::list(&state.store, q.layout.as_deref(), q.kind, &caller.grant).await?;
    let items: Vec<BasisView> = rows.iter().map(BasisView::from).collect();
    Ok(Json(serde_json::json!({ "items": items })))
}

pub async fn get(
    State(state): State<AppState>,
    Extension(caller): Extension<Caller>,
    Path(id): Path<String>,
) -> Result<Response, ApiError> {
    let row = bases::get(&state.store, &id, &caller.grant).await?;
    Ok(Json(BasisView::from(&row)).into_response())
}

/// 204, 404, or 409 while takes still reference the basis.
pub async fn delete(
    State(state): State<AppState>,
    Path(id): Path<String>,
) -> Result<StatusCode, ApiError> {
    bases::delete(&state.store, &id).await?;
    Ok(StatusCode::NO_CONTENT)
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
pub struct JobQuery {
    /// Wait up to this many seconds for the job to finish before answering.
    wait_s: Option<u64>,
}

pub async fn job(
    State(state): State<AppState>,
    Extension(caller): Extension<Caller>,
    Path(id): Path<String>,
    query: Result<Query<JobQuery>, QueryRejection>,
) -> Result<Json<Job>, ApiError> {
    let Query(q) = query?;
    let wait = q.wait_s.unwrap_or(0);
    if wait > MAX_JOB_WAIT_S {
        return Err(ApiError::bad_request(format!(
            "wait_s must be at most {MAX_JOB_WAIT_S}, got {wait}"
        )));
    }
    state
        .jobs
        .wait_for(&id, std::time::Duration::from_secs(wait), &caller.grant)
        .await?
        .map(Json)
        .ok_or_else(|| Error::NotFound(format!("job {id}")).into())
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
pub struct JobsQuery {
    state: Option<String>,
    limit: Option<usize>,
}

/// `GET /v1/jobs`: the jobs the token may see (every server's), newest first.
pub async fn jobs(
    State(state): State<AppState>,
    Extension(caller): Extension<Caller>,
    query: Result<Query<JobsQuery>, QueryRejection>,
) -> Result<Json<serde_json::Value>, ApiError> {
    let Query(q) = query?;
    let job_state = q
        .state
        .as_deref()
        .map(str::parse::<JobState>)
        .transpose()
        .map_err(ApiError::bad_request)?;
    let limit = q.limit.unwrap_or(100);
    if limit == 0 || limit > MAX_JOBS_LISTED {
        return Err(ApiError::bad_request(format!(
            "limit must be 1 to {MAX_JOBS_LISTED}, got {limit}"
        )));
    }
    let items = state.jobs.list(&caller.grant, job_state, limit).await?;
    Ok(Json(serde_json::json!({ "items": items })))
}
