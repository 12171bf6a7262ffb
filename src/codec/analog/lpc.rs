//! Linear prediction of integer signals, as FLAC does it: fixed polynomial predictors
//! (orders 0–4) and LPC of order up to [`MAX_ORDER`] from a windowed autocorrelation and
//! Levinson–Durbin, coefficients quantised to [`PRECISION`] bits with a shift. The order
//! and kind are chosen per chunk by the residual cost they estimate. Pure integer
//! prediction, so encoder and decoder agree bit for bit on every machine.

use crate::codec::rate::Smallest;

/// Highest LPC order tried (FLAC's `-8` uses 12; sampled force and EMG signals gain a
/// little more from longer predictors, and a chunk is long enough to pay for them).
pub const MAX_ORDER: usize = 32;
/// Bits of a quantised coefficient, sign included (FLAC's default for 16-bit audio).
pub const PRECISION: u32 = 15;
/// Largest coefficient shift.
pub const MAX_SHIFT: u32 = 20;

/// How a channel's values are predicted from the ones before.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Predictor {
    /// The order-`k` difference (0: the value itself, 1: the previous one, …, 4).
    Fixed(usize),
    Lpc {
        shift: u32,
        coeffs: Vec<i32>,
    },
}

impl Predictor {
    pub fn order(&self) -> usize {
        match self {
            Predictor::Fixed(k) => *k,
            Predictor::Lpc { coeffs, .. } => coeffs.len(),
        }
    }

    /// The prediction of `x[t]` from `x[t - order..t]` (`t ≥ order`). Wrapping: a corrupt
    /// stream may decode absurd values, and must give an error upstream, not a panic here.
    #[inline]
    pub fn predict(&self, x: &[i64], t: usize) -> i64 {
        match self {
            Predictor::Fixed(0) => 0,
            Predictor::Fixed(1) => x[t - 1],
            Predictor::Fixed(2) => x[t - 1].wrapping_mul(2).wrapping_sub(x[t - 2]),
            Predictor::Fixed(3) => x[t - 1]
                .wrapping_sub(x[t - 2])
                .wrapping_mul(3)
                .wrapping_add(x[t - 3]),
            Predictor::Fixed(_) => x[t - 1]
                .wrapping_mul(4)
                .wrapping_sub(x[t - 2].wrapping_mul(6))
                .wrapping_add(x[t - 3].wrapping_mul(4))
                .wrapping_sub(x[t - 4]),
            Predictor::Lpc { shift, coeffs } => {
                let mut s = 0i64;
                for (i, &c) in coeffs.iter().enumerate() {
                    s = s.wrapping_add(i64::from(c).wrapping_mul(x[t - 1 - i]));
                }
                s >> shift
            }
        }
    }

    /// Residuals `x[t] − predict(t)` for `t ≥ order`.
    pub fn residuals(&self, x: &[i64]) -> Vec<i64> {
        (self.order()..x.len())
            .map(|t| x[t].wrapping_sub(self.predict(x, t)))
            .collect()
    }
}

/// Estimated bits of coding `residuals` with an adaptive Exp-Golomb-like model: about
/// `log2(mean |r|) + 2` bits per value.
fn cost(residuals: &[i64], overhead_bits: f64) -> f64 {
    if residuals.is_empty() {
        return overhead_bits;
    }
    let sum: f64 = residuals.iter().map(|r| r.unsigned_abs() as f64).sum();
    let mean = sum / residuals.len() as f64;
    residuals.len() as f64 * ((mean + 1.0).log2() + 1.5) + overhead_bits
}

/// The predictor with the smallest estimated cost for `x`, and its residuals.
pub fn choose(x: &[i64]) -> (Predictor, Vec<i64>) {
    let warm = |order: usize| order as f64 * 20.0;
    let mut best = Smallest::new();
    let mut consider = |p: Predictor, extra: f64| {
        if p.order() > x.len() {
            return;
        }
        let r = p.residuals(x);
        best.offer(cost(&r, extra + warm(p.order())), (p, r));
    };
    for k in 0..=4 {
        consider(Predictor::Fixed(k), 8.0);
    }
    let max_order = MAX_ORDER.min(x.len() / 8);
    if max_order >= 1 {
        let lpcs = levinson(&autocorrelation(x, max_order), max_order);
        for order in [1, 2, 3, 4, 6, 8, 12, 16, 20, 24, 32] {
            if let Some(c) = lpcs.get(order - 1) {
                if let Some(p) = quantise(c) {
                    consider(p, 16.0 + order as f64 * (PRECISION as f64 + 1.0));
                }
            }
        }
    }
    let (p, r) = best.into_best().expect("fixed order 0 always fits");
    (p, r)
}

/// Autocorrelation of `x` (mean removed, Welch-windowed) at lags `0..=max_lag`.
fn autocorrelation(x: &[i64], max_lag: usize) -> Vec<f64> {
    let n = x.len();
    let mean = x.iter().map(|&v| v as f64).sum::<f64>() / n as f64;
    let half = (n as f64 - 1.0) / 2.0;
    let w: Vec<f64> = x
        .iter()
        .enumerate()
        .map(|(i, &v)| {
            let d = (i as f64 - half) / (half + 1.0);
            (v as f64 - mean) * (1.0 - d * d)
        })
        .collect();
    (0..=max_lag)
        .map(|lag| w[lag..].iter().zip(&w).map(|(a, b)| a * b).sum())
        .collect()
}

/// Levinson–Durbin: the LPC coefficients of every order `1..=max_order` (entry `k − 1` is
/// order `k`; `c[i]` multiplies `x[t − 1 − i]`). Stops early where the error vanishes.
fn levinson(r: &[f64], max_order: usize) -> Vec<Vec<f64>> {
    let mut out = Vec::with_capacity(max_order);
    if r[0] <= 0.0 {
        return out;
    }
    let mut a: Vec<f64> = Vec::with_capacity(max_order);
    let mut err = r[0] * (1.0 + 1e-9);
    for k in 0..max_order {
        let mut acc = r[k + 1];
        for (i, &ai) in a.iter().enumerate() {
            acc -= ai * r[k - i];
        }
        let refl = acc / err;
        let prev = a.clone();
        for i in 0..k {
            a[i] = prev[i] - refl * prev[k - 1 - i];
        }
        a.push(refl);
        err *= 1.0 - refl * refl;
        out.push(a.clone());
        if err <= 0.0 || !err.is_finite() {
            break;
        }
    }
    out
}

/// Coefficients to [`PRECISION`]-bit integers with a shift, rounding with error feedback
/// (as FLAC does) so the quantised filter keeps the original's response.
fn quantise(c: &[f64]) -> Option<Predictor> {
    let cmax = c.iter().fold(0.0f64, |m, v| m.max(v.abs()));
    if !(cmax.is_finite() && cmax > 0.0) {
        return None;
    }
    let log2 = cmax.log2().floor() as i32 + 1;
    let shift = (PRECISION as i32 - 1 - log2).clamp(0, MAX_SHIFT as i32) as u32;
    let lim = (1i64 << (PRECISION - 1)) - 1;
    let mut carry = 0.0;
    let coeffs = c
        .iter()
        .map(|&v| {
            let scaled = v * f64::from(1u32 << shift) + carry;
            let q = (scaled.round() as i64).clamp(-lim - 1, lim);
            carry = scaled - q as f64;
            q as i32
        })
        .collect();
    Some(Predictor::Lpc { shift, coeffs })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn smooth_signals_predict_to_small_residuals() {
        let x: Vec<i64> = (0..4000)
            .map(|t| {
                let t = t as f64 / 1000.0;
                (3000.0 * (2.0 * std::f64::consts::PI * 7.0 * t).sin()
                    + 800.0 * (2.0 * std::f64::consts::PI * 31.0 * t).cos())
                .round() as i64
            })
            .collect();
        let (p, r) = choose(&x);
        assert!(p.order() >= 2, "{p:?}");
        let mean = r.iter().map(|v| v.unsigned_abs()).sum::<u64>() as f64 / r.len() as f64;
        assert!(mean < 2.0, "mean residual {mean} with {p:?}");
        // What the decoder rebuilds from the residuals is the signal.
        let mut y = x[..p.order()].to_vec();
        y.resize(x.len(), 0);
        for (t, res) in (p.order()..x.len()).zip(&r) {
            y[t] = res + p.predict(&y, t);
        }
        assert_eq!(y, x);
    }

    #[test]
    fn short_and_constant_signals_work() {
        for x in [vec![], vec![5], vec![7; 100], vec![1, -1, 1, -1]] {
            let (p, r) = choose(&x);
            assert_eq!(r.len(), x.len() - p.order().min(x.len()));
        }
    }
}
