//! The `Motion` type: one take as a matrix of 3-D point trajectories.

use serde::{Deserialize, Serialize};

use super::error::{Error, Result};
use super::layout::LayoutSignature;
use super::skeleton::Animation;
use super::units::Unit;

/// One take: `frames × points × 3` positions, a frame contiguous.
///
/// A missing sample (a C3D marker the cameras lost, a blank TRC cell) is stored as NaN in
/// all three coordinates. Keeping gaps inside the matrix rather than in a parallel mask means
/// there is no second array to keep in step when slicing or subsetting, and any code that
/// forgets about gaps produces NaN loudly instead of silently using a stale value.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Motion {
    pub fps: f64,
    pub unit: Unit,
    pub point_names: Vec<String>,
    positions: Vec<f32>,
    /// Kept explicitly because a take may have no points at all (an EMG-only C3D) and
    /// still have a length.
    frames: usize,
    pub skeleton: Option<Animation>,
}

impl Motion {
    pub fn new(
        fps: f64,
        unit: Unit,
        point_names: Vec<String>,
        positions: Vec<f32>,
        skeleton: Option<Animation>,
    ) -> Result<Self> {
        crate::limits::fps(fps).map_err(Error::Invalid)?;
        let n = point_names.len();
        if n == 0 && !positions.is_empty() || n > 0 && !positions.len().is_multiple_of(n * 3) {
            return Err(Error::Invalid(format!(
                "{} coordinates do not fill whole frames of {n} points",
                positions.len()
            )));
        }
        let mut positions = positions;
        // A sample is either whole or a gap: a lone NaN coordinate makes the point missing.
        for p in positions.chunks_exact_mut(3) {
            if p.iter().any(|v| !v.is_finite()) {
                p.fill(f32::NAN);
            }
        }
        if let Some(s) = &skeleton {
            if s.joints.len() != n {
                return Err(Error::Invalid(format!(
                    "skeleton has {} joints but the take has {n} points",
                    s.joints.len()
                )));
            }
            if n > 0 && s.frame_count() != positions.len() / (n * 3) {
                return Err(Error::Invalid(format!(
                    "skeleton has {} frames but the take has {}",
                    s.frame_count(),
                    positions.len() / (n * 3)
                )));
            }
        }
        let frames = if n == 0 { 0 } else { positions.len() / (n * 3) };
        Ok(Motion {
            fps,
            unit,
            point_names,
            positions,
            frames,
            skeleton,
        })
    }

    /// Its positions, given back (a caller that built it to look at them keeps them).
    pub fn into_positions(self) -> Vec<f32> {
        self.positions
    }

    /// A take with a length but no points (e.g. a C3D file holding only analog channels).
    pub fn without_points(fps: f64, unit: Unit, frames: usize) -> Result<Self> {
        let mut m = Motion::new(fps, unit, vec![], vec![], None)?;
        m.frames = frames;
        Ok(m)
    }

    pub fn frame_count(&self) -> usize {
        self.frames
    }

    pub fn point_count(&self) -> usize {
        self.point_names.len()
    }

    pub fn duration_s(&self) -> f64 {
        self.frame_count() as f64 / self.fps
    }

    /// All positions, `frames × points × 3`.
    pub fn positions(&self) -> &[f32] {
        &self.positions
    }

    /// One frame, `points × 3`.
    pub fn frame(&self, f: usize) -> &[f32] {
        let w = self.point_count() * 3;
        &self.positions[f * w..(f + 1) * w]
    }

    pub fn sample(&self, frame: usize, point: usize) -> Option<[f32; 3]> {
        let i = (frame * self.point_count() + point) * 3;
        let p = &self.positions[i..i + 3];
        p[0].is_finite().then(|| [p[0], p[1], p[2]])
    }

    /// Turn every sample for which `bad` holds into a gap; how many were.
    pub fn gap_where(&mut self, bad: impl Fn(&[f32]) -> bool) -> usize {
        let mut n = 0;
        for s in self.positions.chunks_exact_mut(3) {
            if !s[0].is_nan() && bad(s) {
                s.fill(f32::NAN);
                n += 1;
            }
        }
        n
    }

    /// Number of missing point samples.
    pub fn gap_count(&self) -> usize {
        self.positions
            .chunks_exact(3)
            .filter(|p| p[0].is_nan())
            .count()
    }

    /// Fraction of point samples missing, 0..=1.
    pub fn gap_fraction(&self) -> f64 {
        let total = self.positions.len() / 3;
        if total == 0 {
            0.0
        } else {
            self.gap_count() as f64 / total as f64
        }
    }

    pub fn layout_signature(&self) -> LayoutSignature {
        LayoutSignature::of(&self.point_names, self.skeleton.as_ref())
    }

    /// Frames `start..end` (end exclusive) as a new take.
    pub fn slice_frames(&self, start: usize, end: usize) -> Result<Motion> {
        if start > end || end > self.frame_count() {
            return Err(Error::Invalid(format!(
                "frames {start}..{end} outside 0..{}",
                self.frame_count()
            )));
        }
        let w = self.point_count() * 3;
        Ok(Motion {
            fps: self.fps,
            unit: self.unit.clone(),
            point_names: self.point_names.clone(),
            positions: self.positions[start * w..end * w].to_vec(),
            frames: end - start,
            skeleton: self.skeleton.as_ref().map(|s| s.slice_frames(start, end)),
        })
    }

    /// Height of the figure in stored units: the largest vertical extent (Y or Z, whichever
    /// is larger) of the valid points over up to 32 evenly spread frames. Used to infer the
    /// unit of takes that carry none; several frames, because one may catch a crouch.
    ///
    /// The root of a skeleton is left out: in many rigs it is a world or ground node rather
    /// than a body part (Bandai's `joint_Root` stays at the origin while the body runs off).
    pub fn figure_height(&self) -> Option<f64> {
        let skip = usize::from(self.skeleton.is_some());
        let frames = self.frame_count();
        if frames == 0 || self.point_count() < 2 {
            return None;
        }
        let step = frames.div_ceil(32).max(1);
        let mut best = 0.0f64;
        for f in (0..frames).step_by(step) {
            for axis in [1, 2] {
                let (lo, hi) = self
                    .frame(f)
                    .chunks_exact(3)
                    .skip(skip)
                    .filter(|p| p[0].is_finite())
                    .fold((f32::MAX, f32::MIN), |(lo, hi), p| {
                        (lo.min(p[axis]), hi.max(p[axis]))
                    });
                if hi > lo {
                    best = best.max(f64::from(hi - lo));
                }
            }
        }
        (best > 0.0).then_some(best)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::motion::units::UnitSource;

    fn mm() -> Unit {
        Unit::new(0.001, UnitSource::Declared).unwrap()
    }

    #[test]
    fn shape_is_checked_and_gaps_are_whole_samples() {
        let names = vec!["a".to_string(), "b".to_string()];
        assert!(Motion::new(100.0, mm(), names.clone(), vec![0.0; 5], None).is_err());
        assert!(Motion::new(0.0, mm(), names.clone(), vec![0.0; 6], None).is_err());
        let mut pos = vec![1.0f32; 12];
        pos[4] = f32::NAN; // y of point b in frame 0
        let m = Motion::new(100.0, mm(), names, pos, None).unwrap();
        assert_eq!(m.frame_count(), 2);
        assert_eq!(m.gap_count(), 1);
        assert!(m.sample(0, 1).is_none());
        assert!(m.positions()[3].is_nan() && m.positions()[5].is_nan());
        assert_eq!(m.sample(1, 1), Some([1.0, 1.0, 1.0]));
        assert!((m.gap_fraction() - 0.25).abs() < 1e-12);
    }

    #[test]
    fn slicing_keeps_frames() {
        let names = vec!["a".to_string()];
        let pos: Vec<f32> = (0..30).map(|v| v as f32).collect();
        let m = Motion::new(10.0, mm(), names, pos, None).unwrap();
        let s = m.slice_frames(2, 5).unwrap();
        assert_eq!(s.frame_count(), 3);
        assert_eq!(s.frame(0), &[6.0, 7.0, 8.0]);
        assert!(m.slice_frames(5, 11).is_err());
    }
}
