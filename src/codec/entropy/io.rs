//! Coding written once for both directions: the encoder codes what it is given and returns
//! it, the decoder ignores it and returns what it decodes. A codec that writes its chunk
//! coding as one function over [`Io`] cannot have an encoder and a decoder that disagree on
//! the order of decisions or their contexts — and a closed-loop encoder gets the decoder's
//! reconstruction for free.

use super::ints::IntModel;
use super::rangecoder::{Bit, Decoder, Encoder};
use crate::codec::error::Result;

/// Residuals at least this large are escaped and written as 64 raw bits.
const BIG: i64 = 1 << 30;

/// One direction of the range coder: the encoder codes what it is given and returns it, the
/// decoder ignores it and returns what it decodes. Coding is written once, over this, so the
/// two sides cannot disagree on the order of decisions or on their contexts.
pub trait Io {
    fn bit(&mut self, p: &mut Bit, b: bool) -> bool;
    fn int(&mut self, m: &mut IntModel, v: i32) -> i32;
    fn raw(&mut self, v: u32, bits: u32) -> u32;
    fn encoding(&self) -> bool;
    /// A trial run that codes nothing and only measures what decodes ([`Dry`]): coding
    /// that cannot change a measured position may skip itself.
    fn dry(&self) -> bool {
        false
    }
}

impl Io for Encoder {
    fn bit(&mut self, p: &mut Bit, b: bool) -> bool {
        self.encode(p, b);
        b
    }
    fn int(&mut self, m: &mut IntModel, v: i32) -> i32 {
        m.encode(self, v);
        v
    }
    fn raw(&mut self, v: u32, bits: u32) -> u32 {
        self.encode_direct(v, bits);
        v
    }
    fn encoding(&self) -> bool {
        true
    }
}

impl Io for Decoder<'_> {
    fn bit(&mut self, p: &mut Bit, _: bool) -> bool {
        self.decode(p)
    }
    fn int(&mut self, m: &mut IntModel, _: i32) -> i32 {
        m.decode(self)
    }
    fn raw(&mut self, _: u32, bits: u32) -> u32 {
        self.decode_direct(bits)
    }
    fn encoding(&self) -> bool {
        false
    }
}

/// The encoder's side of [`Io`] without a range coder: what rate control's trial runs code
/// through when only the decoded result matters.
pub struct Dry;

impl Io for Dry {
    fn bit(&mut self, _: &mut Bit, b: bool) -> bool {
        b
    }
    fn int(&mut self, _: &mut IntModel, v: i32) -> i32 {
        v
    }
    fn raw(&mut self, v: u32, _: u32) -> u32 {
        v
    }
    fn encoding(&self) -> bool {
        true
    }
    fn dry(&self) -> bool {
        true
    }
}

/// A residual: small ones through the adaptive model, the rare huge one escaped to 64 raw
/// bits.
pub fn code_residual<I: Io>(io: &mut I, model: &mut IntModel, r: i64) -> Result<i64> {
    let small = r.unsigned_abs() < BIG as u64;
    let v = io.int(model, if small { r as i32 } else { i32::MAX });
    if v != i32::MAX {
        return Ok(i64::from(v));
    }
    let u = r as u64;
    let hi = io.raw((u >> 32) as u32, 32);
    let lo = io.raw(u as u32, 32);
    Ok(((u64::from(hi) << 32) | u64::from(lo)) as i64)
}
