//! Normalisation statistics of a selection of takes (`/v1/motion-stats`): per point (or
//! per body role) and axis, the mean and standard deviation of the positions and of their
//! velocities, over every frame of every take, as the takes' range answers give them (the
//! one read path, [`super::answer`], with the same transforms: rate, root, up, unit), so
//! that they are the statistics of what a client trains on.
//!
//! # One pass, cached, the same on every server
//! Each take is read once, front to back, into its moments ([`PointMoments`]); a selection's
//! statistics are its takes' moments merged in the order they were stored (exactly:
//! [`crate::motion::moments`]). A take's moments (or why it was skipped) are kept by the
//! take, the [`Stamp`] of the coding and body its answer read (a take re-encoded, replaced
//! or given a corrected body, through any server, is read again; a deleted one is no longer
//! listed) and what was asked, so asking again, or for a library that grew by a take, reads
//! only what is new, as long as the selection's moments fit what a server keeps
//! ([`MOTION_STATS_CACHE_BYTES`], the least recently used dropped first). What is computed
//! depends on the stored take alone, so every server sharing a database answers the same
//! numbers, kept or not. A take still being streamed is left out (skipped, with why): its
//! frames and its body change until it finishes.
//!
//! # Groups
//! Takes of different point sets cannot share statistics: each layout (its point names in
//! order, in one unit) is a group of its own. `points=` selects the same points of every
//! take (one group, if the unit is asked too); `by=roles` gives every take the body's roles
//! ([`Role::all`]: the centroid of the points the body places in each, missing where none),
//! the layout `roles=True` windows have. A role's centroid moves when one of its points
//! drops out or comes back, and its velocity with it, as the windows' do.
//!
//! # What it holds
//! One take's answer at a time (reserved from the answer budget as a range request of the
//! whole take would be, waiting for room as an export does; its chunks are not kept in the
//! decoded-chunk cache), one take's moments and the groups' (at most [`MAX_STATS_GROUPS`]
//! layouts of [`MAX_STATS_POINTS`] points in all, about 150 bytes a point, and the answer
//! about 300 bytes a point); takes are listed a page at a time.

use std::sync::Arc;

use serde::Serialize;

use super::access::{check_take, Grant};
use super::answer::{self, points_written, RangeRequest, BUDGET_WAIT};
use super::budget::{Budget, Holder};
use super::fetch::TimeRange;
use super::kept::Kept;
use super::library::{Pages, TakeQuery};
use super::prepared::{ReadCaches, Stamp};
use super::take::Take;
use super::{Error, Result};
use crate::limits::{
    Limits, MAX_STATS_GROUPS, MAX_STATS_IDS, MAX_STATS_POINTS, MAX_STATS_SKIPPED,
    MOTION_STATS_CACHE_BYTES,
};
use crate::motion::body::centroids;
use crate::motion::body::Role;
use crate::motion::formats::Format;
use crate::motion::moments::PointMoments;
use crate::motion::transform::{Options, Root};
use crate::store::Store;

/// What the statistics are of: each take's points, or its body's roles.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum By {
    #[default]
    Points,
    Roles,
}

impl std::str::FromStr for By {
    type Err = String;
    fn from_str(s: &str) -> std::result::Result<By, String> {
        match s.trim().to_ascii_lowercase().as_str() {
            "points" => Ok(By::Points),
            "roles" => Ok(By::Roles),
            other => Err(format!("by is points or roles, not {other:?}")),
        }
    }
}

/// Which takes: those a query matches, or those named.
#[derive(Debug, Clone, PartialEq)]
pub enum Selection {
    Query(Box<TakeQuery>),
    Ids(Vec<String>),
}

/// A statistics request, parsed.
#[derive(Debug, Clone, PartialEq)]
pub struct StatsRequest {
    pub selection: Selection,
    pub grant: Grant,
    /// Point names, each once: the same points of every take; `None` for each take's own.
    pub points: Option<Vec<String>>,
    pub by: By,
    pub transform: Options,
}

/// The statistics of a selection.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct MotionStats {
    pub by: By,
    /// Takes counted in, and their frames (at the answer's rate).
    pub takes: usize,
    pub frames: u64,
    /// The rate asked for (`None`: each take's own); velocities are per second either way.
    pub fps: Option<f64>,
    pub root: Root,
    pub up: Option<crate::motion::body::Axis>,
    /// One per layout, largest first (by frames).
    pub groups: Vec<Group>,
    /// Takes of the selection not counted in, and why (the first [`MAX_STATS_SKIPPED`]),
    /// and how many there were.
    pub skipped: Vec<Skipped>,
    pub skipped_count: usize,
    /// Takes read for this answer; the others' moments were kept from an earlier one.
    pub read: usize,
}

/// The statistics of the takes of one layout.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Group {
    /// The points (or roles) in order, and the metres a unit of their values is.
    pub points: Vec<String>,
    pub metres_per_unit: f64,
    pub takes: usize,
    pub frames: u64,
    /// Per point: the frames it is present in.
    pub present: Vec<u64>,
    /// Per point, `[x, y, z]`: positions' mean and standard deviation (population), and
    /// those of velocities (units per second, between consecutive frames where the point is
    /// present in both).
    pub mean: Vec<[f64; 3]>,
    pub std: Vec<[f64; 3]>,
    pub velocity_mean: Vec<[f64; 3]>,
    pub velocity_std: Vec<[f64; 3]>,
}

/// A take not counted in.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Skipped {
    pub id: String,
    pub name: String,
    pub reason: String,
}

/// One take's moments, as read: the points they are of and their unit.
#[derive(Debug, Clone)]
pub struct TakeMoments {
    points: Vec<String>,
    metres_per_unit: f64,
    moments: PointMoments,
}

impl TakeMoments {
    fn bytes(&self) -> usize {
        self.moments.bytes() + self.points.iter().map(|p| p.len() + 24).sum::<usize>()
    }
}

/// What reading a take as asked gave: its moments, or why it is not counted in.
#[derive(Debug)]
enum Outcome {
    Counted(TakeMoments),
    Skipped(String),
}

impl Outcome {
    fn bytes(&self) -> usize {
        std::mem::size_of::<Self>()
            + match self {
                Outcome::Counted(m) => m.bytes(),
                Outcome::Skipped(why) => why.len(),
            }
    }
}

/// What reading each take gave, by (take, the [`Stamp`] of what was read, what was asked),
/// bounded in bytes ([`MOTION_STATS_CACHE_BYTES`]), the least recently used dropped first.
pub struct MomentsCache {
    kept: Kept<MomentKey, Arc<Outcome>>,
}

type MomentKey = (String, Stamp, String);

impl Default for MomentsCache {
    fn default() -> Self {
        MomentsCache {
            kept: Kept::new(MOTION_STATS_CACHE_BYTES),
        }
    }
}

impl MomentsCache {
    fn get(&self, key: &MomentKey) -> Option<Arc<Outcome>> {
        self.kept.get(key)
    }

    fn insert(&self, key: MomentKey, outcome: Arc<Outcome>) {
        let size = outcome.bytes() + 2 * (key.0.len() + key.2.len() + 64);
        self.kept.insert(key, outcome, size);
    }

    /// Takes whose outcome is kept.
    pub fn len(&self) -> usize {
        self.kept.len()
    }

    pub fn is_empty(&self) -> bool {
        self.kept.is_empty()
    }
}

/// The merged moments of one layout, growing as takes are read.
struct Gathering {
    points: Vec<String>,
    metres_per_unit: f64,
    takes: usize,
    moments: PointMoments,
}

/// Check a request: what no take could answer is refused before any is read.
fn check(req: &StatsRequest) -> Result<Options> {
    let transform = answer::transform_for(Format::F32, req.transform)?;
    let bad = |m: &str| Err(Error::InvalidRequest(m.to_string()));
    if req.by == By::Roles && req.points.is_some() {
        return bad("by=roles gives every take the body's roles: leave out points");
    }
    if req.by == By::Roles && transform.root == Root::Extract {
        return bad(
            "by=roles gives body roles only, and root=extract adds the root's path as a point: \
             use root=in-place with by=roles",
        );
    }
    if let Some(points) = &req.points {
        if points.is_empty() {
            return bad("points names no point: leave it out for every point");
        }
        if points.iter().any(|p| p.is_empty()) {
            return bad("points has an empty name: give names separated by commas");
        }
        let mut seen = std::collections::HashSet::new();
        if let Some(twice) = points.iter().find(|p| !seen.insert(p.as_str())) {
            return Err(Error::InvalidRequest(format!(
                "point {twice:?} is named twice"
            )));
        }
    }
    match &req.selection {
        Selection::Query(q) => q.check()?,
        Selection::Ids(ids) if ids.is_empty() => return bad("ids names no take"),
        Selection::Ids(ids) if ids.len() > MAX_STATS_IDS => {
            return Err(Error::InvalidRequest(format!(
                "at most {MAX_STATS_IDS} takes by id, not {}; select by library, tag or label",
                ids.len()
            )))
        }
        Selection::Ids(_) => {}
    }
    Ok(transform)
}

/// The statistics `req` asks for, reading each take not in `kept` through its range answer
/// (reserved from `budget` for `holder`).
pub async fn compute(
    store: &Store,
    caches: &Arc<ReadCaches>,
    kept: &MomentsCache,
    budget: &Arc<Budget>,
    holder: Holder,
    limits: &Limits,
    req: StatsRequest,
) -> Result<MotionStats> {
    let transform = check(&req)?;
    let asked = format!("{:?}", (transform, &req.points, req.by));
    let mut run = Run {
        store,
        caches,
        kept,
        budget,
        holder,
        limits,
        req: &req,
        transform,
        asked,
        groups: Vec::new(),
        skipped: Vec::new(),
        skipped_count: 0,
        read: 0,
    };
    match &req.selection {
        Selection::Query(q) => {
            let mut pages = Pages::new(store, q.filter(&req.grant));
            while let Some(rows) = pages.next().await? {
                for row in rows {
                    let (id, name) = (row.id.clone(), row.name.clone());
                    match super::fetch::parse(store, row).await {
                        Ok(take) => run.count(&take).await?,
                        Err(e) if e.is_the_takes_own() => run.skip(id, name, &e),
                        Err(e) => return Err(e),
                    }
                }
            }
        }
        Selection::Ids(ids) => {
            let mut seen = std::collections::HashSet::new();
            for id in ids.iter().filter(|id| seen.insert(id.as_str())) {
                // A take the caller's token cannot see is not found, as by its own route;
                // one that cannot be read is skipped, as in a selection.
                check_take(store, &req.grant, id).await?;
                match super::fetch::take(store, id).await {
                    Ok(take) => run.count(&take).await?,
                    Err(e @ Error::NotFound(_)) => return Err(e),
                    Err(e) if e.is_the_takes_own() => run.skip(id.clone(), String::new(), &e),
                    Err(e) => return Err(e),
                }
            }
        }
    }
    Ok(run.finish())
}

/// A statistics request under way.
struct Run<'a> {
    store: &'a Store,
    caches: &'a Arc<ReadCaches>,
    kept: &'a MomentsCache,
    budget: &'a Arc<Budget>,
    holder: Holder,
    limits: &'a Limits,
    req: &'a StatsRequest,
    transform: Options,
    /// What was asked, as the cache keys a take's moments by.
    asked: String,
    groups: Vec<Gathering>,
    skipped: Vec<Skipped>,
    skipped_count: usize,
    read: usize,
}

impl Run<'_> {
    /// Count `take` in (what reading it gave, as kept, or read now), or skip it if it cannot
    /// be read as asked; an error of the server or the database stops the request.
    async fn count(&mut self, take: &Take) -> Result<()> {
        if take.is_live() {
            let why = "it is being streamed: its statistics count once it finishes";
            self.skipped(take.id.clone(), take.name.clone(), why.into());
            return Ok(());
        }
        let key = (take.id.clone(), Stamp::of(take), self.asked.clone());
        let outcome = match self.kept.get(&key) {
            Some(o) => o,
            None => {
                let (stamp, outcome) = match self.read(take).await {
                    Ok((stamp, m)) => (stamp, Outcome::Counted(m)),
                    Err(e) if e.is_the_takes_own() => {
                        (Stamp::of(take), Outcome::Skipped(e.to_string()))
                    }
                    Err(e) => return Err(e),
                };
                let outcome = Arc::new(outcome);
                self.read += 1;
                // Kept by what was read: a take changed since it was listed is read again
                // by the next request that lists it as it is now.
                self.kept.insert((key.0, stamp, key.2), outcome.clone());
                outcome
            }
        };
        let m = match &*outcome {
            Outcome::Counted(m) => m,
            Outcome::Skipped(why) => {
                self.skipped(take.id.clone(), take.name.clone(), why.clone());
                return Ok(());
            }
        };
        if m.moments.frames == 0 {
            self.skipped(
                take.id.clone(),
                take.name.clone(),
                "it has no frames".into(),
            );
            return Ok(());
        }
        let into = self
            .groups
            .iter()
            .position(|g| g.points == m.points && g.metres_per_unit == m.metres_per_unit);
        match into {
            Some(i) => {
                let g = &mut self.groups[i];
                g.moments.merge(&m.moments);
                g.takes += 1;
            }
            None => {
                let points: usize = self.groups.iter().map(|g| g.points.len()).sum();
                if self.groups.len() >= MAX_STATS_GROUPS
                    || points + m.points.len() > MAX_STATS_POINTS
                {
                    return Err(Error::InvalidRequest(format!(
                        "the selection holds more than {MAX_STATS_GROUPS} point layouts (point \
                         names and unit) or {MAX_STATS_POINTS} points in all; narrow it, name \
                         the same points= of each take with unit=, or ask by=roles"
                    )));
                }
                self.groups.push(Gathering {
                    points: m.points.clone(),
                    metres_per_unit: m.metres_per_unit,
                    takes: 1,
                    moments: m.moments.clone(),
                });
            }
        }
        Ok(())
    }

    fn skip(&mut self, id: String, name: String, e: &Error) {
        self.skipped(id, name, e.to_string());
    }

    fn skipped(&mut self, id: String, name: String, reason: String) {
        self.skipped_count += 1;
        if self.skipped.len() < MAX_STATS_SKIPPED {
            self.skipped.push(Skipped { id, name, reason });
        }
    }

    /// The moments of `take` as asked, read through its range answer, and the stamp of
    /// what the answer read.
    async fn read(&mut self, take: &Take) -> Result<(Stamp, TakeMoments)> {
        let request = RangeRequest {
            range: TimeRange::All,
            points: self.req.points.clone(),
            format: Format::F32,
            transform: self.transform,
            onto: None,
            feet: Default::default(),
        };
        let (budget, holder) = (self.budget.clone(), self.holder.clone());
        let a = answer::open_waiting(
            self.store,
            self.caches,
            || budget.reservation(holder.clone()),
            self.limits,
            &take.id,
            request,
            BUDGET_WAIT,
        )
        .await?;
        // One of many takes read whole: past the chunk cache.
        let mut a = a.bulk();
        let named = self
            .req
            .points
            .clone()
            .unwrap_or_else(|| take.meta.point_names.clone());
        let names = points_written(named, a.points);
        let width = names.len();
        let (points, roles) = match self.req.by {
            By::Points => (names, None),
            By::Roles => {
                let roles = take.roles.placed_in(&names);
                if roles.iter().all(Vec::is_empty) {
                    return Err(Error::Unsatisfiable(format!(
                        "take {} places no body role (its body.unplaced lists every one)",
                        take.name
                    )));
                }
                let names = Role::all().into_iter().map(Role::name).collect();
                (names, Some(roles))
            }
        };
        let mut moments = PointMoments::new(points.len(), a.fps);
        while let Some((positions, _held)) = a.next_positions().await? {
            match &roles {
                Some(groups) => moments.push(&centroids(&positions, width, groups)),
                None => moments.push(&positions),
            }
        }
        let m = TakeMoments {
            points,
            metres_per_unit: a.metres_per_unit,
            moments: moments.finished(),
        };
        Ok((a.stamp(), m))
    }

    fn finish(mut self) -> MotionStats {
        // Stable: groups of as many frames keep the order their first takes were stored in.
        self.groups
            .sort_by_key(|g| std::cmp::Reverse(g.moments.frames));
        let triples = |v: &[crate::motion::moments::Moments],
                       f: &dyn Fn(&crate::motion::moments::Moments) -> f64| {
            v.chunks_exact(3)
                .map(|c| [f(&c[0]), f(&c[1]), f(&c[2])])
                .collect::<Vec<_>>()
        };
        let groups: Vec<Group> = self
            .groups
            .iter()
            .map(|g| {
                let m = &g.moments;
                Group {
                    points: g.points.clone(),
                    metres_per_unit: g.metres_per_unit,
                    takes: g.takes,
                    frames: m.frames,
                    present: m.position.chunks_exact(3).map(|c| c[0].n).collect(),
                    mean: triples(&m.position, &|x| x.mean),
                    std: triples(&m.position, &|x| x.std()),
                    velocity_mean: triples(&m.velocity, &|x| x.mean),
                    velocity_std: triples(&m.velocity, &|x| x.std()),
                }
            })
            .collect();
        MotionStats {
            by: self.req.by,
            takes: groups.iter().map(|g| g.takes).sum(),
            frames: groups.iter().map(|g| g.frames).sum(),
            fps: self.transform.fps,
            root: self.transform.root,
            up: self.transform.up,
            groups,
            skipped: self.skipped,
            skipped_count: self.skipped_count,
            read: self.read,
        }
    }
}
