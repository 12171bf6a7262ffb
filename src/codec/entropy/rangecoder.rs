//! An adaptive binary range coder (the LZMA design): each binary decision is coded with a
//! probability that adapts to the decisions seen so far in its context.
//!
//! Why a binary coder: every integer we code (quantised coefficients, residuals, deltas) is
//! turned into a few binary decisions with their own contexts (see `ints`), which adapts to
//! each stream's statistics within a few hundred symbols — the regime of a single chunk,
//! where zstd has too little data to learn from.

const PROB_BITS: u32 = 11;
const PROB_ONE: u16 = 1 << PROB_BITS;
const ADAPT_SHIFT: u32 = 5;
const TOP: u32 = 1 << 24;

/// Probability that the next bit is 0, in 1/2048ths.
#[derive(Debug, Clone, Copy)]
pub struct Bit(u16);

impl Default for Bit {
    fn default() -> Self {
        Bit(PROB_ONE / 2)
    }
}

impl Bit {
    /// Both outcomes computed and one selected: a decoder's bits are unpredictable, and a
    /// mispredicted branch per decision cost more than the arithmetic.
    #[inline(always)]
    fn update(&mut self, bit: bool) {
        let down = self.0 - (self.0 >> ADAPT_SHIFT);
        let up = self.0 + ((PROB_ONE - self.0) >> ADAPT_SHIFT);
        self.0 = if bit { down } else { up };
    }
}

pub struct Encoder {
    low: u64,
    range: u32,
    cache: u8,
    cache_size: u64,
    out: Vec<u8>,
}

impl Default for Encoder {
    fn default() -> Self {
        Self::new()
    }
}

impl Encoder {
    pub fn new() -> Self {
        Encoder {
            low: 0,
            range: u32::MAX,
            cache: 0,
            cache_size: 1,
            out: Vec::new(),
        }
    }

    #[inline]
    pub fn encode(&mut self, p: &mut Bit, bit: bool) {
        let bound = (self.range >> PROB_BITS) * u32::from(p.0);
        if bit {
            self.low += u64::from(bound);
            self.range -= bound;
        } else {
            self.range = bound;
        }
        p.update(bit);
        while self.range < TOP {
            self.range <<= 8;
            self.shift_low();
        }
    }

    /// Equiprobable bits, most significant first.
    #[inline]
    pub fn encode_direct(&mut self, value: u32, bits: u32) {
        for i in (0..bits).rev() {
            self.range >>= 1;
            if (value >> i) & 1 == 1 {
                self.low += u64::from(self.range);
            }
            while self.range < TOP {
                self.range <<= 8;
                self.shift_low();
            }
        }
    }

    fn shift_low(&mut self) {
        if self.low < 0xFF00_0000 || self.low > 0xFFFF_FFFF {
            let carry = (self.low >> 32) as u8;
            let mut temp = self.cache;
            loop {
                self.out.push(temp.wrapping_add(carry));
                temp = 0xFF;
                self.cache_size -= 1;
                if self.cache_size == 0 {
                    break;
                }
            }
            self.cache = ((self.low >> 24) & 0xFF) as u8;
        }
        self.cache_size += 1;
        self.low = (self.low & 0x00FF_FFFF) << 8;
    }

    pub fn finish(mut self) -> Vec<u8> {
        for _ in 0..5 {
            self.shift_low();
        }
        // The first byte is always the initial zero cache; drop it.
        self.out.remove(0);
        self.out
    }
}

/// Decoder over a byte slice. Reading past the end yields zeros, so corrupt input decodes
/// to garbage values (caught by checksums and shape checks upstream), never a panic.
pub struct Decoder<'a> {
    code: u32,
    range: u32,
    input: &'a [u8],
    pos: usize,
}

impl<'a> Decoder<'a> {
    pub fn new(input: &'a [u8]) -> Self {
        let mut d = Decoder {
            code: 0,
            range: u32::MAX,
            input,
            pos: 0,
        };
        for _ in 0..4 {
            d.code = (d.code << 8) | u32::from(d.next_byte());
        }
        d
    }

    #[inline]
    fn next_byte(&mut self) -> u8 {
        let b = self.input.get(self.pos).copied().unwrap_or(0);
        self.pos += 1;
        b
    }

    /// Whether the decoder has read past the end of its input (a sign of corruption).
    pub fn overran(&self) -> bool {
        self.pos > self.input.len() + 4
    }

    /// One decision. Branch-free (masks instead of `if`): the decision is what the stream
    /// is unsure of, so a branch on it mispredicts about as often as it costs bits.
    #[inline(always)]
    pub fn decode(&mut self, p: &mut Bit) -> bool {
        let bound = (self.range >> PROB_BITS) * u32::from(p.0);
        let bit = self.code >= bound;
        let mask = u32::from(bit).wrapping_neg();
        self.code -= bound & mask;
        self.range = (bound & !mask) | (self.range.wrapping_sub(bound) & mask);
        p.update(bit);
        while self.range < TOP {
            self.range <<= 8;
            self.code = (self.code << 8) | u32::from(self.next_byte());
        }
        bit
    }

    #[inline]
    pub fn decode_direct(&mut self, bits: u32) -> u32 {
        let mut v = 0u32;
        for _ in 0..bits {
            self.range >>= 1;
            let bit = u32::from(self.code >= self.range);
            self.code -= self.range & bit.wrapping_neg();
            v = (v << 1) | bit;
            while self.range < TOP {
                self.range <<= 8;
                self.code = (self.code << 8) | u32::from(self.next_byte());
            }
        }
        v
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn round_trips_skewed_and_direct_bits() {
        let mut rng = 12345u64;
        let mut bits = Vec::new();
        for i in 0..20_000 {
            rng ^= rng << 13;
            rng ^= rng >> 7;
            rng ^= rng << 17;
            // 95 % zeros in context 0, fair coin in context 1.
            let ctx = i % 2;
            let bit = if ctx == 0 {
                rng % 100 < 5
            } else {
                rng.is_multiple_of(2)
            };
            bits.push((ctx, bit, (rng >> 20) as u32 & 0x3ff));
        }
        let mut enc = Encoder::new();
        let mut p = [Bit::default(); 2];
        for &(ctx, bit, direct) in &bits {
            enc.encode(&mut p[ctx], bit);
            enc.encode_direct(direct, 10);
        }
        let out = enc.finish();
        let mut dec = Decoder::new(&out);
        let mut p = [Bit::default(); 2];
        for &(ctx, bit, direct) in &bits {
            assert_eq!(dec.decode(&mut p[ctx]), bit);
            assert_eq!(dec.decode_direct(10), direct);
        }
        assert!(!dec.overran());
        // 10 000 skewed bits (H(0.05) ≈ 0.29) + 10 000 fair + 200 000 direct ≈ 27.6 KB.
        assert!(out.len() < 27_600 + 600, "{}", out.len());
    }

    #[test]
    fn empty_and_garbage_input_do_not_panic() {
        let mut d = Decoder::new(&[]);
        let mut p = Bit::default();
        for _ in 0..100 {
            d.decode(&mut p);
        }
        assert!(d.overran());
    }
}
