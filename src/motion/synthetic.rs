//! Small generated motions for tests and benchmarks: smooth, deterministic, human-sized.

use super::model::Motion;
use super::units::Unit;
pub use crate::rng::Rng;

/// `points` markers in mm on a figure walking forward: a shared root drift, limb-like
/// oscillations at gait frequencies, a little per-marker jitter, and optionally gaps (runs
/// of missing samples) on a fraction of markers.
pub fn walker(frames: usize, points: usize, fps: f64, seed: u64, gap_fraction: f64) -> Motion {
    let mut rng = Rng::new(seed);
    let speed = 800.0 + 800.0 * rng.unit(); // mm/s
    let params: Vec<[f64; 6]> = (0..points)
        .map(|_| {
            [
                rng.unit() * 600.0 - 300.0, // x offset
                rng.unit() * 1700.0,        // height
                rng.unit() * 300.0 - 150.0, // z offset
                20.0 + rng.unit() * 250.0,  // swing amplitude
                rng.unit() * std::f64::consts::TAU,
                0.8 + rng.unit() * 1.4, // gait frequency (Hz)
            ]
        })
        .collect();
    let mut data = Vec::with_capacity(frames * points * 3);
    for f in 0..frames {
        let t = f as f64 / fps;
        for p in &params {
            let phase = std::f64::consts::TAU * p[5] * t + p[4];
            data.push((p[0] + speed * t + p[3] * phase.sin()) as f32);
            data.push((p[1] + 0.2 * p[3] * (2.0 * phase).cos() + 2.0 * rng.unit()) as f32);
            data.push((p[2] + 0.3 * p[3] * phase.cos()) as f32);
        }
    }
    if gap_fraction > 0.0 && frames > 2 {
        for p in 0..points {
            if rng.unit() >= gap_fraction {
                continue;
            }
            let start = rng.below(frames);
            let len = 1 + rng.below(frames / 4 + 1);
            for f in start..(start + len).min(frames) {
                data[(f * points + p) * 3..(f * points + p) * 3 + 3].fill(f32::NAN);
            }
        }
    }
    let names = (0..points).map(|i| format!("M{i}")).collect();
    Motion::new(fps, Unit::millimetres(), names, data, None).expect("consistent shape")
}

/// A BVH file whose hierarchy is a chain `depth` joints deep, with one frame: what a parser
/// that recursed on depth could not survive (tests, and `scripts/hostile`'s case).
pub fn chain_bvh(depth: usize) -> String {
    let mut s = String::from(
        "HIERARCHY\nROOT j0\n{\nOFFSET 0 0 0\nCHANNELS 3 Xposition Yposition Zposition\n",
    );
    for i in 1..depth {
        s.push_str(&format!(
            "JOINT j{i}\n{{\nOFFSET 0 1 0\nCHANNELS 1 Zrotation\n"
        ));
    }
    s.push_str(&"}\n".repeat(depth));
    s.push_str("MOTION\nFrames: 1\nFrame Time: 0.01\n0 0 0");
    s.push_str(&" 1".repeat(depth.saturating_sub(1)));
    s.push('\n');
    s
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn deterministic_and_shaped() {
        let a = walker(50, 4, 120.0, 7, 0.5);
        let b = walker(50, 4, 120.0, 7, 0.5);
        assert_eq!(a.positions().len(), 600);
        assert_eq!(
            a.positions()
                .iter()
                .map(|v| v.to_bits())
                .collect::<Vec<_>>(),
            b.positions()
                .iter()
                .map(|v| v.to_bits())
                .collect::<Vec<_>>()
        );
    }
}
