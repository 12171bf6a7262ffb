//! The open streams of this server and their leases: a place per stream among the
//! server's and its caller's, the lease each live take's row holds (renewed by every commit
//! and by [`Streams::maintain`]), and the closing of takes whose server stopped
//! ([`Streams::close_orphans`]).

use std::collections::HashMap;
use std::sync::{Arc, Mutex};
use std::time::Duration;

use tokio::sync::{watch, OwnedSemaphorePermit, Semaphore};

use super::{Entry, Live};
use crate::limits::Limits;
use crate::service::budget::{Holder, Share, Shares};
use crate::service::{fetch, now_ms, Error, Node, Result};
use crate::store::{Closer, Store};

/// How long before the lease it last wrote runs out a server writes it again before it
/// takes more frames ([`Streams::append`]).
pub(super) const LEASE_MARGIN_MS: i64 = 1_000;

/// Whether `e` is the database being away (worth holding on and trying again), not a fault.
pub(super) fn unavailable(e: &Error) -> bool {
    matches!(e, Error::Store(s) if s.is_unavailable())
}

/// The open streams of this server.
pub struct Streams {
    pub(super) open: Mutex<HashMap<String, Entry>>,
    /// One permit per stream that may be open at once.
    pub(super) slots: Arc<Semaphore>,
    /// Streams open per caller ([`Limits::streams_per_caller`]).
    pub(super) by_caller: Shares,
    pub(super) limits: Limits,
    /// A stream with no request for this long is finished by [`Streams::maintain`].
    pub idle: Duration,
    /// How long a live take stays live without its server renewing it. Servers renew the
    /// leases of their open streams at every [`Streams::maintain`]; run that more often.
    pub lease: Duration,
    /// Set when the server shuts down ([`Streams::stop_watchers`]).
    pub(super) stopping: watch::Sender<bool>,
    /// This server, as stream rows name their owner.
    pub(super) node: Node,
    /// Held while a stream is taken over ([`handover`]).
    pub(super) taking_over: tokio::sync::Mutex<()>,
}

impl Streams {
    /// `limits.stream_points` is capped at [`crate::limits::LSDT_MAX_POINTS`]: a stream codes
    /// with an LSDT basis of its layout.
    pub fn new(mut limits: Limits, lease: Duration, node: Node) -> Self {
        limits.stream_points = limits
            .stream_points
            .min(crate::limits::LSDT_MAX_POINTS as u64);
        Streams {
            open: Mutex::new(HashMap::new()),
            slots: Arc::new(Semaphore::new(limits.open_streams as usize)),
            by_caller: Shares::new(limits.streams_per_caller as usize),
            limits,
            idle: Duration::from_secs(300),
            lease,
            stopping: watch::Sender::new(false),
            node,
            taking_over: tokio::sync::Mutex::new(()),
        }
    }

    /// Streams open on this server now.
    pub fn open_count(&self) -> usize {
        self.open.lock().expect("streams lock").len()
    }

    pub(super) fn lease_end(&self) -> i64 {
        now_ms() + self.lease.as_millis() as i64
    }

    pub(super) fn entry(&self, id: &str) -> Option<Entry> {
        self.open.lock().expect("streams lock").get(id).cloned()
    }

    /// A place among `holder`'s and the server's open streams, held until the stream
    /// closes (or moves to another server).
    pub(super) fn places(&self, holder: &Holder) -> Result<(OwnedSemaphorePermit, Share)> {
        let share = self.by_caller.take(holder).ok_or_else(|| {
            Error::Busy(format!(
                "this caller has {} streams open, the most one caller may have at once; \
                 finish one first",
                self.by_caller.most()
            ))
        })?;
        let slot = self.slots.clone().try_acquire_owned().map_err(|_| {
            Error::Busy(format!(
                "{} streams are open, the most this server takes at once; finish one or retry later",
                self.limits.open_streams
            ))
        })?;
        Ok((slot, share))
    }

    /// Drop a stream this server no longer codes (another server took it over): its
    /// requests go to the new owner from now on.
    pub(super) fn let_go(&self, id: &str) {
        if self.open.lock().expect("streams lock").remove(id).is_some() {
            tracing::warn!(stream = id, "another server took this stream over");
        }
    }

    /// Why a stream id is not open here: finished or coded elsewhere (409), or unknown (404).
    pub(super) async fn not_open(store: &Store, id: &str) -> Error {
        match store.get(id).await {
            Ok(Some(row)) => match row.live_until {
                None => Error::Conflict(format!("stream {id} is finished")),
                Some(until) => Error::Conflict(format!(
                    "stream {id} is not open on this server: another server codes it, or its \
                     server stopped and the take is closed when its lease runs out \
                     ({until} ms since the epoch)"
                )),
            },
            Ok(None) => Error::NotFound(format!("stream {id}")),
            Err(e) => e.into(),
        }
    }

    /// Write how many frames the producer has had accepted, renewing the lease:
    /// [`Error::Moved`] if another server took the stream over meanwhile.
    pub(super) async fn note_received(&self, store: &Store, live: &mut Live) -> Result<()> {
        let received = live.received;
        let until = self.lease_end();
        if !store
            .note_received(&live.take.id, &self.node.id, received as i64, until)
            .await?
        {
            return Err(Self::lost(&live.take.id));
        }
        live.persisted = received;
        live.lease_until = until;
        Ok(())
    }

    /// Why this server may no longer write a stream's take: another server took it over
    /// (or it was finished or deleted meanwhile); the same request sent again is routed to
    /// wherever it is now.
    pub(super) fn lost(id: &str) -> Error {
        Error::Moved(format!(
            "stream {id} is no longer coded by this server (another server took it over, or \
             it was finished or deleted); send the request again"
        ))
    }

    /// Housekeeping, run every few seconds by the server: renew the leases of this server's
    /// open streams, finish those idle longer than [`Streams::idle`], and close the takes of
    /// streams whose server died ([`Streams::close_orphans`]).
    pub async fn maintain(&self, store: &Store) {
        let entries: Vec<(String, Entry)> = self
            .open
            .lock()
            .expect("streams lock")
            .iter()
            .map(|(k, v)| (k.clone(), v.clone()))
            .collect();
        // Leases first: finishing an idle stream may take a while (re-encoding), and must
        // not let the others' leases run out.
        let mut idle = Vec::new();
        for (id, e) in entries {
            // A stream busy with a request renews its lease by committing.
            match e.try_lock() {
                Ok(l) if l.last_activity.elapsed() > self.idle => {
                    idle.push(id);
                    continue;
                }
                Ok(_) => {}
                Err(_) => continue,
            }
            let until = self.lease_end();
            match store.renew_lease(&id, &self.node.id, until).await {
                Err(err) => {
                    tracing::warn!(stream = %id, error = %err, "renewing a stream's lease failed");
                    continue;
                }
                Ok(false) => {
                    self.let_go(&id);
                    continue;
                }
                Ok(true) => {}
            }
            if let Ok(mut live) = e.try_lock() {
                live.lease_until = until;
                // The database is back: store what a quiet stream held meanwhile.
                if !live.unsaved.is_empty() {
                    if let Err(err) = self.save(store, &mut live).await {
                        tracing::warn!(stream = %id, error = %err, "storing held chunks failed");
                    }
                }
            }
        }
        for id in idle {
            if let Err(err) = self.finish(store, &id).await {
                tracing::warn!(stream = %id, error = %err, "finishing an idle stream failed");
            }
        }
        if let Err(err) = self.close_orphans(store).await {
            tracing::warn!(error = %err, "closing orphaned live takes failed");
        }
    }

    /// Close every live take whose lease ran out a lease ago or more and that no stream
    /// here codes: its server stopped mid-stream, and no producer came back to go on
    /// through another server within that lease ([`super::handover`]). What it committed stays,
    /// indexed from its chunk rows; frames that were pending on that server are lost, and
    /// the take says so and how many.
    pub async fn close_orphans(&self, store: &Store) -> Result<usize> {
        let mut closed = 0;
        let before = now_ms() - self.lease.as_millis() as i64;
        for id in store.expired_live(before).await? {
            if self.entry(&id).is_some() {
                continue;
            }
            let take = match fetch::take(store, &id).await {
                Ok(t) => t,
                Err(Error::NotFound(_)) => continue,
                Err(e) => {
                    // One bad record must not keep the others open; `verify` reports it.
                    tracing::error!(stream = %id, error = %e, "an orphaned live take does not parse");
                    continue;
                }
            };
            let header = fetch::header_from_index(&take, &store.chunk_index(&id).await?)?;
            let received = store.stream(&id).await?.map_or(0, |s| s.frames_received);
            let mut meta = take.meta.clone();
            // Its body from all it committed, as a finish would have derived it (it has the
            // first chunk's until then).
            if take.frames > 0 {
                match super::super::body::closing(store, &take).await {
                    Ok(axes) => meta.axes = Some(axes),
                    Err(e) if unavailable(&e) => return Err(e),
                    Err(e) => {
                        tracing::warn!(stream = %id, error = %e, "an orphaned live take's body could not be derived");
                    }
                }
            }
            meta.frames_lost += (received - take.frames as i64).max(0) as usize;
            meta.interrupted = Some(
                "the server coding this stream stopped before it finished; the take keeps the \
                 chunks it had committed"
                    .into(),
            );
            let orphan = Closer::Orphan {
                before,
                frames: take.frames as i64,
            };
            if store
                .close_live(&id, &header.to_bytes(), &meta.to_record(&id)?, orphan)
                .await?
            {
                tracing::warn!(stream = %id, frames = take.frames, "closed a stream whose server stopped");
                closed += 1;
            }
        }
        Ok(closed)
    }
}
