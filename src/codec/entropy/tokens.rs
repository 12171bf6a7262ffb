//! Integers as a rANS-coded token and raw bits beside it — the symbol layout of the
//! per-take-tables entropy stages (`lsdt-frame` version 2+, `lsdt-clip` version 2). A
//! magnitude's token ([`token`]) says its size; its low bits, and a signed value's sign, go to
//! the raw bit stream, where modelling them would gain next to nothing.

use super::geometric::{token, TOKENS, TOKEN_BASE, TOKEN_EXTRA};
use super::rans::{self, BitReader, TableSet};

/// A signed value as `(magnitude, token, raw bit count, raw bits)`: the magnitude's low bits,
/// then the sign (none for zero).
#[inline]
pub fn signed_token(v: i32) -> (u32, u32, u32, u32) {
    let m = v.unsigned_abs();
    let (t, bits, extra) = token(m);
    if t == 0 {
        (0, 0, 0, 0)
    } else {
        (m, t, bits + 1, (extra << 1) | u32::from(v < 0))
    }
}

/// Raw bits after each token of a signed value: its low bits and the sign.
pub const SIGNED_RAW: [u32; TOKENS] = {
    let mut r = [0u32; TOKENS];
    let mut t = 1;
    while t < TOKENS {
        r[t] = TOKEN_EXTRA[t] + 1;
        t += 1;
    }
    r
};

/// The signed value of token `t` (< 64) and its raw bits, without a branch. Tokens cover
/// `u32` exactly; corrupt streams that describe more than an `i32` holds wrap (they fail the
/// chunk's end check) rather than panic.
#[inline]
pub fn signed(t: usize, raw: u32) -> i32 {
    let m = TOKEN_BASE[t & (TOKENS - 1)].wrapping_add(raw >> 1) as i32;
    let s = (raw & 1) as i32;
    (m ^ s.wrapping_neg()).wrapping_add(s)
}

/// The next signed value, its token coded with table `ctx` of `set`.
#[inline]
pub fn get_signed(
    dec: &mut rans::Decoder<'_>,
    bits: &mut BitReader<'_>,
    set: &TableSet,
    ctx: usize,
) -> i32 {
    let t = dec.get_in(set, ctx);
    signed(t, bits.get(SIGNED_RAW[t & (TOKENS - 1)]))
}

/// The next unsigned value, its token coded with table `ctx` of `set`.
#[inline]
pub fn get_unsigned(
    dec: &mut rans::Decoder<'_>,
    bits: &mut BitReader<'_>,
    set: &TableSet,
    ctx: usize,
) -> u32 {
    let t = dec.get_in(set, ctx) & (TOKENS - 1);
    TOKEN_BASE[t].saturating_add(bits.get(TOKEN_EXTRA[t]))
}
