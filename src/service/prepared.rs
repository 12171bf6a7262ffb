//! What the server keeps ready between range requests:
//! - a decoder per take ([`DecoderCache`]): building one parses the header and, for MDTT,
//!   range-decodes the basis and tabulates the DCT — more work than decoding a second;
//! - decoded chunks ([`ChunkCache`], bounded in bytes): a one-second request decodes up to
//!   two whole chunks, so hot ranges are served from memory.
//!
//! Nobody has to tell the caches that a take changed. A cached decoder carries the
//! [`Stamp`] of the coding it was built from, and [`ReadCaches::current`] checks it against
//! the stored one before each use (one indexed lookup, batched with those of concurrent
//! requests: [`super::stamps`]): a take re-encoded or deleted since,
//! here or through another server sharing the database, is built again or answered 404.
//! Decoded chunks are keyed by the take, its coding's stamp (a corrected body decodes the same
//! chunks) and the chunk, so chunks of an older
//! coding (or of a live take before its last commit) are never read again; those age out.

use std::collections::{HashMap, VecDeque};
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, Mutex};

use super::kept::Kept;
use super::stamps::Stamps;
use super::take::Take;
use crate::codec::container::Header;
use crate::codec::{CodecId, Reader, Shared};
use crate::store::{StampRow, Store};

/// What tells one coding of a take from another: a re-encode keeps its result only if
/// smaller, so it changes `stored_bytes`; a live take grows its `frames` (and is never
/// cached meanwhile); a body derived or corrected after storing bumps `body_rev`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct Stamp {
    codec: CodecId,
    stored_bytes: u64,
    frames: usize,
    /// The body's revision: a corrected body changes the stance transforms read.
    body_rev: u64,
}

impl Stamp {
    pub fn of(take: &Take) -> Stamp {
        Stamp {
            codec: take.codec,
            stored_bytes: take.stored_bytes,
            frames: take.frames,
            body_rev: take.body_rev,
        }
    }

    /// The stamp as the take's row holds it.
    pub fn row(self) -> StampRow {
        StampRow {
            codec: self.codec.to_string(),
            stored_bytes: self.stored_bytes as i64,
            frames: self.frames as i64,
            body_rev: self.body_rev as i64,
        }
    }

    /// The stamp of the coding alone: a body corrected changes what transforms read, not
    /// the chunks decoded.
    fn coding(self) -> Stamp {
        Stamp {
            body_rev: 0,
            ..self
        }
    }

    /// A stored stamp: a codec id that does not parse, or a negative count, is a corrupt
    /// record.
    fn parse(id: &str, row: StampRow) -> super::Result<Stamp> {
        let corrupt = |what: &str, v: i64| super::Error::Corrupt(format!("take {id}: {what} {v}"));
        let codec = row
            .codec
            .parse()
            .map_err(|e| super::Error::Corrupt(format!("take {id}: codec: {e}")))?;
        Ok(Stamp {
            codec,
            stored_bytes: u64::try_from(row.stored_bytes)
                .map_err(|_| corrupt("stored_bytes", row.stored_bytes))?,
            frames: usize::try_from(row.frames).map_err(|_| corrupt("frames", row.frames))?,
            body_rev: u64::try_from(row.body_rev).map_err(|_| corrupt("body_rev", row.body_rev))?,
        })
    }
}

/// Each [`Prepared`] built in this process gets its own number.
static GENERATIONS: AtomicU64 = AtomicU64::new(0);

/// What range requests of one take need, ready to use.
pub struct Prepared {
    pub id: String,
    /// The coding this was built from.
    pub stamp: Stamp,
    /// Unique to this [`Prepared`] within the process: which of two decoders of a take a
    /// cache entry is.
    pub generation: u64,
    pub reader: Reader,
    /// Shared with every answer that writes them: a binary answer of every point (f32, NPY)
    /// copies none.
    pub point_names: Arc<[String]>,
    pub fps: f64,
    pub metres_per_unit: f64,
    pub frames: usize,
    /// Whether the take has a skeleton (a BVH take), whatever its codec keeps.
    pub skeleton: bool,
    /// What a file written of it names (glTF's extras): the take's name and bound.
    pub name: String,
    pub bound: crate::codec::ErrorBound,
    /// What transforms need of the take's body: up, the pelvis, the floor.
    pub stance: crate::motion::transform::Stance,
    /// The take's body (its roles: what retargeting maps); `None` until derived.
    pub body: Option<crate::motion::body::Body>,
}

impl Prepared {
    /// `shared` holds what the header names (a basis, a skeleton).
    pub fn new(take: &Take, header: Header, shared: Shared) -> super::Result<Prepared> {
        let reader = Reader::new(header, shared)
            .map_err(|e| super::Error::Corrupt(format!("stored take {}: {e}", take.id)))?;
        Ok(Prepared {
            id: take.id.clone(),
            stamp: Stamp::of(take),
            generation: GENERATIONS.fetch_add(1, Ordering::Relaxed),
            reader,
            point_names: take.meta.point_names.as_slice().into(),
            fps: take.fps,
            metres_per_unit: take.metres_per_unit,
            frames: take.frames,
            skeleton: take.skeleton.is_some(),
            name: take.name.clone(),
            bound: take.bound,
            stance: match take.body() {
                Some(b) => crate::motion::transform::Stance::of(
                    &b,
                    &take.meta.point_names,
                    take.metres_per_unit,
                ),
                None => crate::motion::transform::Stance::default(),
            },
            body: take.body(),
        })
    }

    /// The indices of the named points, or a 400 naming the first that is not in the take
    /// and the take's points (the first [`LISTED`] of them), so the caller can fix the name.
    pub fn point_indices(&self, names: &[String]) -> super::Result<Vec<usize>> {
        names
            .iter()
            .map(|w| {
                self.point_names.iter().position(|n| n == w).ok_or_else(|| {
                    let shown: Vec<&str> = self
                        .point_names
                        .iter()
                        .take(LISTED)
                        .map(String::as_str)
                        .collect();
                    let more = match self.point_names.len().saturating_sub(LISTED) {
                        0 => String::new(),
                        n => format!(" and {n} more (GET /v1/takes/ID lists them all)"),
                    };
                    super::Error::InvalidRequest(format!(
                        "no point named {w:?} in this take; its {} points are {}{more}",
                        self.point_names.len(),
                        shown.join(", ")
                    ))
                })
            })
            .collect()
    }
}

/// How many of a take's point names an error lists.
const LISTED: usize = 20;

/// Entries by id, and ids in insertion order (for eviction).
type Entries = (HashMap<String, Arc<Prepared>>, VecDeque<String>);

/// A bounded map from take id to [`Prepared`], oldest entry evicted first.
pub struct DecoderCache {
    capacity: usize,
    inner: Mutex<Entries>,
}

impl DecoderCache {
    pub fn new(capacity: usize) -> Self {
        DecoderCache {
            capacity: capacity.max(1),
            inner: Mutex::new((HashMap::new(), VecDeque::new())),
        }
    }

    pub fn get(&self, id: &str) -> Option<Arc<Prepared>> {
        self.inner.lock().expect("cache lock").0.get(id).cloned()
    }

    pub fn insert(&self, p: Arc<Prepared>) {
        let mut g = self.inner.lock().expect("cache lock");
        let (map, order) = &mut *g;
        if map.insert(p.id.clone(), p.clone()).is_none() {
            order.push_back(p.id.clone());
        }
        while map.len() > self.capacity {
            match order.pop_front() {
                Some(old) => {
                    map.remove(&old);
                }
                None => break,
            }
        }
    }

    pub fn remove(&self, id: &str) {
        let mut g = self.inner.lock().expect("cache lock");
        g.0.remove(id);
        g.1.retain(|k| k != id);
    }

    /// Remove `id`'s entry if it is still the decoder of `generation`.
    pub fn remove_if(&self, id: &str, generation: u64) {
        let mut g = self.inner.lock().expect("cache lock");
        if g.0.get(id).is_some_and(|p| p.generation == generation) {
            g.0.remove(id);
            g.1.retain(|k| k != id);
        }
    }
}

/// Both caches, as the read path uses them.
pub struct ReadCaches {
    pub decoders: DecoderCache,
    pub chunks: ChunkCache,
    /// How cached decoders are checked: stamp lookups, batched across requests.
    stamps: Stamps,
}

impl ReadCaches {
    /// Caches of the takes of one store (the one every call passes).
    pub fn new(decoded_chunk_bytes: usize) -> Self {
        ReadCaches {
            decoders: DecoderCache::default(),
            chunks: ChunkCache::new(decoded_chunk_bytes),
            stamps: Stamps::default(),
        }
    }

    /// The cached decoder of take `id` if it was built from the take's stored coding;
    /// `Ok(None)` (and the entry dropped) if there is none or it is stale, so the caller
    /// builds one; [`super::Error::NotFound`] if the take is gone.
    pub async fn current(&self, store: &Store, id: &str) -> super::Result<Option<Arc<Prepared>>> {
        let Some(p) = self.decoders.get(id) else {
            return Ok(None);
        };
        match self.stamps.of(store, id).await? {
            None => {
                self.decoders.remove_if(id, p.generation);
                Err(super::Error::NotFound(format!("take {id}")))
            }
            Some(row) => {
                if Stamp::parse(id, row)? == p.stamp {
                    return Ok(Some(p));
                }
                // Only this stale one: another request may have cached a fresh one since.
                self.decoders.remove_if(id, p.generation);
                Ok(None)
            }
        }
    }
}

/// Decoded chunks by (take, its coding's [`Stamp`], chunk index), bounded in bytes, the least
/// recently used dropped first.
pub struct ChunkCache {
    kept: Kept<ChunkKey, Arc<Vec<f32>>>,
}

/// A decoded chunk's key: the take, the coding it was decoded from, the chunk.
type ChunkKey = (String, Stamp, usize);

impl ChunkCache {
    pub fn new(budget_bytes: usize) -> Self {
        ChunkCache {
            kept: Kept::new(budget_bytes),
        }
    }

    /// Chunk `index` of the take `p` reads, as decoded from its coding now.
    pub fn get(&self, p: &Prepared, index: usize) -> Option<Arc<Vec<f32>>> {
        self.kept.get(&(p.id.clone(), p.stamp.coding(), index))
    }

    pub fn insert(&self, p: &Prepared, index: usize, frames: Arc<Vec<f32>>) {
        let size = frames.len() * 4;
        self.kept
            .insert((p.id.clone(), p.stamp.coding(), index), frames, size);
    }

    pub fn bytes(&self) -> usize {
        self.kept.bytes()
    }
}

/// Takes whose decoders a server keeps ready (the one cached first dropped first).
pub const DECODERS: usize = 256;

impl Default for DecoderCache {
    fn default() -> Self {
        DecoderCache::new(DECODERS)
    }
}

/// The take's reader (cached, or built and cached unless the take is live) and `range`
/// resolved against it; the range is checked before a reader is built.
pub(super) async fn prepare(
    store: &Store,
    caches: &ReadCaches,
    id: &str,
    range: super::fetch::TimeRange,
) -> super::Result<(Arc<Prepared>, (usize, usize))> {
    if let Some(p) = caches.current(store, id).await? {
        let r = range.resolve(p.frames, p.fps)?;
        return Ok((p, r));
    }
    let row = super::body::take(store, id).await?;
    let r = range.resolve(row.frames as usize, row.fps)?;
    let (header, live) = super::fetch::header_of(store, &row).await?;
    let shared = super::fetch::shared(store, &header).await?;
    let p = Arc::new(super::blocking(move || Prepared::new(&row, header, shared)).await??);
    // A live take's index grows with every commit (here or on another server).
    if !live {
        caches.decoders.insert(p.clone());
    }
    Ok((p, r))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::codec::{self, ErrorBound};
    use crate::motion::synthetic::walker;

    /// A short take, coded.
    fn encoded() -> codec::Encoded {
        codec::testing::encoded(
            &walker(20, 2, 30.0, 1, 0.0),
            CodecId::Quant,
            ErrorBound::max(1.0),
        )
    }

    fn prepared(id: &str) -> Arc<Prepared> {
        let enc = encoded();
        Arc::new(Prepared {
            id: id.into(),
            stamp: Stamp {
                codec: CodecId::Quant,
                stored_bytes: 1,
                frames: 20,
                body_rev: 0,
            },
            generation: 0,
            reader: Reader::new(enc.container.header, None).unwrap(),
            point_names: vec!["a".into(), "b".into()].into(),
            fps: 30.0,
            metres_per_unit: 0.001,
            frames: 20,
            skeleton: false,
            name: id.into(),
            bound: ErrorBound::max(1.0),
            stance: Default::default(),
            body: None,
        })
    }

    #[test]
    fn chunk_cache_stays_within_its_budget() {
        let c = ChunkCache::new(100);
        let (a, b, d) = (prepared("a"), prepared("b"), prepared("d"));
        c.insert(&a, 0, Arc::new(vec![0.0; 10])); // 40 bytes
        c.insert(&a, 1, Arc::new(vec![0.0; 10]));
        c.insert(&b, 0, Arc::new(vec![0.0; 10])); // 120 > 100: the oldest goes
        assert!(c.get(&a, 0).is_none() && c.get(&a, 1).is_some() && c.get(&b, 0).is_some());
        assert_eq!(c.bytes(), 80);
        c.insert(&d, 0, Arc::new(vec![0.0; 100])); // larger than the budget: not kept
        assert!(c.get(&d, 0).is_none());
        c.insert(&a, 1, Arc::new(vec![0.0; 5])); // replaced: counted once
        assert_eq!(c.bytes(), 60);
        // Another decoder of the same coding shares the chunks; another coding does not.
        assert!(c.get(&prepared("a"), 1).is_some());
        let mut recoded = prepared("a");
        Arc::get_mut(&mut recoded).unwrap().stamp.stored_bytes += 1;
        assert!(c.get(&recoded, 1).is_none());
    }

    #[test]
    fn evicts_the_oldest_and_forgets_removed() {
        let c = DecoderCache::new(2);
        c.insert(prepared("a"));
        c.insert(prepared("b"));
        c.insert(prepared("a")); // refresh, not a new entry
        c.insert(prepared("c"));
        assert!(c.get("a").is_none(), "oldest goes first");
        assert!(c.get("b").is_some() && c.get("c").is_some());
        c.remove("b");
        assert!(c.get("b").is_none());
        c.insert(prepared("d"));
        assert!(c.get("c").is_some() && c.get("d").is_some());
    }

    /// A cached decoder is served only while the take is coded as when it was built: a
    /// re-encode (here or through another server) drops it, a delete answers 404, and no
    /// writer has to say so.
    #[tokio::test]
    async fn a_cached_decoder_is_checked_against_the_stored_coding() {
        let dir = std::env::temp_dir().join(format!("mocapstore-prepared-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join("stamp.db");
        let _ = std::fs::remove_file(&path);
        let store = Store::open(&format!("sqlite://{}", path.display()))
            .await
            .unwrap();
        let enc = encoded();
        let mut take = Take::sample();
        take.header = enc.container.header.to_bytes();
        let chunks = super::super::take::chunk_rows(&enc.container);
        store
            .insert(&crate::store::NewTake {
                row: take.to_row().unwrap(),
                chunks: chunks.clone(),
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
        let caches = ReadCaches::new(1 << 20);
        let built = |take: &Take| {
            Arc::new(Prepared::new(take, enc.container.header.clone(), Shared::default()).unwrap())
        };
        let p = built(&take);
        caches.decoders.insert(p.clone());
        let hit = caches.current(&store, &take.id).await.unwrap().unwrap();
        assert!(Arc::ptr_eq(&hit, &p));

        let mut recoded = take.clone();
        recoded.stored_bytes -= 1;
        let row = recoded.to_row().unwrap();
        assert!(store
            .update_encoding(&row, &chunks, true, None)
            .await
            .unwrap());
        assert!(caches.current(&store, &take.id).await.unwrap().is_none());
        assert!(
            caches.decoders.get(&take.id).is_none(),
            "the stale one is dropped"
        );
        let fresh = built(&recoded);
        assert_ne!(
            fresh.generation, p.generation,
            "its chunks are cached apart"
        );
        caches.decoders.insert(fresh);
        // A request that found the stale one late drops only that one.
        caches.decoders.remove_if(&take.id, p.generation);
        assert!(caches.current(&store, &take.id).await.unwrap().is_some());

        assert!(store.delete(&take.id).await.unwrap());
        assert!(matches!(
            caches.current(&store, &take.id).await,
            Err(super::super::Error::NotFound(_))
        ));
        store.close().await;
        let _ = std::fs::remove_dir_all(&dir);
    }
}
