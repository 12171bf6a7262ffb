//! `/v1/tokens` and `/v1/audit`: API tokens (admin) and the audit log (admin).

use axum::extract::rejection::QueryRejection;
use axum::extract::{Path, Query, State};
use axum::http::{header, StatusCode};
use axum::response::{IntoResponse, Response};
use axum::Json;
use serde::Deserialize;

use super::error::ApiError;
use super::object::Object;
use super::views::{AuditView, NewTokenView, TokenView};
use super::AppState;
use crate::limits::MAX_AUDIT_PAGE;
use crate::service::access::{self, NewToken, TokenRequest};

pub async fn create(
    State(state): State<AppState>,
    body: Object<TokenRequest>,
) -> Result<Response, ApiError> {
    let Object(req) = body;
    let token: NewToken = access::create_token(&state.store, req).await?;
    state.auth.forget();
    let location = format!("/v1/tokens/{}", token.info.id);
    Ok((
        StatusCode::CREATED,
        [(header::LOCATION, location)],
        Json(NewTokenView::from(&token)),
    )
        .into_response())
}

pub async fn list(State(state): State<AppState>) -> Result<Response, ApiError> {
    let tokens = access::list_tokens(&state.store).await?;
    let views: Vec<TokenView> = tokens.iter().map(TokenView::from).collect();
    Ok(Json(views).into_response())
}

pub async fn revoke(
    State(state): State<AppState>,
    Path(id): Path<String>,
) -> Result<StatusCode, ApiError> {
    access::revoke_token(&state.store, &id).await?;
    state.auth.forget();
    Ok(StatusCode::NO_CONTENT)
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
pub struct AuditQuery {
    /// Entries before this `seq` (the last `seq` of the previous page).
    before: Option<i64>,
    limit: Option<usize>,
}

pub async fn audit(
    State(state): State<AppState>,
    query: Result<Query<AuditQuery>, QueryRejection>,
) -> Result<Response, ApiError> {
    let Query(q) = query?;
    if q.before.is_some_and(|b| b < 1) {
        return Err(ApiError::bad_request(
            "before is a seq of the log, 1 or more",
        ));
    }
    let limit = q.limit.unwrap_or(100);
    if limit == 0 || limit > MAX_AUDIT_PAGE {
        return Err(ApiError::bad_request(format!(
            "limit must be 1 to {MAX_AUDIT_PAGE}"
        )));
    }
    // What is counted but not yet written belongs in the answer.
    state.audit.flush(&state.store, true).await?;
    let rows = access::audit_log(&state.store, q.before, limit).await?;
    let entries: Vec<AuditView> = rows.iter().map(AuditView::from).collect();
    Ok(Json(entries).into_response())
}
