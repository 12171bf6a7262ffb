//! Every take's motion features ([`crate::motion::features`]), taken, stored and kept
//! current: what `/v1/search` compares.
//!
//! # Taken through the one read path
//! A take's features are taken from its range answer at 30 fps, in metres, +Y up by its
//! body ([`super::answer`], the frames a client reads), as one point per body role (the
//! centroid of the points its body places there), so they are of the take as stored and
//! as its body now says, and the same on every server.
//!
//! # Kept current
//! Each take's row in `take_features` carries the stamp of the coding and body they were
//! taken from ([`StampRow`]); a take re-encoded, finished streaming or given a corrected
//! body has another stamp, so its features are stale until taken again. An ingest takes
//! them at once; the rest (takes stored before features were, takes changed since) are
//! taken by the index job ([`JOB_KIND`]), which every server starts when its maintenance
//! finds stale takes (one runs at a time over the database; another server takes it over
//! if its own dies). A deleted take's features go with it (the row cascades). A take its
//! own contents keep from giving features (no body role placed) is stored with why, and
//! searched as having none.
//!
//! # Kept in memory
//! Features read from the database are kept decoded by take and stamp
//! ([`MOTION_INDEX_CACHE_BYTES`], least recently used dropped first), so a search reads only
//! the rows of takes it has not seen as they are now.

use std::sync::Arc;

use super::answer::{self, points_written, RangeRequest, BUDGET_WAIT};
use super::budget::{Budget, Holder};
use super::fetch::TimeRange;
use super::jobs::{Jobs, NewJob, Progress};
use super::kept::Kept;
use super::prepared::ReadCaches;
use super::take::Take;
use super::{Error, Result};
use crate::codec::features as stored;
use crate::limits::{Limits, MOTION_INDEX_CACHE_BYTES};
use crate::motion::body::{centroids, Axis, Role};
use crate::motion::features::{self, HOP, RATE};
use crate::motion::formats::Format;
use crate::motion::transform::Options;
use crate::store::{Candidate, FeatureRow, StampRow, Store};

/// What index jobs are called in the job table.
pub const JOB_KIND: &str = "index-motion";

/// Takes an index job asks the database for at a time.
const BATCH: usize = 64;

/// The transforms features are taken with: 30 fps, metres, +Y up.
pub fn reading() -> Options {
    Options {
        fps: Some(RATE),
        up: Some(Axis::Y),
        metres_per_unit: Some(1.0),
        ..Options::default()
    }
}

/// A take's features as a search reads them: its windows, or why it has none.
pub use super::approximate::Indexed;

/// The features of the database's takes, as this server takes, reads and keeps them.
pub struct MotionIndex {
    store: Store,
    caches: Arc<ReadCaches>,
    /// Range answers' budget: a take is read as a range request of it would be.
    budget: Arc<Budget>,
    limits: Limits,
    kept: Kept<(String, StampRow), Indexed>,
    /// The graph approximate search asks ([`super::approximate`]).
    approximate: super::approximate::Slot,
}

impl MotionIndex {
    pub fn new(store: Store, caches: Arc<ReadCaches>, budget: Arc<Budget>, limits: Limits) -> Self {
        MotionIndex {
            store,
            caches,
            budget,
            limits,
            kept: Kept::new(MOTION_INDEX_CACHE_BYTES),
            approximate: Default::default(),
        }
    }

    /// The graph of approximate search as this server holds it.
    pub fn approximate(&self) -> &super::approximate::Slot {
        &self.approximate
    }

    /// Start building the graph of approximate search in the background, from the
    /// features stored now, unless a build is under way; whether one was started.
    pub fn start_graph(self: &Arc<Self>) -> bool {
        if !self.approximate.begin() {
            return false;
        }
        let index = self.clone();
        tokio::spawn(async move {
            let built = match index.graph_of_stored().await {
                Ok(a) => {
                    tracing::info!(
                        takes = a.graph.takes(),
                        windows = a.graph.windows(),
                        bytes = a.graph.bytes(),
                        "approximate search index built"
                    );
                    Some(a)
                }
                Err(e) => {
                    tracing::warn!(error = %e, "approximate search index not built");
                    None
                }
            };
            index.approximate.finish(built);
        });
        true
    }

    /// The graph of every take's current features, in the order the takes were stored.
    async fn graph_of_stored(&self) -> Result<super::approximate::Approximate> {
        let all = self
            .store
            .candidates(&crate::store::Filter::default())
            .await?;
        // The takes the graph can hold, in the order they were stored: those past its cap
        // are not read (searches score them exactly).
        let mut windows = 0usize;
        let listed: Vec<&Candidate> = all
            .iter()
            .filter(|c| !c.live && c.current)
            .take_while(|c| {
                windows += super::approximate::windows_of(c);
                windows <= crate::limits::APPROXIMATE_MAX_WINDOWS
            })
            .collect();
        let features = self.features(&listed).await?;
        let takes: Vec<_> = listed
            .iter()
            .zip(features)
            .filter_map(|(c, f)| Some((super::approximate::key(c), f?)))
            .collect();
        super::blocking(move || super::approximate::build(takes)).await
    }

    pub fn store(&self) -> &Store {
        &self.store
    }

    /// Windows a stored take's features may hold: a take of the most frames the limits
    /// allow, at the highest rate, read at 30 fps.
    fn max_windows(&self) -> u64 {
        self.limits.frames / HOP as u64 + 2
    }

    /// Take and store the features of take `id` as it is now; false if it is being streamed
    /// (its features are taken once it finishes) or changed while they were taken (the
    /// job takes it again).
    pub async fn index(&self, id: &str) -> Result<bool> {
        self.index_waiting(id, BUDGET_WAIT).await
    }

    /// [`Self::index`] without waiting for room in the answers' budget: an ingest's, which
    /// must not hold its client while other answers fill the budget (a busy budget is an
    /// error, and the index job takes the take).
    pub async fn index_now(&self, id: &str) -> Result<bool> {
        self.index_waiting(id, std::time::Duration::ZERO).await
    }

    async fn index_waiting(&self, id: &str, wait: std::time::Duration) -> Result<bool> {
        let take = super::fetch::take(&self.store, id).await?;
        if take.is_live() {
            return Ok(false);
        }
        let row = match self.take(&take, wait).await {
            Ok(row) => row,
            Err(e) if e.is_the_takes_own() => FeatureRow {
                stamp: StampRow {
                    codec: take.codec.to_string(),
                    stored_bytes: take.stored_bytes as i64,
                    frames: take.frames as i64,
                    body_rev: take.body_rev as i64,
                },
                payload: Vec::new(),
                failed: Some(e.to_string()),
            },
            Err(e) => return Err(e),
        };
        Ok(self.store.put_features(id, &row).await?)
    }

    /// The features of `take`, read through its range answer, with the stamp of what the
    /// answer read.
    async fn take(&self, take: &Take, wait: std::time::Duration) -> Result<FeatureRow> {
        let request = RangeRequest {
            range: TimeRange::All,
            points: None,
            format: Format::F32,
            transform: reading(),
            onto: None,
            feet: Default::default(),
        };
        let budget = self.budget.clone();
        let holder = Holder::Token("(motion index)".into());
        let a = answer::open_waiting(
            &self.store,
            &self.caches,
            || budget.reservation(holder.clone()),
            &self.limits,
            &take.id,
            request,
            wait,
        )
        .await?;
        let mut a = a.bulk();
        let names = points_written(take.meta.point_names.clone(), a.points);
        let groups = take.roles.placed_in(&names);
        if groups.iter().all(Vec::is_empty) {
            return Err(Error::Unsatisfiable(format!(
                "take {} places no body role (its body.unplaced lists every one), so it has no \
                 motion features; name its points' roles with PATCH",
                take.name
            )));
        }
        let pelvis = !groups[Role::Pelvis.index()].is_empty();
        // One point per role per frame at 30 fps: bounded as a take's frames are.
        let at_rate = (take.frames as f64 * RATE / take.fps.max(1e-9)).ceil() as u64;
        if at_rate > self.limits.frames {
            return Err(Error::Unsatisfiable(format!(
                "take {} would be {at_rate} frames at 30 fps, over the {} a take may have: it \
                 has no motion features",
                take.name, self.limits.frames
            )));
        }
        let mut roles = Vec::new();
        while let Some((positions, _held)) = a.next_positions().await? {
            roles.extend(centroids(&positions, names.len(), &groups));
        }
        // Stored under the stamp of the take the roles were read from: if the answer read
        // a newer coding or body, the conditional write refuses them and the job takes the
        // take again.
        let stamp = super::prepared::Stamp::of(take).row();
        let frames = roles.len() / (Role::all().len() * 3);
        let payload = super::blocking(move || {
            let f = features::features(&roles);
            stored::encode(&f, pelvis, frames)
        })
        .await??;
        Ok(FeatureRow {
            stamp,
            payload,
            failed: None,
        })
    }

    /// Take the features of every take whose stored ones are missing or stale, reporting
    /// to `progress`; the number taken.
    pub async fn index_stale(&self, progress: Option<&Progress>) -> Result<usize> {
        let mut done = 0usize;
        // A cursor, not a set of takes tried: a take that stays stale after it was taken
        // (it changes under the job) waits for the next job without hiding the rest.
        let mut after: Option<String> = None;
        loop {
            let fresh = self.store.stale_features(after.as_deref(), BATCH).await?;
            let Some(last) = fresh.last() else {
                return Ok(done);
            };
            after = Some(last.clone());
            for id in fresh {
                if progress.is_some_and(Progress::is_lost) {
                    return Ok(done);
                }
                match self.index(&id).await {
                    Ok(true) => done += 1,
                    Ok(false) | Err(Error::NotFound(_)) => {}
                    // The database away: stop, for the next job.
                    Err(Error::Store(e)) if e.is_unavailable() => return Err(Error::Store(e)),
                    // One take's trouble (busy, a worker fault) does not hold back the rest.
                    Err(e) => {
                        tracing::warn!(take = %id, error = %e, "taking motion features failed")
                    }
                }
                if let Some(p) = progress {
                    p.report(0.0, format!("{done} takes indexed"));
                }
            }
        }
    }

    /// The features of `take` as it is now, taken first if they are missing or stale.
    pub async fn of_take(&self, take: &Take) -> Result<Indexed> {
        let key = (take.id.clone(), super::prepared::Stamp::of(take).row());
        if let Some(f) = self.kept.get(&key) {
            return Ok(f);
        }
        for attempt in 0..2 {
            let row = self
                .store
                .features_of(std::slice::from_ref(&key.0))
                .await?
                .pop();
            if let Some((_, row)) = row.filter(|(_, r)| r.stamp == key.1) {
                let max = self.max_windows();
                let f = super::blocking(move || decoded(row, max)).await?;
                self.keep(key, f.clone());
                return Ok(f);
            }
            if attempt == 0 && !self.index(&take.id).await? {
                break;
            }
        }
        Err(Error::Conflict(format!(
            "take {} changed while its motion features were taken: ask again",
            take.name
        )))
    }

    fn keep(&self, key: (String, StampRow), f: Indexed) {
        let bytes = match &f {
            Ok(s) => s.bytes(),
            Err(why) => why.len(),
        } + key.0.len()
            + 128;
        self.kept.insert(key, f, bytes);
    }

    /// The features of `candidates` as stored now: for each, `None` if it has none current
    /// (none stored, or taken from another coding or body than it has now).
    pub async fn features(&self, candidates: &[&Candidate]) -> Result<Vec<Option<Indexed>>> {
        let mut out: Vec<Option<Indexed>> = vec![None; candidates.len()];
        let mut missing = Vec::new();
        for (i, c) in candidates.iter().enumerate() {
            if !c.current {
                continue;
            }
            match self.kept.get(&(c.id.clone(), c.stamp.clone())) {
                Some(f) => out[i] = Some(f),
                None => missing.push(i),
            }
        }
        for batch in missing.chunks(500) {
            let ids: Vec<String> = batch.iter().map(|&i| candidates[i].id.clone()).collect();
            let rows = self.store.features_of(&ids).await?;
            let max = self.max_windows();
            let decoded = super::blocking(move || {
                rows.into_iter()
                    .map(|(id, row)| (id, row.stamp.clone(), decoded(row, max)))
                    .collect::<Vec<_>>()
            })
            .await?;
            for (id, stamp, f) in decoded {
                let Some(&i) = batch.iter().find(|&&i| candidates[i].id == id) else {
                    continue;
                };
                // Changed between the listing and this read: stale, as if not stored.
                if stamp != candidates[i].stamp {
                    continue;
                }
                self.keep((id, stamp), f.clone());
                out[i] = Some(f);
            }
        }
        Ok(out)
    }
}

/// A stored row's features, or why the take has none.
fn decoded(row: FeatureRow, max_windows: u64) -> Indexed {
    match row.failed {
        Some(why) => Err(why),
        None => stored::decode(&row.payload, max_windows)
            .map(Arc::new)
            .map_err(|e| format!("its stored features: {e}")),
    }
}

/// Start the index job on this server if some take's features are missing or stale and no
/// server runs it already; true if one was started here.
pub async fn start_if_stale(index: &Arc<MotionIndex>, jobs: &Arc<Jobs>) -> Result<bool> {
    if index.store.stale_features(None, 1).await?.is_empty() {
        return Ok(false);
    }
    let (_, runner) = jobs
        .start(NewJob {
            kind: JOB_KIND.into(),
            request: serde_json::json!({}),
            libraries: Vec::new(),
        })
        .await?;
    match runner {
        Some(progress) => {
            run(index.clone(), progress);
            Ok(true)
        }
        None => Ok(false),
    }
}

/// Run the index job in the background, reporting through `progress`.
pub fn run(index: Arc<MotionIndex>, progress: Progress) {
    tokio::spawn(async move {
        match index.index_stale(Some(&progress)).await {
            Ok(n) => progress.succeed(serde_json::json!({ "indexed": n })).await,
            Err(e) => progress.fail(e.to_string()).await,
        }
    });
}
