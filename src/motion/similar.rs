//! How alike two runs of windows are ([`super::features`] descriptors), and where in a take
//! a query fits best: what `/v1/search` ranks takes by and what the retrieval measure
//! ([`super::retrieval`]) scores, so the precision it prints is the search's own.
//!
//! # The score
//! Between a query's windows `Q` and a run of a take's windows `C` of the same length:
//! each window's distance to the nearest of the other run, averaged with each window
//! weighted by how much it moves ([`features::energy`]; the still windows most takes begin
//! and end with tell little), taken both ways and halved. Lower is nearer; 0 is the same
//! motion. Nearest rather than aligned windows, so a walk found half a step out of phase
//! is still a walk; both ways, so a run that holds the query's motion and much else is not
//! as near as one that holds only it.
//!
//! # Where in a take
//! A take longer than the query is searched for the run of as many windows that scores
//! best ([`best_run`]: every start, in time linear in the take's windows per query
//! window); a take shorter than the query is compared whole.
//!
//! # Roles a take lacks
//! A descriptor holds zeros for a key role its take does not place. Two takes are compared
//! on the roles both place ([`Shared`]), and the distance scaled up to all of a
//! descriptor's numbers, so that takes of few markers score on the scale of full bodies.

use std::collections::VecDeque;

use super::body::Role;
use super::features::{self, DIMS, HOP, KEY_ROLES, WINDOW};

/// One window's descriptor.
pub type Descriptor = [f32; DIMS];

/// Which numbers of two descriptors are compared: those of the key roles both takes place,
/// and the pelvis's when both place it.
#[derive(Debug, Clone, PartialEq)]
pub struct Shared {
    weights: Descriptor,
    scale: f32,
    /// The key roles compared.
    pub roles: Vec<Role>,
}

impl Shared {
    /// Every number: takes that place every key role and the pelvis.
    pub fn all() -> Shared {
        Shared {
            weights: [1.0; DIMS],
            scale: 1.0,
            roles: KEY_ROLES.to_vec(),
        }
    }

    /// The numbers two takes share: `a` and `b` are the key roles each places, with
    /// whether each places the pelvis (without it, a take's places are all zero and only
    /// its pelvis-free numbers would count; there are none, so nothing is compared).
    pub fn of(a: (&[Role], bool), b: (&[Role], bool)) -> Shared {
        let keys = KEY_ROLES.len();
        let mut weights = [0f32; DIMS];
        let mut roles = Vec::new();
        let pelvis = a.1 && b.1;
        if pelvis {
            for (k, r) in KEY_ROLES.iter().enumerate() {
                if a.0.contains(r) && b.0.contains(r) {
                    weights[k * 9..k * 9 + 9].fill(1.0);
                    roles.push(*r);
                }
            }
            weights[keys * 9..].fill(1.0);
        }
        let n: f32 = weights.iter().sum();
        Shared {
            weights,
            scale: if n > 0.0 { DIMS as f32 / n } else { 0.0 },
            roles,
        }
    }

    /// Whether anything is compared.
    pub fn any(&self) -> bool {
        self.scale > 0.0
    }

    /// The distance between two descriptors on the shared numbers.
    pub fn distance(&self, a: &Descriptor, b: &Descriptor) -> f32 {
        if self.scale == 1.0 {
            return features::distance(a, b).sqrt();
        }
        let s: f32 = a
            .iter()
            .zip(b)
            .zip(&self.weights)
            .map(|((x, y), w)| w * (x - y) * (x - y))
            .sum();
        (s * self.scale).sqrt()
    }
}

/// The best run of a take's windows for a query: its first window, how many, and its
/// score (lower nearer).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Run {
    pub first: usize,
    pub count: usize,
    pub score: f64,
}

impl Run {
    /// Whether this run's frames and those of the run of `count` windows from `first` do
    /// not overlap (consecutive windows do: they overlap by half).
    pub fn apart(&self, first: usize, count: usize) -> bool {
        let reach = WINDOW.div_ceil(HOP);
        self.first + self.count - 1 + reach <= first || first + count - 1 + reach <= self.first
    }
}

fn energies(w: &[Descriptor]) -> Vec<f64> {
    w.iter().map(features::energy).collect()
}

/// The run of `take`'s windows that scores best against `query` (as many windows, or the
/// whole take if it has fewer); `None` if either has none or nothing is `shared`.
pub fn best_run(query: &[Descriptor], take: &[Descriptor], shared: &Shared) -> Option<Run> {
    runs(query, take, shared)
        .into_iter()
        .min_by(|a, b| a.score.total_cmp(&b.score))
}

/// The best runs of `take` for `query` that do not overlap each other nor the run
/// `apart_from` (first window, count: the query's own, when `take` is its take), best
/// first, at most `most`. The forbidden run is left out before picking, so a run that
/// overlaps it never keeps out one that does not.
pub fn best_runs(
    query: &[Descriptor],
    take: &[Descriptor],
    shared: &Shared,
    most: usize,
    apart_from: Option<(usize, usize)>,
) -> Vec<Run> {
    let mut all = runs(query, take, shared);
    all.sort_by(|a, b| a.score.total_cmp(&b.score).then(a.first.cmp(&b.first)));
    let mut out: Vec<Run> = Vec::new();
    for r in all {
        if out.len() >= most {
            break;
        }
        let allowed = apart_from.is_none_or(|(first, count)| r.apart(first, count));
        if allowed && out.iter().all(|o| r.apart(o.first, o.count)) {
            out.push(r);
        }
    }
    out
}

/// Every run of `take`'s windows as long as `query` (or the whole take), by its first
/// window; none if either has no window or nothing is `shared`.
pub fn runs(query: &[Descriptor], take: &[Descriptor], shared: &Shared) -> Vec<Run> {
    let (m, n) = (query.len(), take.len());
    if m == 0 || n == 0 || !shared.any() {
        return Vec::new();
    }
    let eq = energies(query);
    let ec = energies(take);
    let eq_sum: f64 = eq.iter().sum();
    let run = m.min(n);
    let starts = n - run + 1;
    // One query window's distances at a time (memory in the take's windows alone): each
    // take window's nearest query window (the same at every start), and each query
    // window's nearest take window within the run at each start, a sliding minimum.
    let mut col_min = vec![f64::INFINITY; n];
    let mut toward = vec![0f64; starts];
    let mut row = vec![0f64; n];
    let mut deque: VecDeque<usize> = VecDeque::with_capacity(run);
    for (i, q) in query.iter().enumerate() {
        for (j, c) in take.iter().enumerate() {
            row[j] = f64::from(shared.distance(q, c));
            col_min[j] = col_min[j].min(row[j]);
        }
        deque.clear();
        for j in 0..n {
            while deque.back().is_some_and(|&b| row[b] >= row[j]) {
                deque.pop_back();
            }
            deque.push_back(j);
            if j + 1 >= run {
                let start = j + 1 - run;
                while deque.front().is_some_and(|&f| f < start) {
                    deque.pop_front();
                }
                toward[start] += eq[i] * row[deque[0]];
            }
        }
    }
    let mut weighted = vec![0f64; n + 1];
    let mut weight = vec![0f64; n + 1];
    for j in 0..n {
        weighted[j + 1] = weighted[j] + ec[j] * col_min[j];
        weight[j + 1] = weight[j] + ec[j];
    }
    (0..starts)
        .map(|s| {
            let from_query = toward[s] / eq_sum.max(1e-12);
            let from_take =
                (weighted[s + run] - weighted[s]) / (weight[s + run] - weight[s]).max(1e-12);
            Run {
                first: s,
                count: run,
                score: (from_query + from_take) / 2.0,
            }
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn window(seed: f32) -> Descriptor {
        std::array::from_fn(|d| ((d as f32 * 0.7 + seed).sin()) * 2.0)
    }

    /// The plain computation: every start, every pair.
    fn slow(query: &[Descriptor], take: &[Descriptor], shared: &Shared) -> Run {
        let run = query.len().min(take.len());
        let one_way = |a: &[Descriptor], b: &[Descriptor]| {
            let (mut s, mut w) = (0.0, 0.0);
            for x in a {
                let e = features::energy(x);
                let near = b
                    .iter()
                    .map(|y| f64::from(shared.distance(x, y)))
                    .fold(f64::INFINITY, f64::min);
                s += e * near;
                w += e;
            }
            s / w
        };
        (0..=take.len() - run)
            .map(|s| {
                let c = &take[s..s + run];
                Run {
                    first: s,
                    count: run,
                    score: (one_way(query, c) + one_way(c, query)) / 2.0,
                }
            })
            .min_by(|a, b| a.score.total_cmp(&b.score))
            .unwrap()
    }

    #[test]
    fn the_best_run_is_found_where_the_query_was_taken_from() {
        let take: Vec<Descriptor> = (0..40).map(|i| window(i as f32 * 0.37)).collect();
        let query = take[17..23].to_vec();
        let r = best_run(&query, &take, &Shared::all()).unwrap();
        assert_eq!((r.first, r.count), (17, 6));
        assert!(r.score.abs() < 1e-9, "{}", r.score);
        // The same as every start computed in full, for a query not in the take.
        let other: Vec<Descriptor> = (0..7).map(|i| window(i as f32 * 0.51 + 0.2)).collect();
        let fast = best_run(&other, &take, &Shared::all()).unwrap();
        let full = slow(&other, &take, &Shared::all());
        assert_eq!((fast.first, fast.count), (full.first, full.count));
        assert!((fast.score - full.score).abs() < 1e-6);
        // A take shorter than the query is compared whole.
        let short = best_run(&take, &query, &Shared::all()).unwrap();
        assert_eq!((short.first, short.count), (0, 6));
        assert!(best_run(&[], &take, &Shared::all()).is_none());
        // Runs that do not overlap, best first.
        let two = best_runs(&query, &take, &Shared::all(), 2, None);
        assert_eq!(two.len(), 2);
        assert_eq!(two[0].first, 17);
        assert!(two[1].first + 6 < 17 || two[1].first > 23);
        assert!(two[1].apart(17, 6) && !two[0].apart(17, 6));
        assert!(two[1].score > two[0].score);
        // The query's own run left out before picking: as many runs, all apart from it.
        let own = best_runs(&query, &take, &Shared::all(), 2, Some((17, 6)));
        assert_eq!(own.len(), 2, "{own:?}");
        assert!(own.iter().all(|r| r.apart(17, 6)), "{own:?}");
        assert!(own[0].apart(own[1].first, own[1].count));
    }

    #[test]
    fn only_the_roles_both_place_are_compared() {
        let all = KEY_ROLES.to_vec();
        let few = vec![KEY_ROLES[0], KEY_ROLES[3]];
        let shared = Shared::of((&all, true), (&few, true));
        assert_eq!(shared.roles, few);
        // What the take without the other roles holds there (zeros) does not count.
        let a = window(0.3);
        let mut b = a;
        for k in (0..KEY_ROLES.len()).filter(|k| ![0, 3].contains(k)) {
            b[k * 9..k * 9 + 9].fill(0.0);
        }
        assert_eq!(shared.distance(&a, &b), 0.0);
        assert!(Shared::all().distance(&a, &b) > 1.0);
        // Scaled to a whole descriptor: one role off by 1 in every number.
        let mut c = a;
        c[0..9].iter_mut().for_each(|v| *v += 1.0);
        let n = (2 * 9 + 5) as f32;
        assert!((shared.distance(&a, &c) - (9.0 * DIMS as f32 / n).sqrt()).abs() < 1e-4);
        // Without a pelvis, nothing is.
        assert!(!Shared::of((&all, false), (&all, true)).any());
    }
}
