//! The entropy stage: quantised integers to bytes and back.
//!
//! Three coders are kept:
//! - **The adaptive binary range coder** ([`rangecoder`] + [`ints`]). Most codecs use it, and
//!   every live stream does: it learns as it codes, so it needs no tables up front.
//! - **rANS** ([`rans`], with [`tokens`] and [`geometric`] for the models). Whole takes of
//!   `quant` (version 2), `lsdt-clip` and `lsdt-frame` are coded with it against per-take
//!   tables stored in the header; it decodes about twice as fast.
//! - **Zigzag varints + zstd** ([`zstd_varint`]). This is the general-purpose alternative the
//!   others were measured against (`mocapstore bench --entropy`), and no codec writes it.
//!   - Against the range coder, on `quant`'s per-chunk streams over the whole corpus: the
//!     range coder (with `quant`'s contexts and inter-trajectory references) is 3–6 % smaller
//!     than zstd level 19 and 13–18× faster to encode, and zstd level 3 is as fast but 10–20 %
//!     larger.
//!   - Only zstd-19 over a whole take as one stream comes out smaller, at coarse bounds, and
//!     that gives up random access.

pub mod geometric;
pub mod ints;
pub mod io;
pub mod rangecoder;
pub mod rans;
pub mod tokens;
pub mod zstd_varint;

pub use ints::{magnitude_context, IntModel};
pub use rangecoder::{Bit, Decoder, Encoder};

/// Unsigned LEB128, for lengths and counts in bitstream headers.
pub fn put_varint(out: &mut Vec<u8>, mut v: u64) {
    while v >= 0x80 {
        out.push((v as u8) | 0x80);
        v >>= 7;
    }
    out.push(v as u8);
}

/// Read a LEB128 varint at `*pos`; `None` if truncated or longer than 64 bits.
pub fn get_varint(bytes: &[u8], pos: &mut usize) -> Option<u64> {
    let mut v = 0u64;
    for shift in (0..64).step_by(7) {
        let b = *bytes.get(*pos)?;
        *pos += 1;
        v |= u64::from(b & 0x7f) << shift;
        if b & 0x80 == 0 {
            return Some(v);
        }
    }
    None
}

#[inline]
pub fn zigzag(v: i32) -> u32 {
    ((v << 1) ^ (v >> 31)) as u32
}

#[inline]
pub fn unzigzag(u: u32) -> i32 {
    ((u >> 1) as i32) ^ -((u & 1) as i32)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn varints_and_zigzag_round_trip() {
        let mut out = Vec::new();
        for v in [0u64, 1, 127, 128, 300, u64::MAX] {
            put_varint(&mut out, v);
        }
        let mut pos = 0;
        for v in [0u64, 1, 127, 128, 300, u64::MAX] {
            assert_eq!(get_varint(&out, &mut pos), Some(v));
        }
        assert_eq!(get_varint(&out, &mut pos), None);
        assert_eq!(get_varint(&[0xff; 12], &mut 0), None);
        for v in [0, 1, -1, i32::MAX, i32::MIN] {
            assert_eq!(unzigzag(zigzag(v)), v);
        }
        assert_eq!(zigzag(-1), 1);
    }
}
