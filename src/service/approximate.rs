//! Approximate search's index as one server keeps it: the graph of every full-body take's
//! windows ([`crate::motion::nearest`]), built in the background from the features the
//! database holds, and what it left out.
//!
//! # When
//! A search of `index=auto` goes approximate once the takes it may see hold
//! [`APPROXIMATE_FROM_WINDOWS`] windows; `index=approximate` asks for it at any size, and
//! `index=exact` never. The first search that wants the graph starts its build and is
//! answered exactly (or, asked for approximate, with a 503 saying to retry).
//!
//! # Kept current
//! The graph holds takes as they were when it was built, each by its id and the stamp of
//! its features. A take stored or changed since is not in it and is scored exactly beside
//! what the graph proposes, so a search misses nothing new; once such takes hold
//! [`APPROXIMATE_REBUILD_SHARE`] of the graph's windows, the graph is built again, and
//! searched as it was until the new one is ready. A deleted take is never listed, so never
//! allowed: its windows stay in the graph, passed through, never answered, until the graph
//! is built again, as it also is once it is [`APPROXIMATE_REBUILD_AFTER_S`] old.
//!
//! # What it costs
//! About 2 KB a window, twice while a new graph is built beside the one searched; at most
//! [`APPROXIMATE_MAX_WINDOWS`] (the takes past it are not read for it, and are scored
//! exactly). A build that fails is not tried again for [`APPROXIMATE_RETRY_AFTER_S`].
//!
//! # On several servers
//! Each server builds its own graph from the database; the same takes make the same graph
//! ([`crate::motion::nearest`]), and the graph only proposes: every result is scored
//! exactly, so servers agree on every score. Servers whose graphs were built over different
//! takes can propose different takes; `index=exact` gives every server the same answer.

use std::collections::HashSet;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex, RwLock};
use std::time::{Duration, Instant};

use crate::codec::features::Stored;
use crate::limits::{
    APPROXIMATE_MAX_WINDOWS, APPROXIMATE_REBUILD_AFTER_S, APPROXIMATE_REBUILD_SHARE,
    APPROXIMATE_RETRY_AFTER_S,
};
use crate::motion::features::{HOP, KEY_ROLES, RATE};
use crate::motion::nearest::Graph;
use crate::motion::similar::Descriptor;
use crate::store::{Candidate, StampRow};

/// A take's features, or why it has none (as the motion index gives them).
pub type Indexed = std::result::Result<Arc<Stored>, String>;

/// A take as the graph knows it: its id and the stamp of its features.
pub type Key = (String, StampRow);

pub fn key(c: &Candidate) -> Key {
    (c.id.clone(), c.stamp.clone())
}

/// The windows a take's features hold, reckoned from its frames and rate (before they are
/// read).
pub fn windows_of(c: &Candidate) -> usize {
    let seconds = c.stamp.frames.max(0) as f64 / c.fps.max(1e-9);
    (seconds * RATE / HOP as f64).floor() as usize
}

/// The graph and what was read for it but left out.
pub struct Approximate {
    pub graph: Graph<Key>,
    /// Windows of each take in the graph (by slot).
    pub windows: Vec<usize>,
    /// Takes of fewer roles than a full body, or past the graph's cap: scored exactly.
    pub exact: HashSet<Key>,
    /// Takes whose contents give no features.
    pub without: HashSet<Key>,
    built: Instant,
}

impl Approximate {
    /// Whether the graph is behind the database enough to be built again: takes it does
    /// not know (estimated windows) against its own, or its age.
    pub fn stale(&self, unknown_windows: usize) -> bool {
        unknown_windows as f64 > APPROXIMATE_REBUILD_SHARE * self.graph.windows().max(1) as f64
            || self.built.elapsed() > Duration::from_secs(APPROXIMATE_REBUILD_AFTER_S)
    }
}

/// The graph a server holds, and whether one is being built.
#[derive(Default)]
pub struct Slot {
    current: RwLock<Option<Arc<Approximate>>>,
    building: AtomicBool,
    /// When the last build failed: none is tried again for a while.
    failed: Mutex<Option<Instant>>,
}

impl Slot {
    pub fn current(&self) -> Option<Arc<Approximate>> {
        self.current.read().map(|g| g.clone()).unwrap_or(None)
    }

    /// Claim the build: false if one is under way, or one failed lately.
    pub fn begin(&self) -> bool {
        let lately = self
            .failed
            .lock()
            .ok()
            .and_then(|f| *f)
            .is_some_and(|at| at.elapsed() < Duration::from_secs(APPROXIMATE_RETRY_AFTER_S));
        !lately && !self.building.swap(true, Ordering::AcqRel)
    }

    /// End the build claimed, with its graph if it was built (the one held is kept if not,
    /// and no build is tried again for [`APPROXIMATE_RETRY_AFTER_S`]).
    pub fn finish(&self, built: Option<Approximate>) {
        match built {
            Some(a) => {
                if let Ok(mut g) = self.current.write() {
                    *g = Some(Arc::new(a));
                }
            }
            None => {
                if let Ok(mut f) = self.failed.lock() {
                    *f = Some(Instant::now());
                }
            }
        }
        self.building.store(false, Ordering::Release);
    }
}

/// The graph of `takes` (their keys and features, in the order they were stored): the
/// full bodies' windows, up to [`APPROXIMATE_MAX_WINDOWS`]; the others kept aside as
/// scored exactly, or as giving no features. Blocking: minutes for a million windows.
pub fn build(takes: Vec<(Key, Indexed)>) -> Approximate {
    let mut graphed = Vec::new();
    let mut exact = HashSet::new();
    let mut without = HashSet::new();
    let mut total = 0usize;
    for (key, f) in takes {
        match f {
            Err(_) => {
                without.insert(key);
            }
            Ok(f) => {
                let full = f.pelvis && KEY_ROLES.iter().all(|r| f.placed.contains(r));
                if full && total + f.windows.len() <= APPROXIMATE_MAX_WINDOWS {
                    total += f.windows.len();
                    graphed.push((key, f));
                } else {
                    exact.insert(key);
                }
            }
        }
    }
    let list: Vec<(Key, &[Descriptor])> = graphed
        .iter()
        .map(|(k, f)| (k.clone(), &f.windows[..]))
        .collect();
    Approximate {
        graph: Graph::build(&list),
        windows: graphed.iter().map(|(_, f)| f.windows.len()).collect(),
        exact,
        without,
        built: Instant::now(),
    }
}
