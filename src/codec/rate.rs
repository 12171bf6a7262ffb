//! Rate control: the searches every codec runs for the fewest bytes that meet a bound.
//!
//! A codec states its knobs and how to code at a setting; the searches over them live here,
//! once:
//! - per-chunk step indices (`rot`, `pga`): [`largest_meeting`] gallops from the previous
//!   chunk's index ([`ChunkSteps`]);
//! - a count or index whose error falls as it grows (`pga`'s directions): [`narrow`];
//! - a grid where size falls and then rises (`spca`'s scale): [`walk_grid`];
//! - a step multiplier whose error grows with it: [`largest_multiplier`] (bisection below a
//!   top) and [`grow_then_bisect`] (growth, then geometric bisection);
//! - the order of the trials under a max-and-mean bound with a residual layer:
//!   [`max_then_mean`] (the LSDT codecs) and [`with_fallback_residuals`] (MDTT's);
//! - keeping the smallest: [`Best`] (trials that meet a target, with their setting),
//!   [`Smallest`] (anything with a size), [`Ranked`] (the few smallest by an estimate).
//!
//! Every keep-the-smallest here keeps the first of equal sizes (a strict `<`): the order of
//! trials decides ties, so a search's bytes do not depend on which helper it goes through.
//! What a trial costs is [`super::container::estimated_bytes`], the container's own count.

use std::ops::RangeInclusive;

use super::container::estimated_bytes;
use super::error::Result;
use super::{CodecOutput, Target};

/// The number of step indices (one byte in a chunk).
pub const INDICES: u32 = 256;

/// The largest index below [`INDICES`] for which `meets` holds, assuming it holds below some
/// index and not above; `None` if it does not even hold at 0. The search starts at `hint`
/// (the previous chunk's index, when there is one) and gallops away from it, since
/// neighbouring chunks usually need about the same step: a chunk like its neighbour costs
/// a handful of trials instead of eight.
pub fn largest_meeting(
    hint: Option<u32>,
    mut meets: impl FnMut(u32) -> Result<bool>,
) -> Result<Option<u32>> {
    // `lo` meets the bound, `hi` does not (INDICES: past the coarsest).
    let (lo, hi) = match hint.map(|h| h.min(INDICES - 1)) {
        Some(h) if meets(h)? => {
            let (mut lo, mut d) = (h, 1);
            loop {
                let k = lo + d;
                if k >= INDICES {
                    break (lo, INDICES);
                }
                if !meets(k)? {
                    break (lo, k);
                }
                lo = k;
                d *= 2;
            }
        }
        h => {
            let (mut hi, mut d) = (h.unwrap_or(INDICES), 1);
            loop {
                let k = hi.saturating_sub(d);
                if meets(k)? {
                    break (k, hi);
                }
                if k == 0 {
                    return Ok(None);
                }
                hi = k;
                d *= 2;
            }
        }
    };
    let (lo, _) = narrow(lo as usize, hi as usize, |k| meets(k as u32))?;
    Ok(Some(lo as u32))
}

/// Bisect `lo..hi` down to neighbours: `up(mid)` says the boundary lies above `mid` (which
/// becomes `lo`), else at or below it (`hi`). Both ends are assumed to be on their sides
/// already; neither is asked about.
pub fn narrow(
    mut lo: usize,
    mut hi: usize,
    mut up: impl FnMut(usize) -> Result<bool>,
) -> Result<(usize, usize)> {
    while hi - lo > 1 {
        let mid = (lo + hi) / 2;
        if up(mid)? {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    Ok((lo, hi))
}

/// The largest multiplier in (0, `top`] at which `meets` holds, for a setting whose error
/// grows with it: `top` itself if it meets, else eight steps of bisection that start at a
/// quarter of it; `None` if no multiplier tried meets. The mean-bound step searches of the
/// LSDT encoders, which keep every setting that meets as a candidate.
pub fn largest_multiplier(top: f64, mut meets: impl FnMut(f64) -> bool) -> Option<f64> {
    if meets(top) {
        return Some(top);
    }
    let (mut lo, mut hi) = (0.0f64, top);
    for _ in 0..8 {
        let mid = if lo == 0.0 { hi / 4.0 } else { (lo + hi) / 2.0 };
        if meets(mid) {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    (lo > 0.0).then_some(lo)
}

/// A walk over a grid of settings whose size falls and then rises: from `start`, steps of
/// `stride` in whichever direction finds a smaller size first (up if the step above does,
/// else down), until two steps in a row find nothing smaller or the next step leaves `grid`
/// or passes `top`; then the settings half a stride either side of the best (at or below
/// `top`). `better(j)` codes setting `j` and says whether it is the smallest so far.
pub fn walk_grid(
    start: usize,
    stride: usize,
    grid: RangeInclusive<usize>,
    top: usize,
    mut better: impl FnMut(usize) -> Result<bool>,
) -> Result<()> {
    better(start)?;
    let up = start + stride <= top && better(start + stride)?;
    let (mut best, mut j, mut misses) = if up {
        (start + stride, start + stride, 0)
    } else {
        (start, start, 1)
    };
    while misses < 2 {
        let next = if up {
            j.checked_add(stride)
        } else {
            j.checked_sub(stride)
        };
        let Some(n) = next.filter(|&n| grid.contains(&n) && n <= top) else {
            break;
        };
        j = n;
        if better(n)? {
            (best, misses) = (n, 0);
        } else {
            misses += 1;
        }
    }
    let half = stride / 2;
    for j in [best.checked_sub(half), Some(best + half)]
        .into_iter()
        .flatten()
    {
        if j <= top {
            better(j)?;
        }
    }
    Ok(())
}

/// The per-chunk step search of a codec that codes each chunk at a step index of its own:
/// each chunk's search starts from the index the previous chunk settled on.
#[derive(Debug, Default, Clone, Copy)]
pub struct ChunkSteps {
    hint: Option<u32>,
}

impl ChunkSteps {
    /// The largest index at which the chunk `meets` its bound ([`largest_meeting`]), which
    /// becomes the next chunk's hint; `None` (and the hint kept) if not even 0 meets.
    pub fn largest(&mut self, meets: impl FnMut(u32) -> Result<bool>) -> Result<Option<u32>> {
        let found = largest_meeting(self.hint, meets)?;
        if found.is_some() {
            self.hint = found;
        }
        Ok(found)
    }
}

/// Where [`grow_then_bisect`] stops growing when every trial meets.
#[derive(Debug, Clone, Copy)]
pub enum Ceiling {
    /// No growth from a multiplier at or past this: the last one tried may exceed it by a
    /// factor.
    FromBelow(f64),
    /// No multiplier at or past this is tried.
    Tried(f64),
}

/// The largest multiplier that `meets` holds at, for a setting whose error grows with it:
/// from `start` (taken to meet) grown by `factor` while it meets, up to `ceiling`, then
/// `steps` geometric bisections between the last that met and the next one up.
pub fn grow_then_bisect(
    start: f64,
    factor: f64,
    ceiling: Ceiling,
    steps: usize,
    mut meets: impl FnMut(f64) -> bool,
) -> f64 {
    let mut lo = start;
    loop {
        let next = lo * factor;
        let room = match ceiling {
            Ceiling::FromBelow(c) => lo < c,
            Ceiling::Tried(c) => next < c,
        };
        if !room || !meets(next) {
            break;
        }
        lo = next;
    }
    let mut hi = lo * factor;
    for _ in 0..steps {
        let mid = (lo * hi).sqrt();
        if meets(mid) {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    lo
}

/// The step multipliers a residual-layer codec tries under a max-and-mean bound
/// ([`max_then_mean`]).
#[derive(Debug, Clone, Copy)]
pub struct Ladder {
    /// Steps, in units of the max bound, tried with the residual layer at the max.
    pub at_max: &'static [f64],
    /// Steps, in units of the mean bound, tried with the residual layer at the mean when no
    /// step meets the mean with it at the max (noise-like takes).
    pub noise: &'static [f64],
}

/// The trials of a codec with a coarse layer (step) and a residual layer (bound) under
/// `target`, in order: each step of `ladder.at_max` with the residual layer holding the max
/// (where the fewest bytes meet a max bound); under a mean bound, the largest step that
/// meets the mean with it ([`largest_multiplier`] below 8× the mean); failing that, the
/// noise steps with the residual layer at the mean. `offer(step, residual)` codes one and
/// says whether it met the target.
pub fn max_then_mean(target: Target, ladder: Ladder, mut offer: impl FnMut(f64, f64) -> bool) {
    let t = target.max;
    for beta in ladder.at_max {
        offer(beta * t, t);
    }
    let Some(m) = target.mean else {
        return;
    };
    if largest_multiplier(8.0, |f| offer(f * m, t)).is_none() {
        for beta in ladder.noise {
            offer(beta * m, m.min(t));
        }
    }
}

/// A whole search run with its residual layer at the max bound, and when it finds nothing
/// (a mean bound no setting meets so: noise-like or tiny takes), run again with the
/// residual layer at `factors` times the mean (never past the max), the smallest kept.
pub fn with_fallback_residuals<S>(
    target: Target,
    factors: &[f64],
    mut search: impl FnMut(f64) -> Option<(Trial, S)>,
) -> Option<(Trial, S)> {
    search(target.max).or_else(|| {
        let mut kept = Smallest::new();
        for f in factors {
            let Some(m) = target.mean else { break };
            if let Some(found) = search((f * m).min(target.max)) {
                kept.offer(found.0.bytes, found);
            }
        }
        kept.into_best()
    })
}

/// One coding of a take and what it measured: its output, its stored size
/// ([`super::container::estimated_bytes`]) and its max and mean error.
pub struct Trial {
    pub out: CodecOutput,
    pub bytes: usize,
    pub max: f64,
    pub mean: f64,
}

impl Trial {
    pub fn new(out: CodecOutput, max: f64, mean: f64) -> Trial {
        let bytes = estimated_bytes(out.params.len(), &out.chunks);
        Trial {
            out,
            bytes,
            max,
            mean,
        }
    }
}

/// The smallest of what is offered by its size `K` (bytes, or estimated bits), the first of
/// equal sizes.
#[derive(Debug)]
pub struct Smallest<T, K = usize> {
    kept: Option<(K, T)>,
}

impl<T, K> Default for Smallest<T, K> {
    fn default() -> Self {
        Smallest { kept: None }
    }
}

impl<T, K: PartialOrd + Copy> Smallest<T, K> {
    pub fn new() -> Self {
        Self::default()
    }

    /// Keep `item` of `size` if it is smaller than the one kept; whether it was.
    pub fn offer(&mut self, size: K, item: T) -> bool {
        let smaller = self.kept.as_ref().is_none_or(|(b, _)| size < *b);
        if smaller {
            self.kept = Some((size, item));
        }
        smaller
    }

    pub fn size(&self) -> Option<K> {
        self.kept.as_ref().map(|(b, _)| *b)
    }

    pub fn best(&self) -> Option<&T> {
        self.kept.as_ref().map(|(_, t)| t)
    }

    pub fn into_best(self) -> Option<T> {
        self.kept.map(|(_, t)| t)
    }
}

/// The smallest [`Trial`] that meets a target, with the setting `S` it was coded at.
pub struct Best<S> {
    target: Target,
    kept: Smallest<(Trial, S)>,
}

impl<S: Copy> Best<S> {
    pub fn new(target: Target) -> Self {
        Best {
            target,
            kept: Smallest::new(),
        }
    }

    /// Record a trial coded at `setting`: its size if it met the target (kept or not).
    pub fn offer(&mut self, trial: Trial, setting: S) -> Option<usize> {
        if !self.target.holds(trial.max, trial.mean) {
            return None;
        }
        let bytes = trial.bytes;
        self.kept.offer(bytes, (trial, setting));
        Some(bytes)
    }

    /// The setting of the smallest trial so far.
    pub fn setting(&self) -> Option<S> {
        self.kept.best().map(|(_, s)| *s)
    }

    pub fn bytes(&self) -> Option<usize> {
        self.kept.size()
    }

    pub fn into_best(self) -> Option<(Trial, S)> {
        self.kept.into_best()
    }
}

/// The `capacity` smallest of what is offered by an estimate of their size, smallest first
/// (the earlier of equal estimates first): a search that ranks many settings cheaply and
/// codes only the few best in full.
#[derive(Debug)]
pub struct Ranked<T> {
    capacity: usize,
    items: Vec<(f64, T)>,
}

impl<T> Ranked<T> {
    pub fn new(capacity: usize) -> Self {
        Ranked {
            capacity,
            items: Vec::with_capacity(capacity + 1),
        }
    }

    pub fn offer(&mut self, estimate: f64, item: T) {
        let at = self.items.partition_point(|c| c.0 <= estimate);
        if at < self.capacity {
            self.items.insert(at, (estimate, item));
            self.items.truncate(self.capacity);
        }
    }

    /// What was kept, smallest estimate first.
    pub fn into_items(self) -> impl Iterator<Item = T> {
        self.items.into_iter().map(|(_, t)| t)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn trial(bytes: usize, max: f64, mean: f64) -> Trial {
        Trial {
            out: CodecOutput {
                params: Vec::new(),
                chunks: Vec::new(),
            },
            bytes,
            max,
            mean,
        }
    }

    #[test]
    fn the_smallest_is_kept_and_the_first_of_equals_wins() {
        let mut s = Smallest::new();
        assert!(s.offer(5, "a"));
        assert!(!s.offer(5, "b"));
        assert!(s.offer(3, "c"));
        assert!(!s.offer(4, "d"));
        assert_eq!((s.size(), s.best()), (Some(3), Some(&"c")));
        let mut bits = Smallest::new();
        bits.offer(2.5, 1);
        bits.offer(2.5, 2);
        assert_eq!(bits.into_best(), Some(1));
    }

    #[test]
    fn best_keeps_only_trials_that_meet_the_target() {
        let mut b = Best::new(Target {
            max: 1.0,
            mean: Some(0.5),
        });
        assert_eq!(b.offer(trial(10, 2.0, 0.1), 'x'), None, "max missed");
        assert_eq!(b.offer(trial(10, 0.9, 0.6), 'y'), None, "mean missed");
        assert_eq!(b.offer(trial(30, 1.0, 0.5), 'a'), Some(30));
        assert_eq!(b.offer(trial(20, 0.5, 0.2), 'b'), Some(20));
        assert_eq!(b.offer(trial(20, 0.1, 0.1), 'c'), Some(20));
        assert_eq!(b.setting(), Some('b'));
        assert_eq!(b.into_best().map(|(t, s)| (t.bytes, s)), Some((20, 'b')));
    }

    #[test]
    fn ranked_keeps_the_few_smallest_estimates_in_order() {
        let mut r = Ranked::new(2);
        for (e, x) in [(5.0, 'a'), (3.0, 'b'), (9.0, 'c'), (3.0, 'd'), (1.0, 'e')] {
            r.offer(e, x);
        }
        assert_eq!(r.into_items().collect::<String>(), "eb");
    }

    #[test]
    fn grow_then_bisect_stops_at_its_ceiling_as_it_says() {
        // Everything meets: growth stops at the ceiling, which `FromBelow` passes once.
        for (ceiling, last) in [
            (Ceiling::FromBelow(64.0), 1.5f64.powi(11)),
            (Ceiling::Tried(64.0), 1.5f64.powi(10)),
        ] {
            let mut tried = Vec::new();
            grow_then_bisect(1.0, 1.5, ceiling, 0, |x| {
                tried.push(x);
                true
            });
            assert_eq!(tried.last(), Some(&last), "{ceiling:?}");
        }
        // A threshold: growth finds the bracket, bisection closes in on it from below.
        let found = grow_then_bisect(1.0, 1.5, Ceiling::Tried(64.0), 12, |x| x <= 7.0);
        assert!(found <= 7.0 && found > 7.0 * 0.9999, "{found}");
        assert_eq!(
            grow_then_bisect(1.0, 1.5, Ceiling::Tried(64.0), 5, |_| false),
            1.0
        );
    }

    #[test]
    fn max_then_mean_tries_the_noise_steps_only_when_no_step_meets_the_mean() {
        const L: Ladder = Ladder {
            at_max: &[0.5, 2.0],
            noise: &[1.5],
        };
        let mut tried = Vec::new();
        max_then_mean(Target::max(2.0), L, |step, residual| {
            tried.push((step, residual));
            true
        });
        assert_eq!(tried, [(1.0, 2.0), (4.0, 2.0)]);
        let both = Target {
            max: 2.0,
            mean: Some(0.4),
        };
        tried.clear();
        max_then_mean(both, L, |step, residual| {
            tried.push((step, residual));
            step <= 4.0
        });
        assert_eq!(
            tried.len(),
            3,
            "the top (8× the mean) meets: no bisection {tried:?}"
        );
        tried.clear();
        max_then_mean(both, L, |step, residual| {
            tried.push((step, residual));
            residual < 1.0
        });
        assert_eq!(tried.last(), Some(&(1.5 * 0.4, 0.4)), "{tried:?}");
        assert_eq!(tried.len(), 2 + 9 + 1);
    }

    #[test]
    fn fallback_residuals_run_only_when_the_max_finds_nothing_and_keep_the_smallest() {
        let both = Target {
            max: 2.0,
            mean: Some(1.0),
        };
        let mut asked = Vec::new();
        let found = with_fallback_residuals(both, &[3.0, 1.4, 1.0], |rt| {
            asked.push(rt);
            (rt < 2.0).then(|| (trial(if rt > 1.2 { 7 } else { 9 }, 0.0, 0.0), rt))
        });
        assert_eq!(
            asked,
            [2.0, 2.0, 1.4, 1.0],
            "3× the mean is capped at the max"
        );
        assert_eq!(found.map(|(t, rt)| (t.bytes, rt)), Some((7, 1.4)));
        asked.clear();
        with_fallback_residuals(both, &[3.0], |rt| {
            asked.push(rt);
            Some((trial(1, 0.0, 0.0), ()))
        });
        assert_eq!(asked, [2.0]);
        assert!(
            with_fallback_residuals(Target::max(1.0), &[3.0], |_| None::<(Trial, ())>).is_none()
        );
    }

    #[test]
    fn the_grid_walk_finds_the_bottom_of_a_valley_from_either_side() {
        for bottom in [9usize, 20, 36, 37, 50, 63] {
            for top in [64usize, 40] {
                let mut smallest = usize::MAX;
                let mut tried = Vec::new();
                walk_grid(36.min(top), 2, 8..=64, top, |j| {
                    tried.push(j);
                    let size = j.abs_diff(bottom);
                    let better = size < smallest;
                    smallest = smallest.min(size);
                    Ok(better && j <= top)
                })
                .unwrap();
                let want = bottom.min(top);
                assert!(
                    tried.contains(&want),
                    "bottom {bottom} top {top}: {tried:?}"
                );
                assert!(tried.iter().all(|&j| j <= top));
            }
        }
    }

    #[test]
    fn chunk_steps_start_from_the_last_chunk_that_found_one() {
        let mut steps = ChunkSteps::default();
        assert_eq!(steps.largest(|k| Ok(k <= 100)).unwrap(), Some(100));
        assert_eq!(steps.largest(|_| Ok(false)).unwrap(), None);
        let mut trials = 0;
        let got = steps.largest(|k| {
            trials += 1;
            Ok(k <= 100)
        });
        assert_eq!(
            (got.unwrap(), trials),
            (Some(100), 2),
            "the hint survived the miss"
        );
    }

    #[test]
    fn largest_multiplier_bisects_below_the_top_and_says_when_nothing_meets() {
        assert_eq!(largest_multiplier(8.0, |f| f <= 9.0), Some(8.0));
        let found = largest_multiplier(8.0, |f| f <= 3.0).unwrap();
        assert!(found <= 3.0 && found > 3.0 - 8.0 / 256.0, "{found}");
        assert_eq!(largest_multiplier(8.0, |_| false), None);
    }

    #[test]
    fn finds_the_threshold_from_any_hint() {
        for threshold in [0u32, 1, 7, 100, 200, 255] {
            for hint in [None, Some(0), Some(5), Some(120), Some(255), Some(900)] {
                let mut trials = 0;
                let got = largest_meeting(hint, |k| {
                    trials += 1;
                    Ok(k <= threshold)
                })
                .unwrap();
                assert_eq!(got, Some(threshold), "hint {hint:?}");
                assert!(trials <= 20, "{trials} trials");
            }
        }
        assert_eq!(largest_meeting(Some(3), |_| Ok(false)).unwrap(), None);
        assert_eq!(largest_meeting(None, |_| Ok(false)).unwrap(), None);
    }

    #[test]
    fn a_good_hint_costs_few_trials() {
        let mut trials = 0;
        largest_meeting(Some(150), |k| {
            trials += 1;
            Ok(k <= 150)
        })
        .unwrap();
        assert_eq!(trials, 2);
    }
}
