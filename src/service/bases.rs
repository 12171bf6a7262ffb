//! Shared bases as stored objects: loading the one a take names, finding the newest for a
//! layout, listing and deleting them. Training new ones is [`super::training`].

use std::sync::Arc;

use super::access::Grant;
use super::{blocking, Error, Result};
use crate::codec::{Basis, BasisKind};
use crate::store::{BasisRow, Deletion, Store};

/// Parse a stored basis, checking that its bytes still hash to its id.
pub(super) fn parse(row: &BasisRow) -> Result<Basis> {
    let b = Basis::parse(&row.payload)
        .map_err(|e| Error::Internal(format!("stored basis {}: {e}", row.id)))?;
    if b.id() != row.id {
        return Err(Error::Internal(format!(
            "stored basis {} hashes to {}",
            row.id,
            b.id()
        )));
    }
    Ok(b)
}

/// The basis with this id (a take's header names it by hash).
pub async fn load(store: &Store, id: &str) -> Result<Arc<Basis>> {
    let row = store
        .basis(id)
        .await?
        .ok_or_else(|| Error::NotFound(format!("basis {id}")))?;
    Ok(Arc::new(blocking(move || parse(&row)).await??))
}

/// The newest basis of each kind trained for `layout`: what ingest codes takes of that
/// layout with.
pub async fn latest_for(store: &Store, layout: &str) -> Result<Vec<Arc<Basis>>> {
    let mut out = Vec::new();
    for kind in BasisKind::ALL {
        if let Some(row) = store.latest_basis(layout, kind.name()).await? {
            out.push(Arc::new(blocking(move || parse(&row)).await??));
        }
    }
    Ok(out)
}

/// Stored bases, newest first, optionally of one layout and/or kind (payloads not read).
/// A grant limited to libraries sees those its libraries' takes use or were trained from
/// ([`scoped`]).
pub async fn list(
    store: &Store,
    layout: Option<&str>,
    kind: Option<BasisKind>,
    grant: &Grant,
) -> Result<Vec<BasisRow>> {
    let rows = store.bases(layout, kind.map(BasisKind::name)).await?;
    scoped(store, rows, grant).await
}

/// One stored basis; to a grant limited to libraries, only one of theirs ([`scoped`]; any
/// other is `NotFound`, as if it did not exist).
pub async fn get(store: &Store, id: &str, grant: &Grant) -> Result<BasisRow> {
    let row = store.basis(id).await?;
    scoped(store, row.into_iter().collect(), grant)
        .await?
        .pop()
        .ok_or_else(|| Error::NotFound(format!("basis {id}")))
}

/// Delete a basis no take references.
pub async fn delete(store: &Store, id: &str) -> Result<()> {
    match store.delete_basis(id).await? {
        Deletion::Deleted => Ok(()),
        Deletion::NotFound => Err(Error::NotFound(format!("basis {id}"))),
        Deletion::InUse(n) => Err(Error::Conflict(format!(
            "basis {id} codes {n} stored take(s); delete them first"
        ))),
    }
}

/// The bases of `rows` a grant reaches, as it may see them. Over every library: all, as
/// stored. Limited to libraries: those that takes of its libraries use or were trained
/// from, with `used_by` counting only those takes, and a provenance that says nothing of
/// another library: its takes (and their frame total) only those in the grant's libraries,
/// and of the rest only how it was trained ([`SETTINGS`]), not what it measured on the
/// whole selection (samples, clips, sizes, objective).
async fn scoped(store: &Store, rows: Vec<BasisRow>, grant: &Grant) -> Result<Vec<BasisRow>> {
    let Some(within) = grant.within() else {
        return Ok(rows);
    };
    let uses = store.basis_use_within(&within).await?;
    let trained = |row: &BasisRow| -> Vec<String> {
        row.provenance["takes"]
            .as_array()
            .map(|a| {
                a.iter()
                    .filter_map(|v| v.as_str().map(str::to_string))
                    .collect()
            })
            .unwrap_or_default()
    };
    // One lookup for every basis's takes, not one per basis.
    let mut all: Vec<String> = rows.iter().flat_map(trained).collect();
    all.sort();
    all.dedup();
    let visible = store.take_frames_within(&all, &within).await?;
    let mut out = Vec::with_capacity(rows.len());
    for mut row in rows {
        let takes: Vec<String> = trained(&row)
            .into_iter()
            .filter(|t| visible.contains_key(t))
            .collect();
        let used = uses.get(&row.id).copied().unwrap_or(0);
        if used == 0 && takes.is_empty() {
            continue;
        }
        row.used_by = used;
        let frames: i64 = takes.iter().map(|t| visible[t]).sum();
        let mut provenance = serde_json::Map::new();
        for key in SETTINGS {
            if let Some(v) = row.provenance.get(*key) {
                provenance.insert((*key).to_string(), v.clone());
            }
        }
        if row.provenance.get("takes").is_some() {
            provenance.insert("takes".into(), serde_json::json!(takes));
            provenance.insert("frames".into(), serde_json::json!(frames));
        }
        row.provenance = serde_json::Value::Object(provenance);
        out.push(row);
    }
    Ok(out)
}

/// The fields of a basis's provenance that say how it was trained, not what it measured on
/// its takes: what a token limited to some of those takes' libraries is shown.
const SETTINGS: &[&str] = &[
    "algorithm",
    "sparsity",
    "max_iterations",
    "tolerance",
    "rank",
    "k",
    "bound_mm",
];
