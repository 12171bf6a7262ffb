//! MDTT's per-take header block: clip shape, steps, mean and the spatial basis.

use crate::codec::entropy::{Decoder, Encoder, IntModel};
use crate::codec::error::{malformed, Result};
use crate::codec::measure::quantise;
use crate::codec::wire::{Reader, Writer};

/// Everything a chunk decoder needs, parsed once from the header.
#[derive(Debug, Clone, PartialEq)]
pub struct Params {
    pub clip: usize,
    pub k: usize,
    pub l: usize,
    pub coef_step: f64,
    /// Bound the residual layer enforces; 0 when there is none (mean bounds).
    pub residual_t: f64,
    /// Column b of the basis holds multiples of `2^-basis_bits[b]` (the paper: 16 for all).
    pub basis_bits: Vec<u8>,
    pub mean: Vec<f32>,
    /// Column-major (`k` columns of `w`), already dequantised: column b is contiguous, which
    /// is the order the decoder's inner loop runs in.
    pub basis: Vec<f32>,
}

/// Finest basis precision the format allows.
pub const MAX_BASIS_BITS: u8 = 20;

/// Round a basis entry to `bits` fractional bits, as stored.
pub fn quantise_basis(v: f64, bits: u8) -> (i32, f32) {
    let scale = f64::from(1u32 << bits);
    let q = quantise(v * scale);
    (q, (f64::from(q) / scale) as f32)
}

/// Context of a basis entry: its column's precision, which sets the size of its integers.
fn basis_context(bits: u8) -> usize {
    usize::from(bits.min(MAX_BASIS_BITS))
}
const BASIS_CONTEXTS: usize = MAX_BASIS_BITS as usize + 1;

impl Params {
    pub fn width(&self) -> usize {
        self.mean.len()
    }

    pub fn to_bytes(&self) -> Vec<u8> {
        let mut w = Writer::new();
        w.u32(self.clip as u32)
            .u32(self.k as u32)
            .u32(self.l as u32)
            .f64(self.coef_step)
            .f64(self.residual_t)
            .bytes(&self.basis_bits);
        for &m in &self.mean {
            w.f32(m);
        }
        let mut enc = Encoder::new();
        let mut models = vec![IntModel::default(); BASIS_CONTEXTS];
        for (b, &bits) in self.basis_bits.iter().enumerate() {
            let scale = f64::from(1u32 << bits);
            for c in 0..self.width() {
                let q = quantise(f64::from(self.basis[b * self.width() + c]) * scale);
                models[basis_context(bits)].encode(&mut enc, q);
            }
        }
        let coded = enc.finish();
        w.u32(coded.len() as u32).bytes(&coded);
        w.0
    }

    pub fn parse(bytes: &[u8], points: usize) -> Result<Params> {
        let width = points * 3;
        let mut r = Reader::new(bytes);
        let clip = r.u32()? as usize;
        let k = r.u32()? as usize;
        let l = r.u32()? as usize;
        let coef_step = r.f64()?;
        let residual_t = r.f64()?;
        if clip == 0 || clip > crate::codec::MAX_CLIP || k == 0 || k > width || l == 0 || l > clip {
            return Err(malformed(format!(
                "mdtt shape L={clip} k={k} l={l} for {width} coordinates"
            )));
        }
        let basis_bits = r.take(k)?.to_vec();
        if !(coef_step.is_finite()
            && coef_step > 0.0
            && residual_t.is_finite()
            && residual_t >= 0.0
            && basis_bits.iter().all(|&b| b <= MAX_BASIS_BITS))
        {
            return Err(malformed("mdtt steps are out of range"));
        }
        let mean = (0..width).map(|_| r.f32()).collect::<Result<Vec<_>>>()?;
        let len = r.u32()? as usize;
        let coded = r.take(len)?;
        r.finish()?;
        let mut dec = Decoder::new(coded);
        let mut models = vec![IntModel::default(); BASIS_CONTEXTS];
        let mut basis = vec![0f32; width * k];
        for (b, &bits) in basis_bits.iter().enumerate() {
            let scale = f64::from(1u32 << bits);
            for c in 0..width {
                let q = models[basis_context(bits)].decode(&mut dec);
                basis[b * width + c] = (f64::from(q) / scale) as f32;
            }
        }
        if dec.overran() {
            return Err(malformed("mdtt basis is truncated"));
        }
        Ok(Params {
            clip,
            k,
            l,
            coef_step,
            residual_t,
            basis_bits,
            mean,
            basis,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn round_trips_and_rejects_nonsense() {
        let bits = vec![12, 4];
        // Two columns of three: column 0 at 12 bits, column 1 at 4.
        let basis = [0.5, -0.25, 1.0, 0.0, -1.0, 0.123]
            .iter()
            .enumerate()
            .map(|(i, &v)| quantise_basis(v, bits[i / 3]).1)
            .collect();
        let p = Params {
            clip: 70,
            k: 2,
            l: 1,
            coef_step: 0.5,
            residual_t: 1.0,
            basis_bits: bits,
            mean: vec![1.0; 3],
            basis,
        };
        assert_eq!(Params::parse(&p.to_bytes(), 1).unwrap(), p);
        assert!(Params::parse(&p.to_bytes(), 2).is_err());
        // k = 4 > 3 coordinates.
        let mut bad = p.to_bytes();
        bad[4..8].copy_from_slice(&4u32.to_le_bytes());
        assert!(Params::parse(&bad, 1).is_err());
    }
}
