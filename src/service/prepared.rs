//! What the server keeps ready between range requests. A stored take's bitstream never
//! changes, so both are safe to keep until the take is deleted:
//! - a decoder per take ([`DecoderCache`]): building one parses the header and, for MDTT,
//!   range-decodes the basis and tabulates the DCT — more work than decoding a second;
//! - decoded chunks ([`ChunkCache`], bounded in bytes): a one-second request decodes up to
//!   two whole chunks, so hot ranges are served from memory.

use std::collections::{HashMap, VecDeque};
use std::sync::{Arc, Mutex};

use super::take::Take;
use crate::codec::container::Header;
use crate::codec::{Reader, Shared};

/// What range requests of one take need, ready to use.
pub struct Prepared {
    pub id: String,
    pub reader: Reader,
    pub point_names: Vec<String>,
    pub fps: f64,
    pub metres_per_unit: f64,
    pub frames: usize,
    /// Whether the take has a skeleton (a BVH take), whatever its codec keeps.
    pub skeleton: bool,
    /// What a file written of it names (glTF's extras): the take's name and bound.
    pub name: String,
    pub bound: crate::codec::ErrorBound,
    /// The stored coordinates' up axis, where the take's record keeps it.
    pub up: Option<crate::motion::transform::Up>,
}

impl Prepared {
    /// `shared` holds what the header names (a basis, a skeleton).
    pub fn new(take: &Take, header: Header, shared: Shared) -> super::Result<Prepared> {
        let reader = Reader::new(header, shared)
            .map_err(|e| super::Error::Corrupt(format!("stored take {}: {e}", take.id)))?;
        Ok(Prepared {
            id: take.id.clone(),
            reader,
            point_names: take.meta.point_names.clone(),
            fps: take.fps,
            metres_per_unit: take.metres_per_unit,
            frames: take.frames,
            skeleton: take.skeleton.is_some(),
            name: take.name.clone(),
            bound: take.bound,
            up: take.meta.up,
        })
    }

    /// The indices of the named points, or a 400 naming the first that is not in the take.
    pub fn point_indices(&self, names: &[String]) -> super::Result<Vec<usize>> {
        names
            .iter()
            .map(|w| {
                self.point_names.iter().position(|n| n == w).ok_or_else(|| {
                    super::Error::InvalidRequest(format!("no point named {w:?} in this take"))
                })
            })
            .collect()
    }
}

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
}

/// Both caches, as the read path uses them.
pub struct ReadCaches {
    pub decoders: DecoderCache,
    pub chunks: ChunkCache,
}

impl ReadCaches {
    pub fn new(decoded_chunk_bytes: usize) -> Self {
        ReadCaches {
            decoders: DecoderCache::default(),
            chunks: ChunkCache::new(decoded_chunk_bytes),
        }
    }

    /// Forget a take (after it is deleted).
    pub fn forget(&self, id: &str) {
        self.decoders.remove(id);
        self.chunks.remove_take(id);
    }
}

/// Decoded chunks by (take, chunk index), bounded in bytes, oldest evicted first.
pub struct ChunkCache {
    budget: usize,
    inner: Mutex<ChunkEntries>,
}

#[derive(Default)]
struct ChunkEntries {
    map: HashMap<(String, usize), Arc<Vec<f32>>>,
    order: VecDeque<(String, usize)>,
    bytes: usize,
}

impl ChunkCache {
    pub fn new(budget_bytes: usize) -> Self {
        ChunkCache {
            budget: budget_bytes,
            inner: Mutex::new(ChunkEntries::default()),
        }
    }

    pub fn get(&self, id: &str, index: usize) -> Option<Arc<Vec<f32>>> {
        self.inner
            .lock()
            .expect("cache lock")
            .map
            .get(&(id.to_string(), index))
            .cloned()
    }

    pub fn insert(&self, id: &str, index: usize, frames: Arc<Vec<f32>>) {
        let size = frames.len() * 4;
        if size > self.budget {
            return;
        }
        let mut g = self.inner.lock().expect("cache lock");
        let key = (id.to_string(), index);
        if let Some(old) = g.map.insert(key.clone(), frames) {
            g.bytes -= old.len() * 4;
        } else {
            g.order.push_back(key);
        }
        g.bytes += size;
        while g.bytes > self.budget {
            let Some(old) = g.order.pop_front() else {
                break;
            };
            if let Some(v) = g.map.remove(&old) {
                g.bytes -= v.len() * 4;
            }
        }
    }

    pub fn remove_take(&self, id: &str) {
        let mut g = self.inner.lock().expect("cache lock");
        let ChunkEntries { map, order, bytes } = &mut *g;
        map.retain(|(k, _), v| {
            let keep = k != id;
            if !keep {
                *bytes -= v.len() * 4;
            }
            keep
        });
        order.retain(|(k, _)| k != id);
    }

    pub fn bytes(&self) -> usize {
        self.inner.lock().expect("cache lock").bytes
    }
}

/// Takes whose decoders a server keeps ready (least recently used dropped first).
pub const DECODERS: usize = 256;

impl Default for DecoderCache {
    fn default() -> Self {
        DecoderCache::new(DECODERS)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::codec::{self, CodecId, ErrorBound};
    use crate::motion::synthetic::walker;

    fn prepared(id: &str) -> Arc<Prepared> {
        let enc = codec::encode(
            &walker(20, 2, 30.0, 1, 0.0),
            CodecId::Quant,
            ErrorBound::max(1.0),
        )
        .unwrap();
        Arc::new(Prepared {
            id: id.into(),
            reader: Reader::new(enc.container.header, None).unwrap(),
            point_names: vec!["a".into(), "b".into()],
            fps: 30.0,
            metres_per_unit: 0.001,
            frames: 20,
            skeleton: false,
            name: id.into(),
            bound: ErrorBound::max(1.0),
            up: None,
        })
    }

    #[test]
    fn chunk_cache_stays_within_its_budget() {
        let c = ChunkCache::new(100);
        c.insert("a", 0, Arc::new(vec![0.0; 10])); // 40 bytes
        c.insert("a", 1, Arc::new(vec![0.0; 10]));
        c.insert("b", 0, Arc::new(vec![0.0; 10])); // 120 > 100: the oldest goes
        assert!(c.get("a", 0).is_none() && c.get("a", 1).is_some() && c.get("b", 0).is_some());
        assert_eq!(c.bytes(), 80);
        c.insert("c", 0, Arc::new(vec![0.0; 100])); // larger than the budget: not kept
        assert!(c.get("c", 0).is_none());
        c.remove_take("a");
        assert!(c.get("a", 1).is_none());
        assert_eq!(c.bytes(), 40);
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
}
