//! Resampling a take to another frame rate, a block of frames at a time.
//!
//! Output frame `k` lies at `t0 + k / fps_out`, `t0` being the first source frame's time, and
//! the output ends at the last source frame's time or before it: `⌊(n − 1) · fps_out /
//! fps_src⌋ + 1` frames of `n`. A new frame that falls on a source frame (to within 1e-9 of a
//! frame) is that frame, exactly: 120 → 30 fps keeps every fourth frame as decoded. Between
//! source frames `a` and `b`, each [`Interpolant`] says how a value is formed; it is handed
//! the frames before `a` and after `b` where the range has them.
//!
//! Streaming: [`Resampler::push`] takes the source frames as they are decoded and gives the
//! output frames whose neighbours have arrived; it keeps three source frames at most between
//! calls, so what it holds does not grow with the take.

use std::collections::VecDeque;

/// How a frame between two source frames is formed.
pub trait Interpolant {
    /// Values per frame.
    fn width(&self) -> usize;

    /// The frame at fraction `f` (0 < f < 1) from `a` to `b`, into `out` (`width` values),
    /// with the frame before `a` and the one after `b` where there are such frames.
    fn between(
        &self,
        before: Option<&[f64]>,
        a: &[f64],
        b: &[f64],
        after: Option<&[f64]>,
        f: f64,
        out: &mut [f64],
    );
}

/// Source frames per output frame, `from / to`, snapped to a fraction `p / q` (q ≤ 16) when
/// it lies within 1e-4 (relative) of one: a rate read from a frame time printed to a few
/// decimals (CMU's 0.0083333 s is 120.00048 fps; 0.008333 s, six decimals, 120.0048) is
/// the round rate it was written for, so 120 → 30 fps keeps every fourth frame instead of
/// drifting off them. Real rates that differ (29.97 against 30: 1e-3) are not snapped.
pub fn grid_step(from: f64, to: f64) -> f64 {
    let step = from / to;
    for q in 1..=16u32 {
        let p = (step * f64::from(q)).round();
        if p >= 1.0 && (step - p / f64::from(q)).abs() <= 1e-4 * step {
            return p / f64::from(q);
        }
    }
    step
}

/// Trial frame `first` (1-based, at `from` fps) as the frame at the same time at `to` fps:
/// where a resampled C3D starts, so that its events keep their times.
pub fn trial_frame_at(first: usize, from: f64, to: f64) -> usize {
    (first.saturating_sub(1) as f64 * to / from).round() as usize + 1
}

/// Frames a resampled range has: those of `source` frames at `from` fps put on a grid of
/// `to` fps from the first one, up to the last.
pub fn output_frames(source: usize, from: f64, to: f64) -> usize {
    if source == 0 {
        return 0;
    }
    // The same tolerance as `Resampler::locate`, in source frames.
    (((source - 1) as f64 + 1e-9) / grid_step(from, to)).floor() as usize + 1
}

/// Output frames of a source range as its frames arrive.
pub struct Resampler<I> {
    interp: I,
    /// Source frames per output frame.
    step: f64,
    source_frames: usize,
    output_frames: usize,
    /// The source frames kept, from `kept_from` on.
    kept: VecDeque<Vec<f64>>,
    kept_from: usize,
    received: usize,
    next_out: usize,
}

impl<I: Interpolant> Resampler<I> {
    /// A resampler of `source_frames` frames at `from` fps to `to` fps.
    pub fn new(interp: I, source_frames: usize, from: f64, to: f64) -> Self {
        Resampler {
            interp,
            step: grid_step(from, to),
            source_frames,
            output_frames: output_frames(source_frames, from, to),
            kept: VecDeque::with_capacity(4),
            kept_from: 0,
            received: 0,
            next_out: 0,
        }
    }

    /// At most `frames` output frames: the source frames pushed run past the range whose
    /// frames are asked for, only to interpolate its last ones.
    pub fn limit(&mut self, frames: usize) {
        self.output_frames = self.output_frames.min(frames);
    }

    /// Output frames in all.
    pub fn output_frames(&self) -> usize {
        self.output_frames
    }

    /// The most output frames `source` frames pushed at once can give (for buffers sized
    /// before decoding).
    pub fn most_out_of(&self, source: usize) -> usize {
        ((source + 3) as f64 / self.step).ceil() as usize + 1
    }

    /// Where output frame `k` lies: the source frame before it and the fraction past it.
    fn locate(&self, k: usize) -> (usize, f64) {
        let last = self.source_frames.saturating_sub(1);
        let u = k as f64 * self.step;
        let i = (u + 1e-9).floor();
        let f = u - i;
        if !(i.is_finite() && f.is_finite()) || i as usize >= last {
            return (last, 0.0);
        }
        if f < 1e-9 {
            (i as usize, 0.0)
        } else {
            (i as usize, f)
        }
    }

    /// The first source frame an output frame still to make needs (the neighbour before
    /// its first); frames before it are not kept.
    fn first_needed(&self) -> usize {
        if self.next_out >= self.output_frames {
            usize::MAX
        } else {
            self.locate(self.next_out).0.saturating_sub(1)
        }
    }

    /// Push whole source frames (`width` values each, in order); the output frames now
    /// complete are appended to `out`. Returns how many.
    pub fn push(&mut self, frames: &[f64], out: &mut Vec<f64>) -> usize {
        let count = frames.len() / self.interp.width().max(1);
        self.push_count(frames, count, out)
    }

    /// [`Resampler::push`] of `count` frames: a frame of no values (a take of analog
    /// channels and no points) is still a frame, and the output still counts its frames.
    pub fn push_count(&mut self, frames: &[f64], count: usize, out: &mut Vec<f64>) -> usize {
        let w = self.interp.width();
        debug_assert_eq!(frames.len(), count * w);
        let mut made = 0;
        for frame in (0..count).map(|i| &frames[i * w..(i + 1) * w]) {
            if self.received >= self.source_frames {
                break;
            }
            let index = self.received;
            self.received += 1;
            if index < self.first_needed() {
                // No output frame to come lies next to it (a low output rate skips many):
                // what is kept stays a few frames, however far apart the outputs are.
                self.kept.clear();
                self.kept_from = index + 1;
                continue;
            }
            self.kept.push_back(frame.to_vec());
            made += self.emit_ready(out);
        }
        made
    }

    /// Output frames whose neighbours have all arrived.
    fn emit_ready(&mut self, out: &mut Vec<f64>) -> usize {
        let w = self.interp.width();
        let mut made = 0;
        while self.next_out < self.output_frames {
            let (i, f) = self.locate(self.next_out);
            let last = self.source_frames - 1;
            let need = if f == 0.0 { i } else { (i + 2).min(last) };
            if need >= self.received {
                break;
            }
            let at = out.len();
            if f == 0.0 {
                out.extend_from_slice(self.frame(i));
            } else {
                out.resize(at + w, 0.0);
                let before = i.checked_sub(1).filter(|&b| b >= self.kept_from);
                let after = (i + 2 <= last).then_some(i + 2);
                self.interp.between(
                    before.map(|b| self.frame(b)),
                    self.frame(i),
                    self.frame(i + 1),
                    after.map(|a| self.frame(a)),
                    f,
                    &mut out[at..at + w],
                );
            }
            self.next_out += 1;
            made += 1;
            // Keep from the frame before the next output's first neighbour.
            if self.next_out < self.output_frames {
                let (next_i, _) = self.locate(self.next_out);
                while self.kept_from + 1 < next_i && !self.kept.is_empty() {
                    self.kept.pop_front();
                    self.kept_from += 1;
                }
            }
        }
        made
    }

    fn frame(&self, i: usize) -> &[f64] {
        &self.kept[i - self.kept_from]
    }
}

/// Catmull-Rom between `a` and `b` at `f`, with the neighbours `p0` (before `a`) and `p3`
/// (after `b`) where they exist, else reflected (`2a − b`, `2b − a`): a cubic through the
/// four, which is the straight line when both are reflected.
pub fn cubic(p0: Option<f64>, a: f64, b: f64, p3: Option<f64>, f: f64) -> f64 {
    let p0 = p0.unwrap_or(2.0 * a - b);
    let p3 = p3.unwrap_or(2.0 * b - a);
    let (f2, f3) = (f * f, f * f * f);
    0.5 * (2.0 * a
        + (b - p0) * f
        + (2.0 * p0 - 5.0 * a + 4.0 * b - p3) * f2
        + (3.0 * a - p0 - 3.0 * b + p3) * f3)
}

/// Positions (`points × 3` per frame, NaN where a sample is missing): each coordinate by
/// [`cubic`]; a neighbour that is missing counts as absent, and a new sample is missing when
/// either sample it lies between is.
pub struct Positions {
    pub points: usize,
}

impl Interpolant for Positions {
    fn width(&self) -> usize {
        self.points * 3
    }

    fn between(
        &self,
        before: Option<&[f64]>,
        a: &[f64],
        b: &[f64],
        after: Option<&[f64]>,
        f: f64,
        out: &mut [f64],
    ) {
        fn present(s: Option<&[f64]>, p: usize) -> Option<&[f64]> {
            s.map(|s| &s[p * 3..p * 3 + 3])
                .filter(|v| v.iter().all(|x| x.is_finite()))
        }
        for p in 0..self.points {
            let o = &mut out[p * 3..p * 3 + 3];
            let (Some(pa), Some(pb)) = (present(Some(a), p), present(Some(b), p)) else {
                o.fill(f64::NAN);
                continue;
            };
            let (p0, p3) = (present(before, p), present(after, p));
            for k in 0..3 {
                o[k] = cubic(p0.map(|v| v[k]), pa[k], pb[k], p3.map(|v| v[k]), f);
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn resample(points: usize, frames: &[f64], from: f64, to: f64, block: usize) -> Vec<f64> {
        let n = frames.len() / (points * 3);
        let mut r = Resampler::new(Positions { points }, n, from, to);
        let mut out = Vec::new();
        for b in frames.chunks(block * points * 3) {
            r.push(b, &mut out);
        }
        assert_eq!(out.len(), r.output_frames() * points * 3);
        out
    }

    fn wave(n: usize, fps: f64) -> Vec<f64> {
        (0..n)
            .flat_map(|i| {
                let t = i as f64 / fps;
                [t.sin(), (2.0 * t).cos(), t * t]
            })
            .collect()
    }

    #[test]
    fn printed_rates_snap_to_round_ones() {
        assert_eq!(grid_step(1.0 / 0.00833333, 30.0), 4.0);
        assert_eq!(grid_step(1.0 / 0.0333333, 120.0), 0.25);
        assert_eq!(grid_step(120.0, 100.0), 1.2);
        assert_eq!(grid_step(1.0 / 0.008333, 60.0), 2.0);
        assert_eq!(grid_step(29.97, 30.0), 29.97 / 30.0);
        assert_eq!(output_frames(994, 1.0 / 0.00833333, 30.0), 249);
    }

    /// A rate a hair off a multiple of the source's ends on the last source frame, not past
    /// it; a very low rate keeps a few source frames, not all of them.
    #[test]
    fn odd_rates_stay_in_bounds_and_memory() {
        let src = wave(19, 120.0);
        let out = resample(1, &src, 120.0, 113.333_333_326_962_97, 19);
        assert!(out.iter().all(|v| v.is_finite()));
        let long = wave(5000, 120.0);
        let mut r = Resampler::new(Positions { points: 1 }, 5000, 120.0, 0.01);
        let mut got = Vec::new();
        for b in long.chunks(3 * 100) {
            r.push(b, &mut got);
            assert!(r.kept.len() <= 4, "{} frames kept", r.kept.len());
        }
        assert_eq!(got.len() / 3, r.output_frames());
        assert_eq!(&got[..3], &long[..3]);
    }

    #[test]
    fn output_frame_counts() {
        assert_eq!(output_frames(0, 120.0, 30.0), 0);
        assert_eq!(output_frames(1, 120.0, 30.0), 1);
        assert_eq!(output_frames(121, 120.0, 30.0), 31);
        assert_eq!(output_frames(120, 120.0, 30.0), 30);
        assert_eq!(output_frames(31, 30.0, 120.0), 121);
        assert_eq!(output_frames(100, 120.0, 100.0), 83);
    }

    /// Downsampling by a whole factor keeps every k-th frame exactly, in blocks of any size.
    #[test]
    fn whole_factors_keep_frames_exactly() {
        let src = wave(241, 120.0);
        for block in [1, 2, 7, 100, 241] {
            let out = resample(1, &src, 120.0, 30.0, block);
            assert_eq!(out.len(), 61 * 3);
            for (k, f) in out.chunks(3).enumerate() {
                assert_eq!(f, &src[k * 12..k * 12 + 3], "frame {k}, blocks of {block}");
            }
        }
    }

    /// A smooth motion put on a finer grid lies on the motion; back down, it is the source.
    #[test]
    fn up_and_down_again() {
        let src = wave(61, 30.0);
        let up = resample(1, &src, 30.0, 120.0, 5);
        let truth = wave(241, 120.0);
        let worst = up
            .iter()
            .zip(&truth)
            .map(|(a, b)| (a - b).abs())
            .fold(0.0, f64::max);
        assert!(worst < 2e-3, "{worst}");
        let down = resample(1, &up, 120.0, 30.0, 3);
        assert_eq!(down, src);
        // 120 → 100 fps: off the grid, and within a cubic's error of the motion.
        let odd = resample(1, &truth, 120.0, 100.0, 9);
        let want = wave(odd.len() / 3, 100.0);
        let worst = odd
            .iter()
            .zip(&want)
            .map(|(a, b)| (a - b).abs())
            .fold(0.0, f64::max);
        assert!(worst < 1e-5, "{worst}");
    }

    /// A new sample between a missing one and a present one is missing; a neighbour that is
    /// missing only makes the curve one-sided.
    #[test]
    fn gaps_stay_gaps() {
        let mut src = wave(9, 10.0);
        src[4 * 3..5 * 3].fill(f64::NAN);
        let out = resample(1, &src, 10.0, 20.0, 2);
        for (k, f) in out.chunks(3).enumerate() {
            let near_gap = k == 7 || k == 8 || k == 9;
            assert_eq!(f.iter().all(|v| v.is_nan()), near_gap, "frame {k}: {f:?}");
            assert!(near_gap || f.iter().all(|v| v.is_finite()));
        }
    }

    #[test]
    fn cubic_is_the_line_on_a_line() {
        for f in [0.1, 0.5, 0.9] {
            assert!((cubic(Some(0.0), 1.0, 2.0, Some(3.0), f) - (1.0 + f)).abs() < 1e-12);
            assert!((cubic(None, 1.0, 2.0, None, f) - (1.0 + f)).abs() < 1e-12);
        }
    }
}
