//! Decoders kept ready per take. Building one parses the header and, for MDTT, range-decodes
//! the basis and tabulates the DCT — more work than decoding a one-second range — and a
//! stored take's bitstream never changes, so the server keeps the last few hundred.

use std::collections::{HashMap, VecDeque};
use std::sync::{Arc, Mutex};

use crate::codec::container::Header;
use crate::codec::{self, ChunkDecoder, Limits};
use crate::store::SequenceRow;

/// What range requests of one take need, ready to use.
pub struct Prepared {
    pub id: String,
    pub header: Header,
    pub decoder: Box<dyn ChunkDecoder>,
    pub point_names: Vec<String>,
    pub fps: f64,
    pub metres_per_unit: f64,
    pub frames: usize,
}

impl Prepared {
    pub fn new(row: &SequenceRow) -> Result<Prepared, String> {
        let (header, _) =
            Header::parse(&row.header, &Limits::default()).map_err(|e| e.to_string())?;
        let decoder = codec::codec(header.codec)
            .and_then(|c| c.decoder(&header.params, header.points as usize))
            .map_err(|e| e.to_string())?;
        Ok(Prepared {
            id: row.id.clone(),
            header,
            decoder,
            point_names: super::fetch::point_names(row),
            fps: row.fps,
            metres_per_unit: row.metres_per_unit,
            frames: row.frames as usize,
        })
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

impl Default for DecoderCache {
    fn default() -> Self {
        DecoderCache::new(256)
    }
}
