//! Normalisation statistics of motion: the mean and spread of each point's coordinates and
//! of its velocity, gathered in one pass over a take's frames and merged across takes
//! exactly (Welford's update, Chan et al.'s merge), so that a library's statistics are the
//! merge of its takes' and a take's can be kept and merged again without reading it twice.
//!
//! Missing samples (NaN) count in nothing; a velocity needs the point present in both
//! frames. Spreads are population standard deviations (numpy's default, `ddof=0`).

use serde::{Deserialize, Serialize};

/// Running moments of one value: how many, their mean, and the sum of squared deviations
/// from it.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
pub struct Moments {
    pub n: u64,
    pub mean: f64,
    pub m2: f64,
}

impl Moments {
    /// Count `x` in.
    pub fn push(&mut self, x: f64) {
        self.n += 1;
        let d = x - self.mean;
        self.mean += d / self.n as f64;
        self.m2 += d * (x - self.mean);
    }

    /// Count every value `other` counted in, as if each had been pushed here.
    pub fn merge(&mut self, other: &Moments) {
        if other.n == 0 {
            return;
        }
        if self.n == 0 {
            *self = *other;
            return;
        }
        let n = self.n + other.n;
        let d = other.mean - self.mean;
        let (a, b) = (self.n as f64, other.n as f64);
        self.mean += d * b / n as f64;
        self.m2 += other.m2 + d * d * a * b / n as f64;
        self.n = n;
    }

    /// The population standard deviation; 0 for fewer than two values.
    pub fn std(&self) -> f64 {
        if self.n < 2 {
            0.0
        } else {
            (self.m2 / self.n as f64).max(0.0).sqrt()
        }
    }
}

/// The moments of every coordinate of `points` points, and of their velocities (units per
/// second), over frames pushed in order.
#[derive(Debug, Clone, PartialEq)]
pub struct PointMoments {
    points: usize,
    fps: f64,
    /// Frames counted in.
    pub frames: u64,
    /// Per point and axis (`p * 3 + axis`).
    pub position: Vec<Moments>,
    pub velocity: Vec<Moments>,
    /// The last frame pushed: the next push's first velocity is taken from it.
    last: Option<Vec<f32>>,
}

impl PointMoments {
    /// Empty moments of `points` points, whose frames come at `fps`.
    pub fn new(points: usize, fps: f64) -> PointMoments {
        PointMoments {
            points,
            fps,
            frames: 0,
            position: vec![Moments::default(); points * 3],
            velocity: vec![Moments::default(); points * 3],
            last: None,
        }
    }

    pub fn points(&self) -> usize {
        self.points
    }

    /// Count in the frames of `positions` (frames × points × 3, NaN where missing), the
    /// frames that follow those pushed before.
    pub fn push(&mut self, positions: &[f32]) {
        let width = self.points * 3;
        if width == 0 {
            return;
        }
        debug_assert_eq!(positions.len() % width, 0, "whole frames");
        for frame in positions.chunks_exact(width) {
            for p in 0..self.points {
                let at = p * 3..p * 3 + 3;
                let now = &frame[at.clone()];
                if now.iter().any(|v| v.is_nan()) {
                    continue;
                }
                for (k, &v) in now.iter().enumerate() {
                    self.position[p * 3 + k].push(f64::from(v));
                }
                let Some(before) = self.last.as_ref().map(|l| &l[at]) else {
                    continue;
                };
                if before.iter().any(|v| v.is_nan()) {
                    continue;
                }
                for k in 0..3 {
                    let dv = (f64::from(now[k]) - f64::from(before[k])) * self.fps;
                    self.velocity[p * 3 + k].push(dv);
                }
            }
            match &mut self.last {
                Some(l) => l.copy_from_slice(frame),
                None => self.last = Some(frame.to_vec()),
            }
            self.frames += 1;
        }
    }

    /// The moments of the frames pushed here and those of `other` (the same points): a
    /// velocity is never taken across the two (a push after a merge starts afresh).
    pub fn merge(&mut self, other: &PointMoments) {
        debug_assert_eq!(self.points, other.points);
        self.last = None;
        for (a, b) in self.position.iter_mut().zip(&other.position) {
            a.merge(b);
        }
        for (a, b) in self.velocity.iter_mut().zip(&other.velocity) {
            a.merge(b);
        }
        self.frames += other.frames;
    }

    /// The moments alone, without the frame a further push would continue from: what is
    /// kept once a take is read to its end.
    pub fn finished(mut self) -> PointMoments {
        self.last = None;
        self
    }

    /// Bytes these moments hold (what a cache of them counts).
    pub fn bytes(&self) -> usize {
        std::mem::size_of::<Self>()
            + (self.position.len() + self.velocity.len()) * std::mem::size_of::<Moments>()
            + self.last.as_ref().map_or(0, |l| l.len() * 4)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rng::Rng;

    fn direct(values: &[f64]) -> (f64, f64) {
        let n = values.len() as f64;
        let mean = values.iter().sum::<f64>() / n;
        let var = values.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / n;
        (mean, var.sqrt())
    }

    #[test]
    fn pushed_and_merged_moments_are_the_direct_ones() {
        let mut rng = Rng::new(7);
        let values: Vec<f64> = (0..1000).map(|_| 1e3 + (rng.unit() - 0.5) * 6.0).collect();
        let (mean, std) = direct(&values);
        let mut whole = Moments::default();
        values.iter().for_each(|&v| whole.push(v));
        assert!((whole.mean - mean).abs() < 1e-9 && (whole.std() - std).abs() < 1e-9);
        // Split anywhere (an empty part too), merged: the same.
        for cut in [0, 1, 333, 999, 1000] {
            let (mut a, mut b) = (Moments::default(), Moments::default());
            values[..cut].iter().for_each(|&v| a.push(v));
            values[cut..].iter().for_each(|&v| b.push(v));
            a.merge(&b);
            assert_eq!(a.n, 1000);
            assert!((a.mean - mean).abs() < 1e-9, "cut {cut}");
            assert!((a.std() - std).abs() < 1e-9, "cut {cut}");
        }
    }

    #[test]
    fn velocities_run_on_across_pushes_and_skip_what_is_missing() {
        // One point moving 0.5 units a frame along x at 10 fps: 5 units/s; frame 3 missing.
        let frame = |i: usize| {
            if i == 3 {
                [f32::NAN; 3]
            } else {
                [i as f32 * 0.5, 1.0, -2.0]
            }
        };
        let all: Vec<f32> = (0..8).flat_map(frame).collect();
        let mut once = PointMoments::new(1, 10.0);
        once.push(&all);
        let mut twice = PointMoments::new(1, 10.0);
        twice.push(&all[..5 * 3]);
        twice.push(&all[5 * 3..]);
        assert_eq!(once, twice, "pushing in two pieces is pushing once");
        assert_eq!(once.frames, 8);
        assert_eq!(once.position[0].n, 7, "the missing frame counts in nothing");
        // Velocities between present neighbours only: 0-1, 1-2, 4-5, 5-6, 6-7.
        assert_eq!(once.velocity[0].n, 5);
        assert!((once.velocity[0].mean - 5.0).abs() < 1e-9);
        assert!(once.velocity[0].std() < 1e-9);
        assert!((once.position[1].mean - 1.0).abs() < 1e-9 && once.position[1].std() == 0.0);
        let (mean, std) = direct(&[0.0, 0.5, 1.0, 2.0, 2.5, 3.0, 3.5]);
        assert!((once.position[0].mean - mean).abs() < 1e-9);
        assert!((once.position[0].std() - std).abs() < 1e-6);
    }

    #[test]
    fn merged_takes_take_no_velocity_across_them() {
        let a: Vec<f32> = vec![0.0, 0.0, 0.0, 1.0, 0.0, 0.0];
        let b: Vec<f32> = vec![100.0, 0.0, 0.0, 101.0, 0.0, 0.0];
        let mut x = PointMoments::new(1, 1.0);
        x.push(&a);
        let mut y = PointMoments::new(1, 1.0);
        y.push(&b);
        x.merge(&y.finished());
        assert_eq!(x.velocity[0].n, 2);
        assert!((x.velocity[0].mean - 1.0).abs() < 1e-12);
        assert_eq!(x.frames, 4);
    }
}
