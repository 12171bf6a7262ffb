//! The residual layer: exact bounds on top of a transform.
//!
//! A truncated transform is judged by its mean, but archivists need the worst sample
//! bounded (a truncated DCT rings where a trajectory is not smooth). After the transform, each
//! sample farther than the bound from its original gets its error quantised and sent:
//! a flag per frame, a flag per point in flagged frames, then three integers. With the step
//! `2t/√3` (less a margin for f32 rounding), a corrected sample is within `t` by
//! construction, so the bound holds on every sample whatever the transform did.

use super::entropy::{Bit, Decoder, Encoder, IntModel};
use super::measure::{quantise, sample_distance};

/// The quantisation step that guarantees distance ≤ `t` after correction.
pub fn step_for(t: f64) -> f64 {
    2.0 * t / 3f64.sqrt() * 0.99
}

struct Models {
    frame: [Bit; 2],
    point: [Bit; 2],
    value: [IntModel; 3],
}

impl Models {
    fn new() -> Self {
        Models {
            frame: [Bit::default(); 2],
            point: [Bit::default(); 2],
            value: Default::default(),
        }
    }
}

/// Code corrections for the samples of `recon` farther than `t` from `orig`, applying them
/// to `recon` as the decoder will. Returns how many samples were corrected.
pub fn encode(
    enc: &mut Encoder,
    orig: &[f32],
    recon: &mut [f32],
    valid: Option<&[bool]>,
    points: usize,
    t: f64,
) -> usize {
    let step = step_for(t);
    let w = points * 3;
    let frames = orig.len() / w.max(1);
    let mut m = Models::new();
    let mut prev = vec![false; points];
    let mut prev_frame = false;
    let mut corrected = 0;
    let mut flags = vec![false; points];
    for f in 0..frames {
        let mut any = false;
        for p in 0..points {
            let i = f * w + p * 3;
            let ok = valid.is_none_or(|v| v[f * points + p]);
            flags[p] = ok && sample_distance(&orig[i..i + 3], &recon[i..i + 3]) > t;
            any |= flags[p];
        }
        enc.encode(&mut m.frame[usize::from(prev_frame)], any);
        prev_frame = any;
        if !any {
            prev.fill(false);
            continue;
        }
        for p in 0..points {
            enc.encode(&mut m.point[usize::from(prev[p])], flags[p]);
            prev[p] = flags[p];
            if !flags[p] {
                continue;
            }
            corrected += 1;
            for k in 0..3 {
                let i = f * w + p * 3 + k;
                let q = quantise((f64::from(orig[i]) - f64::from(recon[i])) / step);
                m.value[k].encode(enc, q);
                recon[i] += (f64::from(q) * step) as f32;
            }
        }
    }
    corrected
}

/// Apply the corrections coded by [`encode`] to `recon`.
pub fn decode(dec: &mut Decoder<'_>, recon: &mut [f32], points: usize, t: f64) {
    let step = step_for(t);
    let w = points * 3;
    let frames = recon.len() / w.max(1);
    let mut m = Models::new();
    let mut prev = vec![false; points];
    let mut prev_frame = false;
    for f in 0..frames {
        let any = dec.decode(&mut m.frame[usize::from(prev_frame)]);
        prev_frame = any;
        if !any {
            prev.fill(false);
            continue;
        }
        for (p, was) in prev.iter_mut().enumerate() {
            let flag = dec.decode(&mut m.point[usize::from(*was)]);
            *was = flag;
            if !flag {
                continue;
            }
            for k in 0..3 {
                let q = m.value[k].decode(dec);
                recon[f * w + p * 3 + k] += (f64::from(q) * step) as f32;
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn corrects_exactly_the_samples_over_the_bound() {
        let orig: Vec<f32> = (0..60).map(|i| (i as f32 * 0.37).sin() * 100.0).collect();
        let mut recon: Vec<f32> = orig.iter().map(|v| v + 0.2).collect();
        recon[7] += 50.0; // point 2 of frame 0
        recon[40] -= 3.0; // point 1 of frame 3
        let mut enc = Encoder::new();
        let n = encode(&mut enc, &orig, &mut recon, None, 4, 1.0);
        assert_eq!(n, 2);
        for (a, b) in orig.chunks(3).zip(recon.chunks(3)) {
            assert!(sample_distance(a, b) <= 1.0);
        }
        let bytes = enc.finish();
        let mut again: Vec<f32> = orig.iter().map(|v| v + 0.2).collect();
        again[7] += 50.0;
        again[40] -= 3.0;
        decode(&mut Decoder::new(&bytes), &mut again, 4, 1.0);
        assert_eq!(again, recon);
    }
}
