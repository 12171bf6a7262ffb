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
        uploaded_as: None,
    }
}

/// The layout an uploaded skeleton is listed under (it has no takes, so no take layout).
pub const UPLOADED_LAYOUT: &str = "uploaded";

/// A rig uploaded on its own, stored.
#[derive(Debug)]
pub struct Uploaded {
    pub row: SkeletonRow,
    pub rig: Arc<Skeleton>,
    /// False when the same rig (and character) was stored already.
    pub created: bool,
    pub warnings: Vec<String>,
}

/// Store the rig of a character or rig file (`POST /v1/skeletons`): a glTF character with
/// its bind pose and the file itself (for answers that play a take on its mesh), an FBX
/// character's bones at their bind pose, or a BVH hierarchy. Content addressed: the same
/// upload twice is the same skeleton.
pub async fn upload(
    store: &Store,
    bytes: bytes::Bytes,
    format: Option<crate::motion::format::Format>,
    limits: crate::motion::formats::ReadLimits,
) -> Result<Uploaded> {
    let (rig, file, warnings) = blocking(move || -> Result<_> {
        let file = crate::motion::formats::rig::read(&bytes, format, &limits)?;
        let character = file.character.then(|| *blake3::hash(&bytes).as_bytes());
        let rig = Skeleton::uploaded(file.joints, file.rest, character)
            .map_err(|e| Error::InvalidRequest(format!("skeleton: {e}")))?;
        Ok((
            rig,
            file.character.then_some(bytes),
            (file.format, file.warnings),
        ))
    })
    .await??;
    let (format, warnings) = warnings;
    let mut row = row_of(&rig, UPLOADED_LAYOUT, super::now_ms());
    row.uploaded_as = Some(format.name().to_string());
    let created = store.insert_skeleton(&row, file.as_deref()).await?;
    let (row, rig) = get(store, &rig.id(), &Grant::everything()).await?;
    Ok(Uploaded {
        row,
        rig,
        created,
        warnings,
    })
}

/// The character file uploaded skeleton `id` skins, checked against the hash the rig
/// names, and shared: the last few are held (a library export writes every take onto the
/// same one), [`HELD_CHARACTER_BYTES`] at most.
pub async fn character(store: &Store, id: &str) -> Result<Arc<Vec<u8>>> {
    static FILES: OnceLock<Mutex<HashMap<String, Arc<Vec<u8>>>>> = OnceLock::new();
    let files = FILES.get_or_init(|| Mutex::new(HashMap::new()));
    if let Some(f) = files.lock().ok().and_then(|c| c.get(id).cloned()) {
        return Ok(f);
    }
    let rig = load(store, id).await?;
    let want = rig
        .character()
        .ok_or_else(|| Error::Corrupt(format!("skeleton {id} skins no character")))?;
    let file = store.skeleton_character(id).await?.ok_or_else(|| {
        Error::Corrupt(format!(
            "skeleton {id} names a character file that is not stored"
        ))
    })?;
    let (file, got) = blocking(move || {
        let got = blake3::hash(&file).to_hex().to_string();
        (file, got)
    })
    .await?;
    if got != want {
        return Err(Error::Corrupt(format!(
            "skeleton {id}'s character file hashes to {got}, not the {want} it names"
        )));
    }
    let file = Arc::new(file);
    if let Ok(mut c) = files.lock() {
        let held: usize = c.values().map(|f| f.len()).sum();
        if held + file.len() > HELD_CHARACTER_BYTES {
            c.clear();
        }
        c.insert(id.to_string(), file.clone());
    }
    Ok(file)
}

/// The character files [`character`] keeps at most (a couple of large ones).
const HELD_CHARACTER_BYTES: usize = 2 * limits::MAX_CHARACTER_BYTES as usize;

/// Stored skeletons, newest first, optionally of one layout (payloads not read). A grant
/// limited to libraries sees those of its libraries' takes, each counted by those takes,
/// and the uploaded ones (rigs to put takes on, holding no library's motion).
pub async fn list(store: &Store, layout: Option<&str>, grant: &Grant) -> Result<Vec<SkeletonRow>> {
    let rows = store.skeletons(layout).await?;
    let Some(within) = grant.within() else {
        return Ok(rows);
    };
    let uses = store.skeleton_use_within(&within).await?;
    Ok(rows
        .into_iter()
        .filter_map(|mut r| {
            r.used_by = match uses.get(&r.id) {
                Some(&n) => n,
                None if r.uploaded_as.is_some() => 0,
                None => return None,
            };
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
        row.used_by = match uses.get(id) {
            Some(&n) => n,
            None if row.uploaded_as.is_some() => 0,
            None => return Err(missing()),
        };
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
