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
use crate::motion::body::{derive, Axes, Given, Prior};
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
    let axes = derive_stored(store, &take).await?;
    take.meta.axes = Some(axes);
    if !take.is_live() {
        let row = take.to_row()?;
        // Lost to a re-encode meanwhile: the next read derives them again.
        store
            .set_meta(&take.id, &row.meta, &row.codec, row.totals.stored_bytes)
            .await?;
    }
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
async fn derive_stored(store: &Store, take: &Take) -> Result<Axes> {
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
        derive(&m, &take.roles, Given::default(), prior.as_ref()).map_err(Error::Internal)
    })
    .await?
}
