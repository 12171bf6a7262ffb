//! Static-model rANS (Duda 2013, in the two-state interleaved, 16-bit-renormalising form of
//! Giesen's `ryg_rans`), with a plain bit stream beside it for raw bits.
//!
//! Why a second entropy coder: the adaptive binary coder spends one serial multiply-compare
//! per *binary decision* — 300–400 of them per frame for a 38-point skeleton — which caps a
//! frame decoder near 0.3 M frames/s. rANS decodes a whole multi-symbol token per table
//! lookup, and two interleaved states let consecutive symbols overlap in the pipeline. The
//! price is a model fixed before coding: [`Table`]s are built once per take from parameters
//! the encoder fitted (see `geometric`), so this suits coders that see a whole take first.
//!
//! Decoding never panics on corrupt input: reads past the end yield zeros, every state maps
//! to a valid table slot, and [`Decoder::finished_cleanly`] tells whether the states came back
//! to where the encoder started (a cheap integrity check for a chunk).

/// Probabilities are quantised to multiples of `1 / 2^PREC`. Ten bits keep a context's
/// decoding table at 1 KiB (a hundred contexts stay in cache) and cost about 0.1 % in size
/// against twelve on mocap coefficients.
pub const PREC: u32 = 10;
const M: u32 = 1 << PREC;
/// States live in `[L, 2^32)`; a state that falls below `L` takes in 16 more bits.
const L: u32 = 1 << 16;
/// Interleaved states: symbol `k` is coded by state `k mod STATES`, so that the decoder
/// works on consecutive symbols at once (one state's chain is two dependent table loads
/// and a multiply per symbol). Four were measured too: no faster on the lsdt-frame decoder,
/// whose loop is then bound by instruction throughput, and 8 bytes more per chunk.
pub const STATES: usize = 2;
/// Largest alphabet a table can have.
pub const MAX_SYMBOLS: usize = 64;

/// Quantise `weights` (any non-negative scale; at most [`MAX_SYMBOLS`] of them) to
/// frequencies that sum to `2^PREC`, every symbol keeping at least 1. Deterministic: the
/// decoder rebuilds the same table from the same weights on any platform (only IEEE-exact
/// operations are used).
pub fn quantise(weights: &[f64]) -> Vec<u32> {
    let n = weights.len().clamp(1, MAX_SYMBOLS);
    let w = &weights[..weights.len().min(n)];
    let total: f64 = w.iter().map(|v| v.max(0.0)).sum();
    let spare = f64::from(M - n as u32);
    let mut freq: Vec<u32> = (0..n)
        .map(|i| {
            let p = if total > 0.0 {
                w.get(i).copied().unwrap_or(0.0).max(0.0) / total
            } else {
                1.0 / n as f64
            };
            1 + (p * spare).floor() as u32
        })
        .collect();
    // Hand what rounding left over to the most probable symbols, largest first.
    let mut left = M - freq.iter().sum::<u32>();
    let mut order: Vec<usize> = (0..n).collect();
    order.sort_by(|&a, &b| freq[b].cmp(&freq[a]).then(a.cmp(&b)));
    let mut k = 0;
    while left > 0 {
        freq[order[k % n]] += 1;
        left -= 1;
        k += 1;
    }
    freq
}

/// A distribution over `0..len` quantised for rANS.
#[derive(Clone)]
pub struct Table {
    freq: Vec<u16>,
    cum: Vec<u16>,
}

impl std::fmt::Debug for Table {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Table").field("freq", &self.freq).finish()
    }
}

impl Table {
    /// The table of [`quantise`]`(weights)`.
    pub fn from_weights(weights: &[f64]) -> Table {
        Table::from_freqs(&quantise(weights))
    }

    fn from_freqs(freq: &[u32]) -> Table {
        debug_assert_eq!(freq.iter().sum::<u32>(), M);
        let mut cum = Vec::with_capacity(freq.len());
        let mut c = 0u32;
        for &f in freq {
            cum.push(c as u16);
            c += f;
        }
        Table {
            freq: freq.iter().map(|&f| f as u16).collect(),
            cum,
        }
    }

    /// Alphabet size.
    pub fn len(&self) -> usize {
        self.freq.len()
    }

    pub fn is_empty(&self) -> bool {
        self.freq.is_empty()
    }

    /// Cost of coding `symbol` with this table, in bits (encoder-side estimates only).
    pub fn cost(&self, symbol: usize) -> f64 {
        match self.freq.get(symbol) {
            Some(&f) => f64::from(PREC) - f64::from(f).log2(),
            None => f64::INFINITY,
        }
    }
}

/// The decoder's view of a take's tables, indexed by context: every context's slot→symbol
/// map (one byte per slot) back to back, then each symbol's frequency and first slot
/// packed in one word. A context is addressed by the offset of its first slot
/// ([`TableSet::offset`]), so a decoder whose context is a sum of parts can keep each part
/// as an offset and reach the next symbol's table with one add: on the decoder's critical
/// path (symbol → next context → its table) every load and multiply counts.
pub struct TableSet {
    symbols: Vec<u8>,
    /// `freq | cum << 16`, [`MAX_SYMBOLS`] per context.
    entries: Vec<u32>,
}

impl TableSet {
    pub fn new(tables: &[Table]) -> TableSet {
        let mut symbols = vec![0u8; tables.len() << PREC];
        let mut entries = vec![0u32; tables.len() * MAX_SYMBOLS];
        for (c, t) in tables.iter().enumerate() {
            let slots = &mut symbols[c << PREC..(c + 1) << PREC];
            for (s, (&cum, &freq)) in t.cum.iter().zip(&t.freq).enumerate() {
                entries[c * MAX_SYMBOLS + s] = u32::from(freq) | u32::from(cum) << 16;
                slots[usize::from(cum)..usize::from(cum) + usize::from(freq)].fill(s as u8);
            }
        }
        TableSet { symbols, entries }
    }

    /// The offset of context `ctx` (offsets of contexts `a + b` are the sums of theirs).
    pub const fn offset(ctx: usize) -> usize {
        ctx << PREC
    }
}

/// Whether a stream of `bytes` coding `symbols` symbols refills its states often enough
/// that [`Decoder::get_at`] should do it without a branch: more than 1.5 bits per symbol,
/// i.e. a refill every ~10 symbols or more often. Measured on CMU 01_03's lsdt-frame
/// chunks: branchless decodes 5–7 % faster at 1.8–2.3 bits per symbol (max 1 and 0.5 mm),
/// the same at 1.3, and 6 % slower at 0.7–0.8 (max 5 mm, mean 3 mm).
pub fn refills_often(bytes: usize, symbols: usize) -> bool {
    bytes * 8 * 2 > symbols * 3
}

/// Collects symbols in decoding order; [`Encoder::finish`] codes them (rANS runs backwards).
#[derive(Default)]
pub struct Encoder {
    /// `(cum, freq)` per symbol.
    symbols: Vec<(u16, u16)>,
}

impl Encoder {
    pub fn new() -> Self {
        Self::default()
    }

    /// Queue `symbol` (which must be in `table`'s alphabet).
    #[inline]
    pub fn put(&mut self, table: &Table, symbol: usize) {
        debug_assert!(symbol < table.len(), "symbol {symbol} outside the table");
        self.symbols.push((table.cum[symbol], table.freq[symbol]));
    }

    /// The coded stream: the final states, then 16-bit words in the order they are read.
    pub fn finish(self) -> Vec<u8> {
        let mut x = [L; STATES];
        let mut words: Vec<u16> = Vec::with_capacity(self.symbols.len() / 4 + 4);
        for (k, &(cum, freq)) in self.symbols.iter().enumerate().rev() {
            let s = &mut x[k % STATES];
            let (cum, freq) = (u32::from(cum), u32::from(freq));
            let x_max = (u64::from(L >> PREC) << 16) * u64::from(freq);
            while u64::from(*s) >= x_max {
                words.push(*s as u16);
                *s >>= 16;
            }
            *s = ((*s / freq) << PREC) + (*s % freq) + cum;
        }
        let mut out = Vec::with_capacity(4 * STATES + 2 * words.len());
        for s in x {
            out.extend_from_slice(&s.to_le_bytes());
        }
        for w in words.iter().rev() {
            out.extend_from_slice(&w.to_le_bytes());
        }
        out
    }
}

pub struct Decoder<'a> {
    /// The states of the next [`STATES`] symbols, in order.
    x: [u32; STATES],
    input: &'a [u8],
    pos: usize,
}

impl<'a> Decoder<'a> {
    pub fn new(input: &'a [u8]) -> Self {
        let mut d = Decoder {
            x: [0; STATES],
            input,
            pos: 0,
        };
        for k in 0..STATES {
            d.x[k] = u32::from(d.word()) | u32::from(d.word()) << 16;
        }
        d
    }

    /// The word at the read position (zero past the end).
    #[inline]
    fn peek(&self) -> u16 {
        match self.input.get(self.pos..self.pos + 2) {
            Some(b) => u16::from_le_bytes([b[0], b[1]]),
            None => 0,
        }
    }

    #[inline]
    fn word(&mut self) -> u16 {
        let w = self.peek();
        self.pos += 2;
        w
    }

    /// The next symbol, coded with table `ctx` of `set`.
    #[inline]
    pub fn get_in(&mut self, set: &TableSet, ctx: usize) -> usize {
        self.get_at::<false>(set, TableSet::offset(ctx))
    }

    /// The next symbol, coded with the table at `offset` ([`TableSet::offset`]) of `set`.
    ///
    /// `BRANCHLESS` says how a state that ran low takes in its next word. With a branch, the
    /// common case costs nothing, but whether a state runs low is as random as the symbols:
    /// once a stream refills every few symbols ([`refills_often`]) the mispredictions cost
    /// more than reading the word every time and keeping it only when needed.
    #[inline(always)]
    pub fn get_at<const BRANCHLESS: bool>(&mut self, set: &TableSet, offset: usize) -> usize {
        let x0 = self.x[0];
        let slot = x0 & (M - 1);
        let s = usize::from(set.symbols[offset + slot as usize]) & (MAX_SYMBOLS - 1);
        let e = set.entries[(offset >> (PREC - MAX_SYMBOLS.trailing_zeros())) + s];
        let mut x = (e & 0xffff) * (x0 >> PREC) + slot - (e >> 16);
        if BRANCHLESS {
            let low = x < L;
            let w = self.peek();
            x = if low { (x << 16) | u32::from(w) } else { x };
            self.pos += 2 * usize::from(low);
        } else if x < L {
            x = (x << 16) | u32::from(self.word());
        }
        // The next state codes the next symbol; this one waits for its turn again.
        self.x.copy_within(1.., 0);
        self.x[STATES - 1] = x;
        s
    }

    /// Whether the stream was consumed exactly and every state returned to the encoder's
    /// start — false for a truncated or corrupted chunk (or a decoder that read a different
    /// number of symbols than were coded).
    pub fn finished_cleanly(&self) -> bool {
        self.pos == self.input.len() && self.x == [L; STATES]
    }
}

/// Raw bits beside the rANS stream (signs, low mantissa bits): least significant first.
#[derive(Default)]
pub struct BitWriter {
    acc: u64,
    n: u32,
    out: Vec<u8>,
}

impl BitWriter {
    pub fn new() -> Self {
        Self::default()
    }

    /// Append the low `bits` (≤ 32) bits of `value`.
    #[inline]
    pub fn put(&mut self, value: u32, bits: u32) {
        debug_assert!(bits <= 32);
        if bits == 0 {
            return;
        }
        self.acc |= u64::from(value & (u32::MAX >> (32 - bits))) << self.n;
        self.n += bits;
        while self.n >= 8 {
            self.out.push(self.acc as u8);
            self.acc >>= 8;
            self.n -= 8;
        }
    }

    pub fn finish(mut self) -> Vec<u8> {
        if self.n > 0 {
            self.out.push(self.acc as u8);
        }
        self.out
    }
}

pub struct BitReader<'a> {
    acc: u64,
    n: u32,
    input: &'a [u8],
    pos: usize,
}

impl<'a> BitReader<'a> {
    pub fn new(input: &'a [u8]) -> Self {
        BitReader {
            acc: 0,
            n: 0,
            input,
            pos: 0,
        }
    }

    /// The next `bits` (≤ 32) bits; zeros past the end.
    #[inline]
    pub fn get(&mut self, bits: u32) -> u32 {
        debug_assert!(bits <= 32);
        if self.n < bits {
            self.refill();
        }
        let v = (self.acc & !(u64::MAX << bits)) as u32;
        self.acc >>= bits;
        self.n -= bits;
        v
    }

    #[inline]
    fn refill(&mut self) {
        if let Some(b) = self.input.get(self.pos..self.pos + 4) {
            let w = u32::from_le_bytes([b[0], b[1], b[2], b[3]]);
            self.acc |= u64::from(w) << self.n;
            self.n += 32;
            self.pos += 4;
            return;
        }
        while self.n <= 56 {
            self.acc |= u64::from(self.input.get(self.pos).copied().unwrap_or(0)) << self.n;
            self.n += 8;
            self.pos += 1;
        }
    }

    /// Whether exactly the input was read, up to the padding of its last byte.
    pub fn finished_cleanly(&self) -> bool {
        let consumed = self.pos * 8 - self.n as usize;
        consumed.div_ceil(8) == self.input.len()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn xorshift(s: &mut u64) -> u64 {
        *s ^= *s << 13;
        *s ^= *s >> 7;
        *s ^= *s << 17;
        *s
    }

    #[test]
    fn tables_keep_every_symbol_and_sum_to_one() {
        let t = Table::from_weights(&[1000.0, 1.0, 0.0, 1e-9, 5.0]);
        assert_eq!(t.freq.iter().map(|&f| u32::from(f)).sum::<u32>(), M);
        assert!(t.freq.iter().all(|&f| f >= 1));
        assert!(u32::from(t.freq[0]) > M * 9 / 10);
        let one = Table::from_weights(&[3.0]);
        assert_eq!(one.freq, vec![M as u16]);
        assert_eq!(one.cost(0), 0.0);
    }

    #[test]
    fn round_trips_interleaved_symbols_and_bits_near_entropy() {
        let skewed = Table::from_weights(&[0.7, 0.2, 0.05, 0.03, 0.02]);
        let flat = Table::from_weights(&[1.0; 64]);
        let one = Table::from_weights(&[1.0]);
        let mut rng = 7u64;
        let mut items = Vec::new();
        for i in 0..50_000 {
            let r = xorshift(&mut rng);
            let (t, s) = match i % 3 {
                0 => {
                    let u = (r % 100) as usize;
                    let s = match u {
                        0..70 => 0,
                        70..90 => 1,
                        90..95 => 2,
                        95..98 => 3,
                        _ => 4,
                    };
                    (0, s)
                }
                1 => (1, (r >> 8) as usize % 64),
                _ => (2, 0),
            };
            items.push((t, s, (r >> 32) as u32 & 0x1fff));
        }
        let tables = [skewed, flat, one];
        let mut enc = Encoder::new();
        let mut bits = BitWriter::new();
        for &(t, s, raw) in &items {
            enc.put(&tables[t], s);
            bits.put(raw, 13);
        }
        let set = TableSet::new(&tables);
        let coded = enc.finish();
        let raw = bits.finish();
        let mut dec = Decoder::new(&coded);
        let mut branchless = Decoder::new(&coded);
        let mut br = BitReader::new(&raw);
        for &(t, s, r) in &items {
            assert_eq!(dec.get_in(&set, t), s);
            assert_eq!(branchless.get_at::<true>(&set, TableSet::offset(t)), s);
            assert_eq!(br.get(13), r);
        }
        assert!(dec.finished_cleanly());
        assert!(branchless.finished_cleanly());
        assert!(br.finished_cleanly());
        // Entropy: H(0.7,0.2,0.05,0.03,0.02) ≈ 1.29 bits, 6 bits flat, 0 for the certain one.
        let ideal = 50_000.0 / 3.0 * (1.29 + 6.0) / 8.0;
        assert!(
            (coded.len() as f64) < ideal * 1.01 + 16.0,
            "{}",
            coded.len()
        );
    }

    #[test]
    fn corrupt_or_short_input_decodes_garbage_without_panicking() {
        let set = TableSet::new(&[Table::from_weights(&[0.5, 0.25, 0.25])]);
        for input in [&[][..], &[1, 2, 3], &[0xff; 40]] {
            let mut d = Decoder::new(input);
            let mut branchless = Decoder::new(input);
            for _ in 0..1000 {
                assert!(d.get_in(&set, 0) < 3);
                assert!(branchless.get_at::<true>(&set, 0) < 3);
            }
            assert!(!d.finished_cleanly());
            assert!(!branchless.finished_cleanly());
            let mut b = BitReader::new(input);
            for _ in 0..100 {
                b.get(17);
            }
            assert!(!b.finished_cleanly());
        }
    }
}
