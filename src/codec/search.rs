//! The step search of the rate-controlled codecs that code each chunk at a step index of
//! their own (`rot`, `pga`): the largest index whose decoded chunk meets the bound.

use super::error::Result;

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

#[cfg(test)]
mod tests {
    use super::*;

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
