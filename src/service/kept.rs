//! A map bounded in bytes, the entry used least recently dropped first: what the server's
//! caches of decoded chunks ([`super::prepared::ChunkCache`]) and of per-take motion
//! statistics ([`super::motion_stats::MomentsCache`]) hold. Each entry's key names what its
//! value was computed from (a take's coding stamp among it), so a take changed since is
//! looked up under another key, and what is no longer asked for ages out.

use std::collections::{HashMap, VecDeque};
use std::hash::Hash;
use std::sync::Mutex;

pub struct Kept<K, V> {
    budget: usize,
    inner: Mutex<Entries<K, V>>,
}

struct Entries<K, V> {
    map: HashMap<K, Entry<V>>,
    /// Keys in the order they were last used, each with the use it records; a key used
    /// again is pushed again, and its older places are skipped (and now and then dropped).
    order: VecDeque<(K, u64)>,
    bytes: usize,
    uses: u64,
}

struct Entry<V> {
    value: V,
    /// The bytes it counts for, and its last use.
    bytes: usize,
    used: u64,
}

impl<K: Eq + Hash + Clone, V: Clone> Entries<K, V> {
    fn touch(&mut self, key: &K) -> Option<V> {
        self.uses += 1;
        let used = self.uses;
        let e = self.map.get_mut(key)?;
        e.used = used;
        let value = e.value.clone();
        self.order.push_back((key.clone(), used));
        if self.order.len() > 2 * self.map.len() + 64 {
            let map = &self.map;
            self.order
                .retain(|(k, u)| map.get(k).is_some_and(|e| e.used == *u));
        }
        Some(value)
    }
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
                uses: 0,
            }),
        }
    }

    /// The value kept under `key` (now its most recent use).
    pub fn get(&self, key: &K) -> Option<V> {
        self.inner.lock().expect("cache lock").touch(key)
    }

    /// Keep `value` under `key`, counted as `bytes` (a value over the whole budget is not
    /// kept), dropping the least recently used entries past the budget.
    pub fn insert(&self, key: K, value: V, bytes: usize) {
        if bytes > self.budget {
            return;
        }
        let mut g = self.inner.lock().expect("cache lock");
        g.uses += 1;
        let used = g.uses;
        if let Some(old) = g.map.insert(key.clone(), Entry { value, bytes, used }) {
            g.bytes -= old.bytes;
        }
        g.order.push_back((key, used));
        g.bytes += bytes;
        while g.bytes > self.budget {
            let Some((old, at)) = g.order.pop_front() else {
                break;
            };
            if g.map.get(&old).is_some_and(|e| e.used == at) {
                if let Some(e) = g.map.remove(&old) {
                    g.bytes -= e.bytes;
                }
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
    fn the_least_recently_used_go_first_and_the_bytes_stay_within_the_budget() {
        let k: Kept<u32, u32> = Kept::new(100);
        k.insert(1, 10, 40);
        k.insert(2, 20, 40);
        k.insert(1, 11, 30); // replaced: now the most recent
        assert_eq!((k.bytes(), k.get(&1)), (70, Some(11)));
        k.insert(3, 30, 40); // 110 > 100: key 2, used least recently, goes
        assert_eq!(
            (k.get(&2), k.get(&1), k.get(&3)),
            (None, Some(11), Some(30))
        );
        assert_eq!((k.bytes(), k.len()), (70, 2));
        k.get(&1); // 3 is now the least recently used
        k.insert(4, 40, 40);
        assert_eq!(
            (k.get(&3), k.get(&1), k.get(&4)),
            (None, Some(11), Some(40))
        );
        k.insert(5, 50, 101); // over the whole budget: not kept, nothing dropped
        assert_eq!((k.get(&5), k.len()), (None, 2));
        // Many uses of one key keep the order's length bounded.
        for _ in 0..1000 {
            k.get(&1);
        }
        assert!(k.inner.lock().unwrap().order.len() <= 2 * 2 + 64 + 1);
    }
}
