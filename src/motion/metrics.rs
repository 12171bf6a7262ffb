//! Error measures by which every codec is judged.
//!
//! All distances are reported in millimetres. Samples missing in the original (gaps) are
//! excluded; a sample present in the original but missing or non-finite in the
//! reconstruction counts as an infinite error, so it can never pass a bound by accident.

use serde::{Deserialize, Serialize};

use super::error::{Error, Result};
use super::skeleton::Animation;

/// Distortion of a reconstruction against its original.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ErrorStats {
    /// Mean Euclidean distance per point sample (the papers' d̄), mm.
    pub mean_mm: f64,
    /// Root of the mean squared Euclidean distance, mm.
    pub rms_mm: f64,
    /// Largest Euclidean distance of any sample, mm.
    pub max_mm: f64,
    /// Where `max_mm` occurs: (frame, point).
    pub worst: Option<(usize, usize)>,
    /// Largest distance per point, mm.
    pub per_point_max_mm: Vec<f64>,
    /// Karni–Gotsman distortion rate d% = 100·‖A−Ã‖/‖A−E(A)‖, with E(A) holding each
    /// frame's centroid (the consensus reading of the KG paper used by the mesh-compression
    /// literature).
    pub kg_percent: f64,
    /// Point samples compared (gaps excluded).
    pub samples: usize,
}

/// Compare `decoded` with `original`, both `frames × points × 3` in the same units.
pub fn compare(
    original: &[f32],
    decoded: &[f32],
    points: usize,
    mm_per_unit: f64,
) -> Result<ErrorStats> {
    if original.len() != decoded.len() {
        return Err(Error::Invalid(format!(
            "cannot compare {} coordinates with {}",
            original.len(),
            decoded.len()
        )));
    }
    if points == 0 || !original.len().is_multiple_of(points * 3) {
        return Err(Error::Invalid(format!(
            "{} coordinates are not whole frames of {points} points",
            original.len()
        )));
    }
    let mut acc = Accumulator::new(points);
    acc.add(original, decoded);
    Ok(acc.finish(mm_per_unit))
}

/// The distance between an original and a decoded sample (take units); infinite when the
/// decoded one is not finite, so it can never pass a bound.
fn sample_error(pa: &[f32], pb: &[f32]) -> f64 {
    let d2: f64 = (0..3)
        .map(|k| (f64::from(pa[k]) - f64::from(pb[k])).powi(2))
        .sum();
    if d2.is_finite() {
        d2.sqrt()
    } else {
        f64::INFINITY
    }
}

/// Error sums over frames as they come (a live stream's chunks), giving the same
/// [`ErrorStats`] as [`compare`] over all of them at once. Serialisable: a stream taken over
/// by another server goes on from the sums stored with its last chunk.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct Accumulator {
    points: usize,
    frames: usize,
    sum: f64,
    sum_sq: f64,
    max: f64,
    worst: Option<(usize, usize)>,
    per_point_max: Vec<f64>,
    spread_sq: f64,
    samples: usize,
}

impl Accumulator {
    pub fn new(points: usize) -> Self {
        Accumulator {
            points,
            frames: 0,
            sum: 0.0,
            sum_sq: 0.0,
            max: 0.0,
            worst: None,
            per_point_max: vec![0.0; points],
            spread_sq: 0.0,
            samples: 0,
        }
    }

    /// Points per frame.
    pub fn points(&self) -> usize {
        self.points
    }

    /// Add whole frames (`original` and `decoded` of equal length, in the take's units).
    pub fn add(&mut self, original: &[f32], decoded: &[f32]) {
        let points = self.points;
        if points == 0 {
            return;
        }
        for (a, b) in original
            .chunks_exact(points * 3)
            .zip(decoded.chunks_exact(points * 3))
        {
            let f = self.frames;
            self.frames += 1;
            let centroid = centroid(a);
            for p in 0..points {
                let pa = &a[p * 3..p * 3 + 3];
                if pa[0].is_nan() {
                    continue;
                }
                let d = sample_error(pa, &b[p * 3..p * 3 + 3]);
                self.sum += d;
                self.sum_sq += d * d;
                if d > self.max || self.worst.is_none() {
                    self.max = d.max(self.max);
                    self.worst = Some((f, p));
                }
                self.per_point_max[p] = self.per_point_max[p].max(d);
                self.spread_sq += (0..3)
                    .map(|k| (f64::from(pa[k]) - centroid[k]).powi(2))
                    .sum::<f64>();
                self.samples += 1;
            }
        }
    }

    pub fn finish(&self, mm_per_unit: f64) -> ErrorStats {
        let s = mm_per_unit;
        let n = self.samples.max(1) as f64;
        let kg = if self.spread_sq > 0.0 {
            100.0 * (self.sum_sq / self.spread_sq).sqrt()
        } else if self.sum_sq == 0.0 {
            0.0
        } else {
            f64::INFINITY
        };
        ErrorStats {
            mean_mm: self.sum / n * s,
            rms_mm: (self.sum_sq / n).sqrt() * s,
            max_mm: self.max * s,
            worst: self.worst,
            per_point_max_mm: self.per_point_max.iter().map(|v| v * s).collect(),
            kg_percent: kg,
            samples: self.samples,
        }
    }
}

fn centroid(frame: &[f32]) -> [f64; 3] {
    let mut c = [0.0f64; 3];
    let mut n = 0usize;
    for p in frame.chunks_exact(3).filter(|p| !p[0].is_nan()) {
        for k in 0..3 {
            c[k] += f64::from(p[k]);
        }
        n += 1;
    }
    if n > 0 {
        c.iter_mut().for_each(|v| *v /= n as f64);
    }
    c
}

/// How far bone lengths in `positions` stray from the skeleton's own (per frame: the offset,
/// or the position channels where a joint has them).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct BoneDrift {
    pub max_mm: f64,
    pub mean_mm: f64,
    /// Largest drift relative to the bone's length, over bones longer than zero.
    pub max_relative: f64,
    pub bones: usize,
}

/// Bone-length drift of `positions` (`frames × joints × 3`, the skeleton's own units).
pub fn bone_length_drift(
    skeleton: &Animation,
    positions: &[f64],
    mm_per_unit: f64,
) -> Result<BoneDrift> {
    let n = skeleton.joints.len();
    let frames = skeleton.frame_count();
    if positions.len() != frames * n * 3 {
        return Err(Error::Invalid(format!(
            "{} coordinates for {frames} frames of {n} joints",
            positions.len()
        )));
    }
    let (mut max, mut max_rel, mut sum, mut count) = (0.0f64, 0.0f64, 0.0f64, 0usize);
    let mut local = Vec::with_capacity(n);
    for f in 0..frames {
        skeleton.local_translations(f, &mut local);
        let frame = &positions[f * n * 3..(f + 1) * n * 3];
        for (i, j) in skeleton.joints.iter().enumerate() {
            let Some(p) = j.parent else { continue };
            let expected = norm(local[i]);
            let actual = norm([
                frame[i * 3] - frame[p * 3],
                frame[i * 3 + 1] - frame[p * 3 + 1],
                frame[i * 3 + 2] - frame[p * 3 + 2],
            ]);
            let d = (actual - expected).abs();
            max = max.max(d);
            if expected > 0.0 {
                max_rel = max_rel.max(d / expected);
            }
            sum += d;
            count += 1;
        }
    }
    Ok(BoneDrift {
        max_mm: max * mm_per_unit,
        mean_mm: sum / count.max(1) as f64 * mm_per_unit,
        max_relative: max_rel,
        bones: n.saturating_sub(1),
    })
}

fn norm(v: [f64; 3]) -> f64 {
    (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt()
}

/// Per frame step `f → f + 1` of `frames × points × 3` positions: the largest distance any
/// point moves (units per frame; gaps count as 0). What a jump looks like.
pub fn speeds(x: &[f32], points: usize) -> Vec<f64> {
    let w = points * 3;
    x.chunks_exact(w)
        .zip(x.chunks_exact(w).skip(1))
        .map(|(a, b)| {
            a.chunks_exact(3)
                .zip(b.chunks_exact(3))
                .map(|(p, q)| distance(p, q))
                .fold(0.0, f64::max)
        })
        .collect()
}

/// Per frame `f + 1` (`f` from 0): the largest second difference of any point (units per
/// frame²; gaps count as 0). What a jerk looks like.
pub fn accelerations(x: &[f32], points: usize) -> Vec<f64> {
    let w = points * 3;
    let frames = x.len().checked_div(w).unwrap_or(0);
    (1..frames.saturating_sub(1))
        .map(|f| {
            (0..points)
                .map(|p| {
                    let c = |g: usize, k: usize| f64::from(x[g * w + p * 3 + k]);
                    let a = (0..3)
                        .map(|k| (c(f + 1, k) - 2.0 * c(f, k) + c(f - 1, k)).powi(2))
                        .sum::<f64>()
                        .sqrt();
                    if a.is_nan() {
                        0.0
                    } else {
                        a
                    }
                })
                .fold(0.0, f64::max)
        })
        .collect()
}

fn distance(p: &[f32], q: &[f32]) -> f64 {
    let d = norm([0, 1, 2].map(|k| f64::from(p[k]) - f64::from(q[k])));
    if d.is_nan() {
        0.0
    } else {
        d
    }
}

/// Error over time, one bin of `frames_per_bin` frames (a second) at a time: each bin's
/// largest and mean sample distance in mm, over the samples the original has. What a viewer
/// charts against the bound; stored beside a take, a few bytes a second.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct ErrorSeries {
    pub frames_per_bin: usize,
    pub max_mm: Vec<f32>,
    pub mean_mm: Vec<f32>,
}

const SERIES_MAGIC: &[u8; 4] = b"MCES";

impl ErrorSeries {
    /// The series of `decoded` against `original` (equal lengths, whole frames of `points`,
    /// take units; `mm_per_unit` converts).
    pub fn of(
        original: &[f32],
        decoded: &[f32],
        points: usize,
        frames_per_bin: usize,
        mm_per_unit: f64,
    ) -> ErrorSeries {
        let frames_per_bin = frames_per_bin.max(1);
        let bin_len = points * 3 * frames_per_bin;
        let (mut max_mm, mut mean_mm) = (Vec::new(), Vec::new());
        if points > 0 {
            for (a, b) in original.chunks(bin_len).zip(decoded.chunks(bin_len)) {
                let (mut max, mut sum, mut n) = (0.0f64, 0.0f64, 0usize);
                for (pa, pb) in a.chunks_exact(3).zip(b.chunks_exact(3)) {
                    if pa[0].is_nan() {
                        continue;
                    }
                    let d = sample_error(pa, pb);
                    max = max.max(d);
                    sum += d;
                    n += 1;
                }
                max_mm.push((max * mm_per_unit) as f32);
                mean_mm.push(if n > 0 {
                    (sum / n as f64 * mm_per_unit) as f32
                } else {
                    0.0
                });
            }
        }
        ErrorSeries {
            frames_per_bin,
            max_mm,
            mean_mm,
        }
    }

    /// `"MCES"`, frames per bin u32, bins u32, then per bin max and mean as f32; all
    /// little-endian.
    pub fn to_bytes(&self) -> Vec<u8> {
        let mut out = Vec::with_capacity(12 + self.max_mm.len() * 8);
        out.extend_from_slice(SERIES_MAGIC);
        out.extend_from_slice(&(self.frames_per_bin as u32).to_le_bytes());
        out.extend_from_slice(&(self.max_mm.len() as u32).to_le_bytes());
        for (a, b) in self.max_mm.iter().zip(&self.mean_mm) {
            out.extend_from_slice(&a.to_le_bytes());
            out.extend_from_slice(&b.to_le_bytes());
        }
        out
    }

    /// The series of [`ErrorSeries::to_bytes`]; `Err` for anything else.
    pub fn from_bytes(bytes: &[u8]) -> Result<ErrorSeries> {
        let bad = |why: &str| Error::Invalid(format!("error series: {why}"));
        if bytes.len() < 12 || &bytes[..4] != SERIES_MAGIC {
            return Err(bad("not an error series"));
        }
        let word =
            |i: usize| u32::from_le_bytes([bytes[i], bytes[i + 1], bytes[i + 2], bytes[i + 3]]);
        let (per, bins) = (word(4) as usize, word(8) as usize);
        if per == 0 || bytes.len() != 12 + bins.saturating_mul(8) {
            return Err(bad("lengths do not add up"));
        }
        let f = |i: usize| f32::from_le_bytes([bytes[i], bytes[i + 1], bytes[i + 2], bytes[i + 3]]);
        Ok(ErrorSeries {
            frames_per_bin: per,
            max_mm: (0..bins).map(|k| f(12 + 8 * k)).collect(),
            mean_mm: (0..bins).map(|k| f(16 + 8 * k)).collect(),
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn hand_computed_case() {
        // Two frames, two points, unit = 1 mm.
        let a = [0.0, 0.0, 0.0, 2.0, 0.0, 0.0, 0.0, 0.0, 0.0, 2.0, 0.0, 0.0];
        let b = [0.0, 0.0, 0.0, 5.0, 4.0, 0.0, 0.0, 1.0, 0.0, 2.0, 0.0, 0.0];
        let s = compare(&a, &b, 2, 1.0).unwrap();
        // distances: 0, 5, 1, 0
        assert!((s.mean_mm - 1.5).abs() < 1e-12);
        assert!((s.rms_mm - (26.0f64 / 4.0).sqrt()).abs() < 1e-12);
        assert_eq!(s.max_mm, 5.0);
        assert_eq!(s.worst, Some((0, 1)));
        assert_eq!(s.per_point_max_mm, vec![1.0, 5.0]);
        // Centroid of each frame is (1,0,0): spread² = 1+1+1+1 = 4; error² = 26.
        assert!((s.kg_percent - 100.0 * (26.0f64 / 4.0).sqrt()).abs() < 1e-9);
        assert_eq!(s.samples, 4);
    }

    #[test]
    fn units_scale_to_millimetres() {
        let a = [0.0f32; 3];
        let b = [0.0, 0.0, 2.0];
        let s = compare(&a, &b, 1, 10.0).unwrap(); // centimetres
        assert_eq!(s.max_mm, 20.0);
    }

    #[test]
    fn gaps_in_original_are_skipped_and_missing_output_is_infinite() {
        let nan = f32::NAN;
        let a = [nan, nan, nan, 1.0, 1.0, 1.0];
        let b = [5.0, 5.0, 5.0, 1.0, 1.0, 1.0];
        let s = compare(&a, &b, 2, 1.0).unwrap();
        assert_eq!((s.samples, s.max_mm), (1, 0.0));
        let c = [0.0, 0.0, 0.0, nan, nan, nan];
        let s = compare(&a, &c, 2, 1.0).unwrap();
        assert!(s.max_mm.is_infinite());
    }

    #[test]
    fn bone_drift_measures_stretch_against_offsets() {
        use crate::motion::skeleton::{Animation, Channel, Joint};
        let s = Animation::new(
            vec![
                Joint {
                    name: "root".into(),
                    parent: None,
                    offset: [0.0; 3],
                    channels: vec![Channel::Xposition],
                    end_site: false,
                },
                Joint {
                    name: "tip".into(),
                    parent: Some(0),
                    offset: [0.0, 2.0, 0.0],
                    channels: vec![],
                    end_site: true,
                },
            ],
            vec![0.0, 5.0],
        )
        .unwrap();
        // Exact FK: no drift.
        let d = bone_length_drift(&s, &s.forward_kinematics(), 10.0).unwrap();
        assert_eq!((d.max_mm, d.bones), (0.0, 1));
        // Tip 2.5 units from the root in frame 1: 0.5 units = 5 mm too long, 25 %.
        let pos = [0.0, 0.0, 0.0, 0.0, 2.0, 0.0, 5.0, 0.0, 0.0, 5.0, 2.5, 0.0];
        let d = bone_length_drift(&s, &pos, 10.0).unwrap();
        assert!((d.max_mm - 5.0).abs() < 1e-12);
        assert!((d.mean_mm - 2.5).abs() < 1e-12);
        assert!((d.max_relative - 0.25).abs() < 1e-12);
    }

    #[test]
    fn shape_mismatch_is_an_error() {
        assert!(compare(&[0.0; 6], &[0.0; 3], 1, 1.0).is_err());
        assert!(compare(&[0.0; 4], &[0.0; 4], 1, 1.0).is_err());
    }

    #[test]
    fn error_series_bins_seconds_and_round_trips() {
        // 3 frames of 1 point, bins of 2 frames: errors 1, 3 (bin 0), then 2 with a gap.
        let a = [0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0];
        let b = [1.0, 0.0, 0.0, 0.0, 3.0, 0.0, 0.0, 0.0, 2.0];
        let s = ErrorSeries::of(&a, &b, 1, 2, 10.0);
        assert_eq!(s.max_mm, vec![30.0, 20.0]);
        assert_eq!(s.mean_mm, vec![20.0, 20.0]);
        assert_eq!(ErrorSeries::from_bytes(&s.to_bytes()).unwrap(), s);
        assert!(ErrorSeries::from_bytes(&s.to_bytes()[..15]).is_err());
        assert!(ErrorSeries::from_bytes(b"MCES\0\0\0\0\0\0\0\0").is_err());
        let gap = [f32::NAN, 0.0, 0.0, 0.0, 0.0, 0.0];
        let s = ErrorSeries::of(&gap, &[5.0, 0.0, 0.0, 1.0, 0.0, 0.0], 1, 1, 1.0);
        assert_eq!(s.max_mm, vec![0.0, 1.0], "missing samples are not errors");
    }
}
