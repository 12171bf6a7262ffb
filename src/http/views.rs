//! What the API shows of the service's records: a view per record, so that the stored
//! record, the domain type and the body a client reads can each change on their own.

use serde::Serialize;

use crate::codec::basis::BasisKind;
use crate::codec::CodecId;
use crate::motion::skeleton::Joint;
use crate::service::access::{NewToken, Scope, TokenInfo};
use crate::service::bases::{BasisInfo, Provenance};
use crate::service::library::Listing;
use crate::service::take::{Take, TakeMeta};
use crate::store::{AuditRow, SkeletonRow};

/// A take as `GET /v1/takes/{id}` and listings show it: the fields of its record the
/// API promises (`openapi.yaml`'s `Take`), named here one by one so that a field added
/// to [`Take`] stays inside until it is added here too; and whether a live stream is still
/// recording it. `meta` is the take's stored record of what it is and how it was coded.
#[derive(Serialize)]
pub struct TakeView<'a> {
    id: &'a str,
    name: &'a str,
    library: &'a str,
    tags: &'a [String],
    labels: &'a crate::labels::Labels,
    fps: f64,
    frames: usize,
    points: usize,
    duration_s: f64,
    metres_per_unit: f64,
    /// Layout signature (hex): takes of one layout share bases.
    layout: &'a str,
    source_format: &'a str,
    codec: CodecId,
    max_bound_mm: f64,
    #[serde(skip_serializing_if = "Option::is_none")]
    mean_bound_mm: Option<f64>,
    /// Whether the max bound is the cap a mean-only request got, not one asked for.
    max_bound_is_default: bool,
    raw_bytes: u64,
    stored_bytes: u64,
    ratio: f64,
    mean_mm: f64,
    rms_mm: f64,
    max_mm: f64,
    kg_percent: f64,
    meta: &'a TakeMeta,
    /// Milliseconds since the Unix epoch.
    created_at: i64,
    /// The stored skeleton of a skeleton take (its id).
    #[serde(skip_serializing_if = "Option::is_none")]
    skeleton: Option<&'a str>,
    live: bool,
    /// What the take costs on disk (container, metadata row and keys), beside
    /// `stored_bytes` (the container alone).
    disk_bytes: u64,
    /// Its body: up, forward, floor, how each was settled, and which points play which
    /// role. Null only for a listing's take whose axes are not derived yet (its own
    /// `GET` derives them).
    body: Option<crate::motion::body::Body>,
}

impl<'a> From<&'a Take> for TakeView<'a> {
    fn from(t: &'a Take) -> Self {
        TakeView {
            id: &t.id,
            name: &t.name,
            library: &t.library,
            tags: &t.tags,
            labels: &t.labels,
            fps: t.fps,
            frames: t.frames,
            points: t.points,
            duration_s: t.duration_s,
            metres_per_unit: t.metres_per_unit,
            layout: &t.layout,
            source_format: &t.source_format,
            codec: t.codec,
            max_bound_mm: t.bound.max_mm(),
            mean_bound_mm: t.bound.mean_mm(),
            max_bound_is_default: t.bound.max_is_default(),
            raw_bytes: t.raw_bytes,
            stored_bytes: t.stored_bytes,
            ratio: t.ratio,
            mean_mm: t.mean_mm,
            rms_mm: t.rms_mm,
            max_mm: t.max_mm,
            kg_percent: t.kg_percent,
            meta: &t.meta,
            created_at: t.created_at,
            skeleton: t.skeleton.as_deref(),
            live: t.is_live(),
            disk_bytes: t.disk_bytes().unwrap_or(t.stored_bytes),
            body: t.body(),
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
    points: usize,
    /// Shape, e.g. `3×31×31` (matrices × rows × columns).
    dims: &'a str,
    /// Which takes, which parameters, the objective per iteration.
    provenance: &'a Provenance,
    /// Milliseconds since the Unix epoch.
    created_at: i64,
    /// How many takes reference it.
    used_by: u64,
}

impl<'a> From<&'a BasisInfo> for BasisView<'a> {
    fn from(b: &'a BasisInfo) -> Self {
        BasisView {
            id: &b.id,
            kind: b.kind,
            layout: &b.layout,
            points: b.points,
            dims: &b.dims,
            provenance: &b.provenance,
            created_at: b.created_at,
            used_by: b.used_by,
        }
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
    /// Which joints play which role, with the hierarchy.
    #[serde(skip_serializing_if = "Option::is_none")]
    roles: Option<crate::motion::body::Roles>,
    /// The format of the file an uploaded rig came from; absent for a take's skeleton.
    #[serde(skip_serializing_if = "Option::is_none")]
    uploaded_as: Option<&'a str>,
    /// An uploaded rig's rest pose (channel values in hierarchy order: a character's bind
    /// pose), with the hierarchy.
    #[serde(skip_serializing_if = "Option::is_none")]
    rest: Option<&'a [f64]>,
    /// Whether the rig skins a character: a glb or gltf answer on it is the character
    /// playing the take.
    #[serde(skip_serializing_if = "Option::is_none")]
    character: Option<bool>,
}

impl<'a> SkeletonView<'a> {
    /// A listing's row (`hierarchy: None`), or one skeleton with its joints and their roles.
    pub fn of(
        r: &'a SkeletonRow,
        hierarchy: Option<(&'a [Joint], crate::motion::body::Roles)>,
    ) -> Self {
        let (hierarchy, roles) = hierarchy.unzip();
        SkeletonView {
            id: &r.id,
            layout: &r.layout,
            joints: r.joints,
            created_at: r.created_at,
            used_by: r.used_by,
            hierarchy,
            roles,
            uploaded_as: r.uploaded_as.as_deref(),
            rest: None,
            character: None,
        }
    }

    /// An uploaded rig with its hierarchy, roles, rest pose and whether it skins a
    /// character.
    pub fn uploaded(
        r: &'a SkeletonRow,
        hierarchy: (&'a [Joint], crate::motion::body::Roles),
        rest: &'a [f64],
        character: bool,
    ) -> Self {
        SkeletonView {
            rest: Some(rest),
            character: Some(character),
            ..SkeletonView::of(r, Some(hierarchy))
        }
    }
}

/// A token as `GET /v1/tokens` shows it (never its secret or hash).
#[derive(Serialize)]
pub struct TokenView<'a> {
    id: &'a str,
    name: &'a str,
    scope: Scope,
    /// `null`: every library.
    libraries: Option<&'a [String]>,
    /// Milliseconds since the Unix epoch, as every time here.
    created_at: i64,
    expires_at: Option<i64>,
    revoked_at: Option<i64>,
    /// When a request last presented it (to within a minute).
    last_used_at: Option<i64>,
}

impl<'a> From<&'a TokenInfo> for TokenView<'a> {
    fn from(t: &'a TokenInfo) -> Self {
        TokenView {
            id: &t.id,
            name: &t.name,
            scope: t.scope,
            libraries: t.libraries.as_deref(),
            created_at: t.created_at,
            expires_at: t.expires_at,
            revoked_at: t.revoked_at,
            last_used_at: t.last_used_at,
        }
    }
}

/// A token just created, as `POST /v1/tokens` answers: the only time its secret is seen.
#[derive(Serialize)]
pub struct NewTokenView<'a> {
    #[serde(flatten)]
    token: TokenView<'a>,
    secret: &'a str,
}

impl<'a> From<&'a NewToken> for NewTokenView<'a> {
    fn from(t: &'a NewToken) -> Self {
        NewTokenView {
            token: TokenView::from(&t.info),
            secret: &t.secret,
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
    /// What was asked, e.g. `DELETE /v1/takes/{id}` or `token create`.
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

#[cfg(test)]
mod tests {
    use super::*;

    /// The view names each field the API promises, and shows it as the take's own record
    /// spells it; a field added to [`Take`] does not appear in the API by itself.
    #[test]
    fn a_take_shows_the_fields_it_lists() {
        let mut take = Take::sample();
        take.skeleton = Some("s".into());
        let view = serde_json::to_value(TakeView::from(&take)).unwrap();
        let record = serde_json::to_value(&take).unwrap();
        let view = view.as_object().unwrap();
        let mut keys: Vec<&str> = view.keys().map(String::as_str).collect();
        keys.sort_unstable();
        let mut want = vec![
            "id",
            "name",
            "library",
            "tags",
            "labels",
            "fps",
            "frames",
            "points",
            "duration_s",
            "metres_per_unit",
            "layout",
            "source_format",
            "codec",
            "max_bound_mm",
            "mean_bound_mm",
            "max_bound_is_default",
            "raw_bytes",
            "stored_bytes",
            "ratio",
            "mean_mm",
            "rms_mm",
            "max_mm",
            "kg_percent",
            "meta",
            "created_at",
            "skeleton",
            "live",
            "disk_bytes",
            "body",
        ];
        want.sort_unstable();
        assert_eq!(keys, want);
        for (k, v) in view {
            match k.as_str() {
                "live" => assert_eq!(v, false),
                "disk_bytes" => assert!(v.as_u64().unwrap() > take.stored_bytes),
                "body" => assert_eq!(v, &serde_json::to_value(take.body()).unwrap()),
                _ => assert_eq!(Some(v), record.get(k), "{k}"),
            }
        }
    }
}
