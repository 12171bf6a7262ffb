//! Signed integers as binary decisions for the range coder: a zero flag, a sign, the bit
//! length in unary (Exp-Golomb style), the bit below the leading one adaptively, the rest
//! raw. Each decision has its own adaptive probability, so a stream of mostly small values
//! costs little more than its entropy.

use super::rangecoder::{Bit, Decoder, Encoder};

const MAX_EXP: usize = 31;

/// Adaptive model of one kind of integer (one context).
#[derive(Debug, Clone)]
pub struct IntModel {
    zero: Bit,
    sign: Bit,
    exp: [Bit; MAX_EXP + 1],
    mant: [Bit; MAX_EXP + 1],
}

impl Default for IntModel {
    fn default() -> Self {
        IntModel {
            zero: Bit::default(),
            sign: Bit::default(),
            exp: [Bit::default(); MAX_EXP + 1],
            mant: [Bit::default(); MAX_EXP + 1],
        }
    }
}

impl IntModel {
    #[inline]
    pub fn encode(&mut self, enc: &mut Encoder, v: i32) {
        enc.encode(&mut self.zero, v != 0);
        if v == 0 {
            return;
        }
        enc.encode(&mut self.sign, v < 0);
        let m = v.unsigned_abs(); // ≥ 1
        let e = (31 - m.leading_zeros()) as usize; // bit length - 1
        for i in 0..e {
            enc.encode(&mut self.exp[i], true);
        }
        if e < MAX_EXP {
            enc.encode(&mut self.exp[e], false);
        }
        if e >= 1 {
            enc.encode(&mut self.mant[e], (m >> (e - 1)) & 1 == 1);
            if e >= 2 {
                enc.encode_direct(m & ((1 << (e - 1)) - 1), (e - 1) as u32);
            }
        }
    }

    #[inline]
    pub fn decode(&mut self, dec: &mut Decoder<'_>) -> i32 {
        if !dec.decode(&mut self.zero) {
            return 0;
        }
        let negative = dec.decode(&mut self.sign);
        let mut e = 0;
        while e < MAX_EXP && dec.decode(&mut self.exp[e]) {
            e += 1;
        }
        let mut m: u32 = 1;
        if e >= 1 {
            m = (m << 1) | u32::from(dec.decode(&mut self.mant[e]));
            if e >= 2 {
                m = (m << (e - 1)) | dec.decode_direct((e - 1) as u32);
            }
        }
        // Corrupt streams can describe 2^31, which has no positive i32; saturate.
        let m = m.min(i32::MAX as u32) as i32;
        if negative {
            -m
        } else {
            m
        }
    }
}

/// Context index from the size of a neighbouring value: 0 for 0, then its bit length,
/// capped, so that "near a big value" and "near a small value" learn separate statistics.
#[inline]
pub fn magnitude_context(v: i32, contexts: usize) -> usize {
    let bits = (32 - v.unsigned_abs().leading_zeros()) as usize;
    bits.min(contexts - 1)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn round_trips_extremes_and_small_values() {
        let values: Vec<i32> = [
            0,
            1,
            -1,
            2,
            -2,
            3,
            7,
            -8,
            255,
            -256,
            65_535,
            i32::MAX,
            -i32::MAX,
        ]
        .into_iter()
        .chain((-50..50).map(|v| v * v * v))
        .collect();
        let mut enc = Encoder::new();
        let mut m = IntModel::default();
        for &v in &values {
            m.encode(&mut enc, v);
        }
        let bytes = enc.finish();
        let mut dec = Decoder::new(&bytes);
        let mut m = IntModel::default();
        for &v in &values {
            assert_eq!(m.decode(&mut dec), v);
        }
    }

    #[test]
    fn mostly_zero_streams_are_cheap() {
        let values: Vec<i32> = (0..10_000).map(|i| i32::from(i % 50 == 0)).collect();
        let mut enc = Encoder::new();
        let mut m = IntModel::default();
        for &v in &values {
            m.encode(&mut enc, v);
        }
        // Entropy of a 2 % flag is 0.14 bit: ~180 bytes for 10 000 values.
        assert!(enc.finish().len() < 260);
    }
}
