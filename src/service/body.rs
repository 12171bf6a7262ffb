//! A take's body as the service keeps it ([`crate::motion::body`]): its axes are derived
//! at ingest and stored in its record; its roles are read from its skeleton or point names
//! whenever it is parsed ([`super::take::Take::roles`]).
//!
//! A take stored before bodies were kept gets its axes at its first read, from a sample
//! of its decoded chunks, without re-encoding; they are stored then, so that it happens
//! once. A live take's are derived from what it holds so far and not stored (every commit
//! rewrites its record; its finish derives them for good).

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

/// The take stored under `id`, parsed, with its body's axes (derived now, once, for a take
/// stored before bodies were kept: [`ensure`]).
pub async fn take(store: &Store, id: &str) -> Result<Take> {
    ensure(store, super::fetch::take(store, id).await?).await
}

/// `take` with its axes: as stored, or derived now (and stored, unless it is live).
pub async fn ensure(store: &Store, mut take: Take) -> Result<Take> {
    if take.meta.axes.is_some() {
        return Ok(take);
    }
    let axes = derive_stored(store, &take, Given::default()).await?;
    take.meta.axes = Some(axes);
    if !take.is_live() {
        let row = take.to_row()?;
        // Lost to a re-encode meanwhile: the next read derives them again.
        if store
            .set_meta(&take.id, &row.meta, &row.codec, row.totals.stored_bytes)
            .await?
        {
            take.body_rev += 1;
        }
    }
    Ok(take)
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
    let before = take.meta.axes.clone();
    let kept = |pick: fn(&Axes) -> (Option<Axis>, Option<Source>)| {
        before
            .as_ref()
            .map(pick)
            .and_then(|(a, from)| a.filter(|_| from == Some(Source::Given)))
    };
    let given = Given {
        up: c.up.or_else(|| kept(|a| (a.up, a.up_from))),
        forward: c.forward.or_else(|| kept(|a| (a.forward, a.forward_from))),
    };
    given
        .check()
        .map_err(|e| Error::InvalidRequest(format!("body: {e}")))?;
    take.meta.roles_given.extend(c.roles);
    take.roles = std::mem::take(&mut take.roles).with_given(&take.meta.roles_given);
    take.meta.axes = Some(derive_stored(store, &take, given).await?);
    let row = take.to_row()?;
    if !store
        .set_meta(&take.id, &row.meta, &row.codec, row.totals.stored_bytes)
        .await?
    {
        return Err(Error::Conflict(format!(
            "take {id} was re-encoded or deleted while its body was corrected; send it again"
        )));
    }
    take.body_rev += 1;
    Ok(take)
}

/// What the take's source format says of up, as ingest would have read it (a C3D's from
/// its stored parameters).
async fn prior(store: &Store, take: &Take) -> Result<Option<Prior>> {
    let Ok(format) = take.source_format.parse::<Format>() else {
        return Ok(None);
    };
    let params = match format {
        Format::C3d => analog::parameters(store, &take.id).await?,
        _ => None,
    };
    Ok(up_prior(format, params.as_ref()))
}

/// The axes of a stored take, from up to [`SAMPLED_CHUNKS`] of its chunks decoded.
async fn derive_stored(store: &Store, take: &Take, given: Given) -> Result<Axes> {
    let prior = prior(store, take).await?;
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
        let m = Motion::new(
            take.fps,
            take.meta.unit.clone(),
            take.meta.point_names.clone(),
            positions,
            None,
        )?;
        derive(&m, &take.roles, given, prior.as_ref()).map_err(Error::InvalidRequest)
    })
    .await?
}
