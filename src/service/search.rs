//! Finding motion by motion (`POST /v1/search`, `GET /v1/takes/{id}/similar`): the takes
//! whose motion is most like a query's, each with the range of it that is.
//!
//! A query is a range of a stored take or an uploaded clip, read as its windows'
//! descriptors ([`crate::motion::features`]; a stored take's from the motion index, a
//! clip's taken as a stored take's are). Every take the caller's token reaches that matches
//! the filters is scored by its best run of as many windows ([`crate::motion::similar`]),
//! on the body roles both place; the `k` best are answered, at most `per_take` from one
//! take (runs that do not overlap), never the query's own range.
//!
//! Exact search compares every window of every take (an archive of 300,000 frames in about
//! 19 ms p50 on 2 cores, `mocapstore bench --search`). A query of fewer roles than a full
//! body is always answered exactly. Past [`APPROXIMATE_FROM_WINDOWS`] (or
//! asked with `index=approximate`), a graph of every full-body take's windows proposes the
//! takes worth scoring ([`super::approximate`]), and only those, with the takes the graph
//! does not hold, are scored, exactly as exact search scores them.
//!
//! What was searched is said: takes and windows compared, and the takes left out because
//! their features are not taken yet (the index job is at them), they are being streamed,
//! or their contents gave none. A token limited to libraries searches only their takes:
//! the others are never listed, counted or scored.

use std::collections::HashMap;
use std::sync::Arc;

use serde::Serialize;

use super::approximate::{self, Approximate};

use super::access::{check_take, Grant};
use super::library::TakeQuery;
use super::motion_index::MotionIndex;
use super::take::Take;
use super::{Error, Result};
use crate::codec::features::{self as stored, Stored};
use crate::limits::{
    APPROXIMATE_FROM_WINDOWS, APPROXIMATE_MAX_BEAM, MAX_SEARCH_K, MAX_SEARCH_PER_TAKE,
    MAX_SEARCH_QUERY_S,
};
use crate::motion::body::Role;
use crate::motion::features::RATE;
use crate::motion::formats::{self, Format, ReadOptions};
use crate::motion::nearest::Depth;
use crate::motion::rate;
use crate::motion::similar::{self, Descriptor, Shared};

/// What is searched for.
#[derive(Debug, Clone)]
pub enum Query {
    /// A range of a stored take (`t0 ≤ t < t1` in seconds; `None`: its start, its end).
    Take {
        id: String,
        t0: Option<f64>,
        t1: Option<f64>,
    },
    /// An uploaded clip (any format ingest reads), or a range of it.
    Clip {
        bytes: bytes::Bytes,
        format: Option<Format>,
        options: ReadOptions,
        t0: Option<f64>,
        t1: Option<f64>,
    },
}

/// Which index answers: `auto` goes approximate past [`APPROXIMATE_FROM_WINDOWS`].
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Index {
    #[default]
    Auto,
    Exact,
    Approximate,
}

impl Index {
    pub fn parse(s: &str) -> Result<Index> {
        match s {
            "auto" => Ok(Index::Auto),
            "exact" => Ok(Index::Exact),
            "approximate" => Ok(Index::Approximate),
            _ => Err(Error::InvalidRequest(format!(
                "index is auto, exact or approximate, not {s:?}"
            ))),
        }
    }
}

/// Takes the graph proposes for scoring: at least `wanted` (it looks deeper until it has
/// them, or every take it may), at most `most`, so that the `k` best are among them.
fn proposals(k: usize, per_take: usize) -> (usize, usize) {
    let results = k * per_take;
    ((2 * results).max(20), (10 * results).max(100))
}

/// A search, parsed.
#[derive(Debug, Clone)]
pub struct SearchRequest {
    pub query: Query,
    /// Results answered, at most [`MAX_SEARCH_K`].
    pub k: usize,
    /// Results from one take, at most [`MAX_SEARCH_PER_TAKE`].
    pub per_take: usize,
    /// Which takes are searched (library, tags, labels, fps, duration, skeleton …).
    pub takes: TakeQuery,
    pub grant: Grant,
    pub index: Index,
}

/// The query as it was compared.
#[derive(Debug, Clone, Serialize)]
pub struct QueryInfo {
    #[serde(skip_serializing_if = "Option::is_none")]
    pub take: Option<String>,
    /// The seconds its windows span.
    pub t0: f64,
    pub t1: f64,
    pub windows: usize,
    /// The body roles its windows hold, and those it lacks (not compared with any take).
    pub roles: Vec<String>,
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub missing_roles: Vec<String>,
}

/// One range found.
#[derive(Debug, Clone, Serialize)]
pub struct Found {
    pub take: String,
    pub name: String,
    pub library: String,
    /// Seconds of the take: the range `t0 ≤ t < t1` that is most like the query.
    pub t0: f64,
    pub t1: f64,
    /// The same range in the take's own frames, `start ≤ f < end` (what `/v1/ranges` and
    /// `start`/`end` of a range request take).
    pub start: usize,
    pub end: usize,
    /// Lower is nearer; 0 is the same motion.
    pub score: f64,
    /// Roles the query holds that this take does not place: compared without them.
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub missing_roles: Vec<String>,
}

/// What was searched.
#[derive(Debug, Clone, Serialize)]
pub struct Searched {
    /// Takes searched, and their windows (approximate: those the graph walked among, of
    /// which `scored` were scored).
    pub takes: usize,
    pub windows: usize,
    /// Takes left out: features not taken yet (the index job takes them), being streamed,
    /// or none their contents could give.
    pub unindexed: usize,
    pub live: usize,
    pub without_features: usize,
    /// `exact` (every take scored) or `approximate` (the takes the graph proposed, and
    /// those it does not hold).
    pub index: &'static str,
    /// Takes scored.
    pub scored: usize,
}

/// A search's answer.
#[derive(Debug, Clone, Serialize)]
pub struct SearchAnswer {
    pub query: QueryInfo,
    pub results: Vec<Found>,
    pub searched: Searched,
}

/// The graph to propose takes with, or `None` for exact search: `auto` wants it once
/// the listed takes hold [`APPROXIMATE_FROM_WINDOWS`] windows, `approximate` always. A
/// graph wanted and not built yet starts building: meanwhile `auto` is exact and
/// `approximate` is refused as busy.
fn graph_for(
    index: &Arc<MotionIndex>,
    asked: Index,
    listed: &[&crate::store::Candidate],
) -> Result<Option<Arc<Approximate>>> {
    let wanted = match asked {
        Index::Exact => false,
        Index::Approximate => true,
        Index::Auto => {
            listed
                .iter()
                .map(|c| approximate::windows_of(c))
                .sum::<usize>()
                >= APPROXIMATE_FROM_WINDOWS
        }
    };
    if !wanted {
        return Ok(None);
    }
    let current = index.approximate().current();
    if current.is_none() {
        index.start_graph();
        if asked == Index::Approximate {
            return Err(Error::Busy(
                "the approximate index is being built: ask again shortly, or with \
                 index=exact"
                    .into(),
            ));
        }
    }
    Ok(current)
}

/// The listed takes to score approximately: those the graph proposes for `query` among
/// the listed ones it holds, and every listed one it does not (stored or changed since it
/// was built, or of fewer roles), each with whether it is counted in `searched` already.
/// Starts a new graph when the one held is behind the database.
async fn propose(
    index: &Arc<MotionIndex>,
    a: &Arc<Approximate>,
    listed: &[&crate::store::Candidate],
    (query, wanted, most): (&[Descriptor], usize, usize),
    searched: &mut Searched,
) -> Result<Vec<(usize, bool)>> {
    let mut allowed = vec![false; a.graph.takes()];
    let mut listed_at: HashMap<usize, usize> = HashMap::new();
    let mut picked = Vec::new();
    let mut unknown = 0usize;
    for (i, c) in listed.iter().enumerate() {
        if !c.current {
            searched.unindexed += 1;
            continue;
        }
        let key = approximate::key(c);
        if let Some(slot) = a.graph.slot(&key) {
            allowed[slot] = true;
            listed_at.insert(slot, i);
            searched.takes += 1;
            searched.windows += a.windows[slot];
        } else if a.without.contains(&key) {
            searched.without_features += 1;
        } else {
            if !a.exact.contains(&key) {
                unknown += approximate::windows_of(c);
            }
            picked.push((i, false));
        }
    }
    if a.stale(unknown) {
        index.start_graph();
    }
    // Takes the graph holds that this search may see: when their windows are a small share
    // of the graph's (a few libraries' of many), a walk would pass through mostly others'
    // before it had enough, and scoring them all costs less.
    let allowed_windows: usize = listed_at.keys().map(|&slot| a.windows[slot]).sum();
    if allowed_windows * 10 < a.graph.windows() {
        let mut all: Vec<(usize, usize)> = listed_at.into_iter().collect();
        all.sort_unstable();
        picked.extend(all.into_iter().map(|(_, i)| (i, true)));
        return Ok(picked);
    }
    let (graph, query) = (a.clone(), query.to_vec());
    let wanted = wanted.min(listed_at.len());
    let depth = Depth {
        max_ef: APPROXIMATE_MAX_BEAM,
        ..Depth::default()
    };
    let found = super::blocking(move || {
        let allowed = |slot: usize| allowed[slot];
        graph
            .graph
            .nearest_takes(&query, &allowed, depth, wanted, most)
    })
    .await?;
    // Fewer than wanted after looking through the whole graph (clusters it could not walk
    // between): the rest of the takes it may see are scored too.
    let proposed: std::collections::HashSet<usize> = found.iter().map(|f| f.0).collect();
    if proposed.len() < wanted {
        let mut rest: Vec<(usize, usize)> = listed_at
            .iter()
            .filter(|(slot, _)| !proposed.contains(slot))
            .map(|(&slot, &i)| (slot, i))
            .collect();
        rest.sort_unstable();
        picked.extend(rest.into_iter().map(|(_, i)| (i, true)));
    }
    picked.extend(
        found
            .iter()
            .filter_map(|(slot, _)| listed_at.get(slot).map(|&i| (i, true))),
    );
    Ok(picked)
}

fn role_names(roles: &[Role]) -> Vec<String> {
    roles.iter().map(|r| r.name()).collect()
}

/// The windows of `f` within `[t0, t1)` seconds: those wholly inside, or, when the range
/// is shorter than a window, the one whose middle is nearest the range's. `None` when the
/// range lies outside the take.
fn windows_within(f: &Stored, t0: Option<f64>, t1: Option<f64>) -> Result<(usize, usize)> {
    let duration = Stored::seconds(f.frames as usize);
    let (t0, t1) = (
        t0.unwrap_or(0.0),
        t1.unwrap_or(duration.max(t0.unwrap_or(0.0))),
    );
    let bad = || {
        Error::InvalidRequest(format!(
            "the query's range is t0 = {t0} s to t1 = {t1} s: give 0 ≤ t0 < t1"
        ))
    };
    if !(t0.is_finite() && t1.is_finite() && t0 >= 0.0) {
        return Err(bad());
    }
    if t0 >= duration || f.windows.is_empty() {
        return Err(Error::OutOfRange(format!(
            "the query's range starts at t0 = {t0} s, at or past its take's end at \
             {duration:.3} s"
        )));
    }
    if t0 >= t1 {
        return Err(bad());
    }
    let (a, b) = (t0 * RATE - 0.5, t1 * RATE + 0.5);
    let inside: Vec<usize> = (0..f.windows.len())
        .filter(|&i| {
            let (s, e) = f.span(i);
            s as f64 >= a && e as f64 <= b
        })
        .collect();
    if let (Some(&first), Some(&last)) = (inside.first(), inside.last()) {
        return Ok((first, last + 1 - first));
    }
    // No window lies wholly inside: the nearest of those that overlap the range (a range
    // in a take's last frames, which no window ends in), else the nearest of all.
    let middle = (t0 + t1.min(duration)) / 2.0 * RATE;
    let overlapping: Vec<usize> = (0..f.windows.len())
        .filter(|&i| {
            let (s, e) = f.span(i);
            (s as f64) < t1 * RATE && e as f64 > t0 * RATE
        })
        .collect();
    let pool: Vec<usize> = if overlapping.is_empty() {
        (0..f.windows.len()).collect()
    } else {
        overlapping
    };
    let nearest = pool
        .into_iter()
        .min_by(|&x, &y| {
            let m = |i: usize| {
                let (s, e) = f.span(i);
                ((s + e) as f64 / 2.0 - middle).abs()
            };
            m(x).total_cmp(&m(y))
        })
        .expect("a window");
    Ok((nearest, 1))
}

/// The query's windows, and where they come from.
struct Asked {
    windows: Vec<Descriptor>,
    placed: Vec<Role>,
    pelvis: bool,
    /// The stored take and the run of its windows it is, to leave out of the results.
    own: Option<(String, usize, usize)>,
    info: QueryInfo,
}

async fn asked(index: &MotionIndex, req: &SearchRequest) -> Result<Asked> {
    let (features, take, t0, t1) = match &req.query {
        Query::Take { id, t0, t1 } => {
            check_take(index.store(), &req.grant, id).await?;
            let take: Take = super::fetch::take(index.store(), id).await?;
            if take.is_live() {
                return Err(Error::Unsatisfiable(format!(
                    "take {} is being streamed: search with it once it finishes",
                    take.name
                )));
            }
            let f = match index.of_take(&take).await? {
                Ok(f) => f,
                Err(why) => {
                    return Err(Error::Unsatisfiable(format!(
                        "take {} has no motion features: {why}",
                        take.name
                    )))
                }
            };
            (f, Some(take.id), *t0, *t1)
        }
        Query::Clip {
            bytes,
            format,
            options,
            t0,
            t1,
        } => {
            let (bytes, format, options) = (bytes.clone(), *format, options.clone());
            let f = super::blocking(move || -> Result<Stored> {
                let loaded = match (formats::detect(&bytes), format) {
                    (Err(_), Some(f)) => formats::read_as(f, &bytes, &options),
                    _ => formats::read(&bytes, &options),
                }?;
                // What reading it at 30 fps would make, before it is made.
                let m = &loaded.motion;
                let at_rate =
                    (m.frame_count().saturating_sub(1) as f64 * RATE / m.fps).ceil() + 1.0;
                let samples = at_rate * m.point_count().max(1) as f64;
                if samples > options.limits.max_samples as f64 {
                    return Err(Error::InvalidRequest(format!(
                        "the clip at 30 fps would be {at_rate:.0} frames of {} points, over the \
                         {} samples a take may have: send a shorter clip",
                        m.point_count(),
                        options.limits.max_samples
                    )));
                }
                let taken = crate::motion::features::of_motion(&loaded.motion, loaded.up.as_ref())?;
                if !taken.pelvis {
                    return Err(Error::Unsatisfiable(
                        "the clip places no pelvis (no body role it could be compared by): \
                         name its points as a body's"
                            .into(),
                    ));
                }
                // As a stored take's would be: the same codes.
                let bytes = stored::encode(&taken.features, taken.pelvis, taken.frames)?;
                Ok(stored::decode(&bytes, u64::MAX)?)
            })
            .await??;
            (Arc::new(f), None, *t0, *t1)
        }
    };
    if !features.pelvis {
        return Err(Error::Unsatisfiable(
            "the query places no pelvis: no body role it could be compared by (name its \
             points' roles with PATCH)"
                .into(),
        ));
    }
    let (first, count) = windows_within(&features, t0, t1)?;
    let (s, e) = (features.span(first).0, features.span(first + count - 1).1);
    if Stored::seconds(e - s) > MAX_SEARCH_QUERY_S + 1.0 {
        return Err(Error::InvalidRequest(format!(
            "the query spans {:.1} s; a search compares at most {MAX_SEARCH_QUERY_S} s: give \
             t0 and t1",
            Stored::seconds(e - s)
        )));
    }
    let span = |i: usize| features.span(i);
    let info = QueryInfo {
        take: take.clone(),
        t0: Stored::seconds(span(first).0),
        t1: Stored::seconds(span(first + count - 1).1),
        windows: count,
        roles: role_names(&features.placed),
        missing_roles: role_names(
            &crate::motion::features::KEY_ROLES
                .iter()
                .filter(|r| !features.placed.contains(r))
                .copied()
                .collect::<Vec<_>>(),
        ),
    };
    Ok(Asked {
        windows: features.windows[first..first + count].to_vec(),
        placed: features.placed.clone(),
        pelvis: features.pelvis,
        own: take.map(|t| (t, first, count)),
        info,
    })
}

/// Answer `req` from the takes' features `index` holds.
pub async fn search(index: &Arc<MotionIndex>, req: SearchRequest) -> Result<SearchAnswer> {
    if req.k == 0 || req.k > MAX_SEARCH_K {
        return Err(Error::InvalidRequest(format!(
            "k is the results answered: 1 to {MAX_SEARCH_K}, not {}",
            req.k
        )));
    }
    if req.per_take == 0 || req.per_take > MAX_SEARCH_PER_TAKE {
        return Err(Error::InvalidRequest(format!(
            "per_take is the results from one take: 1 to {MAX_SEARCH_PER_TAKE}, not {}",
            req.per_take
        )));
    }
    req.takes.check()?;
    let asked = asked(index, &req).await?;
    let candidates = index
        .store()
        .candidates(&req.takes.filter(&req.grant))
        .await?;
    let mut searched = Searched {
        takes: 0,
        windows: 0,
        unindexed: 0,
        live: 0,
        without_features: 0,
        index: "exact",
        scored: 0,
    };
    let listed: Vec<_> = candidates
        .iter()
        .filter(|c| {
            if c.live {
                searched.live += 1;
            }
            !c.live
        })
        .collect();
    // A query of fewer roles than a full body is compared on the roles it shares with
    // each take, which the graph's distance over every number cannot propose by.
    let full = asked.pelvis
        && crate::motion::features::KEY_ROLES
            .iter()
            .all(|r| asked.placed.contains(r));
    let graph = if full {
        graph_for(index, req.index, &listed)?
    } else {
        None
    };
    // The takes to score, and whether each is counted as searched yet.
    let picked: Vec<(usize, bool)> = match &graph {
        None => (0..listed.len()).map(|i| (i, false)).collect(),
        Some(a) => {
            searched.index = "approximate";
            let (wanted, most) = proposals(req.k, req.per_take);
            let asking = (&asked.windows[..], wanted, most);
            propose(index, a, &listed, asking, &mut searched).await?
        }
    };
    let chosen: Vec<_> = picked.iter().map(|&(i, _)| listed[i]).collect();
    let features = index.features(&chosen).await?;
    let mut compared: Vec<(usize, String, Arc<Stored>)> = Vec::with_capacity(chosen.len());
    for (&(i, counted), f) in picked.iter().zip(features) {
        match f {
            None => searched.unindexed += 1,
            Some(Err(_)) => searched.without_features += 1,
            Some(Ok(f)) => {
                if !counted {
                    searched.takes += 1;
                    searched.windows += f.windows.len();
                }
                compared.push((i, listed[i].id.clone(), f));
            }
        }
    }
    searched.scored = compared.len();
    let (k, per_take) = (req.k, req.per_take);
    let Asked {
        windows,
        placed,
        pelvis,
        own,
        info,
    } = asked;
    let query_roles = placed.clone();
    let ranked = super::blocking(move || {
        let mut found: Vec<(usize, similar::Run, Arc<Stored>, String)> = Vec::new();
        for (i, id, f) in compared {
            let shared = Shared::of((&placed, pelvis), (&f.placed, f.pelvis));
            let mine = own.as_ref().filter(|o| o.0 == id).map(|o| (o.1, o.2));
            let kept = similar::best_runs(&windows, &f.windows, &shared, per_take, mine);
            found.extend(kept.into_iter().map(|r| (i, r, f.clone(), id.clone())));
        }
        // Ties (copies of one take score alike) in an order of their own, not the order
        // the takes were scored in, so exact and approximate search answer alike.
        found.sort_by(|a, b| {
            (a.1.score.total_cmp(&b.1.score))
                .then_with(|| a.3.cmp(&b.3))
                .then(a.1.first.cmp(&b.1.first))
        });
        found.truncate(k);
        found
    });
    let ranked = ranked.await?;
    let results = ranked
        .into_iter()
        .map(|(i, r, f, _)| {
            let c = listed[i];
            let (t0, t1) = (
                Stored::seconds(f.span(r.first).0),
                Stored::seconds(f.span(r.first + r.count - 1).1),
            );
            let frames = usize::try_from(c.stamp.frames).unwrap_or(0);
            let frame = |t: f64| (rate::first_frame_from(t, c.fps).max(0.0) as usize).min(frames);
            let start = frame(t0).min(frames.saturating_sub(1));
            Found {
                take: c.id.clone(),
                name: c.name.clone(),
                library: c.library.clone(),
                t0,
                t1,
                start,
                end: frame(t1).max(start + 1).min(frames.max(1)),
                score: r.score,
                missing_roles: role_names(
                    &query_roles
                        .iter()
                        .filter(|r| !f.placed.contains(r))
                        .copied()
                        .collect::<Vec<_>>(),
                ),
            }
        })
        .collect();
    Ok(SearchAnswer {
        query: info,
        results,
        searched,
    })
}
