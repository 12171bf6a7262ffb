//! What the API shows of the service's records: a view per record, so that the stored
//! record, the domain type and the body a client reads can each change on their own.

use serde::Serialize;

use super::error::ApiError;
use crate::codec::basis::BasisKind;
use crate::motion::skeleton::Joint;
use crate::service;
use crate::service::library::Listing;
use crate::service::take::Take;
use crate::store::{AuditRow, BasisRow, SkeletonRow};

/// A take as `GET /v1/sequences/{id}` and listings show it: the take's record (its header
/// bytes and lease stay inside) and whether a live stream is still recording it.
#[derive(Serialize)]
pub struct TakeView<'a> {
    #[serde(flatten)]
    take: &'a Take,
    live: bool,
    /// What the take costs on disk (container, metadata row and keys), beside
    /// `stored_bytes` (the container alone).
    disk_bytes: u64,
}

impl<'a> From<&'a Take> for TakeView<'a> {
    fn from(take: &'a Take) -> Self {
        TakeView {
            take,
            live: take.is_live(),
            disk_bytes: take.disk_bytes().unwrap_or(take.stored_bytes),
        }
    }
}

/// One page of a listing.
#[derive(Serialize)]
pub struct ListingView<'a> {
    items: Vec<TakeView<'a>>,
    next_cursor: Option<&'a str>,
}

impl<'a> From<&'a Listing> for ListingView<'a> {
    fn from(l: &'a Listing) -> Self {
        ListingView {
            items: l.items.iter().map(TakeView::from).collect(),
            next_cursor: l.next_cursor.as_deref(),
        }
    }
}

/// A shared basis as `GET /v1/bases` and `GET /v1/bases/{id}` show it (not its payload).
#[derive(Serialize)]
pub struct BasisView<'a> {
    /// BLAKE3 of the payload, hex.
    id: &'a str,
    kind: BasisKind,
    layout: &'a str,
    points: i64,
    /// Shape, e.g. `3×31×31` (matrices × rows × columns).
    dims: &'a str,
    /// Which takes, which parameters, the objective per iteration.
    provenance: &'a serde_json::Value,
    /// Milliseconds since the Unix epoch.
    created_at: i64,
    /// How many takes reference it.
    used_by: i64,
}

impl<'a> TryFrom<&'a BasisRow> for BasisView<'a> {
    type Error = ApiError;
    /// A stored kind this build does not know is a corrupt record (500), not a default.
    fn try_from(r: &'a BasisRow) -> Result<Self, ApiError> {
        let kind = r
            .kind
            .parse::<BasisKind>()
            .map_err(|e| ApiError::from(service::Error::Corrupt(format!("basis {}: {e}", r.id))))?;
        Ok(BasisView {
            id: &r.id,
            kind,
            layout: &r.layout,
            points: r.points,
            dims: &r.dims,
            provenance: &r.provenance,
            created_at: r.created_at,
            used_by: r.used_by,
        })
    }
}

/// A skeleton as `GET /v1/skeletons` shows it, and with its hierarchy as
/// `GET /v1/skeletons/{id}` does.
#[derive(Serialize)]
pub struct SkeletonView<'a> {
    /// BLAKE3 of the payload, hex.
    id: &'a str,
    /// Layout signature of the takes of this skeleton.
    layout: &'a str,
    /// Joints, End Sites included.
    joints: i64,
    /// Milliseconds since the Unix epoch.
    created_at: i64,
    /// How many takes reference it.
    used_by: i64,
    #[serde(skip_serializing_if = "Option::is_none")]
    hierarchy: Option<&'a [Joint]>,
}

impl<'a> SkeletonView<'a> {
    pub fn of(r: &'a SkeletonRow, hierarchy: Option<&'a [Joint]>) -> Self {
        SkeletonView {
            id: &r.id,
            layout: &r.layout,
            joints: r.joints,
            created_at: r.created_at,
            used_by: r.used_by,
            hierarchy,
        }
    }
}

/// One entry of the audit log as `GET /v1/audit` shows it.
#[derive(Serialize)]
pub struct AuditView<'a> {
    /// Increasing; the cursor of the next page (`before`).
    seq: i64,
    /// Milliseconds since the Unix epoch.
    at: i64,
    token_id: Option<&'a str>,
    token_name: Option<&'a str>,
    /// What was asked, e.g. `DELETE /v1/sequences/{id}` or `token create`.
    action: &'a str,
    /// What it was asked of: the request's path, or the token's id.
    target: &'a str,
    /// The HTTP status it ended with.
    status: i64,
    detail: &'a str,
    /// How many requests the entry stands for (refusals counted together).
    count: i64,
}

impl<'a> From<&'a AuditRow> for AuditView<'a> {
    fn from(r: &'a AuditRow) -> Self {
        AuditView {
            seq: r.seq,
            at: r.at,
            token_id: r.token_id.as_deref(),
            token_name: r.token_name.as_deref(),
            action: &r.action,
            target: &r.target,
            status: r.status,
            detail: &r.detail,
            count: r.count,
        }
    }
}
