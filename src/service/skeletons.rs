//! Skeletons as stored objects: one per distinct joint hierarchy, referenced by every take
//! of it ([`crate::codec::Skeleton`]). Ingest stores a take's with the take; reads load the one a
//! take or header names, through a small cache (a skeleton never changes: its id is the hash
//! of its bytes).

use std::collections::HashMap;
use std::sync::{Arc, Mutex, OnceLock};

use super::access::Grant;
use super::{blocking, Error, Result};
use crate::codec::Skeleton;
use crate::limits;
use crate::motion::body::Roles;
use crate::motion::Animation;
use crate::store::{Deletion, SkeletonRow, Store};

/// Skeletons kept parsed; past this many the cache starts over.
const CACHED: usize = 256;

fn cache() -> &'static Mutex<HashMap<String, Arc<Skeleton>>> {
    static CACHE: OnceLock<Mutex<HashMap<String, Arc<Skeleton>>>> = OnceLock::new();
    CACHE.get_or_init(|| Mutex::new(HashMap::new()))
}

/// Parse a stored skeleton, checking that its bytes still hash to its id.
pub(super) fn parse(row: &SkeletonRow) -> Result<Skeleton> {
    let corrupt = |what: String| Error::Corrupt(format!("stored skeleton {}: {what}", row.id));
    let rig = Skeleton::parse(&row.payload, limits::Limits::default().points)
        .map_err(|e| corrupt(e.to_string()))?;
    if rig.id() != row.id {
        return Err(corrupt(format!("its bytes hash to {}", rig.id())));
    }
    Ok(rig)
}

/// The skeleton with this id (a take or a header names it).
pub async fn load(store: &Store, id: &str) -> Result<Arc<Skeleton>> {
    if let Some(r) = cache().lock().ok().and_then(|c| c.get(id).cloned()) {
        return Ok(r);
    }
    let row = store
        .skeleton(id)
        .await?
        .ok_or_else(|| Error::Corrupt(format!("skeleton {id} is referenced but not stored")))?;
    let rig = Arc::new(blocking(move || parse(&row)).await??);
    if let Ok(mut c) = cache().lock() {
        if c.len() >= CACHED {
            c.clear();
        }
        c.insert(id.to_string(), rig.clone());
    }
    Ok(rig)
}

/// The rig of a take's skeleton and the row that stores it.
pub fn of(skeleton: &Animation, layout: &str, now_ms: i64) -> Result<(Skeleton, SkeletonRow)> {
    let rig = Skeleton::new(skeleton.joints.clone())
        .map_err(|e| Error::InvalidRequest(format!("skeleton: {e}")))?;
    let row = row_of(&rig, layout, now_ms);
    Ok((rig, row))
}

/// The row that stores a rig (of takes of `layout`).
pub fn row_of(rig: &Skeleton, layout: &str, now_ms: i64) -> SkeletonRow {
    SkeletonRow {
        id: rig.id(),
        layout: layout.to_string(),
        joints: rig.joints().len() as i64,
        payload: rig.bytes().to_vec(),
        created_at: now_ms,
        used_by: 0,
    }
}

/// Stored skeletons, newest first, optionally of one layout (payloads not read). A grant
/// limited to libraries sees those of its libraries' takes, each counted by those takes.
pub async fn list(store: &Store, layout: Option<&str>, grant: &Grant) -> Result<Vec<SkeletonRow>> {
    let rows = store.skeletons(layout).await?;
    let Some(within) = grant.within() else {
        return Ok(rows);
    };
    let uses = store.skeleton_use_within(&within).await?;
    Ok(rows
        .into_iter()
        .filter_map(|mut r| {
            r.used_by = *uses.get(&r.id)?;
            Some(r)
        })
        .collect())
}

/// The roles of a stored skeleton's joints, as every take of it has them (before a take's
/// own corrections): read from its names, or its shape, once per skeleton (a listing parses
/// many takes of a few skeletons).
pub fn roles(rig: &Skeleton) -> Roles {
    static ROLES: OnceLock<Mutex<HashMap<String, Roles>>> = OnceLock::new();
    let cache = ROLES.get_or_init(|| Mutex::new(HashMap::new()));
    let id = rig.id();
    if let Some(r) = cache.lock().ok().and_then(|c| c.get(&id).cloned()) {
        return r;
    }
    let roles = Roles::of_skeleton(rig.joints());
    if let Ok(mut c) = cache.lock() {
        if c.len() >= CACHED {
            c.clear();
        }
        c.insert(id, roles.clone());
    }
    roles
}

/// One stored skeleton, parsed; to a grant limited to libraries, only one of their takes'
/// (any other is `NotFound`, as if it did not exist).
pub async fn get(store: &Store, id: &str, grant: &Grant) -> Result<(SkeletonRow, Arc<Skeleton>)> {
    let missing = || Error::NotFound(format!("skeleton {id}"));
    let mut row = store.skeleton(id).await?.ok_or_else(missing)?;
    if let Some(within) = grant.within() {
        let uses = store.skeleton_use_within(&within).await?;
        row.used_by = *uses.get(id).ok_or_else(missing)?;
    }
    let rig = load(store, id).await?;
    Ok((row, rig))
}

/// Delete a skeleton no take references.
pub async fn delete(store: &Store, id: &str) -> Result<()> {
    match store.delete_skeleton(id).await? {
        Deletion::Deleted => {
            if let Ok(mut c) = cache().lock() {
                c.remove(id);
            }
            Ok(())
        }
        Deletion::NotFound => Err(Error::NotFound(format!("skeleton {id}"))),
        Deletion::InUse(n) => Err(Error::Conflict(format!(
            "skeleton {id} is the skeleton of {n} stored take(s); delete them first"
        ))),
    }
}
