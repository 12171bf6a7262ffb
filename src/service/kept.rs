//! A map bounded in bytes, the entry kept longest dropped first: what the server's caches
//! of decoded chunks ([`super::prepared::ChunkCache`]) and of per-take motion statistics
//! ([`super::motion_stats::MomentsCache`]) hold. Each entry's key names everything its
//! value was computed from, so an entry is never stale: one no longer asked for ages out.

use std::collections::{HashMap, VecDeque};
use std::hash::Hash;
use std::sync::Mutex;

pub struct Kept<K, V> {
    budget: usize,
    inner: Mutex<Entries<K, V>>,
}

struct Entries<K, V> {
    /// Each value with the bytes it counts for.
    map: HashMap<K, (V, usize)>,
    order: VecDeque<K>,
    bytes: usize,
}

impl<K: Eq + Hash + Clone, V: Clone> Kept<K, V> {
    /// An empty map that keeps at most `budget` bytes.
    pub fn new(budget: usize) -> Self {
        Kept {
            budget,
            inner: Mutex::new(Entries {
                map: HashMap::new(),
                order: VecDeque::new(),
                bytes: 0,
            }),
        }
    }

    pub fn get(&self, key: &K) -> Option<V> {
        let g = self.inner.lock().expect("cache lock");
        g.map.get(key).map(|(v, _)| v.clone())
    }

    /// Keep `value` under `key`, counted as `bytes` (a value over the whole budget is not
    /// kept); a key kept already gets the new value and keeps its place.
    pub fn insert(&self, key: K, value: V, bytes: usize) {
        if bytes > self.budget {
            return;
        }
        let mut g = self.inner.lock().expect("cache lock");
        match g.map.insert(key.clone(), (value, bytes)) {
            Some((_, old)) => g.bytes -= old,
            None => g.order.push_back(key),
        }
        g.bytes += bytes;
        while g.bytes > self.budget {
            let Some(old) = g.order.pop_front() else {
                break;
            };
            if let Some((_, size)) = g.map.remove(&old) {
                g.bytes -= size;
            }
        }
    }

    /// Bytes kept now.
    pub fn bytes(&self) -> usize {
        self.inner.lock().expect("cache lock").bytes
    }

    /// Entries kept now.
    pub fn len(&self) -> usize {
        self.inner.lock().expect("cache lock").map.len()
    }

    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_oldest_go_first_and_the_bytes_stay_within_the_budget() {
        let k: Kept<u32, u32> = Kept::new(100);
        k.insert(1, 10, 40);
        k.insert(2, 20, 40);
        k.insert(1, 11, 30); // replaced in place: still the oldest
        assert_eq!((k.bytes(), k.get(&1)), (70, Some(11)));
        k.insert(3, 30, 40); // 110 > 100: key 1 goes
        assert_eq!(
            (k.get(&1), k.get(&2), k.get(&3)),
            (None, Some(20), Some(30))
        );
        assert_eq!((k.bytes(), k.len()), (80, 2));
        k.insert(4, 40, 101); // over the whole budget: not kept, nothing evicted
        assert_eq!((k.get(&4), k.len()), (None, 2));
    }
}
