//! Watchers of an open stream (the viewer's live page): every append as it arrives, before
//! it is coded, through a bounded broadcast. One that reads too slowly skips appends (and is
//! told), so watching never holds the producer nor grows memory.

use std::sync::Arc;

use tokio::sync::{broadcast, watch};

use super::{Live, StreamInfo, Streams};
use crate::limits::{STREAM_WATCHERS, STREAM_WATCH_SAMPLES};
use crate::service::budget::{Holder, Share};
use crate::service::{now_ms, Error, Result};
use crate::store::Store;

/// Frames as they arrived at an open stream, for its watchers: the newest frames of one
/// append (at most [`STREAM_WATCH_SAMPLES`] samples), as sent, before they are coded.
#[derive(Debug, Clone)]
pub struct Arrival {
    /// The index in the take of the first frame here.
    pub first: usize,
    pub frames: usize,
    /// When this server took the append (ms since the Unix epoch, server clock).
    pub received_ms: i64,
    /// When the producer captured the append's last frame, if it said (`captured_ms`,
    /// producer clock).
    pub captured_ms: Option<i64>,
    /// `frames × points × 3`, stored units, NaN where a sample is missing.
    pub positions: Vec<f32>,
}

/// A watcher of an open stream: its state now, its newest frame (so there is something
/// to show at once), and every append from here on.
pub struct Watch {
    pub info: StreamInfo,
    pub latest: Option<Arc<Arrival>>,
    pub arrivals: broadcast::Receiver<Arc<Arrival>>,
    /// Turns true when the server shuts down: watchers end then, not hold it open.
    pub stopping: watch::Receiver<bool>,
    /// This watcher's place among its caller's watchers of the stream.
    _share: Share,
}

impl Live {
    /// Pass an append on to the watchers (its newest frames) and keep its last frame.
    pub(super) fn show_watchers(&mut self, first: usize, frames: &[f32], captured_ms: Option<i64>) {
        let w = self.take.points * 3;
        let n = frames.len() / w;
        if n == 0 {
            return;
        }
        let received_ms = now_ms();
        let newest = |k: usize| {
            Arc::new(Arrival {
                first: first + n - k,
                frames: k,
                received_ms,
                captured_ms,
                positions: frames[(n - k) * w..].to_vec(),
            })
        };
        let latest = newest(1);
        if self.watchers.receiver_count() > 0 {
            let kept = n.min((STREAM_WATCH_SAMPLES / self.take.points).max(1));
            let arrival = if kept == 1 {
                latest.clone()
            } else {
                newest(kept)
            };
            // Fails only when every watcher has gone since the count: nothing to do.
            let _ = self.watchers.send(arrival);
        }
        self.latest = Some(latest);
    }
}

impl Streams {
    /// Watch an open stream for `holder`: every append from now on, as it arrives. At most
    /// [`STREAM_WATCHERS`] at once per stream, [`crate::limits::Limits::watchers_per_caller`] of them one
    /// caller's; the watch ends when the stream closes.
    pub async fn watch(&self, store: &Store, id: &str, holder: &Holder) -> Result<Watch> {
        let Some(entry) = self.entry(id) else {
            return Err(Self::not_open(store, id).await);
        };
        let live = entry.lock().await;
        if live.watchers.receiver_count() >= STREAM_WATCHERS {
            return Err(Error::Busy(format!(
                "stream {id} has {STREAM_WATCHERS} watchers, the most it takes at once"
            )));
        }
        let share = live.watchers_by.take(holder).ok_or_else(|| {
            Error::Busy(format!(
                "this caller watches stream {id} {} times, the most one caller may",
                live.watchers_by.most()
            ))
        })?;
        Ok(Watch {
            info: live.info(),
            latest: live.latest.clone(),
            arrivals: live.watchers.subscribe(),
            stopping: self.stopping.subscribe(),
            _share: share,
        })
    }

    /// End every watch: the server is shutting down, and open watches would hold it.
    pub fn stop_watchers(&self) {
        self.stopping.send_replace(true);
    }

    /// Turns true when the server shuts down ([`Streams::stop_watchers`]): what a watch
    /// forwarded to another server ends on.
    pub fn stopping(&self) -> watch::Receiver<bool> {
        self.stopping.subscribe()
    }
}
