//! The parameter search of per-take `mdtt` and of `mdtt-shared`: the same walk over rank,
//! temporal bandwidth, basis precision and coefficient step, each codec with its own
//! [`Plan`] (the lists the two were tuned with). The searches themselves (keep the
//! smallest, grow then bisect, residual fallbacks) are [`crate::codec::rate`]'s.

use super::transform::{clip_len, ratio};
use crate::codec::rate::{grow_then_bisect, Best, Ceiling, Smallest, Trial};
use crate::codec::{Input, Target};

/// One point of the parameter space, as coded.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) struct Choice {
    pub k: usize,
    pub l: usize,
    pub coef_step: f64,
    /// Basis precision relative to the coefficients' (see `basis_bits`); 0 for the paper's
    /// flat 16 bits. `mdtt-shared` stores no basis and ignores it.
    pub basis_gamma: f64,
}

/// One point of the parameter space, as searched: the rank, the bandwidth relative to the
/// paper's ratio, the step relative to the bound, the basis precision.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) struct Setting {
    pub k: usize,
    pub m: f64,
    pub beta: f64,
    pub gamma: f64,
}

/// What differs between the two codecs' searches.
pub(super) struct Plan {
    /// Try the ranks between the neighbours of the best rung of the ladder.
    pub refine_rank: bool,
    /// Bandwidths relative to the paper's ratio, tried at the best rank, and which one the
    /// later stages code at.
    pub bandwidths: &'static [f64],
    pub bandwidth: Bandwidth,
    /// The basis precision of the first trials, and those tried after the bandwidth.
    pub gamma: f64,
    pub gammas: &'static [f64],
    /// Where a mean bound's step growth stops.
    pub ceiling: Ceiling,
    /// Residual bounds, in units of the mean, to search again at when nothing meets the
    /// bound with the residual layer at the max.
    pub fallbacks: &'static [f64],
}

/// Which bandwidth the stages after the bandwidth scan code at. The two differ only when a
/// scanned bandwidth codes exactly as small as the best trial before the scan.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) enum Bandwidth {
    /// The bandwidth of the smallest trial so far (per-take `mdtt`).
    OfTheBest,
    /// The smallest of the scan itself, the earlier of equals; the paper's ratio if none
    /// meets the bound (`mdtt-shared`).
    SmallestScanned,
}

/// Steps relative to the bound scanned at the best rank and bandwidth: the residual layer
/// holds the max at every step, so the fewest bytes come from a scan.
const BETAS: [f64; 5] = [0.25, 0.35, 0.5, 0.7, 1.0];

/// The clip shape a search codes with, and how a [`Setting`] becomes a [`Choice`].
pub(super) struct Shape {
    pub w: usize,
    pub clip: usize,
    r: f64,
    t: f64,
}

impl Shape {
    pub fn new(input: &Input<'_>, target: Target) -> Shape {
        let clip = clip_len(input.fps).min(input.frames);
        Shape {
            w: input.width(),
            clip,
            r: ratio(clip, input.fps),
            t: target.tightest(),
        }
    }

    /// The bandwidth of rank `k` at `m` times the paper's ratio.
    pub fn l(&self, k: usize, m: f64) -> usize {
        ((self.r * m * k as f64).round() as usize).clamp(1, self.clip)
    }

    /// The quantisation error of S spreads over a whole clip (B and D̃ are orthonormal), so
    /// the step scales with √(L·w / k·l) relative to the bound.
    fn choice(&self, s: Setting) -> Choice {
        let l = self.l(s.k, s.m);
        Choice {
            k: s.k,
            l,
            coef_step: s.beta
                * self.t
                * ((self.clip * self.w) as f64 / (s.k * l) as f64)
                    .sqrt()
                    .min(8.0),
            basis_gamma: s.gamma,
        }
    }
}

/// The fewest bytes `code` finds that meet `target` (with the residual layer at whatever
/// bound `code` holds), and the setting it came from; `None` if no setting meets it.
///
/// 1. Rank on a geometric ladder at the paper's ratio, stopping two rungs past the best
///    once sizes grow again; with [`Plan::refine_rank`], the ranks beside the best rung.
/// 2. The bandwidth, then the basis precision, then the step, each around the best so far.
/// 3. Under a mean bound, whose error grows with the step: grow the step while the mean
///    holds, then bisect.
pub(super) fn run(
    shape: &Shape,
    target: Target,
    plan: &Plan,
    mut code: impl FnMut(Choice) -> Trial,
) -> Option<(Trial, Setting)> {
    let bisect = target.mean.is_some();
    let beta0 = if bisect { 1.0 } else { 0.5 };
    let mut best = Best::new(target);
    let mut offer = |best: &mut Best<Setting>, s: Setting| best.offer(code(shape.choice(s)), s);
    let at = |k: usize| Setting {
        k,
        m: 1.0,
        beta: beta0,
        gamma: plan.gamma,
    };

    let ks = rank_ladder(shape.w);
    let mut met = Vec::new();
    for &k in &ks {
        met.extend(offer(&mut best, at(k)));
        if past_the_best(&met) {
            break;
        }
    }
    let c = best.setting()?;
    if plan.refine_rank {
        let i = ks.iter().position(|&k| k == c.k).unwrap_or(0);
        let (lo, hi) = (ks[i.saturating_sub(1)], ks[(i + 1).min(ks.len() - 1)]);
        let stride = ((hi - lo) / 4).max(1);
        for k in (lo..=hi).step_by(stride).filter(|k| !ks.contains(k)) {
            offer(&mut best, at(k));
        }
    }
    let c = best.setting()?;
    let mut scanned = Smallest::new();
    for &m in plan.bandwidths {
        if let Some(bytes) = offer(&mut best, Setting { m, ..c }) {
            scanned.offer(bytes, m);
        }
    }
    let c = best.setting()?;
    for &gamma in plan.gammas {
        offer(&mut best, Setting { gamma, ..c });
    }
    let mut c = best.setting()?;
    if plan.bandwidth == Bandwidth::SmallestScanned {
        c.m = scanned.into_best().unwrap_or(1.0);
    }
    for beta in BETAS.into_iter().filter(|&b| b != beta0) {
        offer(&mut best, Setting { beta, ..c });
    }
    if bisect {
        grow_then_bisect(beta0, 1.5, plan.ceiling, 5, |beta| {
            offer(&mut best, Setting { beta, ..c }).is_some()
        });
    }
    best.into_best()
}

/// Whether the rank ladder's sizes so far (`met`, in rung order) have grown past their
/// smallest on the last two rungs, by more than 1 %: at low ranks, where the residual layer
/// codes nearly everything, sizes sit on a plateau and move by a few bytes either way, and
/// stopping there (measured on C3D marker takes with clips shorter than the full length)
/// kept rank 1 at 3.6× the size of the rank the ladder reaches further up.
fn past_the_best(met: &[usize]) -> bool {
    let Some(&min) = met.iter().min() else {
        return false;
    };
    let grown = |b: usize| b as f64 > min as f64 * 1.01;
    met.len() >= 3 && grown(met[met.len() - 1]) && grown(met[met.len() - 2])
}

/// Candidate ranks: a geometric ladder up to the number of coordinates.
fn rank_ladder(w: usize) -> Vec<usize> {
    let mut ks = Vec::new();
    let mut k = 1.0f64;
    while (k.round() as usize) < w {
        let v = k.round() as usize;
        if ks.last() != Some(&v) {
            ks.push(v);
        }
        k *= 1.4;
    }
    ks.push(w);
    ks
}
