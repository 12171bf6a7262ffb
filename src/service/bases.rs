//! Shared bases as stored objects: loading the one a take names, finding the newest for a
//! layout, listing and deleting them. Training new ones is [`super::training`].

use std::sync::Arc;

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
pub async fn list(
    store: &Store,
    layout: Option<&str>,
    kind: Option<BasisKind>,
) -> Result<Vec<BasisRow>> {
    Ok(store.bases(layout, kind.map(BasisKind::name)).await?)
}

/// One stored basis.
pub async fn get(store: &Store, id: &str) -> Result<BasisRow> {
    store
        .basis(id)
        .await?
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
