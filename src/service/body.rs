//! A take's body as the service keeps it ([`crate::motion::body`]): its axes are derived
//! at ingest and stored in its record; its roles are read from its skeleton or point names
//! whenever it is parsed ([`super::take::Take::roles`]).
//!
//! A take stored before bodies were kept gets its axes at its first read, from a sample
//! of its decoded chunks, without re-encoding; they are stored then, so that it happens
//! once. A live stream's are derived from its first chunk's frames as it commits it
//! ([`opening`]), and again from the whole take when it finishes or its server's lease
//! runs out and another closes it ([`closing`]).
//!
//! Every write of a body is conditional on the record being the one it was derived from
//! (`body_rev`, [`Store::set_meta`]): a correction is never undone by a derivation that
//! started before it, on this server or another.

use std::sync::Arc;

use super::analog;
use super::fetch::{header_of, shared};
use super::take::Take;
use super::{blocking, Error, Result};
use crate::codec::Reader;
use crate::motion::body::{derive, Axes, Axis, Given, Prior, RoleMap, Source};
use crate::motion::format::Format;
use crate::motion::formats::up_prior;
use crate::motion::Motion;
use crate::store::Store;

/// Chunks decoded to derive a stored take's axes: spread over the take, the first
/// included (its first second tells the way the body faces when it turns about).
const SAMPLED_CHUNKS: usize = 12;

/// How often a correction is tried again when the record changed under it (another
/// server derived or corrected the same body at the same moment).
const CORRECT_ATTEMPTS: usize = 3;

/// The take stored under `id`, parsed, with its body's axes (derived now, once, for a take
/// stored before bodies were kept: [`ensure`]).
pub async fn take(store: &Store, id: &str) -> Result<Take> {
    ensure(store, super::fetch::take(store, id).await?).await
}

/// `take` with its axes: as stored, or derived now and stored. A live take's are stored
/// by its stream (none before its first commit): it is given back as it is.
pub async fn ensure(store: &Store, mut take: Take) -> Result<Take> {
    if take.meta.axes.is_some() || take.is_live() {
        return Ok(take);
    }
    let given = given_before(&take);
    take.meta.axes = Some(derive_stored(store, &take, given).await?);
    // Lost to a re-encode or another derivation meanwhile: what is stored then wins, and
    // a later read finds it.
    if store.set_meta(&take.to_row()?).await? {
        take.body_rev += 1;
    }
    Ok(take)
}

/// A live stream's axes from the frames of its first chunk (`positions`, as sent): what
/// readers of the live take turn and move it by until it finishes.
pub fn opening(take: &Take, positions: Vec<f32>) -> Result<Axes> {
    axes_of(take, positions, None, given_before(take), None)
}

/// The axes of `take` from frames of it (`positions`; `joints`, a skeleton take's).
fn axes_of(
    take: &Take,
    positions: Vec<f32>,
    joints: Option<&[crate::motion::skeleton::Joint]>,
    given: Given,
    prior: Option<&Prior>,
) -> Result<Axes> {
    let m = Motion::new(
        take.fps,
        take.meta.unit.clone(),
        take.meta.point_names.clone(),
        positions,
        None,
    )
    .map_err(|e| stored(take, e))?;
    derive(&m, joints, &take.roles, given, prior).map_err(|e| stored(take, e))
}

/// A finishing stream's axes from the whole take, from a sample of its committed chunks
/// (as a take stored before bodies were kept gets them): what it is read by from then on.
pub async fn closing(store: &Store, take: &Take) -> Result<Axes> {
    derive_stored(store, take, given_before(take)).await
}

/// A stored take whose body cannot be derived: its record contradicts itself (what was
/// given is checked before it is stored).
fn stored(take: &Take, e: crate::motion::Error) -> Error {
    Error::Corrupt(format!("take {}: its body: {e}", take.id))
}

/// What a user gave of the take's axes before (at ingest or by PATCH): it stays when the
/// axes are derived again.
fn given_before(take: &Take) -> Given {
    let kept = |a: Option<Axis>, from: Option<Source>| a.filter(|_| from == Some(Source::Given));
    match &take.meta.axes {
        Some(a) => Given {
            up: kept(a.up, a.up_from),
            forward: kept(a.forward, a.forward_from),
        },
        None => Given::default(),
    }
}

/// A user's correction of a take's body: what it gives wins over what was read.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Correction {
    pub up: Option<Axis>,
    pub forward: Option<Axis>,
    /// Roles and the points that play them (none: nothing does), over the ones read.
    pub roles: RoleMap,
}

/// Correct take `id`'s body: the roles given replace the ones read (and earlier given
/// ones), the axes are derived again with what is given winning (an up or forward given
/// before stays unless given anew), and stored. A live take's body is derived at its
/// finish: it is corrected after.
pub async fn correct(store: &Store, id: &str, c: Correction) -> Result<Take> {
    for _ in 0..CORRECT_ATTEMPTS {
        let mut take = super::fetch::take(store, id).await?;
        if take.is_live() {
            return Err(Error::Unsatisfiable(format!(
                "take {id} is live: its body is derived when its stream finishes; correct it then"
            )));
        }
        for (role, names) in &c.roles {
            if let Some(n) = names.iter().find(|n| !take.meta.point_names.contains(n)) {
                return Err(Error::InvalidRequest(format!(
                    "body.roles.{role}: the take has no point named {n:?}"
                )));
            }
        }
        let before = given_before(&take);
        let given = Given {
            up: c.up.or(before.up),
            forward: c.forward.or(before.forward),
        };
        given
            .check()
            .map_err(|e| Error::InvalidRequest(format!("body: {e}")))?;
        take.meta.roles_given.extend(c.roles.clone());
        take.roles = std::mem::take(&mut take.roles).with_given(&take.meta.roles_given);
        take.meta.axes = Some(derive_stored(store, &take, given).await?);
        if store.set_meta(&take.to_row()?).await? {
            take.body_rev += 1;
            return Ok(take);
        }
        // Re-encoded, derived or corrected meanwhile: correct what is stored now.
    }
    Err(Error::Conflict(format!(
        "take {id} kept changing while its body was corrected; send the correction again"
    )))
}

/// What the take's source format says of up, as ingest would have read it (a C3D's from
/// its stored parameters).
async fn prior(store: &Store, take: &Take) -> Result<Option<Prior>> {
    // A stream's frames come in no file format: no convention.
    if take.source_format == "stream" {
        return Ok(None);
    }
    let format = take
        .source_format
        .parse::<Format>()
        .map_err(|e| Error::Corrupt(format!("take {}: source format: {e}", take.id)))?;
    let params = match format {
        Format::C3d => analog::parameters(store, &take.id).await?,
        _ => None,
    };
    Ok(up_prior(format, params.as_ref()))
}

/// The axes of a stored take, from up to [`SAMPLED_CHUNKS`] of its chunks decoded.
async fn derive_stored(store: &Store, take: &Take, given: Given) -> Result<Axes> {
    let prior = prior(store, take).await?;
    // The skeleton's joints, whatever the codec keeps: a toe's end site finds the floor.
    let rig = match &take.skeleton {
        Some(id) => Some(super::skeletons::load(store, id).await?),
        None => None,
    };
    let (header, _) = header_of(store, take).await?;
    let shared = shared(store, &header).await?;
    let n = header.chunks.len();
    let picked: Vec<usize> = if n <= SAMPLED_CHUNKS {
        (0..n).collect()
    } else {
        (0..SAMPLED_CHUNKS)
            .map(|i| i * (n - 1) / (SAMPLED_CHUNKS - 1))
            .collect()
    };
    let mut payloads = Vec::with_capacity(picked.len());
    for &i in &picked {
        let rows = store.chunks(&take.id, i as i64, i as i64 + 1).await?;
        let row = rows
            .into_iter()
            .next()
            .ok_or_else(|| Error::NotFound(format!("take {} chunk {i}", take.id)))?;
        payloads.push((i, row.payload));
    }
    let take = Arc::new(take.clone());
    blocking(move || {
        let reader = Reader::new(header, shared)
            .map_err(|e| Error::Corrupt(format!("stored take {}: {e}", take.id)))?;
        let mut positions = Vec::new();
        for (i, payload) in &payloads {
            positions.extend(reader.decode_chunk(*i, payload)?);
        }
        let joints = rig.as_ref().map(|r| r.joints());
        axes_of(&take, positions, joints, given, prior.as_ref())
    })
    .await?
}
