//! Approximate search by motion: which takes hold windows near a query's, found in a
//! navigable small-world graph (HNSW, the `hnsw_rs` crate) over every window of every take
//! instead of by scoring every take. What it finds are candidates only: search scores them
//! exactly ([`super::similar`]), so a result's score is the same found either way, and what
//! approximation can cost is a take it did not propose (its recall, which
//! `mocapstore bench --search` measures against exact search).
//!
//! # What is in the graph
//! Full bodies only: takes that place the pelvis and every key role, whose descriptors are
//! compared on all their numbers, as the graph's plain Euclidean distance compares them.
//! A take of fewer roles is compared on the roles it shares with the query, which no one
//! distance in a graph can give: search scores those exactly beside the candidates.
//!
//! # The same graph for the same takes
//! Points go in one at a time in the order given, and the crate's level generator is
//! seeded: the same takes in the same order make the same graph, on every server.

use std::collections::HashMap;

use hnsw_rs::prelude::{DistL2, Hnsw};

use super::similar::Descriptor;

/// Links a point keeps per layer (the paper's M): 16 is the usual choice for vectors of
/// about a hundred numbers.
const LINKS: usize = 16;
/// Neighbours considered while points go in: recall at search depends on it more than on
/// anything else, and build time grows with it.
const EF_BUILD: usize = 100;
/// Layers at most (the crate's own cap).
const LAYERS: usize = 16;

/// How deep a search looks.
#[derive(Debug, Clone, Copy)]
pub struct Depth {
    /// Query windows looked up at most (spread evenly over the query).
    pub query_windows: usize,
    /// Nearest windows asked for each.
    pub per_window: usize,
    /// The search's beam in the lowest layer (≥ `per_window`).
    pub ef: usize,
    /// The widest beam a search may deepen to: each window's search costs about as many
    /// distances as its beam, and with a filter the crate walks on until the beam is full.
    pub max_ef: usize,
}

impl Default for Depth {
    fn default() -> Self {
        Depth {
            query_windows: 16,
            per_window: 48,
            ef: 96,
            max_ef: 4_096,
        }
    }
}

/// The windows of a set of takes, each take known by its key `K`.
pub struct Graph<K> {
    hnsw: Hnsw<'static, f32, DistL2>,
    /// The take (its place in `keys`) of each point.
    take_of: Vec<u32>,
    keys: Vec<K>,
    slots: HashMap<K, usize>,
}

impl<K: Clone + Eq + std::hash::Hash> Graph<K> {
    /// The graph of `takes`' windows, put in take by take, window by window, in the order
    /// given.
    pub fn build(takes: &[(K, &[Descriptor])]) -> Graph<K> {
        let points: usize = takes.iter().map(|(_, w)| w.len()).sum();
        // The crate's defaults otherwise: keeping pruned links (to fill each list up to
        // LINKS) was measured on Bandai x10 and took recall@10 from 0.995 to 0.57, the
        // extra long links leading the greedy walk astray.
        let hnsw = Hnsw::new(LINKS, points.max(1), LAYERS, EF_BUILD, DistL2 {});
        let mut take_of = Vec::with_capacity(points);
        let mut keys = Vec::with_capacity(takes.len());
        let mut slots = HashMap::with_capacity(takes.len());
        for (slot, (key, windows)) in takes.iter().enumerate() {
            for w in windows.iter() {
                hnsw.insert_slice((w.as_slice(), take_of.len()));
                take_of.push(slot as u32);
            }
            keys.push(key.clone());
            slots.insert(key.clone(), slot);
        }
        Graph {
            hnsw,
            take_of,
            keys,
            slots,
        }
    }

    /// Windows in the graph.
    pub fn windows(&self) -> usize {
        self.take_of.len()
    }

    /// Takes in the graph.
    pub fn takes(&self) -> usize {
        self.keys.len()
    }

    /// Where take `key` is in the graph, if it is.
    pub fn slot(&self, key: &K) -> Option<usize> {
        self.slots.get(key).copied()
    }

    pub fn key(&self, slot: usize) -> &K {
        &self.keys[slot]
    }

    /// Bytes the graph holds, about: each point's numbers and links (the crate keeps a
    /// point's links as shared pointers, about 40 bytes each, and a list per layer).
    pub fn bytes(&self) -> usize {
        self.windows() * (std::mem::size_of::<Descriptor>() + 2 * LINKS * 40 + LAYERS * 24 + 64)
            + self.keys.len() * 128
    }

    /// The takes (their slots) with a window nearest `query`'s, nearest first, at most
    /// `most`, among those `allowed` accepts (the graph's walk passes through others but
    /// never answers them). Looks deeper (four times the neighbours a window, while the
    /// beam stays within `depth.max_ef` and short of every point) while it has found fewer
    /// than `wanted` takes: a query whose nearest windows all lie in a few takes gets more
    /// takes. It may still find fewer: the caller decides what to score then.
    pub fn nearest_takes(
        &self,
        query: &[Descriptor],
        allowed: &dyn Fn(usize) -> bool,
        depth: Depth,
        wanted: usize,
        most: usize,
    ) -> Vec<(usize, f32)> {
        let mut depth = depth;
        loop {
            let found = self.nearest_at(query, allowed, depth);
            let deepest = depth.per_window >= self.windows() || depth.ef * 4 > depth.max_ef;
            if found.len() >= wanted || deepest {
                let mut out: Vec<(usize, f32)> = found.into_iter().collect();
                out.sort_by(|a, b| a.1.total_cmp(&b.1).then(a.0.cmp(&b.0)));
                out.truncate(most);
                return out;
            }
            depth.per_window *= 4;
            depth.ef *= 4;
        }
    }

    /// Each take's nearest window to any of `query`'s looked up at `depth`.
    fn nearest_at(
        &self,
        query: &[Descriptor],
        allowed: &dyn Fn(usize) -> bool,
        depth: Depth,
    ) -> HashMap<usize, f32> {
        let mut best: HashMap<usize, f32> = HashMap::new();
        let asked = depth.query_windows.clamp(1, query.len().max(1));
        let filter = |id: &usize| allowed(self.take_of[*id] as usize);
        for i in 0..asked.min(query.len()) {
            // Spread over the query: its first and last windows and evenly between.
            let q = if asked == 1 {
                query.len() / 2
            } else {
                i * (query.len() - 1) / (asked - 1)
            };
            let found = self.hnsw.search_filter(
                &query[q],
                depth.per_window,
                depth.ef.max(depth.per_window),
                Some(&filter),
            );
            for n in found {
                let slot = self.take_of[n.d_id] as usize;
                let d = best.entry(slot).or_insert(f32::INFINITY);
                *d = d.min(n.distance);
            }
        }
        best
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::motion::features::DIMS;
    use crate::rng::Rng;

    /// `n` takes of `windows` random windows each, take `t`'s around its own centre.
    fn takes(n: usize, windows: usize, seed: u64) -> Vec<Vec<Descriptor>> {
        let mut rng = Rng::new(seed);
        (0..n)
            .map(|_| {
                let centre: Vec<f32> = (0..DIMS).map(|_| rng.unit() as f32 * 10.0).collect();
                (0..windows)
                    .map(|_| {
                        let mut d = [0f32; DIMS];
                        for (x, c) in d.iter_mut().zip(&centre) {
                            *x = c + rng.unit() as f32 * 0.5;
                        }
                        d
                    })
                    .collect()
            })
            .collect()
    }

    #[test]
    fn a_take_s_own_windows_find_it_first() {
        let all = takes(60, 20, 7);
        let list: Vec<(usize, &[Descriptor])> =
            all.iter().enumerate().map(|(i, w)| (i, &w[..])).collect();
        let g = Graph::build(&list);
        assert_eq!(g.windows(), 1200);
        assert_eq!(g.takes(), 60);
        for (i, w) in all.iter().enumerate() {
            let found = g.nearest_takes(&w[3..6], &|_| true, Depth::default(), 1, 5);
            assert_eq!(g.key(found[0].0), &i, "{found:?}");
            assert_eq!(found[0].1, 0.0);
        }
    }

    #[test]
    fn what_is_not_allowed_is_never_answered() {
        let all = takes(40, 10, 9);
        let list: Vec<(usize, &[Descriptor])> =
            all.iter().enumerate().map(|(i, w)| (i, &w[..])).collect();
        let g = Graph::build(&list);
        let even = |slot: usize| slot.is_multiple_of(2);
        let found = g.nearest_takes(&all[3], &even, Depth::default(), 20, 40);
        assert_eq!(
            found.len(),
            20,
            "every allowed take, looking deeper: {found:?}"
        );
        assert!(!found.is_empty());
        assert!(found.iter().all(|(s, _)| s.is_multiple_of(2)), "{found:?}");
    }

    #[test]
    fn the_same_takes_in_the_same_order_make_the_same_graph() {
        let all = takes(30, 12, 11);
        let list: Vec<(usize, &[Descriptor])> =
            all.iter().enumerate().map(|(i, w)| (i, &w[..])).collect();
        let (a, b) = (Graph::build(&list), Graph::build(&list));
        let q = takes(1, 4, 99).remove(0);
        let depth = Depth {
            query_windows: 4,
            per_window: 5,
            ef: 8,
            max_ef: 8,
        };
        assert_eq!(
            a.nearest_takes(&q, &|_| true, depth, 10, 10),
            b.nearest_takes(&q, &|_| true, depth, 10, 10)
        );
    }
}
