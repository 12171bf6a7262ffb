//! The residual layer: exact bounds on top of a transform.
//!
//! A truncated transform is judged by its mean, but archivists need the worst sample
//! bounded (a truncated DCT rings where a trajectory is not smooth). After the transform, each
//! sample farther than the bound from its original gets its error quantised and sent:
//! a flag per frame, a flag per point in flagged frames, then three integers. With the step
//! `2t/√3` (less a margin for f32 rounding), a corrected sample is within `t` by
//! construction, so the bound holds on every sample whatever the transform did.

use super::entropy::{magnitude_context, Bit, Decoder, Encoder, IntModel};
use super::measure::{quantise, sample_distance};

/// The quantisation step that guarantees distance ≤ `t` after correction.
pub fn step_for(t: f64) -> f64 {
    2.0 * t / 3f64.sqrt() * 0.99
}

/// Magnitude buckets of the previous frame's correction that condition a value's model.
const BUCKETS: usize = 4;

struct Models {
    frame: [Bit; 2],
    /// By (flagged in the previous frame, previous point flagged in this frame).
    point: [Bit; 4],
    /// By axis and the bucket of the same coordinate's correction in the previous frame.
    value: Vec<IntModel>,
}

impl Models {
    fn new() -> Self {
        Models {
            frame: [Bit::default(); 2],
            point: [Bit::default(); 4],
            value: vec![IntModel::default(); 3 * BUCKETS],
        }
    }
}

/// State carried from frame to frame: which points were corrected, and by how much.
struct History {
    flagged: Vec<bool>,
    /// Last frame's correction per coordinate (0 where none).
    q: Vec<i32>,
}

impl History {
    fn new(points: usize) -> Self {
        History {
            flagged: vec![false; points],
            q: vec![0; points * 3],
        }
    }

    #[inline]
    fn point_context(&self, p: usize, previous_point_flagged: bool) -> usize {
        usize::from(self.flagged[p]) * 2 + usize::from(previous_point_flagged)
    }

    /// Model index of coordinate `i` (axis `k`): by the size of its correction in the last
    /// frame, since the transform misses features for a few frames at a time. (Using that
    /// correction as a prediction was measured and is worse: corrections of one or two
    /// steps flip sign from frame to frame.)
    #[inline]
    fn value_context(&self, i: usize, k: usize) -> usize {
        k * BUCKETS + magnitude_context(self.q[i], BUCKETS)
    }

    fn clear(&mut self) {
        self.flagged.fill(false);
        self.q.fill(0);
    }
}

/// The residual layer's state, one frame at a time: what frame-by-frame coders (which must
/// correct a frame before predicting the next from it) drive directly, and what [`encode`]
/// and [`decode`] loop over. Deciding the corrections ([`FrameResidual::correct`]) is apart
/// from coding them ([`FrameResidual::code`]) so that a coder with its own entropy stage can
/// take the corrections as they are.
pub struct FrameResidual {
    m: Models,
    h: History,
    prev_frame: bool,
    /// This frame's decision: which points are corrected, and by how many steps.
    flags: Vec<bool>,
    q: Vec<i32>,
    any: bool,
    step: f64,
    t: f64,
}

impl FrameResidual {
    pub fn new(points: usize, t: f64) -> Self {
        FrameResidual {
            m: Models::new(),
            h: History::new(points),
            prev_frame: false,
            flags: vec![false; points],
            q: vec![0; points * 3],
            any: false,
            step: step_for(t),
            t,
        }
    }

    /// Correct the samples of one frame's `recon` farther than `t` from `orig`; returns how
    /// many were corrected. [`FrameResidual::corrections`] then tells which and by how much.
    pub fn correct(&mut self, orig: &[f32], recon: &mut [f32], valid: Option<&[bool]>) -> usize {
        let mut corrected = 0;
        for (p, flag) in self.flags.iter_mut().enumerate() {
            let i = p * 3;
            let ok = valid.is_none_or(|v| v[p]);
            *flag = ok && sample_distance(&orig[i..i + 3], &recon[i..i + 3]) > self.t;
            for k in i..i + 3 {
                self.q[k] = if *flag {
                    let q = quantise((f64::from(orig[k]) - f64::from(recon[k])) / self.step);
                    recon[k] += (f64::from(q) * self.step) as f32;
                    q
                } else {
                    0
                };
            }
            corrected += usize::from(*flag);
        }
        self.any = corrected > 0;
        corrected
    }

    /// The last [`FrameResidual::correct`]'s decision: a flag per point, steps per coordinate.
    pub fn corrections(&self) -> (&[bool], &[i32]) {
        (&self.flags, &self.q)
    }

    /// What a correction of `q` steps adds to its sample.
    #[inline]
    pub fn correction(&self, q: i32) -> f32 {
        (f64::from(q) * self.step) as f32
    }

    /// Code the last [`FrameResidual::correct`]'s decision with the adaptive models.
    pub fn code(&mut self, enc: &mut Encoder) {
        let (m, h) = (&mut self.m, &mut self.h);
        enc.encode(&mut m.frame[usize::from(self.prev_frame)], self.any);
        self.prev_frame = self.any;
        if !self.any {
            h.clear();
            return;
        }
        let mut previous_point = false;
        for (p, &flag) in self.flags.iter().enumerate() {
            enc.encode(&mut m.point[h.point_context(p, previous_point)], flag);
            previous_point = flag;
            h.flagged[p] = flag;
            for k in 0..3 {
                let i = p * 3 + k;
                let ctx = h.value_context(i, k);
                if flag {
                    m.value[ctx].encode(enc, self.q[i]);
                }
                h.q[i] = self.q[i];
            }
        }
    }

    /// Correct one frame's `recon` (see [`FrameResidual::correct`]) and code the corrections.
    pub fn encode_frame(
        &mut self,
        enc: &mut Encoder,
        orig: &[f32],
        recon: &mut [f32],
        valid: Option<&[bool]>,
    ) -> usize {
        let n = self.correct(orig, recon, valid);
        self.code(enc);
        n
    }

    /// Apply one frame's corrections to `recon`.
    pub fn decode_frame(&mut self, dec: &mut Decoder<'_>, recon: &mut [f32]) {
        let (m, h) = (&mut self.m, &mut self.h);
        let any = dec.decode(&mut m.frame[usize::from(self.prev_frame)]);
        self.prev_frame = any;
        if !any {
            h.clear();
            return;
        }
        let mut previous_point = false;
        for p in 0..self.flags.len() {
            let flag = dec.decode(&mut m.point[h.point_context(p, previous_point)]);
            previous_point = flag;
            h.flagged[p] = flag;
            for k in 0..3 {
                let ctx = h.value_context(p * 3 + k, k);
                if !flag {
                    h.q[p * 3 + k] = 0;
                    continue;
                }
                let q = m.value[ctx].decode(dec);
                recon[p * 3 + k] += (f64::from(q) * self.step) as f32;
                h.q[p * 3 + k] = q;
            }
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
    let w = points * 3;
    let mut r = FrameResidual::new(points, t);
    let mut corrected = 0;
    for (f, (o, rc)) in orig
        .chunks_exact(w)
        .zip(recon.chunks_exact_mut(w))
        .enumerate()
    {
        let v = valid.map(|v| &v[f * points..(f + 1) * points]);
        corrected += r.encode_frame(enc, o, rc, v);
    }
    corrected
}

/// Apply the corrections coded by [`encode`] to `recon`.
pub fn decode(dec: &mut Decoder<'_>, recon: &mut [f32], points: usize, t: f64) {
    let frames = recon.len() / (points * 3).max(1);
    decode_rows(dec, recon, points, t, 0..frames);
}

/// Apply the corrections of frames `rows` of a chunk to `recon` (those frames only). The
/// stream is read up to the end of `rows` and no further; the corrections of the frames
/// before are decoded (the models adapt through them) and dropped.
pub fn decode_rows(
    dec: &mut Decoder<'_>,
    recon: &mut [f32],
    points: usize,
    t: f64,
    rows: std::ops::Range<usize>,
) {
    let mut r = FrameResidual::new(points, t);
    let mut dropped = vec![0f32; points * 3];
    for _ in 0..rows.start {
        r.decode_frame(dec, &mut dropped);
    }
    for rc in recon.chunks_exact_mut(points * 3).take(rows.len()) {
        r.decode_frame(dec, rc);
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
