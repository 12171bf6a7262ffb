//! `GET /v1/takes` (listing), `PATCH /v1/takes/{id}`, `GET /v1/stats`,
//! `GET /v1/export` (a library as one ZIP), `GET`/`POST /v1/motion-stats` (normalisation
//! statistics of a selection's motion).

use axum::extract::rejection::QueryRejection;
use axum::extract::{Path, Query, State};
use axum::response::{IntoResponse, Response};
use axum::Extension;
use axum::Json;
use serde::Deserialize;

use axum::http::{header, HeaderMap, HeaderValue};

use super::error::ApiError;
use super::object::Object;
use super::takes::{feet_of, format_of, onto_of, streamed, transform_of};
use super::views::{ListingView, TakeView};
use super::AppState;
use crate::codec::CodecId;
use crate::labels::LabelChanges;
use crate::motion::body::{Axis, RoleMap};
use crate::service::access::Caller;
use crate::service::body;
use crate::service::budget::Holder;
use crate::service::export::{self, ExportRequest};
use crate::service::library::{self, Page, Stats, TakeQuery};
use crate::service::motion_stats::{self, By, MotionStats, Selection, StatsRequest};
use crate::store::SortKey;

/// A listing's order and page; its filter is the same query string read as a [`TakeQuery`].
#[derive(Deserialize)]
pub struct PageQuery {
    sort: Option<SortKey>,
    order: Option<Order>,
    limit: Option<usize>,
    cursor: Option<String>,
}

#[derive(Deserialize)]
#[serde(rename_all = "lowercase")]
enum Order {
    Asc,
    Desc,
}

pub async fn list(
    State(state): State<AppState>,
    Extension(caller): Extension<Caller>,
    takes: Result<Query<TakeQuery>, QueryRejection>,
    page: Result<Query<PageQuery>, QueryRejection>,
    pairs: Result<Query<Pairs>, QueryRejection>,
) -> Result<Response, ApiError> {
    let (Query(takes), Query(q), Query(pairs)) = (takes?, page?, pairs?);
    let takes = takes.with_labels(pairs.iter().map(|(k, v)| (k.as_str(), v.as_str())));
    let page = Page {
        sort: q.sort.unwrap_or_default(),
        descending: q.order.map(|o| matches!(o, Order::Desc)),
        limit: q.limit,
        cursor: q.cursor,
    };
    let listing = library::list(&state.store, &caller.grant, &takes, page).await?;
    Ok(Json(ListingView::from(&listing)).into_response())
}

/// A query string's pairs in order: where `label.<key>=<value>` conditions are read from.
pub(super) type Pairs = Vec<(String, String)>;

#[derive(Deserialize)]
pub struct StatsQuery {
    library: Option<String>,
    tag: Option<String>,
    codec: Option<CodecId>,
}

pub async fn stats(
    State(state): State<AppState>,
    Extension(caller): Extension<Caller>,
    query: Result<Query<StatsQuery>, QueryRejection>,
    pairs: Result<Query<Pairs>, QueryRejection>,
) -> Result<Json<Stats>, ApiError> {
    let (Query(q), Query(pairs)) = (query?, pairs?);
    let takes = TakeQuery {
        library: q.library,
        tag: q.tag,
        codec: q.codec,
        ..TakeQuery::default()
    }
    .with_labels(pairs.iter().map(|(k, v)| (k.as_str(), v.as_str())));
    Ok(Json(
        library::stats(&state.store, &caller.grant, &takes).await?,
    ))
}

#[derive(Deserialize)]
pub struct ExportQuery {
    library: Option<String>,
    tag: Option<String>,
    name_prefix: Option<String>,
    codec: Option<CodecId>,
    layout: Option<String>,
    format: Option<String>,
    fps: Option<f64>,
    root: Option<String>,
    up: Option<String>,
    unit: Option<String>,
    skeleton: Option<String>,
    feet: Option<String>,
}

/// `GET /v1/export`: every take of a selection in one format, as a ZIP streamed as it is
/// written, `manifest.csv` last.
pub async fn export(
    State(state): State<AppState>,
    Extension(caller): Extension<Caller>,
    Extension(holder): Extension<Holder>,
    query: Result<Query<ExportQuery>, QueryRejection>,
    pairs: Result<Query<Pairs>, QueryRejection>,
) -> Result<Response, ApiError> {
    let (Query(q), Query(pairs)) = (query?, pairs?);
    let format = format_of(q.format.as_deref())?;
    let transform = transform_of(q.fps, q.root.as_deref(), q.up.as_deref(), q.unit.as_deref())?;
    let file = format!(
        "{}-{}.zip",
        export::safe(q.library.as_deref().unwrap_or("library")),
        format.name()
    );
    let takes = TakeQuery {
        library: q.library,
        tag: q.tag,
        name_prefix: q.name_prefix,
        codec: q.codec,
        layout: q.layout,
        ..TakeQuery::default()
    }
    .with_labels(pairs.iter().map(|(k, v)| (k.as_str(), v.as_str())));
    let request = ExportRequest {
        takes,
        grant: caller.grant.clone(),
        format,
        transform,
        onto: onto_of(q.skeleton.as_deref())?,
        feet: feet_of(q.feet.as_deref())?,
    };
    let e = export::open(
        &state.store,
        &state.caches,
        &state.answers,
        holder,
        &state.limits,
        request,
    )
    .await?;
    let mut headers = HeaderMap::new();
    headers.insert(
        header::CONTENT_TYPE,
        HeaderValue::from_static("application/zip"),
    );
    headers.insert(header::CONTENT_DISPOSITION, attachment(&file));
    headers.insert("x-takes", HeaderValue::from(e.takes));
    Ok((headers, streamed(e).await?).into_response())
}

/// `GET /v1/motion-stats`: the selection as a listing's filters (and `label.<key>=`),
/// the points and transforms as a range request's.
#[derive(Deserialize)]
pub struct MotionStatsQuery {
    library: Option<String>,
    tag: Option<String>,
    name_prefix: Option<String>,
    codec: Option<CodecId>,
    layout: Option<String>,
    /// Point names, comma-separated.
    points: Option<String>,
    by: Option<String>,
    fps: Option<f64>,
    root: Option<String>,
    up: Option<String>,
    unit: Option<String>,
    /// Not a field of the query: refused with where it goes, rather than ignored (which
    /// would answer for every take the token reaches).
    ids: Option<String>,
}

/// `POST /v1/motion-stats`: the same as JSON, with the takes named by id (a training
/// split) instead of filters if wished, and labels as an object.
#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
pub struct MotionStatsBody {
    ids: Option<Vec<String>>,
    library: Option<String>,
    tag: Option<String>,
    name_prefix: Option<String>,
    codec: Option<CodecId>,
    layout: Option<String>,
    /// `{"content": "walk"}`: each a condition, as `label.<key>=` in a query string.
    labels: Option<serde_json::Map<String, serde_json::Value>>,
    points: Option<Vec<String>>,
    by: Option<String>,
    fps: Option<f64>,
    root: Option<String>,
    up: Option<String>,
    unit: Option<String>,
}

pub async fn motion_stats(
    State(state): State<AppState>,
    Extension(caller): Extension<Caller>,
    Extension(holder): Extension<Holder>,
    query: Result<Query<MotionStatsQuery>, QueryRejection>,
    pairs: Result<Query<Pairs>, QueryRejection>,
) -> Result<Json<MotionStats>, ApiError> {
    let (Query(q), Query(pairs)) = (query?, pairs?);
    if q.ids.is_some() {
        return Err(ApiError::bad_request(
            "takes by id come in the body of POST /v1/motion-stats ({\"ids\": [...]})",
        ));
    }
    let takes = TakeQuery {
        library: q.library,
        tag: q.tag,
        name_prefix: q.name_prefix,
        codec: q.codec,
        layout: q.layout,
        ..TakeQuery::default()
    }
    .with_labels(pairs.iter().map(|(k, v)| (k.as_str(), v.as_str())));
    let request = StatsRequest {
        selection: Selection::Query(Box::new(takes)),
        grant: caller.grant.clone(),
        points: q.points.map(|p| p.split(',').map(str::to_string).collect()),
        by: by_of(q.by.as_deref())?,
        transform: transform_of(q.fps, q.root.as_deref(), q.up.as_deref(), q.unit.as_deref())?,
    };
    stats_answer(&state, holder, request).await
}

pub async fn motion_stats_of(
    State(state): State<AppState>,
    Extension(caller): Extension<Caller>,
    Extension(holder): Extension<Holder>,
    body: Object<MotionStatsBody>,
) -> Result<Json<MotionStats>, ApiError> {
    let Object(b) = body;
    let mut labels = Vec::new();
    for (k, v) in b.labels.unwrap_or_default() {
        let text = match v {
            serde_json::Value::String(s) => s,
            serde_json::Value::Number(n) => n.to_string(),
            other => {
                return Err(ApiError::bad_request(format!(
                    "label {k:?}: a label is text or a number, not {other}"
                )))
            }
        };
        labels.push((format!("label.{k}"), text));
    }
    let filtered = b.library.is_some()
        || b.tag.is_some()
        || b.name_prefix.is_some()
        || b.codec.is_some()
        || b.layout.is_some()
        || !labels.is_empty();
    if b.ids.is_some() && filtered {
        return Err(ApiError::bad_request(
            "give ids or filters (library, tag, labels, name_prefix, codec, layout), not both",
        ));
    }
    let query = TakeQuery {
        library: b.library,
        tag: b.tag,
        name_prefix: b.name_prefix,
        codec: b.codec,
        layout: b.layout,
        ..TakeQuery::default()
    }
    .with_labels(labels.iter().map(|(k, v)| (k.as_str(), v.as_str())));
    let selection = match b.ids {
        Some(ids) => Selection::Ids(ids),
        None => Selection::Query(Box::new(query)),
    };
    let request = StatsRequest {
        selection,
        grant: caller.grant.clone(),
        points: b.points,
        by: by_of(b.by.as_deref())?,
        transform: transform_of(b.fps, b.root.as_deref(), b.up.as_deref(), b.unit.as_deref())?,
    };
    stats_answer(&state, holder, request).await
}

fn by_of(by: Option<&str>) -> Result<By, ApiError> {
    by.map(str::parse)
        .transpose()
        .map_err(ApiError::bad_request)
        .map(Option::unwrap_or_default)
}

async fn stats_answer(
    state: &AppState,
    holder: Holder,
    request: StatsRequest,
) -> Result<Json<MotionStats>, ApiError> {
    Ok(Json(
        motion_stats::compute(
            &state.store,
            &state.caches,
            &state.moments,
            &state.answers,
            holder,
            &state.limits,
            request,
        )
        .await?,
    ))
}

/// `Content-Disposition` of a download named `file` (letters of any script, digits, `._-`):
/// an ASCII `filename` for old clients and the UTF-8 one (RFC 6266) for the rest.
fn attachment(file: &str) -> HeaderValue {
    let ascii: String = file
        .chars()
        .map(|c| if c.is_ascii() { c } else { '_' })
        .collect();
    let encoded: String = file
        .bytes()
        .map(|b| {
            if b.is_ascii_alphanumeric() || b"._-".contains(&b) {
                char::from(b).to_string()
            } else {
                format!("%{b:02X}")
            }
        })
        .collect();
    HeaderValue::from_str(&format!(
        "attachment; filename=\"{ascii}\"; filename*=UTF-8''{encoded}"
    ))
    .expect("an ASCII header value")
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Patch {
    #[serde(default, deserialize_with = "present")]
    name: Option<String>,
    #[serde(default, deserialize_with = "present")]
    library: Option<String>,
    #[serde(default, deserialize_with = "present")]
    tags: Option<Vec<String>>,
    /// Labels set (key → text or number) or removed (key → null).
    #[serde(default, deserialize_with = "present")]
    labels: Option<serde_json::Value>,
    #[serde(default, deserialize_with = "present")]
    body: Option<BodyPatch>,
}

/// `body` of a PATCH: what the user says of the take's body, which wins over what was
/// read (`up`, `forward`: signed axes; `roles`: role → point names, `[]` for none).
#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
pub struct BodyPatch {
    #[serde(default, deserialize_with = "present")]
    up: Option<Axis>,
    #[serde(default, deserialize_with = "present")]
    forward: Option<Axis>,
    #[serde(default, deserialize_with = "present")]
    roles: Option<RoleMap>,
}

/// A PATCH field is absent (kept as it is) or a value: `null` is refused rather than read
/// as "absent", which would answer 200 to a request that changed nothing it named.
fn present<'de, D, T>(d: D) -> Result<Option<T>, D::Error>
where
    D: serde::Deserializer<'de>,
    T: Deserialize<'de>,
{
    Option::<T>::deserialize(d)?.map(Some).ok_or_else(|| {
        serde::de::Error::custom("null is not a value here; leave the field out to keep it")
    })
}

pub async fn patch(
    State(state): State<AppState>,
    Extension(caller): Extension<Caller>,
    Path(id): Path<String>,
    body: Object<Patch>,
) -> Result<Response, ApiError> {
    let Object(p) = body;
    if let Some(to) = &p.library {
        caller.grant.library(to)?;
    }
    let labels = p
        .labels
        .as_ref()
        .map(LabelChanges::from_json)
        .transpose()
        .map_err(ApiError::bad_request)?;
    let edit = library::Edit {
        name: p.name,
        library: p.library,
        tags: p.tags,
        labels,
        body: p.body.map(|b| body::Correction {
            up: b.up,
            forward: b.forward,
            roles: b.roles.unwrap_or_default(),
        }),
    };
    let take = library::update(&state.store, &id, edit).await?;
    Ok(Json(TakeView::from(&take)).into_response())
}
