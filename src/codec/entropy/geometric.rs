//! Integers as tokens for [`rans`](super::rans), and the two-parameter model of a token
//! distribution that a take's side data carries instead of whole frequency tables.
//!
//! A magnitude `m` becomes a token (0–3 stand for themselves; above that, the bit length and
//! the bit below the leading one) plus `m`'s remaining low bits, which are sent raw: they
//! are close to uniform, and raw bits cost a decoder almost nothing.
//!
//! Quantised transform coefficients are close to a geometric distribution with an extra
//! mass at zero (the dead zone), so a context's distribution is sent as `P(0)` and the decay
//! `θ` of `P(m) ∝ θ^(m−1)` for `m ≥ 1`, each on a 64-step log-odds grid, plus the largest
//! token it uses: a few bits per context where a frequency table would take tens of bytes
//! — which is what makes per-take tables affordable on takes of a few seconds.
//! The decoder rebuilds tables from these numbers with IEEE-exact arithmetic only, so
//! encoder and decoder agree bit for bit on every platform.

use super::rangecoder::{Decoder as RangeDecoder, Encoder as RangeEncoder};
use super::rans::{quantise, Table, MAX_SYMBOLS, PREC};
use super::IntModel;

/// Tokens a magnitude up to `2^32 − 1` can take.
pub const TOKENS: usize = 64;

/// `(token, number of raw bits, their value)` for magnitude `m`.
#[inline]
pub fn token(m: u32) -> (u32, u32, u32) {
    if m < 4 {
        return (m, 0, 0);
    }
    let e = 31 - m.leading_zeros(); // ≥ 2
    let t = 4 + 2 * (e - 2) + ((m >> (e - 1)) & 1);
    (t, e - 1, m & ((1 << (e - 1)) - 1))
}

/// Per token: smallest magnitude, raw bits after it, bit length of its magnitudes.
const fn token_ranges() -> ([u32; TOKENS], [u32; TOKENS], [u8; TOKENS]) {
    let mut base = [0u32; TOKENS];
    let mut extra = [0u32; TOKENS];
    let mut len = [0u8; TOKENS];
    let mut t = 0;
    while t < TOKENS {
        if t < 4 {
            base[t] = t as u32;
        } else {
            let e = (t as u32 - 4) / 2 + 2;
            let msb = (t as u32 - 4) & 1;
            base[t] = (1 << e) | (msb << (e - 1));
            extra[t] = e - 1;
        }
        len[t] = (32 - base[t].leading_zeros()) as u8;
        t += 1;
    }
    (base, extra, len)
}
const RANGES: ([u32; TOKENS], [u32; TOKENS], [u8; TOKENS]) = token_ranges();
/// Smallest magnitude of each token.
pub const TOKEN_BASE: [u32; TOKENS] = RANGES.0;
/// Raw bits after each token.
pub const TOKEN_EXTRA: [u32; TOKENS] = RANGES.1;
/// Bit length of every magnitude a token stands for (0 for token 0): a value's size class
/// can be had from its token alone, before its raw bits are read.
pub const TOKEN_BITS: [u8; TOKENS] = RANGES.2;

/// Steps of the log-odds grid (`log2(p / (1 − p))` in steps of 5/16, centred on 1/2).
pub const LEVELS: u8 = 64;
const STEP: f64 = 1.241_857_812_073_484; // 2^(5/16)

/// `b^n` by repeated squaring: IEEE-exact steps, so the same on every platform.
fn powi(b: f64, n: u64) -> f64 {
    let (mut acc, mut b, mut n) = (1.0, b, n);
    while n > 0 {
        if n & 1 == 1 {
            acc *= b;
        }
        b *= b;
        n >>= 1;
    }
    acc
}

/// The probability at grid level `k`.
pub fn level_probability(k: u8) -> f64 {
    let k = i64::from(k.min(LEVELS - 1)) - i64::from(LEVELS / 2);
    // p = 1 / (1 + 2^(−l)), l = k · 5/16.
    let odds_inv = if k >= 0 {
        1.0 / powi(STEP, k as u64)
    } else {
        powi(STEP, (-k) as u64)
    };
    1.0 / (1.0 + odds_inv)
}

/// Nearest grid level to probability `p`.
pub fn level_of(p: f64) -> u8 {
    let p = p.clamp(1e-9, 1.0 - 1e-9);
    let l = (p / (1.0 - p)).log2() / (5.0 / 16.0);
    (l.round() + f64::from(LEVELS / 2)).clamp(0.0, f64::from(LEVELS - 1)) as u8
}

/// One context's distribution over tokens `0..len`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct Geometric {
    /// Level of `P(token 0)`.
    pub zero: u8,
    /// Level of the decay `θ`.
    pub decay: u8,
    /// Alphabet size: the largest token used, plus one.
    pub len: u8,
}

impl Geometric {
    /// Token weights (unnormalised probabilities).
    fn weights(&self) -> Vec<f64> {
        let p0 = level_probability(self.zero);
        let th = level_probability(self.decay);
        (0..usize::from(self.len).clamp(1, MAX_SYMBOLS))
            .map(|t| {
                if t == 0 {
                    return p0;
                }
                let lo = u64::from(TOKEN_BASE[t]);
                let hi = lo + (1u64 << TOKEN_EXTRA[t]) - 1;
                (1.0 - p0) * (powi(th, lo - 1) - powi(th, hi))
            })
            .collect()
    }

    pub fn freqs(&self) -> Vec<u32> {
        quantise(&self.weights())
    }

    pub fn table(&self) -> Table {
        Table::from_weights(&self.weights())
    }
}

/// The rANS tables of per-context models. A context without one is never used by a valid
/// stream; a one-symbol table keeps corrupt streams safe there.
pub fn tables_of(models: &[Option<Geometric>]) -> Vec<Table> {
    models
        .iter()
        .map(|m| match m {
            Some(g) => g.table(),
            None => Table::from_weights(&[1.0]),
        })
        .collect()
}

/// What an encoder gathers about one context before fitting its model.
#[derive(Debug, Clone)]
pub struct Stats {
    pub counts: [u64; TOKENS],
    /// Σ (m − 1) over non-zero magnitudes: with their count, the decay's ML estimate.
    pub excess: f64,
}

impl Default for Stats {
    fn default() -> Self {
        Stats {
            counts: [0; TOKENS],
            excess: 0.0,
        }
    }
}

impl Stats {
    #[inline]
    pub fn add(&mut self, m: u32, t: u32) {
        self.counts[t as usize] += 1;
        if m > 0 {
            self.excess += f64::from(m - 1);
        }
    }

    pub fn total(&self) -> u64 {
        self.counts.iter().sum()
    }

    /// Bits to code these tokens with `freqs` (raw bits not included).
    pub fn cost(&self, freqs: &[u32]) -> f64 {
        self.counts
            .iter()
            .enumerate()
            .filter(|(_, &c)| c > 0)
            .map(|(t, &c)| {
                let f = freqs.get(t).copied().unwrap_or(0);
                if f == 0 {
                    f64::INFINITY
                } else {
                    c as f64 * (f64::from(PREC) - f64::from(f).log2())
                }
            })
            .sum()
    }

    /// The model that codes these tokens in the fewest bits: maximum-likelihood levels,
    /// then a small search around them (the grid and the frequency quantisation move the
    /// optimum a little). `None` if the context saw nothing.
    pub fn fit(&self) -> Option<(Geometric, f64)> {
        let n = self.total();
        if n == 0 {
            return None;
        }
        let len = self.counts.iter().rposition(|&c| c > 0).unwrap_or(0) as u8 + 1;
        let nonzero = n - self.counts[0];
        let p0 = self.counts[0] as f64 / n as f64;
        let mean = if nonzero > 0 {
            self.excess / nonzero as f64
        } else {
            0.0
        };
        let mut best = Geometric {
            zero: level_of(p0),
            decay: level_of(mean / (1.0 + mean)),
            len,
        };
        let mut best_cost = self.cost(&best.freqs());
        // Coordinate descent, one level at a time, until neither parameter moves.
        loop {
            let mut moved = false;
            for (dz, dd) in [(-1i16, 0i16), (1, 0), (0, -1), (0, 1)] {
                let z = i16::from(best.zero) + dz;
                let d = i16::from(best.decay) + dd;
                if !(0..i16::from(LEVELS)).contains(&z) || !(0..i16::from(LEVELS)).contains(&d) {
                    continue;
                }
                let g = Geometric {
                    zero: z as u8,
                    decay: d as u8,
                    len,
                };
                let c = self.cost(&g.freqs());
                if c < best_cost {
                    best = g;
                    best_cost = c;
                    moved = true;
                }
            }
            if !moved {
                break;
            }
        }
        Some((best, best_cost))
    }
}

/// What [`write_models`] and [`read_models`] both keep: the used-flag and per-field models,
/// and the last used context's values (what the next is coded against).
struct SideData {
    used: super::Bit,
    m: [IntModel; 3],
    prev: [i32; 3],
}

impl SideData {
    fn new() -> Self {
        SideData {
            used: super::Bit::default(),
            m: [
                IntModel::default(),
                IntModel::default(),
                IntModel::default(),
            ],
            prev: [32, 32, 1],
        }
    }
}

/// Models of contexts coded with the adaptive range coder, each value against the previous
/// context's (neighbouring contexts have similar statistics): a few bits per context.
pub fn write_models(models: &[Option<Geometric>]) -> Vec<u8> {
    let mut enc = RangeEncoder::new();
    let SideData {
        mut used,
        mut m,
        mut prev,
    } = SideData::new();
    for g in models {
        enc.encode(&mut used, g.is_some());
        if let Some(g) = g {
            let v = [i32::from(g.zero), i32::from(g.decay), i32::from(g.len)];
            for k in 0..3 {
                m[k].encode(&mut enc, v[k] - prev[k]);
            }
            prev = v;
        }
    }
    enc.finish()
}

/// Read `n` models written by [`write_models`]; `None` if the bytes don't hold them.
pub fn read_models(bytes: &[u8], n: usize) -> Option<Vec<Option<Geometric>>> {
    let mut dec = RangeDecoder::new(bytes);
    let SideData {
        mut used,
        mut m,
        mut prev,
    } = SideData::new();
    let mut out = Vec::with_capacity(n);
    for _ in 0..n {
        if !dec.decode(&mut used) {
            out.push(None);
            continue;
        }
        let mut v = [0i32; 3];
        for k in 0..3 {
            v[k] = prev[k].checked_add(m[k].decode(&mut dec))?;
        }
        let ok = (0..i32::from(LEVELS)).contains(&v[0])
            && (0..i32::from(LEVELS)).contains(&v[1])
            && (1..=MAX_SYMBOLS as i32).contains(&v[2]);
        if !ok {
            return None;
        }
        out.push(Some(Geometric {
            zero: v[0] as u8,
            decay: v[1] as u8,
            len: v[2] as u8,
        }));
        prev = v;
    }
    (!dec.overran()).then_some(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn tokens_cover_every_magnitude_once() {
        for m in (0..5000u32).chain([u32::MAX, 1 << 31, (1 << 31) - 1, 65_537]) {
            let (t, bits, v) = token(m);
            assert!((t as usize) < TOKENS);
            assert_eq!(bits, TOKEN_EXTRA[t as usize]);
            assert_eq!(TOKEN_BASE[t as usize] + v, m, "m = {m}");
            assert_eq!(u32::from(TOKEN_BITS[t as usize]), 32 - m.leading_zeros());
        }
    }

    #[test]
    fn levels_span_the_grid_and_invert() {
        assert!((level_probability(32) - 0.5).abs() < 1e-12);
        for k in 0..LEVELS {
            assert_eq!(level_of(level_probability(k)), k);
        }
        assert!(level_probability(0) < 1e-3 && level_probability(63) > 0.998);
    }

    #[test]
    fn fitted_models_code_geometric_data_near_its_entropy() {
        // P(0) = 0.6, then θ = 0.5 for m ≥ 1.
        let mut s = Stats::default();
        let mut ideal = 0.0;
        for m in 0..40u32 {
            let p = if m == 0 {
                0.6
            } else {
                0.4 * 0.5 * 0.5f64.powi(m as i32 - 1)
            };
            let c = (p * 1e6).round() as u64;
            let (t, bits, _) = token(m);
            for _ in 0..c {
                s.add(m, t);
            }
            ideal += c as f64 * (-p.log2() - f64::from(bits));
        }
        let (g, cost) = s.fit().unwrap();
        assert!(cost < ideal * 1.005, "{cost} vs {ideal}");
        assert!((level_probability(g.zero) - 0.6).abs() < 0.03, "{g:?}");
    }

    #[test]
    fn models_round_trip_through_their_side_data() {
        let models = vec![
            Some(Geometric {
                zero: 40,
                decay: 20,
                len: 7,
            }),
            None,
            Some(Geometric {
                zero: 63,
                decay: 0,
                len: 64,
            }),
            Some(Geometric {
                zero: 0,
                decay: 63,
                len: 1,
            }),
        ];
        let b = write_models(&models);
        assert!(b.len() < 20, "{}", b.len());
        assert_eq!(read_models(&b, 4), Some(models));
        assert_eq!(read_models(&[0xff; 3], 40), None);
    }
}
