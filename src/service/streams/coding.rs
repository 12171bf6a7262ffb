//! Coding and committing: each chunk coded on the blocking pool, checked, and committed in
//! one transaction with the take's running totals (held in memory while the database is
//! away); the shared basis a stream codes with; a finished take coded again whole.

use std::sync::Arc;

use super::handover::Resumable;
use super::{Live, Streams};
use crate::codec::stream::StreamChunk;
use crate::codec::{self, Basis, CodecId, Latency};
use crate::motion::Motion;
use crate::service::bases::Provenance;
use crate::service::choose::{CodecRequest, Keep};
use crate::service::{bases, blocking, body, ingest, take, Error, Result};
use crate::store::{BasisRow, ChunkAppend, Store};

/// The shared basis a stream coded with `codec` codes with, if the codec uses one: the
/// newest of its kind trained for the layout, or else the codec's untrained basis (stored as
/// a basis too, so the take references what decodes it).
pub(super) async fn stream_basis(
    store: &Store,
    codec: CodecId,
    layout: &str,
    points: usize,
) -> Result<Option<Arc<Basis>>> {
    let Some(kind) = codec::codec(codec)?.basis_kind() else {
        return Ok(None);
    };
    if let Some(b) = bases::latest_for(store, layout)
        .await?
        .into_iter()
        .find(|b| b.kind() == kind)
    {
        return Ok(Some(b));
    }
    let (b, provenance) = blocking(move || codec::stream::untrained_basis(codec, points))
        .await?
        .ok_or_else(|| {
            Error::Unsatisfiable(format!(
                "{codec} streams code with a trained {kind} basis and none is trained for \
                     this layout; train one first"
            ))
        })?;
    if !store.basis_exists(&b.id()).await? {
        let m = &b.matrices()[0];
        store
            .insert_basis(&BasisRow {
                id: b.id(),
                kind: kind.name().into(),
                layout: layout.to_string(),
                points: points as i64,
                dims: format!("{}×{}×{}", b.matrices().len(), m.rows, m.cols),
                payload: b.bytes().to_vec(),
                provenance: Provenance {
                    algorithm: provenance.into(),
                    ..Provenance::default()
                }
                .to_value()?,
                // Dated at the epoch, so that any basis trained later is the layout's newest.
                created_at: 0,
                used_by: 0,
            })
            .await?;
    }
    Ok(Some(Arc::new(b)))
}

impl Streams {
    /// Store the chunks waiting for the database, in order; the first that cannot be stored
    /// (the database still away) stays first, and its error is returned.
    ///
    /// A chunk leaves the queue only once stored: a request dropped while it commits (its
    /// client gone) leaves it first in line, and storing it again is a no-op
    /// ([`Store::append_chunk`] stores a chunk once).
    pub(super) async fn save(&self, store: &Store, live: &mut Live) -> Result<()> {
        while let Some(chunk) = live.unsaved.front().cloned() {
            self.commit(store, live, &chunk).await?;
            live.unsaved.pop_front();
            live.encoder_mut()?.confirm(chunk)?;
        }
        Ok(())
    }

    /// Code `frames` on the blocking pool and commit every chunk they finish, in order.
    pub(super) async fn code_and_commit(
        &self,
        store: &Store,
        live: &mut Live,
        frames: Vec<f32>,
        flush: bool,
    ) -> Result<()> {
        let mut encoder = live.encoder.take().ok_or_else(super::encoder_missing)?;
        let (encoder, chunks) = blocking(move || {
            let chunks = encoder.push(&frames, flush);
            (encoder, chunks)
        })
        .await?;
        live.encoder = Some(encoder);
        live.unsaved.extend(chunks?);
        self.save(store, live).await
    }

    /// Commit one coded and checked chunk: one chunk row and the take's running totals,
    /// nothing that grows with the stream.
    pub(super) async fn commit(
        &self,
        store: &Store,
        live: &mut Live,
        chunk: &StreamChunk,
    ) -> Result<()> {
        let totals = live.encoder()?.totals_with(chunk);
        let mut take = live.take.clone();
        // The first commit after a chunk's worth of frames arrived gives the take its body,
        // for readers of the live take (a flushed first chunk of a few frames would tell
        // too little: a body's forward needs it to move).
        let w = take.points * 3;
        let meta = if take.meta.axes.is_none()
            && w > 0
            && live.opening.len() >= live.chunk_frames * w
        {
            let (t, opening) = (take.clone(), std::mem::take(&mut live.opening));
            match blocking(move || body::opening(&t, opening)).await? {
                Ok(axes) => {
                    take.meta.axes = Some(axes);
                    Some(take.meta.to_record(&take.id)?)
                }
                // Its finish derives it from what it committed.
                Err(e) => {
                    tracing::warn!(stream = %take.id, error = %e, "a live take's body could not be derived");
                    None
                }
            }
        } else {
            None
        };
        take.set_frames(totals.frames);
        take.set_measured(totals.stored_bytes, &totals.stats);
        let chunk_row = take::chunk_row(chunk.index, &chunk.meta, &chunk.payload);
        let state = Resumable {
            chunk_frames: live.chunk_frames,
            reencode_on_finish: live.archive.is_some(),
            errors: Some(chunk.running().clone()),
        }
        .to_text()?;
        let until = self.lease_end();
        let append = ChunkAppend {
            server: &self.node.id,
            live_until: until,
            frames_received: live.received as i64,
            state: &state,
            meta: meta.as_deref(),
        };
        if !store
            .append_chunk(&take.id, &take.totals(), &chunk_row, &append)
            .await?
        {
            return Err(Self::lost(&live.take.id));
        }
        live.take = take;
        live.persisted = live.received;
        live.lease_until = until;
        Ok(())
    }
}

/// Code a finished stream's take again, from the frames as sent, with every candidate
/// codec; keep the result if it is smaller than the live coding. Written over the record as
/// it is then, unless it was re-encoded meanwhile: a body corrected since the stream closed
/// stays.
pub(super) async fn reencode_take(store: &Store, id: &str, positions: Vec<f32>) -> Result<()> {
    let closed = match crate::service::fetch::take(store, id).await {
        Err(Error::NotFound(_)) => return Ok(()), // deleted since it closed
        r => r?,
    };
    let (unit, names) = (closed.meta.unit.clone(), closed.meta.point_names.clone());
    let motion = Arc::new(
        Motion::new(closed.fps, unit, names, positions, None)
            .map_err(|e| Error::Internal(e.to_string()))?,
    );
    let coding = ingest::Coding {
        codec: CodecRequest::Auto,
        bound: closed.bound,
        latency: Latency::Sequence,
        keep: Keep::default(),
        hints: Default::default(),
    };
    let (decision, enc) = ingest::encode_best(store, motion, &closed.layout, &coding, None).await?;
    if enc.stored_bytes as u64 >= closed.stored_bytes {
        return Ok(());
    }
    let basis = enc.container.header.basis.as_ref().map(codec::basis::hex);
    let chunks = take::chunk_rows(&enc.container);
    for _ in 0..REENCODE_ATTEMPTS {
        let now = match crate::service::fetch::take(store, id).await {
            Err(Error::NotFound(_)) => return Ok(()),
            r => r?,
        };
        if (now.codec, now.stored_bytes) != (closed.codec, closed.stored_bytes) {
            return Ok(()); // coded again elsewhere
        }
        let mut new = now;
        new.codec = decision.winner;
        new.set_measured(enc.stored_bytes, &enc.stats);
        new.header = enc.container.header.to_bytes();
        new.meta.decision = decision.clone();
        new.meta.decoded_blake3 = Some(enc.decoded_digest.clone());
        new.meta.reencoded_from = Some(closed.codec);
        if store
            .update_encoding(&new.to_row()?, &chunks, true, basis.as_deref())
            .await?
        {
            return Ok(());
        }
        // Its body was corrected as this wrote: written again over the corrected record.
    }
    tracing::warn!(
        take = id,
        "the body kept changing while the re-encoding was stored; the take stays as coded live"
    );
    Ok(())
}

/// How often a re-encoding is written again over a record whose body changed under it.
const REENCODE_ATTEMPTS: usize = 3;
