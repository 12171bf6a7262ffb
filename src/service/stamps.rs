//! Stamp lookups batched across concurrent requests.
//!
//! Every range read checks its take's stored [`super::prepared::Stamp`] before it uses a
//! cached decoder, so that a take re-encoded, deleted or given a corrected body through any
//! server is never read stale. That is one indexed lookup; on SQLite it is also a round trip
//! to a connection's worker thread, which in a profile of one-second range reads cost more
//! than the rest of the request (docs/PROFILING.md).
//!
//! So lookups are batched. A request asks [`Stamps::of`]; if no lookup is running it runs at
//! once, alone; requests that ask while one runs wait for the next, which looks all of them
//! up in one query. Each is still answered by a lookup that began after it asked, so the
//! guarantee is the same as a query of its own; under load one query serves many requests.
//! A request that goes away meanwhile only drops its answer.

use std::collections::HashMap;
use std::sync::Mutex;

use tokio::sync::{mpsc, oneshot};

use super::Result;
use crate::store::{StampRow, Store, STAMPS_AT_ONCE};

/// What a waiting request is sent: its take's stamp (`None`: no such take), or `Err` when
/// its batch failed (it then asks alone, and gets its own error).
type Answer = std::result::Result<Option<StampRow>, ()>;

/// A request for one take's stamp.
struct Ask {
    id: String,
    answer: oneshot::Sender<Answer>,
}

/// The batching lookups of one store's stamps.
#[derive(Default)]
pub struct Stamps {
    /// The running batcher's queue; started on first use (on the runtime of the request
    /// that first asks), started again if that runtime has gone.
    queue: Mutex<Option<mpsc::UnboundedSender<Ask>>>,
}

impl Stamps {
    /// Take `id`'s stamp as stored now (`None` if there is no such take). `store` must be
    /// the same store at every call: the batcher keeps the first one.
    pub async fn of(&self, store: &Store, id: &str) -> Result<Option<StampRow>> {
        let (answer, wait) = oneshot::channel();
        let ask = Ask {
            id: id.to_string(),
            answer,
        };
        let sent = {
            let mut queue = self.queue.lock().expect("stamp queue lock");
            let tx = queue.get_or_insert_with(|| start(store.clone()));
            match tx.send(ask) {
                Ok(()) => true,
                Err(mpsc::error::SendError(ask)) => {
                    // The batcher's runtime ended (a test's): start one on this one.
                    let tx = start(store.clone());
                    let sent = tx.send(ask).is_ok();
                    *queue = Some(tx);
                    sent
                }
            }
        };
        if sent {
            if let Ok(Ok(stamp)) = wait.await {
                return Ok(stamp);
            }
        }
        Ok(store.coding_stamp(id).await?)
    }
}

/// A batcher over `store`: the sender its requests go to.
fn start(store: Store) -> mpsc::UnboundedSender<Ask> {
    let (tx, rx) = mpsc::unbounded_channel();
    tokio::spawn(batches(store, rx));
    tx
}

/// Answer requests a batch at a time: each batch is every request that came while the
/// one before was looked up (at most [`STAMPS_AT_ONCE`] takes' worth of queries).
async fn batches(store: Store, mut rx: mpsc::UnboundedReceiver<Ask>) {
    let mut batch = Vec::new();
    while rx.recv_many(&mut batch, 4 * STAMPS_AT_ONCE).await > 0 {
        let mut ids: Vec<&str> = batch.iter().map(|a| a.id.as_str()).collect();
        ids.sort_unstable();
        ids.dedup();
        let found: std::result::Result<HashMap<String, StampRow>, ()> = store
            .coding_stamps(&ids)
            .await
            .map(|rows| rows.into_iter().collect())
            .map_err(|_| ());
        for ask in batch.drain(..) {
            let answer = match &found {
                Ok(found) => Ok(found.get(&ask.id).cloned()),
                Err(()) => Err(()),
            };
            // A request that went away has dropped its receiver: nothing to do.
            let _ = ask.answer.send(answer);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::service::take::Take;

    /// Many requests at once, of several takes and one that does not exist: each gets its
    /// own take's stamp as stored when it asked, including a change made between two asks.
    #[tokio::test(flavor = "multi_thread", worker_threads = 2)]
    async fn concurrent_asks_each_get_their_own_takes_stamp() {
        let dir = std::env::temp_dir().join(format!("mocapstore-stamps-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join("s.db");
        let _ = std::fs::remove_file(&path);
        let store = Store::open(&format!("sqlite://{}", path.display()))
            .await
            .unwrap();
        let mut takes = Vec::new();
        for k in 0..5u64 {
            let mut take = Take::sample();
            take.id = format!("take-{k}");
            take.stored_bytes = 100 + k;
            store
                .insert(&crate::store::NewTake {
                    row: take.to_row().unwrap(),
                    chunks: Vec::new(),
                    basis: None,
                    skeleton: None,
                    errors: None,
                    analog: None,
                    parameters: None,
                    outputs: None,
                    stream: None,
                })
                .await
                .unwrap();
            takes.push(take);
        }
        let stamps = std::sync::Arc::new(Stamps::default());
        let mut asks = Vec::new();
        for n in 0..200 {
            let (stamps, store) = (stamps.clone(), store.clone());
            let id = if n % 7 == 6 {
                "no-such-take".to_string()
            } else {
                format!("take-{}", n % 5)
            };
            asks.push(tokio::spawn(async move {
                (id.clone(), stamps.of(&store, &id).await.unwrap())
            }));
        }
        for ask in asks {
            let (id, stamp) = ask.await.unwrap();
            match takes.iter().find(|t| t.id == id) {
                Some(t) => {
                    let stamp = stamp.expect("a stored take has a stamp");
                    assert_eq!(stamp.stored_bytes as u64, t.stored_bytes, "{id}");
                    assert_eq!(stamp.codec, t.codec.to_string(), "{id}");
                }
                None => assert!(stamp.is_none(), "{id}"),
            }
        }
        // Asked after a change, the answer is the change's.
        assert!(store.delete("take-3").await.unwrap());
        assert!(stamps.of(&store, "take-3").await.unwrap().is_none());
        store.close().await;
        let _ = std::fs::remove_dir_all(&dir);
    }
}
