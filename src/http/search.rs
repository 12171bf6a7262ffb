//! `POST /v1/search` and `GET /v1/takes/{id}/similar`: finding motion by motion
//! ([`crate::service::search`]). The query string carries the query's range, `k`,
//! `per_take` and the same filters a listing takes (`label.<key>=` too); `POST`'s body,
//! when it has one, is the clip to search with (any format ingest reads), else `take=`
//! names a stored take.

use axum::body::Bytes;
use axum::extract::rejection::{BytesRejection, QueryRejection};
use axum::extract::{Path, Query, State};
use axum::http::HeaderMap;
use axum::{Extension, Json};
use serde::Deserialize;

use super::error::ApiError;
use super::library::Pairs;
use super::AppState;
use crate::motion::formats::{self, ReadOptions};
use crate::motion::units::parse_unit;
use crate::service::access::Caller;
use crate::service::library::TakeQuery;
use crate::service::search::{self, Index, Query as Asked, SearchAnswer, SearchRequest};

/// Results answered when `k` is not given.
const DEFAULT_K: usize = 10;

#[derive(Deserialize)]
pub struct SearchQuery {
    /// The stored take whose range is the query (`POST` without a body).
    take: Option<String>,
    t0: Option<f64>,
    t1: Option<f64>,
    k: Option<usize>,
    per_take: Option<usize>,
    /// An uploaded clip's unit, when its file does not say.
    unit: Option<String>,
    /// `auto` (the default), `exact` or `approximate`.
    index: Option<String>,
}

fn request(
    caller: &Caller,
    q: SearchQuery,
    takes: TakeQuery,
    pairs: &Pairs,
    query: Asked,
) -> Result<SearchRequest, ApiError> {
    Ok(SearchRequest {
        query,
        k: q.k.unwrap_or(DEFAULT_K),
        per_take: q.per_take.unwrap_or(1),
        takes: takes.with_labels(pairs.iter().map(|(k, v)| (k.as_str(), v.as_str()))),
        grant: caller.grant.clone(),
        index: q
            .index
            .as_deref()
            .map(Index::parse)
            .transpose()?
            .unwrap_or_default(),
    })
}

pub async fn search(
    State(state): State<AppState>,
    Extension(caller): Extension<Caller>,
    headers: HeaderMap,
    query: Result<Query<SearchQuery>, QueryRejection>,
    takes: Result<Query<TakeQuery>, QueryRejection>,
    pairs: Result<Query<Pairs>, QueryRejection>,
    body: Result<Bytes, BytesRejection>,
) -> Result<Json<SearchAnswer>, ApiError> {
    let (Query(q), Query(takes), Query(pairs), body) = (query?, takes?, pairs?, body?);
    let asked = match (q.take.clone(), body.is_empty()) {
        (Some(_), false) => {
            return Err(ApiError::bad_request(
                "give take= (a stored take's range) or a clip as the body, not both",
            ))
        }
        (None, true) => {
            return Err(ApiError::bad_request(
                "nothing to search with: give take= (with t0 and t1 for a range of it), or \
                 send a clip as the body",
            ))
        }
        (Some(id), true) => Asked::Take {
            id,
            t0: q.t0,
            t1: q.t1,
        },
        (None, false) => Asked::Clip {
            bytes: body,
            format: super::takes::content_type_format(&headers),
            options: ReadOptions {
                limits: formats::ReadLimits::from(&state.limits),
                unit: q
                    .unit
                    .as_deref()
                    .map(parse_unit)
                    .transpose()
                    .map_err(|e| ApiError::bad_request(format!("unit: {e}")))?,
                fps: None,
                lenient: false,
                animation: None,
            },
            t0: q.t0,
            t1: q.t1,
        },
    };
    let req = request(&caller, q, takes, &pairs, asked)?;
    Ok(Json(search::search(&state.index, req).await?))
}

pub async fn similar(
    State(state): State<AppState>,
    Extension(caller): Extension<Caller>,
    Path(id): Path<String>,
    query: Result<Query<SearchQuery>, QueryRejection>,
    takes: Result<Query<TakeQuery>, QueryRejection>,
    pairs: Result<Query<Pairs>, QueryRejection>,
) -> Result<Json<SearchAnswer>, ApiError> {
    let (Query(q), Query(takes), Query(pairs)) = (query?, takes?, pairs?);
    if q.take.is_some() {
        return Err(ApiError::bad_request(
            "the take is the one in the path: leave out take=",
        ));
    }
    let asked = Asked::Take {
        id,
        t0: q.t0,
        t1: q.t1,
    };
    let req = request(&caller, q, takes, &pairs, asked)?;
    Ok(Json(search::search(&state.index, req).await?))
}
