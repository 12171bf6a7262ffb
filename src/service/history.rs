//! What per-take choice learns from the takes before it: in a library ingested take after
//! take (one layout, one bound, the same bases), the codecs that lose to the others so
//! consistently that encoding them in full is wasted work.
//!
//! Why learn, rather than estimate each take on its own: a library's takes are alike (the
//! same rig, the same capture, the same kind of motion), and so are the codecs' sizes on
//! them — on the Bandai Namco takes at max 1 mm, `pga` was 1.2–1.8× `rot` on every one of
//! 174 takes. Estimating a codec on a sample of a take costs a third to a half of encoding
//! it on takes of a few seconds (measured: 16–45 % of the full encode on the corpus), which
//! would leave little to save; the history costs nothing.
//!
//! The rule: takes are *explored* (every candidate encoded in full, as without a history)
//! until [`MIN_EXPLORED`] of them are known, and then every [`EXPLORE_EVERY`]-th take, so
//! the history follows the library as it changes. For the others, the candidates are ranked
//! by how often they won in the last [`WINDOW`] explored takes, and kept greedily: one that
//! came out smaller than every candidate kept before it in at most [`BEATEN_AT_MOST`] of
//! those takes is pruned. So a pruned codec would have won at most that often, by what the
//! history shows; the bytes lost to pruning are measured on the corpus
//! (`tests/choice.rs`). A candidate the history has not seen (a new codec, a basis just
//! trained, which starts a new history) is always encoded.

use std::collections::{BTreeMap, HashMap, VecDeque};
use std::sync::Mutex;

use serde::{Deserialize, Serialize};

use crate::codec::CodecId;

/// Explored takes needed before anything is pruned.
pub const MIN_EXPLORED: usize = 12;
/// After that, one take in this many is explored.
pub const EXPLORE_EVERY: u64 = 16;
/// The explored takes the rule looks at: the most recent this many.
pub const WINDOW: usize = 64;
/// A candidate is pruned if it beat the candidates kept before it in at most this share
/// of the explored takes it took part in.
pub const BEATEN_AT_MOST: f64 = 0.05;

/// What a history is kept per: takes of one layout, coded to one bound with the same
/// candidates' rules and the same shared bases, in which codec sizes are comparable.
#[derive(Debug, Clone, PartialEq, Eq, Hash)]
pub struct Key {
    pub layout: String,
    /// The bound, as [`crate::codec::ErrorBound`] shows it.
    pub bound: String,
    /// Latency class and what a skeleton take keeps, as the request named them.
    pub rules: String,
    /// Hashes of the shared bases the shared-basis candidates code with.
    pub bases: Vec<String>,
}

/// One explored take: every candidate's stored bytes (those that failed are absent).
type Sizes = BTreeMap<CodecId, usize>;

#[derive(Default)]
struct History {
    /// Takes planned under this key.
    seen: u64,
    explored: VecDeque<Sizes>,
}

/// The histories of one server, per [`Key`]. Kept in memory: a restarted server explores
/// again, and servers sharing a database each learn from their own takes.
#[derive(Default)]
pub struct Histories {
    inner: Mutex<HashMap<Key, History>>,
}

/// Which candidates to encode for one take.
#[derive(Debug, Clone, PartialEq)]
pub struct Plan {
    pub run: Vec<CodecId>,
    pub pruned: Vec<Pruned>,
    /// Every candidate runs, and the take's sizes join the history.
    pub explore: bool,
}

/// A candidate left out, and the history that says it would have lost.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Pruned {
    pub codec: CodecId,
    /// Explored takes in which it came out smaller than every candidate kept before it.
    pub beat_kept: usize,
    /// Explored takes it took part in.
    pub of: usize,
    /// Its median size relative to the smallest kept candidate in those takes.
    pub median_ratio: f64,
    /// Its estimated stored bytes on this take: the winner's times `median_ratio`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub estimated_bytes: Option<usize>,
}

impl Histories {
    /// The plan for the next take under `key` with these `candidates`.
    pub fn plan(&self, key: &Key, candidates: &[CodecId]) -> Plan {
        let mut map = self.inner.lock().unwrap_or_else(|e| e.into_inner());
        let h = map.entry(key.clone()).or_default();
        h.seen += 1;
        let explore = h.explored.len() < MIN_EXPLORED || h.seen.is_multiple_of(EXPLORE_EVERY);
        if explore || candidates.len() < 2 {
            return Plan {
                run: candidates.to_vec(),
                pruned: Vec::new(),
                explore,
            };
        }
        let (run, pruned) = keep(candidates, h.explored.make_contiguous());
        Plan {
            run,
            pruned,
            explore,
        }
    }

    /// Record an explored take's sizes under `key`.
    pub fn record(&self, key: &Key, sizes: Sizes) {
        if sizes.is_empty() {
            return;
        }
        let mut map = self.inner.lock().unwrap_or_else(|e| e.into_inner());
        let h = map.entry(key.clone()).or_default();
        h.explored.push_back(sizes);
        while h.explored.len() > WINDOW {
            h.explored.pop_front();
        }
    }
}

/// The rule of the module docs: candidates ranked by wins in `explored`, each kept unless it
/// beat every candidate kept before it in at most [`BEATEN_AT_MOST`] of the takes.
fn keep(candidates: &[CodecId], explored: &[Sizes]) -> (Vec<CodecId>, Vec<Pruned>) {
    let wins = |c: CodecId| {
        explored
            .iter()
            .filter(|s| s.iter().min_by_key(|(_, b)| **b).map(|(k, _)| *k) == Some(c))
            .count()
    };
    let mut order: Vec<(usize, CodecId)> = candidates.iter().map(|&c| (wins(c), c)).collect();
    // Most wins first; ties in id order, so a plan never depends on hash order.
    order.sort_by(|a, b| b.0.cmp(&a.0).then(a.1.cmp(&b.1)));
    let mut kept: Vec<CodecId> = Vec::new();
    let mut pruned = Vec::new();
    for (_, c) in order {
        // Per explored take in which `c` and a kept candidate both succeeded: c's size
        // relative to the smallest kept one.
        let ratios: Vec<f64> = explored
            .iter()
            .filter_map(|s| {
                let own = *s.get(&c)?;
                let best = kept.iter().filter_map(|k| s.get(k)).min()?;
                Some(own as f64 / *best as f64)
            })
            .collect();
        let beat = ratios.iter().filter(|&&r| r < 1.0).count();
        let prune = !kept.is_empty()
            && ratios.len() >= MIN_EXPLORED
            && beat as f64 <= BEATEN_AT_MOST * ratios.len() as f64;
        if prune {
            pruned.push(Pruned {
                codec: c,
                beat_kept: beat,
                of: ratios.len(),
                median_ratio: median(ratios),
                estimated_bytes: None,
            });
        } else {
            kept.push(c);
        }
    }
    // Keep the candidates' own order for the run.
    let run = candidates
        .iter()
        .copied()
        .filter(|c| kept.contains(c))
        .collect();
    (run, pruned)
}

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

#[cfg(test)]
mod tests {
    use super::*;
    use CodecId::{Pga, Quant, Rot};

    fn key() -> Key {
        Key {
            layout: "l".into(),
            bound: "max 1 mm".into(),
            rules: String::new(),
            bases: Vec::new(),
        }
    }

    fn sizes(v: &[(CodecId, usize)]) -> Sizes {
        v.iter().copied().collect()
    }

    #[test]
    fn a_codec_that_always_loses_is_pruned_after_the_exploration_and_explored_again_later() {
        let h = Histories::default();
        let all = [Quant, Rot, Pga];
        for i in 0..MIN_EXPLORED {
            let p = h.plan(&key(), &all);
            assert!(p.explore && p.run == all, "take {i}: {p:?}");
            // rot wins; quant wins one take in twelve; pga never.
            let q = if i == 5 { 90 } else { 120 };
            h.record(&key(), sizes(&[(Quant, q), (Rot, 100), (Pga, 130 + i)]));
        }
        let p = h.plan(&key(), &all);
        assert!(!p.explore);
        assert_eq!(
            p.run,
            vec![Quant, Rot],
            "quant beat rot in 1 of 12 (> 5 %): kept"
        );
        assert_eq!(p.pruned.len(), 1);
        let pga = &p.pruned[0];
        assert_eq!((pga.codec, pga.beat_kept, pga.of), (Pga, 0, 12));
        assert!((pga.median_ratio - 1.36).abs() < 0.02, "{pga:?}");
        // Every EXPLORE_EVERY-th take runs everything again.
        let explored = (MIN_EXPLORED as u64 + 2..=EXPLORE_EVERY)
            .map(|_| h.plan(&key(), &all).explore)
            .collect::<Vec<_>>();
        assert_eq!(explored.iter().filter(|e| **e).count(), 1);
        assert!(*explored.last().unwrap());
        // A candidate the history has not seen always runs; another key knows nothing.
        let p = h.plan(&key(), &[Rot, Pga, CodecId::Spca]);
        assert!(p.run.contains(&CodecId::Spca) && !p.run.contains(&Pga));
        let other = Key {
            bound: "max 2 mm".into(),
            ..key()
        };
        assert!(h.plan(&other, &all).explore);
    }

    #[test]
    fn the_window_forgets_old_takes() {
        let h = Histories::default();
        for i in 0..WINDOW + 10 {
            h.record(&key(), sizes(&[(Rot, 100), (Pga, 100 + i)]));
        }
        let map = h.inner.lock().unwrap();
        let kept = &map[&key()].explored;
        assert_eq!(kept.len(), WINDOW);
        assert_eq!(kept.front().unwrap()[&Pga], 110);
    }
}
